"""TransPose / PIP kinematics nets adapted to 4 IMUs: inputs, targets, nets, training, checkpoints,
inference."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import torch

from grip.core import skeleton as sk
from grip.core.metrics import contacts_from_motion
from grip.core.rotations import rot_z, sixd_to_matrix
from grip.kinematics.baseline_config import (
    config_from_json,
    default_run_config,
    feature_config,
    input_columns,
    n_inputs,
    replace_train,
)
from grip.kinematics.baseline_nets import PipNets, TransPoseNets, cumulative_loss
from grip.kinematics.baseline_train import BaselineTrainer, add_baseline_targets
from grip.kinematics.baselines import BaselineEstimator, export_baseline, insole_contact_prob
from grip.kinematics.dataset import sequence_arrays
from grip.kinematics.features import input_features, targets
from grip.nn.symmetry import rotate_batch
from grip.nn.weights import load_checkpoint
from prism_tools.synthetic import make_recording


def _tiny(method: str, **train):
    """Small nets and budgets for fast tests."""
    cfg = default_run_config(method)
    if method == "transpose":
        net = dataclasses.replace(cfg.net, s1_width=16, s2_width=12, s3_width=12, b1_width=8,
                                  b2_width=12, layers=1, b2_flight_windows_only=False)  # fmt: skip
    else:
        net = dataclasses.replace(cfg.net, width=16, contact_width=8, layers=1)
    cfg = dataclasses.replace(cfg, net=net)
    kw = {"window_frames": 40, "batch_size": 4, "steps_per_epoch": 3, "epochs": 2,
          "val_windows": 4} | train  # fmt: skip
    return replace_train(cfg, **kw)


def _seqs(cfg, lengths=(150, 120)):
    out = []
    for n in lengths:
        s = sequence_arrays(make_recording(n, seed=n), feature_config(cfg, True))
        add_baseline_targets(s, len(cfg.sites), cfg.train)
        out.append(s)
    return out


@pytest.fixture(autouse=True, scope="module")
def one_thread():
    """Tiny nets: one torch thread (on a busy 2-core machine two threads fight and a 16-wide
    LSTM step takes seconds instead of milliseconds)."""
    prev = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(prev)


@pytest.fixture(scope="module")
def rec():
    return make_recording(90, seed=7)


# ---------------------------------------------------------------------------- inputs, targets
def test_inputs_are_accelerations_then_orientations_then_insoles(rec):
    assert len(input_columns(4, False)) == 48 and len(input_columns(4, True)) == 58
    assert n_inputs(default_run_config("pip")) == 48
    cfg = default_run_config("transpose")
    x = input_features(rec, feature_config(cfg, True))
    sel = x[:, input_columns(4, True)]
    for i, site in enumerate(cfg.sites):
        acc = np.asarray(rec.imu[site].acc_world_filt) / 30.0
        np.testing.assert_allclose(sel[:, 3 * i : 3 * i + 3], acc, atol=1e-5)
        ori = sel[:, 12 + 9 * i : 21 + 9 * i].reshape(-1, 3, 3)
        np.testing.assert_allclose(ori @ ori.transpose(0, 2, 1), np.broadcast_to(np.eye(3),
                                   ori.shape), atol=1e-5)  # fmt: skip
    np.testing.assert_allclose(sel[:, 48:], x[:, 60:70])


def test_targets_root_frame_velocities_and_insole_contacts(rec):
    cfg = default_run_config("pip")
    s = sequence_arrays(rec, feature_config(cfg, True))
    add_baseline_targets(s, 4, cfg.train)
    t = targets(rec)
    pos = t.joint_pos + t.root_pos[:, None]
    world = np.einsum("tij,tkj->tki", t.global_rot[:, 0], s.y["jvel"].reshape(-1, 24, 3) * 3.0)
    np.testing.assert_allclose(world[1:], np.diff(pos, axis=0) * rec.fps, atol=2e-3)
    np.testing.assert_allclose(world[0], world[1], atol=1e-3)
    ins = np.stack([np.asarray(rec.insole[f].contacts).any(axis=1) for f in sk.FEET], axis=1)
    np.testing.assert_array_equal(s.y["contact"], ins)
    motion = replace_train(cfg, contact_labels="motion")
    add_baseline_targets(s, 4, motion.train)
    np.testing.assert_array_equal(s.y["contact"],
                                  contacts_from_motion(pos[:, [10, 11]], rec.fps))  # fmt: skip
    no_insole = sequence_arrays(rec, feature_config(cfg, False))
    with pytest.raises(ValueError, match="insole"):
        add_baseline_targets(no_insole, 4, cfg.train)


def test_yaw_augmentation_leaves_root_frame_targets_consistent():
    cfg = _tiny("pip")
    s = _seqs(cfg, (80,))[0]
    x = torch.from_numpy(s.x[None])
    y = {k: torch.from_numpy(v[None]) for k, v in s.y.items()}
    rot = torch.from_numpy(rot_z(np.array([1.1])).astype(np.float32))
    _, yr = rotate_batch(x, y, rot, 4)
    torch.testing.assert_close(yr["jvel"], y["jvel"])
    # root-frame velocity of each joint relative to the pelvis, from the rotated positions
    fp = yr["fp"][0].numpy().reshape(-1, 24, 3).astype(np.float64)
    r0 = sixd_to_matrix(yr["fa"][0].numpy().reshape(-1, 24, 6)[:, 0])
    rel = np.einsum("tji,tkj->tki", r0[1:], np.diff(fp, axis=0)) * s.fps / 3.0
    jv = s.y["jvel"].reshape(-1, 24, 3)
    np.testing.assert_allclose(rel, jv[1:] - jv[1:, :1], atol=2e-3)


def test_cumulative_loss_by_hand():
    pred = torch.full((2, 10, 1), 0.5)
    gt = torch.zeros(2, 10, 1)
    # blocks of 1, 3, 9 frames: mean over blocks of (n * 0.5)^2 = 0.25 + 2.25 + 20.25
    np.testing.assert_allclose(float(cumulative_loss(pred, gt, (1, 3, 9))), 22.75, rtol=1e-6)
    assert float(cumulative_loss(pred, gt, (27,))) == 0.0  # window shorter than the block
    pred[1] = 0.0
    w = torch.tensor([0.0, 1.0])
    assert float(cumulative_loss(pred, gt, (1, 3), w)) == 0.0  # only the exact window counts
    # errors that cancel within a block cost less than errors that accumulate
    alt = torch.tensor([1.0, -1.0] * 5).view(1, 10, 1)
    assert (
        float(cumulative_loss(alt, gt[:1], (2,)))
        == 0.0
        < float(cumulative_loss(alt.abs(), gt[:1], (2,)))
    )


# ---------------------------------------------------------------------------- nets
def test_output_shapes_and_directionality():
    torch.manual_seed(0)
    cfg = _tiny("transpose")
    tp = TransPoseNets(cfg.net, 48).eval()
    x = torch.randn(2, 30, 48)
    out = tp(x)
    shapes = {k: tuple(v.shape) for k, v in out.items()}
    assert shapes == {"lp": (2, 30, 15), "pall": (2, 30, 69), "fa": (2, 30, 144),
                      "contact": (2, 30, 2), "vel": (2, 30, 3)}  # fmt: skip
    x2 = x.clone()
    x2[:, 20] += 1.0
    out2 = tp(x2)
    for k in ("lp", "pall", "fa", "contact"):  # bidirectional: the past sees the future
        assert not torch.allclose(out[k][:, :20], out2[k][:, :20])
    # Trans-B2 is unidirectional, but reads S2's (bidirectional) output: only the net itself
    # is causal
    b2_in = torch.randn(1, 30, 69 + 48)
    b2_in2 = b2_in.clone()
    b2_in2[:, 20] += 1.0
    a, b = tp.nets["b2"](b2_in)[0], tp.nets["b2"](b2_in2)[0]
    torch.testing.assert_close(a[:, :20], b[:, :20])
    assert not torch.allclose(a[:, 20:], b[:, 20:])

    pip = PipNets(_tiny("pip").net, 48).eval()
    lp0, v0 = torch.randn(2, 15), torch.zeros(2, 72)
    p, _ = pip(x, lp0, v0)
    assert {k: tuple(v.shape) for k, v in p.items()} == {
        "lp": (2, 30, 15), "pall": (2, 30, 69), "fa": (2, 30, 144), "vel": (2, 30, 72),
        "contact": (2, 30, 2)}  # fmt: skip
    p2, _ = pip(x2, lp0, v0)
    for k in p:  # PIP is causal end to end
        torch.testing.assert_close(p[k][:, :20], p2[k][:, :20])
        assert not torch.allclose(p[k][:, 20:], p2[k][:, 20:])


def test_pip_streaming_equals_offline():
    torch.manual_seed(1)
    pip = PipNets(_tiny("pip").net, 48).eval()
    x, lp0, v0 = torch.randn(1, 25, 48), torch.randn(1, 15), torch.randn(1, 72)
    with torch.no_grad():
        full, _ = pip(x, lp0, v0)
        a, st = pip(x[:, :10], lp0, v0)
        b, _ = pip(x[:, 10:], lp0, v0, state=st)
    for k in full:
        torch.testing.assert_close(torch.cat([a[k], b[k]], 1), full[k], atol=1e-5, rtol=0)


def test_learned_init_changes_the_first_outputs():
    torch.manual_seed(2)
    cfg = _tiny("pip")
    pip = PipNets(cfg.net, 48).eval()
    x = torch.randn(1, 5, 48)
    lp_a, lp_b = torch.zeros(1, 15), torch.full((1, 15), 0.3)
    v0 = torch.zeros(1, 72)
    with torch.no_grad():
        a, _ = pip(x, lp_a, v0)
        b, _ = pip(x, lp_b, v0)
        c, _ = pip(x, lp_a, torch.full((1, 72), 0.5))
    assert (a["lp"][0, 0] - b["lp"][0, 0]).abs().max() > 1e-4  # P_L follows its init
    assert (a["vel"][0, 0] - c["vel"][0, 0]).abs().max() > 1e-4  # V_A follows its init
    torch.testing.assert_close(a["fa"], c["fa"])  # R_A has no learned init
    plain = PipNets(dataclasses.replace(cfg.net, learned_init=False), 48).eval()
    assert not any(n.startswith("nets.p_l.init") for n, _ in plain.named_parameters())
    with torch.no_grad():
        torch.testing.assert_close(plain(x, lp_a, v0)[0]["lp"], plain(x, lp_b, v0)[0]["lp"])


# ---------------------------------------------------------------------------- training
@pytest.mark.parametrize("method", ["transpose", "pip"])
def test_a_few_steps_lower_the_loss(method, tmp_path):
    cfg = _tiny(method, epochs=1, steps_per_epoch=25, lr=3e-3)
    seqs = _seqs(cfg)
    tr = BaselineTrainer(cfg, seqs, seqs, tmp_path)
    before = tr.validate()
    tr.fit()
    after = tr.history[-1]["val"]
    assert set(after) == {*tr.nets.NETS, "total", "chain_pos_mm"}
    # every net learns (measured over seeds 0-3: ratios 0.05-0.89)
    ratios = {k: after[k] / before[k] for k in tr.nets.NETS}
    assert all(r < 0.95 for r in ratios.values()), ratios


def test_checkpoints_resume_per_net_best_and_export(tmp_path):
    cfg = _tiny("transpose", contact_labels="motion")
    seqs = _seqs(cfg)
    tr = BaselineTrainer(cfg, seqs, seqs, tmp_path)
    hist = tr.fit()
    assert [h["epoch"] for h in hist] == [0, 1]
    ck = torch.load(tmp_path / "last.pt", map_location="cpu", weights_only=True)
    assert int(ck["epoch"]) == 2 and config_from_json(ck["config"], "x") == cfg
    assert (tmp_path / "best.pt").exists()
    # resume: same weights, epoch and history; training continues when epochs grow
    tr2 = BaselineTrainer(cfg, seqs, seqs, tmp_path)
    tr2.load(tmp_path / "last.pt")
    assert tr2.epoch == 2 and tr2.history == json_roundtrip(hist)
    for a, b in zip(tr.nets.parameters(), tr2.nets.parameters(), strict=True):
        torch.testing.assert_close(a, b)
    longer = replace_train(cfg, epochs=3)
    tr3 = BaselineTrainer(longer, seqs, seqs, tmp_path)
    tr3.load(tmp_path / "last.pt")
    assert [h["epoch"] for h in tr3.fit()] == [0, 1, 2]
    assert tr3.wall_s() > tr2.wall_s() == hist[-1]["wall_s"] > hist[0]["wall_s"] > 0
    with pytest.raises(ValueError, match="another configuration"):
        BaselineTrainer(replace_train(cfg, lr=0.5), seqs, seqs, tmp_path).load(tmp_path / "last.pt")
    with pytest.raises(ValueError, match="beyond"):
        BaselineTrainer(replace_train(cfg, epochs=1), seqs, seqs, tmp_path).load(
            tmp_path / "last.pt")  # fmt: skip
    with pytest.raises(ValueError, match="resumable"):
        tr3.load(tmp_path / "best.pt")
    # per-net best: a net whose validation got worse keeps its earlier weights
    snap = {k: v.clone() for k, v in tr3.nets.state_dict().items()}
    tr3.update_best({k: -1.0 for k in tr3.nets.NETS})
    with torch.no_grad():
        for p in tr3.nets.parameters():
            p.add_(1.0)
    tr3.update_best({"s1": 0.0, "s2": -2.0, "s3": -2.0, "b1": -2.0, "b2": -2.0})
    best = tr3.best_state()["model"]
    now = tr3.nets.state_dict()
    for k in best:
        ref = snap[k] if k.startswith("nets.s1.") else now[k]
        torch.testing.assert_close(best[k], ref)
    # export: fp16, no optimiser, loads and predicts like the original
    size = export_baseline(tmp_path / "last.pt", tmp_path / "small.pt")
    assert size < (tmp_path / "last.pt").stat().st_size / 3
    small = load_checkpoint(tmp_path / "small.pt")
    assert "optimizer" not in small and small["model"]["nets.s1.inp.weight"].dtype == torch.float16
    rec = make_recording(60, seed=4)
    full = BaselineEstimator.from_checkpoint(tmp_path / "last.pt").predict([rec])[0]
    half = BaselineEstimator.from_checkpoint(tmp_path / "small.pt").predict([rec])[0]
    np.testing.assert_allclose(half.joint_pos, full.joint_pos, atol=5e-3)
    # int8: smaller (about half on real nets; pickling overhead dominates this tiny one)
    size8 = export_baseline(tmp_path / "last.pt", tmp_path / "int8.pt", precision="int8")
    assert size8 < 0.9 * size
    q = BaselineEstimator.from_checkpoint(tmp_path / "int8.pt").predict([rec])[0]
    np.testing.assert_allclose(q.joint_pos, full.joint_pos, atol=2e-2)


def json_roundtrip(obj):
    import json

    return json.loads(json.dumps(obj))


# ---------------------------------------------------------------------------- inference
@pytest.fixture(scope="module")
def estimators(tmp_path_factory):
    out = {}
    for method in ("transpose", "pip"):
        cfg = _tiny(method, epochs=1, steps_per_epoch=2)
        cfg = dataclasses.replace(cfg, net=dataclasses.replace(cfg.net, insoles=True))
        run = tmp_path_factory.mktemp(method)
        BaselineTrainer(cfg, _seqs(cfg), _seqs(cfg, (100,)), run).fit()
        out[method] = BaselineEstimator.from_checkpoint(run / "best.pt")
    return out


def test_estimates_have_documented_shapes_and_frames(estimators, rec):
    tp = estimators["transpose"].predict([rec, make_recording(50, seed=8)])
    assert [e.global_rot.shape for e in tp] == [(90, 24, 3, 3), (50, 24, 3, 3)]
    e = tp[0]
    assert e.joint_pos.shape == (90, 24, 3) and np.all(e.joint_pos[:, 0] == 0)
    assert e.leaf_pos.shape == (90, 5, 3) and e.root_vel.shape == (90, 3) and e.joint_vel is None
    assert np.all((e.contact_prob > 0) & (e.contact_prob < 1))
    eye = np.broadcast_to(np.eye(3), e.global_rot.shape)
    np.testing.assert_allclose(e.global_rot @ e.global_rot.transpose(0, 1, 3, 2), eye, atol=1e-9)
    p = estimators["pip"].predict([rec])[0]
    assert p.joint_vel.shape == (90, 24, 3)
    np.testing.assert_allclose(p.root_vel, p.joint_vel[:, 0])
    # world velocities = estimated root rotation x root-frame output x 3
    est = estimators["pip"]
    x = torch.from_numpy(est.inputs(rec))[None]
    with torch.no_grad():
        raw = est.nets(x, *est.first_quantities(rec, False))[0]
    local = raw["vel"][0].double().numpy().reshape(-1, 24, 3) * 3.0
    world = np.einsum("tij,tkj->tki", p.global_rot[:, 0], local)
    np.testing.assert_allclose(p.joint_vel, world, atol=1e-9)
    walking = make_recording(220, seed=8).slice_frames(150, 220)  # starts mid-stride
    zero, gt_init = (est.predict([walking], gt_init_velocity=g)[0] for g in (False, True))
    assert np.abs(gt_init.joint_vel[0] - zero.joint_vel[0]).max() > 1e-6
    ins = est.predict([rec], insole_contact=True)[0]
    assert set(np.unique(ins.contact_prob)) <= {0.0, 1.0}
    np.testing.assert_array_equal(ins.contact_prob > 0.5, insole_contact_prob(rec) > 0.5)
    np.testing.assert_allclose(ins.global_rot, p.global_rot)
    np.testing.assert_array_equal(insole_contact_prob(rec), np.stack(
        [np.asarray(rec.insole[f].contacts).any(axis=1) for f in sk.FEET], axis=1))  # fmt: skip


def test_transpose_online_window_limits_the_lookahead(estimators):
    est = estimators["transpose"]
    fut = est.cfg.net.online_future_frames
    rec = make_recording(80, seed=9)
    x = torch.from_numpy(est.inputs(rec))[None]
    x2 = x.clone()
    x2[:, 60] += 2.0
    with torch.no_grad():
        on, on2 = est.run_online(x), est.run_online(x2)
        off, off2 = est.nets(x), est.nets(x2)
    k = 60 - fut
    for key in ("lp", "pall", "fa", "contact", "vel"):
        torch.testing.assert_close(on[key][:, :k], on2[key][:, :k])
        assert not torch.allclose(on[key][:, k:61], on2[key][:, k:61])
    assert not torch.allclose(off["fa"][:, :k], off2["fa"][:, :k])
    online = est.predict([rec], online=True)[0]
    assert online.global_rot.shape == (80, 24, 3, 3)


def test_bad_configs_and_checkpoints_are_clear_errors(tmp_path, rec):
    with pytest.raises(ValueError, match="transpose, pip"):
        default_run_config("dip")
    with pytest.raises(ValueError, match="contact_labels"):
        replace_train(default_run_config("pip"), contact_labels="force")
    with pytest.raises(ValueError, match="init_leaf_frame"):
        dataclasses.replace(default_run_config("pip").net, init_leaf_frame="pelvis")
    with pytest.raises(ValueError, match="not a TransPose/PIP"):
        config_from_json('{"hidden": 3}', "kin.pt")
    with pytest.raises(ValueError, match="unknown key"):
        config_from_json('{"method": "pip", "net": {"widht": 3}}', "x.pt")
    bad = tmp_path / "broken.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match=r"broken\.pt"):
        BaselineEstimator.from_checkpoint(bad)
    cfg = _tiny("pip")
    s = sequence_arrays(rec, feature_config(cfg, True))
    with pytest.raises(ValueError, match="load_baseline_sequences"):
        BaselineTrainer(cfg, [s], [s], tmp_path)
    # "+I" needs the insole columns in the training features
    imu_only = replace_train(cfg, contact_labels="motion")
    s = sequence_arrays(rec, feature_config(imu_only, False))
    add_baseline_targets(s, 4, imu_only.train)
    plus_i = dataclasses.replace(imu_only, net=dataclasses.replace(imu_only.net, insoles=True))
    with pytest.raises(ValueError, match="insole"):
        BaselineTrainer(plus_i, [s], [s], tmp_path)
