import dataclasses
import itertools
import json
from pathlib import Path

import numpy as np
import pytest
import torch

from grip.core.body import build_body
from grip.kinematics.config import KinematicsRunConfig, TrainConfig
from grip.kinematics.dataset import sequence_arrays
from grip.kinematics.features import FeatureConfig, targets
from grip.kinematics.model import STAGE_DIMS
from grip.kinematics.train import Trainer, fk_positions
from grip.nn.symmetry import rotate_batch, yaw_matrices
from grip.nn.weights import load_checkpoint
from prism_tools.synthetic import make_recording


@pytest.fixture(scope="module")
def seqs():
    return [sequence_arrays(make_recording(n, seed=n), FeatureConfig()) for n in (150, 120)]


def _cfg(**kw):
    kw = {"window_frames": 40, "batch_size": 4, "steps_per_epoch": 3, "stage_epochs": 1,
          "joint_epochs": 1, "val_windows": 4} | kw  # fmt: skip
    train = TrainConfig(**kw)
    return KinematicsRunConfig(hidden=16, layers=1, init_hidden=8, train=train)


def test_fk_positions_match_the_targets():
    rec = make_recording(30, seed=2)
    t = targets(rec)
    from grip.kinematics.features import recording_body

    offs = torch.from_numpy(build_body(recording_body(rec)).offsets[None].astype(np.float32))
    pos = fk_positions(torch.from_numpy(t.rot6d.reshape(1, 30, 144).astype(np.float32)), offs)
    np.testing.assert_allclose(pos[0].numpy(), t.joint_pos.reshape(30, 72), atol=1e-4)


def test_yaw_rotation_keeps_features_and_targets_consistent(seqs):
    s = seqs[0]
    rot = yaw_matrices(torch.tensor([0.7]))
    x = torch.from_numpy(s.x[None])
    y = {k: torch.from_numpy(v[None]) for k, v in s.y.items()}
    xr, yr = rotate_batch(x, y, rot, 4)
    # Insoles untouched, orientation rotated, FK of rotated rotations = rotated positions.
    torch.testing.assert_close(xr[..., 60:], x[..., 60:])
    ori = x[0, :, 6:15].reshape(-1, 3, 3)
    torch.testing.assert_close(xr[0, :, 6:15].reshape(-1, 3, 3), rot[0] @ ori)
    offs = torch.from_numpy(s.offsets[None])
    torch.testing.assert_close(fk_positions(yr["fa"], offs), yr["fp"], atol=1e-4, rtol=0)


def test_training_runs_checkpoints_and_resumes(seqs, tmp_path):
    cfg = _cfg()
    tr = Trainer(cfg, seqs, seqs, tmp_path)
    hist = tr.fit()
    assert len(hist) == cfg.total_epochs() == 5
    assert [h["phase"] for h in hist] == ["lp", "fp", "fa", "lv", "joint"]
    ck = load_checkpoint(tmp_path / "last.pt")
    assert int(ck["epoch"]) == 5 and (tmp_path / "best.pt").exists()
    # Resume: a new trainer continues from epoch 5 with the same weights.
    tr2 = Trainer(cfg, seqs, seqs, tmp_path)
    tr2.load(tmp_path / "last.pt")
    assert tr2.epoch == 5
    for a, b in zip(tr.model.parameters(), tr2.model.parameters(), strict=True):
        torch.testing.assert_close(a, b)
    with pytest.raises(ValueError, match="another configuration"):
        Trainer(_cfg(lr=0.5), seqs, seqs, tmp_path).load(tmp_path / "last.pt")
    # A longer last phase resumes and trains only the extra epoch.
    tr3 = Trainer(_cfg(joint_epochs=2), seqs, seqs, tmp_path)
    tr3.load(tmp_path / "last.pt")
    assert [h["phase"] for h in tr3.fit()][-2:] == ["joint", "joint"] and tr3.epoch == 6
    walls = [h["wall_s"] for h in tr3.history]  # training time adds up across sittings
    assert all(b > a > 0 for a, b in itertools.pairwise(walls))
    assert tr3.wall_s() == walls[-1] > tr.wall_s() == walls[-2]
    with pytest.raises(ValueError, match="beyond"):
        Trainer(_cfg(joint_epochs=0), seqs, seqs, tmp_path).load(tmp_path / "last.pt")


