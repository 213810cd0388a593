"""Rotation utilities, vectorised over any leading shape (e.g. ``(T, J)``).

Conventions: quaternions are ``(w, x, y, z)`` (MuJoCo order), rotation matrices act on column
vectors (``v_world = R @ v_local``), axis-angle vectors are ``angle * unit_axis`` in radians and the
6D representation is the first two *columns* of the matrix, stacked ``(c0, c1)`` (Zhou et al. 2019).
Every function accepts arrays with arbitrary leading dimensions ``(...,)``.
"""

from __future__ import annotations

import numpy as np

_EPS = 1e-12


def _as_float(a: np.ndarray) -> np.ndarray:
    return np.asarray(a, dtype=np.float64)


# --------------------------------------------------------------------------- quaternions
def quat_normalize(q: np.ndarray) -> np.ndarray:
    """Unit quaternions with a non-negative w. ``(..., 4) -> (..., 4)``."""
    q = _as_float(q)
    q = q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), _EPS)
    return np.where(q[..., :1] < 0.0, -q, q)


def quat_mul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Hamilton product ``a * b`` (apply ``b`` first). ``(..., 4) x (..., 4) -> (..., 4)``."""
    a, b = _as_float(a), _as_float(b)
    aw, ax, ay, az = np.moveaxis(a, -1, 0)
    bw, bx, by, bz = np.moveaxis(b, -1, 0)
    return np.stack(
        [
            aw * bw - ax * bx - ay * by - az * bz,
            aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
        ],
        axis=-1,
    )


def quat_conj(q: np.ndarray) -> np.ndarray:
    """Conjugate (inverse of a unit quaternion). ``(..., 4) -> (..., 4)``."""
    q = _as_float(q)
    return q * np.array([1.0, -1.0, -1.0, -1.0])


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) to rotation matrix. ``(..., 4) -> (..., 3, 3)``."""
    q = _as_float(q)
    q = q / np.maximum(np.linalg.norm(q, axis=-1, keepdims=True), _EPS)
    w, x, y, z = np.moveaxis(q, -1, 0)
    xx, yy, zz = x * x, y * y, z * z
    xy, xz, yz = x * y, x * z, y * z
    wx, wy, wz = w * x, w * y, w * z
    m = np.stack(
        [
            1 - 2 * (yy + zz), 2 * (xy - wz), 2 * (xz + wy),
            2 * (xy + wz), 1 - 2 * (xx + zz), 2 * (yz - wx),
            2 * (xz - wy), 2 * (yz + wx), 1 - 2 * (xx + yy),
        ],
        axis=-1,
    )  # fmt: skip
    return m.reshape(*q.shape[:-1], 3, 3)


def matrix_to_quat(m: np.ndarray) -> np.ndarray:
    """Rotation matrix to unit quaternion with w >= 0 (Shepperd's method, branch-free).

    ``(..., 3, 3) -> (..., 4)``.
    """
    m = _as_float(m)
    m00, m11, m22 = m[..., 0, 0], m[..., 1, 1], m[..., 2, 2]
    # Four candidate solutions; pick the numerically best per element.
    t = np.stack([1 + m00 + m11 + m22, 1 + m00 - m11 - m22, 1 - m00 + m11 - m22,
                  1 - m00 - m11 + m22], axis=-1)  # fmt: skip
    best = np.argmax(t, axis=-1)
    s = np.sqrt(np.maximum(np.take_along_axis(t, best[..., None], -1)[..., 0], _EPS)) * 2.0
    q0 = np.stack([s / 4, (m[..., 2, 1] - m[..., 1, 2]) / s, (m[..., 0, 2] - m[..., 2, 0]) / s,
                   (m[..., 1, 0] - m[..., 0, 1]) / s], -1)  # fmt: skip
    q1 = np.stack([(m[..., 2, 1] - m[..., 1, 2]) / s, s / 4, (m[..., 0, 1] + m[..., 1, 0]) / s,
                   (m[..., 0, 2] + m[..., 2, 0]) / s], -1)  # fmt: skip
    q2 = np.stack([(m[..., 0, 2] - m[..., 2, 0]) / s, (m[..., 0, 1] + m[..., 1, 0]) / s, s / 4,
                   (m[..., 1, 2] + m[..., 2, 1]) / s], -1)  # fmt: skip
    q3 = np.stack([(m[..., 1, 0] - m[..., 0, 1]) / s, (m[..., 0, 2] + m[..., 2, 0]) / s,
                   (m[..., 1, 2] + m[..., 2, 1]) / s, s / 4], -1)  # fmt: skip
    q = np.choose(best[..., None], [q0, q1, q2, q3])
    return quat_normalize(q)


