"""Ray tasks behind the interface of the local worker processes.

:class:`RayPool` runs the same calls as :class:`grip.eval.pool.WorkerPool` (a module-level
function and its picklable arguments), each as one Ray task of one CPU, and hands each result
(or the exception its call raised, with the worker's traceback as its cause) back to ``done`` on
the driver as it finishes, so the commands' progress bars, resumable outputs and per-unit failure
reports are those of the local path. A task whose worker process or node dies is not retried by
Ray: it is returned as lost, and the caller decides what that means, as with a local worker that
dies (``grip bench`` runs it again alone, ``grip data build`` and ``grip reconstruct`` report it,
``grip policy eval`` and ``grip kin eval`` stop).

The functions run in Ray's worker processes, which stay from one task to the next (what a
function caches there, such as its models, stays built). Workers read and write the paths in
their arguments themselves: on a cluster of several machines the dataset, the models and the
output folder must lie on a file system every node mounts at the same path, and the project must
be installed on every node (docs/cluster.md).
"""

from __future__ import annotations

import os
import pickle
import traceback
from collections.abc import Callable, Sequence
from typing import Any

__all__ = ["FORWARDED_ENV", "RAY_REQUIREMENT", "RayPool", "RayUnavailable", "connect",
           "import_ray"]  # fmt: skip

RAY_REQUIREMENT = "ray[tune]==2.60.0"
"""What ``pip install`` needs for ``--ray`` and ``--tune`` (also in the ``dev`` extras)."""

FORWARDED_ENV: tuple[str, ...] = ("GRIP_LIMITS", "GRIP_DEBUG", "MUJOCO_GL")
"""Environment variables of the driver that each task sees as the driver has them (a local
worker process inherits them; a Ray worker, started by the cluster, would not)."""