@pytest.mark.parametrize("bf16", [False, True])
def test_training_lowers_the_validation_loss(seqs, tmp_path, bf16):
    cfg = _cfg(bf16=bf16)
    tr = Trainer(cfg, seqs, seqs, tmp_path)
    before = tr.validate()["total"]
    tr.fit()
    assert tr.validate()["total"] < before
    assert all(p.dtype == torch.float32 for p in tr.model.parameters())  # weights stay fp32


def test_bf16_losses_are_float32_and_close_to_the_float32_pass(seqs, tmp_path):
    tr = Trainer(_cfg(), seqs, seqs, tmp_path / "a")
    half = Trainer(_cfg(bf16=True), seqs, seqs, tmp_path / "b")
    half.model.load_state_dict(tr.model.state_dict())
    x, y = tr._tensors(*tr.val_batch, augment=False)
    full, low = tr.losses(x, y), half.losses(x, y)
    for k, v in full.items():
        assert low[k].dtype == torch.float32
        assert abs(low[k].item() - v.item()) <= 0.05 * v.item() + 1e-6, k  # bfloat16 rounding
    assert any(low[k].item() != v.item() for k, v in full.items())  # autocast did act


class _Hostile:
    """Unpickling this runs ``Path.touch`` on its marker: a stand-in for a malicious payload."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (Path.touch, (self.marker,))


def test_corrupt_and_hostile_checkpoints_are_clean_errors(tmp_path):
    bad = tmp_path / "x.pt"
    bad.write_bytes(b"not a checkpoint")
    with pytest.raises(ValueError, match=r"x\.pt: not a KinematicsNet checkpoint: corrupt") as e:
        load_checkpoint(bad)
    assert "weights_only" not in str(e.value)  # none of torch's advice to load unsafely
    marker, hostile = tmp_path / "ran", tmp_path / "h.pt"
    torch.save({"version": 1, "model": _Hostile(marker)}, hostile)
    with pytest.raises(ValueError, match=r"h\.pt: .*pickled Python objects, refused"):
        load_checkpoint(hostile)
    assert not marker.exists()
    torch.load(hostile, weights_only=False)  # the payload is live: an unsafe load runs it
    assert marker.exists()


def test_pack_weights_round_trip():
    from grip.nn.weights import pack_weights, unpack_weights

    g = torch.Generator().manual_seed(0)
    state = {"w": torch.randn(64, 128, generator=g), "b": torch.randn(64, generator=g),
             "small": torch.randn(4, 4, generator=g), "zero": torch.zeros(64, 64),
             "steps": torch.tensor(7)}  # fmt: skip
    for precision in ("fp32", "fp16", "int8"):
        back = unpack_weights(pack_weights(state, precision))
        assert set(back) == set(state) and int(back["steps"]) == 7
        for k in ("w", "b", "small", "zero"):
            v = state[k]
            if precision == "fp32":
                bound = torch.zeros(())
            elif precision == "int8" and k in ("w", "zero"):  # half a step of the row's scale
                bound = v.abs().amax(dim=1, keepdim=True) / 254 + 1e-7
            else:  # fp16: 11 significant bits
                bound = v.abs() * 2**-11 + 1e-7
            assert torch.all((back[k] - v).abs() <= bound), (precision, k)
    packed = pack_weights(state, "int8")
    assert packed["w"].dtype == torch.int8 and packed["w@scale"].shape == (64, 1)
    assert packed["small"].dtype == torch.float16  # small matrices stay fp16
    with pytest.raises(ValueError, match="precision"):
        pack_weights(state, "int4")


def test_cosine_schedule_decays_over_the_joint_phase_only(seqs, tmp_path):
    tr = Trainer(_cfg(stage_epochs=1, joint_epochs=2, steps_per_epoch=10, lr=1e-3,
                      lr_final=1e-5), seqs, seqs, tmp_path)  # fmt: skip
    assert tr.learning_rate(0, 5) == tr.learning_rate(3, 9) == 1e-3  # stage-wise: constant
    assert tr.learning_rate(4, 0) == pytest.approx(1e-3)  # joint phase starts at lr
    assert tr.learning_rate(5, 0) == pytest.approx(0.5 * (1e-3 + 1e-5))  # halfway
    assert tr.learning_rate(5, 9) == pytest.approx(
        1e-5 + 0.5 * (1e-3 - 1e-5) * (1 + np.cos(0.95 * np.pi))
    )
    rates = [tr.learning_rate(e, s) for e in (4, 5) for s in range(10)]
    assert all(a > b for a, b in itertools.pairwise(rates))
    const = Trainer(_cfg(lr=2e-3), seqs, seqs, tmp_path)
    assert {const.learning_rate(e, 0) for e in range(5)} == {2e-3}
    tr.fit()
    assert tr.opt.param_groups[0]["lr"] == pytest.approx(tr.learning_rate(5, 9))  # last step
    assert type(tr.opt.param_groups[0]["lr"]) is float  # a numpy scalar breaks weights_only
    Trainer(_cfg(stage_epochs=1, joint_epochs=2, steps_per_epoch=10, lr=1e-3, lr_final=1e-5),
            seqs, seqs, tmp_path).load(tmp_path / "last.pt")  # fmt: skip


def test_init_from_copies_weights_and_normaliser_and_checks_the_network(seqs, tmp_path):
    src = Trainer(_cfg(), seqs, seqs, tmp_path / "a")
    src.fit()
    from grip.kinematics.train import export_for_inference

    export_for_inference(tmp_path / "a" / "last.pt", tmp_path / "a.pt", precision="fp16")
    for path, tol in ((tmp_path / "a" / "last.pt", 0.0), (tmp_path / "a.pt", 1e-2)):
        dst = Trainer(_cfg(lr_final=1e-5, joint_epochs=3, stage_epochs=0), seqs[:1], seqs,
                      tmp_path / "b")  # fmt: skip
        dst.init_from(path)
        for (k, v), w in zip(src.model.state_dict().items(), dst.model.state_dict().values(),
                             strict=True):  # fmt: skip
            torch.testing.assert_close(w, v, atol=tol, rtol=tol, msg=k)
        np.testing.assert_array_equal(dst.norm.mean, src.norm.mean)
        assert dst.epoch == 0
    other = Trainer(dataclasses.replace(_cfg(), hidden=12), seqs, seqs, tmp_path / "c")
    with pytest.raises(ValueError, match="network or sensor settings differ"):
        other.init_from(tmp_path / "a" / "last.pt")


def test_runs_begun_before_new_train_fields_still_resume(seqs, tmp_path):
    tr = Trainer(_cfg(), seqs, seqs, tmp_path)
    tr.fit()
    ck = torch.load(tmp_path / "last.pt", weights_only=True)
    cfg = json.loads(ck["config"])
    for k in ("mirror_augment", "lr_final", "weight_decay"):
        cfg["train"].pop(k)  # as a checkpoint written before these settings existed
    cfg.pop("dropout")
    ck["config"] = json.dumps(cfg)
    torch.save(ck, tmp_path / "old.pt")
    Trainer(_cfg(), seqs, seqs, tmp_path).load(tmp_path / "old.pt")
    with pytest.raises(ValueError, match="another configuration"):
        Trainer(_cfg(mirror_augment=True), seqs, seqs, tmp_path).load(tmp_path / "old.pt")
    with pytest.raises(ValueError, match="dropout"):
        Trainer(dataclasses.replace(_cfg(), dropout=0.3), seqs, seqs, tmp_path).load(
            tmp_path / "old.pt")


def test_dropout_acts_in_training_only_and_weight_decay_selects_adamw(seqs, tmp_path):
    cfg = dataclasses.replace(_cfg(weight_decay=0.01), dropout=0.5)
    tr = Trainer(cfg, seqs, seqs, tmp_path / "a")
    assert isinstance(tr.opt, torch.optim.AdamW)
    assert tr.opt.param_groups[0]["weight_decay"] == 0.01
    assert isinstance(Trainer(_cfg(), seqs, seqs, tmp_path / "b").opt, torch.optim.Adam)
    x = torch.randn(2, 10, cfg.features.n_features)
    st = tr.model.initial_state({s: torch.zeros(2, d) for s, d in STAGE_DIMS.items()})

    def fp():
        return tr.model(x, st)[0]["fp"]

    tr.model.train()
    assert not torch.allclose(fp(), fp())  # two dropout draws
    tr.model.eval()
    torch.testing.assert_close(fp(), fp())
    tr.fit()
    # a model trained with dropout fine-tunes one without, and the reverse (same weights)
    dst = Trainer(_cfg(), seqs, seqs, tmp_path / "c")
    dst.init_from(tmp_path / "a" / "last.pt")
    torch.testing.assert_close(dst.model.state_dict()["stages.fp.head.weight"],
                               tr.model.state_dict()["stages.fp.head.weight"])  # fmt: skip
    dst.save(tmp_path / "plain.pt")
    back = Trainer(cfg, seqs, seqs, tmp_path / "d")
    back.init_from(tmp_path / "plain.pt")
    torch.testing.assert_close(back.model.state_dict()["stages.fp.head.weight"],
                               tr.model.state_dict()["stages.fp.head.weight"])  # fmt: skip


def test_stored_configs_with_removed_settings():
    from dataclasses import asdict

    from grip.config import ConfigError, drop_removed
    from grip.kinematics.config import (
        REMOVED_IN,
        REMOVED_SETTINGS,
        KinematicsRunConfig,
        run_config_from_dict,
    )

    d = asdict(KinematicsRunConfig())
    off = {**d, "train": {**d["train"], "time_warp": 0.0,
                          "reverse_categories": []}}  # fmt: skip
    assert run_config_from_dict(off) == KinematicsRunConfig()
    on = {**d, "train": {**d["train"], "time_warp": 0.2}}
    assert run_config_from_dict(on) == KinematicsRunConfig()  # to run it: trained as it was
    with pytest.raises(ConfigError, match=f"time_warp = 0.2 turns on time-warp.*{REMOVED_IN}"):
        drop_removed(on, REMOVED_SETTINGS, "ck.pt")  # a resume could not go on as it began
    # hypothesis 5's runs (docs/kinematics_person.md) recorded speed_augment = 0.25
    sped = {**d, "train": {**d["train"], "speed_augment": 0.25}}
    assert run_config_from_dict(sped) == KinematicsRunConfig()
    with pytest.raises(ConfigError, match=r"speed_augment = 0\.25 turns on speed augmentation"):
        drop_removed(sped, REMOVED_SETTINGS, "ck.pt")
    with pytest.raises(TypeError, match="no_such_knob"):
        run_config_from_dict({**d, "train": {**d["train"], "no_such_knob": 1}})


def test_standing_starts_equal_the_standing_calibration_of_a_recording():
    """A window started from the standing pose gets the states a recording without ground truth
    starts from (first_state of standing_calibration, heading from its foot IMUs)."""
    from grip.kinematics.features import (
        first_state,
        input_features,
        recording_body,
        standing_calibration,  # fmt: skip
    )
    from grip.kinematics.train import heading_of_feet, standing_first

    cfg = FeatureConfig()
    for seed in (3, 4):
        rec = make_recording(20, seed=seed)
        want = first_state(standing_calibration(rec, cfg), recording_body(rec), rec.fps)
        x = torch.from_numpy(input_features(rec, cfg)[None])
        offs = torch.from_numpy(build_body(recording_body(rec)).offsets[None].astype(np.float32))
        got = standing_first(heading_of_feet(x, cfg.sites), offs)
        assert set(got) == set(want)
        for k, v in want.items():
            np.testing.assert_allclose(got[k][0].numpy(), v, atol=1e-5, err_msg=k)


def test_standing_init_share_of_windows_start_from_standing(seqs, tmp_path):
    cfg = _cfg(standing_init=0.5, batch_size=64)
    tr = Trainer(cfg, seqs, seqs, tmp_path / "run")
    x, y = sample_windows_for_test(tr, seqs, 64)
    _, yt = tr._tensors(x, y, augment=True)
    truth = torch.all(yt["first/fp"] == yt["fp"][:, 0], dim=1)
    assert 16 < int((~truth).sum()) < 48  # about half start standing, at rest
    assert torch.all(yt["first/lv"][~truth] == 0)
    torch.testing.assert_close(yt["first/fa"][truth], yt["fa"][truth, 0])
    # the validation pass starts from the truth
    _, yv = tr._tensors(x, y, augment=False)
    assert "first/fp" not in yv
    with pytest.raises(ValueError, match="standing_init"):
        TrainConfig(standing_init=1.5)


def sample_windows_for_test(tr, seqs, n):
    from grip.kinematics.dataset import sample_windows

    return sample_windows(seqs, n, tr.cfg.train.window_frames, np.random.default_rng(0))
