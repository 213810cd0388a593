"""A gate over frozen controllers (policies/gate.py, ``grip policy combine --gate``)."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import torch

F = 6  # sensor features of the synthetic gates


def _features(rng, n: int, centre: float) -> np.ndarray:
    x = rng.normal(0.0, 0.2, (n, F))
    x[:, 0] += centre
    return x


def test_fit_gate_routes_each_family_and_refuses_an_empty_route():
    from policies.gate import fit_gate, route_counts

    rng = np.random.default_rng(0)
    feats = [_features(rng, 400, 3.0), _features(rng, 60, -3.0), _features(rng, 60, 0.0)]
    cats = ["walk", "sit-stand", "jump"]
    gate, losses = fit_gate(feats, cats, [("sit*",), ("jump",)], hidden=(16,), steps=600)
    assert losses[-1] < losses[0]
    assert [gate.route_of(c) for c in ("walk", "sit-stand", "jump", "run")] == [0, 1, 2, 0]
    test = [_features(rng, 50, c) for c in (3.0, -3.0, 0.0)]
    for want, x in enumerate(test):
        assert np.mean(gate.routes(x) == want) > 0.9  # the rare routes learnt despite 60 frames
    counts = route_counts(gate, [*test, test[1]], ["walk", "sit-stand", "jump", "sit-stand"])
    assert list(counts) == ["jump", "sit-stand", "walk"]  # sorted, one entry per category
    assert counts["sit-stand"].sum() == 100 and counts["sit-stand"].argmax() == 1
    with pytest.raises(ValueError, match=r"no training frames.*dance"):
        fit_gate(feats, cats, [("dance",)], steps=1)
    with pytest.raises(ValueError, match="width"):
        fit_gate([np.zeros((5, 3)), np.zeros((5, 4))], ["a", "b"], [("a",)], steps=1)


def _two_policies(tmp_path):
    """The shipped policy and a copy whose actor acts differently."""
    from grip.assets import SHIPPED_POLICY
    from policies.runner import read_policy_file, write_policy_file

    members, _ = read_policy_file(SHIPPED_POLICY)
    other = dict(members[0])
    other["actor"] = {k: (-v.float()).to(v.dtype) for k, v in other["actor"].items()}
    a, b = tmp_path / "a.pt", tmp_path / "b.pt"
    write_policy_file([members[0]], ["a"], a)
    write_policy_file([other], ["b"], b)
    return a, b


def _obs(runner, sensor: np.ndarray) -> dict:
    rng = np.random.default_rng(1)
    obs = {k: rng.normal(0, 1, (len(sensor), runner.obs_mean[k].shape[-1])).astype(np.float32)
           for k in runner.obs_keys}  # fmt: skip
    obs["sensor"] = sensor.astype(np.float32)
    return obs


def test_gated_file_plays_each_rows_routed_member(tmp_path):
    from policies.controller import load_controller
    from policies.gate import Gate, GatedController, gate_network, write_gated_policy
    from policies.runner import PolicyRunner

    a, b = _two_policies(tmp_path)
    ra, rb = PolicyRunner.load(a), PolicyRunner.load(b)
    width = ra.obs_mean["sensor"].shape[-1]
    net = gate_network(width, (4,), 2)
    with torch.no_grad():  # route 1 exactly where the first feature is negative
        for p in net.parameters():
            p.zero_()
        net[0].weight[0, 0] = -1.0
        net[0].bias[0] = 0.0
        net[2].weight[1, 0] = 10.0
    gate = Gate(net, np.zeros(width), np.ones(width), [("sit-stand",)], (4,))
    out = tmp_path / "gated.pt"
    write_gated_policy([a, b], gate, out)
    ctrl = load_controller(out)
    assert isinstance(ctrl, GatedController)
    assert ctrl.info["gate"] == ["default", "sit-stand"]
    sensor = np.random.default_rng(2).normal(0, 1, (12, width))
    sensor[:, 0] = np.where(np.arange(12) % 3 == 0, -1.0, 1.0)
    obs = _obs(ra, sensor)
    got = ctrl.act(obs)
    want = np.where((sensor[:, 0] < 0)[:, None], rb.act(obs), ra.act(obs))
    np.testing.assert_allclose(got, want, atol=1e-6)
    assert ctrl.last_routes.tolist() == (sensor[:, 0] < 0).astype(int).tolist()
    one = {k: v[0] for k, v in obs.items()}  # a single observation: member b's action
    np.testing.assert_allclose(ctrl.act(one), rb.act(one), atol=1e-6)
    with pytest.raises(ValueError, match="sensor features"):
        ctrl.act({**obs, "sensor": sensor[:, :-1]})
    with pytest.raises(ValueError, match="drives alone"):
        load_controller([out, a])


def test_gated_file_refuses_what_does_not_fit(tmp_path, ensemble_policy):
    from policies.controller import combine
    from policies.gate import (
        Gate,
        gate_from_payload,
        gate_network,
        gate_payload,
        write_gated_policy,
    )
    from policies.runner import read_policy_parts

    a, b = _two_policies(tmp_path)
    width = 70
    gate = Gate(gate_network(width, (4,), 2), np.zeros(width), np.ones(width), [("x",)], (4,))
    with pytest.raises(ValueError, match="2 routes needs as many policies, got 3"):
        write_gated_policy([a, b, b], gate, tmp_path / "g.pt")
    with pytest.raises(ValueError, match="ensemble of 3 policies"):
        write_gated_policy([a, ensemble_policy], gate, tmp_path / "g.pt")
    bad = gate_payload(gate)
    bad["net"] = {k: v[:1] for k, v in bad["net"].items()}
    with pytest.raises(ValueError, match=r"where\.pt: malformed gate"):
        gate_from_payload(bad, "where.pt")
    with pytest.raises(ValueError, match="malformed gate"):
        gate_from_payload({**gate_payload(gate), "format": "pickle"}, "where.pt")
    # One member taken out of a gated file is an ordinary policy file.
    out = tmp_path / "g.pt"
    write_gated_policy([a, b], gate, out)
    assert read_policy_parts(out)[2] is not None
    combine(out, tmp_path / "m1.pt", member=1)
    assert read_policy_parts(tmp_path / "m1.pt")[2] is None
    # The ONNX graph plays one policy or an ensemble's mean, never a gate's routes.
    from policies.onnx import export_policy_onnx

    with pytest.raises(ValueError, match=r"g\.pt: a gated policy file.*--member K"):
        export_policy_onnx(out, tmp_path / "g.onnx")
    assert not (tmp_path / "g.onnx").exists()


def test_grip_policy_gate_command(tmp_path, capsys):
    from grip.cli.main import main
    from policies.controller import load_controller
    from policies.gate import GatedController
    from prism_tools.chunking import save_split
    from prism_tools.io import save_recording
    from prism_tools.synthetic import make_recording

    a, b = _two_policies(tmp_path)
    data = tmp_path / "data"
    names = {"w0": "walk", "w1": "walk", "s0": "sit-stand", "t0": "walk"}
    for i, (name, cat) in enumerate(names.items()):
        rec = make_recording(150, seed=i)
        rec = dataclasses.replace(rec, extras={**rec.extras, "category": cat})
        save_recording(rec, data / "sequences" / f"{name}.npz")
    save_split({"format": "grip-prism-split", "version": 1, "train": ["w0", "w1", "s0"],
                "test": ["t0"], "split_by": "clip"}, data / "split.json")  # fmt: skip
    out = tmp_path / "gated.pt"
    argv = ["policy", "combine", str(a), str(b), "--gate", "sit-stand", "--data", str(data),
            "--out", str(out), "--gate-steps", "20"]  # fmt: skip
    assert main(argv) == 0
    text = capsys.readouterr().out
    assert "routes on the train split" in text and "routes on the test split" in text
    assert "| sit-stand | 150 | sit-stand |" in text and "2 controllers and their gate" in text
    gated = load_controller(out)
    assert isinstance(gated, GatedController) and gated.gate.window == 60  # (the default)
    assert gated.env_cfg.sensor_context == 60
    assert main([*argv, "--gate-window", "0"]) != 0
    assert "--gate-window must be at least 1" in capsys.readouterr().err
    assert main(["policy", "combine", str(a), str(b), "--gate", "sit-stand", "--out",
                 str(out)]) != 0  # fmt: skip
    assert "--gate needs --data" in capsys.readouterr().err
    assert main(["policy", "combine", str(a), str(b), "--data", str(data), "--out",
                 str(out)]) != 0  # fmt: skip
    assert "belong to --gate" in capsys.readouterr().err
    assert main([*argv[:6], "--gate", "jump", *argv[6:]]) != 0  # one --gate too many
    assert "need 1 --gate" in capsys.readouterr().err
    # A family without training frames is refused, naming the folder.
    assert main([*argv[:5], "dance", *argv[6:]]) != 0
    assert "no training frames" in capsys.readouterr().err
    assert json.loads((data / "split.json").read_text())["train"]  # (the data are untouched)


def _sine_or_still(rng, n: int, moving: bool) -> np.ndarray:
    """Feature 0 a sine of amplitude 1 (moving) or a constant drawn from [-1, 1] (still): one
    frame's value tells the two apart badly, a second of frames at once."""
    x = rng.normal(0.0, 0.03, (n, F))
    x[:, 0] += np.sin(np.arange(n) * 2 * np.pi / 20) if moving else rng.uniform(-1, 1)
    return x