def quat_rotate(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Rotate vectors by unit quaternions. ``(..., 4), (..., 3) -> (..., 3)``."""
    return np.einsum("...ij,...j->...i", quat_to_matrix(q), _as_float(v))


# --------------------------------------------------------------------------- axis-angle
def axis_angle_to_matrix(aa: np.ndarray) -> np.ndarray:
    """Rodrigues' formula. ``(..., 3) -> (..., 3, 3)``; zero vectors give the identity."""
    aa = _as_float(aa)
    theta = np.linalg.norm(aa, axis=-1)[..., None, None]
    k = skew(aa)
    # sin(t)/t and (1-cos t)/t^2 with their Taylor limits for small angles.
    small = theta < 1e-6
    t_safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(t_safe) / t_safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(t_safe)) / t_safe**2)
    eye = np.broadcast_to(np.eye(3), k.shape)
    return eye + a * k + b * (k @ k)


def matrix_to_axis_angle(m: np.ndarray) -> np.ndarray:
    """Rotation matrix to axis-angle with angle in [0, pi]. ``(..., 3, 3) -> (..., 3)``."""
    return quat_to_axis_angle(matrix_to_quat(m))


def quat_to_axis_angle(q: np.ndarray) -> np.ndarray:
    """``(..., 4) -> (..., 3)``, angle in [0, pi]."""
    q = quat_normalize(q)
    sin_half = np.linalg.norm(q[..., 1:], axis=-1)
    angle = 2.0 * np.arctan2(sin_half, q[..., 0])
    scale = np.where(sin_half < 1e-8, 2.0, angle / np.maximum(sin_half, 1e-12))
    return q[..., 1:] * scale[..., None]


