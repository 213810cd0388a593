"""Fixtures shared across the test tree."""

from __future__ import annotations

import pytest

_WALK = ("cmu", "bvh", "07_05.bvh")


@pytest.fixture(scope="session")
def cmu_walk_or_none():
    """CMU 07_05 (a slow walk, 4.3 s) from the shared clips, retargeted onto the default body
    at 100 Hz, or ``None`` where the shared motion data is absent. Read-only: tests derive
    copies (``dataclasses.replace``)."""
    from grip.cli.paths import default_motions_dir
    from grip.motion.catalog import load_clip
    from grip.motion.retarget import retarget

    root = default_motions_dir()
    path = root.joinpath(*_WALK) if root else None
    if path is None or not path.is_file():
        return None
    return retarget(load_clip(str(path)))


@pytest.fixture(scope="session")
def cmu_walk(cmu_walk_or_none):
    """:func:`cmu_walk_or_none`, skipping the test where the shared data is absent."""
    if cmu_walk_or_none is None:
        pytest.skip("shared motion data (" + "/".join(_WALK) + ") not found")
    return cmu_walk_or_none
