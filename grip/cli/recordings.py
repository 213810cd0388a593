"""Recordings and KinematicsNet checkpoints as the commands take them (errors -> CliError),
and the ``--input-limit NAME=VALUE`` option of the commands that read input files."""

from __future__ import annotations

import argparse
import fnmatch
import os
import sys
from collections.abc import Sequence
from pathlib import Path


def split_paths(data: Path, split: str) -> list[Path]:
    """The recording files of a dataset split."""
    from grip.cli.errors import CliError
    from grip.kinematics.dataset import split_files

    try:
        return split_files(data, split)
    except (OSError, ValueError) as e:
        raise CliError(str(e)) from e


LIMIT_HELP = (
    "raise or lower one limit on input files, NAME=VALUE (VALUE a number or inf; repeatable), "
    "for genuine long or unusual takes. Also settable for every process as "
    "GRIP_LIMITS=NAME=VALUE,NAME=VALUE. Limits and defaults: "
)

LoadErrors = list[tuple[str, str]]
"""``(file, reason)`` of each input file a command skipped."""


def add_limit_arguments(parser: argparse.ArgumentParser) -> None:
    """Adds the repeatable ``--input-limit NAME=VALUE`` option
    (:class:`grip.core.limits.InputLimits`)."""
    from grip.core.limits import limit_help

    parser.add_argument("--input-limit", action="append", default=[], metavar="NAME=VALUE",
                        dest="input_limits", help=LIMIT_HELP + limit_help())  # fmt: skip


def limits_from_args(args: argparse.Namespace):
    """The limits in force for a command: ``$GRIP_LIMITS`` overridden by its ``--input-limit``
    options.

    Given options make them the limits of this process and of the worker processes it starts
    (:func:`grip.core.limits.set_active_limits`), so every loader applies them.

    Returns:
        The :class:`grip.core.limits.InputLimits`.

    Raises:
        CliError: An unknown limit name or a bad value (the message lists the names).
    """
    from grip.cli.errors import CliError
    from grip.core.limits import active_limits, set_active_limits

    items = getattr(args, "input_limits", None) or []
    try:
        limits = active_limits().with_overrides(items)
    except ValueError as e:
        raise CliError(f"--input-limit: {e}") from e
    if items:
        set_active_limits(limits)
    return limits


def _reason(path: str, err: BaseException) -> str:
    """The message of ``err`` without a leading ``path:`` (loaders start with it)."""
    text = str(err)
    return text[len(path) + 1 :].strip() if text.startswith(f"{path}:") else text


def skip_file(errors: LoadErrors, path: str | os.PathLike, err: BaseException | str) -> None:
    """Records a skipped input file and reports it at once: ``grip: error: FILE: reason``."""
    path = str(path)
    reason = err if isinstance(err, str) else _reason(path, err)
    errors.append((path, reason))
    print(f"grip: error: {path}: {reason}", file=sys.stderr, flush=True)


def exit_status(errors: LoadErrors, n_files: int | None = None) -> int:
    """A command's exit code after its work: 0, or 1 when input files were skipped (then a
    closing line on stderr says how many)."""
    if not errors:
        return 0
    of = f" of {n_files}" if n_files is not None else ""
    print(f"grip: {len(errors)}{of} input file(s) were skipped (unreadable or refused; see the "
          "errors above); the results cover the others", file=sys.stderr)  # fmt: skip
    return 1


