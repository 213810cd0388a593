"""Run folders of ``grip policy train`` and ``grip policy distill``: the clips held out of
training and the training reference set both build (which settings a resumed run may change is
the trainers' :data:`policies.train.RESUMABLE`, checked by :class:`grip.core.rundir.RunDir`)."""

from __future__ import annotations

import json
from pathlib import Path

_ONE_INPUT: dict[str, float] = {}
"""``max_total_bytes`` as this process had it before :func:`allow_reference_size` raised it."""

HOLDOUT_FILE = "holdout.json"
"""Sequence names held out of a policy run's training (``holdout_fraction``), in the run folder."""


def training_files(files: list[Path], cfg, out: Path) -> list[Path]:
    """The training split's recording files less the clips that ``cfg.holdout_fraction`` holds
    out, whose sequence names go to ``out/holdout.json`` (every call: the draw depends only on
    the names, the fraction and the seed)."""
    from grip.cli.errors import CliError
    from grip.core.atomic import atomic_write_text
    from grip.kinematics.dataset import holdout_names

    if cfg.holdout_fraction <= 0:
        return files
    held = holdout_names([f.stem for f in files], cfg.holdout_fraction, cfg.seed)
    kept = [f for f in files if f.stem not in held]
    if not kept:
        raise CliError(f"holdout_fraction={cfg.holdout_fraction} holds out every training "
                       f"clip of {len(files)} sequence(s): nothing to train on")  # fmt: skip
    payload = {"fraction": cfg.holdout_fraction, "seed": cfg.seed, "sequences": sorted(held)}
    atomic_write_text(out / HOLDOUT_FILE, json.dumps(payload, indent=1))
    print(f"held out {len(held)} of {len(files)} training sequences ({out / HOLDOUT_FILE})")
    return kept


