"""A tampered training run folder is read without running anything it holds.

stable-baselines3's ``PPO.load`` unpickles (and so runs) every ``":serialized:"`` entry of the
``data`` JSON in ``model.zip``. ``grip policy export RUN`` and a resumed ``grip policy train
--out RUN`` read the folder through :mod:`policies.checkpoint` instead: those entries are
ignored, and a tensor file holding pickled Python objects is refused with its name.
"""

from __future__ import annotations

import base64
import io
import json
import pathlib
import shutil
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from envs.tracking_env import SAMPLE_REFERENCE
from grip.cli.main import main


class Touch:
    """Unpickling this touches ``marker``: the stand-in for a hostile payload."""

    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self):
        return (pathlib.Path.touch, (self.marker,))


def _serialized(obj: object) -> dict:
    """``obj`` as stable-baselines3 stores an object in the ``data`` JSON of its zip."""
    import cloudpickle

    return {":type:": "<class 'object'>",
            ":serialized:": base64.b64encode(cloudpickle.dumps(obj)).decode()}  # fmt: skip


def _rewrite_zip(path: Path, name: str, edit) -> None:
    """Replace member ``name`` of the zip at ``path`` by ``edit(its bytes)``."""
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    members[name] = edit(members[name])
    with zipfile.ZipFile(path, "w") as z:
        for n, data in members.items():
            z.writestr(n, data)


@pytest.fixture
def train_args(tiny_policy_settings):
    """``train_args(data, run, *extra)``: the argv of the tiny run's (resumed) training."""

    def argv(data: Path, run: Path, *extra: str) -> list[str]:
        return ["policy", "train", "--data", str(data), "--out", str(run), *tiny_policy_settings,
                *extra]  # fmt: skip

    return argv


@pytest.fixture
def trained(tiny_policy_run) -> tuple[Path, Path]:
    return tiny_policy_run


def _copy(trained, tmp_path: Path) -> tuple[Path, Path]:
    data, run = trained
    copy = tmp_path / "run"
    shutil.copytree(run, copy)
    return data, copy


@pytest.mark.parametrize("how", ["extra_entry", "every_entry"])
def test_serialized_payloads_in_model_zip_are_never_run(trained, train_args, tmp_path, how):
    """Export and resume ignore the zip's pickled entries: an added one, or every stored one
    (spaces, schedules, policy class and kwargs) replaced; the resumed run continues."""
    data, run = _copy(trained, tmp_path)
    marker = tmp_path / "pwned"
    zpath = run / "checkpoint" / "model.zip"

    def tamper(marker: Path):
        def edit(raw: bytes) -> bytes:
            d = json.loads(raw)
            if how == "extra_entry":
                d["hostile"] = _serialized(Touch(marker))
            else:
                n = 0
                for k, v in d.items():
                    if isinstance(v, dict) and ":serialized:" in v:
                        d[k], n = _serialized(Touch(marker)), n + 1
                assert n >= 5  # observation/action space, policy class, schedules, ...
            return json.dumps(d).encode()

        return edit

    # the payload is live: stable-baselines3's own loader runs it
    live, live_marker = tmp_path / "live.zip", tmp_path / "live"
    shutil.copy(zpath, live)
    _rewrite_zip(live, "data", tamper(live_marker))
    from stable_baselines3 import PPO

    try:
        PPO.load(live, device="cpu")
    except Exception:  # with every entry replaced it fails, after running the payloads
        pass
    assert live_marker.exists()

    _rewrite_zip(zpath, "data", tamper(marker))
    out = tmp_path / "policy.pt"
    assert main(["policy", "export", str(run), "--out", str(out)]) == 0
    assert not marker.exists()
    from policies.runner import PolicyRunner

    assert PolicyRunner.load(out).actor is not None
    steps = json.loads((run / "checkpoint" / "state.json").read_text())["stage_done"]
    assert main(train_args(data, run, "--set", "stage2.timesteps=128")) == 0  # resumes
    assert not marker.exists()
    state = json.loads((run / "checkpoint" / "state.json").read_text())
    assert steps == 64 and state["stage_index"] == 1 and state["stage_done"] == 128
    # the resumed checkpoint counts every decision (the counter came from the plain JSON)
    with zipfile.ZipFile(zpath) as z:
        assert json.loads(z.read("data"))["num_timesteps"] == 64 + 128


