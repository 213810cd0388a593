"""Reference motions for the tracking environment: a small numpy protocol (no torch, no MuJoCo).

It lives in ``grip.core`` because both sides use it: ``envs`` reads it, and
:mod:`grip.kinematics.reference` (torch) writes it; neither may import the other.

The environment never runs KinematicsNet. For every recording, :mod:`grip.kinematics.reference`
precomputes the KinematicsNet estimate once (offline, batched) and stores it next to the ground
truth and the sensor features in a :class:`ReferenceSet` file; the environment only indexes
arrays. What the env reads from a clip:

* the **estimate** (observations, and the reference pose of relative actions): root-relative
  joint positions, global joint rotations, leaf/pelvis velocities, the integrated root
  trajectory, hinge angles and angular velocities derived from them;
* the **ground truth** (imitation reward, reference state initialisation, early termination):
  the pose as ``qpos``, and joint positions, rotations, linear and angular velocities from FK;
* the **sensor features** (the same inputs KinematicsNet sees), for the sensor observation;
* the subject's body (height, mass) and the recording's scene objects (terrain).

Only primary arrays are stored (float32, compressed); derived arrays are computed on load in
numpy, so a file of a few seconds of motion stays small enough to bundle.

Array conventions: world frame z up, metres, radians, w-first quaternions; hinge angles in SMPL
order (joint 1..23 x its hinges in composition order), i.e. :func:`grip.core.mjcf.hinge_names`
order, *not*
MuJoCo's ``qpos`` order (the env maps them through its index arrays).
"""

from __future__ import annotations

import json
import os
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar, Protocol

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyParams, build_body
from grip.core.fk import forward_kinematics, integrate_root
from grip.core.limits import InputLimits, LimitExceeded, active_limits, load_checked_npz
from grip.core.rotations import (
    angular_velocity,
    angular_velocity_at,
    euler_to_matrix,
    matrix_to_6d,
    matrix_to_euler,
    matrix_to_quat,
    quat_to_matrix,
    sixd_to_matrix,
)

FORMAT_VERSION = 2  # 2: per-joint hinge orders (skeleton.HINGE_ORDERS)

N_HINGES = 3 * (sk.N_JOINTS - 1)

# name -> trailing shape of the stored (primary) arrays; T is the first axis of each.
PRIMARY: dict[str, tuple[int, ...]] = {
    "gt_qpos": (7 + N_HINGES,),
    "est_pos": (sk.N_JOINTS, 3),
    "est_rot6d": (sk.N_JOINTS, 6),
    "est_vel": (len(sk.VELOCITY_JOINTS), 3),
    "sensor": (-1,),
}


TRAINING_DTYPE = np.float32
"""What the clips of a training set keep their arrays in, all but ``gt_qpos``
(:meth:`ReferenceClip.compact`). A training set holds millions of frames: in float64 a
speed-scaled set of 2,255 clips took 11.4 GB resident and let no second run share the machine;
compact, 6.0 GB (docs/performance.md § Memory of a training set)."""


class ReferenceError(ValueError):
    """A reference file or clip is malformed (the message names the file and the key)."""


_ORDER_GROUPS: tuple[tuple[str, np.ndarray], ...] = tuple(
    (o, np.array([j for j in range(1, sk.N_JOINTS) if sk.HINGE_ORDERS[j] == o]))
    for o in sorted(set(sk.HINGE_ORDERS[1:]))
)  # (order, joints 1..23 composed in that order)


def hinges_from_local(local: np.ndarray) -> np.ndarray:
    """``(..., 23, 3, 3)`` local rotations of joints 1..23 -> ``(..., 69)`` hinge angles in
    :func:`grip.core.mjcf.hinge_names` order (each joint's Euler angles in its
    :data:`grip.core.skeleton.HINGE_ORDERS` order)."""
    local = np.asarray(local, dtype=np.float64)
    out = np.empty((*local.shape[:-3], sk.N_JOINTS - 1, 3))
    for order, joints in _ORDER_GROUPS:
        out[..., joints - 1, :] = matrix_to_euler(local[..., joints - 1, :, :], order)
    return out.reshape(*local.shape[:-3], N_HINGES)


