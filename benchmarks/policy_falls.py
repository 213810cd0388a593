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

``--timeline K`` instead plays clip K of the selected categories once from its frame 0 and
prints every 5th decision until the episode ends: pelvis height against the reference's, root
error, horizontal speed against the reference's, contacts, MPJPE and the position-imitation
reward (how a fall builds up).
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
    ap.add_argument("--fall-below", type=float, default=0.0,
                    help="a low pelvis is a fall only this far under the reference's, m")
    ap.add_argument("--timeline", type=int, default=None, metavar="K",
                    help="trace clip K (of the selected categories) from its frame 0")
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    torch.set_grad_enabled(False)
    runner = load_controller(args.policy)
    cats = tuple(args.category or ("walk*", "run*", "dash*"))
    ref = select_clips(load_reference(args.reference), cats)
    cfg = dataclasses.replace(runner.env_cfg, termination_dist_m=0.0,
                              fall_height_m=args.fall_height, max_episode_frames=args.max_frames,
                              fall_below_reference_m=args.fall_below,
                              random_start=True, clip_index=-1, reference="")  # fmt: skip
    env = GripTrackingEnv(cfg, ref)
    k = cfg.action_repeat
    if k > 1:
        env = ActionRepeat(env, k)
    if args.timeline is not None:
        _timeline(env, runner, args.timeline)
        return
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


def _timeline(env, runner, k: int) -> None:
    """Play clip ``k`` from frame 0 and print every 5th decision (the module docstring)."""
    base = env.unwrapped
    obs, _ = env.reset(options={"clip": k, "start": 0})
    clip = base.clip
    dt = 1.0 / clip.fps
    print(f"{clip.name} ({clip.category}, {clip.n_frames} frames)")
    print("frame | pelvis z / ref (m) | root err (m) | speed / ref (m/s) | contacts | MPJPE (mm) "
          "| r_imit_pos")  # fmt: skip
    done, n = False, 0
    while not done:
        obs, _, term, trunc, info = env.step(runner.act(obs))
        done, n = term or trunc, n + 1
        if n % 5 and not done:
            continue
        data, t = base._sim.data, min(int(info["frame"]), clip.n_frames - 1)
        g = clip.gt_qpos
        step = g[min(t + 1, clip.n_frames - 1), :2] - g[max(t - 1, 0), :2]
        ref_v = np.linalg.norm(step) / (2 * dt)
        print(f"{t:5d} | {data.qpos[2]:.2f} / {g[t, 2]:.2f} | "
              f"{np.linalg.norm(data.qpos[:2] - g[t, :2]):.2f} | "
              f"{np.linalg.norm(data.qvel[:2]):.2f} / {ref_v:.2f} | {data.ncon} | "
              f"{1000 * info.get('mpjpe_m', np.nan):.0f} | "
              f"{info.get('reward/imit_pos', np.nan):.2f}")
    print("fell" if term else "reached the end or the length limit")


if __name__ == "__main__":
    main()
