"""Left-right mirror augmentation of KinematicsNet's training windows."""

import dataclasses

import numpy as np
import pytest
import torch

from grip.core import skeleton as sk
from grip.kinematics.config import KinematicsRunConfig, TrainConfig
from grip.kinematics.dataset import sequence_arrays
from grip.kinematics.features import FeatureConfig
from grip.kinematics.train import Trainer, fk_positions
from grip.motion.motion import Motion
from grip.nn.symmetry import mirror_batch, mirror_site_order
from prism_tools.synth import recording_from_motion
from prism_tools.synthetic import make_recording

SITES = ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist", "Head", "Pelvis")


def _motion(n: int = 160, seed: int = 3) -> Motion:
    """A walking motion with lateral asymmetry (arm swing, lean), from the synthetic test
    recording generator."""
    rec = make_recording(n, seed=seed)
    from grip.core.rotations import axis_angle_to_quat

    q = axis_angle_to_quat(np.asarray(rec.smpl_params.poses, dtype=np.float64).reshape(n, 24, 3))
    root = np.asarray(rec.smpl_params.trans, dtype=np.float64) + rec.smpl_params.root_offset
    m = Motion(fps=100.0, root_pos=root, local_quat=q, name="m", category="walk")
    # On the floor: the sensor synthesis refuses a body whose soles never come near it.
    from prism_tools.synth.props import insole_cell_positions

    body = m.body_model()
    lowest = insole_cell_positions(*m.fk(body), body)[..., 2].min()
    return dataclasses.replace(m, root_pos=root - np.array([0.0, 0.0, lowest]))


def _mirror_motion(m: Motion) -> Motion:
    """The mirror image through x = 0: left and right joints swap, local rotations R -> M R M
    (quaternion (w, x, -y, -z)) and the root x -> -x."""
    q = m.local_quat[:, sk.MIRROR] * np.array([1.0, 1.0, -1.0, -1.0])
    return dataclasses.replace(m, local_quat=q, root_pos=m.root_pos * np.array([-1.0, 1.0, 1.0]))


def _batch(s):
    x = torch.from_numpy(s.x[None].astype(np.float64))
    y = {k: torch.from_numpy(v[None].astype(np.float64)) for k, v in s.y.items()}
    y["offsets"] = torch.from_numpy(s.offsets[None].astype(np.float64))
    return x, y


@pytest.mark.parametrize("insoles", [True, False])
def test_mirrored_window_equals_the_window_of_the_mirrored_motion(insoles):
    # Synthesise clean sensors from a motion and from its mirror image: mirroring the first
    # one's features and targets must give the second one's (an independent path through the
    # body model, forward kinematics, IMU and insole synthesis).
    cfg = FeatureConfig(sites=SITES, insoles=insoles)
    m = _motion()
    a = sequence_arrays(recording_from_motion(m, noise=False), cfg)
    b = sequence_arrays(recording_from_motion(_mirror_motion(m), noise=False), cfg)
    xa, ya = _batch(a)
    xb, yb = _batch(b)
    xm, ym = mirror_batch(xa, ya, SITES, insoles)
    n = 15 * len(SITES)
    for i, site in enumerate(SITES):
        sl = slice(15 * i, 15 * i + 15)
        torch.testing.assert_close(xm[..., sl], xb[..., sl], atol=2e-4, rtol=0, msg=site)
    if insoles:
        # Force and contacts exactly; the CoP (forward, medial) to a millimetre.
        torch.testing.assert_close(xm[..., n:], xb[..., n:], atol=1e-3, rtol=0)
    for k in ("lp", "fp", "fa", "lv", "offsets"):
        torch.testing.assert_close(ym[k], yb[k], atol=1e-4, rtol=0, msg=k)


def test_mirror_is_an_involution_and_keeps_fk_consistent():
    s = sequence_arrays(make_recording(120, seed=5), FeatureConfig())
    x, y = _batch(s)
    xm, ym = mirror_batch(x, y, FeatureConfig().sites, True)
    assert not torch.allclose(xm, x)
    x2, y2 = mirror_batch(xm, ym, FeatureConfig().sites, True)
    torch.testing.assert_close(x2, x)
    for k in y:
        torch.testing.assert_close(y2[k], y[k])
    torch.testing.assert_close(fk_positions(ym["fa"], ym["offsets"]), ym["fp"], atol=1e-4, rtol=0)