def axis_angle_to_quat(aa: np.ndarray) -> np.ndarray:
    """``(..., 3) -> (..., 4)``."""
    aa = _as_float(aa)
    angle = np.linalg.norm(aa, axis=-1, keepdims=True)
    half = 0.5 * angle
    scale = np.where(angle < 1e-8, 0.5 - angle**2 / 48.0, np.sin(half) / np.maximum(angle, 1e-12))
    return np.concatenate([np.cos(half), aa * scale], axis=-1)


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrix ``[v]x`` with ``[v]x @ u = v x u``. ``(..., 3) -> (..., 3, 3)``."""
    v = _as_float(v)
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([z, -w, y, w, z, -x, -y, x, z], axis=-1).reshape(*v.shape[:-1], 3, 3)


# --------------------------------------------------------------------------- 6D
def matrix_to_6d(m: np.ndarray) -> np.ndarray:
    """First two columns, ``(..., 3, 3) -> (..., 6)`` ordered ``(c0, c1)``."""
    m = _as_float(m)
    return np.concatenate([m[..., :, 0], m[..., :, 1]], axis=-1)


def sixd_to_matrix(d6: np.ndarray) -> np.ndarray:
    """Gram-Schmidt back to a rotation matrix. ``(..., 6) -> (..., 3, 3)``."""
    d6 = _as_float(d6)
    a, b = d6[..., :3], d6[..., 3:]
    c0 = a / np.maximum(np.linalg.norm(a, axis=-1, keepdims=True), _EPS)
    b = b - np.sum(c0 * b, axis=-1, keepdims=True) * c0
    c1 = b / np.maximum(np.linalg.norm(b, axis=-1, keepdims=True), _EPS)
    c2 = np.cross(c0, c1)
    return np.stack([c0, c1, c2], axis=-1)


# --------------------------------------------------------------------------- Euler (MuJoCo hinges)
def matrix_to_euler_xyz(m: np.ndarray) -> np.ndarray:
    """Intrinsic X-Y-Z Euler angles ``(a, b, c)`` with ``R = Rx(a) @ Ry(b) @ Rz(c)``
    (:func:`matrix_to_euler` with order ``"xyz"``). ``(..., 3, 3) -> (..., 3)``."""
    return matrix_to_euler(m, "xyz")


def euler_xyz_to_matrix(e: np.ndarray) -> np.ndarray:
    """Inverse of :func:`matrix_to_euler_xyz`. ``(..., 3) -> (..., 3, 3)``."""
    return euler_to_matrix(e, "xyz")


def _tait_bryan(order: str) -> tuple[int, int, int, float]:
    if sorted(order) != ["x", "y", "z"]:
        raise ValueError(f"Euler order {order!r}: use a permutation of 'xyz'")
    i, j, k = ("xyz".index(c) for c in order)
    return i, j, k, (1.0 if (j - i) % 3 == 1 else -1.0)


def matrix_to_euler(m: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Tait-Bryan angles ``(a, b, c)`` with ``R = R_o0(a) @ R_o1(b) @ R_o2(c)`` for
    ``order = o0 o1 o2`` (a permutation of ``"xyz"``): the composition of three MuJoCo hinges
    stacked in one body in that order. ``b`` lies in [-pi/2, pi/2] (the gimbal lock is at
    |b| = pi/2, where ``c`` is set to 0). ``(..., 3, 3) -> (..., 3)``.
    """
    m = _as_float(m)
    i, j, k, s = _tait_bryan(order)
    sb = np.clip(s * m[..., i, k], -1.0, 1.0)
    b = np.arcsin(sb)
    lock = np.sqrt(np.maximum(1.0 - sb**2, 0.0)) < 1e-9
    a = np.where(lock, np.arctan2(s * m[..., k, j], m[..., j, j]),
                 np.arctan2(-s * m[..., j, k], m[..., k, k]))  # fmt: skip
    c = np.where(lock, 0.0, np.arctan2(-s * m[..., i, j], m[..., i, i]))
    return np.stack([a, b, c], axis=-1)


def euler_to_matrix(e: np.ndarray, order: str) -> np.ndarray:
    """Inverse of :func:`matrix_to_euler`. ``(..., 3) -> (..., 3, 3)``."""
    e = _as_float(e)
    _tait_bryan(order)
    rots = {"x": rot_x, "y": rot_y, "z": rot_z}
    return rots[order[0]](e[..., 0]) @ rots[order[1]](e[..., 1]) @ rots[order[2]](e[..., 2])


def rot_x(a: np.ndarray) -> np.ndarray:
    """Rotation about x by ``a`` rad. ``(...) -> (..., 3, 3)``."""
    a = _as_float(a)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([o, z, z, z, c, -s, z, s, c], -1).reshape(*a.shape, 3, 3)


def rot_y(a: np.ndarray) -> np.ndarray:
    """Rotation about y by ``a`` rad. ``(...) -> (..., 3, 3)``."""
    a = _as_float(a)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([c, z, s, z, o, z, -s, z, c], -1).reshape(*a.shape, 3, 3)


def rot_z(a: np.ndarray) -> np.ndarray:
    """Rotation about z by ``a`` rad. ``(...) -> (..., 3, 3)``."""
    a = _as_float(a)
    c, s, o, z = np.cos(a), np.sin(a), np.ones_like(a), np.zeros_like(a)
    return np.stack([c, -s, z, s, c, z, z, z, o], -1).reshape(*a.shape, 3, 3)