def _hostile_torch(marker: Path) -> bytes:
    buf = io.BytesIO()
    torch.save({"weights": Touch(marker)}, buf)
    return buf.getvalue()


@pytest.mark.parametrize("part", ["policy.pth", "policy.optimizer.pth", "amp.pt", "vecnorm.npz",
                                  "not_a_zip"])  # fmt: skip
def test_hostile_files_in_a_run_folder_are_refused_naming_them(trained, train_args, tmp_path,
                                                               part, capsys):  # fmt: skip
    """Pickled objects where tensors or arrays belong, or a model.zip that is no zip: export
    and resume stop with an error naming the file, and nothing in it runs."""
    data, run = _copy(trained, tmp_path)
    marker = tmp_path / "pwned"
    ck = run / "checkpoint"
    if part.endswith(".pth"):
        _rewrite_zip(ck / "model.zip", part, lambda _raw: _hostile_torch(marker))
        name = "model.zip"
    elif part == "amp.pt":
        (ck / "amp.pt").write_bytes(_hostile_torch(marker))
        name = "amp.pt"
    elif part == "vecnorm.npz":
        with np.load(ck / "vecnorm.npz") as z:
            arrays = dict(z)
        arrays["ret_mean"] = np.array([Touch(marker)], dtype=object)
        np.savez(ck / "vecnorm.npz", **arrays)
        name = "vecnorm.npz"
    else:
        (ck / "model.zip").write_bytes(b"PK\x03\x04 junk")
        name = "model.zip"
    for argv in (["policy", "export", str(run), "--out", str(tmp_path / "p.pt")],
                 train_args(data, run, "--set", "stage2.timesteps=128")):  # fmt: skip
        assert main(argv) == 2, argv[0]
        err = capsys.readouterr().err
        assert name in err and "weights_only=False" not in err, (argv[0], err)
        assert not marker.exists()
    assert not (tmp_path / "p.pt").exists()


def test_resume_continues_exactly_as_sb3_load_would(tmp_path):
    """The safe resume (a PPO built from the config, given the zip's state dicts and counters)
    trains on bit-identically to resuming with stable-baselines3's own ``PPO.load`` (the old
    path, on an untampered run), so run folders written before it resume as they did."""
    import dataclasses

    from stable_baselines3 import PPO

    from envs.factory import make_tracking_env
    from policies.train import PolicyTrainer, run_config_dict
    from policies.vec_env import load_vecnorm_state
    from tests.policies.test_train import _tiny

    cfg = _tiny()
    run = tmp_path / "run"
    run.mkdir()
    (run / "config.json").write_text(json.dumps({"config": run_config_dict(cfg)}))
    PolicyTrainer(cfg, run, SAMPLE_REFERENCE, make_tracking_env).train()
    longer = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, timesteps=128))

    def sb3_restore(self) -> None:  # what PolicyTrainer did before (runs pickled entries)
        with np.load(self.ckpt_dir / "vecnorm.npz", allow_pickle=False) as z:
            load_vecnorm_state(self.venv, dict(z))
        self.model = PPO.load(self.ckpt_dir / "model.zip", env=self.venv,
                              device=self.cfg.ppo.device, **self._ppo_settings())  # fmt: skip

    got = {}
    for how in ("safe", "sb3"):
        copy = tmp_path / how
        shutil.copytree(run, copy)
        tr = PolicyTrainer(longer, copy, SAMPLE_REFERENCE, make_tracking_env)
        if how == "sb3":
            tr._restore_model = sb3_restore.__get__(tr)
        tr.train()
        got[how] = (tr.model.policy.state_dict(), tr.model.policy.optimizer.state_dict(),
                    tr.model.num_timesteps, [{**h, "wall_s": 0} for h in tr.history])  # fmt: skip
    (safe, safe_opt, safe_n, safe_hist), (sb3, sb3_opt, sb3_n, sb3_hist) = got["safe"], got["sb3"]
    assert safe.keys() == sb3.keys()
    for k in safe:
        assert torch.equal(safe[k], sb3[k]), k
    for i, st in safe_opt["state"].items():
        assert torch.equal(st["exp_avg"], sb3_opt["state"][i]["exp_avg"]), i
    assert safe_n == sb3_n == 128 + 128  # (stage 1, then stage 2 extended to 128)
    assert safe_hist == sb3_hist
