"""``grip reconstruct``: recordings -> physically plausible motion (KinematicsNet + policy)."""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import os
import sys
from collections import Counter
from collections.abc import Mapping, Sequence
from pathlib import Path


def add_parser(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser(
        "reconstruct",
        help="reconstruct PRISM-format recordings with GRIP (KinematicsNet + policy + recovery)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Load PRISM-format recordings (real PRISM pickles or ours), run KinematicsNet,\n"
            "drive the simulated humanoid with the policy in MuJoCo, recover from falls with\n"
            "GRIP's history buffer, and write per recording OUT/<name>.npz (joint positions and\n"
            "rotations, root trajectory, per-foot GRF and CoP, joint torques, contacts, fall\n"
            "events; keys in grip/core/reconstruction.py) plus the exports of --formats, and\n"
            "OUT/summary.json. <name> is the input's path below the inputs' common folder\n"
            "('/' as '__', no suffix): the file name for files of one folder; two inputs never\n"
            "share one (a clash gets the suffix appended, then -2, -3, ...).\n"
            "Recordings already reconstructed in OUT are skipped (resume); a resume with other\n"
            "settings (--max-frames, --no-recovery, --history, --fill-gaps, the models' contents)\n"
            "or over an input replaced in place (compared by SHA-256) is refused, --overwrite\n"
            "redoes them.\n"
            "The recording's first frame is the calibration pose the humanoid starts from\n"
            "(its ground truth, or the standing pose at the foot IMUs' heading without one or\n"
            "with --init standing; with ground truth, standing is placed at its frame-0 x, y).\n"
            "Sensor dropouts (NaN runs) up to --fill-gaps frames are interpolated; a recording\n"
            "with longer ones, or without a sensor the models read (an IMU site, an insole),\n"
            "is reported and skipped, the others go on (exit status 1)."
        ),
        epilog="example: grip reconstruct data/prism_synth/sequences/*walk*.npz --out recon\n"
        "         grip reconstruct take.pkl --out recon --formats npz,bvh,png --workers 2",
    )
    p.add_argument("recordings", nargs="+", type=Path, help="recordings (.pkl/.npz)")
    p.add_argument("--out", required=True, type=Path, help="output folder")
    p.add_argument("--policy", type=Path, default=None,
                   help="policy export (default: the shipped grip/assets/policy_default.pt)")
    p.add_argument("--kin", type=Path, default=None,
                   help="KinematicsNet checkpoint (default: the shipped one)")
    p.add_argument("--workers", type=int, default=1,
                   help="parallel processes, each on a share of the recordings (default 1)")
    p.add_argument("--batch", type=int, default=16, metavar="N",
                   help="recordings played side by side in each process, one controller "
                   "forward per frame over all of them (default 16; 1: one after another); "
                   "the numbers of each alone up to the float32 rounding of a batched "
                   "forward, which a simulation can amplify")  # fmt: skip
    p.add_argument("--no-recovery", action="store_true",
                   help="report falls but do not recover from them (the humanoid stays down)")
    p.add_argument("--history", type=int, default=30,
                   help="history buffer length N in frames (default 30 = 0.3 s)")
    p.add_argument("--max-frames", type=int, default=0,
                   help="crop each recording to its first N frames (0: all)")
    p.add_argument("--formats", default="npz",
                   help="comma-separated: npz (always), bvh, glb, mp4, png, amass, html "
                   "(default npz)")  # fmt: skip
    p.add_argument("--fill-gaps", type=int, default=10, metavar="N",
                   help="interpolate sensor dropouts (NaN runs) of up to N frames, listed in "
                        "summary.json; longer ones fail the recording (default 10 = 0.1 s; 0: "
                        "any NaN fails it)")  # fmt: skip
    p.add_argument("--overwrite", action="store_true", help="redo recordings already in OUT")
    from grip.cli.cluster import add_ray_argument
    from grip.cli.recordings import (
        add_init_argument,
        add_limit_arguments,
        add_pace_arguments,
        add_restart_argument,
    )

    add_init_argument(p, "KinematicsNet and the humanoid")
    add_restart_argument(p)
    add_pace_arguments(p)
    add_ray_argument(p, "shares of the recordings (--batch N each)")
    add_limit_arguments(p)
    p.set_defaults(func=cmd_reconstruct)