def local_from_hinges(hinges: np.ndarray) -> np.ndarray:
    """Inverse of :func:`hinges_from_local`: ``(..., 69)`` -> ``(..., 23, 3, 3)``."""
    e = np.asarray(hinges, dtype=np.float64)
    e = e.reshape(*e.shape[:-1], sk.N_JOINTS - 1, 3)
    out = np.empty((*e.shape[:-1], 3, 3))
    for order, joints in _ORDER_GROUPS:
        out[..., joints - 1, :, :] = euler_to_matrix(e[..., joints - 1, :], order)
    return out


def pose_vector(local_rot: np.ndarray, root_pos: np.ndarray) -> np.ndarray:
    """``(..., 24, 3, 3)`` local rotations (row 0 = root world rotation) and ``(..., 3)`` root
    position -> ``(..., 76)`` ``[root_pos, root_quat_wxyz, 69 hinge angles (SMPL order)]``.
    Hinge angles are the Euler angles of the MuJoCo humanoid's hinges
    (:func:`hinges_from_local`)."""
    local_rot = np.asarray(local_rot, dtype=np.float64)
    lead = local_rot.shape[:-3]
    out = np.empty((*lead, 7 + N_HINGES))
    out[..., :3] = root_pos
    out[..., 3:7] = matrix_to_quat(local_rot[..., 0, :, :])
    out[..., 7:] = hinges_from_local(local_rot[..., 1:, :, :])
    return out


def local_rot_from_qpos(qpos: np.ndarray) -> np.ndarray:
    """Inverse of :func:`pose_vector`: ``(T, 76)`` -> ``(T, 24, 3, 3)`` local rotations."""
    t = qpos.shape[0]
    local = np.empty((t, sk.N_JOINTS, 3, 3))
    local[:, 0] = quat_to_matrix(qpos[:, 3:7])
    local[:, 1:] = local_from_hinges(qpos[:, 7:])
    return local


def hinge_angles(global_rot: np.ndarray) -> np.ndarray:
    """``(T, 24, 3, 3)`` global rotations -> ``(T, 69)`` hinge angles (SMPL order), unwrapped
    over time so that finite differences stay small."""
    parent = global_rot[:, list(sk.PARENTS[1:])]
    local = np.swapaxes(parent, -1, -2) @ global_rot[:, 1:]
    e = hinges_from_local(local)
    return np.unwrap(e, axis=0)


