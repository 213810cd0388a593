"""Unencodable strings in a recording or a reconstruction (issue 50, item 5).

A lone surrogate (``"\\udcff"``, what :func:`os.fsdecode` gives for an undecodable byte) in a
recording's category or name, or in a reconstruction's name, once ended ``grip data info``,
``kin eval``, ``policy eval``, ``bench``, ``export`` and ``view`` with a traceback after the work
was done (printing a table, or writing ``table.md`` or a CSV as UTF-8). Such strings are cleaned
where the files are read (:func:`grip.core.text.clean_strings`): each unencodable code point
becomes U+FFFD, so every writer downstream is safe. ``capsys`` gives a strict UTF-8 stdout, as
a terminal with a UTF-8 locale does.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from grip.cli.main import main
from grip.core.reconstruction import Reconstruction
from grip.core.text import clean_strings, clean_text
from grip.kinematics.features import ground_truth
from prism_tools.chunking import make_split, save_split
from prism_tools.io import load_recording, save_recording
from prism_tools.synthetic import make_recording

BAD = "\udcff"  # os.fsdecode(b"\xff")
FRAMES = 60
TAKES = {"take0": 70, "take1": 65}


def _recording(name: str, n: int, seed: int):
    rec = make_recording(n, seed=seed)
    return dataclasses.replace(rec, extras={**rec.extras, "take_name": name + BAD,
                                            "category": "walk" + BAD,
                                            "label": "lbl" + BAD})  # fmt: skip


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    """A dataset folder whose recordings carry a lone surrogate in category, name, label."""
    root = tmp_path_factory.mktemp("unencodable")
    for i, (name, n) in enumerate(TAKES.items()):
        save_recording(_recording(name, n, i), root / "sequences" / f"{name}.npz")
    save_split(make_split(list(TAKES), test_fraction=1.0), root / "split.json")
    return root


@pytest.fixture(scope="module")
def recon_files(tmp_path_factory) -> dict[str, Path]:
    """A reconstruction named with a lone surrogate (method and a note too) and its take."""
    d = tmp_path_factory.mktemp("unencodable_recon")
    rec = _recording("take0", 70, 0)
    gt = ground_truth(rec)
    recon = Reconstruction(name="seg" + BAD, method="grip" + BAD, fps=gt.fps,
                           joint_pos=gt.joint_pos, global_rot=gt.global_rot,
                           notes={"why" + BAD: ["x" + BAD]})  # fmt: skip
    recon.save(d / "seg.npz")
    save_recording(rec, d / "rec.npz")
    return {"recon": d / "seg.npz", "rec": d / "rec.npz"}


def _encodable(text: str) -> bool:
    try:
        text.encode("utf-8")
    except UnicodeEncodeError:
        return False
    return True


# ---------------------------------------------------------------------------- the rule itself
def test_clean_text_replaces_each_unencodable_code_point() -> None:
    assert clean_text("walk") == "walk"
    assert clean_text("wälk ✓") == "wälk ✓"
    assert clean_text("a" + BAD + "b") == "a\ufffdb"
    assert clean_text(BAD + "\ud800") == "\ufffd\ufffd"
    assert clean_text("\ud83d\ude00") == "\U0001f600"  # a pair given as two halves: joined


def test_clean_strings_cleans_keys_values_and_text_arrays() -> None:
    arr = np.array(["ok", "x" + BAD])
    tree = {"a" + BAD: ["b" + BAD, 1, {"c": ("d" + BAD,)}], "n": np.zeros(3), "u": arr}
    got = clean_strings(tree)
    assert list(got) == ["a\ufffd", "n", "u"]
    assert got["a\ufffd"][0] == "b\ufffd" and got["a\ufffd"][2]["c"] == ("d\ufffd",)
    assert got["u"].tolist() == ["ok", "x\ufffd"]
    assert arr.tolist() == ["ok", "x" + BAD]  # the input is not changed
    clean = {"a": "b", "n": np.zeros(3)}
    assert clean_strings(clean) is clean  # nothing to clean: the same object
    with pytest.raises(ValueError, match="two keys"):
        clean_strings({"k" + BAD: 1, "k\udcfe": 2})


def test_loaders_clean_names_and_categories(dataset, recon_files) -> None:
    rec = load_recording(dataset / "sequences" / "take0.npz")
    assert rec.name == "take0\ufffd" and rec.category == "walk\ufffd"
    assert rec.extras["label"] == "lbl\ufffd"
    recon = Reconstruction.load(recon_files["recon"])
    assert (recon.name, recon.method) == ("seg\ufffd", "grip\ufffd")
    assert recon.notes == {"why\ufffd": ["x\ufffd"]}


def test_a_recording_named_by_an_undecodable_path_gets_a_clean_name(tmp_path) -> None:
    rec = make_recording(50, seed=3)
    rec = dataclasses.replace(rec, extras={})  # no take name stored: it comes from the path
    path = tmp_path / ("take" + BAD + ".pkl")
    save_recording(rec, path)
    assert _encodable(load_recording(path).name)


# ------------------------------------------------------------------------------- the commands
def test_data_info(dataset, tmp_path, capsys) -> None:
    assert main(["data", "info", str(dataset), "--json", str(tmp_path / "i.json")]) == 0
    assert "walk\ufffd" in capsys.readouterr().out
    assert "walk\ufffd" in json.dumps(json.loads((tmp_path / "i.json").read_text()),
                                     ensure_ascii=False)  # fmt: skip


def test_kin_eval(dataset, tmp_path, capsys) -> None:
    out = tmp_path / "ke"
    rc = main(["kin", "eval", "--data", str(dataset), "--segment-frames", str(FRAMES),
               "--out", str(out), "--json", str(tmp_path / "ke.json")])  # fmt: skip
    assert rc == 0
    assert "walk\ufffd" in capsys.readouterr().out
    texts = [p for p in out.iterdir() if p.suffix in (".md", ".csv")]
    assert texts and all("walk\ufffd" in p.read_text(encoding="utf-8") for p in texts)


def test_policy_eval(dataset, tmp_path, capsys) -> None:
    out = tmp_path / "pe"
    rc = main(["policy", "eval", "--data", str(dataset), "--segment-frames", str(FRAMES),
               "--out", str(out)])  # fmt: skip
    assert rc == 0
    assert "walk\ufffd" in capsys.readouterr().out
    assert "walk\ufffd" in (out / "segments.csv").read_text(encoding="utf-8")


def test_bench_keeps_its_table_and_plots(dataset, tmp_path, capsys) -> None:
    out = tmp_path / "b"
    rc = main(["bench", "--data", str(dataset), "--methods", "kinematics", "--segment-frames",
               str(FRAMES), "--workers", "1", "--out", str(out)])  # fmt: skip
    assert rc == 0
    capsys.readouterr()
    assert "walk\ufffd" in (out / "table.md").read_text(encoding="utf-8")
    assert (out / "segments.csv").is_file() and list(out.glob("*.png"))
    row = json.loads(next((out / "segments" / "kinematics").glob("take0_*.json")).read_text())
    assert row["category"] == "walk\ufffd"


def test_export(recon_files, tmp_path, capsys) -> None:
    out = tmp_path / "ex"
    rc = main(["export", str(recon_files["recon"]), "--out", str(out), "--gt",
               str(recon_files["rec"]), "--formats", "bvh,glb,amass"])  # fmt: skip
    assert rc == 0
    capsys.readouterr()
    assert {p.suffix for p in out.iterdir()} == {".bvh", ".glb", ".npz"}


def test_view(recon_files, tmp_path, capsys) -> None:
    page = tmp_path / "v.html"
    rc = main(["view", str(recon_files["recon"]), "--gt", str(recon_files["rec"]),
               "--out", str(page)])  # fmt: skip
    assert rc == 0
    capsys.readouterr()
    assert "seg\ufffd" in page.read_text(encoding="utf-8")


def test_bench_on_a_file_with_an_undecodable_name(tmp_path, capsys) -> None:
    data = tmp_path / "d"
    names = ["take0" + BAD, "take1"]
    for i, name in enumerate(names):
        rec = make_recording(70, seed=i)
        rec = dataclasses.replace(rec, extras={**rec.extras, "take_name": f"t{i}",
                                               "category": "walk"})  # fmt: skip
        save_recording(rec, data / "sequences" / f"{name}.npz")
    save_split(make_split(names, test_fraction=1.0), data / "split.json")
    out = tmp_path / "b"
    rc = main(["bench", "--data", str(data), "--methods", "kinematics", "--segment-frames",
               str(FRAMES), "--workers", "1", "--out", str(out)])  # fmt: skip
    assert rc == 0
    capsys.readouterr()
    assert "take0\ufffd_f000000" in (out / "segments.csv").read_text(encoding="utf-8")
