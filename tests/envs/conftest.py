"""Reference sets for the environment tests: real mocap (CMU slow walk) with a perfect estimate."""

from __future__ import annotations

from pathlib import Path

import pytest

from grip.core.reference import ReferenceSet
from grip.kinematics.reference import oracle_reference_clip

MOTIONS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "motions"
WALK = MOTIONS / "cmu" / "bvh" / "07_05.bvh"  # slow walk, 4.3 s


@pytest.fixture(scope="session")
def walk_reference() -> ReferenceSet:
    from grip.motion.catalog import load_clip
    from grip.motion.retarget import retarget
    from prism_tools.synth import SynthConfig, recording_from_motion

    motion = retarget(load_clip(str(WALK)))
    rec = recording_from_motion(motion, SynthConfig(), seed=0, noise=False)
    return ReferenceSet([oracle_reference_clip(rec)], ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist"),
                        True, source=str(WALK))  # fmt: skip