@dataclass(eq=False)
class ReferenceClip:
    """One recording prepared for the environment (see the module docstring).

    Attributes (T frames at ``fps``):
        name, category: From the recording.
        fps: Frame rate, Hz (the env's control rate must match).
        body: Subject parameters; the env builds its humanoid from them.
        gt_qpos: ``(T, 76)`` ground-truth ``[root_pos_world, root_quat_wxyz, 69 hinges]``.
        est_pos: ``(T, 24, 3)`` KinematicsNet joint positions minus the root, world axes, m.
        est_rot6d: ``(T, 24, 6)`` KinematicsNet global joint rotations, 6D.
        est_vel: ``(T, 6, 3)`` KinematicsNet world velocities of the velocity joints
            (:data:`grip.core.skeleton.VELOCITY_JOINTS`), m/s.
        sensor: ``(T, F)`` the KinematicsNet input features (unnormalised).
        objects: Scene meshes ``{name: (vertices (V, 3), faces (F, 3))}`` or ``None``.

    Derived on construction (float64): ``gt_qvel (T, 75)`` (root linear velocity in the world,
    root angular velocity in the root frame, hinge rates: MuJoCo's free-joint convention),
    ``gt_pos``, ``gt_rot``, ``gt_vel``, ``gt_angvel`` (world, per joint),
    ``est_rot (T, 24, 3, 3)``, ``est_angvel (T, 24, 3)`` (world), ``est_hinge (T, 69)``,
    ``est_hinge_vel (T, 69)``, ``est_root_pos (T, 3)`` (the root integrated from the estimated
    pelvis velocity, starting at the ground truth).
    """

    name: str
    category: str
    fps: float
    body: BodyParams
    gt_qpos: np.ndarray
    est_pos: np.ndarray
    est_rot6d: np.ndarray
    est_vel: np.ndarray
    sensor: np.ndarray
    objects: dict[str, tuple[np.ndarray, np.ndarray]] | None = None

    def __post_init__(self) -> None:
        where = f"clip {self.name!r}"
        arrays = {k: np.asarray(getattr(self, k), dtype=np.float64) for k in PRIMARY}
        t = arrays["gt_qpos"].shape[0] if arrays["gt_qpos"].ndim else 0
        if t < 2:
            raise ReferenceError(f"{where}: needs at least 2 frames, got {t}")
        for k, shape in PRIMARY.items():
            a = arrays[k]
            if (
                a.ndim != 1 + len(shape)
                or a.shape[0] != t
                or any(s not in (-1, d) for s, d in zip(shape, a.shape[1:], strict=True))
            ):
                dims = ", ".join("F" if s < 0 else str(s) for s in shape)
                raise ReferenceError(f"{where}: {k} has shape {a.shape}, expected (T={t}, {dims})")
            if not np.isfinite(a).all():
                bad = int(np.argwhere(~np.isfinite(a.reshape(t, -1)).all(axis=1))[0, 0])
                raise ReferenceError(f"{where}: {k} has non-finite values (first at frame {bad})")
            setattr(self, k, a)
        if not self.fps > 0:
            raise ReferenceError(f"{where}: fps must be positive, got {self.fps}")
        self._derive()

    @property
    def n_frames(self) -> int:
        return int(self.gt_qpos.shape[0])

    def compact(self) -> None:
        """Keep every array but ``gt_qpos`` in float32 from now on, derived ones included:
        about half the memory (:data:`TRAINING_DTYPE`). For the clips of a training set; a
        clip a reconstruction plays stays float64, so that the offline and the streaming
        paths agree to the last digit."""
        for k, v in vars(self).items():
            if k != "gt_qpos" and isinstance(v, np.ndarray) and v.dtype == np.float64:
                setattr(self, k, v.astype(TRAINING_DTYPE))

    def oracle(self) -> ReferenceClip:
        """This clip with its ground truth as the estimate (joints minus the root, global
        rotations, velocities of the velocity joints), the same sensors and scene: what a
        privileged tracker (``follow = "truth"``) follows. Equals
        :func:`grip.kinematics.reference.oracle_reference_clip` of the clip's recording to
        float rounding."""
        return ReferenceClip(
            name=self.name, category=self.category, fps=self.fps, body=self.body,
            gt_qpos=self.gt_qpos.copy(), est_pos=self.gt_pos - self.gt_pos[:, :1],
            est_rot6d=matrix_to_6d(self.gt_rot),
            est_vel=self.gt_vel[:, list(sk.VELOCITY_JOINTS)], sensor=self.sensor,
            objects=self.objects,
        )  # fmt: skip

    def _derive(self) -> None:
        for k, v in ground_truth_arrays(self.gt_qpos, self.body, self.fps).items():
            setattr(self, k, v)
        est = derive_estimate(self.est_rot6d, self.est_vel, self.gt_qpos[0, :3], self.fps)
        for k, v in est.items():
            setattr(self, k, v)


def ground_truth_arrays(gt_qpos: np.ndarray, body: BodyParams, fps: float) -> dict[str, np.ndarray]:
    """The ground truth of a pose track, derived (float64; ``gt_qpos``'s quaternions are
    normalised in place).

    Args:
        gt_qpos: ``(T >= 2, 76)`` pose vectors (:func:`pose_vector`).
        body: The subject.
        fps: Frame rate, Hz.

    Returns:
        ``gt_qvel (T, 75)`` (root linear velocity in the world, root angular velocity in the root
        frame, hinge rates: MuJoCo's free-joint convention), ``gt_pos (T, 24, 3)``, ``gt_rot (T,
        24, 3, 3)``, ``gt_vel (T, 24, 3)``, ``gt_angvel (T, 24, 3)`` (world, per joint).
    """
    fps = float(fps)
    q = gt_qpos
    q[:, 3:7] /= np.linalg.norm(q[:, 3:7], axis=1, keepdims=True)
    local = local_rot_from_qpos(q)
    offsets = build_body(body).offsets
    gt_rot, gt_pos = forward_kinematics(local, q[:, :3], offsets)
    qvel = np.empty((q.shape[0], 6 + N_HINGES))
    qvel[:, :3] = np.gradient(q[:, :3], axis=0) * fps
    qvel[:, 3:6] = angular_velocity(local[:, 0], fps, local=True)
    qvel[:, 6:] = np.gradient(np.unwrap(q[:, 7:], axis=0), axis=0) * fps
    return {
        "gt_qvel": qvel,
        "gt_pos": gt_pos,
        "gt_rot": gt_rot,
        "gt_vel": np.gradient(gt_pos, axis=0) * fps,
        "gt_angvel": angular_velocity(gt_rot, fps),
    }


