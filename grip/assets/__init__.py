"""The files shipped with the package, as absolute paths (no imports beyond the standard library).

Every layer that needs a shipped file (the commands, the evaluation methods, benchmarks, tests)
takes its path from here.
"""

from __future__ import annotations

from pathlib import Path

ASSETS = Path(__file__).resolve().parent
REPO_ROOT = ASSETS.parents[1]
"""The checkout's root (where ``configs/`` lives in a development install)."""

SHIPPED_KIN = ASSETS / "kinematics_default.pt"
"""The KinematicsNet checkpoint every command uses by default."""
SHIPPED_POLICY = ASSETS / "policy_default.pt"
"""The controller every command uses by default."""
SHIPPED_BASELINES = {"transpose": ASSETS / "transpose4.pt", "pip": ASSETS / "pip4.pt"}
"""The baselines' networks, by method name."""
SAMPLE_RECORDING = ASSETS / "sample_recording.npz"
"""The demo's recording: a 5 s walk of the test split with 4 IMUs and both insoles."""
