"""Load the MuJoCo humanoid and map between SMPL-ordered arrays and MuJoCo's indices.

MuJoCo orders ``qpos``/``qvel`` by depth-first body order, actuators in SMPL order; every
mapping goes through :class:`HumanoidIndex`, whose integer arrays are resolved once per model so
that per-step code never looks a name up.
"""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from grip.core import skeleton as sk
from grip.core.body import BodyModel, BodyParams
from grip.core.mjcf import (
    ROOT_JOINT,
    MjcfConfig,
    build_mjcf,
    foot_force_sensor_names,
    hinge_names,
    imu_site_names,
    insole_site_names,
    touch_sensor_names,
)
from grip.core.reference import pose_vector


def load_model(
    body_or_params: BodyModel | BodyParams | None = None, cfg: MjcfConfig | None = None
) -> mujoco.MjModel:
    """Compile the humanoid of one subject.

    Args:
        body_or_params: Body model or subject parameters (``None``: 1.70 m, 70 kg).
        cfg: MJCF options (``None``: :class:`MjcfConfig` defaults).

    Returns:
        The compiled model (nq = 76, nv = 75, nu = 69); ``qpos0`` and keyframe ``"stand"`` are
        the rest T-pose standing on the floor.
    """
    return mujoco.MjModel.from_xml_string(build_mjcf(body_or_params, cfg))


@dataclass(frozen=True)
class HumanoidIndex:
    """Integer indices of the humanoid's parts, resolved once per model.

    Attributes:
        body_ids: ``(24,)`` MuJoCo body id of each SMPL joint's body.
        root_qpos_adr: First ``qpos`` address of the free root (position, then quaternion wxyz).
        root_dof_adr: First ``qvel`` address of the free root (linear, then angular velocity).
        hinge_qpos_adr: ``(69,)`` ``qpos`` address of each hinge, SMPL order (joint 1..23, then
            its hinges in :data:`grip.core.skeleton.HINGE_ORDERS` order).
        hinge_dof_adr: ``(69,)`` ``qvel``/``qfrc`` address of each hinge, same order.
        actuator_ids: ``(69,)`` actuator id of each hinge, same order.
        imu_site_ids: ``(8,)`` site ids in :data:`grip.core.skeleton.IMU_PARTS` order.
        insole_site_ids: ``(2, 16)`` insole cell site ids, left foot first.
        touch_adr: ``(2, 16)`` ``sensordata`` address of each cell's touch sensor, or an empty
            ``(0,)`` array when the model has no insole sensors.
    """

    body_ids: np.ndarray
    root_qpos_adr: int
    root_dof_adr: int
    hinge_qpos_adr: np.ndarray
    hinge_dof_adr: np.ndarray
    actuator_ids: np.ndarray
    imu_site_ids: np.ndarray
    insole_site_ids: np.ndarray
    touch_adr: np.ndarray

    @classmethod
    def from_model(cls, model: mujoco.MjModel) -> HumanoidIndex:
        """Resolve all names of a model built by :func:`grip.core.mjcf.build_mjcf`.

        Raises:
            KeyError: A body, joint, actuator or site of the humanoid is missing.
        """
        hinges = hinge_names()
        jids = np.array([model.joint(n).id for n in hinges], dtype=np.int64)
        root = model.joint(ROOT_JOINT)
        touch = np.zeros(0, dtype=np.int64)
        touch_names = touch_sensor_names()
        if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, touch_names[0][0]) >= 0:
            touch = np.array([[model.sensor(n).adr[0] for n in row] for row in touch_names],
                             dtype=np.int64)  # fmt: skip
        return cls(
            body_ids=np.array([model.body(n).id for n in sk.JOINT_NAMES], dtype=np.int64),
            root_qpos_adr=int(root.qposadr[0]),
            root_dof_adr=int(root.dofadr[0]),
            hinge_qpos_adr=model.jnt_qposadr[jids].astype(np.int64),
            hinge_dof_adr=model.jnt_dofadr[jids].astype(np.int64),
            actuator_ids=np.array([model.actuator(n).id for n in hinges], dtype=np.int64),
            imu_site_ids=np.array([model.site(n).id for n in imu_site_names()], dtype=np.int64),
            insole_site_ids=np.array(
                [[model.site(n).id for n in row] for row in insole_site_names()], dtype=np.int64
            ),
            touch_adr=touch,
        )


