"""The torch ring shared by :mod:`grip.kinematics` and :mod:`policies`.

Its modules import only torch, numpy and :mod:`grip.core`, so both learning layers may use
them without depending on each other (``tests/test_layering.py``):

===========================  ====================================================================
module                       holds
===========================  ====================================================================
:mod:`grip.nn.weights`       weight packing (fp32/fp16/int8) and safe KinematicsNet checkpoint
                             loading (``torch.load(weights_only=True)``)
:mod:`grip.nn.symmetry`      the yaw turns and the left-right mirror of sensor features and
                             KinematicsNet targets
===========================  ====================================================================
"""