def test_one_sided_sensor_sets_are_refused():
    assert mirror_site_order(("L_Foot", "R_Foot", "Head")) == [1, 0, 2]
    with pytest.raises(ValueError, match=r"lacks.*R_Wrist"):
        mirror_site_order(("L_Foot", "R_Foot", "L_Wrist"))
    cfg = KinematicsRunConfig(
        features=FeatureConfig(sites=("L_Foot", "R_Foot", "L_Wrist")),
        train=TrainConfig(mirror_augment=True),
    )
    s = sequence_arrays(make_recording(60, seed=1), cfg.features)
    with pytest.raises(ValueError, match="partner"):
        Trainer(cfg, [s], [s], "/nonexistent")
    with pytest.raises(ValueError, match="no mirror rule"):
        x, y = _batch(s)
        mirror_batch(x, {**y, "other": y["lp"]}, ("L_Foot", "R_Foot"), False)


def test_training_with_mirror_flips_about_half_the_windows(tmp_path, monkeypatch):
    seqs = [sequence_arrays(make_recording(n, seed=n), FeatureConfig()) for n in (150, 120)]
    train = TrainConfig(window_frames=30, batch_size=64, steps_per_epoch=1, stage_epochs=0,
                        joint_epochs=1, val_windows=4, mirror_augment=True,
                        yaw_augment=False, acc_noise=0.0, ori_noise_rad=0.0)  # fmt: skip
    cfg = KinematicsRunConfig(hidden=8, layers=1, init_hidden=8, train=train)
    tr = Trainer(cfg, seqs, seqs, tmp_path)
    from grip.kinematics.dataset import sample_windows

    x, y = sample_windows(seqs, 64, 30, np.random.default_rng(0))
    xt, yt = tr._tensors(x, y, augment=True)
    plain = (torch.from_numpy(x) - torch.from_numpy(tr.norm.mean)) / torch.from_numpy(tr.norm.std)
    same = torch.isclose(xt, plain, atol=1e-6).flatten(1).all(1)
    assert 16 < int(same.sum()) < 48  # about half mirrored
    mirrored = mirror_batch(torch.from_numpy(x), {k: torch.from_numpy(v) for k, v in y.items()},
                            cfg.features.sites, True)[1]  # fmt: skip
    for k in ("fp", "offsets"):
        torch.testing.assert_close(yt[k][~same], mirrored[k][~same])
        torch.testing.assert_close(yt[k][same], torch.from_numpy(y[k])[same])


def test_mirrored_reference_clip_equals_the_clip_of_the_mirrored_motion():
    # The controller's references: mirroring the clip of a motion (ground-truth pose vector,
    # estimate, sensors) must give the clip made from the motion's mirror image.
    from grip.core.reference import ReferenceSet
    from grip.kinematics.reference import (
        MIRROR_SUFFIX,
        mirror_reference_clip,
        oracle_reference_clip,
        with_mirrored_clips,
    )

    cfg = FeatureConfig()
    m = _motion()
    a = oracle_reference_clip(recording_from_motion(m, noise=False), cfg)
    b = oracle_reference_clip(recording_from_motion(_mirror_motion(m), noise=False), cfg)
    c = mirror_reference_clip(a, cfg.sites, cfg.insoles)
    assert c.name == a.name + MIRROR_SUFFIX and c.category == a.category
    np.testing.assert_allclose(c.gt_qpos, b.gt_qpos, atol=1e-6)
    np.testing.assert_allclose(c.gt_pos, b.gt_pos, atol=1e-6)
    for k in ("est_pos", "est_rot6d", "est_vel"):
        np.testing.assert_allclose(getattr(c, k), getattr(b, k), atol=1e-4, err_msg=k)
    n = 15 * len(cfg.sites)
    np.testing.assert_allclose(c.sensor[:, :n], b.sensor[:, :n], atol=2e-4)
    np.testing.assert_allclose(c.sensor[:, n:], b.sensor[:, n:], atol=1e-3)
    # mirroring twice gives the clip back; a set gets every clip and its mirror image
    back = mirror_reference_clip(c, cfg.sites, cfg.insoles)
    np.testing.assert_allclose(back.gt_qpos, a.gt_qpos, atol=1e-12)
    np.testing.assert_allclose(back.sensor, a.sensor, atol=1e-6)
    both = with_mirrored_clips(ReferenceSet([a], tuple(cfg.sites), cfg.insoles))
    assert [x.name for x in both.clips] == [a.name, c.name]
