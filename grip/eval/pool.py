"""Worker processes of the evaluations (``grip bench --workers``, ``grip policy eval --workers``).

:class:`WorkerPool` runs module-level functions in worker processes that use one BLAS thread
each (torch's thread count is the worker functions' to set: :func:`one_torch_thread`), and hands
each result (or the exception its call raised) back as it finishes. A worker that dies breaks the
pool: the calls not finished are returned as lost, and the caller decides what that means
(``grip bench`` runs them again, ``grip policy eval`` reports them).
"""

from __future__ import annotations

import multiprocessing as mp
import os
import sys
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager

from grip.core.runs import exit_with_process, process_start

__all__ = ["THREAD_VARS", "WorkerPool", "one_torch_thread", "run_pool", "start_method"]

THREAD_VARS: tuple[str, ...] = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS")
"""The BLAS thread counts set to 1 for the workers."""


def start_method() -> str:
    """How workers start: ``forkserver`` where there is one (no copy of this process' threads
    and models), else ``spawn``."""
    return "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"


@contextmanager
def one_torch_thread() -> Iterator[None]:
    """torch (where imported) on one thread inside, as in a worker process, restored after: the
    numbers and runtimes of work done here compare with a worker's."""
    torch = sys.modules.get("torch")
    prev = torch.get_num_threads() if torch is not None else 0
    if torch is not None:
        torch.set_num_threads(1)
    try:
        yield
    finally:
        if torch is not None:
            torch.set_num_threads(prev)


class WorkerPool:
    """Up to ``workers`` worker processes, kept from one :meth:`run` to the next (what a worker
    built, such as its models, stays built), started when first needed. A context manager: the
    workers end, and the thread variables are restored, on leaving it. Each worker also ends
    within :data:`grip.core.runs.PARENT_POLL_S` seconds of the process that made the pool (a
    command killed with SIGKILL leaves no worker and, with them, no forkserver behind).

    Args:
        workers: Processes, >= 1.
        initializer: Run once in each worker before its first call.
    """

    def __init__(self, workers: int, initializer: Callable[[], object] | None = None) -> None:
        self.workers, self.initializer = max(1, int(workers)), initializer
        self._pool: ProcessPoolExecutor | None = None
        self._saved: dict[str, str | None] = {}

    def __enter__(self) -> WorkerPool:
        # one BLAS thread per worker: set before the workers (and the forkserver) start, because
        # OpenBLAS reads it when numpy is first imported
        self._saved = {v: os.environ.get(v) for v in THREAD_VARS}
        os.environ.update(dict.fromkeys(THREAD_VARS, "1"))
        return self

    def __exit__(self, kind, *exc) -> None:
        try:
            self._close(wait=kind is None)
        finally:
            for v, old in self._saved.items():
                if old is None:
                    os.environ.pop(v, None)
                else:
                    os.environ[v] = old

    def _close(self, wait: bool) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=wait, cancel_futures=True)
            self._pool = None

    def run(self, calls: Sequence[tuple[Callable, tuple]],
            done: Callable[[int, object], object]) -> list[int]:  # fmt: skip
        """Run ``fn(*args)`` of each call in the workers.

        Args:
            calls: ``(fn, args)``: a module-level function (workers import it) and its
                picklable arguments.
            done: Called here with ``(index of the call, its result)`` as each finishes, in
                the order they finish; the result is the exception the call raised where it
                raised. If ``done`` raises, the calls not yet started are cancelled and the
                exception propagates (the workers stay for the next run).

        Returns:
            The indices of the calls lost because a worker process died (a crash, out of
            memory): the one running in it and every other unfinished one. The next run starts
            new workers.
        """
        if self._pool is None:
            ctx = mp.get_context(start_method())
            me = os.getpid()
            init = (me, process_start(me), self.initializer)
            self._pool = ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx,
                                             initializer=_start_worker,
                                             initargs=init)  # fmt: skip
        futures = {self._pool.submit(fn, *args): k for k, (fn, args) in enumerate(calls)}
        lost: list[int] = []
        try:
            for fut in as_completed(futures):
                k = futures[fut]
                try:
                    got = fut.result()
                except BrokenProcessPool:
                    lost.append(k)
                    continue
                except Exception as e:
                    got = e
                done(k, got)
        except BaseException:
            for fut in futures:
                fut.cancel()  # (those not started)
            raise
        if lost:
            self._close(wait=True)  # (broken: no further call would run)
        return sorted(lost)


def _start_worker(owner: int, owner_start: str | None,
                  initializer: Callable[[], object] | None) -> None:  # fmt: skip
    """Every worker's initializer: end with the process that made the pool (its parent is the
    forkserver: :func:`grip.core.runs.exit_with_process`), then ``initializer``."""
    exit_with_process(owner, owner_start)
    if initializer is not None:
        initializer()


def run_pool(calls: Sequence[tuple[Callable, tuple]], workers: int,
             done: Callable[[int, object], object],
             initializer: Callable[[], object] | None = None) -> list[int]:  # fmt: skip
    """:meth:`WorkerPool.run` in a pool of ``min(workers, len(calls))`` processes for these
    calls alone."""
    with WorkerPool(min(workers, len(calls)), initializer) as pool:
        return pool.run(calls, done)
