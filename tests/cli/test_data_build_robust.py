"""``grip data build`` when things go wrong: a build killed mid-way (its workers must end with
it, a rerun must not mix settings, its temporary files go), and malformed motion files (each
reported by name, the others built, exit status 1, never a traceback)."""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from grip.cli.main import main

MOTIONS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "motions"
DEEPMIMIC = MOTIONS / "deepmimic"
pytestmark = pytest.mark.skipif(not DEEPMIMIC.is_dir(), reason="shared motion clips not found")

# A build with two workers whose parent stalls after its first finished clip: the workers
# finish the rest and wait for more work, the manifest is never written.
_STALLING_BUILD = """
import sys, time
from pathlib import Path
from grip.cli.data import select_clips
from grip.dataset.build import BuildConfig, build_dataset
clips = select_clips([Path(sys.argv[1])], 4)
build_dataset(clips, sys.argv[2], BuildConfig(), workers=2,
              progress=lambda n: (print("progress", flush=True), time.sleep(600)))
"""


def _children(pid: int) -> list[int]:
    """Live (not zombie) processes whose parent is ``pid``."""
    kids = []
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid and fields[0] != "Z":
            kids.append(int(stat.parent.name))
    return kids


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


@pytest.mark.skipif(not Path("/proc/self/stat").is_file(), reason="needs /proc (Linux)")
def test_killed_build_leaves_no_workers_and_never_mixes_settings(tmp_path: Path, capsys) -> None:
    out = tmp_path / "ds"
    repo = Path(__file__).resolve().parents[2]
    proc = subprocess.Popen([sys.executable, "-c", _STALLING_BUILD, str(DEEPMIMIC), str(out)],
                            cwd=repo, stdout=subprocess.PIPE, text=True)  # fmt: skip
    workers: list[int] = []
    try:
        assert proc.stdout.readline().strip() == "progress"
        workers = _children(proc.pid)
        assert len(workers) == 2, workers
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        deadline = time.monotonic() + 5.0
        while any(map(_alive, workers)) and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not any(map(_alive, workers)), "workers outlived the killed build"
    finally:
        if proc.poll() is None:
            proc.kill()
        for pid in [*workers, *_children(proc.pid)]:  # only if the test failed: no leaks
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        proc.stdout.close()
    assert not (out / "manifest.json").exists() and (out / "settings.json").is_file()
    assert list((out / "done").glob("*.json")), "the workers finished clips before the kill"
    stale = out / "sequences" / ".deepmimic__walk_v0_seq000.npz.abcd_123.tmp"
    stale.write_bytes(b"half a file")
    argv = ["data", "build", "--out", str(out), "--motions", str(DEEPMIMIC), "--limit", "4",
            "--workers", "1"]  # fmt: skip
    for other in (["--noise-variants", "2"], ["--fixed-body"], ["--seed", "1"]):
        assert main([*argv, *other]) == 2
        err = capsys.readouterr().err
        assert "different settings" in err and "settings.json" in err
    assert stale.exists(), "a refused rerun changes nothing"
    assert main(argv) == 0
    manifest = json.loads((out / "manifest.json").read_text())
    assert [c["status"] for c in manifest["clips"]] == ["done"] * 4
    assert not stale.exists() and not list(out.rglob("*.tmp"))


