"""How a trained discriminator scores each motion category's *real* windows (issue 47, part 1).

An AMP discriminator learns which windows are common among real examples relative to the
policy's play. When a category is a small share of the real windows but most of the play, its
real windows may score like fakes: the style reward then punishes a perfect imitation of it.
This script loads a run's discriminator (``RUN/checkpoint/amp.pt``, or a packed resume state)
and scores every category's real windows of a reference set with it:

    python benchmarks/amp_category_scores.py --run RUN --reference REF.npz --json F

Per category: its share of the real frames (what ``RealSampler`` draws from), the mean style
reward of its real windows (``Discriminator.reward``, 1 for a window the discriminator is sure
is real), the mean probability the fall detector reads (``Discriminator.probability``) and the
share of windows under the fall threshold 0.7.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))


def score(run: Path, reference: Path, stride: int = 5) -> dict:
    import torch

    from grip.core.reference import ReferenceSet
    from grip.task import amp as A
    from policies.amp import Discriminator
    from policies.checkpoint import load_weights
    from policies.config import policy_config_from_dict

    cfg_path = run / "config.json"
    cfg = policy_config_from_dict(json.loads(cfg_path.read_text())["config"], str(cfg_path))
    disc = Discriminator(cfg.amp.window * A.FRAME_DIM, cfg.amp.hidden, cfg.amp.loss)
    state = load_weights(run / "checkpoint" / "amp.pt", "discriminator checkpoint")
    disc.load_state_dict({k: v.float() for k, v in state["disc"].items()})
    disc.eval()
    ref = ReferenceSet.load(reference)
    w = cfg.amp.window
    by_cat: dict[str, list[np.ndarray]] = {}
    frames: dict[str, int] = {}
    for c in ref.clips:
        f = A.reference_amp_features(c).astype(np.float32)
        frames[c.category] = frames.get(c.category, 0) + len(f)
        t = np.arange(w - 1, len(f), stride)
        if len(t) == 0:
            continue
        idx = t[:, None] + np.arange(-w + 1, 1)[None, :]
        by_cat.setdefault(c.category, []).append(f[idx].reshape(len(t), -1))
    total = sum(frames.values())
    out = {}
    with torch.no_grad():
        for cat, parts in sorted(by_cat.items()):
            x = np.concatenate(parts)
            r = disc.reward(x)
            p = disc.probability(x)
            out[cat] = {"real_share": frames[cat] / total, "windows": len(x),
                        "style_reward": float(r.mean()), "probability": float(p.mean()),
                        "below_fall_threshold": float((p < 0.7).mean())}  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--run", type=Path, required=True, help="run folder (or packed resume state)")
    ap.add_argument("--reference", type=Path, required=True, help="reference set (.npz)")
    ap.add_argument("--stride", type=int, default=5, help="score every STRIDE-th window")
    ap.add_argument("--json", type=Path, required=True)
    args = ap.parse_args(argv)
    res = score(args.run, args.reference, args.stride)
    args.json.write_text(json.dumps(res, indent=1))
    print(f"{'category':12s} {'real share':>10s} {'style reward':>12s} {'p(real)':>8s} "
          f"{'p < 0.7':>8s}")  # fmt: skip
    for cat, r in sorted(res.items(), key=lambda kv: -kv[1]["real_share"]):
        print(f"{cat:12s} {100 * r['real_share']:9.1f}% {r['style_reward']:12.3f} "
              f"{r['probability']:8.3f} {100 * r['below_fall_threshold']:7.1f}%")  # fmt: skip


if __name__ == "__main__":
    main()
