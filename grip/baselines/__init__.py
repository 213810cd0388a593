"""Optimisation and kinematics baselines (BASELINES_AND_METRICS.md sections 1-2).

Each method returns a :class:`grip.core.reconstruction.Reconstruction`, the output type GRIP
itself produces, so the benchmark treats every method alike. Modules:

* :mod:`grip.baselines.pip_physics`: PIP's per-frame QP physics optimiser on MuJoCo (section 1).
* :mod:`grip.baselines.transpose_translation`: TransPose's root translation (section 2.2, numpy).

This package's ``__init__`` imports nothing, so that a numpy-only module of the package can be
used without loading MuJoCo.
"""
