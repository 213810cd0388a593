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
"""The demo's recording: a 5 s walk with 4 IMUs and both insoles (Bandai Namco dataset-1's "proud"
walk: in the test split of the per-clip corpus, a training person of the split by person on which
both shipped models were trained)."""
SAMPLE_PROPS_RECORDING = ASSETS / "sample_props_recording.npz"
"""The demo's recording with props: 6 s of CMU subject 14 (a person in no training split of the
``--test-group cmu/14`` corpus) climbing three steps, with the steps the data build inferred from
the motion as its objects. Made with ``grip data build --out DATA --test-group cmu/14`` and
``grip data cut DATA/sequences/cmu__14_21_v0_seq000.npz --start 0.5 --end 6.5 --out
grip/assets/sample_props_recording.npz``."""
