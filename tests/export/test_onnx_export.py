"""ONNX exports: a policy file (one member, the shipped ensemble) and KinematicsNet's streaming
step, run with onnxruntime against the torch controllers and the streaming estimator; their
metadata, the commands and their refusals."""

from __future__ import annotations

import json
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import torch

from grip.assets import SAMPLE_RECORDING, SHIPPED_BASELINES, SHIPPED_KIN, SHIPPED_POLICY
from grip.cli.main import main

ort = pytest.importorskip("onnxruntime", reason="onnxruntime is not installed (pip install "
                          "onnx onnxruntime, or pip install -e '.[dev]')")  # fmt: skip
pytest.importorskip("onnx", reason="onnx is not installed (pip install onnx onnxruntime)")

from grip.kinematics.config import KinematicsRunConfig  # noqa: E402
from grip.kinematics.features import (  # noqa: E402
    first_state,
    input_features,
    recording_body,
    recording_calibration,
)
from grip.kinematics.inference import KinematicsEstimator  # noqa: E402
from grip.kinematics.model import STAGES, KinematicsNet  # noqa: E402
from grip.kinematics.onnx import N_OUT, export_kinematics_onnx, init_path  # noqa: E402
from grip.nn.onnx import read_metadata  # noqa: E402
from grip.nn.weights import CHECKPOINT_VERSION, save_checkpoint  # noqa: E402
from grip.task.observations import kinematic_dim  # noqa: E402
from policies.controller import combine, load_controller  # noqa: E402
from policies.onnx import export_policy_onnx  # noqa: E402
from prism_tools.io import load_recording  # noqa: E402

ATOL = 1e-4


def _session(path: Path):
    opts = ort.SessionOptions()
    opts.intra_op_num_threads = opts.inter_op_num_threads = 1
    return ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])


def _flat(ctrl, obs: dict) -> np.ndarray:
    """Observation dicts -> the ONNX input: parts in ``obs_keys`` order, side by side."""
    return np.concatenate([np.asarray(obs[k], np.float64).reshape(len(obs[k]), -1)
                           for k in ctrl.obs_keys], axis=-1)  # fmt: skip


def _split(ctrl, x: np.ndarray) -> dict:
    members = getattr(ctrl, "members", [ctrl])
    out, i = {}, 0
    for k in ctrl.obs_keys:
        n = np.asarray(members[0].obs_mean[k]).size
        out[k] = x[:, i : i + n]
        i += n
    return out


def _random_obs(ctrl, n: int, seed: int) -> np.ndarray:
    """Observations around the first member's normaliser, some far out (clipped inside)."""
    m = getattr(ctrl, "members", [ctrl])[0]
    rng = np.random.default_rng(seed)
    scale = np.where(rng.random((n, 1)) < 0.25, 20.0, 1.5)
    return m._mean + m._std * scale * rng.standard_normal((n, m._mean.size))


@pytest.fixture(scope="module")
def sample_obs() -> list[dict]:
    """Real observations: what the shipped ensemble sees over the first 0.4 s of the sample
    walk, streamed through KinematicsNet and the simulated humanoid."""
    from grip.eval.stream import GripStream
    from grip.kinematics.features import sensor_frames

    rec = load_recording(SAMPLE_RECORDING)
    est = KinematicsEstimator.from_checkpoint(SHIPPED_KIN)
    ctrl = load_controller(SHIPPED_POLICY)
    seen: list[dict] = []

    class Recorder:
        def __getattr__(self, name):
            return getattr(ctrl, name)

        def act(self, obs):
            seen.append({k: np.array(v) for k, v in obs.items()})
            return ctrl.act(obs)

    stream = GripStream(Recorder(), est, rec)
    for i, frame in enumerate(sensor_frames(rec, est.cfg.features)):
        stream.push(frame, index=i)
        if i == 40:
            break
    assert len(seen) >= 10
    return seen


# ------------------------------------------------------------------------------------ policy
def test_one_policy_matches_the_runner(tmp_path, ensemble_policy) -> None:
    one = tmp_path / "one.pt"
    combine([ensemble_policy], one, member=2, precision="fp32")
    runner = load_controller(one)
    size, n = export_policy_onnx(one, tmp_path / "one.onnx")
    assert n == 1 and size == (tmp_path / "one.onnx").stat().st_size
    x = _random_obs(runner, 64, seed=0)
    got = _session(tmp_path / "one.onnx").run(["action"], {"obs": x.astype(np.float32)})[0]
    want = runner.act(_split(runner, x))
    assert got.shape == want.shape == (64, 69)
    np.testing.assert_allclose(got, want, atol=ATOL)
    assert np.abs(got).max() <= 1.0 and (np.abs(got) == 1.0).any()  # clipped, and it bites


