"""Cheaper physics settings against the motion they produce, in one run.

Each variant changes one setting of the simulation; the recipe's settings are the reference.
For every variant, with the variants in turns:

- **PD playback**: a mocap walk (CMU 07_05) played with the pelvis pinned to the ground truth
  and relative actions of 0 (``benchmarks/env_pd_tracking.py``): MPJPE against the ground
  truth.
- **A trained policy's behaviour**: a policy (default: the first member of the shipped
  ensemble) follows each clip of a reference set for ``--frames`` frames from its first frame,
  without distance termination (a fall ends the episode: pelvis below 0.3 m): success (no fall),
  MPJPE. The same episodes for every variant (mean actions: no noise).
- **Cost**: CPU time inside ``Humanoid.step`` per frame (per physics step x substeps) during
  those episodes (each variant's own states: a setting also changes the states it steps).

The tolerances, fixed before anything was measured (docs/performance.md): PD playback MPJPE
within 1 mm of the recipe's; the policy's success within one episode in 40 (2.5 points) of the
recipe's and its MPJPE within 2 mm. A variant that keeps them and costs less could replace the
recipe's setting; one that misses them changes the motion.

    python benchmarks/physics_settings.py --reference REF.npz --json F
    python benchmarks/physics_settings.py --variants recipe,sensors_off,pads_off

Variants: ``recipe`` (MuJoCo's defaults: sensors and islands on); ``sensors_off`` and
``islands_off`` (what the training env does since issue 48: the same motion bit for bit);
``iterations3`` (at most 3 Newton iterations instead of 100); ``tolerance1e-6``; ``pads_off``
(box feet without the 32 sole pads); ``self_collision_off``; ``step10ms`` (one 10 ms step per
frame instead of two of 5 ms).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
import time
from collections.abc import Callable, Sequence
from pathlib import Path

import mujoco
import numpy as np

D = mujoco.mjtDisableBit

VARIANTS: dict[str, tuple[dict, Callable | None]] = {
    "recipe": ({}, None),
    "sensors_off": ({}, lambda o: setattr(o, "disableflags", o.disableflags | D.mjDSBL_SENSOR)),
    "iterations3": ({}, lambda o: setattr(o, "iterations", 3)),
    "islands_off": ({}, lambda o: setattr(o, "disableflags", o.disableflags | D.mjDSBL_ISLAND)),
    "tolerance1e-6": ({}, lambda o: setattr(o, "tolerance", 1e-6)),
    "pads_off": ({"mjcf": {"sole_pads": False}}, None),
    "self_collision_off": ({"mjcf": {"self_collision": False}}, None),
    "step10ms": ({"mjcf": {"timestep_s": 0.01}, "substeps": 1}, None),
}
"""name -> (TrackingEnvConfig changes, a change of the compiled model's ``opt``)."""


def _config(cfg, changes: dict):
    mj = changes.get("mjcf")
    if mj:
        cfg = dataclasses.replace(cfg, mjcf=dataclasses.replace(cfg.mjcf, **mj))
    rest = {k: v for k, v in changes.items() if k != "mjcf"}
    return dataclasses.replace(cfg, **rest) if rest else cfg


class _Env:
    """A tracking env of one variant whose humanoids get the variant's ``opt`` change (and
    MuJoCo's defaults otherwise, sensors and islands on, which the training env turns off:
    only the variant differs), and whose physics is timed."""

    def __init__(self, cfg, reference, opt_change: Callable | None) -> None:
        from envs.tracking_env import GripTrackingEnv
        from envs.wrappers import ActionRepeat

        self.env = GripTrackingEnv(cfg, reference)
        self.outer = ActionRepeat(self.env, cfg.action_repeat) if cfg.action_repeat > 1 else None
        self.opt_change, self.cpu_s, self.steps = opt_change, 0.0, 0
        get = self.env._humanoid_for

        def humanoid_for(clip, i):
            h = get(clip, i)
            h.sensors = h.islands = True
            if opt_change is not None:
                opt_change(h.model.opt)
            if not getattr(h, "_timed", False):
                step = h.step

                def timed() -> None:
                    c = time.thread_time()
                    step()
                    self.cpu_s += time.thread_time() - c
                    self.steps += h.cfg.substeps

                h.step, h._timed = timed, True
            return h

        self.env._humanoid_for = humanoid_for

    @property
    def gym(self):
        return self.outer or self.env


def pd_playback(cfg, walk, opt_change) -> float:
    """MPJPE (m) of the pinned-root PD playback of ``walk`` (a reference set)."""
    c = dataclasses.replace(cfg, pin_root=True, random_start=False, termination_dist_m=0.0,
                            action_repeat=1, amp_window=0)  # fmt: skip
    env = _Env(c, walk, opt_change).env
    env.reset(seed=0)
    err = []
    while True:
        _, _, term, trunc, info = env.step(np.zeros(69, np.float32))
        err.append(info["mpjpe_m"])
        if term or trunc:
            return float(np.mean(err))


def policy_episodes(cfg, reference, opt_change, runner, frames: int) -> dict:
    """The policy on every clip's first ``frames`` frames: success, MPJPE, CPU us per mj_step."""
    c = dataclasses.replace(cfg, random_start=False, termination_dist_m=0.0, fall_height_m=0.3,
                            max_episode_frames=frames)  # fmt: skip
    env = _Env(c, reference, opt_change)
    ok, err = [], []
    for i in range(len(reference)):
        obs, _ = env.gym.reset(seed=0, options={"clip": i, "start": 0})
        e = []
        while True:
            obs, _, term, trunc, info = env.gym.step(runner.act(obs))
            if np.isfinite(info["mpjpe_m"]):
                e.append(info["mpjpe_m"])
            if term or trunc:
                break
        ok.append(bool(trunc and not term))
        err.append(float(np.mean(e)) if e else np.nan)
    us = 1e6 * env.cpu_s / max(env.steps, 1)
    return {"success": float(np.mean(ok)), "mpjpe_m": float(np.nanmean(err)), "outcomes": ok,
            "cpu_us_per_mj_step": us, "cpu_us_per_frame": us * c.substeps}  # fmt: skip


def main(argv: Sequence[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--reference", type=Path, required=True, help="reference set (.npz)")
    ap.add_argument("--policy", default=None, help="policy file (default: the shipped one)")
    ap.add_argument("--member", type=int, default=0, help="member of an ensemble file")
    ap.add_argument("--frames", type=int, default=300, help="frames per policy episode")
    ap.add_argument("--clips", type=int, default=40, help="first N clips of the reference")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--walk", default=None, help="PD playback clip (default: CMU 07_05)")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    import torch

    from grip.assets import SHIPPED_POLICY
    from grip.cli.paths import default_motions_dir
    from grip.core.reference import ReferenceSet
    from grip.core.reference_sets import load_reference
    from grip.kinematics.reference import oracle_reference_clip
    from grip.motion.catalog import load_clip
    from grip.motion.retarget import retarget
    from policies.ensemble import member_payload
    from policies.runner import PolicyRunner
    from prism_tools.synth import SynthConfig, recording_from_motion

    torch.set_num_threads(1)
    path = args.policy or SHIPPED_POLICY
    ck, name, _ = member_payload(path, args.member)
    runner = PolicyRunner.from_payload(ck, name)
    ref = load_reference(str(args.reference))
    ref = ReferenceSet(ref.clips[: args.clips], ref.sensor_sites, ref.insoles, str(args.reference))
    walk_path = args.walk or str(default_motions_dir() / "cmu/bvh/07_05.bvh")
    rec = recording_from_motion(retarget(load_clip(walk_path)), SynthConfig(), seed=0,
                                noise=False)  # fmt: skip
    walk = ReferenceSet([oracle_reference_clip(rec)], ref.sensor_sites, ref.insoles)
    base = dataclasses.replace(runner.env_cfg, reference=str(args.reference))
    out: dict = {"policy": str(path), "member": args.member, "reference": str(args.reference),
                 "clips": len(ref), "frames": args.frames, "variants": {}}  # fmt: skip
    for v in args.variants.split(","):
        changes, opt_change = VARIANTS[v]
        cfg = _config(base, changes)
        t = time.perf_counter()
        res = {"pd_mpjpe_m": pd_playback(cfg, walk, opt_change)}
        res.update(policy_episodes(cfg, ref, opt_change, runner, args.frames))
        res["wall_s"] = time.perf_counter() - t
        out["variants"][v] = res
        print(
            f"{v:20s} PD {1e3 * res['pd_mpjpe_m']:6.2f} mm | policy success "
            f"{res['success']:.3f}, MPJPE {1e3 * res['mpjpe_m']:6.1f} mm | "
            f"{res['cpu_us_per_frame']:6.1f} us CPU per frame",
            flush=True,
        )
    rec0 = out["variants"].get("recipe")
    if rec0 is not None:
        n = len(rec0["outcomes"])
        for v, r in out["variants"].items():
            r["pd_mpjpe_diff_mm"] = 1e3 * (r["pd_mpjpe_m"] - rec0["pd_mpjpe_m"])
            r["success_diff"] = r["success"] - rec0["success"]
            r["mpjpe_diff_mm"] = 1e3 * (r["mpjpe_m"] - rec0["mpjpe_m"])
            changed = [a != b for a, b in zip(r["outcomes"], rec0["outcomes"], strict=True)]
            r["outcomes_changed"] = int(sum(changed))
            r["cost_ratio"] = r["cpu_us_per_frame"] / rec0["cpu_us_per_frame"]
            r["within_tolerance"] = bool(abs(r["pd_mpjpe_diff_mm"]) <= 1.0
                                         and abs(r["success_diff"]) <= max(1, n // 40) / n + 1e-9
                                         and abs(r["mpjpe_diff_mm"]) <= 2.0)  # fmt: skip
            print(
                f"{v:20s} vs recipe: PD {r['pd_mpjpe_diff_mm']:+.2f} mm, success "
                f"{r['success_diff']:+.3f} ({r['outcomes_changed']} outcomes changed), MPJPE "
                f"{r['mpjpe_diff_mm']:+.1f} mm, cost per frame x{r['cost_ratio']:.3f}: "
                f"{'within' if r['within_tolerance'] else 'OUTSIDE'} the tolerances"
            )
    if args.json:
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
