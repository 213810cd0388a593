"""Learning curves of a DynamicsNet run (matplotlib, headless)."""

from __future__ import annotations

import os


def plot_curves(history: list[dict], out_png: str | os.PathLike) -> None:
    """Success rate, MPJPE, reward terms and discriminator accuracy against env steps."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from grip.core.atomic import atomic_write

    fig, axes = plt.subplots(2, 2, figsize=(11, 7), constrained_layout=True)
    if history:
        x = [h["timesteps"] / 1e6 for h in history]

        def series(key):
            return [h.get(key, float("nan")) for h in history]

        ax = axes[0, 0]
        ax.plot(x, [100 * v for v in series("success_rate")])
        ax.set_ylabel("episodes without early end, %")
        ax = axes[0, 1]
        ax.plot(x, series("mpjpe_mm"))
        ax.set_ylabel("MPJPE during training, mm")
        ax = axes[1, 0]
        for k in ("imit_pos", "imit_rot", "imit_vel", "imit_angvel", "amp"):
            ax.plot(x, series(f"reward/{k}"), label=k)
        ax.set_ylabel("raw reward term per step")
        ax.legend(fontsize=8)
        ax = axes[1, 1]
        ax.plot(x, series("amp/acc_real"), label="real")
        ax.plot(x, series("amp/acc_fake"), label="policy")
        ax.set_ylabel("discriminator accuracy")
        ax.legend(fontsize=8)
        stage2 = next((h["timesteps"] / 1e6 for h in history if h.get("stage") == "stage2"), None)
        for a in axes.flat:
            a.set_xlabel("env steps (M)")
            a.grid(alpha=0.3)
            if stage2 is not None:
                a.axvline(stage2, color="grey", ls="--", lw=0.8)
    fig.suptitle("DynamicsNet training (dashed: stage 2 starts)")
    atomic_write(out_png, lambda f: fig.savefig(f, format="png", dpi=90))
    plt.close(fig)
