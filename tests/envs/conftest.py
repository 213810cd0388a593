"""Reference sets for the environment tests, with a perfect estimate (the ground truth).

``walk_reference``: real mocap (CMU 07_05, a slow walk, 4.3 s) from the shared clips, for the
physics checks; skipped where the shared data is absent. ``reference``: the same walk when it is
there, else a synthetic recording, for the contract tests that hold for any motion.
"""

from __future__ import annotations

import pytest

from grip.core.reference import ReferenceSet
from grip.kinematics.reference import oracle_reference_clip

SITES = ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist")


@pytest.fixture(scope="session")
def _walk_or_none(cmu_walk_or_none) -> ReferenceSet | None:
    if cmu_walk_or_none is None:
        return None
    from prism_tools.synth import SynthConfig, recording_from_motion

    rec = recording_from_motion(cmu_walk_or_none, SynthConfig(), seed=0, noise=False)
    return ReferenceSet([oracle_reference_clip(rec)], SITES, True, source="cmu/bvh/07_05.bvh")


@pytest.fixture(scope="session")
def walk_reference(_walk_or_none) -> ReferenceSet:
    if _walk_or_none is None:
        pytest.skip("shared motion data (cmu/bvh/07_05.bvh) not found")
    return _walk_or_none


@pytest.fixture(scope="session")
def reference(_walk_or_none) -> ReferenceSet:
    if _walk_or_none is not None:
        return _walk_or_none
    from prism_tools.synthetic import make_recording

    return ReferenceSet([oracle_reference_clip(make_recording(300, seed=0))], SITES, True)
