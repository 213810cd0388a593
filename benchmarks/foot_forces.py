"""Foot GRF and CoP of a recorded frame: MuJoCo's net contact-force sensors against the Python
loop over the contacts (``grip.sim.model.FootContacts``, ``loop=True``), timed on the same
states in the same run, with ``mj_step`` as the reference.

Plays the bundled sample reference clip (a walk) with the humanoid following its estimate; at
every frame both paths read the forces of the same state (each call first solves the state's
constraint forces, as every recorded frame does), alternating which goes first.

    python benchmarks/foot_forces.py [--repeats 3] [--json PATH]
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeats", type=int, default=3, help="passes over the clip")
    ap.add_argument("--json", type=Path, default=None)
    args = ap.parse_args(argv)

    from envs.tracking_env import SAMPLE_REFERENCE
    from grip.core.reference import ReferenceSet
    from grip.sim.humanoid import Humanoid, HumanoidConfig
    from grip.sim.model import FootContacts, load_model

    clip = ReferenceSet.load(SAMPLE_REFERENCE).clip(0)
    h = Humanoid(load_model(clip.body), HumanoidConfig(), None)
    paths = {"sensors": FootContacts(h.model, h.index),
             "loop": FootContacts(h.model, h.index, loop=True)}
    spent = dict.fromkeys([*paths, "step"], 0.0)
    calls, grf_diff, cop_diff = 0, 0.0, 0.0
    for r in range(args.repeats):
        h.reset(clip.gt_qpos[0], clip.gt_qvel[0])
        for t in range(1, clip.n_frames):
            h.set_targets(clip.est_hinge[t])
            t0 = time.perf_counter()
            h.step()
            spent["step"] += time.perf_counter() - t0
            order = list(paths) if (t + r) % 2 else list(paths)[::-1]
            got = {}
            for name in order:
                t0 = time.perf_counter()
                got[name] = paths[name](h.data)
                spent[name] += time.perf_counter() - t0
            calls += 1
            grf_diff = max(grf_diff, float(np.abs(got["sensors"][0] - got["loop"][0]).max()))
            on = ~np.isnan(got["loop"][1][:, 0])
            if on.any():
                d = np.abs(got["sensors"][1][on] - got["loop"][1][on]).max()
                cop_diff = max(cop_diff, float(d))
    us = {k: 1e6 * v / calls for k, v in spent.items()}
    out = {"frames": calls, "us_per_call": us, "sensors_over_loop": us["sensors"] / us["loop"],
           "sensors_over_step": us["sensors"] / us["step"],
           "loop_over_step": us["loop"] / us["step"], "max_grf_diff_n": grf_diff,
           "max_cop_diff_m": cop_diff}  # fmt: skip
    print(f"{calls} frames: sensors {us['sensors']:.1f} us, loop {us['loop']:.1f} us, "
          f"humanoid step {us['step']:.1f} us per frame; sensors / loop "
          f"{out['sensors_over_loop']:.2f}; largest GRF difference {grf_diff:.2g} N, "
          f"CoP {1e3 * cop_diff:.2f} mm")  # fmt: skip
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
