"""Speed of the PIP physics optimiser (``grip.baselines.pip_physics``) on a walking clip.

Runs the optimiser on a mocap walk with a perfect kinematic input (ground-truth pose, joint
velocities by backward differences, contacts by the TransPose rule) and prints its frames/s,
the share of that time spent inside the QP solver, and the ratio against a reference measured in
the same run on the same model: raw ``mj_forward`` calls/s at the clip's states. It also times
the QPs of the run with quadprog called directly and through ``qpsolvers.solve_qp`` (the
conversion overhead), and with daqp. The ratio is the number to compare between machines; the
absolute numbers depend on the machine's load.

    python benchmarks/pip_speed.py [--frames 2000] [--solver quadprog|daqp] [--clip FILE]
"""

from __future__ import annotations

import argparse
import time

import mujoco
import numpy as np
import quadprog

import grip.baselines.pip_physics as pip
from grip.baselines.pip_config import SOLVERS, PipConfig
from grip.baselines.pip_dynamics import backward_velocity
from grip.cli.paths import default_motions_dir
from grip.core.metrics import contacts_from_motion
from grip.motion.catalog import load_clip
from grip.motion.retarget import retarget


def _forward_rate(phys: pip.PipPhysics, qpos: np.ndarray, seconds: float = 1.0) -> float:
    """Raw ``mj_forward`` calls/s on the optimiser's model, cycling through ``qpos`` states."""
    m, d = phys.model, mujoco.MjData(phys.model)
    n, start = 0, time.perf_counter()
    while time.perf_counter() - start < seconds:
        for q in qpos:
            d.qpos[:] = q
            mujoco.mj_forward(m, d)
        n += len(qpos)
    return n / (time.perf_counter() - start)


def _time_qps(problems: list, solve) -> float:
    """Mean ms per QP of ``solve(hess, lin, g, h)`` over the captured problems."""
    start = time.perf_counter()
    for p in problems:
        solve(*p)
    return (time.perf_counter() - start) * 1e3 / len(problems)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    root = default_motions_dir()
    ap.add_argument("--clip", default=str(root / "cmu/bvh/07_05.bvh") if root else None,
                    help="motion clip (default: CMU 07_05, a slow walk)")  # fmt: skip
    ap.add_argument("--frames", type=int, default=2000, help="frames to optimise (the clip "
                    "is replayed from its first frame as often as needed)")  # fmt: skip
    ap.add_argument("--solver", choices=SOLVERS, default="quadprog")
    args = ap.parse_args()
    if not args.clip:
        ap.error("no shared motion data found: pass --clip")
    if args.frames < 2:
        ap.error("--frames must be at least 2")

    motion = retarget(load_clip(args.clip))
    body = motion.body_model()
    _, pos = motion.fk(body)
    local = motion.local_rot()
    vel = backward_velocity(pos, motion.fps)
    contact = contacts_from_motion(pos[:, list(pip.sk.FOOT_JOINTS)], motion.fps).astype(float)
    phys = pip.PipPhysics(body, PipConfig(fps=motion.fps, solver=args.solver))

    problems: list = []
    solver_s = [0.0]
    inner = pip._solve_qp

    def timed(hess, lin, g, h, solver):
        if len(problems) < 500:
            problems.append((hess.copy(), lin.copy(), g.copy(), h.copy()))
        t0 = time.perf_counter()
        y = inner(hess, lin, g, h, solver)
        solver_s[0] += time.perf_counter() - t0
        return y

    pip._solve_qp = timed
    try:
        done, wall, qpos, failures = 0, 0.0, [], 0
        while done < args.frames:
            n = min(args.frames - done, motion.n_frames)
            t0 = time.perf_counter()
            rec = phys.reconstruct(local[:n], vel[:n], contact[:n], motion.root_pos[0])
            wall += time.perf_counter() - t0
            failures += rec.notes["qp_failures"]
            if not qpos:  # states for the mj_forward reference: every 10th output frame
                pairs = zip(rec.local_rot[::10], rec.root_pos[::10], strict=True)
                qpos = [phys.pose_qpos(r, p) for r, p in pairs]
            done += n
    finally:
        pip._solve_qp = inner

    fps = done / wall
    ref = _forward_rate(phys, np.array(qpos))
    print(f"clip {args.clip}: {motion.n_frames} frames at {motion.fps:g} Hz, optimised {done} "
          f"frames with {args.solver} ({failures} QP failures)")  # fmt: skip
    print(f"PIP optimiser:        {fps:8.0f} frames/s  ({1e3 / fps:.2f} ms/frame, "
          f"{100 * solver_s[0] / wall:.0f} % in the QP solver)")  # fmt: skip
    print(f"raw mj_forward:       {ref:8.0f} calls/s  (same model, same run)")
    print(f"ratio optimiser/mj_forward: {fps / ref:.4f}  "
          f"(one optimiser frame costs {ref / fps:.1f} mj_forward calls)")  # fmt: skip

    def direct_quadprog(hess, lin, g, h):
        return quadprog.solve_qp(hess, lin, -g.T, -h, 0)[0] if len(h) else None

    direct = _time_qps(problems, direct_quadprog)
    wrapped = _time_qps(problems, lambda *p: inner(*p, "quadprog"))
    daqp = _time_qps(problems, lambda *p: inner(*p, "daqp"))
    sizes = sorted({p[0].shape[0] for p in problems})
    print(f"QP solve over {len(problems)} captured problems (sizes {sizes[0]}-{sizes[-1]}): "
          f"quadprog direct {direct:.3f} ms, quadprog via qpsolvers {wrapped:.3f} ms, "
          f"daqp via qpsolvers {daqp:.3f} ms")  # fmt: skip


if __name__ == "__main__":
    main()