def safe_name(name: str) -> str:
    """A file name for a recording name (path separators and odd characters replaced)."""
    keep = "".join(c if c.isalnum() or c in "-_.+" else "_" for c in name.replace("/", "__"))
    return keep.strip(".") or "recording"


def output_stems(files: Sequence[Path], reserved: Mapping[str, str] | None = None
                 ) -> dict[Path, str]:  # fmt: skip
    """The output file stem of each input, unique among the inputs and the outputs kept.

    The stem is the input's path relative to the inputs' common folder, without its suffix and
    with ``/`` as ``__`` (``safe_name``): files of one folder keep their own names. Inputs whose
    stems clash (``take.pkl`` and ``take.npz``, or two paths ``safe_name`` maps alike) get their
    suffix appended (``take_pkl``, ``take_npz``), and a stem still taken (by another input or
    by ``reserved``) gets ``-2``, ``-3``, ... in input order. Decided before any work starts, so
    the names do not depend on ``--workers``.

    Args:
        files: The inputs, resolved and without duplicates, in command-line order.
        reserved: ``{stem: file}`` of outputs already in the folder (from ``summary.json``);
            an input listed there keeps its stem, no other input gets it.

    Returns:
        ``{file: stem}`` for every input.
    """
    reserved = dict(reserved or {})
    kept = {Path(f): stem for stem, f in reserved.items()}
    if not files:
        return {}
    root = Path(os.path.commonpath([str(f.parent) for f in files]))
    rel = {f: f.relative_to(root) for f in files}
    base = {f: safe_name(r.with_suffix("").as_posix()) for f, r in rel.items()}
    clash = {b for b in base.values() if list(base.values()).count(b) > 1}
    base = {f: safe_name(f"{rel[f].with_suffix('').as_posix()}_{f.suffix.lstrip('.')}")
            if b in clash else b for f, b in base.items()}  # fmt: skip
    used = set(reserved)
    stems: dict[Path, str] = {}
    for f in files:  # inputs with an output already keep its name
        if f in kept:
            stems[f] = kept[f]
    for f in files:
        if f in stems:
            continue
        stem, k = base[f], 1
        while stem in used:
            k += 1
            stem = f"{base[f]}-{k}"
        used.add(stem)
        stems[f] = stem
    return stems


def check_inputs(rows: Mapping[str, dict], inputs: Sequence[Path], where: Path) -> int:
    """Refuse to resume when an input was replaced since its output was written.

    Each summary row records its input's contents (``"input"``, a
    :data:`grip.core.digests.Record`); a file whose size and times still match its record is
    not read again. A row without one (written by an older version) has nothing to compare:
    it gets the input's record now and is counted.

    Args:
        rows: ``{resolved input: summary row}`` of the outputs kept (updated in place).
        inputs: This run's inputs, resolved.
        where: The summary file (named in the message).

    Returns:
        How many rows had no record.

    Raises:
        CliError: An input's contents differ from its row's record (the message names it).
    """
    from grip.cli.errors import CliError
    from grip.core.digests import FileDigests, change_text, same_contents

    digests = FileDigests()
    changed: list[str] = []
    unrecorded = 0
    for f in inputs:
        row = rows.get(str(f))
        if row is None:
            continue
        old = row.get("input")
        rec = digests.record(f, known=old)
        if old is None:
            unrecorded += 1
        elif not same_contents(old, rec):
            changed.append(change_text(f, old, rec))
            continue
        row["input"] = rec
    if changed:
        more = f" (and {len(changed) - 1} other input(s))" if len(changed) > 1 else ""
        raise CliError(f"{where}: {changed[0]}{more} since it was reconstructed in "
                       f"{where.parent}; a resume would keep outputs of the old contents: use "
                       "--overwrite to redo them, or another --out to start afresh")  # fmt: skip
    return unrecorded


def _row_formats(row: Mapping) -> set[str]:
    """Formats a summary row was made with (older summaries: from its files and failures)."""
    if "formats" in row:
        return set(row["formats"])
    got = {Path(w).suffix.lstrip(".") for w in row.get("written", [])}
    return got | set(row.get("failed", {}))


def policy_checkpoint(path: Path | None) -> Path:
    """``path`` or the shipped policy, which must exist."""
    from grip.assets import SHIPPED_POLICY
    from grip.cli.errors import CliError

    p = path or SHIPPED_POLICY
    if not Path(p).is_file():
        hint = "" if path else " (no policy ships yet: pass --policy RUN/policy.pt)"
        raise CliError(f"policy checkpoint {p} not found{hint}")
    return Path(p)


