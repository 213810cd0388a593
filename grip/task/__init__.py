"""The tracking task's numpy definition, shared by the layers that pose, solve and replay it.

The environment (:mod:`envs`) computes these observations and AMP frames from the simulator,
the policies (:mod:`policies`) read their settings and layouts, and the inference pipeline
(:mod:`grip.pipeline`) computes them again without the environment. Its modules import only
numpy and :mod:`grip.core`, so each of those layers may use them without importing another
(``tests/test_layering.py``):

================================  ===============================================================
module                            holds
================================  ===============================================================
:mod:`grip.task.config`           the environment's settings (``TrackingEnvConfig``,
                                  ``RewardConfig``), which the policy recipe composes
:mod:`grip.task.observations`     the observation parts, their layouts and the height-map grid
:mod:`grip.task.amp`              the AMP frame: its layout and features (real and simulated)
================================  ===============================================================
"""
