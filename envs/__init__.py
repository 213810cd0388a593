"""MuJoCo tracking environment of GRIP (mujoco + gymnasium; never torch).

``gymnasium.make("GripTracking-v0")`` works with no arguments: it tracks the small bundled
reference sample. Pass ``cfg=TrackingEnvConfig(...)`` and/or ``reference=ReferenceSet.load(...)``
for real runs.
"""

from gymnasium.envs.registration import register, registry

ENV_ID = "GripTracking-v0"

if ENV_ID not in registry:
    register(id=ENV_ID, entry_point="envs.tracking_env:GripTrackingEnv")
