"""MuJoCo Warp against MuJoCo C on one model: the same states and controls, stepped side by
side, and how far apart they end up (the physics half of ``tests/warp`` and ``docs/gpu.md``).

:func:`compare_physics` steps W worlds of a compiled model with ``mujoco.mj_step`` (float64) and
with ``mujoco_warp.step`` (float32, one batch of W worlds) from the same states under the same
control sequence, and reports per step the largest ``qpos`` difference of each world and whether
the sets of geom pairs in contact agree beyond a grazing depth. :func:`humanoid_cases` builds the
two scenarios of ``docs/gpu.md``: tracking states of a clip on the flat floor, and standing or
dropped humanoids on a terrain's height field.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass, replace

import mujoco
import mujoco_warp as mjw
import numpy as np
import warp as wp


@dataclass(frozen=True)
class PhysicsGap:
    """How MuJoCo Warp's trajectories differ from MuJoCo C's.

    Attributes:
        root_pos_m: ``(W, T)`` distance between the free root's positions after each step, m.
        hinge_rad: ``(W, T)`` largest hinge-angle difference after each step, rad.
        contacts_equal: ``(W, T)`` bool: the same geom pairs in contact, up to pairs that only
            one side has and that penetrate less than ``grazing_m``.
        pairs_c: ``(W, T)`` geom pairs in contact in MuJoCo C.
        pairs_warp: ``(W, T)`` geom pairs in contact in MuJoCo Warp.
        contacts_c, contacts_warp: ``(W, T)`` contact points (a geom pair on a height field has
            one per prism in MuJoCo C, at most 4 in MuJoCo Warp).
        warp_s: Wall time of the MuJoCo Warp steps (kernels compiled before), s.
    """

    root_pos_m: np.ndarray
    hinge_rad: np.ndarray
    contacts_equal: np.ndarray
    pairs_c: np.ndarray
    pairs_warp: np.ndarray
    contacts_c: np.ndarray
    contacts_warp: np.ndarray
    warp_s: float


def _pairs(geom: np.ndarray, dist: np.ndarray) -> dict[tuple[int, int], float]:
    out: dict[tuple[int, int], float] = {}
    for g, d in zip(geom.tolist(), dist.tolist(), strict=True):
        key = (min(g), max(g))
        out[key] = min(out.get(key, np.inf), d)
    return out


def _agree(a: dict, b: dict, grazing_m: float) -> bool:
    extra = [v for k, v in a.items() if k not in b] + [v for k, v in b.items() if k not in a]
    return all(v > -grazing_m for v in extra)


def compare_physics(model: mujoco.MjModel, qpos: np.ndarray, qvel: np.ndarray,
                    ctrl: np.ndarray, device: str = "cpu", grazing_m: float = 1e-3,
                    nconmax: int = 256, njmax: int = 1200) -> PhysicsGap:  # fmt: skip
    """Step W worlds in MuJoCo C and in MuJoCo Warp from the same states.

    Args:
        model: The compiled model (sensors are turned off on both sides' copies).
        qpos: ``(W, nq)`` start positions.
        qvel: ``(W, nv)`` start velocities.
        ctrl: ``(T, W, nu)`` controls of each physics step.
        device: Warp device.
        grazing_m: Contacts shallower than this may be on one side only.
        nconmax, njmax: MuJoCo Warp's contacts and constraint rows per world.
    """
    m = copy.copy(model)
    m.opt.disableflags |= int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
    steps, worlds = ctrl.shape[0], ctrl.shape[1]
    c_q = np.zeros((worlds, steps, m.nq))
    c_con: list[list[dict]] = []
    c_n = np.zeros((worlds, steps), dtype=np.int64)
    for w in range(worlds):
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:] = qpos[w], qvel[w]
        cons = []
        for k in range(steps):
            d.ctrl[:] = ctrl[k, w]
            mujoco.mj_step(m, d)
            c_q[w, k] = d.qpos
            c_n[w, k] = d.ncon
            # (the contacts mj_step used: those of the state before its integration)
            cons.append(_pairs(np.array([c.geom for c in d.contact[: d.ncon]]).reshape(-1, 2),
                               np.array([c.dist for c in d.contact[: d.ncon]])))  # fmt: skip
        c_con.append(cons)
    with wp.ScopedDevice(device):
        mw = mjw.put_model(m)
        dw = mjw.make_data(m, nworld=worlds, nconmax=nconmax, njmax=njmax)
        dw.qpos.assign(qpos.astype(np.float32))
        dw.qvel.assign(qvel.astype(np.float32))
        dw.ctrl.assign(ctrl[0].astype(np.float32))
        mjw.forward(mw, dw)  # (compiles the kernels: not timed)
        mjw.step(mw, dw)
        dw.qpos.assign(qpos.astype(np.float32))
        dw.qvel.assign(qvel.astype(np.float32))
        dw.qacc_warmstart.zero_()
        dw.time.zero_()
        w_q = np.zeros((steps, worlds, m.nq))
        w_con = []
        w_n = np.zeros((worlds, steps), dtype=np.int64)
        wall = 0.0
        for k in range(steps):
            dw.ctrl.assign(ctrl[k].astype(np.float32))
            t0 = time.perf_counter()
            mjw.step(mw, dw)
            wp.synchronize_device(device)
            wall += time.perf_counter() - t0
            w_q[k] = dw.qpos.numpy()
            n = min(int(dw.nacon.numpy()[0]), dw.naconmax)
            geom, world = dw.contact.geom.numpy()[:n], dw.contact.worldid.numpy()[:n]
            dist = dw.contact.dist.numpy()[:n]
            w_n[:, k] = np.bincount(world, minlength=worlds)
            w_con.append([_pairs(geom[world == w], dist[world == w]) for w in range(worlds)])
    w_q = w_q.transpose(1, 0, 2)
    equal = np.array([[_agree(w_con[k][w], c_con[w][k], grazing_m) for k in range(steps)]
                      for w in range(worlds)])  # fmt: skip
    hinge = np.abs(w_q[..., 7:] - c_q[..., 7:]).max(axis=-1)
    return PhysicsGap(
        root_pos_m=np.linalg.norm(w_q[..., :3] - c_q[..., :3], axis=-1),
        hinge_rad=hinge,
        contacts_equal=equal,
        pairs_c=np.array([[len(c) for c in row] for row in c_con]),
        pairs_warp=np.array([[len(w_con[k][w]) for k in range(steps)] for w in range(worlds)]),
        contacts_c=c_n,
        contacts_warp=w_n,
        warp_s=wall,
    )


Case = tuple[mujoco.MjModel, np.ndarray, np.ndarray, np.ndarray]
"""The inputs of :func:`compare_physics`: model, ``qpos (W, nq)``, ``qvel (W, nv)``, ``ctrl (T, W,
nu)``."""


def tracking_case(cfg, reference, clip: int, starts: list[int], steps: int) -> Case:
    """Worlds at frames ``starts`` of a clip (its ground truth), driven toward the clip's
    estimate (the PD targets of a relative action of 0) for ``steps`` physics steps: the inputs
    of :func:`compare_physics`.

    Args:
        cfg: The tracking env's settings (:class:`grip.task.config.TrackingEnvConfig`).
        reference: The clips.
        clip: The clip played.
        starts: One start frame per world.
        steps: Physics steps (``cfg.substeps`` per frame).
    """
    from envs.tracking_env import GripTrackingEnv

    env = GripTrackingEnv(replace(cfg, random_start=False), reference)
    qpos, qvel = [], []
    for s in starts:
        env.reset(options={"clip": clip, "start": s})
        qpos.append(env.data.qpos.copy())
        qvel.append(env.data.qvel.copy())
    h, est, last = env.humanoid, env._est, env.clip.n_frames - 1
    ctrl = np.zeros((steps, len(starts), env.model.nu))
    for k in range(steps):
        for w, s in enumerate(starts):
            ctrl[k, w, h.act] = np.clip(est.target[min(s + k // cfg.substeps + 1, last)], h.lo,
                                        h.hi)  # fmt: skip
    return env.model, np.array(qpos), np.array(qvel), ctrl


TERRAIN_CASES: tuple[tuple[float, float, float, float], ...] = (
    (0.0, 0.0, 0.0, 0.0),  # standing on the floor at the origin (the height field's flat part)
    (0.0, 2.35, 0.6, 0.0),  # standing on the stairs' landing (0.6 m up)
    (0.0, 1.25, 0.35, 0.3),  # dropped from 5 cm onto the second tread, drifting forward
    (0.0, 0.65, 0.0, 1.0),  # walking at 1 m/s into the first rise
)
"""Terrain worlds: ``(x, y, lift, forward speed)`` of the standing pose (keyframe ``stand``)
in the stairs scene (:func:`envs.terrain.stairs_scene`), m and m/s."""


def terrain_case(cfg, steps: int) -> Case:
    """The standing humanoid placed as :data:`TERRAIN_CASES` in the scene of ``cfg.terrain``,
    PD targets at the standing pose, for ``steps`` physics steps (the default subject)."""
    from envs.scenes import humanoid_scenes
    from grip.core.body import BodyParams

    model = humanoid_scenes(cfg).get(BodyParams()).model
    key = model.key("stand")
    qpos = np.tile(key.qpos, (len(TERRAIN_CASES), 1))
    qvel = np.zeros((len(TERRAIN_CASES), model.nv))
    for w, (x, y, lift, vy) in enumerate(TERRAIN_CASES):
        qpos[w, :3] += (x, y, lift)
        qvel[w, 1] = vy
    ctrl = np.broadcast_to(key.ctrl, (steps, len(TERRAIN_CASES), model.nu)).copy()
    return model, qpos, qvel, ctrl