_LOADED: dict = {}


def _work(job: tuple) -> list[dict]:
    """One worker: reconstruct a share of the recordings (``batch`` of them side by side) and
    write their files. A recording that cannot be read or does not carry the sensors the models
    need gives a row with an ``"error"`` (the others go on)."""
    files, out, policy, kin, (recovery, pace), max_frames, formats, fill_gaps, batch, threads, \
        init = job  # fmt: skip
    import torch

    torch.set_num_threads(1)
    from grip.cli.errors import CliError
    from grip.cli.recordings import load_recordings
    from grip.core.digests import FileDigests
    from grip.eval.reconstruct import GripReconstructor

    key = (policy, kin, recovery, pace)
    g = _LOADED.get(key)
    if g is None:  # each worker process loads the models once
        _LOADED.clear()
        g = _LOADED[key] = GripReconstructor.from_files(policy, kin, recovery, pace)
    caught = (CliError, KeyError, ValueError, OSError)
    loaded: list = []  # (f, stem, recording or the error reading it)
    digests = FileDigests()
    inputs = {}  # what each file held when it was read (the resume check's record)
    for f, stem in files:
        inputs[f] = digests.record(f)
        try:
            (rec,) = load_recordings([f], max_frames=max_frames, fill_gaps=fill_gaps)
        except caught as e:
            rec = e
        loaded.append((f, stem, rec))
    recs = [r for _, _, r in loaded if not isinstance(r, Exception)]
    # each recording's KinematicsNet pass alone: the numbers of --batch 1
    got = iter(g.reconstruct(recs, batch=1, play_batch=batch, threads=threads, errors=True,
                             init=init))  # fmt: skip
    rows = []
    for f, stem, rec in loaded:
        recon = rec if isinstance(rec, Exception) else next(got)
        if isinstance(recon, Exception):
            if not isinstance(recon, caught):
                raise recon
            rows.append({"file": str(f), "error": _error_message(recon, g)})
            continue
        dst = Path(out) / f"{stem}.npz"
        recon.save(dst)
        written, failed = _exports(recon, rec, Path(out), formats, stem)
        rows.append({"file": str(f), "input": inputs[f], "name": rec.name, "stem": stem,
                     "formats": formats,
                     "frames": recon.n_frames,
                     "falls": recon.falls.tolist(), "ms_per_frame": recon.ms_per_frame,
                     "blowups": recon.notes.get("blowups", 0), "lost": recon.notes.get("lost", 0),
                     "written": [str(dst), *written],
                     "failed": failed,
                     "filled_gaps": rec.extras.get("filled_gaps", [])})  # fmt: skip
    return rows


def _error_message(e: Exception, g) -> str:
    """What a summary says of a recording that failed with ``e``."""
    msg = e.args[0] if isinstance(e, KeyError) and e.args else str(e)
    if isinstance(e, KeyError):  # a sensor the models read is missing
        feats = g.estimator.cfg.features
        msg += (f"; the models read the IMUs {list(feats.sites)}"
                f"{' and both insoles' if feats.insoles else ''}, so a model trained "
                "for the sensors present is needed (grip kin train --set "
                "features.sites=[...] --set features.insoles=false, and a policy on "
                "its estimates)")  # fmt: skip
    return msg


def _exports(recon, rec, out: Path, formats: list[str],
             stem: str) -> tuple[list[str], dict[str, str]]:  # fmt: skip
    """Write the non-npz formats; a format that cannot be written is reported, not fatal."""
    extra = [f for f in formats if f != "npz"]
    if not extra:
        return [], {}
    from grip.export import export_reconstruction

    written, failed = export_reconstruction(recon, out, extra, stem=stem,
                                            recording=rec)  # fmt: skip
    return [str(p) for p in written], failed