def test_a_gate_with_context_tells_apart_what_one_frame_cannot():
    from policies.gate import fit_gate, gate_from_payload, gate_payload

    rng = np.random.default_rng(3)
    cats = ["walk"] * 30 + ["dance"] * 30  # (the still ones at 30 levels: none to learn by heart)
    feats = [_sine_or_still(rng, 90, c == "dance") for c in cats]
    test = [_sine_or_still(rng, 90, c == "dance") for c in cats]
    share = {}
    for window in (1, 30):
        gate, _ = fit_gate(feats, cats, [("dance",)], hidden=(32,), steps=800, window=window)
        assert gate.window == window and gate.in_dim == F
        share[window] = np.mean([np.mean(gate.recording_routes(x)[30:] == gate.route_of(c))
                                 for x, c in zip(test, cats, strict=True)])  # fmt: skip
    assert share[1] < 0.8 < 0.95 < share[30]
    back = gate_from_payload(gate_payload(gate), "g.pt")
    assert back.window == 30
    np.testing.assert_array_equal(back.recording_routes(test[9]), gate.recording_routes(test[9]))
    one, _ = fit_gate(feats, cats, [("dance",)], hidden=(8,), steps=1)
    old = gate_payload(one)
    del old["window"]  # a file written before the context window: the frame alone
    assert gate_from_payload(old, "g.pt").window == 1
    with pytest.raises(ValueError, match="window of 30 frames over 7 inputs"):
        gate_from_payload({**gate_payload(gate), "mean": torch.zeros(7),
                           "std": torch.ones(7)}, "g.pt")  # fmt: skip
    with pytest.raises(ValueError, match="window must be >= 1"):
        fit_gate(feats, cats, [("dance",)], steps=1, window=0)


