"""Worker pools end with the command that made them (issue 50, item 4): after ``kill -9`` of
``grip reconstruct`` or ``grip bench`` with ``--workers 2``, the forkserver and its workers
(~445 MB each) lived on for hours; now every process the command started is gone seconds
later, as with ``grip data build`` (tests/cli/test_data_build_robust.py)."""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
SAMPLE = ROOT / "grip" / "assets" / "sample_recording.npz"
pytestmark = pytest.mark.skipif(not Path("/proc/self/stat").is_file(),
                                reason="needs /proc (Linux)")  # fmt: skip


def _stat(pid: int) -> list[str] | None:
    """``/proc/PID/stat`` after the command name (state, ppid, ... start time at [19]), or
    ``None`` for a process that is gone or a zombie."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return None if fields[0] in "ZX" else fields


def _descendants(root: int) -> dict[int, str]:
    """Live descendants of ``root``: pid -> start time (to tell a reused pid)."""
    parent: dict[int, int] = {}
    start: dict[int, str] = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        fields = _stat(int(stat.parent.name))
        if fields is not None:
            parent[int(stat.parent.name)] = int(fields[1])
            start[int(stat.parent.name)] = fields[19]
    found: dict[int, str] = {}
    frontier = [root]
    while frontier:
        p = frontier.pop()
        for child, ppid in parent.items():
            if ppid == p and child not in found:
                found[child] = start[child]
                frontier.append(child)
    return found


def _survivors(seen: dict[int, str]) -> list[int]:
    return [pid for pid, t in seen.items() if (f := _stat(pid)) is not None and f[19] == t]


def _kill_when_working(argv: list[str], cwd: Path, workers: int = 2) -> dict[int, str]:
    """Start ``grip ARGV``, wait until it runs ``workers`` pool workers (processes two levels
    below it: forkserver -> worker) that have been up a few seconds, SIGKILL it; returns every
    process it started."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen([sys.executable, "-m", "grip.cli.main", *argv], cwd=cwd, env=env,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)  # fmt: skip
    seen: dict[int, str] = {}
    try:
        deadline = time.monotonic() + 240
        ready_at = None
        while time.monotonic() < deadline and proc.poll() is None:
            kids = _descendants(proc.pid)
            seen.update(kids)
            grandchildren = [p for p in kids if (f := _stat(p)) and int(f[1]) != proc.pid]
            if len(grandchildren) >= workers and ready_at is None:
                ready_at = time.monotonic() + 3.0  # (the workers are loading their models)
            if ready_at is not None and time.monotonic() > ready_at:
                break
            time.sleep(0.2)
        if proc.poll() is not None:
            tail = proc.stderr.read().decode()[-2000:]
            raise AssertionError(f"the command ended before its workers ran: {tail}")
        assert ready_at is not None, "no pool workers started"
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        end = time.monotonic() + 10.0
        while _survivors(seen) and time.monotonic() < end:
            time.sleep(0.2)
        return seen
    finally:
        if proc.poll() is None:
            proc.kill()
        for pid in _survivors(seen):  # only if the test fails: leave nothing behind
            os.kill(pid, signal.SIGKILL)
        proc.stderr.close()


def test_killed_reconstruct_leaves_no_workers(tmp_path: Path) -> None:
    recs = []
    for i in range(24):  # (work that outlasts the workers' start when idle: 4 took 3 s)
        recs.append(tmp_path / f"rec{i}.npz")
        shutil.copy(SAMPLE, recs[-1])
    argv = ["reconstruct", *map(str, recs), "--out", str(tmp_path / "out"), "--workers", "2"]
    seen = _kill_when_working(argv, tmp_path)
    assert len(seen) >= 3, seen  # the forkserver and two workers at least
    assert not _survivors(seen), f"outlived the killed reconstruct: {_survivors(seen)}"


def test_killed_bench_leaves_no_workers(tmp_path: Path, walk_takes: Path) -> None:
    argv = ["bench", "--data", str(walk_takes), "--out", str(tmp_path / "bench"), "--methods",
            "grip", "--segment-frames", "100", "--workers", "2"]  # fmt: skip
    seen = _kill_when_working(argv, tmp_path)
    assert len(seen) >= 3, seen
    assert not _survivors(seen), f"outlived the killed bench: {_survivors(seen)}"
