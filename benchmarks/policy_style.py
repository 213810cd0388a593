"""How the discriminator sees a policy's motion, and how jittery that motion is.

Plays stage-2 episodes (random starts on the reference set, no distance termination, falls end
episodes) with ``--envs`` environments and collects the AMP windows of every decision (the
discriminator's input, ``info["amp_obs"]``), then prints:

- the judging discriminator's mean score on real windows of the same motions and on the
  policy's, its accuracy on each (LSGAN: real > 0 > policy), and the style reward the policy's
  windows earn (its mean, sd and 5-95 % range);
- the jitter of the joints: mean absolute hinge velocity and mean absolute change of a hinge
  velocity from one frame to the next, real and policy;
- with ``--groups``, per part of the AMP frame, the held-out accuracy of a small classifier
  trained to tell real windows from the policy's on that part alone (0.5: indistinguishable),
  and the hinge angles whose means differ most.

``--noise S`` samples actions with S times the policy's own standard deviation (1 = what PPO
plays while it trains; 0, the default, = deterministic, as evaluations play).

    python benchmarks/policy_style.py --reference RUN/reference_train.npz \\
        [--policy FILE ...] [--judge FILE] [--noise 1] [--groups]
"""

from __future__ import annotations

import argparse

import numpy as np
import torch

from envs.factory import make_tracking_env
from grip.assets import SHIPPED_POLICY
from grip.core import skeleton as sk
from grip.core.reference_sets import load_reference, select_clips
from grip.task import amp as A
from policies.amp import RealSampler
from policies.controller import load_controller
from policies.vec_env import stage2_rollout_env


def policy_windows(runner, ref_path: str, cats: tuple[str, ...], n_envs: int, steps: int,
                   seed: int) -> np.ndarray:  # fmt: skip
    """``(n_envs * steps, window * FRAME_DIM)`` AMP windows of the policy's decisions."""
    venv = stage2_rollout_env(make_tracking_env, runner.env_cfg, ref_path, cats, n_envs, seed)
    out = []
    try:
        obs = venv.reset()
        for _ in range(steps):
            obs, _r, _d, infos = venv.step(runner.act(obs))
            out.append(np.stack([i["amp_obs"] for i in infos]))
    finally:
        venv.close()
    return np.concatenate(out).astype(np.float32)


def jitter(windows: np.ndarray, window: int) -> tuple[float, float]:
    """Mean |hinge velocity| and mean |frame-to-frame change of a hinge velocity|, rad/s."""
    qd = windows.reshape(len(windows), window, A.FRAME_DIM)[:, :, A.PARTS["hinge_qd"]]
    return float(np.abs(qd).mean()), float(np.abs(np.diff(qd, axis=1)).mean())


