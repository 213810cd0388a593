"""Observation parts of the tracking task as pure numpy functions (GRIP Sec. 3.3-3.4).

Everything is expressed in the simulated humanoid's *heading frame*: a yaw-only frame at the
pelvis whose x axis points where the body faces (the pelvis' canonical +z axis projected on
the floor), y to its left, z up. World row vectors ``v`` become ``v @ H`` with ``H`` from
:func:`heading_matrix` (``H.T @ v`` for column vectors).

Shapes: J = 24 joints. 6D rotations are the first two matrix columns, ``(c0, c1)``.
"""

from __future__ import annotations

import math

import numpy as np

from grip.core import skeleton as sk
from grip.core.rotations import axis_angle_to_matrix, matrix_to_euler

IMU_JOINTS: tuple[int, ...] = (
    sk.IMU_BODY["L_Foot"], sk.IMU_BODY["R_Foot"], sk.IMU_BODY["L_Wrist"], sk.IMU_BODY["R_Wrist"],
)  # fmt: skip
"""Bodies carrying GRIP's four IMUs (ankles, forearms): where D_leaf's rotation terms live."""

SELF_DIM = 1 + 3 * (sk.N_JOINTS - 1) + 6 * sk.N_JOINTS + 3 * sk.N_JOINTS + 3 * sk.N_JOINTS

ROOT_GAP_CLIP_M = 1.0
"""``OAV_Jrel_root``: each axis of the followed pelvis minus the simulated one is clipped to
this, m (a body metres behind is told "far behind", not how far: the numbers stay in the
range training saw)."""


def kinematic_dim(variant: str) -> int:
    """Length of the state difference for a GRIP Table 4 variant."""
    n = len(IMU_JOINTS) * (6 + 3 + 6)  # d_theta, d_omega, theta_leaf
    if variant != "OA":
        n += 3 * len(sk.VELOCITY_JOINTS)  # d_v
    if variant.startswith("OAV_J"):
        n += 2 * 3 * sk.N_JOINTS  # d_p and p
    if variant == "OAV_Jrel_root":
        n += 2  # the followed pelvis minus the simulated one, horizontal
    return n


_IMU = np.array(IMU_JOINTS)
_VEL = np.array(sk.VELOCITY_JOINTS)
_N_IMU = len(IMU_JOINTS)
_N_SELF_VEC = (sk.N_JOINTS - 1) + 2 * sk.N_JOINTS  # rows of 3-vectors in O^self
_XY = np.array([1.0, 1.0, 0.0])


def heading_matrix(root_rot: np.ndarray) -> np.ndarray:
    """``(3, 3)`` yaw rotation whose x axis is the pelvis' facing direction on the floor."""
    fx, fy = float(root_rot[0, 2]), float(root_rot[1, 2])  # image of the canonical forward +z
    n = math.hypot(fx, fy)
    c, s = (fx / n, fy / n) if n > 1e-9 else (1.0, 0.0)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def heading_matrices(root_rot: np.ndarray) -> np.ndarray:
    """``(..., 3, 3)`` yaw rotations whose x axis is the pelvis' facing direction (vectorised
    :func:`heading_matrix`)."""
    fx, fy = root_rot[..., 0, 2], root_rot[..., 1, 2]
    n = np.hypot(fx, fy)
    ok = n > 1e-9
    h = np.zeros((*root_rot.shape[:-2], 3, 3))
    c, s = h[..., 0, 0], h[..., 1, 0]
    c[...] = 1.0
    np.divide(fx, n, out=c, where=ok)
    np.divide(fy, n, out=s, where=ok)
    h[..., 1, 1] = c
    np.negative(s, out=h[..., 0, 1])
    h[..., 2, 2] = 1.0
    return h


