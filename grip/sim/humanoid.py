"""``Humanoid``: one subject's simulated body, PD targets in, state out (no task, no reference).

The physics half of dm_control's ``Environment(physics, task)``: the training task
(:class:`envs.tracking_env.GripTrackingEnv`) and the inference pipeline (:mod:`grip.pipeline`)
both drive a :class:`Humanoid`; neither reaches into MuJoCo themselves. Everything a control step
touches is resolved once (index arrays, views of ``MjData``), so that a step costs MuJoCo's time
plus a few microseconds.

State layout: ``pvw (3, 24, 3)`` = world positions (m), linear (m/s) and angular (rad/s)
velocities of the 24 SMPL bodies, ``rot (24, 3, 3)`` their world rotations. Pose vectors are
``(76,)`` ``[root_pos, root_quat_wxyz, 69 hinges]`` and velocity vectors ``(75,)`` (root linear
velocity in the world, root angular velocity in the root frame, hinge rates), both in SMPL
order (:func:`grip.core.reference.pose_vector`).
"""

from __future__ import annotations

import ctypes
from collections.abc import Callable, Hashable
from dataclasses import dataclass

import mujoco
import numpy as np

from grip.core import skeleton as sk
from grip.sim.model import (
    FootContacts,
    HumanoidIndex,
    ModelArrays,
    ModelVariants,
    write_pose_vector,
    write_velocity_vector,
)

HeightSampler = Callable[..., np.ndarray]
"""Terrain heights around a point: ``(center_xy (2,), rot2 (2, 2), grid (N, 2), out=None) ->
(N,)`` heights above z = 0 at ``center_xy + grid @ rot2.T``, m
(``envs.heightfield.sample_heightmap`` bound to a height field)."""

_UNSTABLE = np.array([int(w) for w in (mujoco.mjtWarning.mjWARN_BADQPOS,
                                       mujoco.mjtWarning.mjWARN_BADQVEL,
                                       mujoco.mjtWarning.mjWARN_BADQACC)])  # fmt: skip
"""MuJoCo's warnings for a state it could not integrate (it then resets ``MjData`` itself, which
also zeroes the counters, and counts the warning: a second blow-up leaves the count at 1)."""
_W_QPOS, _W_QVEL, _W_QACC = (int(w) for w in _UNSTABLE)
_C1, _C2 = np.array([1, 2, 0]), np.array([2, 0, 1])  # index permutations of a cross product
_NO_SENSORS = int(mujoco.mjtDisableBit.mjDSBL_SENSOR)
_NO_ISLANDS = int(mujoco.mjtDisableBit.mjDSBL_ISLAND)

_NJ = sk.N_JOINTS
ROW_PARTS: tuple[tuple[str, int], ...] = (
    ("pos", 3 * _NJ),  # body origins, world, m
    ("vel", 3 * _NJ),  # body-origin linear velocities, world, m/s (body_state fills it)
    ("angvel", 3 * _NJ),  # angular velocities, world, rad/s
    ("rot", 9 * _NJ),  # world rotations, row-major 3 x 3
    ("hinge_q", 69),  # hinge angles, SMPL order, rad
    ("hinge_qd", 69),  # hinge rates, rad/s
    ("root_angvel", 3),  # the free root's angular qvel (root frame), rad/s
    ("root_linvel", 3),  # the free root's linear qvel (world), m/s
    ("root_z", 1),  # the free root's qpos height, m
    ("torque", 69),  # actuator torques, SMPL order, N m
    # inputs of body_state: the velocities at the pelvis subtree's COM (cvel) and the cross
    # product's operands, gathered in the permuted order it needs
    ("com_vel", 3 * _NJ),
    ("angvel_c1", 3 * _NJ),
    ("angvel_c2", 3 * _NJ),
    ("pos_c1", 3 * _NJ),
    ("pos_c2", 3 * _NJ),
    ("com_c1", 3 * _NJ),
    ("com_c2", 3 * _NJ),
)
"""Layout of a state row (:meth:`Humanoid.gather`): ``(name, length)`` in order, float64,
joints in SMPL order. Once :func:`body_state` has run, ``pos, vel, angvel`` are ``pvw (3, 24,
3)`` and ``rot`` is ``(24, 3, 3)``; ``hinge_qd`` and ``root_angvel`` together are every angular
rate :meth:`Humanoid.blown_up` bounds."""
_ENDS = np.cumsum([n for _, n in ROW_PARTS])
ROW: dict[str, slice] = {
    k: slice(int(e) - n, int(e)) for (k, n), e in zip(ROW_PARTS, _ENDS, strict=True)
}
"""Where each part of a state row lies."""
ROW_DIM = int(_ENDS[-1])
_PVW, _ROT = slice(0, ROW["rot"].start), ROW["rot"]
_RATES = slice(ROW["hinge_qd"].start, ROW["root_angvel"].stop)