def separability(real: np.ndarray, fake: np.ndarray, seed: int = 0) -> float:
    """Held-out accuracy of a one-hidden-layer classifier telling ``real`` rows from ``fake``
    (trained on three quarters, tested on the rest)."""
    g = torch.Generator().manual_seed(seed)
    x = torch.as_tensor(np.concatenate([real, fake]), dtype=torch.float32)
    x = (x - x.mean(0)) / (x.std(0) + 1e-6)
    y = torch.cat([torch.ones(len(real)), torch.zeros(len(fake))])
    idx = torch.randperm(len(x), generator=g)
    tr, te = idx[: 3 * len(x) // 4], idx[3 * len(x) // 4 :]
    torch.manual_seed(seed)
    net = torch.nn.Sequential(torch.nn.Linear(x.shape[1], 64), torch.nn.ReLU(),
                              torch.nn.Linear(64, 1))  # fmt: skip
    opt = torch.optim.Adam(net.parameters(), 3e-3)
    bce = torch.nn.functional.binary_cross_entropy_with_logits
    for _ in range(300):
        loss = bce(net(x[tr]).squeeze(-1), y[tr])
        opt.zero_grad()
        loss.backward()
        opt.step()
    with torch.no_grad():
        return float(((net(x[te]).squeeze(-1) > 0).float() == y[te]).float().mean())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reference", required=True,
                    help="reference set (grip policy train writes RUN/reference_train.npz)")
    ap.add_argument("--policy", action="append", default=None,
                    help="policy or ensemble file (repeatable; default: the shipped one)")
    ap.add_argument("--judge", default=None,
                    help="file whose (first member's) discriminator judges (default: the policy's)")
    ap.add_argument("--category", action="append", default=None,
                    help="glob on the motion category (repeatable; default walk*, run*, dash*)")
    ap.add_argument("--envs", type=int, default=8)
    ap.add_argument("--decisions", type=int, default=300, help="decisions per environment")
    ap.add_argument("--noise", type=float, default=0.0,
                    help="action noise in units of the policy's own sd (1 = PPO's sampling)")
    ap.add_argument("--groups", action="store_true", help="per-part separability and angles")
    ap.add_argument("--seed", type=int, default=100)
    args = ap.parse_args()
    torch.set_num_threads(1)
    runner = load_controller(args.policy or [SHIPPED_POLICY])
    if args.noise > 0:
        runner.use_action_noise(args.noise, seed=args.seed)
    judge = load_controller(args.judge) if args.judge else runner
    disc = judge.disc
    if disc is None:
        raise SystemExit(f"{args.judge or args.policy}: the file has no discriminator")
    cats = tuple(args.category or ("walk*", "run*", "dash*"))
    window = disc.in_dim // A.FRAME_DIM
    fake = policy_windows(runner, args.reference, cats, args.envs, args.decisions, args.seed)
    ref = select_clips(load_reference(args.reference), cats)
    real = RealSampler([A.reference_amp_features(c) for c in ref.clips], window).sample(
        len(fake), np.random.default_rng(args.seed))
    with torch.no_grad():
        d_real = disc(torch.as_tensor(real)).numpy()
        d_fake = disc(torch.as_tensor(fake)).numpy()
    style = disc.reward(fake)
    print(f"{len(fake)} policy windows ({args.envs} envs x {args.decisions} decisions, noise "
          f"{args.noise:g}) and as many real ones of {len(ref)} clips ({', '.join(cats)})")
    print("\n| | real | policy |\n|---|---:|---:|")
    print(f"| discriminator score, mean (sd) | {d_real.mean():+.3f} ({d_real.std():.3f}) | "
          f"{d_fake.mean():+.3f} ({d_fake.std():.3f}) |")
    print(f"| discriminator accuracy | {(d_real > 0).mean():.3f} | {(d_fake < 0).mean():.3f} |")
    print(f"| style reward, mean (sd) [5-95 %] | | {style.mean():.3f} ({style.std():.3f}) "
          f"[{np.percentile(style, 5):.3f}-{np.percentile(style, 95):.3f}] |")
    (vr, jr), (vf, jf) = jitter(real, window), jitter(fake, window)
    print(f"| mean abs. hinge velocity, rad/s | {vr:.3f} | {vf:.3f} |")
    print(f"| mean abs. change of a hinge velocity per frame, rad/s | {jr:.3f} | {jf:.3f} |")
    if not args.groups:
        return
    rw = real.reshape(len(real), window, A.FRAME_DIM)
    fw = fake.reshape(len(fake), window, A.FRAME_DIM)
    print("\n| AMP part | held-out accuracy real vs policy |\n|---|---:|")
    for name, part in A.PARTS.items():
        acc = separability(rw[:, :, part].reshape(len(rw), -1), fw[:, :, part].reshape(len(fw), -1))
        print(f"| {name} | {acc:.3f} |")
    xr, xf = rw[:, -1, A.PARTS["hinge_q"]], fw[:, -1, A.PARTS["hinge_q"]]
    d = (xf.mean(0) - xr.mean(0)) / (0.5 * (xr.std(0) + xf.std(0)) + 1e-6)
    names = [f"{sk.JOINT_NAMES[1 + i // 3]}.{'xyz'[i % 3]}" for i in range(A.N_HINGES)]
    print("\n| hinge | policy - real, in sd | real mean, rad | policy mean, rad |")
    print("|---|---:|---:|---:|")
    for i in np.argsort(-np.abs(d))[:8]:
        print(f"| {names[i]} | {d[i]:+.2f} | {xr[:, i].mean():+.3f} | {xf[:, i].mean():+.3f} |")


if __name__ == "__main__":
    main()
