"""``grip policy export RUN --checkpoint``: a run's resume state with its optimiser moments in
bfloat16, which a run resumes from as from the original (up to the moments' rounding), never
unpickling."""

from __future__ import annotations

import dataclasses
import json
import shutil
import zipfile

import pytest
import torch

from envs.factory import make_tracking_env
from envs.tracking_env import SAMPLE_REFERENCE
from grip.cli.main import main
from policies.checkpoint import load_weights, read_ppo_zip
from policies.train import PolicyTrainer, run_config_dict
from tests.policies.test_train import _tiny


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    run = tmp_path_factory.mktemp("pack") / "run"
    run.mkdir()
    cfg = _tiny()
    (run / "config.json").write_text(json.dumps({"config": run_config_dict(cfg)}))
    PolicyTrainer(cfg, run, SAMPLE_REFERENCE, make_tracking_env).train()
    return cfg, run


def test_pack_halves_the_moments_and_keeps_weights_counters_and_state(trained, tmp_path, capsys):
    _, run = trained
    out = tmp_path / "packed"
    assert main(["policy", "export", str(run), "--checkpoint", "--out", str(out)]) == 0
    assert str(out) in capsys.readouterr().out
    orig, packed = (read_ppo_zip(d / "checkpoint/model.zip") for d in (run, out))
    assert packed.counters == orig.counters
    for k, v in orig.policy.items():
        assert torch.equal(packed.policy[k], v), k
    for i, st in orig.optimizer["state"].items():
        for name, v in st.items():
            got = packed.optimizer["state"][i][name]
            if v.dim() == 0:
                assert torch.equal(got, v), (i, name)
            else:
                assert got.dtype == torch.bfloat16, (i, name)
                torch.testing.assert_close(got.float(), v, rtol=1e-2, atol=1e-12)
    amp_o, amp_p = (load_weights(d / "checkpoint/amp.pt", "amp") for d in (run, out))
    for k, v in amp_o["disc"].items():
        assert torch.equal(amp_p["disc"][k], v), k
    moments = [v for st in amp_p["opt"]["state"].values() for v in st.values() if v.dim() > 0]
    assert moments and all(v.dtype == torch.bfloat16 for v in moments)
    for name in ("state.json", "vecnorm.npz"):
        assert (out / "checkpoint" / name).read_bytes() == (run / "checkpoint" / name).read_bytes()
    assert (out / "config.json").read_bytes() == (run / "config.json").read_bytes()
    with zipfile.ZipFile(run / "checkpoint/model.zip") as a, zipfile.ZipFile(
            out / "checkpoint/model.zip") as b:  # fmt: skip
        assert a.namelist() == b.namelist()
        assert b.getinfo("policy.optimizer.pth").file_size < 0.6 * a.getinfo(
            "policy.optimizer.pth").file_size  # fmt: skip


def test_a_packed_run_resumes_like_the_original(trained, tmp_path):
    cfg, run = trained
    main(["policy", "export", str(run), "--checkpoint", "--out", str(tmp_path / "packed")])
    longer = dataclasses.replace(cfg, stage2=dataclasses.replace(cfg.stage2, timesteps=128))
    got = {}
    for how, src in (("orig", run), ("packed", tmp_path / "packed")):
        copy = tmp_path / f"resume_{how}"
        shutil.copytree(src, copy)
        tr = PolicyTrainer(longer, copy, SAMPLE_REFERENCE, make_tracking_env)
        tr.train()
        got[how] = tr
        assert tr.model.num_timesteps == 128 + 128
        assert tr.model.policy.optimizer.state[next(iter(tr.model.policy.parameters()))][
            "exp_avg"].dtype == torch.float32  # fmt: skip
    a, b = got["orig"].model.policy.state_dict(), got["packed"].model.policy.state_dict()
    for k in a:
        torch.testing.assert_close(b[k], a[k], rtol=0, atol=1e-3)
    assert [h["timesteps"] for h in got["orig"].history] == [
        h["timesteps"] for h in got["packed"].history]  # fmt: skip


def test_pack_refuses_a_folder_without_a_checkpoint_and_the_run_itself(trained, tmp_path, capsys):
    _, run = trained
    (tmp_path / "empty").mkdir()
    assert main(["policy", "export", str(tmp_path / "empty"), "--checkpoint", "--out",
                 str(tmp_path / "o")]) == 2
    assert "empty" in capsys.readouterr().err
    assert main(["policy", "export", str(run), "--checkpoint", "--out", str(run)]) == 2
    assert "is the run itself" in capsys.readouterr().err
    assert (run / "checkpoint/model.zip").is_file()
    assert main(["policy", "export", str(run), "--checkpoint", "--precision", "fp32", "--out",
                 str(tmp_path / "p")]) == 2  # fmt: skip
    assert "--precision" in capsys.readouterr().err and not (tmp_path / "p").exists()


def test_pack_never_overwrites_another_runs_resume_state(trained, tmp_path, capsys):
    """``--out`` naming another run's folder replaced its resume state (issue 50); the same
    run's earlier packed copy is updated as before, and ``--overwrite`` says so explicitly."""
    _, run = trained
    other = tmp_path / "other"
    shutil.copytree(run, other)
    cfg = json.loads((other / "config.json").read_text())
    cfg["config"]["seed"] = cfg["config"]["seed"] + 1
    (other / "config.json").write_text(json.dumps(cfg))
    before = (other / "checkpoint" / "model.zip").read_bytes()
    argv = ["policy", "export", str(run), "--checkpoint", "--out", str(other)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert str(other) in err and "another run" in err and "--overwrite" in err, err
    assert (other / "checkpoint" / "model.zip").read_bytes() == before
    ahead = tmp_path / "ahead"
    assert main(["policy", "export", str(run), "--checkpoint", "--out", str(ahead)]) == 0
    assert main(["policy", "export", str(run), "--checkpoint", "--out", str(ahead)]) == 0
    state = json.loads((ahead / "checkpoint" / "state.json").read_text())
    state["stage_done"] = state["stage_done"] + 10_000
    (ahead / "checkpoint" / "state.json").write_text(json.dumps(state))
    assert main(["policy", "export", str(run), "--checkpoint", "--out", str(ahead)]) == 2
    assert "further" in capsys.readouterr().err
    assert main([*argv, "--overwrite"]) == 0
    assert (other / "config.json").read_bytes() == (run / "config.json").read_bytes()
