import numpy as np
import pytest

from grip.core import skeleton as sk
from grip.core.body import build_body
from grip.kinematics.config import KinematicsRunConfig, TrainConfig
from grip.kinematics.dataset import sequence_arrays
from grip.kinematics.features import FeatureConfig, input_features, recording_body
from grip.kinematics.inference import KinematicsEstimator, decode_outputs
from grip.kinematics.train import Trainer
from prism_tools.synthetic import make_recording


@pytest.fixture(scope="module")
def ckpt(tmp_path_factory):
    seqs = [sequence_arrays(make_recording(n, seed=n), FeatureConfig()) for n in (120, 90)]
    train = TrainConfig(window_frames=30, batch_size=2, steps_per_epoch=2, stage_epochs=0,
                        joint_epochs=1, val_windows=2)  # fmt: skip
    cfg = KinematicsRunConfig(hidden=16, layers=2, init_hidden=8, train=train)
    run = tmp_path_factory.mktemp("run")
    Trainer(cfg, seqs, seqs, run).fit()
    return run / "last.pt"


def test_offline_batched_equals_single_and_streaming(ckpt):
    est = KinematicsEstimator.from_checkpoint(ckpt)
    recs = [make_recording(80, seed=11), make_recording(50, seed=12)]
    both = est.predict(recs)
    single = est.predict([recs[1]])[0]
    np.testing.assert_allclose(both[1].joint_pos, single.joint_pos, atol=1e-5)
    assert both[0].global_rot.shape == (80, 24, 3, 3) and both[1].root_pos.shape == (50, 3)
    stream = est.stream(recs[0])
    feats = input_features(recs[0], est.cfg.features)
    rows = [stream.step(f) for f in feats]
    fp = np.stack([r["fp"] for r in rows]).reshape(80, 24, 3)
    np.testing.assert_allclose(fp, both[0].fp_joint_pos, atol=1e-5)
    # the pose's joints: forward kinematics of the streamed rotations on the subject's body
    rot = decode_outputs({k: np.stack([r[k] for r in rows]) for k in rows[0]}, 80,
                         build_body(recording_body(recs[0])).offsets)  # fmt: skip
    np.testing.assert_allclose(rot[0], both[0].joint_pos, atol=1e-5)
    np.testing.assert_allclose(rot[1], both[0].global_rot, atol=1e-5)
    bones = np.linalg.norm(both[0].joint_pos[:, 1:] - both[0].joint_pos[:, sk.PARENTS[1:]], axis=-1)
    rest = np.linalg.norm(build_body(recording_body(recs[0])).offsets[1:], axis=-1)
    np.testing.assert_allclose(bones, np.broadcast_to(rest, bones.shape), atol=1e-9)
    sp = recs[0].smpl_params
    np.testing.assert_allclose(both[0].root_pos[0], sp.trans[0] + sp.root_offset, atol=1e-6)


def test_evaluation_rows_and_table(ckpt, tmp_path):
    from grip.eval.kinematics import aggregate, markdown_table
    from grip.kinematics.evaluate import evaluate_recordings

    est = KinematicsEstimator.from_checkpoint(ckpt)
    rows = evaluate_recordings(est, [make_recording(130, seed=3)], segment_frames=50)
    assert [r["frames"] for r in rows] == [50, 50, 30]
    agg = aggregate(rows)
    assert agg["overall"]["frames"] == 130 and agg["overall"]["PEL_MPJPE_mm"] > 0
    assert "**all**" in markdown_table(agg)
    # the FP stage's joints instead of the posed rotations: another position error, same MPJRE
    fp = evaluate_recordings(est, [make_recording(130, seed=3)], segment_frames=50, joints="fp")
    for a, b in zip(rows, fp, strict=True):
        assert a["PEL_MPJPE_mm"] != pytest.approx(b["PEL_MPJPE_mm"], rel=1e-3)
        assert a["MPJRE_deg"] == b["MPJRE_deg"]
    with pytest.raises(ValueError, match="joints must be"):
        evaluate_recordings(est, [make_recording(60, seed=3)], segment_frames=50, joints="lp")


@pytest.mark.parametrize("mode", ["mirror", "yaw4", "full"])
def test_test_time_augmentation_streams_like_offline(ckpt, mode):
    est = KinematicsEstimator.from_checkpoint(ckpt, tta=mode)
    plain = KinematicsEstimator.from_checkpoint(ckpt)
    rec = make_recording(60, seed=21)
    off = est.predict([rec])[0]
    stream = est.stream(rec)
    rows = [stream.step(f) for f in input_features(rec, est.cfg.features)]
    np.testing.assert_allclose(np.stack([r["fp"] for r in rows]).reshape(60, 24, 3),
                               off.fp_joint_pos, atol=1e-5)  # fmt: skip
    # an average of several copies: not the plain estimate
    assert np.abs(off.fp_joint_pos - plain.predict([rec])[0].fp_joint_pos).max() > 1e-3