# --------------------------------------------------------------------------- heading, geodesics
def heading_angle(m: np.ndarray, forward_local: np.ndarray | None = None) -> np.ndarray:
    """Yaw (about world z) of a body's forward axis, rad. ``(..., 3, 3) -> (...)``.

    Args:
        m: Global rotations of the body (z-up world).
        forward_local: The body's forward axis in its own frame, ``(3,)``. Default: +z, the
            facing direction of the SMPL-canonical rest pose used by this project's body model.
    """
    fwd = np.array([0.0, 0.0, 1.0]) if forward_local is None else _as_float(forward_local)
    f = np.einsum("...ij,j->...i", _as_float(m), fwd)
    return np.arctan2(f[..., 1], f[..., 0])


def heading_rotation(m: np.ndarray, forward_local: np.ndarray | None = None) -> np.ndarray:
    """Rotation about world z that turns world +x into the body's horizontal facing direction.

    The *heading frame* of GRIP/PHC: ``heading_rotation(R).T @ v`` expresses a world vector in a
    yaw-only frame whose x axis points where the body faces. ``(..., 3, 3) -> (..., 3, 3)``.
    """
    return rot_z(heading_angle(m, forward_local))


def geodesic_angle(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Angle of ``a.T @ b`` in rad, in [0, pi]. ``(..., 3, 3) x (..., 3, 3) -> (...)``."""
    rel = np.swapaxes(_as_float(a), -1, -2) @ _as_float(b)
    tr = np.trace(rel, axis1=-2, axis2=-1)
    return np.arccos(np.clip((tr - 1.0) / 2.0, -1.0, 1.0))


def rotation_between(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Minimal rotation (swing) taking direction ``u`` to ``v``. ``(..., 3) -> (..., 3, 3)``.

    For opposite vectors a rotation by pi about an axis perpendicular to ``u`` is returned.
    """
    u = _as_float(u)
    v = _as_float(v)
    u = u / np.maximum(np.linalg.norm(u, axis=-1, keepdims=True), _EPS)
    v = v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), _EPS)
    axis = np.cross(u, v)
    s = np.linalg.norm(axis, axis=-1)
    c = np.sum(u * v, axis=-1)
    # Fallback axis for anti-parallel vectors: any perpendicular of u.
    perp = np.cross(u, np.array([1.0, 0.0, 0.0]))
    perp = np.where(np.linalg.norm(perp, axis=-1, keepdims=True) < 1e-6,
                    np.cross(u, np.array([0.0, 1.0, 0.0])), perp)  # fmt: skip
    axis = np.where(s[..., None] < 1e-9, perp, axis)
    axis = axis / np.maximum(np.linalg.norm(axis, axis=-1, keepdims=True), _EPS)
    angle = np.arctan2(s, c)
    return axis_angle_to_matrix(axis * angle[..., None])


def orthonormalize(m: np.ndarray) -> np.ndarray:
    """Nearest rotation matrix (SVD polar factor). ``(..., 3, 3) -> (..., 3, 3)``."""
    u, _, vt = np.linalg.svd(_as_float(m))
    d = np.sign(np.linalg.det(u @ vt))
    u = u.copy()
    u[..., :, 2] *= d[..., None]
    return u @ vt


# --------------------------------------------------------------------------- interpolation
def quat_slerp(q0: np.ndarray, q1: np.ndarray, t: np.ndarray | float) -> np.ndarray:
    """Spherical linear interpolation along the shorter arc.

    ``(..., 4) x (..., 4) x (...) -> (..., 4)``.
    """
    q0 = quat_normalize(q0)
    q1 = quat_normalize(q1)
    t = np.asarray(t, dtype=np.float64)[..., None]
    dot = np.sum(q0 * q1, axis=-1, keepdims=True)
    q1 = np.where(dot < 0.0, -q1, q1)
    dot = np.abs(dot)
    theta = np.arccos(np.clip(dot, -1.0, 1.0))
    sin_t = np.sin(theta)
    lin = sin_t < 1e-6
    s_safe = np.where(lin, 1.0, sin_t)
    w0 = np.where(lin, 1.0 - t, np.sin((1.0 - t) * theta) / s_safe)
    w1 = np.where(lin, t, np.sin(t * theta) / s_safe)
    return quat_normalize(w0 * q0 + w1 * q1)