def test_malformed_motion_files_are_reported_and_the_others_built(tmp_path: Path,
                                                                  capsys) -> None:  # fmt: skip
    motions = tmp_path / "motions" / "mixed"
    motions.mkdir(parents=True)
    shutil.copy(DEEPMIMIC / "humanoid3d_walk.txt", motions / "walk.txt")
    shutil.copy(DEEPMIMIC / "humanoid3d_run.txt", motions / "run.txt")  # 80 frames: no sequence
    (motions / "truncated.npz").write_bytes(b"PK\x03\x04\x14\x00\x00\x00 cut short")
    (motions / "clips.csv").write_bytes(b"file,category\nwalk.txt,\xff\xfe walking\n")
    (motions / "fuzzed.bvh").write_bytes(b"HIERARCHY\nROOT Hips\n{\n OFFSET 0 0 \xff\x00 1e999\n")
    walk = (DEEPMIMIC / "humanoid3d_walk.txt").read_text()
    (motions / "cut.txt").write_text(walk[: len(walk) // 2])
    (motions / "nested.json").write_text('{"Frames": ' + "[" * 100_000)
    out = tmp_path / "ds"
    rc = main(["data", "build", "--out", str(out), "--motions", str(motions.parent),
               "--workers", "1"])  # fmt: skip
    captured = capsys.readouterr()
    err = captured.err
    assert rc == 1 and "Traceback" not in err
    manifest = json.loads((out / "manifest.json").read_text())
    skipped = {Path(s["file"]).name: s["reason"] for s in manifest["skipped_files"]}
    assert set(skipped) == {"truncated.npz", "clips.csv", "cut.txt", "nested.json"}
    assert "npz" in skipped["truncated.npz"] and "UnicodeDecodeError" in skipped["clips.csv"]
    assert "RecursionError" in skipped["nested.json"] and "JSON" in skipped["cut.txt"]
    for name in skipped:
        assert f"SKIPPED {motions / name}: " in err
    assert "4 file(s) under --motions could not be read" in err
    clips = {c["clip_id"]: c for c in manifest["clips"]}
    assert clips["mixed/walk"]["status"] == "done" and clips["mixed/walk"]["sequences"]
    assert clips["mixed/run"]["status"] == "done" and not clips["mixed/run"]["sequences"]
    assert "no sequence" in clips["mixed/run"]["note"]
    assert "1 built clip(s) gave no sequence" in captured.out
    bad = clips["mixed/fuzzed"]
    assert bad["status"] == "failed" and str(motions / "fuzzed.bvh") in bad["error"]
    line = next(ln for ln in err.splitlines() if ln.startswith("FAILED mixed/fuzzed: "))
    assert str(motions / "fuzzed.bvh") in line


def test_a_clip_replaced_in_place_is_refused_not_kept(tmp_path: Path, capsys) -> None:
    """A finished clip whose source (or AMC skeleton) now holds other contents would keep
    recordings of the old motion: the resume is refused, naming the file (issue 50, item 1)."""
    motions = tmp_path / "motions" / "mine"
    motions.mkdir(parents=True)
    shutil.copy(DEEPMIMIC / "humanoid3d_run.txt", motions / "a.txt")
    shutil.copy(DEEPMIMIC / "humanoid3d_backflip.txt", motions / "b.txt")
    cmu = MOTIONS / "cmu" / "asf_amc"
    amc = (cmu / "131_04.amc").read_text().splitlines(keepends=True)
    (motions / "131_04.amc").write_text("".join(amc[: amc.index("60\n")]))  # 59 frames
    shutil.copy(cmu / "131.asf", motions / "131.asf")
    out = tmp_path / "ds"
    argv = ["data", "build", "--out", str(out), "--motions", str(motions.parent),
            "--workers", "1"]  # fmt: skip
    assert main(argv) == 0
    done = json.loads((out / "done" / "mine__131_04.json").read_text())
    assert set(done["inputs"]) == {"clip", "skeleton"}
    # the same bytes written anew: nothing changed
    b = motions / "b.txt"
    text = b.read_bytes()
    b.unlink()
    b.write_bytes(text)
    capsys.readouterr()
    assert main(argv) == 0
    assert "3 clip(s) were finished before" in capsys.readouterr().out
    for changed in (b, motions / "131.asf"):
        before = changed.read_bytes()
        changed.write_bytes(before.replace(b"0", b"1", 1))  # replaced in place
        assert main(argv) == 2
        err = capsys.readouterr().err
        assert str(changed.resolve()) in err and "contents changed" in err
        assert "another --out" in err and "done" in err and "Traceback" not in err
        changed.write_bytes(before)
    # markers written before the records existed: nothing to compare, it resumes with a note
    for marker in (out / "done").glob("*.json"):
        d = json.loads(marker.read_text())
        del d["inputs"]
        marker.write_text(json.dumps(d))
    assert main(argv) == 0
    assert "no record of the sources of 3 finished clip(s)" in capsys.readouterr().out
    assert all("inputs" in json.loads(m.read_text()) for m in (out / "done").glob("*.json"))