def test_full_test_time_augmentation_is_exactly_equivariant(ckpt):
    """Averaged over the group of quarter turns and the mirror, the estimate of a turned or
    mirrored input is the turned or mirrored estimate; the bare network is not equivariant."""
    import torch

    from grip.nn.symmetry import (
        mirror_features,
        mirror_targets,
        rotate_features,
        rotate_targets,
        yaw_matrices,
    )

    rec = make_recording(40, seed=5)
    feats = FeatureConfig()
    x = torch.from_numpy(input_features(rec, feats)[None].astype(np.float32))
    first = KinematicsEstimator.from_checkpoint(ckpt)._first([rec])
    sites, n = feats.sites, len(feats.sites)
    r = yaw_matrices(torch.tensor([np.pi / 2]))

    def with_first(y):
        return {k: v[:, 0] for k, v in y.items()}

    f3 = {k: v[:, None] for k, v in first.items()}
    transforms = {
        "mirror": (mirror_features(x, sites, True), with_first(mirror_targets(f3)), mirror_targets),
        "turn": (rotate_features(x, r, n), with_first(rotate_targets(f3, r)),
                 lambda y: rotate_targets(y, r)),
    }  # fmt: skip
    for mode, atol, expect_equal in (("full", 1e-5, True), ("none", 1e-3, False)):
        est = KinematicsEstimator.from_checkpoint(ckpt, tta=mode)
        base = est.run_features(x, first)
        for xt, ft, apply in transforms.values():
            got, want = est.run_features(xt, ft), apply(base)
            err = max(float((got[k] - want[k]).abs().max()) for k in ("lp", "fp", "fa", "lv"))
            assert (err < atol) == expect_equal, (mode, err)


def test_test_time_augmentation_errors(ckpt):
    with pytest.raises(ValueError, match="unknown test-time augmentation 'twice'"):
        KinematicsEstimator.from_checkpoint(ckpt, tta="twice")
    from grip.kinematics.inference import Symmetries

    with pytest.raises(ValueError, match="needs a mirror image"):
        Symmetries("mirror", ("L_Foot", "R_Foot", "L_Wrist"), True)
    assert Symmetries("yaw4", ("L_Foot", "R_Foot", "L_Wrist"), True).n == 4


def test_standing_init_starts_as_a_recording_without_ground_truth(ckpt):
    import dataclasses

    est = KinematicsEstimator.from_checkpoint(ckpt)
    rec = make_recording(60, seed=21)
    truth = est.predict([rec])[0]
    standing = est.predict([rec], init="standing")[0]
    no_gt = est.predict([dataclasses.replace(rec, smpl_params=None)])[0]
    np.testing.assert_allclose(standing.joint_pos, no_gt.joint_pos, atol=1e-6)
    # the same root track, placed at the truth's frame-0 place on the floor (the gauge)
    np.testing.assert_allclose(standing.root_pos - standing.root_pos[0],
                               no_gt.root_pos - no_gt.root_pos[0], atol=1e-9)  # fmt: skip
    np.testing.assert_allclose(standing.root_pos[0, :2], truth.root_pos[0, :2], atol=1e-9)
    np.testing.assert_allclose(standing.root_pos[0, 2], no_gt.root_pos[0, 2], atol=1e-12)
    assert np.abs(standing.joint_pos[0] - truth.joint_pos[0]).max() > 1e-3
    stream = est.stream(rec, init="standing")
    first = stream.step(input_features(rec, est.cfg.features)[0])
    np.testing.assert_allclose(first["fp"].reshape(24, 3), standing.fp_joint_pos[0], atol=1e-5)
    with pytest.raises(ValueError, match="init must be one of"):
        est.predict([rec], init="oracle")


def test_settled_error_leaves_out_the_first_second():
    """An estimate off by 10 cm in the first second only: all frames err, the settled figure
    does not; a segment no longer than a second has no settled figure."""
    from types import SimpleNamespace

    from grip.kinematics.evaluate import segment_metrics
    from grip.kinematics.features import targets
    from prism_tools.synthetic import make_recording

    rec = make_recording(250, seed=3)
    gt = targets(rec)
    pos = gt.joint_pos.copy()
    fps = round(rec.fps)
    pos[:fps] += np.array([0.1, 0.0, 0.0])
    pos[:fps, 0] = 0.0  # root-relative: the pelvis stays at the origin
    est = SimpleNamespace(joint_pos=pos, global_rot=gt.global_rot, velocity=gt.velocity,
                          root_pos=gt.root_pos)  # fmt: skip
    m = segment_metrics(est, rec)
    assert m["PEL_MPJPE_mm"] > 10.0 and m["PEL_MPJPE_settled_mm"] < 1e-6
    assert m["settled_frames"] == 250 - fps
    short = rec.slice_frames(0, fps)
    cut = SimpleNamespace(**{k: getattr(est, k)[:fps] for k in vars(est)})
    m = segment_metrics(cut, short)
    assert np.isnan(m["PEL_MPJPE_settled_mm"]) and m["settled_frames"] == 0