def derive_estimate(est_rot6d: np.ndarray, est_vel: np.ndarray, root0: np.ndarray,
                    fps: float) -> dict[str, np.ndarray]:  # fmt: skip
    """The derived arrays of a kinematic estimate (float64): ``est_rot (T, 24, 3, 3)``,
    ``est_angvel (T, 24, 3)`` (world), ``est_hinge (T, 69)`` (unwrapped), ``est_hinge_vel (T,
    69)`` and ``est_root_pos (T, 3)``: the root integrated from the estimated pelvis velocity
    ``est_vel[:, -1]``, starting at ``root0 (3,)`` (the calibration frame's root), m."""
    fps = float(fps)
    est_rot = sixd_to_matrix(est_rot6d)
    est_hinge = hinge_angles(est_rot)
    return {
        "est_rot": est_rot,
        "est_angvel": angular_velocity(est_rot, fps),
        "est_hinge": est_hinge,
        "est_hinge_vel": np.gradient(est_hinge, axis=0) * fps,
        "est_root_pos": integrate_root(root0, est_vel[:, -1], fps),
    }


_EST_PRIMARY = {k: PRIMARY[k] for k in ("est_pos", "est_rot6d", "est_vel", "sensor")}


@dataclass(eq=False)
class Estimate:
    """A whole recording's kinematic estimate with the sensor features it came from: what the
    controller follows (no ground truth; :class:`ReferenceClip` adds it for training).

    Attributes (T frames at ``fps``): ``name``, ``fps``, ``est_pos``, ``est_rot6d``, ``est_vel``
    and ``sensor`` as in :class:`ReferenceClip`; ``root0 (3,)`` the root position the
    integrated root starts at (the calibration frame's), m. Derived on construction:
    :func:`derive_estimate`'s arrays.
    """

    name: str
    fps: float
    est_pos: np.ndarray
    est_rot6d: np.ndarray
    est_vel: np.ndarray
    sensor: np.ndarray
    root0: np.ndarray

    def __post_init__(self) -> None:
        t = np.shape(self.est_pos)[0] if np.ndim(self.est_pos) else 0
        for k, shape in _EST_PRIMARY.items():
            a = np.asarray(getattr(self, k), dtype=np.float64)
            if a.ndim != 1 + len(shape) or a.shape[0] != t or t < 2 or any(
                    s not in (-1, d) for s, d in zip(shape, a.shape[1:], strict=True)):
                raise ReferenceError(f"estimate {self.name!r}: {k} has shape {a.shape}, "
                                     f"expected (T >= 2, {shape})")  # fmt: skip
            setattr(self, k, a)
        self.root0 = np.asarray(self.root0, dtype=np.float64).reshape(3)
        for k, v in derive_estimate(self.est_rot6d, self.est_vel, self.root0, self.fps).items():
            setattr(self, k, v)

    @property
    def n_frames(self) -> int:
        return int(self.est_pos.shape[0])


def _unwrap_step(dd: np.ndarray) -> np.ndarray:
    """The phase correction :func:`numpy.unwrap` adds for a step ``dd`` (period 2 pi), written
    out so that a stream can unwrap one frame at a time with the same values."""
    ddmod = np.mod(dd + np.pi, 2 * np.pi) - np.pi
    np.copyto(ddmod, np.pi, where=(ddmod == -np.pi) & (dd > 0))
    corr = ddmod - dd
    np.copyto(corr, 0, where=np.abs(dd) < np.pi)
    return corr


