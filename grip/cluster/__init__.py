"""The commands' work on a Ray cluster (``--ray [ADDRESS]``, ``--tune SPACE.toml``).

Stdlib only at import: Ray is imported when a pool or a sweep first needs it, so ``grip --help``
never loads it, and a missing Ray is a :class:`RayUnavailable` that says how to install it.

* :class:`RayPool` (:mod:`grip.cluster.ray_pool`): the units of work of ``grip data build``,
  ``grip bench``, ``grip reconstruct``, ``grip policy eval`` and ``grip kin eval`` as Ray tasks,
  behind the interface of the local worker processes (:class:`grip.core.runs.CallPool`).
* :func:`run_sweep` (:mod:`grip.cluster.sweep`): a hyper-parameter sweep of ``grip kin train``
  or ``grip policy train`` through Ray Tune, one trial per run folder, resumable.
"""

from __future__ import annotations

from grip.cluster.ray_pool import RAY_REQUIREMENT, RayPool, RayUnavailable, connect, import_ray
from grip.cluster.sweep import (
    SweepSpace,
    Trial,
    TrialFailed,
    TrialResult,
    expand_trials,
    load_space,
    results_table,
    run_sweep,
    write_results,
)

__all__ = [
    "RAY_REQUIREMENT",
    "RayPool",
    "RayUnavailable",
    "SweepSpace",
    "Trial",
    "TrialFailed",
    "TrialResult",
    "connect",
    "expand_trials",
    "import_ray",
    "load_space",
    "results_table",
    "run_sweep",
    "write_results",
]
