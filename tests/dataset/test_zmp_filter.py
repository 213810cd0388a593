"""The dynamic filter (:mod:`grip.dataset.zmp_filter`): a few millimetres of pelvis shift bring
the ZMP of a dynamically inconsistent motion onto the feet; consistent motions are left alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grip.assets import REPO_ROOT
from grip.core import fk
from grip.core.body import build_body
from grip.core.rotations import matrix_to_quat, rot_z
from grip.dataset.build import BuildConfig, ClipSpec, process_clip
from grip.dataset.zmp_filter import (
    ZmpFilterConfig,
    _acceleration_operator,
    project_to_hulls,
    support_hulls,
    zmp_filter,
)
from grip.motion.motion import Motion
from grip.motion.retarget_feet import leg_ik
from prism_tools.synth.config import InsoleSynthConfig
from prism_tools.synth.insole import smooth_derivative
from prism_tools.synth.recording import ZMP_OUTSIDE_M

FPS = 100.0
BODY = build_body()
ANKLES = [7, 8]


def _standing(n: int) -> tuple[np.ndarray, np.ndarray]:
    """Rest pose upright (facing +y), arms lowered, feet flat on the floor."""
    rot, pos = fk.rest_pose(n)
    rot[:, 16] = rot_z(np.array(-np.deg2rad(75.0)))
    rot[:, 17] = rot_z(np.array(np.deg2rad(75.0)))
    pos[:, 2] = BODY.pelvis_height - 0.03  # knees slightly bent: the legs can take a shift
    local = leg_ik(rot, pos, BODY, np.full((n, 2), 0.03))  # feet back on the floor
    return local, pos


def _motion(local: np.ndarray, root: np.ndarray) -> Motion:
    return Motion(fps=FPS, root_pos=root, local_quat=matrix_to_quat(local), name="test/zmp")


def _pelvis_sway(n: int = 300, amp_m: float = 0.015, hz: float = 2.0) -> Motion:
    """Both feet planted, the pelvis swaying sideways at 2 Hz: the ZMP swings about 15 times
    further than the pelvis, well beyond the feet."""
    local, root = _standing(n)
    t = np.arange(n) / FPS
    shift = np.zeros((n, 3))
    shift[:, 0] = amp_m * np.sin(2 * np.pi * hz * t)
    local = leg_ik(local, root + shift, BODY, np.repeat(-shift[:, None], 2, axis=1))
    return _motion(local, root + shift)


def test_leg_ik_moves_the_ankle_in_3d_and_keeps_the_foot_orientation() -> None:
    local, root = _standing(5)
    g0, p0 = fk.forward_kinematics(local, root, BODY.offsets)
    disp = np.zeros((5, 2, 3))
    disp[:, 0] = [0.02, -0.01, 0.015]
    disp[:, 1] = [-0.01, 0.02, 0.0]
    g1, p1 = fk.forward_kinematics(leg_ik(local, root, BODY, disp), root, BODY.offsets)
    np.testing.assert_allclose(p1[:, ANKLES], p0[:, ANKLES] + disp, atol=1e-9)
    np.testing.assert_allclose(g1[:, ANKLES], g0[:, ANKLES], atol=1e-9)
    # (T, 2) still means a vertical move.
    lift = np.full((5, 2), 0.01)
    p2 = fk.forward_kinematics(leg_ik(local, root, BODY, lift), root, BODY.offsets)[1]
    np.testing.assert_allclose(p2[:, ANKLES, 2], p0[:, ANKLES, 2] + 0.01, atol=1e-9)


def test_hull_projection() -> None:
    square = np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0], [0.5, 0.5]])
    cells = np.broadcast_to(square, (4, 5, 2)).copy()
    use = np.ones((4, 5), dtype=bool)
    use[3] = [True, True, False, False, False]  # a segment
    verts, n = support_hulls(cells, use)
    assert list(n) == [4, 4, 4, 2]
    q = np.array([[0.5, 0.5], [2.0, 0.5], [-1.0, -1.0], [0.5, 0.5]])
    near, out = project_to_hulls(q, verts, n)
    np.testing.assert_allclose(near, [[0.5, 0.5], [1.0, 0.5], [0.0, 0.0], [0.5, 0.0]])
    np.testing.assert_allclose(out, [0.0, 1.0, np.sqrt(2.0), 0.5])


@pytest.mark.parametrize("window_s", [0.1, 0.2])
@pytest.mark.parametrize("n", [9, 40, 300])
def test_acceleration_operator_is_the_synthesis_derivative(window_s: float, n: int) -> None:
    cfg = InsoleSynthConfig(smoothing_window_s=window_s)
    x = np.random.default_rng(0).normal(size=(n, 2))
    op = _acceleration_operator(n, FPS, cfg)
    np.testing.assert_allclose(op @ x, smooth_derivative(x, FPS, window_s, 2, 2), atol=1e-6)


def test_sway_out_of_phase_with_the_feet_is_corrected_by_millimetres() -> None:
    motion = _pelvis_sway()
    res = zmp_filter(motion)
    before = res.synth_before.zmp_error_m > ZMP_OUTSIDE_M
    after = res.synth_after.zmp_error_m > ZMP_OUTSIDE_M
    assert res.feet_alone.all()
    assert before.mean() > 0.3
    assert after.mean() < 0.05
    shift = np.linalg.norm(res.shift_m, axis=1)
    assert 0.002 < shift.max() < 0.012  # a few millimetres against the 15 mm sway
    # Opposing the sway: the corrected pelvis sways less (z d'' / g does the rest).
    sway = motion.root_pos[:, 0] - motion.root_pos[:, 0].mean()
    assert np.corrcoef(res.shift_m[:, 0], sway)[0, 1] < -0.9
    # The feet do not move, and the motion is the input plus the shift.
    assert res.ankle_moved_m.max() < 1e-6
    np.testing.assert_allclose(res.motion.root_pos[:, :2], motion.root_pos[:, :2] + res.shift_m)
    np.testing.assert_allclose(res.motion.root_pos[:, 2], motion.root_pos[:, 2])
    g0, p0 = motion.fk(BODY)
    g1, p1 = res.motion.fk(BODY)
    np.testing.assert_allclose(g1[:, ANKLES], g0[:, ANKLES], atol=1e-6)
    np.testing.assert_allclose(p1[:, 15, :2] - p0[:, 15, :2], res.shift_m, atol=1e-6)  # head
    assert res.motion.meta["zmp_filter"]["shift_max_m"] == pytest.approx(shift.max())


def test_static_stance_is_unchanged() -> None:
    local, root = _standing(200)
    motion = _motion(local, root)
    res = zmp_filter(motion)
    assert res.feet_alone.all()
    assert not res.shift_m.any()
    assert res.motion is motion


def test_frames_not_carried_by_the_feet_alone_want_nothing() -> None:
    """In the air no foot is down: nothing to correct, the motion comes back as it was."""
    local, root = _pelvis_sway(120).local_rot(), _pelvis_sway(120).root_pos.copy()
    root[:, 2] += 0.3
    motion = _motion(local, root)
    res = zmp_filter(motion)
    assert not res.feet_alone.any() and not res.shift_m.any() and res.motion is motion


def test_settings_are_checked_and_the_build_setting_is_on_by_default() -> None:
    assert BuildConfig().zmp_filter is True
    with pytest.raises(ValueError):
        ZmpFilterConfig(shift_weight=0.0)
    with pytest.raises(ValueError):
        ZmpFilterConfig(jerk_weight_s6=-1.0)
    with pytest.raises(ValueError):
        ZmpFilterConfig(iterations=0)


DEEPMIMIC_WALK = (
    REPO_ROOT.parent / "shared" / "data" / "motions" / "deepmimic" / "humanoid3d_walk.txt"
)


@pytest.mark.skipif(not DEEPMIMIC_WALK.is_file(), reason="shared motion clips not found")
def test_build_setting_filters_the_stored_motion_and_its_recordings(tmp_path: Path) -> None:
    clip = ClipSpec(str(DEEPMIMIC_WALK), "deepmimic/walk", "walk")
    res = {}
    for on in (False, True):
        out = tmp_path / str(on)
        res[on] = process_clip(clip, str(out), BuildConfig(zmp_filter=on, vary_body=False))
        assert res[on].status == "done", res[on].error
        meta = Motion.load(out / "motions" / "deepmimic__walk.npz").meta
        assert ("zmp_filter" in meta) is on
    assert res[True].synth_frames == res[False].synth_frames
    assert res[True].zmp_outside_frames < 0.5 * res[False].zmp_outside_frames


def test_a_folder_that_predates_the_filter_resumes_only_without_it(tmp_path: Path) -> None:
    """Its motions are unfiltered: resuming it with the default (filter on) is refused by name,
    with ``zmp_filter=False`` (``--no-zmp-filter``) it resumes."""
    import json
    from dataclasses import asdict

    from grip.core.runs import SettingsMismatch
    from grip.dataset.build import SETTINGS, _settings_check

    old = asdict(BuildConfig())
    del old["zmp_filter"]
    (tmp_path / SETTINGS).write_text(json.dumps(old))
    with pytest.raises(SettingsMismatch, match="zmp_filter"):
        _settings_check(tmp_path, BuildConfig())
    _settings_check(tmp_path, BuildConfig(zmp_filter=False))