def test_the_ensemble_averages_its_members_each_with_its_own_normaliser(
        tmp_path, sample_obs, ensemble_policy) -> None:  # fmt: skip
    ens = load_controller(ensemble_policy)
    assert len(ens.members) >= 3
    assert np.abs(ens.members[0]._mean - ens.members[1]._mean).max() > 1e-3  # (they differ)
    out = tmp_path / "ens.onnx"
    assert export_policy_onnx(ensemble_policy, out)[1] == len(ens.members)
    sess = _session(out)
    x = _random_obs(ens, 32, seed=1)
    got = sess.run(None, {"obs": x.astype(np.float32)})[0]
    np.testing.assert_allclose(got, ens.act(_split(ens, x)), atol=ATOL)
    # one member's normaliser for all would be another action
    first_only = np.mean([np.clip(m.actor(torch.from_numpy(np.clip(
        (x - ens.members[0]._mean) / ens.members[0]._std, -10, 10)).float()).detach().numpy(),
        -1, 1) for m in ens.members], axis=0)  # fmt: skip
    assert np.abs(first_only - got).max() > 10 * ATOL
    # the real observations of a streamed walk, one at a time as deployed and as a batch
    real = np.stack([_flat(ens, {k: v[None] for k, v in o.items()})[0] for o in sample_obs])
    want = np.stack([ens.act(o) for o in sample_obs])
    for i in (0, len(real) - 1):
        np.testing.assert_allclose(sess.run(None, {"obs": real[i : i + 1].astype(np.float32)})[0],
                                   want[i : i + 1], atol=ATOL)  # fmt: skip
    np.testing.assert_allclose(sess.run(None, {"obs": real.astype(np.float32)})[0], want,
                               atol=ATOL)  # fmt: skip


def test_policy_metadata_documents_the_input_and_output(tmp_path, ensemble_policy) -> None:
    ens = load_controller(ensemble_policy)
    out = tmp_path / "p.onnx"
    export_policy_onnx(ensemble_policy, out)
    meta = read_metadata(out)
    assert meta["format"] == "grip-policy-onnx" and meta["members"] == str(len(ens.members))
    keys = json.loads(meta["obs_keys"])
    sizes, slices = json.loads(meta["obs_sizes"]), json.loads(meta["obs_slices"])
    assert keys == ens.obs_keys == list(sizes) == list(slices)
    stop = 0
    for k in keys:
        assert slices[k] == [stop, stop + sizes[k]]
        stop += sizes[k]
    width = ens.members[0]._mean.size
    assert stop == width and sizes["kinematic"] == kinematic_dim(ens.env_cfg.kinematic_obs)
    assert len(json.loads(meta["action_names"])) == 69
    assert json.loads(meta["env_config"]) == json.loads(json.dumps(asdict(ens.env_cfg)))
    sess = _session(out)
    assert [(i.name, i.shape[1]) for i in sess.get_inputs()] == [("obs", width)]
    assert [(o.name, o.shape[1]) for o in sess.get_outputs()] == [("action", 69)]