def observation_parts(
    variant: str,
    h: np.ndarray,
    sim_pvw: np.ndarray,
    sim_rot: np.ndarray,
    est_pos: np.ndarray,
    est_leaf_rot: np.ndarray,
    est_vel: np.ndarray,
    est_leaf_angvel: np.ndarray,
    est_root_pos: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """O^kin (GRIP's State Difference) and O^self, in the simulated heading frame.

    Both are built together so that every vector is rotated by one matrix product and every
    rotation by another (this runs at every control step).

    Args:
        variant: One of :data:`grip.task.config.KINEMATIC_OBS` (GRIP Table 4).
        h: ``(3, 3)`` heading matrix of the simulated pelvis (:func:`heading_matrix`).
        sim_pvw: ``(3, J, 3)`` simulated world joint positions (m), linear (m/s) and angular
            (rad/s) velocities.
        sim_rot: ``(J, 3, 3)`` simulated global joint rotations.
        est_pos: ``(J, 3)`` estimated joints minus the root (world axes), m.
        est_leaf_rot: ``(4, 3, 3)`` estimated global rotations of :data:`IMU_JOINTS`.
        est_vel: ``(6, 3)`` estimated world velocities of the velocity joints
            (:data:`grip.core.skeleton.VELOCITY_JOINTS`), m/s.
        est_leaf_angvel: ``(4, 3)`` estimated world angular velocities of :data:`IMU_JOINTS`,
            rad/s.
        est_root_pos: ``(3,)`` root integrated from the estimated pelvis velocity (J_glo), m.

    Returns:
        ``kinematic (kinematic_dim(variant),)`` = [d_theta (4x6): rotation from simulated to
        estimated orientation, theta_leaf (4x6): estimated orientation, d_omega (4x3)] at the
        IMU bodies, then [d_v (6x3)] (not in ``OA``), then [d_p (24x3), p (24x3)] (``J``
        variants; d_p root-relative for ``J_rel``, global via the integrated root for
        ``J_glo``; p = the estimated root-relative joints), then for ``OAV_Jrel_root`` the
        followed pelvis (``est_root_pos``) minus the simulated pelvis, horizontal (2: forward,
        left), each clipped to :data:`ROOT_GAP_CLIP_M`;
        ``self (SELF_DIM,)`` = [pelvis height (1), joints 1..23 minus the pelvis (69), linear
        velocities (72), angular velocities (72), rotations 6D (144)].
    """
    pos, vel, w = sim_pvw
    rel = pos - pos[0]
    rows = [rel[1:], vel, w, est_leaf_angvel - w[_IMU]]
    if variant != "OA":
        rows.append(est_vel - vel[_VEL])
    if variant.startswith("OAV_Jrel"):
        rows += [est_pos - rel, est_pos]
    elif variant == "OAV_Jglo":
        rows += [(est_root_pos + est_pos) - pos, est_pos]
    gap = variant == "OAV_Jrel_root"
    if gap:  # (the heading is a yaw: a horizontal vector stays horizontal)
        rows.append((est_root_pos - pos[0])[None] * _XY)
    vecs = np.concatenate(rows) @ h
    if gap:
        np.clip(vecs[-1], -ROOT_GAP_CLIP_M, ROOT_GAP_CLIP_M, out=vecs[-1])
    e_leaf = est_leaf_rot
    d_rot = e_leaf @ np.swapaxes(sim_rot[_IMU], -1, -2)
    # Only the first two columns of each rotation are needed (6D). H.T @ R[:, :2] for every R
    # is one (2M x 3) @ (3 x 3) product on the transposed columns; d_theta = H.T d_rot H.
    cols = np.concatenate([sim_rot[..., :2], e_leaf[..., :2], d_rot @ h[:, :2]])
    six = (np.swapaxes(cols, 1, 2).reshape(-1, 3) @ h).reshape(-1, 6)
    n = sk.N_JOINTS
    self_vec = np.concatenate([pos[0, 2:3], vecs[:_N_SELF_VEC].ravel(), six[:n].ravel()])
    kin = np.concatenate([six[n + _N_IMU :].ravel(), six[n : n + _N_IMU].ravel(),
                          vecs[_N_SELF_VEC : len(vecs) - gap].ravel(),
                          vecs[-1, :2] if gap else vecs[:0, 0]])  # fmt: skip
    return kin, self_vec


def observation_parts_batch(
    variant: str,
    h: np.ndarray,
    sim_pvw: np.ndarray,
    sim_rot: np.ndarray,
    est_pos: np.ndarray,
    est_leaf_rot: np.ndarray,
    est_vel: np.ndarray,
    est_leaf_angvel: np.ndarray,
    est_root_pos: np.ndarray,
    out_kin: np.ndarray | None = None,
    out_self: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`observation_parts` of B states at once (the tracking environments' step).

    Args:
        variant: As :func:`observation_parts`.
        h: ``(B, 3, 3)`` heading matrices.
        sim_pvw: ``(B, 3, J, 3)``; sim_rot: ``(B, J, 3, 3)``; est_pos: ``(B, J, 3)``;
            est_leaf_rot: ``(B, 4, 3, 3)``; est_vel: ``(B, 6, 3)``; est_leaf_angvel:
            ``(B, 4, 3)``; est_root_pos: ``(B, 3)``: the arguments of
            :func:`observation_parts` stacked.
        out_kin, out_self: Buffers to write the results into (e.g. float32: the same numbers
            cast); new float64 arrays when ``None``.

    Returns:
        ``kinematic (B, kinematic_dim(variant))`` and ``self (B, SELF_DIM)`` (equal to the
        unbatched function's to float rounding: its 3 x 3 products may sum in another order).
    """
    b = h.shape[0]
    pos, vel, w = sim_pvw[:, 0], sim_pvw[:, 1], sim_pvw[:, 2]
    rel = pos - pos[:, :1]
    rows = [rel[:, 1:], vel, w, est_leaf_angvel - w[:, _IMU]]
    if variant != "OA":
        rows.append(est_vel - vel[:, _VEL])
    if variant.startswith("OAV_Jrel"):
        rows += [est_pos - rel, est_pos]
    elif variant == "OAV_Jglo":
        rows += [(est_root_pos[:, None] + est_pos) - pos, est_pos]
    gap = variant == "OAV_Jrel_root"
    if gap:
        rows.append((est_root_pos - pos[:, 0])[:, None] * _XY)
    vecs = np.concatenate(rows, axis=1) @ h
    if gap:
        np.clip(vecs[:, -1], -ROOT_GAP_CLIP_M, ROOT_GAP_CLIP_M, out=vecs[:, -1])
    e_leaf = est_leaf_rot
    d_rot = e_leaf @ np.swapaxes(sim_rot[:, _IMU], -1, -2)
    cols = np.concatenate([sim_rot[..., :2], e_leaf[..., :2], d_rot @ h[:, None, :, :2]], axis=1)
    six = (np.swapaxes(cols, -1, -2).reshape(b, -1, 3) @ h).reshape(b, -1, 6)
    n = sk.N_JOINTS
    self_vec = np.concatenate([pos[:, 0, 2:3], vecs[:, :_N_SELF_VEC].reshape(b, -1),
                               six[:, :n].reshape(b, -1)], axis=1, out=out_self)  # fmt: skip
    kin = np.concatenate([six[:, n + _N_IMU :].reshape(b, -1),
                          six[:, n : n + _N_IMU].reshape(b, -1),
                          vecs[:, _N_SELF_VEC : vecs.shape[1] - gap].reshape(b, -1),
                          vecs[:, -1, :2] if gap else vecs[:, :0, 0]], axis=1,
                         out=out_kin)  # fmt: skip
    return kin, self_vec


def heightmap_grid(n: int = 25, extent_m: float = 1.5) -> np.ndarray:
    """Local sample offsets of the height-map observation.

    Args:
        n: Samples per side (>= 2).
        extent_m: Side of the square, metres; samples span ``[-extent_m/2, extent_m/2]``.

    Returns:
        (n*n, 2) float64 offsets ``(x, y)`` in the heading frame (x = forward, y = left),
        metres, row-major like :class:`envs.heightfield.HeightField`: ``grid.reshape(n, n,
        2)[i, j] = (s[j], s[i])`` with ``s = linspace(-extent_m/2, extent_m/2, n)``, i.e. rows
        run along the left axis and columns along the forward axis.
    """
    if n < 2:
        raise ValueError(f"n must be >= 2, got {n}")
    s = np.linspace(-extent_m / 2.0, extent_m / 2.0, n)
    gx, gy = np.meshgrid(s, s)  # gx[i, j] = s[j], gy[i, j] = s[i]
    return np.ascontiguousarray(np.column_stack([gx.ravel(), gy.ravel()]))


def observe(
    variant: str,
    sim_pvw: np.ndarray,
    sim_rot: np.ndarray,
    est_pos: np.ndarray,
    est_leaf_rot: np.ndarray,
    est_vel: np.ndarray,
    est_leaf_angvel: np.ndarray,
    est_root_pos: np.ndarray,
    sensor: np.ndarray,
    grid: np.ndarray,
    terrain=None,
    out: np.ndarray | None = None,
) -> dict[str, np.ndarray]:
    """The policy's observation dict (float32 arrays): ``"sensor"`` (the KinematicsNet inputs),
    ``"kinematic"`` and ``"self"`` (:func:`observation_parts`) and ``"environment"`` (terrain
    height minus pelvis height on ``grid``, turned with the heading).

    Args:
        variant, sim_pvw, sim_rot, est_pos, est_leaf_rot, est_vel, est_leaf_angvel,
            est_root_pos: As :func:`observation_parts` (the heading comes from ``sim_rot[0]``).
        sensor: ``(F,)`` KinematicsNet input features of the frame.
        grid: ``(N, 2)`` height-map offsets in the heading frame, m
            (:func:`heightmap_grid`).
        terrain: ``(center_xy, rot2, grid, out) -> (N,)`` terrain heights
            (:attr:`grip.sim.humanoid.Humanoid.terrain`), ``None`` for the flat floor.
        out: ``(N,)`` float64 buffer for the terrain heights.
    """
    root = sim_pvw[0, 0]
    h = heading_matrix(sim_rot[0])
    kin, self_vec = observation_parts(variant, h, sim_pvw, sim_rot, est_pos, est_leaf_rot,
                                      est_vel, est_leaf_angvel, est_root_pos)  # fmt: skip
    if terrain is None:  # flat floor: the height map is the pelvis height
        hm = np.full(grid.shape[0], -root[2], dtype=np.float32)
    else:
        hm = (terrain(root[:2], h[:2, :2], grid, out) - root[2]).astype(np.float32)
    return {
        "sensor": sensor.astype(np.float32),
        "kinematic": kin.astype(np.float32),
        "self": self_vec.astype(np.float32),
        "environment": hm,
    }


_OBS_ROW_PARTS = (("est_pos", 3 * sk.N_JOINTS), ("leaf_rot", 9 * _N_IMU),
                  ("est_vel", 3 * len(sk.VELOCITY_JOINTS)), ("leaf_angvel", 3 * _N_IMU),
                  ("est_root_pos", 3))  # fmt: skip
_OBS_ENDS = np.cumsum([n for _, n in _OBS_ROW_PARTS])
OBS_ROW: dict[str, slice] = {
    k: slice(int(e) - n, int(e)) for (k, n), e in zip(_OBS_ROW_PARTS, _OBS_ENDS, strict=True)
}
"""Where each estimate input of :func:`observation_parts` lies in a row of
:attr:`EstimateFrames.obs_rows`: ``est_pos (J, 3)``, ``est_leaf_rot (4, 3, 3)``, ``est_vel (6,
3)``, ``est_leaf_angvel (4, 3)``, ``est_root_pos (3,)``, flattened."""
OBS_ROW_DIM = int(_OBS_ENDS[-1])


def sensor_context_rows(x: np.ndarray, window: int) -> np.ndarray:
    """``(T, F)`` sensor features -> ``(T, 2F)``: each feature's mean and standard deviation
    over the last ``window`` frames up to and including each frame (fewer at the start), the
    context a gate reads beside the frame (:attr:`grip.task.config.TrackingEnvConfig.
    sensor_context`; :func:`sensor_context_at` gives one row of it)."""
    x = np.asarray(x, np.float64)
    zero = np.zeros((1, x.shape[1]))
    c1 = np.cumsum(np.vstack([zero, x]), 0)
    c2 = np.cumsum(np.vstack([zero, x * x]), 0)
    t = np.arange(1, len(x) + 1)
    lo = np.maximum(t - max(int(window), 1), 0)
    n = (t - lo)[:, None]
    mean = (c1[t] - c1[lo]) / n
    var = np.maximum((c2[t] - c2[lo]) / n - mean * mean, 0.0)
    return np.hstack([mean, np.sqrt(var)])


def sensor_context_at(x: np.ndarray, t: int, window: int) -> np.ndarray:
    """Row ``t`` of :func:`sensor_context_rows` ``(2F,)`` float32, from frames ``t - window +
    1 .. t`` of ``x (T, F)`` alone (a growing stream's frames after ``t`` are not read)."""
    w = np.asarray(x[max(int(t) - max(int(window), 1) + 1, 0): int(t) + 1], np.float64)
    return np.concatenate([w.mean(0), w.std(0)]).astype(np.float32)


def observation_rows(
    variant: str,
    h: np.ndarray,
    sim_pvw: np.ndarray,
    sim_rot: np.ndarray,
    est_rows: np.ndarray,
    out_kin: np.ndarray | None = None,
    out_self: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`observation_parts_batch` with the estimate's inputs as rows of
    :attr:`EstimateFrames.obs_rows` (``est_rows (B, OBS_ROW_DIM)``, the root already offset)."""
    b, r = est_rows.shape[0], OBS_ROW
    return observation_parts_batch(
        variant, h, sim_pvw, sim_rot, est_rows[:, r["est_pos"]].reshape(b, sk.N_JOINTS, 3),
        est_rows[:, r["leaf_rot"]].reshape(b, _N_IMU, 3, 3),
        est_rows[:, r["est_vel"]].reshape(b, -1, 3),
        est_rows[:, r["leaf_angvel"]].reshape(b, _N_IMU, 3), est_rows[:, r["est_root_pos"]],
        out_kin, out_self)  # fmt: skip


_VEL_ROWS = OBS_ROW["est_vel"]
_ROOT_XY = slice(OBS_ROW["est_root_pos"].start, OBS_ROW["est_root_pos"].start + 2)
_N_VEL = len(sk.VELOCITY_JOINTS)
_PELVIS_VEL = sk.VELOCITY_JOINTS.index(0)


def carried_faster(est_vel: np.ndarray, scale) -> np.ndarray:
    """``est_vel (..., 6, 3)`` (the world velocities of :data:`grip.core.skeleton.
    VELOCITY_JOINTS`) of the same motion carried over the ground ``scale`` times as fast (a
    number, or one per leading row): ``(scale - 1)`` x the pelvis' horizontal velocity added to
    every velocity joint's, the pelvis' own horizontal velocity so ``scale`` times itself. A new
    array. The root-speed augmentation (:func:`scale_root_speed`) and its probe
    (``benchmarks/pace_cause.py --root-speed-scale``) share it."""
    v = np.array(est_vel, dtype=np.float64)
    f = np.asarray(scale, dtype=np.float64).reshape((*np.shape(scale), 1, 1))
    v[..., :2] += (f - 1.0) * v[..., _PELVIS_VEL, None, :2]
    return v


def scale_root_speed(est_rows: np.ndarray, scale) -> None:
    """Make the rows of :attr:`EstimateFrames.obs_rows` (``est_rows (B, OBS_ROW_DIM)``, before
    an episode's root offset) describe the same pose carried over the ground ``scale`` (one
    number, or one per row) times as fast, in place: the integrated root's horizontal
    coordinates times ``scale`` (the episode's offset, :func:`root_speed_offset`, puts its start
    where the episode starts) and the velocity joints' velocities as :func:`carried_faster`
    gives them. Root-relative positions and orientations stay. The training task's root-speed
    augmentation (``TrackingEnvConfig.root_speed_range``)."""
    f = np.broadcast_to(np.asarray(scale, dtype=np.float64).reshape(-1), (len(est_rows),))
    est_rows[:, _ROOT_XY] *= f[:, None]
    vel = est_rows[:, _VEL_ROWS].reshape(len(est_rows), _N_VEL, 3)
    est_rows[:, _VEL_ROWS] = carried_faster(vel, f).reshape(len(est_rows), -1)


def root_speed_offset(start_pos: np.ndarray, root_at_start: np.ndarray,
                      scale: float) -> np.ndarray:  # fmt: skip
    """``(3,)`` the offset added to a root scaled by :func:`scale_root_speed` (its horizontal
    coordinates times ``scale``) so that it is at ``start_pos`` at the episode's start, where
    the unscaled integrated root is ``root_at_start``."""
    out = np.asarray(start_pos, dtype=np.float64) - np.asarray(root_at_start, dtype=np.float64)
    out[:2] -= (scale - 1.0) * np.asarray(root_at_start, dtype=np.float64)[:2]
    return out


class EstimateFrames:
    """A kinematic estimate laid out for the control step: what the observation and a relative
    action read per frame, gathered once per clip (and per new frame of a growing one) rather
    than per step. Shared by the training task and the inference pipeline, so both observe
    and act alike.

    ``est`` is any object with the estimate arrays of :class:`grip.core.reference.
    ReferenceClip` (``est_pos``, ``est_rot``, ``est_vel``, ``est_angvel``, ``est_hinge``,
    ``est_hinge_vel``, ``est_root_pos``, ``sensor``; rows at least ``n_frames``).

    Attributes:
        leaf_rot: ``(T, 4, 3, 3)`` estimated rotations of :data:`IMU_JOINTS`.
        leaf_angvel: ``(T, 4, 3)`` their angular velocities, rad/s.
        target: ``(T, 69)`` PD target of a relative action of 0: the estimated hinge angles
            (plus ``kd/kp`` x their rates with velocity feed-forward), rad.
        obs_rows: ``(T, OBS_ROW_DIM)`` what :func:`observation_parts` reads of each frame, one
            row per frame (:data:`OBS_ROW`; ``leaf_rot`` and ``leaf_angvel`` are views of it;
            the root is the integrated one, without an episode's offset).
    """

    def __init__(self) -> None:
        self.est = None
        self._key: tuple | None = None
        self.leaf_rot = self.leaf_angvel = self.target = np.zeros(0)
        self.obs_rows = np.zeros((0, OBS_ROW_DIM))

    def update(self, est, kd_over_kp: np.ndarray, feedforward: bool, start: int = 0,
               key=None) -> None:  # fmt: skip
        """Gather frames ``start..est.n_frames - 1`` of ``est`` (all of them when ``est`` or
        ``key`` changed, or its arrays were reallocated)."""
        rows = len(est.est_pos)  # a growing estimate's capacity, else its length
        if self._key != (est, key) or len(self.target) != rows:
            self._key, self.est, start = (est, key), est, 0
            self.obs_rows = o = np.zeros((rows, OBS_ROW_DIM))
            self.leaf_rot = o[:, OBS_ROW["leaf_rot"]].reshape(rows, _N_IMU, 3, 3)
            self.leaf_angvel = o[:, OBS_ROW["leaf_angvel"]].reshape(rows, _N_IMU, 3)
            self.target = np.empty((rows, 3 * (sk.N_JOINTS - 1)))
        sl = slice(start, est.n_frames)
        self.leaf_rot[sl] = est.est_rot[sl, IMU_JOINTS]
        self.leaf_angvel[sl] = est.est_angvel[sl, IMU_JOINTS]
        o, n = self.obs_rows[sl], est.n_frames - start
        o[:, OBS_ROW["est_pos"]] = est.est_pos[sl].reshape(n, -1)
        o[:, OBS_ROW["est_vel"]] = est.est_vel[sl].reshape(n, -1)
        o[:, OBS_ROW["est_root_pos"]] = est.est_root_pos[sl]
        ref = self.target[sl]
        ref[:] = est.est_hinge[sl]
        if feedforward:
            ref += kd_over_kp * est.est_hinge_vel[sl]

    def pd_target(self, action: np.ndarray, t: int, relative: bool, gain: np.ndarray,
                  lo: np.ndarray, half: np.ndarray,
                  lean: np.ndarray | None = None) -> np.ndarray:  # fmt: skip
        """``(69,)`` PD target of an action toward frame ``t`` (the action clipped to [-1, 1]):
        relative: ``target[t] + action x gain``; absolute: the action spans ``lo .. lo + 2
        half`` (the hinge ranges), rad. The humanoid clips it to the hinge limits. ``lean``
        (3, 3): frame ``t``'s upper body turned by it about the pelvis (:func:`lean_hinges`;
        relative actions only)."""
        a = np.minimum(np.maximum(action, -1.0), 1.0)  # (np.clip's dispatch costs more per step)
        if relative:
            ref = self.target[t] if lean is None else self.target[t] + lean_hinges(
                self.est.est_rot[t], lean)  # fmt: skip
            return ref + a * gain
        return lo + (a + 1.0) * half

    def observe(self, t: int, variant: str, sim_pvw: np.ndarray, sim_rot: np.ndarray,
                root_offset: np.ndarray, grid: np.ndarray, terrain=None,
                out: np.ndarray | None = None,
                lean: np.ndarray | None = None) -> dict[str, np.ndarray]:  # fmt: skip
        """:func:`observe` against estimate frame ``t`` (the frame the next action aims at);
        ``root_offset (3,)`` is added to the integrated root (where the episode started);
        ``lean (3, 3)`` turns the frame's upper body about the pelvis (:func:`leaned`)."""
        e = self.est
        pos, leaf_rot, vel = e.est_pos[t], self.leaf_rot[t], e.est_vel[t]
        if lean is not None:
            pos, rot, vel = leaned(pos, e.est_rot[t], vel, lean)
            leaf_rot = rot[list(IMU_JOINTS)]
        return observe(variant, sim_pvw, sim_rot, pos, leaf_rot, vel, self.leaf_angvel[t],
                       e.est_root_pos[t] + root_offset, e.sensor[t], grid, terrain,
                       out)  # fmt: skip


UPPER_BODY: tuple[int, ...] = (3, 6, 9, 12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23)
"""The joints above the pelvis (spine, neck, head, collars, arms): what a lean turns."""
_UPPER_VEL = [i for i, j in enumerate(sk.VELOCITY_JOINTS) if j in UPPER_BODY]


def _turned_upper(pos: np.ndarray, vel: np.ndarray,
                  lean: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """New ``pos (..., 24, 3)`` root-relative joints and ``vel (..., 6, 3)`` velocity joints'
    velocities with :data:`UPPER_BODY` turned by ``lean (..., 3, 3)`` about the pelvis (the
    upper velocities relative to the pelvis', the last row)."""
    up = list(UPPER_BODY)
    pos, vel = pos.copy(), vel.copy()
    pos[..., up, :] = np.einsum("...ij,...kj->...ki", lean, pos[..., up, :])
    rel = vel[..., _UPPER_VEL, :] - vel[..., -1:, :]
    vel[..., _UPPER_VEL, :] = vel[..., -1:, :] + np.einsum("...ij,...kj->...ki", lean, rel)
    return pos, vel


def leaned(pos: np.ndarray, rot: np.ndarray, vel: np.ndarray,
           lean: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # fmt: skip
    """An estimate's upper body (:data:`UPPER_BODY`) turned by ``lean (..., 3, 3)`` about the
    pelvis, one frame or ``(T, ...)`` frames: ``pos (..., 24, 3)`` root-relative joints, ``rot
    (..., 24, 3, 3)`` global rotations and ``vel (..., 6, 3)`` the velocity joints' (the upper
    ones turned relative to the pelvis', the last row); new arrays, the inputs untouched."""
    pos, vel = _turned_upper(pos, vel, lean)
    rot = rot.copy()
    up = list(UPPER_BODY)
    rot[..., up, :, :] = lean[..., None, :, :] @ rot[..., up, :, :]
    return pos, rot, vel


def lean_towards(forward_xy: np.ndarray, deg) -> np.ndarray:
    """``(..., 3, 3)`` rotations about the horizontal axis across the unit horizontal
    directions ``forward_xy (..., 2)`` that turn the vertical ``deg`` (one number, or one per
    leading row; negative: away) towards them: a lean forward about the pelvis."""
    f = np.asarray(forward_xy, dtype=np.float64)
    axis = np.stack([-f[..., 1], f[..., 0], np.zeros(f.shape[:-1])], axis=-1)  # z x forward
    return axis_angle_to_matrix(axis * np.radians(np.asarray(deg, dtype=np.float64))[..., None])


def forward_lean(root_rot: np.ndarray, deg) -> np.ndarray:
    """:func:`lean_towards` the facing direction of pelvis rotations ``root_rot (..., 3, 3)``
    (:func:`heading_matrices`' x axis)."""
    return lean_towards(heading_matrices(root_rot)[..., :2, 0], deg)


_UPPER_IMU = [k for k, j in enumerate(IMU_JOINTS) if j in UPPER_BODY]


def lean_rows(est_rows: np.ndarray, lean: np.ndarray) -> None:
    """Turn the upper body of rows of :attr:`EstimateFrames.obs_rows` (``est_rows (B,
    OBS_ROW_DIM)``) by ``lean (B, 3, 3)`` about the pelvis, in place: the joints and velocity
    joints as :func:`leaned` turns them, and the rotations and angular velocities of the IMUs
    on the upper body (the wrists) as a constant turn changes them. The training task's lean
    augmentation (``TrackingEnvConfig.lean_range_deg``)."""
    b, r = len(est_rows), OBS_ROW
    pos, vel = _turned_upper(est_rows[:, r["est_pos"]].reshape(b, sk.N_JOINTS, 3),
                             est_rows[:, r["est_vel"]].reshape(b, _N_VEL, 3), lean)  # fmt: skip
    est_rows[:, r["est_pos"]] = pos.reshape(b, -1)
    est_rows[:, r["est_vel"]] = vel.reshape(b, -1)
    rot = est_rows[:, r["leaf_rot"]].reshape(b, _N_IMU, 3, 3)
    w = est_rows[:, r["leaf_angvel"]].reshape(b, _N_IMU, 3)
    rot[:, _UPPER_IMU] = lean[:, None] @ rot[:, _UPPER_IMU]
    w[:, _UPPER_IMU] = np.einsum("bij,bkj->bki", lean, w[:, _UPPER_IMU])
    est_rows[:, r["leaf_rot"]] = rot.reshape(b, -1)
    est_rows[:, r["leaf_angvel"]] = w.reshape(b, -1)


def lean_hinges(global_rot: np.ndarray, lean: np.ndarray) -> np.ndarray:
    """``(..., 69)`` the change of the hinge angles when the upper body of a pose with ``(...,
    24, 3, 3)`` global rotations turns by ``lean (..., 3, 3)`` about the pelvis: only the first
    spine joint's local rotation changes (its three angles' change, each wrapped to [-pi,
    pi])."""
    j = UPPER_BODY[0]
    parent = np.swapaxes(global_rot[..., sk.PARENTS[j], :, :], -1, -2)
    g = global_rot[..., j, :, :]
    e = matrix_to_euler(np.stack([parent @ g, parent @ lean @ g]), sk.HINGE_ORDERS[j])
    out = np.zeros((*np.shape(lean)[:-2], 3 * (sk.N_JOINTS - 1)))
    out[..., 3 * (j - 1) : 3 * j] = np.angle(np.exp(1j * (e[1] - e[0])))
    return out