class LiveEstimate:
    """A kinematic estimate that grows one frame at a time (streaming reconstruction).

    It has the attributes of :class:`Estimate`, as arrays of :attr:`capacity` rows (at least
    :attr:`n_frames`; they grow by doubling). The values of frames ``0 .. n_frames - 1`` are
    those an :class:`Estimate` of the frames so far would have: the derivatives of the newest
    frame are one-sided (as at a clip's end) and turn central when the next frame arrives, the
    hinge angles are unwrapped as :func:`numpy.unwrap` does.

    Args:
        name: Recording name, for messages.
        fps: Frame rate, Hz.
        root0: ``(3,)`` the calibration frame's root position, where the integrated root
            starts, m.
        sensor_dim: Width of the sensor features.
        capacity: Rows allocated at first.
    """

    _EST: ClassVar[dict[str, tuple[int, ...]]] = {
        "est_pos": (sk.N_JOINTS, 3), "est_rot6d": (sk.N_JOINTS, 6),
        "est_rot": (sk.N_JOINTS, 3, 3), "est_vel": (len(sk.VELOCITY_JOINTS), 3),
        "est_angvel": (sk.N_JOINTS, 3), "est_hinge": (N_HINGES,),
        "est_hinge_vel": (N_HINGES,), "est_root_pos": (3,),
    }  # fmt: skip

    def __init__(self, name: str, fps: float, root0: np.ndarray, sensor_dim: int,
                 capacity: int = 1024) -> None:  # fmt: skip
        self.name, self.fps = str(name), float(fps)
        self.root0 = np.asarray(root0, dtype=np.float64).reshape(3)
        self._sensor_dim = int(sensor_dim)
        self._n = 0
        self._raw_prev = np.zeros(N_HINGES)  # hinge angles of the previous frame, wrapped
        self._corr = np.zeros(N_HINGES)  # accumulated unwrap correction
        self._disp = np.zeros(3)  # integrated root displacement up to the newest frame
        self._alloc(max(int(capacity), 2))

    def _alloc(self, rows: int) -> None:
        old = {k: getattr(self, k) for k in (*self._EST, "sensor")} if self._n else {}
        for k, shape in self._EST.items():
            setattr(self, k, np.zeros((rows, *shape)))
        self.sensor = np.zeros((rows, self._sensor_dim))
        for k, a in old.items():
            getattr(self, k)[: self._n] = a[: self._n]

    @property
    def n_frames(self) -> int:
        """Frames appended so far."""
        return self._n

    @property
    def capacity(self) -> int:
        """Rows of the arrays (they are reallocated, doubled, when a frame does not fit)."""
        return int(self.sensor.shape[0])

    def append(self, joint_pos: np.ndarray, global_rot: np.ndarray, velocity: np.ndarray,
               features: np.ndarray) -> int:  # fmt: skip
        """Add the estimate of the next frame; returns its index.

        Args:
            joint_pos: ``(24, 3)`` estimated joints minus the root, world axes, m.
            global_rot: ``(24, 3, 3)`` estimated global rotations.
            velocity: ``(6, 3)`` estimated velocities of the velocity joints, m/s.
            features: ``(F,)`` the KinematicsNet inputs of the frame.
        """
        i = self._n
        vals = {"est_pos": joint_pos, "est_rot": global_rot, "est_vel": velocity}
        for k, v in vals.items():
            v = np.asarray(v, dtype=np.float64)
            if v.shape != self._EST[k] or not np.isfinite(v).all():
                raise ReferenceError(f"clip {self.name!r} frame {i}: {k} must be finite "
                                     f"{self._EST[k]}, got {v.shape}")  # fmt: skip
        f = np.asarray(features, dtype=np.float64).reshape(-1)
        if f.shape != (self._sensor_dim,):
            raise ReferenceError(f"clip {self.name!r} frame {i}: features must have "
                                 f"{self._sensor_dim} values, got {f.shape}")  # fmt: skip
        if i == self.capacity:
            self._alloc(2 * self.capacity)
        fps = self.fps
        self.est_pos[i] = joint_pos
        self.est_rot6d[i] = matrix_to_6d(np.asarray(global_rot, dtype=np.float64))
        self.est_rot[i] = sixd_to_matrix(self.est_rot6d[i])
        self.est_vel[i] = velocity
        self.sensor[i] = f
        # hinge angles, unwrapped over time (hinge_angles / numpy.unwrap, one frame)
        rot = self.est_rot[i]
        raw = hinges_from_local(np.swapaxes(rot[list(sk.PARENTS[1:])], -1, -2) @ rot[1:])
        if i > 0:
            self._corr = self._corr + _unwrap_step(raw - self._raw_prev)
            self.est_hinge[i] = raw + self._corr
        else:
            self.est_hinge[i] = raw
        self._raw_prev = raw
        # root: forward Euler on the estimated pelvis velocity (integrate_root)
        if i > 0:
            self._disp = self._disp + self.est_vel[i - 1, -1] / fps
            self.est_root_pos[i] = self._disp + self.root0
        else:
            self.est_root_pos[i] = self.root0
        self._n = i + 1
        # derivatives (numpy.gradient, angular_velocity): frame i one-sided, i - 1 central
        h, r = self.est_hinge, self.est_rot
        if i > 0:
            self.est_hinge_vel[i] = (h[i] - h[i - 1]) / 1.0 * fps
            self.est_angvel[i] = angular_velocity_at(r[: i + 1], i, fps)
            self.est_angvel[i - 1] = angular_velocity_at(r[: i + 1], i - 1, fps)
            if i > 1:
                self.est_hinge_vel[i - 1] = (h[i] - h[i - 2]) / 2.0 * fps
            else:
                self.est_hinge_vel[0] = self.est_hinge_vel[1]
        return i

    def append_held(self, n: int) -> int:
        """Add ``n`` frames that hold the newest frame's pose standing still (zero velocity,
        its features): what ``n`` calls of :meth:`append` with that pose would give, in one
        step (a stream's long dropout). Returns the index of the last frame.

        Raises:
            ReferenceError: No frame to hold.
        """
        if n <= 0:
            return self._n - 1
        if self._n == 0:
            raise ReferenceError(f"clip {self.name!r}: no frame to hold")
        last, i0 = self._n - 1, self._n
        end = i0 + n
        rows = self.capacity
        while rows < end:
            rows *= 2
        if rows != self.capacity:
            self._alloc(rows)
        for k in ("est_pos", "est_rot6d", "est_rot", "est_hinge", "sensor"):
            arr = getattr(self, k)
            arr[i0:end] = arr[last]
        self.est_vel[i0:end] = 0.0
        self.est_hinge_vel[i0:end] = 0.0
        self.est_angvel[i0:end] = 0.0
        # root: the newest frame's velocity moves it once, then it stands (forward Euler)
        self._disp = self._disp + self.est_vel[last, -1] / self.fps
        self.est_root_pos[i0:end] = self._disp + self.root0
        self._n = end
        # the held frame's derivatives turn central (its successor is the same pose)
        h, fps = self.est_hinge, self.fps
        self.est_angvel[last] = angular_velocity_at(self.est_rot[: i0 + 1], last, fps)
        if last > 0:
            self.est_hinge_vel[last] = (h[i0] - h[last - 1]) / 2.0 * fps
        else:
            self.est_hinge_vel[0] = self.est_hinge_vel[1]
        return end - 1