def load_recordings(
    files: Sequence[str | os.PathLike],
    categories: Sequence[str] = (),
    segment_frames: int = 0,
    max_frames: int = 0,
    limit: int = 0,
    fill_gaps: int = 0,
    segment_stride: int = 0,
    errors: LoadErrors | None = None,
) -> list:
    """Load recordings, keeping those whose category matches a glob of ``categories`` (all when
    empty); crop each to ``max_frames``, or cut it into ``segment_frames``-frame segments (a
    shorter tail is left out; with ``segment_stride`` a segment starts every that many frames,
    overlapping when it is below ``segment_frames``); stop at ``limit`` recordings or segments
    (0: no limit). Sensor dropouts (NaN runs) of at most ``fill_gaps`` frames are interpolated
    (:func:`prism_tools.gaps.fill_gaps`, listed in ``extras["filled_gaps"]``); longer ones are
    an error.

    A file that cannot be read (corrupt, hostile, above the input limits): with ``errors=None``
    the first one ends the command (``CliError``); with an ``errors`` list it is reported on
    stderr (``grip: error: FILE: reason``), appended to ``errors`` as ``(file, reason)`` and
    skipped, and the command goes on with the others (finish with :func:`exit_status`).

    Raises:
        CliError: A file cannot be read and ``errors`` is ``None`` (the message names it), or
            nothing is selected (with ``errors``: no file was readable).
    """
    from grip.cli.errors import CliError
    from prism_tools.chunking import segments
    from prism_tools.io import load_recording

    recs: list = []
    for f in files:
        try:
            rec = load_recording(f, fill_gaps=fill_gaps)
        except (OSError, ValueError) as e:
            if errors is None:
                raise CliError(str(e)) from e
            skip_file(errors, f, e)
            continue
        cat = rec.category or "unknown"
        if categories and not any(fnmatch.fnmatch(cat, c) for c in categories):
            continue
        if max_frames and rec.n_frames > max_frames:
            rec = rec.slice_frames(0, max_frames)
        if segment_frames:
            cuts = segments(rec.n_frames, segment_frames, min_length=segment_frames,
                            stride=segment_stride)  # fmt: skip
            recs += [rec.slice_frames(sl.start, sl.stop) for sl in cuts]
        else:
            recs.append(rec)
        if limit and len(recs) >= limit:
            return recs[:limit]
    if not recs:
        what = f" of categories {list(categories)}" if categories else ""
        bad = f" ({len(errors)} unreadable)" if errors else ""
        raise CliError(f"no recordings{what} selected from {len(files)} file(s){bad}")
    return recs


def kin_checkpoint(path: Path | None, flag: str = "--kin") -> Path:
    """``path`` or the shipped KinematicsNet checkpoint, which must exist."""
    from grip.assets import SHIPPED_KIN
    from grip.cli.errors import CliError

    kin = Path(path) if path is not None else SHIPPED_KIN
    if not kin.is_file():
        raise CliError(f"{kin}: no such KinematicsNet checkpoint (train one with 'grip kin train' "
                       f"and pass {flag} RUN/best.pt)")  # fmt: skip
    return kin


TTA_HELP = (
    "test-time augmentation of KinematicsNet: average its estimates of the input turned about "
    "the vertical and mirrored left-right, each mapped back ('mirror': 2 copies, 'yaw4': 4 "
    "turns, 'full': both, 8 copies; default 'none'). More accurate, n times the computation"
)


def add_tta_argument(parser) -> None:
    """The ``--tta`` option of the commands that run KinematicsNet."""
    from grip.kinematics.features import TTA_MODES

    parser.add_argument("--tta", default="none", choices=tuple(TTA_MODES), help=TTA_HELP)


def add_init_argument(parser, what: str = "KinematicsNet", note: str = "") -> None:
    """The ``--init truth|standing`` option of the commands that start on recordings: where
    ``what`` start on each segment or recording (for the help; ``note`` ends it)."""
    from grip.kinematics.features import INITS

    parser.add_argument(
        "--init", default="truth", choices=INITS,
        help=f"where {what} start on each segment: 'truth' (default, the GRIP protocol), the "
        "ground truth of its first frame; 'standing', the standing rest pose at rest, turned "
        "to the heading of the foot IMUs, as a user without motion capture must start (no "
        "ground-truth pose is read; on a recording with ground truth the standing pelvis is "
        f"put at its frame-0 horizontal position, so that trajectories share an origin){note}",
    )  # fmt: skip


def add_restart_argument(parser) -> None:
    """The ``--restart simulated|estimate`` option of the commands that play GRIP with fall
    recovery (:attr:`grip.player.RecoveryConfig.restart`)."""
    from grip.player import RESTARTS, RecoveryConfig

    parser.add_argument(
        "--restart", default=RecoveryConfig().restart, choices=RESTARTS,
        help="where the humanoid's root restarts after a fall: 'simulated', GRIP's rule (its "
        "pelvis 0.3 s before the fall plus the estimated displacement since: distance lost "
        "before the fall stays lost), or 'estimate', the estimate's own pelvis: 24 %% lower "
        "world error on the split by person (default "
        f"{RecoveryConfig().restart!r}; docs/pace.md)",
    )  # fmt: skip
    parser.add_argument(
        "--lost-gap", type=float, default=RecoveryConfig().lost_gap_m, metavar="M",
        help="recover the humanoid like a fall when its pelvis is farther than M metres "
        "(horizontally) from the pelvis it follows, though it stands (counted as a fall; "
        f"0: off, only falls; default {RecoveryConfig().lost_gap_m:g}; docs/pace.md, 'Lost')",
    )  # fmt: skip


