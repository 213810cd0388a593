"""The project's own body model with the SMPL topology (no SMPL files).

Rest pose and frames
--------------------
The rest pose is a T-pose expressed in the *SMPL canonical frame*: x = the subject's left,
y = up, z = forward, so PRISM's SMPL ``poses`` apply joint by joint. In the z-up world of PRISM
and MuJoCo, a body standing upright and facing +y has the root rotation
:data:`CANONICAL_TO_WORLD` (canonical y -> world z, canonical z -> world y, left -> world -x).

Proportions follow anthropometric tables (Winter 2009 segment lengths as fractions of stature,
de Leva 1996 mass fractions). Optional measured leg length (hip joint to floor) and arm length
(shoulder joint to wrist joint) rescale those chains; foot length rescales the foot.

Everything here is numpy only: the MJCF builder (:mod:`grip.core.mjcf`) and the numpy forward
kinematics (:mod:`grip.core.fk`) both read one :class:`BodyModel`, so they cannot disagree.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass, field

import numpy as np

from grip.core import skeleton as sk

CANONICAL_TO_WORLD: np.ndarray = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, 1.0, 0.0]])
"""Root rotation that stands the canonical rest pose upright in the z-up world, facing +y."""

GRAVITY = 9.81
"""Gravitational acceleration used throughout, m/s^2."""

# Rest joint positions as fractions of stature H, canonical frame, floor at y = 0 (left side;
# the right side mirrors x). Columns: x (left), y (up), z (forward).
_REST_FRAC = np.array(
    [
        [0.000, 0.565, 0.000],   # 0 Pelvis
        [0.050, 0.515, -0.004],  # 1 L_Hip
        [-0.050, 0.515, -0.004], # 2 R_Hip
        [0.000, 0.630, -0.012],  # 3 Spine1
        [0.056, 0.285, 0.000],   # 4 L_Knee
        [-0.056, 0.285, 0.000],  # 5 R_Knee
        [0.000, 0.710, -0.005],  # 6 Spine2
        [0.050, 0.045, -0.016],  # 7 L_Ankle
        [-0.050, 0.045, -0.016], # 8 R_Ankle
        [0.000, 0.743, 0.000],   # 9 Spine3
        [0.060, 0.013, 0.066],   # 10 L_Foot (toe base)
        [-0.060, 0.013, 0.066],  # 11 R_Foot
        [0.000, 0.870, -0.010],  # 12 Neck
        [0.045, 0.815, -0.005],  # 13 L_Collar
        [-0.045, 0.815, -0.005], # 14 R_Collar
        [0.000, 0.922, 0.012],   # 15 Head
        [0.100, 0.828, -0.010],  # 16 L_Shoulder
        [-0.100, 0.828, -0.010], # 17 R_Shoulder
        [0.260, 0.822, -0.014],  # 18 L_Elbow
        [-0.260, 0.822, -0.014], # 19 R_Elbow
        [0.408, 0.822, -0.012],  # 20 L_Wrist
        [-0.408, 0.822, -0.012], # 21 R_Wrist
        [0.458, 0.820, -0.012],  # 22 L_Hand
        [-0.458, 0.820, -0.012], # 23 R_Hand
    ]
)  # fmt: skip

# de Leva (1996) mass fractions distributed over the 24 segments (sum = 1).
_MASS_FRAC = np.array(
    [0.1117, 0.1416, 0.1416, 0.0800, 0.0433, 0.0433, 0.0833, 0.0110, 0.0110, 0.1296, 0.0027,
     0.0027, 0.0150, 0.0150, 0.0150, 0.0544, 0.0271, 0.0271, 0.0162, 0.0162, 0.0040, 0.0040,
     0.0021, 0.0021]
)  # fmt: skip

# Hinge limits (x, y, z) in degrees for joints 1..23, left side; right side mirrors y and z.
_LIMITS_DEG_LEFT = {
    "Hip": [(-140, 45), (-70, 70), (-40, 80)],
    "Knee": [(-10, 160), (-40, 40), (-30, 30)],
    "Ankle": [(-60, 60), (-50, 50), (-50, 50)],
    "Foot": [(-70, 70), (-20, 20), (-20, 20)],
    "Spine1": [(-70, 70), (-70, 70), (-60, 60)],
    "Spine2": [(-70, 70), (-70, 70), (-60, 60)],
    "Spine3": [(-70, 70), (-70, 70), (-60, 60)],
    "Neck": [(-80, 80), (-80, 80), (-70, 70)],
    "Head": [(-80, 80), (-80, 80), (-70, 70)],
    "Collar": [(-40, 40), (-50, 50), (-50, 50)],
    "Shoulder": [(-170, 170), (-170, 170), (-170, 170)],
    "Elbow": [(-120, 120), (-170, 15), (-40, 40)],
    "Wrist": [(-110, 110), (-90, 90), (-90, 90)],
    "Hand": [(-90, 90), (-90, 90), (-90, 90)],
}

# Base PD gains per joint group for a 1.70 m, 70 kg body (N m/rad); scaled by mass x height.
_KP_BASE = {
    "Hip": 1000.0, "Knee": 1000.0, "Ankle": 1000.0, "Foot": 300.0, "Spine1": 1000.0,
    "Spine2": 1000.0, "Spine3": 1000.0, "Neck": 400.0, "Head": 300.0, "Collar": 500.0,
    "Shoulder": 500.0, "Elbow": 400.0, "Wrist": 200.0, "Hand": 80.0,
}  # fmt: skip
_KD_RATIO = 0.1  # kd = 0.1 * kp, critically damped-ish at ~50 Hz for typical segment inertias


def _group(name: str) -> str:
    return name[2:] if name[:2] in ("L_", "R_") else name


@dataclass(frozen=True)
class BodyParams:
    """Subject parameters that define a body model.

    Attributes:
        height_m: Stature, m.
        mass_kg: Body mass, kg.
        leg_length_m: Optional measured leg length (hip joint centre to floor), m.
        arm_length_m: Optional measured arm length (shoulder joint to wrist joint), m.
        foot_length_m: Optional foot (shoe) length, heel to toe tip, m.
    """

    height_m: float = 1.70
    mass_kg: float = 70.0
    leg_length_m: float | None = None
    arm_length_m: float | None = None
    foot_length_m: float | None = None

    def __post_init__(self) -> None:
        checks = {
            "height_m": (self.height_m, 0.5, 2.6),
            "mass_kg": (self.mass_kg, 10.0, 300.0),
            "leg_length_m": (self.leg_length_m, 0.2, 1.5),
            "arm_length_m": (self.arm_length_m, 0.15, 1.2),
            "foot_length_m": (self.foot_length_m, 0.08, 0.45),
        }
        for name, (value, lo, hi) in checks.items():
            if value is None:
                continue
            if not np.isfinite(value) or not lo <= value <= hi:
                raise ValueError(f"BodyParams.{name}={value!r} is outside [{lo}, {hi}]")
        ratios = {
            "leg_length_m": (self.leg_length_m, 0.38, 0.62),
            "arm_length_m": (self.arm_length_m, 0.22, 0.45),
            "foot_length_m": (self.foot_length_m, 0.11, 0.20),
        }
        for name, (value, lo, hi) in ratios.items():
            if value is not None and not lo <= value / self.height_m <= hi:
                raise ValueError(
                    f"BodyParams.{name}={value!r} is implausible for height_m={self.height_m}: "
                    f"expected {lo:.2f}-{hi:.2f} x height"
                )

    def to_array(self) -> np.ndarray:
        """``(5,)`` float64 with NaN for unset optional values (for npz storage)."""
        vals = [self.height_m, self.mass_kg, self.leg_length_m, self.arm_length_m,
                self.foot_length_m]  # fmt: skip
        return np.array([np.nan if v is None else float(v) for v in vals])

    @classmethod
    def from_array(cls, a: np.ndarray) -> BodyParams:
        """Inverse of :meth:`to_array`."""
        a = np.asarray(a, dtype=np.float64).reshape(-1)
        if a.shape != (5,):
            raise ValueError(f"body parameters must have 5 values, got {a.shape[0]}")
        opt = [None if np.isnan(v) else float(v) for v in a[2:]]
        return cls(float(a[0]), float(a[1]), *opt)


@dataclass(frozen=True)
class Geom:
    """A collision/visual shape attached to a body, in that body's frame (canonical rest axes).

    Attributes:
        body: Index of the carrying body (SMPL joint index).
        kind: ``"capsule"``, ``"box"`` or ``"sphere"``.
        pos: ``(3,)`` centre, m.
        size: capsule: ``(radius, half_length)``; box: ``(hx, hy, hz)`` half sizes;
            sphere: ``(r,)``.
        axis: ``(3,)`` unit axis of a capsule (unused otherwise).
    """

    body: int
    kind: str
    pos: np.ndarray
    size: np.ndarray
    axis: np.ndarray = field(default_factory=lambda: np.array([0.0, 1.0, 0.0]))

    def fromto(self) -> np.ndarray:
        """Capsule end points ``(6,)`` (start, end), m."""
        half = self.size[1] * self.axis
        return np.concatenate([self.pos - half, self.pos + half])


@dataclass(frozen=True)
class BodyModel:
    """Rest skeleton, mass distribution, shapes and sensor mounts of one subject.

    All vectors are in the carrying body's frame, which at rest is parallel to the canonical frame
    (x left, y up, z forward); lengths in m, masses in kg, angles in rad.

    Attributes:
        params: The parameters this model was built from.
        offsets: ``(24, 3)`` rest offset of each joint from its parent joint. Row 0 holds the
            pelvis position above the floor in the rest pose.
        rest_joint_pos: ``(24, 3)`` rest joint positions, floor at y = 0.
        masses: ``(24,)`` segment masses, kg; they sum to ``params.mass_kg``.
        com_local: ``(24, 3)`` centre of mass of each segment in its body frame.
        inertia_local: ``(24, 3, 3)`` inertia tensor about the segment COM, body frame, kg m^2.
        geoms: Shapes (capsules, boxes, spheres) used for collisions, inertia and rendering.
        hinge_range: ``(24, 3, 2)`` lower/upper limit of the x, y, z hinges of each joint
            (row 0, the free root, is unused).
        kp: ``(24,)`` PD stiffness per joint (same for its 3 hinges), N m/rad, scaled by mass.
        kd: ``(24,)`` PD damping, N m s/rad.
        imu_sites: part -> ``(body index, (3,) position)`` of the 8 PRISM IMU mounts.
        insole_body: ``(2, 16)`` body carrying each insole cell (foot or toes), feet L then R.
        insole_pos: ``(2, 16, 3)`` cell centres on the sole in the carrying body's frame.
        insole_area_cm2: ``(2, 16)`` cell areas, cm^2.
        insole_origin: ``(2, 3)`` insole-frame origin (mid-foot on the sole), foot body frame.
        insole_axes: ``(2, 2, 3)`` insole-frame axes in the foot body frame: forward
            (heel -> toe) and medial, per foot.
        foot_length: Heel to toe tip, m.
        foot_width: Sole width, m.
        sole_points_body: ``(2, 6)`` body index of the 6 sole corner points of each foot.
        sole_points_pos: ``(2, 6, 3)`` those points in the body frame (heel corners, toe-base
            corners on the foot, toe-tip corners on the toes).
    """

    params: BodyParams
    offsets: np.ndarray
    rest_joint_pos: np.ndarray
    masses: np.ndarray
    com_local: np.ndarray
    inertia_local: np.ndarray
    geoms: tuple[Geom, ...]
    hinge_range: np.ndarray
    kp: np.ndarray
    kd: np.ndarray
    imu_sites: dict[str, tuple[int, np.ndarray]]
    insole_body: np.ndarray
    insole_pos: np.ndarray
    insole_area_cm2: np.ndarray
    insole_origin: np.ndarray
    insole_axes: np.ndarray
    foot_length: float
    foot_width: float
    sole_points_body: np.ndarray
    sole_points_pos: np.ndarray

    @property
    def leg_length(self) -> float:
        """Hip joint centre to floor in the rest pose, m."""
        return float(self.rest_joint_pos[1, 1])

    @property
    def pelvis_height(self) -> float:
        """Pelvis joint above the floor in the rest pose, m."""
        return float(self.rest_joint_pos[0, 1])

    @property
    def total_mass(self) -> float:
        return float(self.masses.sum())


def _capsule_inertia(mass: float, radius: float, length: float) -> np.ndarray:
    """Solid capsule (cylinder of ``length`` + two hemispheres) about its COM, axis = y."""
    r, h = radius, length
    v_cyl = np.pi * r**2 * h
    v_sph = 4.0 / 3.0 * np.pi * r**3
    m_cyl = mass * v_cyl / (v_cyl + v_sph)
    m_sph = mass - m_cyl
    i_axis = m_cyl * r**2 / 2 + m_sph * 2 * r**2 / 5
    i_perp = (m_cyl * (r**2 / 4 + h**2 / 12)
              + m_sph * (2 * r**2 / 5 + h**2 / 4 + 3 * h * r / 8))  # fmt: skip
    return np.diag([i_perp, i_axis, i_perp])


def _frame_from_axis(axis: np.ndarray) -> np.ndarray:
    """Rotation whose y column is ``axis``."""
    from grip.core.rotations import rotation_between

    return rotation_between(np.array([0.0, 1.0, 0.0]), axis)


def build_body(params: BodyParams | None = None) -> BodyModel:
    """Build the body model for one subject.

    Models are cached by their parameters (the last 256): evaluation, training and synthesis ask
    for the same subject's body many times, and a build takes ~20 ms. A cached model is shared,
    so its arrays are read-only.

    Args:
        params: Subject parameters; defaults to 1.70 m, 70 kg.

    Returns:
        The :class:`BodyModel` shared by numpy FK, sensor synthesis and the MJCF builder.
    """
    return _cached_body(params or BodyParams())


def _read_only(x):
    """``x`` with every numpy array in it (also inside tuples, dicts and geoms) made read-only."""
    if isinstance(x, np.ndarray):
        x.setflags(write=False)
    elif isinstance(x, tuple | list):
        for v in x:
            _read_only(v)
    elif isinstance(x, dict):
        for v in x.values():
            _read_only(v)
    elif isinstance(x, Geom):
        for f in ("pos", "size", "axis"):
            _read_only(getattr(x, f))
    return x


@functools.lru_cache(maxsize=256)
def _cached_body(p: BodyParams) -> BodyModel:
    body = _build_body(p)
    for f in dataclasses.fields(body):
        _read_only(getattr(body, f.name))
    return body


def _build_body(p: BodyParams) -> BodyModel:
    h = p.height_m
    rest = _REST_FRAC * h
    offsets = np.zeros_like(rest)
    offsets[0] = rest[0]
    offsets[1:] = rest[1:] - rest[sk.PARENTS[1:]]

    # Leg length: scale the chain hip -> knee -> ankle -> toe and the ankle height.
    leg_scale = 1.0 if p.leg_length_m is None else p.leg_length_m / rest[1, 1]
    for j in (4, 5, 7, 8):
        offsets[j] *= leg_scale
    for j in (10, 11):
        offsets[j, 1] *= leg_scale
    arm_scale = 1.0
    if p.arm_length_m is not None:
        arm_scale = p.arm_length_m / np.linalg.norm(rest[20] - rest[16])
    for j in (18, 19, 20, 21, 22, 23):
        offsets[j] *= arm_scale
    foot_scale = 1.0 if p.foot_length_m is None else p.foot_length_m / (0.152 * h)
    for j in (10, 11):
        offsets[j, [0, 2]] *= foot_scale
    # The pelvis sits above the hips at the rest height the legs give it.
    offsets[0] = np.array([0.0, -offsets[1, 1] - offsets[4, 1] - offsets[7, 1] + 0.0, 0.0])
    offsets[0, 1] += 0.045 * h * leg_scale  # ankle above the sole
    rest_pos = np.zeros_like(rest)
    rest_pos[0] = offsets[0]
    for j in range(1, sk.N_JOINTS):
        rest_pos[j] = rest_pos[sk.PARENTS[j]] + offsets[j]

    masses = _MASS_FRAC / _MASS_FRAC.sum() * p.mass_kg

    # ---------------------------------------------------------------- feet
    ankle_h = rest_pos[7, 1]  # ankle above the sole
    foot_len = 0.152 * h * foot_scale
    foot_w = 0.055 * h * foot_scale
    heel_z = -0.25 * foot_len  # heel behind the ankle
    toe_tip_z = 0.75 * foot_len
    mid_z = 0.5 * (heel_z + toe_tip_z)

    geoms: list[Geom] = []
    com = np.zeros((sk.N_JOINTS, 3))
    inertia = np.zeros((sk.N_JOINTS, 3, 3))

    def add_capsule(j: int, a: np.ndarray, b: np.ndarray, r: float) -> None:
        axis = b - a
        length = float(np.linalg.norm(axis))
        geoms.append(Geom(j, "capsule", 0.5 * (a + b), np.array([r, length / 2]), axis / length))

    def add_box(j: int, pos: np.ndarray, half: np.ndarray) -> None:
        geoms.append(Geom(j, "box", pos, half))

    def add_sphere(j: int, pos: np.ndarray, r: float) -> None:
        geoms.append(Geom(j, "sphere", pos, np.array([r])))

    def child(c: int, lo: float = 0.08, hi: float = 0.92) -> tuple[np.ndarray, np.ndarray]:
        return lo * offsets[c], hi * offsets[c]

    add_capsule(0, np.array([-0.04 * h, -0.02 * h, 0.0]), np.array([0.04 * h, -0.02 * h, 0.0]),
                0.06 * h)  # fmt: skip
    for j, c, r in ((1, 4, 0.034), (2, 5, 0.034), (4, 7, 0.026), (5, 8, 0.026)):
        add_capsule(j, *child(c), r * h)
    for j, c in ((3, 6), (6, 9)):
        y = 0.5 * offsets[c, 1]
        add_capsule(j, np.array([-0.035 * h, y, 0.0]), np.array([0.035 * h, y, 0.0]), 0.055 * h)
    add_capsule(9, np.array([-0.05 * h, 0.06 * h, 0.0]), np.array([0.05 * h, 0.06 * h, 0.0]),
                0.06 * h)  # fmt: skip
    add_capsule(12, 0.1 * offsets[15], 0.8 * offsets[15], 0.022 * h)
    for j, c in ((13, 16), (14, 17)):
        add_capsule(j, *child(c, 0.2, 0.8), 0.022 * h)
    add_sphere(15, np.array([0.0, 0.035 * h, 0.01 * h]), 0.058 * h)
    for j, c, r in ((16, 18, 0.022), (17, 19, 0.022), (18, 20, 0.018), (19, 21, 0.018),
                    (20, 22, 0.016), (21, 23, 0.016)):  # fmt: skip
        add_capsule(j, *child(c, 0.05, 0.95), r * h)
    for j, sign in ((22, 1.0), (23, -1.0)):
        add_capsule(j, np.zeros(3), np.array([sign * 0.05 * h, 0.0, 0.0]), 0.012 * h)
    toe_h = rest_pos[10, 1]  # toe joint above the sole
    for a, t in ((7, 10), (8, 11)):
        toe_rel_z = offsets[t, 2]
        add_box(a, np.array([offsets[t, 0] / 2, -ankle_h / 2, 0.5 * (heel_z + toe_rel_z)]),
                np.array([foot_w / 2, ankle_h / 2, 0.5 * (toe_rel_z - heel_z)]))  # fmt: skip
        toe_len = toe_tip_z - toe_rel_z
        add_box(t, np.array([-offsets[t, 0] / 2, -toe_h / 2 + 0.005, toe_len / 2]),
                np.array([foot_w / 2, toe_h / 2 + 0.005, toe_len / 2]))  # fmt: skip

    # Segment COM and inertia from the main shape of each body, with the segment's mass.
    for j in range(sk.N_JOINTS):
        shapes = [g for g in geoms if g.body == j]
        g = shapes[0]
        m = masses[j]
        com[j] = g.pos
        if g.kind == "capsule":
            rot = _frame_from_axis(g.axis)
            inertia[j] = rot @ _capsule_inertia(m, g.size[0], 2 * g.size[1]) @ rot.T
        elif g.kind == "box":
            hx, hy, hz = g.size
            inertia[j] = np.diag([m * (hy**2 + hz**2) / 3, m * (hx**2 + hz**2) / 3,
                                  m * (hx**2 + hy**2) / 3])  # fmt: skip
        else:
            inertia[j] = np.eye(3) * 0.4 * m * g.size[0] ** 2

    # ---------------------------------------------------------------- limits and gains
    hinge_range = np.zeros((sk.N_JOINTS, 3, 2))
    kp = np.zeros(sk.N_JOINTS)
    for j, name in enumerate(sk.JOINT_NAMES):
        if j == 0:
            continue
        grp = _group(name)
        lim = np.deg2rad(np.array(_LIMITS_DEG_LEFT[grp], dtype=np.float64))
        if name.startswith("R_"):
            # Mirroring x -> -x keeps rotations about x and flips those about y and z.
            lim[1:] = -lim[1:, ::-1]
        hinge_range[j] = lim
        # Gravity torques grow with mass x height, so the gains do too.
        kp[j] = _KP_BASE[grp] * (p.mass_kg / 70.0) * (p.height_m / 1.70)
    kd = _KD_RATIO * kp

    # ---------------------------------------------------------------- IMU sites
    imu_sites = {
        "L_Foot": (7, np.array([offsets[10, 0] / 2, -ankle_h + 0.006, mid_z])),
        "R_Foot": (8, np.array([offsets[11, 0] / 2, -ankle_h + 0.006, mid_z])),
        "L_Wrist": (18, 0.92 * offsets[20] + np.array([0.0, 0.016 * h, 0.0])),
        "R_Wrist": (19, 0.92 * offsets[21] + np.array([0.0, 0.016 * h, 0.0])),
        "Head": (15, np.array([0.0, 0.05 * h, 0.05 * h])),
        "Pelvis": (0, np.array([0.0, 0.0, -0.06 * h])),
        "L_Knee": (4, np.array([0.0, -0.05 * h, 0.03 * h]) * leg_scale),
        "R_Knee": (5, np.array([0.0, -0.05 * h, 0.03 * h]) * leg_scale),
    }

    # ---------------------------------------------------------------- insoles
    insole_body = np.zeros((2, sk.N_INSOLE_CELLS), dtype=np.int64)
    insole_pos = np.zeros((2, sk.N_INSOLE_CELLS, 3))
    insole_origin = np.zeros((2, 3))
    insole_axes = np.zeros((2, 2, 3))
    sole_body = np.zeros((2, 6), dtype=np.int64)
    sole_pos = np.zeros((2, 6, 3))
    area = np.broadcast_to(sk.INSOLE_CELL_AREA_CM2 * (foot_len * foot_w) / (0.26 * 0.095),
                           (2, sk.N_INSOLE_CELLS)).copy()  # fmt: skip
    for f, (a, t) in enumerate(((7, 10), (8, 11))):
        lateral_x = 1.0 if f == 0 else -1.0  # left foot: lateral = +x (the subject's left)
        centre_x = offsets[t, 0] / 2
        medial = np.array([-lateral_x, 0.0, 0.0])
        insole_origin[f] = np.array([centre_x, -ankle_h, mid_z])
        insole_axes[f] = np.array([[0.0, 0.0, 1.0], medial])
        u, v = sk.INSOLE_CELL_UV[:, 0] * foot_len, sk.INSOLE_CELL_UV[:, 1] * foot_w
        pos_foot = insole_origin[f] + u[:, None] * insole_axes[f, 0] + v[:, None] * medial
        on_toe = pos_foot[:, 2] > offsets[t, 2]
        insole_body[f] = np.where(on_toe, t, a)
        insole_pos[f] = np.where(on_toe[:, None], pos_foot - offsets[t], pos_foot)
        half_w = foot_w / 2
        corners_foot = [
            [centre_x - half_w, -ankle_h, heel_z],
            [centre_x + half_w, -ankle_h, heel_z],
            [centre_x - half_w, -ankle_h, offsets[t, 2]],
            [centre_x + half_w, -ankle_h, offsets[t, 2]],
        ]  # fmt: skip
        toe_len = toe_tip_z - offsets[t, 2]
        toe_x = -offsets[t, 0] / 2  # the toe box shares the foot box's centre line
        corners_toe = [[toe_x - half_w, -toe_h, toe_len], [toe_x + half_w, -toe_h, toe_len]]
        sole_body[f] = [a, a, a, a, t, t]
        sole_pos[f] = np.array(corners_foot + corners_toe)

    return BodyModel(
        params=p,
        offsets=offsets,
        rest_joint_pos=rest_pos,
        masses=masses,
        com_local=com,
        inertia_local=inertia,
        geoms=tuple(geoms),
        hinge_range=hinge_range,
        kp=kp,
        kd=kd,
        imu_sites=imu_sites,
        insole_body=insole_body,
        insole_pos=insole_pos,
        insole_area_cm2=area,
        insole_origin=insole_origin,
        insole_axes=insole_axes,
        foot_length=float(foot_len),
        foot_width=float(foot_w),
        sole_points_body=sole_body,
        sole_points_pos=sole_pos,
    )