class ReferenceSource(Protocol):
    """What the environment needs from a collection of reference clips."""

    def __len__(self) -> int: ...

    def clip(self, i: int) -> ReferenceClip: ...


class ReferenceSet:
    """A list of :class:`ReferenceClip` with the feature settings they were made with.

    Args:
        clips: The clips (at least one).
        sensor_sites: IMU sites of the ``sensor`` features, in channel order.
        insoles: Whether the features end with the 10 insole values.
        source: Where the clips came from (a path or a description), for messages.
    """

    def __init__(self, clips: list[ReferenceClip], sensor_sites: tuple[str, ...],
                 insoles: bool, source: str = "<memory>") -> None:  # fmt: skip
        if not clips:
            raise ReferenceError(f"{source}: no reference clips")
        widths = {c.sensor.shape[1] for c in clips}
        if len(widths) != 1:
            raise ReferenceError(f"{source}: clips have different sensor widths {sorted(widths)}")
        expected = 15 * len(sensor_sites) + (10 if insoles else 0)
        if widths != {expected}:
            raise ReferenceError(f"{source}: sensor width {widths.pop()} does not match "
                                 f"{len(sensor_sites)} sites (+insoles={insoles})")  # fmt: skip
        self.clips = list(clips)
        self.sensor_sites = tuple(sensor_sites)
        self.insoles = bool(insoles)
        self.source = source

    def __len__(self) -> int:
        return len(self.clips)

    def clip(self, i: int) -> ReferenceClip:
        return self.clips[i]

    @property
    def sensor_dim(self) -> int:
        return int(self.clips[0].sensor.shape[1])

    @property
    def total_frames(self) -> int:
        return sum(c.n_frames for c in self.clips)

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> None:
        """Write a compressed ``.npz`` (float32 arrays, JSON metadata; no pickles), atomically."""
        from grip.core.atomic import atomic_write

        meta = {
            "format": "grip-reference",
            "version": FORMAT_VERSION,
            "sensor_sites": list(self.sensor_sites),
            "insoles": self.insoles,
            "clips": [],
        }
        arrays: dict[str, np.ndarray] = {}
        for i, c in enumerate(self.clips):
            meta["clips"].append({
                "name": c.name, "category": c.category, "fps": c.fps,
                "body": {"height_m": c.body.height_m, "mass_kg": c.body.mass_kg},
                "objects": sorted(c.objects) if c.objects else [],
            })  # fmt: skip
            for k in PRIMARY:
                arrays[f"{i}/{k}"] = getattr(c, k).astype(np.float32)
            arrays[f"{i}/gt_qpos"] = c.gt_qpos  # float64: root positions of long clips
            for name, (v, f) in (c.objects or {}).items():
                arrays[f"{i}/objects/{name}/vertices"] = np.asarray(v, dtype=np.float64)
                arrays[f"{i}/objects/{name}/faces"] = np.asarray(f, dtype=np.int64)
        arrays["__meta__"] = np.array(json.dumps(meta))

        def write(f) -> None:
            np.savez_compressed(f, **arrays)

        atomic_write(path, write)

    @classmethod
    def load(cls, path: str | os.PathLike, *, limits: InputLimits | None = None,
             compact: bool = False) -> ReferenceSet:  # fmt: skip
        """Read a file written by :meth:`save` (with ``compact``, each clip
        :meth:`ReferenceClip.compact` as soon as it is built: a training set's memory).

        Member sizes are checked from the npy headers before any array is loaded, the JSON
        metadata's depth and integer digits before it is parsed, each clip's frame rate and
        duration before it is built (``limits``, default
        :func:`grip.core.limits.active_limits`).

        Raises:
            ReferenceError: Not a reference file, a missing key, a bad shape or value, a value
                above ``limits``, a corrupt file (the message names the file and the key).
        """
        path = Path(path)
        limits = limits or active_limits()
        data, meta = load_checked_npz(path, limits, ReferenceError, ".npz reference file")
        if not isinstance(meta, dict) or meta.get("format") != "grip-reference":
            raise ReferenceError(f"{path}: not a grip reference file")
        if meta.get("version") != FORMAT_VERSION:
            raise ReferenceError(f"{path}: format version {meta.get('version')}, this code "
                                 f"reads {FORMAT_VERSION}; rebuild it "
                                 "(grip data reference)")  # fmt: skip
        clips = []
        try:
            for i, cm in enumerate(meta["clips"]):
                objects = None
                if cm["objects"]:
                    objects = {
                        n: (data[f"{i}/objects/{n}/vertices"], data[f"{i}/objects/{n}/faces"])
                        for n in cm["objects"]
                    }
                body = BodyParams(height_m=float(cm["body"]["height_m"]),
                                  mass_kg=float(cm["body"]["mass_kg"]))  # fmt: skip
                qpos = data[f"{i}/gt_qpos"]
                limits.check_take(int(qpos.shape[0]) if qpos.ndim else 0, float(cm["fps"]))
                clips.append(ReferenceClip(
                    name=str(cm["name"]), category=str(cm["category"]), fps=float(cm["fps"]),
                    body=body, objects=objects, **{k: data.pop(f"{i}/{k}") for k in PRIMARY},
                ))  # fmt: skip
                if compact:
                    clips[-1].compact()
            return cls(clips, tuple(meta["sensor_sites"]), bool(meta["insoles"]), str(path))
        except KeyError as e:
            raise ReferenceError(f"{path}: missing key {e}") from e
        except ReferenceError as e:
            raise ReferenceError(f"{path}: {e}") from e
        except LimitExceeded as e:
            raise ReferenceError(f"{path}: {e}") from None
        except Exception as e:  # a value no check foresaw (wrong type in the metadata, ...)
            raise ReferenceError(f"{path}: malformed reference file "
                                 f"({type(e).__name__}: {str(e)[:300]})") from None