def test_grip_policy_export_to_onnx_and_its_refusals(tmp_path, capsys, monkeypatch,
                                                     ensemble_policy) -> None:  # fmt: skip
    out = tmp_path / "p.onnx"
    assert main(["policy", "export", str(ensemble_policy), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    ens = load_controller(ensemble_policy)
    assert "p.onnx" in printed and f"ensemble of {len(ens.members)}" in printed
    assert f"({ens.members[0]._mean.size},)" in printed
    assert read_metadata(out)["source"] == str(ensemble_policy)
    for argv, why in [
        ([str(SHIPPED_POLICY), "--out", str(tmp_path / "x.onnx"), "--precision", "int8"],
         "fp32"),
        ([str(SHIPPED_POLICY), "--out", str(tmp_path / "x.pt")], "already the inference file"),
        ([str(tmp_path / "nothing"), "--out", str(tmp_path / "x.onnx")], "no such run folder"),
    ]:  # fmt: skip
        assert main(["policy", "export", *argv]) == 2
        assert why in capsys.readouterr().err
    assert not (tmp_path / "x.onnx").exists() and not (tmp_path / "x.pt").exists()
    monkeypatch.setitem(sys.modules, "onnx", None)  # as if not installed
    assert main(["policy", "export", str(SHIPPED_POLICY), "--out", str(tmp_path / "y.onnx")]) == 2
    assert "pip install onnx" in capsys.readouterr().err


def test_a_run_folder_goes_through_its_fp32_policy_file(tmp_path, capsys, monkeypatch,
                                                        ensemble_policy) -> None:  # fmt: skip
    """``grip policy export RUN --out F.onnx``: the run's policy file at fp32 (made here from
    the shipped file's member 0 instead of a training run), then its graph."""
    import policies.runner

    run = tmp_path / "run"
    (run / "checkpoint").mkdir(parents=True)
    (run / "checkpoint" / "state.json").write_text(json.dumps(
        {"history": [{"timesteps": 64}], "wall_s": 1.0}))  # fmt: skip
    calls = []

    def fake_export(run_dir, out, half=True, info=None, precision=None):
        calls.append((Path(run_dir), precision, info))
        return combine([ensemble_policy], out, member=0)[0]

    monkeypatch.setattr(policies.runner, "export_policy", fake_export)
    out = tmp_path / "run.onnx"
    assert main(["policy", "export", str(run), "--out", str(out)]) == 0
    assert calls == [(run, "fp32", {"timesteps": 64, "wall_s": 1.0})]
    assert "ONNX of one policy" in capsys.readouterr().out
    assert read_metadata(out)["source"] == str(run) and read_metadata(out)["members"] == "1"
    member0 = load_controller(ensemble_policy).members[0]
    x = _random_obs(member0, 8, seed=2)
    np.testing.assert_allclose(_session(out).run(None, {"obs": x.astype(np.float32)})[0],
                               member0.act(_split(member0, x)), atol=ATOL)  # fmt: skip


# ------------------------------------------------------------------------------ KinematicsNet
def _run_onnx(step, start, first_rows: np.ndarray, feats: np.ndarray) -> np.ndarray:
    """The two graphs over ``feats (B, T, F)`` from ``first_rows (B, 249)`` -> ``(B, T, 249)``."""
    h, c = start.run(None, {"first_state": first_rows.astype(np.float32)})
    outs = []
    for t in range(feats.shape[1]):
        o, h, c = step.run(None, {"features": feats[:, t].astype(np.float32), "h": h, "c": c})
        outs.append(o)
    return np.stack(outs, axis=1)


def _run_stream(est: KinematicsEstimator, first: dict, feats: np.ndarray) -> np.ndarray:
    """The estimator's streaming path over ``feats (T, F)`` -> ``(T, 249)``."""
    s = est.stream_from(first)
    return np.stack([np.concatenate([r[k] for k in STAGES]) for r in map(s.step, feats)])


@pytest.fixture(scope="module")
def tiny_ckpt(tmp_path_factory) -> Path:
    """An untrained KinematicsNet (hidden 16, 3 layers) with a non-trivial normaliser."""
    torch.manual_seed(0)
    cfg = KinematicsRunConfig(hidden=16, layers=3, init_hidden=8)
    net = KinematicsNet(cfg.net_config())
    n = cfg.features.n_features
    rng = np.random.default_rng(3)
    path = tmp_path_factory.mktemp("kin") / "tiny.pt"
    save_checkpoint(path, {
        "version": CHECKPOINT_VERSION, "config": json.dumps(asdict(cfg)),
        "model": net.state_dict(),
        "norm_mean": torch.from_numpy(rng.normal(size=n).astype(np.float32)),
        "norm_std": torch.from_numpy(rng.uniform(0.2, 3.0, size=n).astype(np.float32)),
    })  # fmt: skip
    return path


def test_kinematics_step_matches_the_streaming_estimator(tiny_ckpt, tmp_path) -> None:
    """Random features, three sequences side by side (a batch): every frame's outputs, and the
    start graph's states equal the network's learned initial states."""
    est = KinematicsEstimator.from_checkpoint(tiny_ckpt)
    (step_path, _), (start_path, _) = export_kinematics_onnx(tiny_ckpt, tmp_path / "k.onnx")
    assert start_path == tmp_path / "k_init.onnx" == init_path(step_path)
    step, start = _session(step_path), _session(start_path)
    rng = np.random.default_rng(4)
    n_f = est.cfg.features.n_features
    feats = rng.normal(size=(3, 25, n_f)) * est.norm.std + est.norm.mean
    firsts = [{k: rng.normal(size=d).astype(np.float32) for k, d in
               zip(STAGES, (15, 72, 144, 18), strict=True)} for _ in range(3)]  # fmt: skip
    rows = np.stack([np.concatenate([f[k] for k in STAGES]) for f in firsts])
    h, c = start.run(None, {"first_state": rows.astype(np.float32)})
    with torch.no_grad():
        want = est.model.initial_state({k: torch.from_numpy(np.stack([f[k] for f in firsts]))
                                        for k in STAGES})  # fmt: skip
    np.testing.assert_allclose(h, torch.cat([want[k][0] for k in STAGES]).numpy(), atol=1e-6)
    np.testing.assert_allclose(c, torch.cat([want[k][1] for k in STAGES]).numpy(), atol=1e-6)
    got = _run_onnx(step, start, rows, feats)
    for b in range(3):
        np.testing.assert_allclose(got[b], _run_stream(est, firsts[b], feats[b]), atol=ATOL)
    # the graph normalises: feeding it normalised features gives something else
    other = _run_onnx(step, start, rows[:1], (feats[:1] - est.norm.mean) / est.norm.std)
    assert np.abs(other[0] - got[0]).max() > 100 * ATOL


def test_shipped_kinematics_on_the_sample_walk(tmp_path) -> None:
    """The shipped checkpoint on real features, from the recording's calibration pose."""
    est = KinematicsEstimator.from_checkpoint(SHIPPED_KIN)
    rec = load_recording(SAMPLE_RECORDING)
    feats = input_features(rec, est.cfg.features)[:40]
    first = first_state(recording_calibration(rec, est.cfg.features), recording_body(rec),
                        rec.fps)
    (step_path, _), (start_path, _) = export_kinematics_onnx(SHIPPED_KIN, tmp_path / "k.onnx")
    got = _run_onnx(_session(step_path), _session(start_path),
                    np.concatenate([first[k] for k in STAGES])[None], feats[None])[0]
    np.testing.assert_allclose(got, _run_stream(est, first, feats), atol=ATOL)
    meta = read_metadata(step_path)
    assert meta["graph"] == "step" and read_metadata(start_path)["graph"] == "init"
    assert meta["format"] == "grip-kinematics-onnx" and meta["normalised_inside"] == "true"
    assert int(meta["n_features"]) == feats.shape[1] == 70
    assert json.loads(meta["output_slices"]) == {"lp": [0, 15], "fp": [15, 87], "fa": [87, 231],
                                                 "lv": [231, N_OUT]}  # fmt: skip
    assert json.loads(meta["feature_config"])["sites"] == list(est.cfg.features.sites)
    rows = 4 * est.model.cfg.layers
    shapes = {i.name: i.shape for i in _session(step_path).get_inputs()}
    assert shapes["features"][1] == 70 and shapes["h"][0] == shapes["c"][0] == rows
    assert shapes["h"][2] == est.model.cfg.hidden


def test_grip_kin_export_to_onnx_and_its_refusals(tiny_ckpt, tmp_path, capsys) -> None:
    out = tmp_path / "kin.onnx"
    assert main(["kin", "export", str(tiny_ckpt), "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert "kin.onnx" in printed and "kin_init.onnx" in printed
    assert out.is_file() and (tmp_path / "kin_init.onnx").is_file()
    assert main(["kin", "export", str(tiny_ckpt), "--out", str(tmp_path / "k.pt")]) == 0
    assert "k.pt" in capsys.readouterr().out  # (a .pt still is the inference copy)
    baseline = SHIPPED_BASELINES["transpose"]
    for argv, why in [
        ([str(baseline), "--out", str(tmp_path / "b.onnx")], "transpose baseline"),
        ([str(tiny_ckpt), "--out", str(tmp_path / "b.onnx"), "--precision", "fp16"], "fp32"),
    ]:  # fmt: skip
        assert main(["kin", "export", *argv]) == 2
        assert why in capsys.readouterr().err
    assert not (tmp_path / "b.onnx").exists() and not (tmp_path / "b_init.onnx").exists()
    not_ckpt = tmp_path / "junk.pt"
    not_ckpt.write_bytes(b"not a checkpoint")
    assert main(["kin", "export", str(not_ckpt), "--out", str(tmp_path / "j.onnx")]) == 2
    assert "junk.pt" in capsys.readouterr().err


def test_read_metadata_refuses_what_is_no_model(tmp_path) -> None:
    junk = tmp_path / "junk.onnx"
    junk.write_bytes(b"\x00\x01 not protobuf")
    with pytest.raises(ValueError, match=r"junk\.onnx: not an ONNX model"):
        read_metadata(junk)
    with pytest.raises(FileNotFoundError, match=r"missing\.onnx"):
        read_metadata(tmp_path / "missing.onnx")
