import dataclasses

import numpy as np
import pytest

from grip.core.reference import ReferenceClip, ReferenceError, ReferenceSet
from grip.kinematics.reference import oracle_reference_clip
from prism_tools.synthetic import make_recording


@pytest.fixture(scope="module")
def clip() -> ReferenceClip:
    return oracle_reference_clip(make_recording(60, seed=4))


def test_round_trip_keeps_the_arrays_and_derives_the_rest(clip, tmp_path) -> None:
    rs = ReferenceSet([clip], ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist"), True)
    rs.save(tmp_path / "r.npz")
    back = ReferenceSet.load(tmp_path / "r.npz").clip(0)
    np.testing.assert_allclose(back.gt_qpos, clip.gt_qpos)
    np.testing.assert_allclose(back.est_pos, clip.est_pos, atol=1e-6)
    np.testing.assert_allclose(back.gt_pos, clip.gt_pos, atol=1e-9)
    # perfect estimate: the estimated root-relative joints are the ground truth's
    np.testing.assert_allclose(clip.est_pos, clip.gt_pos - clip.gt_pos[:, :1], atol=1e-5)
    assert back.gt_qvel.shape == (60, 75) and back.est_hinge_vel.shape == (60, 69)


def test_a_training_sets_clips_are_compact_and_equal_to_float32_rounding(clip, tmp_path) -> None:
    from grip.core.reference_sets import load_reference

    rs = ReferenceSet([clip], ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist"), True)
    rs.save(tmp_path / "r.npz")
    full = ReferenceSet.load(tmp_path / "r.npz").clip(0)
    small = load_reference(str(tmp_path / "r.npz")).clip(0)  # the training loader: compact
    arrays = [k for k, v in vars(full).items() if isinstance(v, np.ndarray)]
    assert len(arrays) > 10 and full.gt_qpos.dtype == small.gt_qpos.dtype == np.float64
    for k in arrays:
        a, b = getattr(full, k), getattr(small, k)
        assert a.dtype == np.float64 and (k == "gt_qpos" or b.dtype == np.float32), k
        np.testing.assert_allclose(b, a, rtol=1e-6, atol=1e-6, err_msg=k)
    size = lambda c: sum(getattr(c, k).nbytes for k in arrays)  # noqa: E731
    assert size(small) < 0.55 * size(full)
    again = ReferenceSet.load(tmp_path / "r.npz")
    again.clip(0).compact()
    np.testing.assert_array_equal(again.clip(0).est_rot, small.est_rot)


def test_bad_clips_and_files_are_refused_with_the_key_named(clip, tmp_path) -> None:
    bad = clip.est_vel.copy()
    bad[7, 0, 0] = np.nan
    with pytest.raises(ReferenceError, match=r"est_vel.*frame 7"):
        ReferenceClip(clip.name, clip.category, clip.fps, clip.body, clip.gt_qpos, clip.est_pos,
                      clip.est_rot6d, bad, clip.sensor)  # fmt: skip
    with pytest.raises(ReferenceError, match="est_pos"):
        ReferenceClip(clip.name, clip.category, clip.fps, clip.body, clip.gt_qpos,
                      clip.est_pos[:-1], clip.est_rot6d, clip.est_vel, clip.sensor)  # fmt: skip
    with pytest.raises(ReferenceError, match="sensor width"):
        ReferenceSet([clip], ("L_Foot",), False)
    np.savez(tmp_path / "x.npz", a=np.zeros(3))
    with pytest.raises(ReferenceError, match=r"x\.npz.*__meta__"):
        ReferenceSet.load(tmp_path / "x.npz")


_EST = ("est_pos", "est_rot", "est_vel", "est_angvel", "est_hinge", "est_hinge_vel",
        "est_root_pos", "sensor")  # fmt: skip


def _head(clip: ReferenceClip, n: int) -> ReferenceClip:
    return ReferenceClip(clip.name, clip.category, clip.fps, clip.body, clip.gt_qpos[:n],
                         clip.est_pos[:n], clip.est_rot6d[:n], clip.est_vel[:n], clip.sensor[:n])


def test_live_estimate_grows_to_the_offline_clip_frame_by_frame(clip) -> None:
    from grip.core.reference import LiveEstimate

    rec = make_recording(120, seed=9)
    full = oracle_reference_clip(rec)
    live = LiveEstimate(full.name, full.fps, full.gt_qpos[0, :3], full.sensor.shape[1],
                        capacity=8)  # fmt: skip
    for i in range(full.n_frames):
        assert live.append(full.est_pos[i], full.est_rot[i], full.est_vel[i], full.sensor[i]) == i
        if i in (1, 2, 37):  # the frames so far equal a clip that ends here
            part = _head(full, i + 1)
            for k in _EST:
                np.testing.assert_allclose(getattr(live, k)[: i + 1], getattr(part, k),
                                           atol=1e-9, err_msg=k)  # fmt: skip
    assert live.n_frames == full.n_frames and live.capacity == 128  # 8 doubled four times
    for k in _EST:
        np.testing.assert_allclose(getattr(live, k)[: full.n_frames], getattr(full, k),
                                   atol=1e-9, err_msg=k)  # fmt: skip
    assert not hasattr(live, "gt_qpos")  # no ground truth while streaming
    with pytest.raises(ReferenceError, match="frame 120: est_vel"):
        live.append(full.est_pos[0], full.est_rot[0], np.full((6, 3), np.nan), full.sensor[0])
    with pytest.raises(ReferenceError, match="features must have 70"):
        live.append(full.est_pos[0], full.est_rot[0], full.est_vel[0], full.sensor[0, :5])


@pytest.mark.parametrize(("frames", "n"), [(1, 3), (7, 1), (7, 200)])
def test_held_frames_equal_frames_appended_one_by_one(frames, n) -> None:
    """A stream's long dropout holds the newest pose n frames in one step (issue 50)."""
    from grip.core.reference import LiveEstimate

    full = oracle_reference_clip(make_recording(20, seed=3))
    one, held = (LiveEstimate(full.name, full.fps, full.gt_qpos[0, :3], full.sensor.shape[1],
                              capacity=4) for _ in range(2))  # fmt: skip
    for live in (one, held):
        for i in range(frames):
            live.append(full.est_pos[i], full.est_rot[i], full.est_vel[i], full.sensor[i])
    k = frames - 1
    for _ in range(n):
        one.append(full.est_pos[k], full.est_rot[k], np.zeros((6, 3)), full.sensor[k])
    assert held.append_held(n) == frames + n - 1 == one.n_frames - 1 == held.n_frames - 1
    for live in (one, held):  # and the next frame after it
        live.append(full.est_pos[k + 1], full.est_rot[k + 1], full.est_vel[k + 1],
                    full.sensor[k + 1])  # fmt: skip
    for key in _EST:
        np.testing.assert_allclose(getattr(held, key)[: held.n_frames],
                                   getattr(one, key)[: one.n_frames], atol=1e-9,
                                   err_msg=key)  # fmt: skip
    empty = LiveEstimate("x", 100.0, np.zeros(3), 70)
    with pytest.raises(ReferenceError, match="no frame to hold"):
        empty.append_held(3)


def test_live_clip_unwraps_hinge_angles_as_numpy_does() -> None:
    from grip.core.reference import _unwrap_step

    rng = np.random.default_rng(0)
    p = np.cumsum(rng.uniform(-3.5, 3.5, size=(300, 5)), axis=0)
    wrapped = np.angle(np.exp(1j * p))
    wrapped[10, 0] = np.pi  # the boundary case numpy.unwrap treats specially
    wrapped[11, 0] = -np.pi
    up = np.empty_like(wrapped)
    up[0], corr = wrapped[0], np.zeros(5)
    for i in range(1, len(p)):
        corr = corr + _unwrap_step(wrapped[i] - wrapped[i - 1])
        up[i] = wrapped[i] + corr
    np.testing.assert_array_equal(up, np.unwrap(wrapped, axis=0))


def test_merging_sets_keeps_every_clip_with_unique_names() -> None:
    from grip.kinematics.features import FeatureConfig
    from grip.kinematics.reference import merge_reference_sets

    cfg = FeatureConfig()

    def one(seed: int, sites=tuple(cfg.sites)) -> ReferenceSet:
        clips = [oracle_reference_clip(make_recording(40, seed=s)) for s in (seed, seed + 1)]
        return ReferenceSet(clips, sites, cfg.insoles, f"set{seed}")

    a, b = one(0), one(0)
    merged = merge_reference_sets([a, b], source="both")
    assert len(merged) == 4 and merged.source == "both"
    names = [c.name for c in merged.clips]
    assert names[2:] == [f"{n}#1" for n in names[:2]] and len(set(names)) == 4
    np.testing.assert_array_equal(merged.clip(2).gt_qpos, merged.clip(0).gt_qpos)
    assert [c.name for c in b.clips] == names[:2]  # the inputs keep their names
    with pytest.raises(ValueError, match="differ"):
        merge_reference_sets([one(0), one(0, sites=tuple(reversed(cfg.sites)))])
    with pytest.raises(ValueError, match="at least one"):
        merge_reference_sets([])


def test_a_clips_oracle_is_the_oracle_clip_of_its_recording() -> None:
    """``ReferenceClip.oracle()`` (the teacher's view in grip policy distill) equals
    ``oracle_reference_clip`` (the references a follow = "truth" run trains on)."""
    rec = make_recording(80, seed=9)
    est = oracle_reference_clip(rec)
    noisy = dataclasses.replace(est, est_pos=est.est_pos + 0.05, est_vel=est.est_vel * 1.3)
    got = noisy.oracle()
    for key in ("est_pos", "est_rot", "est_vel", "est_angvel", "est_hinge", "est_hinge_vel",
                "est_root_pos", "sensor", "gt_qpos"):  # fmt: skip
        np.testing.assert_allclose(getattr(got, key), getattr(est, key), atol=1e-9, err_msg=key)
