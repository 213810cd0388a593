"""``grip policy eval --workers K``: whole batches of ``--batch N`` segments played in worker
processes give rows bit-identical to ``--workers 1`` (falls and frame counts included, with
either init and reference, with action noise over replays), in segment order; a segment that
raises raises as in one process, and a worker that dies is reported."""

from __future__ import annotations

import math
import os
import re
from pathlib import Path

import pytest

from grip.assets import SHIPPED_KIN, SHIPPED_POLICY
from grip.cli.main import main
from grip.eval import policy as P
from grip.eval.pool import WorkerPool
from grip.eval.segments import BenchError, Segment, list_segments, split_files

FRAMES = 40  # the shipped policy falls on some of these synthetic segments (from the truth)
BATCH = 5  # 12 segments: batches of 5, 5 and 2


@pytest.fixture(scope="module")
def dataset(walk_takes) -> Path:
    return walk_takes


@pytest.fixture(scope="module")
def segments(dataset) -> list[Segment]:
    return list_segments(split_files(dataset, "test"), FRAMES)


@pytest.fixture(scope="module")
def setup() -> P.PolicySetup:
    return P.PolicySetup((str(SHIPPED_POLICY),), str(SHIPPED_KIN))


@pytest.fixture(scope="module")
def built(setup):
    return setup.build()


@pytest.fixture(scope="module")
def pool():
    """Two workers kept for the module (each builds the models once)."""
    with WorkerPool(2) as p:
        yield p


def _same(a: dict, b: dict) -> bool:
    return a.keys() == b.keys() and all(
        a[k] == b[k] or (isinstance(a[k], float) and math.isnan(a[k]) and math.isnan(b[k]))
        for k in a
    )


@pytest.mark.parametrize(("init", "reference"), [("truth", "estimate"), ("truth", "truth"),
                                                 ("standing", "truth")])  # fmt: skip
def test_rows_are_bit_identical_whatever_the_workers(segments, setup, built, pool, init,
                                                     reference) -> None:  # fmt: skip
    kw = {"init": init, "reference": reference}
    done: list[int] = []
    (one,) = P.evaluate_batches(setup, segments, BATCH, 1, built=built, **kw)
    (two,) = P.evaluate_batches(setup, segments, BATCH, pool=pool, progress=done.append, **kw)
    assert len(segments) == 12 and sorted(done) == [2, 5, 5]
    assert [r["segment"] for r in two] == [s.id for s in segments]  # merged in segment order
    assert [(r["fell"], r["frames"]) for r in two] == [(r["fell"], r["frames"]) for r in one]
    assert all(_same(a, b) for a, b in zip(one, two, strict=True))
    if (init, reference) == ("truth", "truth"):  # both outcomes, and several lengths
        assert len({r["fell"] for r in one}) == 2 and len({r["frames"] for r in one}) > 1


def test_a_segment_that_raises_raises_as_in_one_process(segments, setup, built, pool,
                                                        tmp_path) -> None:  # fmt: skip
    bad = tmp_path / "broken.npz"
    bad.write_bytes(b"not a recording")
    segs = [*segments[:BATCH], Segment("broken_f000000", bad, 0, FRAMES, "walk")]
    with pytest.raises(Exception) as here:  # (whatever the reader raises)
        P.evaluate_batches(setup, segs, BATCH, 1, built=built)
    with pytest.raises(type(here.value), match=re.escape(str(here.value)[:40])):
        P.evaluate_batches(setup, segs, BATCH, pool=pool)


def test_a_worker_that_dies_is_reported(segments, setup) -> None:
    with WorkerPool(2) as p:  # a real death: the pool reports the unfinished calls lost
        got: dict[int, object] = {}
        lost = p.run([(abs, (-1,)), (os._exit, (3,))], got.__setitem__)
        assert 1 in lost and set(lost) | set(got) == {0, 1}
        assert p.run([(abs, (-2,))], got.__setitem__) == [] and got[0] == 2  # new workers

    class Dying:  # what a pool whose worker died on the second batch reports
        workers = 2

        def run(self, calls, done):
            done(0, [])
            return [1]

    with pytest.raises(BenchError, match=rf"worker process died.*{segments[BATCH].id}"):
        P.evaluate_batches(setup, segments, BATCH, pool=Dying())


def test_cli_workers_write_the_same_files(dataset, tmp_path) -> None:
    """--workers 2 against 1 with action noise over two replays (each batch its own noise
    generator), from the standing pose and following the truth."""
    base = ["policy", "eval", "--data", str(dataset), "--segment-frames", str(FRAMES),
            "--batch", str(BATCH), "--init", "standing", "--reference", "truth",
            "--action-noise", "0.5", "--repeats", "2"]  # fmt: skip
    text = {}
    for k in (1, 2):
        out = tmp_path / f"w{k}"
        assert main([*base, "--workers", str(k), "--out", str(out),
                     "--json", str(out / "eval.json")]) == 0  # fmt: skip
        text[k] = [(out / f).read_text() for f in ("segments.csv", "summary.md", "eval.json")]
    assert text[1] == text[2]
    assert len(text[1][0].splitlines()) == 1 + 2 * 12
    assert main([*base, "--workers", "0"]) == 2
