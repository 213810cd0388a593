"""Run folders of ``grip policy train`` and ``grip policy distill``: which settings a resumed run
may change, the clips held out of training, and the training reference set both build."""

from __future__ import annotations

import json
from pathlib import Path

HOLDOUT_FILE = "holdout.json"
"""Sequence names held out of a policy run's training (``holdout_fraction``), in the run folder."""

RESUMABLE: tuple[str, ...] = (
    "stage2.", "stage1.termination_", "checkpoint_every", "ppo.threads", "ppo.device",
    "ppo.learning_rate", "ppo.n_steps", "ppo.batch_size", "ppo.n_epochs", "ppo.gae_lambda",
    "ppo.clip_range", "ppo.ent_coef", "ppo.vf_coef", "ppo.max_grad_norm", "ppo.target_kl",
    "ppo.critic_warmup_steps",
)  # fmt: skip
"""Settings (dotted prefixes) that may differ when a run is resumed: the optimiser's (a resumed
run takes them from the config, not from its checkpoint), the termination curriculum, stage 2."""


def _flatten(d: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in d.items():
        if isinstance(v, dict):
            out.update(_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def changed_settings(old: dict, new: dict, defaults: dict | None = None,
                     resumable: tuple[str, ...] = RESUMABLE) -> list[str]:  # fmt: skip
    """Dotted keys whose values differ between two config dicts, except those starting with one
    of ``resumable`` (``grip policy train``'s :data:`RESUMABLE` by default).

    A key missing from ``old`` (a setting added to the project after the run began) takes its
    value from ``defaults``, the current default config, if given: a new setting left at its
    default does not block resuming an older run."""
    a, b = _flatten(json.loads(json.dumps(old))), _flatten(json.loads(json.dumps(new)))
    if defaults is not None:
        d = _flatten(json.loads(json.dumps(defaults)))
        a = {**{k: v for k, v in d.items() if k not in a}, **a}
    keys = sorted(set(a) | set(b))
    return [k for k in keys if a.get(k) != b.get(k) and not k.startswith(resumable)]


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
                             mirror: bool = False) -> None:  # fmt: skip
    """Write the training reference set ``ref_path`` (the recordings ``files`` of dataset
    ``data`` with the estimates of each KinematicsNet checkpoint in ``kins``; training clips of
    ``reverse_categories`` played backwards, and every clip's mirror image with ``mirror``)
    unless it exists. Shared by ``grip policy train`` and ``grip policy distill``."""
    from tqdm import tqdm

    from grip.cli.errors import CliError
    from grip.cli.recordings import load_recordings

    if ref_path.is_file():
        return
    from grip.kinematics.inference import KinematicsEstimator
    from grip.kinematics.reference import build_reference_set, merge_reference_sets

    recs = load_recordings(files)
    if reverse_categories:
        from grip.cli.recordings import reversed_training_recordings

        recs += reversed_training_recordings(data, files, reverse_categories)
    sets = []
    for kin in kins:
        try:
            est = KinematicsEstimator.from_checkpoint(kin)
        except ValueError as e:
            raise CliError(str(e)) from e
        desc = f"KinematicsNet estimates ({kin.name})"
        with tqdm(total=len(recs), unit="rec", desc=desc) as bar:
            sets.append(build_reference_set(recs, est, progress=bar.update, source=str(kin)))
    try:
        ref = merge_reference_sets(sets, source=str(ref_path))
    except ValueError as e:
        raise CliError(str(e)) from e
    if mirror:
        from grip.kinematics.reference import with_mirrored_clips

        ref = with_mirrored_clips(ref)
    ref.save(ref_path)
    print(f"wrote {ref_path}: {len(ref)} clips, {ref.total_frames} frames")