def test_a_gated_controller_with_context_asks_for_it_and_routes_by_it(tmp_path):
    from policies.controller import load_controller
    from policies.gate import Gate, gate_network, write_gated_policy
    from policies.runner import PolicyRunner
    from policies.symmetry import ObservationMirror

    a, b = _two_policies(tmp_path)
    ra, rb = PolicyRunner.load(a), PolicyRunner.load(b)
    width = ra.obs_mean["sensor"].shape[-1]
    net = gate_network(3 * width, (4,), 2)
    with torch.no_grad():  # route 1 where the context's first deviation exceeds 0.5
        for p in net.parameters():
            p.zero_()
        net[0].weight[0, 2 * width] = 1.0
        net[0].bias[0] = -0.5
        net[2].weight[1, 0] = 10.0
    gate = Gate(net, np.zeros(3 * width), np.ones(3 * width), [("dance",)], (4,), window=40)
    write_gated_policy([a, b], gate, tmp_path / "g.pt")
    ctrl = load_controller(tmp_path / "g.pt")
    assert ctrl.gate.window == 40 and ctrl.env_cfg.sensor_context == 40
    assert ra.env_cfg.sensor_context == 0 and ctrl.info["gate_window"] == 40
    obs = _obs(ra, np.zeros((6, width)))
    with pytest.raises(ValueError, match="40 frames of context"):
        ctrl.act(obs)
    context = np.zeros((6, 2 * width), np.float32)
    context[::2, width] = 2.0  # rows 0, 2, 4: a large deviation of feature 0
    obs["sensor_context"] = context
    want = np.where((context[:, width] > 0.5)[:, None], rb.act(obs), ra.act(obs))
    np.testing.assert_allclose(ctrl.act(obs), want, atol=2e-5)
    assert ctrl.last_routes.tolist() == [1, 0, 1, 0, 1, 0]
    # The mirror image's context is the context of the mirrored features.
    from grip.task.observations import sensor_context_rows

    mirror = ObservationMirror(ra.env_cfg, ("L_Foot", "R_Foot", "L_Wrist", "R_Wrist"), True)
    x = np.random.default_rng(4).normal(0.0, 1.0, (50, width)).astype(np.float32)
    got = mirror.observation({"sensor_context": sensor_context_rows(x, 40).astype(np.float32)})
    want = sensor_context_rows(mirror.observation({"sensor": x})["sensor"], 40)
    np.testing.assert_allclose(got["sensor_context"], want, atol=1e-5)