def cmd_reconstruct(args: argparse.Namespace) -> int:
    if "mp4" in args.formats:  # MuJoCo picks its OpenGL backend at import; EGL works headless
        os.environ.setdefault("MUJOCO_GL", "egl")
    from tqdm import tqdm

    from grip.cli.cluster import command_pool, ray_args
    from grip.cli.errors import CliError
    from grip.cli.recordings import kin_checkpoint, limits_from_args, lost_gap, pace_keeper
    from grip.core.atomic import atomic_write_text
    from grip.core.digests import file_sha256
    from grip.core.runs import (
        SettingsMismatch,
        exit_with_parent,
        remove_stale_temps,
        require_same_settings,
    )
    from grip.pipeline import RecoveryConfig

    limits_from_args(args)  # also for the worker processes ($GRIP_LIMITS)
    ray_args(args)
    formats = [f.strip() for f in args.formats.split(",") if f.strip()]
    from grip.export import FORMATS

    unknown = sorted(set(formats) - {"npz", *FORMATS})
    if unknown:
        raise CliError(f"--formats: unknown {unknown}; use npz, {', '.join(FORMATS)}")
    missing = [str(f) for f in args.recordings if not f.is_file()]
    if missing:
        raise CliError(f"no such recording file(s): {', '.join(missing)}")
    if args.workers < 1 or args.history < 1 or args.batch < 1:
        raise CliError("--workers, --history and --batch must be >= 1")
    if args.fill_gaps < 0:
        raise CliError("--fill-gaps must be >= 0")
    policy, kin = policy_checkpoint(args.policy), kin_checkpoint(args.kin)
    recovery = RecoveryConfig(enabled=not args.no_recovery, history_frames=args.history,
                              restart=args.restart, lost_gap_m=lost_gap(args))  # fmt: skip
    settings = {"max_frames": args.max_frames, "recovery": recovery.enabled,
                "history_frames": recovery.history_frames, "fill_gaps": args.fill_gaps,
                "policy_sha256": file_sha256(policy), "kin_sha256": file_sha256(kin)}  # fmt: skip
    if args.init != "truth":  # (absent from the settings of runs before --init: their start)
        settings["init"] = args.init
    if recovery.enabled and args.restart != "simulated":  # (absent before --restart: GRIP's)
        settings["restart"] = args.restart
    if recovery.enabled and args.lost_gap > 0:  # (absent when off, as in the runs before it)
        settings["lost_gap_m"] = args.lost_gap
    pace = pace_keeper(args)
    if pace.gain > 0.0 or pace.lean_gain_deg > 0.0:  # (absent when off: the runs before them)
        settings["pace"] = dataclasses.asdict(pace)
        if pace.lean_gain_deg == 0.0:  # (absent when off: the runs before the lean keeper)
            del settings["pace"]["lean_gain_deg"], settings["pace"]["lean_max_deg"]
    args.out.mkdir(parents=True, exist_ok=True)
    summary_path = args.out / "summary.json"
    old: dict = {}
    if summary_path.is_file() and not args.overwrite:
        try:
            old = json.loads(summary_path.read_text())
            rows = [r for r in old["recordings"]
                    if isinstance(r, dict) and r.get("written") and r.get("file")]  # fmt: skip
        except (ValueError, KeyError, TypeError):
            old, rows = {}, []
        if rows:  # finished outputs: a resume must bring their settings
            hint = "use another --out, the same options, or --overwrite to redo them"
            try:
                if isinstance(old.get("settings"), dict):
                    require_same_settings(old["settings"], settings, summary_path, hint)
                else:  # a summary of an older version: the settings it recorded
                    require_same_settings(old, settings, summary_path, hint, common_only=True)
            except SettingsMismatch as e:
                raise CliError(str(e)) from e
        npz = Counter(r["written"][0] for r in rows)  # rows sharing a file (older versions)
        old = {str(Path(r["file"]).resolve()): r for r in rows if npz[r["written"][0]] == 1}
    remove_stale_temps(args.out, recursive=False)  # of a killed run's unfinished writes
    inputs = list(dict.fromkeys(Path(f).resolve() for f in args.recordings))
    given = {Path(f).resolve(): str(f) for f in reversed(args.recordings)}  # first spelling
    reserved = {r.get("stem") or Path(r["written"][0]).stem: f for f, r in old.items()}
    stems = output_stems(inputs, reserved)
    done = dict(old)
    unrecorded = check_inputs(done, inputs, summary_path)
    if unrecorded:
        print(f"note: {summary_path}: no record of the contents of {unrecorded} input(s) "
              "(outputs of an older version): they are kept, their inputs assumed unchanged; "
              "a change is refused from now on")  # fmt: skip

    def finished(f: Path) -> bool:
        r = done.get(str(f))
        return (r is not None and set(formats) <= _row_formats(r)
                and all(Path(w).is_file() for w in r["written"]))  # fmt: skip

    todo = [f for f in inputs if not finished(f)]
    print(f"{len(inputs)} recording(s), {len(inputs) - len(todo)} already done")

    errors: dict[str, str] = {}
    rank = {str(f): i for i, f in enumerate(inputs)}  # (rows in input order, whatever finishes)

    def save() -> None:
        rows = [r for _, r in sorted(done.items(), key=lambda kv: rank.get(kv[0], -1))]
        meta = {"policy": str(policy), "kin": str(kin), "recovery": recovery.enabled,
                "history_frames": recovery.history_frames, "fill_gaps": args.fill_gaps,
                "max_frames": args.max_frames, "settings": settings,
                "falls": sum(len(r["falls"]) for r in rows),
                "blowups": sum(int(r.get("blowups", 0)) for r in rows),
                "lost": sum(int(r.get("lost", 0)) for r in rows)}  # fmt: skip
        failed = dict(sorted(errors.items(),
                             key=lambda kv: rank.get(str(Path(kv[0]).resolve()), -1)))  # fmt: skip
        atomic_write_text(summary_path, json.dumps({**meta, "recordings": rows,
                                                    "errors": failed}, indent=1))  # fmt: skip

    from grip.pipeline import usable_cores

    if unrecorded and not todo:
        save()  # (the records, so that the next resume compares them)
    pooled = (command_pool(args, args.workers if len(todo) > 1 else 1, exit_with_parent)
              if todo else contextlib.nullcontext())  # fmt: skip
    with pooled as pool, tqdm(total=len(todo), unit="rec", desc="reconstruct") as bar:
        workers = pool.workers if pool is not None else 1
        # --batch recordings side by side per job (fewer when a worker would wait for work)
        size = max(1, min(args.batch, -(-len(todo) // workers)))
        threads = max(1, usable_cores() // workers)
        jobs = [([(given[f], stems[f]) for f in todo[i : i + size]], str(args.out), str(policy),
                 str(kin), (recovery, pace), args.max_frames, formats, args.fill_gaps, args.batch,
                 threads, args.init)
                for i in range(0, len(todo), size)]  # fmt: skip

        def collect(k: int, rows) -> None:
            if isinstance(rows, BaseException):
                raise rows
            for r in rows:
                if "error" in r:
                    errors[r["file"]] = r["error"]
                    continue
                done[str(Path(r["file"]).resolve())] = r
                bar.set_postfix(falls=len(r["falls"]), ms_per_frame=f"{r['ms_per_frame']:.1f}")
            save()
            bar.update(len(rows))

        try:
            if pool is None:
                for k, job in enumerate(jobs):
                    collect(k, _work(job))
            else:
                for k in pool.run([(_work, (job,)) for job in jobs], collect):
                    for f, _ in jobs[k][0]:
                        errors[f] = ("the worker process died while reconstructing it (a crash "
                                     "or out of memory); run the command again to retry")
                    save()
                    bar.update(len(jobs[k][0]))
        except (OSError, ValueError) as e:
            raise CliError(str(e)) from e
    rows = [done[str(f)] for f in inputs if str(f) in done]
    falls = sum(len(r["falls"]) for r in rows)
    blowups = sum(int(r.get("blowups", 0)) for r in rows)
    lost = sum(int(r.get("lost", 0)) for r in rows)
    frames = sum(r["frames"] for r in rows)
    print(f"wrote {len(rows)} reconstruction(s) to {args.out}: {frames} frames, {falls} fall "
          f"event(s){' recovered' if recovery.enabled else ''}"
          f"{f' ({lost} of them lost, not fallen)' if lost else ''}, {blowups} blow-up(s) "
          f"recovered; summary {summary_path}")  # fmt: skip
    failed = [(r["name"], fmt, msg) for r in rows for fmt, msg in r.get("failed", {}).items()]
    for name, fmt, msg in failed:
        print(f"grip: error: {fmt} of {name}: {msg}", file=sys.stderr)
    for f, msg in errors.items():
        print(f"grip: error: {f}: not reconstructed: {msg}", file=sys.stderr)
    gaps = [(r["name"], g) for r in rows for g in r.get("filled_gaps", [])]
    if gaps:
        print(f"filled {len(gaps)} sensor dropout(s) of at most {args.fill_gaps} frames by "
              "interpolation (listed in summary.json)")  # fmt: skip
    return 1 if failed or errors else 0