def pose_to_qpos(local_rot: np.ndarray, root_pos: np.ndarray, index: HumanoidIndex,
                 qpos: np.ndarray) -> None:  # fmt: skip
    """Write a pose into a ``qpos`` vector in place.

    Args:
        local_rot: ``(24, 3, 3)`` joint rotations relative to the parent body; row 0 is the
            root's world rotation (as in :func:`grip.core.fk.forward_kinematics`).
        root_pos: ``(3,)`` pelvis position, world frame, m.
        index: Indices of the model.
        qpos: ``(nq,)`` vector to fill (root and the 69 hinges).
    """
    local_rot = np.asarray(local_rot, dtype=np.float64)
    if local_rot.shape != (sk.N_JOINTS, 3, 3):
        raise ValueError(f"local_rot must have shape (24, 3, 3), got {local_rot.shape}")
    root_pos = np.asarray(root_pos, dtype=np.float64).reshape(3)
    write_pose_vector(pose_vector(local_rot, root_pos), index, qpos)


def write_pose_vector(pose: np.ndarray, index: HumanoidIndex, qpos: np.ndarray) -> None:
    """Scatter a ``(76,)`` pose vector (:func:`grip.core.reference.pose_vector`: root position,
    root quaternion, hinges in SMPL order) into MuJoCo's ``qpos`` order, in place."""
    r = index.root_qpos_adr
    qpos[r : r + 7] = pose[:7]
    qpos[index.hinge_qpos_adr] = pose[7:]


def write_velocity_vector(vel: np.ndarray, index: HumanoidIndex, qvel: np.ndarray) -> None:
    """Scatter a ``(75,)`` velocity vector (root linear velocity in the world, root angular
    velocity in the root frame, hinge rates in SMPL order) into MuJoCo's ``qvel``, in place."""
    r = index.root_dof_adr
    qvel[r : r + 6] = vel[:6]
    qvel[index.hinge_dof_adr] = vel[6:]


def set_pose(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    index: HumanoidIndex,
    local_rot: np.ndarray,
    root_pos: np.ndarray,
    kinematics: bool = True,
) -> None:
    """Put the humanoid in a pose (``qpos`` only; velocities are left as they are).

    Hinge angles are the Euler angles of each local rotation in the joint's hinge order
    (:data:`grip.core.skeleton.HINGE_ORDERS`); they are written as they come, even outside the
    hinge limits.

    Args:
        model: The humanoid model.
        data: Its data; ``data.qpos`` is overwritten for the root and all hinges.
        index: :class:`HumanoidIndex` of ``model``.
        local_rot: ``(24, 3, 3)`` local joint rotations, row 0 = root world rotation.
        root_pos: ``(3,)`` pelvis position, world frame, m.
        kinematics: Run ``mj_kinematics`` afterwards so that ``xpos``/``xmat``/``site_xpos``
            match the pose (contacts and sensors still need ``mj_forward``).
    """
    pose_to_qpos(local_rot, root_pos, index, data.qpos)
    if kinematics:
        mujoco.mj_kinematics(model, data)


def body_positions(data: mujoco.MjData, index: HumanoidIndex) -> np.ndarray:
    """``(24, 3)`` world positions of the 24 joints (body origins) in SMPL order, m (a copy)."""
    return data.xpos[index.body_ids].copy()


def body_rotations(data: mujoco.MjData, index: HumanoidIndex) -> np.ndarray:
    """``(24, 3, 3)`` world rotations of the 24 bodies in SMPL order (a copy)."""
    return data.xmat[index.body_ids].reshape(sk.N_JOINTS, 3, 3).copy()


def insole_forces(data: mujoco.MjData, index: HumanoidIndex) -> np.ndarray:
    """``(2, 16)`` normal force on each insole cell from the touch sensors, N.

    Raises:
        ValueError: The model was built without insole sensors.
    """
    if index.touch_adr.size == 0:
        raise ValueError("the model has no insole touch sensors (MjcfConfig.insole_sensors)")
    return data.sensordata[index.touch_adr].copy()