class RayUnavailable(RuntimeError):
    """Ray is not installed here, or the cluster cannot be reached; the message says what to
    do."""


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a Ray worker (set as that exception's cause, as
    :mod:`concurrent.futures` does for a worker process)."""

    def __init__(self, tb: str) -> None:
        super().__init__(tb)
        self.tb = tb

    def __str__(self) -> str:
        return f'\n"""\n{self.tb}"""'


def import_ray():
    """The ``ray`` module.

    Raises:
        RayUnavailable: Ray is not installed (the message gives the pip command).
    """
    try:
        import ray
    except ImportError as e:
        raise RayUnavailable(f"Ray is not installed in this environment ({e}); install it with "
                             f"pip install '{RAY_REQUIREMENT}' (it is in the dev extras: "
                             "pip install -e '.[dev]')") from e  # fmt: skip
    return ray


def connect(address: str | None = None) -> bool:
    """Connect this process to Ray, unless it already is (a caller's connection is kept).

    Args:
        address: A running cluster (``HOST:6379``, ``auto`` for the one started on this
            machine with ``ray start``, ``ray://HOST:10001`` for Ray Client). Empty or
            ``None``: a new Ray on this machine's cores, for this process alone (Ray's
            ``address="local"``: never a cluster that runs here, nor a stale record of one).

    Returns:
        Whether this call connected (the caller then disconnects: ``ray.shutdown()``).

    Raises:
        RayUnavailable: Ray is missing, or the cluster could not be reached or started.
    """
    ray = import_ray()
    if ray.is_initialized():
        return False
    kwargs: dict[str, Any] = {} if address else {"include_dashboard": False}
    try:
        ray.init(address=address or "local", **kwargs)
    except Exception as e:  # (ray raises ConnectionError, RuntimeError, ValueError, ...)
        where = f"the Ray cluster at {address}" if address else "a local Ray"
        raise RayUnavailable(f"could not connect to {where}: {type(e).__name__}: {e} (start a "
                             "cluster with 'ray start --head' on its head node, then pass the "
                             "address it prints; docs/cluster.md)") from e  # fmt: skip
    return True


def _call(fn: Callable, args: tuple, env: dict[str, str | None]) -> tuple[bool, object, str]:
    """One call in a Ray worker: ``(True, result, "")`` or ``(False, exception, traceback)``."""
    for k, v in env.items():  # (the driver's values for this call, whatever an earlier call had)
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v
    try:
        return True, fn(*args), ""
    except Exception as e:
        tb = traceback.format_exc()
        try:
            pickle.dumps(e)
        except Exception:  # an exception that cannot travel: its type and message can
            e = RuntimeError(f"{type(e).__name__}: {e}")
        return False, e, tb


def _lost_errors(ray) -> tuple[type[BaseException], ...]:
    """The Ray errors that mean a task's worker process or node died (not that it raised)."""
    x = ray.exceptions
    return (x.WorkerCrashedError, x.NodeDiedError, x.OutOfMemoryError, x.ObjectLostError,
            x.LocalRayletDiedError)  # fmt: skip


class RayPool:
    """Calls as Ray tasks of ``cpus_per_call`` CPUs each, with the interface of
    :class:`grip.eval.pool.WorkerPool` (:class:`grip.core.runs.CallPool`). A context manager:
    entering connects to Ray (:func:`connect`), leaving disconnects if entering connected.

    Args:
        address: See :func:`connect` (``None``/empty: a local Ray).
        cpus_per_call: CPUs Ray reserves for each task (Ray sets the task's thread count,
            ``OMP_NUM_THREADS``, to it).

    Attributes:
        workers: Tasks the cluster runs at once: its CPUs over ``cpus_per_call`` (at least 1;
            known once connected).
    """

    def __init__(self, address: str | None = None, cpus_per_call: float = 1.0) -> None:
        if cpus_per_call <= 0:
            raise ValueError(f"cpus_per_call must be > 0, got {cpus_per_call}")
        self.address, self.cpus_per_call = address or None, float(cpus_per_call)
        self.workers = 0
        self._ray = None
        self._owned = False
        self._remote = None

    def __enter__(self) -> RayPool:
        self._ray = import_ray()
        self._owned = connect(self.address)
        cpus = float(self._ray.cluster_resources().get("CPU", 1.0))
        self.workers = max(1, int(cpus // self.cpus_per_call))
        self._remote = self._ray.remote(_call).options(num_cpus=self.cpus_per_call,
                                                       max_retries=0)  # fmt: skip
        return self

    def __exit__(self, *exc) -> None:
        if self._owned and self._ray is not None:
            self._ray.shutdown()
        self._owned = False
        self._remote = None

    def run(self, calls: Sequence[tuple[Callable, tuple]],
            done: Callable[[int, object], object]) -> list[int]:  # fmt: skip
        """Run ``fn(*args)`` of each call as a Ray task.

        Args:
            calls: ``(fn, args)``: a module-level function (the workers import its module) and
                its picklable arguments.
            done: Called here with ``(index of the call, its result)`` as each finishes, in the
                order they finish; the result is the exception the call raised where it raised
                (its cause: the worker's traceback). If ``done`` raises, the tasks not finished
                are cancelled and the exception propagates.

        Returns:
            The indices of the calls lost because their worker process or node died (Ray does
            not retry them).

        Raises:
            RuntimeError: Used outside its ``with`` block.
        """
        if self._remote is None:
            raise RuntimeError("RayPool.run outside 'with RayPool(...) as pool:'")
        ray = self._ray
        env = {k: os.environ.get(k) for k in FORWARDED_ENV}
        refs = {self._remote.remote(fn, tuple(args), env): k for k, (fn, args) in enumerate(calls)}
        pending = list(refs)
        lost: list[int] = []
        lost_errors = _lost_errors(ray)
        try:
            while pending:
                ready, pending = ray.wait(pending, num_returns=1)
                for ref in ready:
                    k = refs[ref]
                    try:
                        ok, got, tb = ray.get(ref)
                    except lost_errors:
                        lost.append(k)
                        continue
                    except ray.exceptions.RayError as e:  # raised outside the call (a module
                        ok, got, tb = False, e, ""  # missing on a node, a BaseException)
                    if not ok and tb:
                        got.__cause__ = RemoteTraceback(tb)
                    done(k, got)
        except BaseException:
            for ref in pending:
                ray.cancel(ref)
            raise
        return sorted(lost)
