"""Learning curves of a DynamicsNet run (matplotlib, headless)."""

from __future__ import annotations

import os

import numpy as np


def plot_curves(history: list[dict], out_png: str | os.PathLike) -> None:
    """Success rate, MPJPE, reward terms and discriminator accuracy against env steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from grip.core.atomic import atomic_write

    fig, axes = plt.subplots(2, 3, figsize=(15, 7), constrained_layout=True)
    if history:
        # simulated frames where the history has them (with an action repeat a step is k frames)
        key = "frames" if all("frames" in h for h in history) else "timesteps"
        x = np.array([h[key] / 1e6 for h in history])
        w = max(1, len(history) // 50)  # rolling mean: one rollout holds few episodes

        def series(key, smooth=False):
            v = np.array([h.get(key, np.nan) for h in history], dtype=float)
            if smooth and w > 1:
                ok = np.isfinite(v)
                k = np.ones(w)
                num = np.convolve(np.where(ok, v, 0.0), k, "same")
                den = np.convolve(ok.astype(float), k, "same")
                v = np.where(den > 0, num / np.maximum(den, 1), np.nan)
            return v

        ax = axes[0, 0]
        ax.plot(x, 100 * series("success_rate", True))
        ax.set_ylabel("episodes without early end, %")
        ax = axes[0, 1]
        ax.plot(x, series("ep_len", True), label="episode length")
        ax.set_ylabel("mean episode length, frames")
        if any("termination_m" in h for h in history):
            tw = ax.twinx()
            tw.plot(x, 100 * series("termination_m"), color="grey", ls=":", label="termination")
            tw.set_ylabel("termination distance, cm (dotted)")
        ax = axes[0, 2]
        ax.plot(x, series("mpjpe_mm", True))
        ax.set_ylabel("MPJPE during training, mm")
        ax = axes[1, 0]
        for k in ("imit_pos", "imit_rot", "imit_vel", "imit_angvel", "root_vel", "amp"):
            ax.plot(x, series(f"reward/{k}", True), label=k)
        ax.set_ylabel("raw reward term per step")
        ax.legend(fontsize=8)
        ax = axes[1, 1]
        ax.plot(x, series("reward/energy", True))
        ax.set_ylabel("mechanical power, W (energy term before its weight)")
        ax = axes[1, 2]
        ax.plot(x, series("amp/acc_real", True), label="real")
        ax.plot(x, series("amp/acc_fake", True), label="policy")
        ax.set_ylabel("discriminator accuracy")
        ax.legend(fontsize=8)
        stage2 = next((h[key] / 1e6 for h in history if h.get("stage") == "stage2"), None)
        for a in axes.flat:
            a.set_xlabel("simulated frames (M)" if key == "frames" else "env steps (M)")
            a.grid(alpha=0.3)
            if stage2 is not None:
                a.axvline(stage2, color="grey", ls="--", lw=0.8)
    fig.suptitle("DynamicsNet training, per rollout, rolling means (dashed: stage 2 starts)")
    atomic_write(out_png, lambda f: fig.savefig(f, format="png", dpi=90))
    plt.close(fig)