def body_state(rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Finish gathered state rows: body-origin velocities ``v + w x (p - com)`` (cvel is the
    velocity at the pelvis subtree's COM) into their ``vel`` part.

    Args:
        rows: ``(B, ROW_DIM)`` rows of :meth:`Humanoid.gather`, changed in place.

    Returns:
        Views into ``rows``: ``pvw (B, 3, 24, 3)`` positions (m), linear (m/s) and angular
        (rad/s) velocities, world, and ``rot (B, 24, 3, 3)`` world rotations (the numbers of
        :meth:`Humanoid.state`, bit for bit).
    """
    r = ROW
    r2 = rows[:, r["pos_c2"]] - rows[:, r["com_c2"]]
    r1 = rows[:, r["pos_c1"]] - rows[:, r["com_c1"]]
    r2 *= rows[:, r["angvel_c1"]]
    r1 *= rows[:, r["angvel_c2"]]
    r2 -= r1
    np.add(rows[:, r["com_vel"]], r2, out=rows[:, r["vel"]])
    b = rows.shape[0]
    return rows[:, _PVW].reshape(b, 3, _NJ, 3), rows[:, _ROT].reshape(b, _NJ, 3, 3)


def absurd_rows(rows: np.ndarray, cfg: HumanoidConfig, z_range: np.ndarray) -> np.ndarray:
    """Whether each gathered state is absurd (the bounds of :meth:`Humanoid.blown_up` after
    MuJoCo's warnings: the pelvis speed, any angular rate, the pelvis height; NaN counts as
    absurd).

    Args:
        rows: ``(B, ROW_DIM)`` gathered rows (:func:`body_state` not needed).
        cfg: The bounds.
        z_range: ``(B, 2)`` lowest and highest pelvis height allowed, m
            (:attr:`Humanoid.z_range` of each).

    Returns:
        ``(B,)`` bool.
    """
    lin = rows[:, ROW["root_linvel"]]
    ok = (lin * lin).sum(axis=1) <= cfg.blowup_lin_vel_mps**2
    ok &= np.abs(rows[:, _RATES]).max(axis=1) <= cfg.blowup_ang_vel_radps
    z = rows[:, ROW["root_z"].start]
    ok &= z >= z_range[:, 0]
    ok &= z <= z_range[:, 1]
    return ~ok


def _float64_span(arrays: list[np.ndarray]) -> tuple[np.ndarray, int]:
    """A float64 view of the memory from the first to the end of the last of ``arrays`` (all
    parts of one ``MjData`` buffer, which MuJoCo allocates once) and the address it starts
    at: one ``take`` on it gathers any of their elements."""
    addr = [a.__array_interface__["data"][0] for a in arrays]
    base = min(addr)
    end = max(p + a.nbytes for p, a in zip(addr, arrays, strict=True))
    if any((p - base) % 8 for p in addr) or any(a.dtype != np.float64 for a in arrays):
        raise ValueError("MjData arrays are not float64 arrays 8-byte aligned to each other")
    buf = (ctypes.c_double * ((end - base) // 8)).from_address(base)
    return np.ctypeslib.as_array(buf), base


def _as_slice(idx: np.ndarray) -> slice | np.ndarray:
    """A slice for consecutive indices (basic indexing is cheaper than fancy indexing)."""
    if idx.size and np.array_equal(idx, np.arange(idx[0], idx[0] + idx.size)):
        return slice(int(idx[0]), int(idx[0]) + idx.size)
    return idx


@dataclass(frozen=True)
class HumanoidConfig:
    """Stepping and blow-up detection of a :class:`Humanoid`.

    Attributes:
        substeps: Physics steps per control step.
        blowup_lin_vel_mps: Pelvis speed above which the state is a blow-up, m/s.
        blowup_ang_vel_radps: Angular speed of any joint above which the state is a blow-up,
            rad/s.
        blowup_height_m: Pelvis height above the highest terrain point that is a blow-up, m.
        blowup_depth_m: Pelvis depth below the floor (z = 0) that is a blow-up, m.
    """

    substeps: int = 2
    blowup_lin_vel_mps: float = 50.0
    blowup_ang_vel_radps: float = 200.0
    blowup_height_m: float = 4.0
    blowup_depth_m: float = 1.0


class Humanoid:
    """One compiled humanoid (one scene) with its data, stepped by PD targets.

    Args:
        model: The compiled humanoid (:func:`grip.core.mjcf.build_mjcf`, maybe with a height
            field), modified in place when another subject is switched in (:meth:`switch`).
        cfg: Stepping and blow-up bounds.
        key: The subject the model was compiled for (any hashable, e.g. ``(height_m,
            mass_kg)``).
        terrain: Heights of the scene's terrain (``None``: the flat floor z = 0).
        terrain_top_m: Highest terrain point, m (bounds the blow-up check).
        arrays: :class:`grip.sim.model.ModelArrays` of ``model`` when already made (of the
            compiled model ``model`` is an unchanged copy of: shared, read only).
    """

    def __init__(self, model: mujoco.MjModel, cfg: HumanoidConfig = HumanoidConfig(),
                 key: Hashable = None, terrain: HeightSampler | None = None,
                 terrain_top_m: float = 0.0,
                 arrays: ModelArrays | None = None) -> None:  # fmt: skip
        self.model, self.cfg, self.terrain = model, cfg, terrain
        self.index = ix = HumanoidIndex.from_model(model)
        self.data = d = mujoco.MjData(model)
        act = ix.actuator_ids
        rng = model.actuator_ctrlrange[act]
        self.lo, self.hi = rng[:, 0].copy(), rng[:, 1].copy()  # (69,) hinge limits, rad
        self.half = 0.5 * (rng[:, 1] - rng[:, 0])  # (69,) half the hinge ranges, rad
        self.pelvis_body = int(ix.body_ids[0])
        self.variants = ModelVariants(model, key, arrays)
        self.kd_over_kp = self._kd_over_kp()
        # views of MjData arrays, taken once (attribute access through the bindings is slow)
        self.xpos, self.xmat, self.cvel = d.xpos, d.xmat, d.cvel
        self.com = d.subtree_com[self.pelvis_body]  # (3,) subtree COM of the pelvis
        self.ctrl, self.qvel, self.qpos = d.ctrl, d.qvel, d.qpos
        self.act_force = d.actuator_force
        self.warnings = d.warning.number  # live view
        self.act = _as_slice(act)
        rv = ix.root_dof_adr
        self._lin = slice(rv, rv + 3)  # qvel of the pelvis' linear velocity
        self._ang = _as_slice(np.setdiff1d(np.arange(model.nv), np.arange(rv, rv + 3)))
        self._root_z = ix.root_qpos_adr + 2
        self.z_range = (-cfg.blowup_depth_m, terrain_top_m + cfg.blowup_height_m)
        self._feet: FootContacts | None = None
        self._geoms = np.flatnonzero(model.geom_bodyid > 0)
        self._span, self._row_idx = self._row_index()
        self._row = np.empty((1, ROW_DIM))  # (state())

    def _row_index(self) -> tuple[np.ndarray, np.ndarray]:
        """The span of ``MjData`` memory a state row is gathered from and the index of each
        row element in it (:data:`ROW_PARTS`). The span is a view of ``self.data``'s memory
        (it lives as long as the humanoid keeps its data)."""
        d, ix = self.data, self.index
        arrays = [d.qpos, d.qvel, d.xpos, d.xmat, d.cvel, d.subtree_com, d.actuator_force]
        span, base = _float64_span(arrays)

        def at(a: np.ndarray, idx) -> np.ndarray:
            return (a.__array_interface__["data"][0] - base) // 8 + np.asarray(idx).ravel()

        ids = ix.body_ids[:, None]
        xyz = np.arange(3)
        com = 3 * self.pelvis_body
        parts = {
            "pos": at(d.xpos, 3 * ids + xyz),
            "vel": at(d.cvel, 6 * ids + 3 + xyz),  # (overwritten by body_state)
            "angvel": at(d.cvel, 6 * ids + xyz),
            "rot": at(d.xmat, 9 * ids + np.arange(9)),
            "hinge_q": at(d.qpos, ix.hinge_qpos_adr),
            "hinge_qd": at(d.qvel, ix.hinge_dof_adr),
            "root_angvel": at(d.qvel, ix.root_dof_adr + 3 + xyz),
            "root_linvel": at(d.qvel, ix.root_dof_adr + xyz),
            "root_z": at(d.qpos, [ix.root_qpos_adr + 2]),
            "torque": at(d.actuator_force, ix.actuator_ids),
            "com_vel": at(d.cvel, 6 * ids + 3 + xyz),
            "angvel_c1": at(d.cvel, 6 * ids + _C1),
            "angvel_c2": at(d.cvel, 6 * ids + _C2),
            "pos_c1": at(d.xpos, 3 * ids + _C1),
            "pos_c2": at(d.xpos, 3 * ids + _C2),
            "com_c1": at(d.subtree_com, np.tile(com + _C1, _NJ)),
            "com_c2": at(d.subtree_com, np.tile(com + _C2, _NJ)),
        }
        idx = np.concatenate([parts[k] for k, _ in ROW_PARTS]).astype(np.intp)
        if idx.shape != (ROW_DIM,) or idx.min() < 0 or idx.max() >= span.size:
            raise ValueError("state row index outside the MjData span")
        return span, idx

    # ------------------------------------------------------------------ subjects
    def _kd_over_kp(self) -> np.ndarray:
        act = self.index.actuator_ids
        return -self.model.actuator_biasprm[act, 2] / self.model.actuator_gainprm[act, 0]

    @property
    def key(self) -> Hashable:
        """The subject switched in."""
        return self.variants.key

    def has(self, key: Hashable) -> bool:
        """Whether subject ``key`` was added."""
        return key in self.variants

    def add(self, key: Hashable, compiled: mujoco.MjModel,
            arrays: ModelArrays | None = None) -> None:  # fmt: skip
        """Register another subject from its compiled model (same topology; ``arrays``: its
        :class:`grip.sim.model.ModelArrays` when already made)."""
        self.variants.add(key, compiled, arrays)

    def switch(self, key: Hashable) -> None:
        """Make the model that of subject ``key`` (added before)."""
        if key != self.variants.key:
            self.variants.switch(key)
            self.kd_over_kp = self._kd_over_kp()

    # ------------------------------------------------------------------ state in
    def reset(self, qpos76: np.ndarray, qvel75: np.ndarray) -> None:
        """Start from a pose and velocity (fresh ``MjData``; PD targets at the pose)."""
        m, d, ix = self.model, self.data, self.index
        mujoco.mj_resetData(m, d)
        write_pose_vector(qpos76, ix, d.qpos)
        write_velocity_vector(qvel75, ix, d.qvel)
        d.ctrl[ix.actuator_ids] = np.clip(qpos76[7:], self.lo, self.hi)
        mujoco.mj_forward(m, d)
        self.warnings[_UNSTABLE] = 0

    def teleport(self, qpos76: np.ndarray, qvel75: np.ndarray | None = None) -> None:
        """Put the body in a new state, lifted or lowered so that its lowest geom rests on the
        terrain under it (GRIP's fall recovery); hinges are clipped to their limits and the PD
        targets set to them. ``qvel75``: zeros if ``None``.

        Raises:
            ValueError: Not a finite ``(76,)`` pose and ``(75,)`` velocity.
        """
        m, d, ix = self.model, self.data, self.index
        q = np.asarray(qpos76, dtype=np.float64).reshape(-1)
        v = np.zeros(75) if qvel75 is None else np.asarray(qvel75, dtype=np.float64).reshape(-1)
        finite = np.isfinite(q).all() and np.isfinite(v).all()
        if q.shape != (76,) or v.shape != (75,) or not finite:
            raise ValueError(f"teleport needs finite (76,) qpos and (75,) qvel, got {q.shape}, "
                             f"{v.shape}")  # fmt: skip
        q = q.copy()
        q[7:] = np.clip(q[7:], self.lo, self.hi)
        write_pose_vector(q, ix, d.qpos)
        write_velocity_vector(v, ix, d.qvel)
        d.ctrl[ix.actuator_ids] = q[7:]
        mujoco.mj_forward(m, d)
        d.qpos[self._root_z] -= self.lowest_clearance()
        mujoco.mj_forward(m, d)
        self.warnings[_UNSTABLE] = 0

    def set_targets(self, target69: np.ndarray) -> None:
        """PD targets of the 69 hinges (SMPL order, rad), clipped to their limits."""
        self.ctrl[self.act] = np.minimum(np.maximum(target69, self.lo), self.hi)

    def push_pelvis(self, force: np.ndarray) -> None:
        """A world-frame force (N, ``(3,)``) at the pelvis' centre of mass until changed (zeros
        end it; :meth:`reset` clears it)."""
        self.data.xfrc_applied[self.pelvis_body, :3] = force

    # ------------------------------------------------------------------ stepping
    def step(self) -> None:
        """One control step: ``cfg.substeps`` physics steps toward the PD targets."""
        m, d = self.model, self.data
        # mj_step = mj_step1 (positions, velocities) + mj_step2 (forces, integration). Run them
        # as step2 + step1 so that positions and velocities of the new state are computed once,
        # by the step itself (same trajectory as mj_step, bit for bit).
        for _ in range(self.cfg.substeps):
            mujoco.mj_step2(m, d)
            mujoco.mj_step1(m, d)

    def step_pinned(self, root_from: np.ndarray, root_to: np.ndarray,
                    root_vel: np.ndarray) -> None:  # fmt: skip
        """One control step with the root written before each substep: position interpolated
        from ``root_from[:3]`` to ``root_to[:3]``, orientation ``root_from[3:7]`` for the first
        half of the substeps and ``root_to[3:7]`` after, velocity ``root_vel (6,)`` (a physics
        check of the PD servos, not a mode of training or inference)."""
        m, d, ix = self.model, self.data, self.index
        r, rv, n = ix.root_qpos_adr, ix.root_dof_adr, self.cfg.substeps
        for k in range(n):
            f = (k + 1) / n
            d.qpos[r : r + 3] = (1 - f) * root_from[:3] + f * root_to[:3]
            d.qpos[r + 3 : r + 7] = (root_to if f >= 0.5 else root_from)[3:7]
            d.qvel[rv : rv + 6] = root_vel
            mujoco.mj_step(m, d)
        mujoco.mj_step1(m, d)  # derived quantities of the final state (see step())

    def warned(self) -> bool:
        """Whether MuJoCo could not integrate the state since the last check (its bad-qpos/
        qvel/qacc warnings; it then reset ``MjData`` itself). Clears them. The first half of
        :meth:`blown_up`."""
        w = self.warnings
        if w[_W_QPOS] or w[_W_QVEL] or w[_W_QACC]:  # (scalar reads: cheaper than w[_UNSTABLE])
            w[_UNSTABLE] = 0
            return True
        return False

    def blown_up(self) -> bool:
        """Whether the state is a simulation blow-up: MuJoCo could not integrate it (its
        bad-qpos/qvel/qacc warnings, counted since the last check, then cleared), or it is
        absurd before MuJoCo's own limit (1e10): non-finite, the pelvis faster than
        ``cfg.blowup_lin_vel_mps``, any joint faster than ``cfg.blowup_ang_vel_radps``, the
        pelvis ``cfg.blowup_depth_m`` under the floor or ``cfg.blowup_height_m`` above the
        terrain. Costs ~3 us."""
        w = self.warnings
        if w[_W_QPOS] or w[_W_QVEL] or w[_W_QACC]:  # (scalar reads: cheaper than w[_UNSTABLE])
            w[_UNSTABLE] = 0
            return True
        cfg, v = self.cfg, self.qvel
        lin = v[self._lin]
        z = self.qpos[self._root_z]
        lo, hi = self.z_range
        # (written so that NaN fails every comparison and counts as a blow-up)
        ok = (float(lin @ lin) <= cfg.blowup_lin_vel_mps**2
              and float(np.abs(v[self._ang]).max()) <= cfg.blowup_ang_vel_radps
              and lo <= z <= hi)  # fmt: skip
        return not ok

    # ------------------------------------------------------------------ state out
    def gather(self, out: np.ndarray) -> np.ndarray:
        """The state as one row (:data:`ROW_PARTS`; finish it with :func:`body_state`): one
        ``take`` from ``MjData``, ~1 us.

        Args:
            out: ``(ROW_DIM,)`` float64 buffer, filled and returned.
        """
        return self._span.take(self._row_idx, out=out, mode="clip")

    def state(self) -> tuple[np.ndarray, np.ndarray]:
        """``pvw (3, 24, 3)`` world positions, linear and angular velocities of the bodies and
        ``rot (24, 3, 3)`` their world rotations (new arrays)."""
        row = self._row
        self._span.take(self._row_idx, out=row[0], mode="clip")
        pvw, rot = body_state(row)  # (cvel is the velocity at the subtree COM: v + w x r)
        return pvw[0].copy(), rot[0].copy()

    def hinge_angles(self) -> np.ndarray:
        """``(69,)`` hinge angles, SMPL order, rad (a copy)."""
        return self.qpos[self.index.hinge_qpos_adr]

    def hinge_velocities(self) -> np.ndarray:
        """``(69,)`` hinge rates, SMPL order, rad/s (a copy)."""
        return self.qvel[self.index.hinge_dof_adr]

    def torques(self) -> np.ndarray:
        """``(69,)`` actuator torques, SMPL order, N m (a view: copy to keep)."""
        return self.act_force[self.act]

    @property
    def sensors(self) -> bool:
        """Whether the physics step computes the model's sensors (IMU, insole touch and foot
        force sensors; on by default). They never act on the motion: a task that reads none
        of them turns them off, about 7 % of a training step's physics
        (``benchmarks/physics_settings.py``); :meth:`foot_forces` works either way."""
        return not self.model.opt.disableflags & _NO_SENSORS

    @sensors.setter
    def sensors(self, on: bool) -> None:
        opt = self.model.opt
        opt.disableflags = (opt.disableflags & ~_NO_SENSORS) | (0 if on else _NO_SENSORS)

    @property
    def islands(self) -> bool:
        """Whether MuJoCo splits the constraints into islands (on by default). The humanoid is
        one body tree on static ground, so there is one island to solve whatever the setting:
        off, the steps of 9,438 training states were bit for bit the same and 4 % cheaper
        (``benchmarks/physics_settings.py``; tested)."""
        return not self.model.opt.disableflags & _NO_ISLANDS

    @islands.setter
    def islands(self, on: bool) -> None:
        opt = self.model.opt
        opt.disableflags = (opt.disableflags & ~_NO_ISLANDS) | (0 if on else _NO_ISLANDS)

    def foot_forces(self) -> tuple[np.ndarray, np.ndarray]:
        """``grf (2, 3)`` ground reaction force on the left, right foot (N, world) and ``cop
        (2, 3)`` centre of pressure (m, NaN without contact): :class:`grip.sim.model.
        FootContacts` (does not change the simulation; the sensors it reads are computed for
        the call when :attr:`sensors` are off)."""
        if self._feet is None:
            self._feet = FootContacts(self.model, self.index)
        if self.sensors:
            return self._feet(self.data)
        self.sensors = True
        try:
            return self._feet(self.data)
        finally:
            self.sensors = False

    def heights_around(self, center_xy: np.ndarray, rot2: np.ndarray, grid: np.ndarray,
                       out: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """Terrain heights at ``center_xy + grid @ rot2.T`` (``(N,)``, m; zeros when flat)."""
        if self.terrain is None:
            if out is None:
                return np.zeros(len(grid))
            out.fill(0.0)
            return out
        return self.terrain(center_xy, rot2, grid, out)

    def lowest_clearance(self) -> float:
        """Height of the lowest geom point (bounding-box corner) above the terrain under it, m."""
        m, d, g = self.model, self.data, self._geoms
        rot = d.geom_xmat[g].reshape(-1, 3, 3)
        centre = d.geom_xpos[g] + np.einsum("gij,gj->gi", rot, m.geom_aabb[g, :3])
        z = centre[:, 2] - np.einsum("gj,gj->g", np.abs(rot[:, 2]), m.geom_aabb[g, 3:])
        mid = centre[:, :2].mean(axis=0)
        ground = self.heights_around(mid, np.eye(2), centre[:, :2] - mid)
        return float((z - ground).min())