def lost_gap(args: argparse.Namespace) -> float:
    """``--lost-gap`` (:func:`add_restart_argument`), m.

    Raises:
        CliError: A negative gap.
    """
    from grip.cli.errors import CliError

    if not args.lost_gap >= 0.0:
        raise CliError(f"--lost-gap must be >= 0 (0: off), got {args.lost_gap:g}")
    return float(args.lost_gap)


def add_pace_arguments(parser) -> None:
    """The pace keeper's options (:class:`grip.player.PaceKeeper`) of the commands that play
    GRIP; :func:`pace_keeper` reads them."""
    from grip.player import PaceKeeper

    d = PaceKeeper()
    parser.add_argument(
        "--pace-gain", type=float, default=d.gain, metavar="K",
        help="pace keeper: the pelvis the controller is shown leads the estimate's by K x the "
        f"humanoid's horizontal gap to it, at most --pace-lead-max (default {d.gain:g}; 0: off; "
        "only controllers that read the followed pelvis' position see it; docs/pace.md)",
    )  # fmt: skip
    parser.add_argument("--pace-lead-max", type=float, default=d.lead_max_m, metavar="M",
                        help=f"pace keeper: the longest lead, m (default {d.lead_max_m:g})")
    parser.add_argument(
        "--lean-gain", type=float, default=d.lean_gain_deg, metavar="D",
        help="lean keeper: the followed upper body leans D deg further forward per metre the "
        f"humanoid's pelvis is behind the estimate's, at most --lean-max (default "
        f"{d.lean_gain_deg:g}; 0: off; docs/pace.md, the lean keeper)",
    )  # fmt: skip
    parser.add_argument("--lean-max", type=float, default=d.lean_max_deg, metavar="D",
                        help=f"lean keeper: the largest lean, deg (default {d.lean_max_deg:g})")


def pace_keeper(args: argparse.Namespace):
    """The :class:`grip.player.PaceKeeper` of :func:`add_pace_arguments`' options.

    Raises:
        CliError: A value out of range."""
    from grip.cli.errors import CliError
    from grip.player import PaceKeeper

    try:
        return PaceKeeper(gain=args.pace_gain, lead_max_m=args.pace_lead_max,
                          lean_gain_deg=args.lean_gain, lean_max_deg=args.lean_max)
    except ValueError as e:
        raise CliError(f"--pace-gain {args.pace_gain:g} --pace-lead-max {args.pace_lead_max:g} "
                       f"--lean-gain {args.lean_gain:g} --lean-max {args.lean_max:g}: "
                       f"{e}") from e


def reversed_training_recordings(data: Path, files: Sequence[Path | str],
                                 categories: Sequence[str]) -> list:  # fmt: skip
    """The time-reversed recordings of the clips of ``categories`` among the training sequence
    files (or file stems) ``files`` (``reverse_categories`` of ``grip policy distill``,
    :mod:`grip.dataset.augment`), with a progress bar; refuses globs that select nothing."""
    from grip.dataset.augment import time_reversed_recordings

    return _augmented(data, files, categories, "reverse_categories", "time-reversed", 1,
                      lambda stems, bar: time_reversed_recordings(data, stems, categories,
                                                                  progress=bar))  # fmt: skip


def speed_scaled_training_recordings(data: Path, files: Sequence[Path | str],
                                     categories: Sequence[str],
                                     factors: Sequence[float]) -> list:  # fmt: skip
    """The recordings of the clips of ``categories`` among the training sequence files
    ``files`` played each of ``factors`` times faster (``speed_factors`` of ``grip policy
    train``, :mod:`grip.dataset.augment`), with a progress bar; refuses globs that select
    nothing."""
    from grip.dataset.augment import time_scaled_recordings

    return _augmented(data, files, categories, "speed_categories", "speed-scaled", len(factors),
                      lambda stems, bar: time_scaled_recordings(data, stems, categories, factors,
                                                                progress=bar))  # fmt: skip


def _augmented(data: Path, files: Sequence[Path | str], categories: Sequence[str], setting: str,
               what: str, per_clip: int, make) -> list:  # fmt: skip
    from tqdm import tqdm

    from grip.cli.errors import CliError
    from grip.dataset.augment import reversed_clip_ids

    stems = [Path(f).stem for f in files]
    try:
        n = len(reversed_clip_ids(data, stems, categories))
        if n == 0:
            raise CliError(f"{setting}={list(categories)}: no training clip of {data} "
                           "has such a category")  # fmt: skip
        with tqdm(total=n * per_clip, unit="clip", desc=f"{what} motions") as bar:
            recs = make(stems, bar.update)
    except ValueError as e:
        raise CliError(str(e)) from e
    print(f"{len(recs)} {what} recordings of {n} training clips "
          f"({', '.join(categories)})")  # fmt: skip
    return recs
