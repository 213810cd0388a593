"""The batched env constructor that ``grip policy train --backend warp`` hands to
:class:`policies.warp.train.WarpPolicyTrainer` (its ``TensorEnvMaker``)."""

from __future__ import annotations

from envs.warp.env import WarpTrackingEnv
from grip.core.reference_sets import load_reference, select_clips
from grip.task.config import TrackingEnvConfig


def make_warp_tracking_env(env_cfg: TrackingEnvConfig, categories: tuple[str, ...],
                           num_envs: int, device: str, seed: int) -> WarpTrackingEnv:  # fmt: skip
    """``num_envs`` tracking episodes on MuJoCo Warp on ``device``, on the clips of
    ``categories`` (category globs; all when empty) of the reference set ``env_cfg.reference``
    (loaded once per process, :func:`grip.core.reference_sets.load_reference`); clip and start
    draws seeded with ``seed``.

    Raises:
        ValueError: No clip matches ``categories``, or settings the env refuses.
    """
    ref = select_clips(load_reference(env_cfg.reference), categories)
    return WarpTrackingEnv(env_cfg, ref, num_envs, device=device, seed=seed)
