"""``grip kin train --baseline`` / ``grip kin export`` on a tiny synthetic dataset (in-process)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import torch

from grip.cli.main import main
from prism_tools.chunking import make_split, save_split
from prism_tools.io import save_recording
from prism_tools.synthetic import make_recording


def _sets(prefix: str, **values) -> list[str]:
    return [a for k, v in values.items() for a in ("--set", f"{prefix}.{k}={v}")]


TINY = ["--threads", "1", *_sets("train", window_frames=30, batch_size=2, steps_per_epoch=2,
                                 epochs=1, val_windows=2)]  # fmt: skip
TINY_TP = [*TINY, *_sets("net", s1_width=8, s2_width=8, s3_width=8, b1_width=8, b2_width=8,
                         layers=1)]  # fmt: skip
TINY_PIP = [*TINY, *_sets("net", width=8, contact_width=8, layers=1)]


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """Three synthetic recordings in the layout of 'grip data build' (split.json + sequences)."""
    root = tmp_path_factory.mktemp("baseline_ds")
    ids = [f"synthetic_seq{i:03d}" for i in range(3)]
    for i, sid in enumerate(ids):
        save_recording(make_recording(90 + 20 * i, seed=i), root / "sequences" / f"{sid}.npz")
    save_split(make_split(ids, test_fraction=0.34, seed=0), root / "split.json")
    return root


@pytest.fixture(autouse=True)
def one_thread():
    prev = torch.get_num_threads()
    yield
    torch.set_num_threads(prev)


def test_train_baseline_runs_resumes_and_exports(dataset: Path, tmp_path: Path, capsys) -> None:
    run = tmp_path / "pip"
    args = ["kin", "train", "--baseline", "pip", "--data", str(dataset), "--out", str(run),
            *TINY_PIP]  # fmt: skip
    assert main(args) == 0
    out = capsys.readouterr().out
    assert "pip: 48 inputs" in out and "steps/s" in out
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["method"] == "pip" and cfg["config"]["net"]["width"] == 8 and "git" in cfg
    assert cfg["config"]["train"]["epochs"] == 1  # the override beats configs/baselines/pip.toml
    assert (run / "last.pt").exists() and (run / "best.pt").exists()
    assert list((run / "tb").iterdir())
    assert main(args) == 0
    assert "resuming" in capsys.readouterr().out
    longer = [*args, "--set", "train.epochs=2"]
    assert main(longer) == 0
    ck = torch.load(run / "last.pt", map_location="cpu", weights_only=True)
    assert int(ck["epoch"]) == 2
    assert main([*args, "--set", "net.widht=3"]) == 2
    assert "widht" in capsys.readouterr().err
    assert main([*args, "--insoles"]) == 2  # another configuration in the same folder
    assert "another configuration" in capsys.readouterr().err
    small = tmp_path / "pip_small.pt"
    assert main(["kin", "export", str(run / "best.pt"), "--out", str(small)]) == 0
    assert "MB" in capsys.readouterr().out
    from grip.kinematics.baselines import BaselineEstimator

    est = BaselineEstimator.from_checkpoint(small)
    assert est.method == "pip" and not est.cfg.net.insoles
    _check_bench_method("pip", small, dataset)


def _check_bench_method(name: str, checkpoint: Path, dataset: Path) -> None:
    """The exported nets run as a ``grip bench`` method from the true first frame."""
    from grip.eval.methods import MethodOptions, make_method
    from grip.eval.scoring import segment_metrics
    from grip.kinematics.features import ground_truth
    from prism_tools.io import load_recording

    rec = load_recording(sorted((dataset / "sequences").glob("*.npz"))[0]).slice_frames(0, 40)
    method = make_method(name, MethodOptions(**{f"{name}_checkpoint": checkpoint}))
    recon = method.reconstruct(rec)
    gt = ground_truth(rec)
    assert recon.method == name and recon.n_frames == 40 and not method.can_fall
    assert abs(recon.joint_pos[0, 0] - gt.joint_pos[0, 0]).max() < 0.05
    m, _ = segment_metrics(recon, gt, can_fall=False)
    assert np.isfinite(m["MPJPE_mm"]) and (np.isfinite(m["vGRF_N"]) == (name == "pip"))


def test_train_transpose_with_insoles(dataset: Path, tmp_path: Path, capsys) -> None:
    run = tmp_path / "tp"
    assert main(["kin", "train", "--baseline", "transpose", "--insoles", "--data", str(dataset),
                 "--out", str(run), *TINY_TP]) == 0  # fmt: skip
    assert "transpose + insoles: 58 inputs" in capsys.readouterr().out
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["method"] == "transpose" and cfg["config"]["net"]["insoles"] is True
    _check_bench_method("transpose", run / "best.pt", dataset)


def test_clear_errors(dataset: Path, tmp_path: Path, capsys) -> None:
    assert main(["kin", "train", "--baseline", "pip", "--data", str(tmp_path), "--out",
                 str(tmp_path / "r"), *TINY_PIP]) == 2  # fmt: skip
    assert "split.json" in capsys.readouterr().err
    bad = tmp_path / "broken.pt"
    bad.write_bytes(b"junk")
    assert main(["kin", "export", str(bad), "--out", str(tmp_path / "o.pt")]) == 2
    err = capsys.readouterr().err
    assert "broken.pt" in err and "Traceback" not in err
    with pytest.raises(SystemExit):
        main(["kin", "train", "--baseline", "dip", "--data", str(dataset), "--out",
              str(tmp_path / "x")])  # fmt: skip