def resample_quats(times_s: np.ndarray, quats: np.ndarray, new_times_s: np.ndarray) -> np.ndarray:
    """Slerp-resample a quaternion track onto new sample times.

    Args:
        times_s: ``(T,)`` strictly increasing sample times, s.
        quats: ``(T, ..., 4)`` quaternions (w, x, y, z).
        new_times_s: ``(N,)`` times inside ``[times_s[0], times_s[-1]]`` (clipped otherwise).

    Returns:
        ``(N, ..., 4)`` resampled unit quaternions.
    """
    times_s = _as_float(times_s)
    new_t = np.clip(_as_float(new_times_s), times_s[0], times_s[-1])
    idx = np.clip(np.searchsorted(times_s, new_t, side="right") - 1, 0, len(times_s) - 2)
    span = times_s[idx + 1] - times_s[idx]
    frac = (new_t - times_s[idx]) / np.where(span > 0, span, 1.0)
    frac = frac.reshape(-1, *([1] * (quats.ndim - 2)))
    frac = np.broadcast_to(frac, quats[idx].shape[:-1])
    return quat_slerp(quats[idx], quats[idx + 1], frac)


def resample_linear(times_s: np.ndarray, values: np.ndarray, new_times_s: np.ndarray) -> np.ndarray:
    """Linear resampling of ``(T, ...)`` values onto ``(N,)`` new times -> ``(N, ...)``."""
    times_s = _as_float(times_s)
    new_t = np.clip(_as_float(new_times_s), times_s[0], times_s[-1])
    idx = np.clip(np.searchsorted(times_s, new_t, side="right") - 1, 0, len(times_s) - 2)
    span = times_s[idx + 1] - times_s[idx]
    frac = (new_t - times_s[idx]) / np.where(span > 0, span, 1.0)
    frac = frac.reshape(-1, *([1] * (values.ndim - 1)))
    v = _as_float(values)
    return v[idx] * (1.0 - frac) + v[idx + 1] * frac


def angular_velocity(rot: np.ndarray, fps: float, local: bool = False) -> np.ndarray:
    """Angular velocity from a rotation track by central differences, rad/s.

    Args:
        rot: ``(T, ..., 3, 3)`` rotations sampled at ``fps``.
        fps: Sample rate, Hz.
        local: If True, the result is in the body frame, else in the world frame.

    Returns:
        ``(T, ..., 3)``; one-sided differences at both ends.
    """
    rot = _as_float(rot)
    if rot.shape[0] < 2:
        return np.zeros(rot.shape[:-1])
    nxt = np.concatenate([rot[1:], rot[-1:]], axis=0)
    prv = np.concatenate([rot[:1], rot[:-1]], axis=0)
    steps = np.full(rot.shape[0], 2.0)
    steps[0] = steps[-1] = 1.0
    rt = np.swapaxes(prv, -1, -2)
    rel = nxt @ rt if not local else rt @ nxt  # world: R1 R0^T ; local: R0^T R1
    w = matrix_to_axis_angle(rel)
    return w * (fps / steps.reshape(-1, *([1] * (w.ndim - 1))))


def angular_velocity_at(rot: np.ndarray, i: int, fps: float) -> np.ndarray:
    """``angular_velocity(rot, fps)[i]`` (world frame) computed for frame ``i`` alone, with the
    same values: the one-frame update of a stream.

    Args:
        rot: ``(T, ..., 3, 3)`` rotations (only frames ``i - 1 .. i + 1`` are read).
        i: Frame, ``0 <= i < T``.
        fps: Sample rate, Hz.
    """
    n = rot.shape[0]
    if n < 2:
        return np.zeros(rot.shape[1:-1])
    lo, hi = max(i - 1, 0), min(i + 1, n - 1)
    rel = _as_float(rot[hi]) @ np.swapaxes(_as_float(rot[lo]), -1, -2)
    return matrix_to_axis_angle(rel) * (fps / float(hi - lo))
