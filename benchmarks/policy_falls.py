"""Where and how an exported policy falls: training-style episodes, per category and per clip.

Plays stage-2 episodes (random starts on the reference set, no distance termination, an episode
ends when the pelvis drops below ``--fall-height``; deterministic actions, the policy's action
repeat) and prints:

- the fall rate per motion category and the clips with the most falls (what hard-clip mining,
  ``stage2.mining_mix``, samples more often);
- the per-decision reward terms (imitation, mechanical power, the discriminator's style reward)
  over the 10 decisions before each fall against all other decisions: whether a falling body is
  paid less than a standing one (it is not if the energy term makes the reward negative).

    python benchmarks/policy_falls.py --reference RUN/reference_train.npz \\
        [--policy grip/assets/policy_default.pt] [--episodes 120] [--category 'walk*' ...]
"""

from __future__ import annotations

import argparse
import dataclasses
from collections import defaultdict

import numpy as np
import torch

from envs.tracking_env import GripTrackingEnv
from envs.wrappers import ActionRepeat
from grip.assets import SHIPPED_POLICY
from grip.core.reference_sets import load_reference, select_clips
from policies.controller import load_controller

TERMS = ("imit_pos", "imit_rot", "imit_vel", "imit_angvel", "energy")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reference", required=True,
                    help="reference set (grip policy train writes RUN/reference_train.npz)")
    ap.add_argument("--policy", default=str(SHIPPED_POLICY))
    ap.add_argument("--episodes", type=int, default=120)
    ap.add_argument("--category", action="append", default=None,
                    help="glob on the motion category (repeatable; default walk*, run*, dash*)")
    ap.add_argument("--max-frames", type=int, default=1000, help="episode length limit")
    ap.add_argument("--fall-height", type=float, default=0.3, help="pelvis height of a fall, m")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    torch.set_grad_enabled(False)
    runner = load_controller(args.policy)
    cats = tuple(args.category or ("walk*", "run*", "dash*"))
    ref = select_clips(load_reference(args.reference), cats)
    cfg = dataclasses.replace(runner.env_cfg, termination_dist_m=0.0,
                              fall_height_m=args.fall_height, max_episode_frames=args.max_frames,
                              random_start=True, clip_index=-1, reference="")  # fmt: skip
    env = GripTrackingEnv(cfg, ref)
    k = cfg.action_repeat
    if k > 1:
        env = ActionRepeat(env, k)
    weights = runner.env_cfg.reward.weights
    obs, _ = env.reset(seed=args.seed)
    episodes, rows = [], []
    while len(episodes) < args.episodes:
        obs, reward, term, trunc, info = env.step(runner.act(obs))
        style = float(runner.disc.reward(info["amp_obs"][None])[0]) if runner.disc else 0.0
        rows.append([reward + weights.amp * style, style, *(info[f"reward/{t}"] for t in TERMS)])
        if term or trunc:
            clip = env.unwrapped.clip
            episodes.append((clip.category, clip.name, bool(term), np.array(rows)))
            rows = []
            obs, _ = env.reset()
    n_fall = sum(e[2] for e in episodes)
    frames = np.mean([len(e[3]) for e in episodes]) * k
    print(f"{args.policy}: {len(episodes)} episodes on {len(ref)} clips ({', '.join(cats)}), "
          f"{n_fall} falls ({100 * n_fall / len(episodes):.1f} %), {frames:.0f} frames each")
    by_cat: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    by_clip: dict[str, list[int]] = defaultdict(lambda: [0, 0])
    for cat, name, fell, _ in episodes:
        for d, key in ((by_cat, cat), (by_clip, name)):
            d[key][0] += 1
            d[key][1] += fell
    print("\n| category | episodes | falls | fall rate |\n|---|---:|---:|---:|")
    for cat, (n, f) in sorted(by_cat.items()):
        print(f"| {cat} | {n} | {f} | {100 * f / n:.0f} % |")
    worst = sorted(((f, n, name) for name, (n, f) in by_clip.items() if f), reverse=True)[:10]
    print("\nclips with the most falls (falls / episodes):")
    for f, n, name in worst:
        print(f"  {f} / {n}  {name}")
    before = [e[3][-10:] for e in episodes if e[2]]
    other = [e[3][:-10] if e[2] else e[3] for e in episodes]
    names = ("reward (with style)", "style reward", *TERMS[:4], "power (W)")
    print("\n| per decision | last 10 before a fall | all other decisions |\n|---|---:|---:|")
    if before:
        b, o = np.concatenate(before), np.concatenate(other)
        for i, nm in enumerate(names):
            print(f"| {nm} | {b[:, i].mean():.3f} | {o[:, i].mean():.3f} |")
        print(f"| share with a negative reward | {(b[:, 0] < 0).mean():.2f} "
              f"| {(o[:, 0] < 0).mean():.2f} |")


if __name__ == "__main__":
    main()