class FootContacts:
    """Ground reaction force and centre of pressure of each foot from MuJoCo's contacts.

    With the model's net foot-force sensors (``MjcfConfig.foot_force_sensors``, the default)
    MuJoCo sums the contacts of each foot's subtree with the world body in C; the centre of
    pressure is the point on the contact's level where the net wrench has no horizontal moment
    (equal to the vertical-force-weighted mean of the contact points where they lie at one
    height, as on a floor or a box top). Without them (``loop=True`` or a model built without),
    the foot-ground contacts are summed here (``mj_contactForce``, turned to the world frame;
    the CoP weighted by the normal forces); contacts with other body parts are not ground
    reaction forces either way.

    Args:
        model: The humanoid model.
        index: Its :class:`HumanoidIndex`.
        loop: Sum the contacts in Python even when the sensors exist (the reference the
            sensors are tested against).
    """

    def __init__(self, model: mujoco.MjModel, index: HumanoidIndex, loop: bool = False) -> None:
        self._sensor_adr = None
        ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, n)
               for n in foot_force_sensor_names()]  # fmt: skip
        if not loop and min(ids) >= 0:
            self._sensor_adr = [int(model.sensor_adr[i]) for i in ids]
        self._side = np.full(model.ngeom, -1, dtype=np.int64)
        for s, side in enumerate(("L_Foot", "R_Foot")):
            for joint in (sk.FOOT_BODY[side], sk.TOE_BODY[side]):
                body = int(index.body_ids[joint])
                self._side[model.geom_bodyid == body] = s
        self._ground = model.geom_bodyid == 0  # floor and terrain belong to the world body
        self._model = model
        self._f6 = np.zeros(6)

    def __call__(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """``grf (2, 3)`` (N, world, the force the ground exerts on each foot) and ``cop (2, 3)``
        (world, m; normal-force-weighted mean of the contact points, NaN without contact)."""
        m = self._model
        # After mj_step (or the env's step2 + step1) the contact list belongs to the new state
        # but the constraint forces to the previous one: solve the forces of this state (the
        # state itself is not changed, and the next step computes the same forces again).
        mujoco.mj_fwdActuation(m, data)
        mujoco.mj_fwdAcceleration(m, data)
        mujoco.mj_fwdConstraint(m, data)
        if self._sensor_adr is not None:
            return self._from_sensors(data)
        grf = np.zeros((2, 3))
        moment = np.zeros((2, 3))
        fz = np.zeros(2)
        for i in range(data.ncon):
            c = data.contact[i]
            s1, s2 = self._side[c.geom1], self._side[c.geom2]
            if not ((s1 >= 0 and self._ground[c.geom2]) or (s2 >= 0 and self._ground[c.geom1])):
                continue  # not a foot on the ground
            mujoco.mj_contactForce(m, data, i, self._f6)
            f = c.frame.reshape(3, 3).T @ self._f6[:3]  # world force on geom2
            side = s2 if s2 >= 0 else s1
            if s1 >= 0:
                f = -f
            grf[side] += f
            moment[side] += abs(self._f6[0]) * c.pos
            fz[side] += abs(self._f6[0])
        cop = np.full((2, 3), np.nan)
        on = fz > 1e-9
        cop[on] = moment[on] / fz[on, None]
        return grf, cop

    def _from_sensors(self, data: mujoco.MjData) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`__call__` from the net foot-force sensors (the constraint forces solved)."""
        mujoco.mj_sensorAcc(self._model, data)
        s = data.sensordata
        grf = np.empty((2, 3))
        cop = np.full((2, 3), np.nan)
        for k, a in enumerate(self._sensor_adr):
            w = s[a : a + 9]  # the wrench the foot exerts on the world, about the point w[6:9]
            grf[k] = -w[:3]
            fz = grf[k, 2]
            if fz > 1e-9:  # the point on its level where the GRF's horizontal moment vanishes
                cop[k] = (w[6] + w[4] / fz, w[7] - w[3] / fz, w[8])
        return grf, cop


_STAT_FIELDS = ("meaninertia", "meanmass", "meansize", "extent", "center")


def _model_arrays(model: mujoco.MjModel) -> dict[str, np.ndarray]:
    """Copies of a model's numeric arrays (``stat.*`` included, names and paths left out)."""
    out = {}
    for name in dir(model):
        if name.startswith(("_", "name_", "names", "paths")):
            continue
        try:
            a = getattr(model, name)
        except (AttributeError, TypeError, ValueError):
            continue
        if isinstance(a, np.ndarray) and a.dtype.kind in "biuf":
            out[name] = a.copy()
    for name in _STAT_FIELDS:
        out[f"stat.{name}"] = np.array(getattr(model.stat, name), dtype=np.float64)
    return out


class ModelArrays:
    """Copies of a model's numeric arrays (:func:`_model_arrays`) and their bytes laid end to
    end, so that two models of one topology are compared in one pass. Built once per compiled
    model, it can be shared by every :class:`ModelVariants` that adds or starts from that
    model (read only).

    Args:
        model: The model (not changed).
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.arrays = _model_arrays(model)
        self._names = [n for n, a in self.arrays.items() if a.size]
        parts = [self.arrays[n].reshape(-1).view(np.uint8) for n in self._names]
        self._bytes = np.concatenate(parts)
        self._starts = np.cumsum([0] + [p.size for p in parts[:-1]])

    def differing(self, other: ModelArrays) -> list[str]:
        """Names of the arrays whose bytes differ from ``other``'s (same shapes: checked by
        the caller). A NaN of another bit pattern, or -0.0 against 0.0, counts as different."""
        if self._bytes.size != other._bytes.size or self._names != other._names:
            raise ValueError("models of different topology")
        neq = np.add.reduceat(self._bytes != other._bytes, self._starts, dtype=np.intp)
        return [n for n, c in zip(self._names, neq.tolist(), strict=True) if c]


class ModelVariants:
    """Switch one compiled ``MjModel`` between variants of the same topology (the humanoid of
    other subjects: other segment lengths, masses and gains) by copying the arrays that differ,
    instead of compiling and allocating a model per variant (~50 ms each).

    After :meth:`switch` the model equals, array by array, the model compiled for that
    variant (``stat`` included; names stay those of the first), so a simulation on it is
    identical to one on the compiled model (tested bit for bit).

    Args:
        model: The compiled model, modified in place by :meth:`switch`.
        key: The variant it was compiled for.
        arrays: ``ModelArrays(model)`` when already made (e.g. of the compiled model that
            ``model`` is an unchanged copy of; shared, read only).
    """

    def __init__(self, model: mujoco.MjModel, key, arrays: ModelArrays | None = None) -> None:
        self.model = model
        self.key = key
        self._base_arrays = arrays if arrays is not None else ModelArrays(model)
        self._base = self._base_arrays.arrays
        self._diffs: dict = {key: {}}
        self._touched: set[str] = set()

    def __contains__(self, key) -> bool:
        return key in self._diffs

    def add(self, key, compiled: mujoco.MjModel, arrays: ModelArrays | None = None) -> None:
        """Register a variant from the model compiled for it (which is then not needed;
        ``arrays``: its :class:`ModelArrays` when already made, shared and read only).

        Raises:
            ValueError: The model's topology (array sizes) differs from the first one's.
        """
        got = arrays if arrays is not None else ModelArrays(compiled)
        for name, base in self._base.items():
            a = got.arrays.get(name)
            if a is None or a.shape != base.shape:
                raise ValueError(f"model variant {key!r}: {name} has shape "
                                 f"{None if a is None else a.shape}, the model's is {base.shape}"
                                 " (a variant must have the same topology)")  # fmt: skip
        diff = {name: got.arrays[name] for name in self._base_arrays.differing(got)}
        self._diffs[key] = diff
        self._touched |= diff.keys()

    def switch(self, key) -> None:
        """Make the model the variant ``key`` (added before)."""
        if key == self.key:
            return
        diff = self._diffs[key]
        m = self.model
        for name in self._touched:
            v = diff.get(name, self._base[name])
            if name.startswith("stat."):
                field = name[5:]
                if field == "center":
                    m.stat.center[:] = v
                else:
                    setattr(m.stat, field, float(v))
            else:
                getattr(m, name)[...] = v
        self.key = key