def build_training_reference(ref_path: Path, data: Path, files: list[Path], kins: list[Path],
                             reverse_categories: tuple[str, ...] = (),
                             mirror: bool = False, follow: str = "estimate",
                             speed_factors: tuple[float, ...] = (),
                             speed_categories: tuple[str, ...] = ()) -> None:  # fmt: skip
    """Write the training reference set ``ref_path`` (the recordings ``files`` of dataset
    ``data`` with the estimates of each KinematicsNet checkpoint in ``kins``; training clips of
    ``reverse_categories`` played backwards, and every clip's mirror image with ``mirror``;
    with ``follow="truth"`` the ground truth is the reference, with the feature settings of
    ``kins[0]``; with ``follow="both"`` the estimates and, as ``<clip>#truth``, the ground
    truth; training clips of ``speed_categories`` also played each of ``speed_factors`` times
    faster) unless it exists. When ``kins`` are the K fold models of a split by person
    (``grip kin train --set train.val_source=fold``), each recording is estimated once, by the
    model that never saw its person (cross-fitted, recorded as ``cross_fit``). The augmentation
    settings are written beside it (``reference_train.json``): an existing set made with other
    settings is refused, not silently reused (a set without that record predates
    ``speed_factors``: it holds no speed-scaled clips). Shared by ``grip policy train`` and
    ``grip policy distill``."""
    from tqdm import tqdm

    from grip.cli.errors import CliError
    from grip.cli.recordings import load_recordings
    from grip.core.atomic import atomic_write_text

    made = {"reverse_categories": list(reverse_categories), "mirror": bool(mirror),
            "follow": follow, "speed_factors": [float(f) for f in speed_factors],
            "speed_categories": list(speed_categories) if speed_factors else []}  # fmt: skip
    from grip.kinematics.inference import KinematicsEstimator
    from grip.kinematics.reference import fold_partition

    ests = None
    if len(kins) > 1 and follow != "truth":  # (cross-fitting takes at least two fold models)
        try:
            ests = [KinematicsEstimator.from_checkpoint(kin) for kin in kins]
            if fold_partition(ests, kins) is not None:
                made["cross_fit"] = len(kins)  # (each clip estimated once, by its fold's model)
        except ValueError as e:
            raise CliError(str(e)) from e
    sidecar = ref_path.with_suffix(".json")
    if ref_path.is_file():
        try:
            was = json.loads(sidecar.read_text()) if sidecar.is_file() else None
        except (OSError, ValueError):
            was = None
        note = ""
        if not isinstance(was, dict):  # (older: the rest unknown, no speed-scaled clips)
            was = {**made, "speed_factors": [], "speed_categories": []}
            note = f"; no readable {sidecar.name}: made before speed_factors existed"
        if was != made:
            changed = sorted(k for k in {*made, *was} if was.get(k) != made.get(k))
            before, now = ({k: d.get(k) for k in changed} for d in (was, made))
            raise CliError(f"{ref_path} was made with other settings ({', '.join(changed)}: "
                           f"{before} -> {now}{note}); delete it to rebuild the reference set, "
                           "or use a new run folder")  # fmt: skip
        allow_reference_size(reference_copies(made, len(kins)))
        return
    from grip.kinematics.reference import build_reference_set, merge_reference_sets

    if ests is None:  # (before any recording is read: a refusal costs nothing)
        try:
            ests = [KinematicsEstimator.from_checkpoint(kin) for kin in kins]
        except ValueError as e:
            raise CliError(str(e)) from e
        t = ests[0].cfg.train  # (several fold models are cross-fitted above)
        if follow != "truth" and t.val_source == "fold":
            raise CliError(f"{kins[0]} is the model of fold {t.fold} of {t.folds} "
                           "(train.val_source = 'fold'): its estimates of the training clips mix "
                           "people it saw and people it never saw; pass all the fold models "
                           "(--kin F0 --kin F1 ...) to cross-fit them, or a model trained on "
                           "every training person")  # fmt: skip
    recs = load_recordings(files)
    if reverse_categories:
        from grip.cli.recordings import reversed_training_recordings

        recs += reversed_training_recordings(data, files, reverse_categories)
    if speed_factors:
        from grip.cli.recordings import speed_scaled_training_recordings

        recs += speed_scaled_training_recordings(data, files, speed_categories, speed_factors)
    sets, est = [], ests[0]
    if "cross_fit" in made:
        from grip.kinematics.dataset import dataset_groups
        from grip.kinematics.reference import build_cross_fitted_reference_set, fold_model_chooser

        with tqdm(total=len(recs), unit="rec",
                  desc=f"cross-fitted estimates ({len(kins)} fold models)") as bar:
            try:
                choose = fold_model_chooser(ests, dataset_groups(data), kins)
                sets.append(build_cross_fitted_reference_set(
                    recs, choose, progress=bar.update, source="cross-fitted", compact=True))
            except ValueError as e:
                raise CliError(str(e)) from e
    else:
        truth = follow == "truth"
        for kin, one in zip(kins, ests, strict=True):
            desc = ("ground truth as the reference" if truth
                    else f"KinematicsNet estimates ({kin.name})")  # fmt: skip
            with tqdm(total=len(recs), unit="rec", desc=desc) as bar:
                sets.append(build_reference_set(recs, one, progress=bar.update, source=str(kin),
                                                truth=truth, compact=True))  # fmt: skip
            if truth:
                break  # (the truth is the same whichever checkpoint gave the feature settings)
    suffixes = None
    if follow == "both":
        with tqdm(total=len(recs), unit="rec", desc="ground truth as the reference") as bar:
            sets.append(build_reference_set(recs, est, progress=bar.update, source="truth",
                                            truth=True, compact=True))  # fmt: skip
        suffixes = [f"#{k}" for k in range(len(sets) - 1)] + ["#truth"]
    try:
        ref = merge_reference_sets(sets, source=str(ref_path), suffixes=suffixes)
    except ValueError as e:
        raise CliError(str(e)) from e
    if mirror:
        from grip.kinematics.reference import with_mirrored_clips

        ref = with_mirrored_clips(ref)
        for c in ref.clips:
            c.compact()
    atomic_write_text(sidecar, json.dumps(made, indent=1))  # (first: never a set without it)
    ref.save(ref_path)
    allow_reference_size(reference_copies(made, len(kins)))
    print(f"wrote {ref_path}: {len(ref)} clips, {ref.total_frames} frames")


def reference_copies(made: dict, n_kins: int) -> int:
    """How many copies of the training recordings a reference set made with the settings
    ``made`` (the record :func:`build_training_reference` writes) and ``n_kins`` KinematicsNet
    checkpoints holds at most: one per estimator (one for the truth alone or for cross-fitted
    fold models; one more for the truth beside the estimates), times one more per speed factor
    and one for the clips played backwards, times two with mirror images."""
    one = made["follow"] == "truth" or made.get("cross_fit")
    sets = 1 if one else max(1, n_kins) + (made["follow"] == "both")
    per_set = 1 + len(made["speed_factors"]) + bool(made["reverse_categories"])
    return sets * per_set * (2 if made["mirror"] else 1)


def allow_reference_size(copies: int) -> None:
    """Let this process and its workers read a training reference set of ``copies`` copies of
    the training recordings: ``max_total_bytes`` (what one input file may expand to, 1 GiB by
    default, ``$GRIP_LIMITS`` included) is raised to ``copies`` times itself. The limit is meant
    for one input; the run's own set holds several by its recorded settings (a speed-scaled set
    of the whole corpus is 1.07 GB), and those settings are the command's, checked against the
    set's record, not read from a file the run was handed."""
    from grip.core.limits import active_limits, set_active_limits

    limits = active_limits()
    base = _ONE_INPUT.setdefault("max_total_bytes", limits.max_total_bytes)  # (not compounded)
    if base * copies > limits.max_total_bytes:
        set_active_limits(limits.with_overrides({"max_total_bytes": base * copies}))
