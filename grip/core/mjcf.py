"""MJCF (MuJoCo XML) text of the humanoid, built from the same :class:`BodyModel` as numpy FK.

This module writes text only: it never imports mujoco (``grip.core`` stays numpy-only); the
loader lives in :mod:`grip.sim.model`.

Model layout
------------
* Bodies are named as :data:`grip.core.skeleton.JOINT_NAMES` and nested in SMPL parent order.
  The root ``Pelvis`` carries a free joint named ``"root"``; every other body sits at its rest
  offset with identity orientation (body frames are parallel to the SMPL canonical frame
  x = left, y = up, z = forward at rest) and carries three hinges ``<Joint>_x``, ``<Joint>_y``,
  ``<Joint>_z`` about its local x, y, z axes, listed in the joint's order
  :data:`grip.core.skeleton.HINGE_ORDERS` (``xyz`` except shoulders ``yxz`` and elbows ``yzx``,
  chosen to keep the hinges away from gimbal lock). MuJoCo composes the hinges of one body in
  that order, e.g. ``Rx(a) @ Ry(b) @ Rz(c)``: :func:`grip.core.rotations.euler_to_matrix`.
* ``qpos`` is ``[root_pos_world (3), root_quat_wxyz (4), 69 hinge angles]`` with the hinges in
  MuJoCo's depth-first body order, which is *not* SMPL order. Actuators are listed in SMPL order
  (joint 1..23, then its hinges in composition order), which is :func:`hinge_names`; map with
  the index arrays of
  :class:`grip.sim.model.HumanoidIndex`, never by position.
* The standing pose (rest T-pose upright on the floor, facing world +y) is ``qpos0`` of the model
  and the keyframe ``"stand"``: root quaternion = :data:`grip.core.body.CANONICAL_TO_WORLD`,
  root height = :attr:`BodyModel.pelvis_height`, all hinges 0.
* Mass and inertia come only from explicit ``<inertial>`` elements (``inertiafromgeom="false"``),
  so the model weighs exactly ``BodyModel.masses.sum()``; geoms are for collision and display.
* PD control runs inside MuJoCo: one position actuator per hinge, ``kp``/``kv`` from
  :attr:`BodyModel.kp`/:attr:`BodyModel.kd`, ``ctrl`` = target hinge angle in rad, clamped to the
  hinge range. Joint armature and damping keep the 5 ms ``implicitfast`` step stable
  (``DESIGN.md``, "Facts about this machine").

Contacts
--------
Collision bits (``contype``/``conaffinity``): the floor (and any terrain added later) has
``contype=1, conaffinity=0``; body geoms have ``contype=2`` and ``conaffinity=1|2`` with
self-collision or ``1`` without; sole pads have ``contype=4, conaffinity=1``. So everything
touches the floor, sole pads touch nothing else, and limbs touch each other only when
:attr:`MjcfConfig.self_collision` is on. MuJoCo already drops parent-child pairs; body pairs whose
shapes overlap (or nearly touch) in the rest pose (torso vs upper legs, chest vs upper arms,
neck vs collars, ...) are listed in ``<contact><exclude>`` (:func:`rest_overlap_pairs`), because
they would otherwise push each other apart from the first step.

Feet and insoles. MuJoCo's box-plane collision produces contacts only at box corners, so box
feet alone could never load an insole cell that is not at a corner. Each of the 32 insole cells
therefore gets a small collision sphere ("sole pad", floor-only) whose lowest point is the cell
centre on the sole plane; the foot and toe boxes of the body model still collide with the floor
(and with limbs), but their bottom face is raised by :attr:`MjcfConfig.foot_box_clearance_m`, so
a flat foot rests on its pads and the 32 ``touch`` sensors (one per cell site; each site is a
thin box around the cell reaching a few mm above and below the sole) add up to the ground
reaction force. When the foot is tilted far enough for a box edge to touch (a steep heel
strike), that part of the force is not seen by the insole, as on a real insole with a rigid
shoe rim. With ``sole_pads=False`` the boxes are emitted exactly as in the body model and the
touch sensors only see corner contacts that happen to lie under a cell.
"""

from __future__ import annotations

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from grip.core import skeleton as sk
from grip.core.body import CANONICAL_TO_WORLD, GRAVITY, BodyModel, BodyParams, build_body
from grip.core.rotations import matrix_to_quat

ROOT_JOINT = "root"
"""Name of the free joint of the pelvis."""

STAND_KEY = "stand"
"""Name of the standing keyframe."""

FOOT_SIDES: tuple[str, str] = ("L", "R")
"""Insole side letters, in the order of ``BodyModel.insole_*`` rows."""


# Collision bits, see the module docstring.
SIM_TEXTURE_PX = 64
"""Texture size (:attr:`MjcfConfig.texture_px`) of the models that simulate without a video:
a 64 px floor still shows its grid in an env's ``render()``, at 86 kB instead of 5.5 MB."""

_BIT_FLOOR = 1
_BIT_BODY = 2
_BIT_PAD = 4

_FOOT_BODIES = frozenset((*sk.FOOT_BODY.values(), *sk.TOE_BODY.values()))

_RGBA_BODY = "0.80 0.62 0.50 1"
_RGBA_FOOT = "0.25 0.25 0.30 1"
_RGBA_PAD = "0.15 0.15 0.18 1"
_RGBA_IMU = "1.00 0.45 0.00 1"
_RGBA_INSOLE = "0.10 0.55 1.00 0.6"


@dataclass(frozen=True)
class MjcfConfig:
    """Simulation options of the generated humanoid.

    Attributes:
        timestep_s: Physics step, s. 5 ms with ``implicitfast`` is the measured stable setting.
        integrator: MuJoCo integrator; ``implicitfast`` integrates actuator ``kv`` implicitly.
        armature: Rotor inertia added to every hinge, kg m^2. Light segments (hands, toes)
            under stiff PD blow up at 5 ms without it; 0.1-0.3 was measured stable.
        joint_damping: Passive damping of every hinge, N m s/rad (on top of actuator ``kv``).
        friction: Sliding friction coefficient of the floor, feet and all body geoms.
        contact_solref: ``(timeconst_s, dampratio)`` of floor, feet and sole pads. The time
            constant must be at least twice ``timestep_s``.
        contact_solimp: ``(dmin, dmax, width_m)`` impedance of those contacts.
        insole_sensors: Add a ``touch`` sensor per insole cell site (``touch_<L|R>_<k>``).
        foot_force_sensors: Add a net contact-force sensor per foot (``grf_L``, ``grf_R``:
            the contacts of the ankle's subtree with the world body, i.e. the
            floor, terrain and props; force, torque and point in the world frame), from which
            :class:`grip.sim.model.FootContacts` reads the ground reaction force and centre of
            pressure in C instead of a Python loop over the contacts.
        imu_sensors: Add ``framequat``, ``gyro`` and ``accelerometer`` sensors per IMU site
            (``imu_<part>_quat|_gyro|_acc``; the accelerometer measures specific force, i.e.
            includes gravity, in the site frame).
        floor: Add the ground plane at z = 0.
        actuator: ``"position"`` (``<position kp kv>``) or ``"general"`` (``<general>`` with an
            affine bias); both give ``tau = kp (ctrl - q) - kv qdot``.
        gain_scale: Factor applied to both ``kp`` and ``kd`` of the body model.
        self_collision: Limb geoms collide with each other (besides the floor).
        rest_clearance_m: Body pairs whose shapes come closer than this in the rest pose get a
            contact exclusion (only used with ``self_collision``), m.
        sole_pads: Add one floor-only collision sphere per insole cell (see module docstring).
        sole_pad_radius_m: Radius of the sole pads, m (capped at 45 % of the toe height).
        foot_box_clearance_m: Lift of the foot/toe boxes' bottom face above the sole plane when
            sole pads are on, m.
        insole_site_half_height_m: Half height of the insole cell site boxes, m; the touch
            zone reaches this far below and above the sole.
        texture_px: Width and height of the skybox and floor textures, px. Visual only: the
            physics is the same for every value. 512 suits videos; the simulation scenes of
            training and evaluation (:mod:`envs.scenes`) use :data:`SIM_TEXTURE_PX`, which
            makes a model 5.4 MB smaller and its compile about 17 ms (of 19) shorter.
    """

    timestep_s: float = 0.005
    integrator: str = "implicitfast"
    armature: float = 0.1
    joint_damping: float = 0.5
    friction: float = 1.0
    contact_solref: tuple[float, float] = (0.02, 1.0)
    contact_solimp: tuple[float, float, float] = (0.9, 0.95, 0.001)
    insole_sensors: bool = True
    foot_force_sensors: bool = True
    imu_sensors: bool = True
    floor: bool = True
    actuator: str = "position"
    gain_scale: float = 1.0
    self_collision: bool = True
    rest_clearance_m: float = 0.01
    sole_pads: bool = True
    sole_pad_radius_m: float = 0.01
    foot_box_clearance_m: float = 0.004
    insole_site_half_height_m: float = 0.005
    texture_px: int = 512

    def __post_init__(self) -> None:
        if isinstance(self.texture_px, bool) or not isinstance(self.texture_px, int) \
                or self.texture_px < 1:  # fmt: skip
            raise ValueError(f"MjcfConfig.texture_px={self.texture_px!r} must be an int >= 1")
        positive = {
            "timestep_s": self.timestep_s,
            "gain_scale": self.gain_scale,
            "sole_pad_radius_m": self.sole_pad_radius_m,
            "insole_site_half_height_m": self.insole_site_half_height_m,
        }
        for name, value in positive.items():
            if not np.isfinite(value) or value <= 0.0:
                raise ValueError(f"MjcfConfig.{name}={value!r} must be > 0")
        non_negative = {
            "armature": self.armature,
            "joint_damping": self.joint_damping,
            "friction": self.friction,
            "rest_clearance_m": self.rest_clearance_m,
            "foot_box_clearance_m": self.foot_box_clearance_m,
        }
        for name, value in non_negative.items():
            if not np.isfinite(value) or value < 0.0:
                raise ValueError(f"MjcfConfig.{name}={value!r} must be >= 0")
        if self.actuator not in ("position", "general"):
            raise ValueError(f"MjcfConfig.actuator={self.actuator!r}: use 'position' or 'general'")
        if self.integrator not in ("Euler", "RK4", "implicit", "implicitfast"):
            raise ValueError(
                f"MjcfConfig.integrator={self.integrator!r} is not a MuJoCo integrator"
            )
        if len(self.contact_solref) != 2 or len(self.contact_solimp) != 3:
            raise ValueError("MjcfConfig.contact_solref needs 2 values, contact_solimp 3")


# --------------------------------------------------------------------------- names
def hinge_names() -> list[str]:
    """The 69 hinge (and actuator) names in SMPL order: joint 1..23, then its hinges in
    composition order (:data:`grip.core.skeleton.HINGE_ORDERS`)."""
    return [f"{sk.JOINT_NAMES[j]}_{ax}" for j in range(1, sk.N_JOINTS) for ax in sk.HINGE_ORDERS[j]]


def imu_site_names() -> list[str]:
    """The 8 IMU site names ``imu_<part>`` in :data:`grip.core.skeleton.IMU_PARTS` order."""
    return [f"imu_{part}" for part in sk.IMU_PARTS]


def insole_site_names() -> list[list[str]]:
    """Insole cell site names ``insole_<L|R>_<k>``, nested ``[2][16]`` (left foot first)."""
    return [[f"insole_{s}_{k}" for k in range(sk.N_INSOLE_CELLS)] for s in FOOT_SIDES]


def foot_force_sensor_names() -> list[str]:
    """Net foot contact-force sensor names (``MjcfConfig.foot_force_sensors``), left first."""
    return [f"grf_{s}" for s in FOOT_SIDES]


def touch_sensor_names() -> list[list[str]]:
    """Touch sensor names ``touch_<L|R>_<k>``, nested ``[2][16]`` (left foot first)."""
    return [[f"touch_{s}_{k}" for k in range(sk.N_INSOLE_CELLS)] for s in FOOT_SIDES]


# --------------------------------------------------------------------------- poses
def as_body_model(body: BodyModel | BodyParams | None = None) -> BodyModel:
    """A :class:`BodyModel` from a model, subject parameters, or ``None`` (default subject)."""
    if isinstance(body, BodyModel):
        return body
    if body is None or isinstance(body, BodyParams):
        return build_body(body)
    raise TypeError(f"expected BodyModel, BodyParams or None, got {type(body).__name__}")


def standing_qpos(body: BodyModel | BodyParams | None = None) -> np.ndarray:
    """``qpos`` of the rest T-pose standing on the floor at the origin, facing world +y.

    Args:
        body: The body model (or its parameters; ``None`` for the default subject).

    Returns:
        ``(76,)``: root position (0, 0, pelvis height) m, root quaternion wxyz of
        :data:`CANONICAL_TO_WORLD`, then 69 zero hinge angles.
    """
    bm = as_body_model(body)
    qpos = np.zeros(7 + 3 * (sk.N_JOINTS - 1))
    qpos[2] = bm.pelvis_height
    qpos[3:7] = matrix_to_quat(CANONICAL_TO_WORLD)
    return qpos


# --------------------------------------------------------------------------- geometry helpers
def _segment_distance(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> float:
    """Shortest distance between segments ``p0-p1`` and ``q0-q1`` (points allowed), m."""
    d1, d2, r = p1 - p0, q1 - q0, p0 - q0
    a, e, f = float(d1 @ d1), float(d2 @ d2), float(d2 @ r)
    eps = 1e-15
    if a <= eps and e <= eps:
        return float(np.linalg.norm(r))
    if a <= eps:
        s, t = 0.0, float(np.clip(f / e, 0.0, 1.0))
    else:
        c = float(d1 @ r)
        if e <= eps:
            s, t = float(np.clip(-c / a, 0.0, 1.0)), 0.0
        else:
            b = float(d1 @ d2)
            denom = a * e - b * b
            s = float(np.clip((b * f - c * e) / denom, 0.0, 1.0)) if denom > eps else 0.0
            t = (b * s + f) / e
            if t < 0.0:
                s, t = float(np.clip(-c / a, 0.0, 1.0)), 0.0
            elif t > 1.0:
                s, t = float(np.clip((b - c) / a, 0.0, 1.0)), 1.0
    return float(np.linalg.norm((p0 + s * d1) - (q0 + t * d2)))


def _bounding_capsule(
    kind: str, pos: np.ndarray, size: np.ndarray, axis: np.ndarray
) -> tuple[np.ndarray, np.ndarray, float]:
    """``(a, b, radius)``: a capsule containing the shape, same frame as ``pos``."""
    if kind == "capsule":
        half = size[1] * axis
        return pos - half, pos + half, float(size[0])
    if kind == "sphere":
        return pos, pos, float(size[0])
    k = int(np.argmax(size))
    half = np.zeros(3)
    half[k] = size[k]
    others = np.delete(size, k)
    return pos - half, pos + half, float(np.linalg.norm(others))


def rest_overlap_pairs(body: BodyModel, clearance_m: float = 0.01) -> list[tuple[int, int]]:
    """Body pairs (not parent-child) whose collision shapes come closer than ``clearance_m``.

    Shapes are compared in the rest pose; boxes are replaced by a bounding capsule (so the
    test errs on the side of excluding). These pairs get ``<exclude>`` in the MJCF.

    Args:
        body: The body model.
        clearance_m: Minimum surface distance at rest, m.

    Returns:
        Sorted ``(i, j)`` SMPL joint indices with ``i < j``.
    """
    caps: list[tuple[int, np.ndarray, np.ndarray, float]] = []
    for g in body.geoms:
        a, b, r = _bounding_capsule(g.kind, g.pos, g.size, g.axis)
        base = body.rest_joint_pos[g.body]
        caps.append((g.body, a + base, b + base, r))
    pairs: set[tuple[int, int]] = set()
    for m, (bi, a0, a1, ra) in enumerate(caps):
        for bj, b0, b1, rb in caps[m + 1 :]:
            i, j = min(bi, bj), max(bi, bj)
            if i == j or sk.PARENTS[j] == i or (i, j) in pairs:
                continue
            if _segment_distance(a0, a1, b0, b1) - ra - rb < clearance_m:
                pairs.add((i, j))
    return sorted(pairs)


def insole_site_half_sizes(body: BodyModel) -> np.ndarray:
    """Half side of the square footprint of each insole cell site, ``(2, 16)``, m.

    About half the square root of the cell area, shrunk so that no two sites on the same body
    overlap (a touch sensor would then count a contact twice).
    """
    half = 0.5 * np.sqrt(body.insole_area_cm2 * 1e-4)
    for f in range(2):
        pos = body.insole_pos[f][:, [0, 2]]
        owner = body.insole_body[f]
        cheb = np.max(np.abs(pos[:, None, :] - pos[None, :, :]), axis=-1)
        cheb[owner[:, None] != owner[None, :]] = np.inf
        np.fill_diagonal(cheb, np.inf)
        half[f] = np.minimum(half[f], 0.49 * cheb.min(axis=1))
    return half


# --------------------------------------------------------------------------- XML writing
def _num(x: float) -> str:
    """Shortest text that round-trips the float exactly."""
    v = float(x)
    return "0" if v == 0.0 else repr(v)


def _vec(v: np.ndarray | tuple[float, ...] | list[float]) -> str:
    return " ".join(_num(x) for x in np.asarray(v, dtype=np.float64).reshape(-1))


def _sub(parent: ET.Element, tag: str, **attrib: str) -> ET.Element:
    return ET.SubElement(parent, tag, {k.rstrip("_"): v for k, v in attrib.items()})


def _add_assets_and_defaults(root: ET.Element, cfg: MjcfConfig) -> None:
    vis = _sub(root, "visual")
    _sub(vis, "global", offwidth="1280", offheight="720")
    _sub(vis, "headlight", ambient="0.35 0.35 0.35", diffuse="0.6 0.6 0.6")
    asset = _sub(root, "asset")
    px = str(cfg.texture_px)
    _sub(asset, "texture", name="skybox", type="skybox", builtin="gradient",
         rgb1="0.45 0.6 0.75", rgb2="0.05 0.08 0.12", width=px, height=px)  # fmt: skip
    _sub(asset, "texture", name="grid", type="2d", builtin="checker", rgb1="0.22 0.3 0.38",
         rgb2="0.14 0.2 0.26", width=px, height=px, mark="edge",
         markrgb="0.5 0.5 0.5")  # fmt: skip
    _sub(asset, "material", name="grid", texture="grid", texrepeat="1 1", texuniform="true",
         reflectance="0.1")  # fmt: skip

    body_aff = _BIT_FLOOR | (_BIT_BODY if cfg.self_collision else 0)
    fric = f"{_num(cfg.friction)} 0.005 0.0001"
    solref, solimp = _vec(cfg.contact_solref), _vec(cfg.contact_solimp)
    default = _sub(root, "default")
    _sub(default, "geom", contype=str(_BIT_BODY), conaffinity=str(body_aff), condim="3",
         friction=fric, rgba=_RGBA_BODY)  # fmt: skip
    _sub(default, "site", group="3")
    hinge = _sub(default, "default", class_="hinge")
    _sub(hinge, "joint", type="hinge", limited="true", armature=_num(cfg.armature),
         damping=_num(cfg.joint_damping))  # fmt: skip
    foot = _sub(default, "default", class_="foot")
    _sub(foot, "geom", solref=solref, solimp=solimp, rgba=_RGBA_FOOT)
    pad = _sub(default, "default", class_="sole_pad")
    _sub(pad, "geom", type="sphere", contype=str(_BIT_PAD), conaffinity=str(_BIT_FLOOR),
         solref=solref, solimp=solimp, rgba=_RGBA_PAD, group="1")  # fmt: skip
    imu = _sub(default, "default", class_="imu")
    _sub(imu, "site", type="box", size="0.012 0.006 0.018", rgba=_RGBA_IMU, group="2")
    insole = _sub(default, "default", class_="insole")
    _sub(insole, "site", type="box", rgba=_RGBA_INSOLE, group="2")


def _add_geoms(el: ET.Element, j: int, bm: BodyModel, cfg: MjcfConfig) -> None:
    name = sk.JOINT_NAMES[j]
    raise_boxes = cfg.sole_pads and j in _FOOT_BODIES and cfg.foot_box_clearance_m > 0.0
    for n, g in enumerate(gg for gg in bm.geoms if gg.body == j):
        gname = f"{name}_{g.kind}{n}"
        if g.kind == "capsule":
            _sub(el, "geom", name=gname, type="capsule", fromto=_vec(g.fromto()),
                 size=_num(g.size[0]))  # fmt: skip
        elif g.kind == "sphere":
            _sub(el, "geom", name=gname, type="sphere", pos=_vec(g.pos), size=_num(g.size[0]))
        elif g.kind == "box":
            pos, size = g.pos.astype(np.float64), g.size.astype(np.float64)
            if raise_boxes:
                lift = min(cfg.foot_box_clearance_m, size[1])  # keep a positive height
                size = size - np.array([0.0, 0.5 * lift, 0.0])
                pos = pos + np.array([0.0, 0.5 * lift, 0.0])
            attrs = {"class": "foot"} if j in _FOOT_BODIES else {}
            _sub(el, "geom", name=gname, type="box", pos=_vec(pos), size=_vec(size), **attrs)
        else:
            raise ValueError(f"body {name}: unknown geom kind {g.kind!r}")


def _add_sites_and_pads(
    els: list[ET.Element], bm: BodyModel, cfg: MjcfConfig, site_half: np.ndarray
) -> None:
    for part, site in zip(sk.IMU_PARTS, imu_site_names(), strict=True):
        j, pos = bm.imu_sites[part]
        _sub(els[j], "site", name=site, class_="imu", pos=_vec(pos))
    toe_h = float(bm.rest_joint_pos[list(sk.TOE_BODY.values()), 1].min())
    radius = min(cfg.sole_pad_radius_m, 0.45 * toe_h)
    up = np.array([0.0, 1.0, 0.0])  # sole normal in the foot/toe body frames
    names = insole_site_names()
    for f, side in enumerate(FOOT_SIDES):
        for k in range(sk.N_INSOLE_CELLS):
            j, pos = int(bm.insole_body[f, k]), bm.insole_pos[f, k]
            h = site_half[f, k]
            _sub(els[j], "site", name=names[f][k], class_="insole", pos=_vec(pos),
                 size=_vec([h, cfg.insole_site_half_height_m, h]))  # fmt: skip
            if cfg.sole_pads:
                _sub(els[j], "geom", name=f"sole_{side}_{k}", class_="sole_pad",
                     pos=_vec(pos + radius * up), size=_num(radius))  # fmt: skip


def build_mjcf(body: BodyModel | BodyParams | None = None, cfg: MjcfConfig | None = None) -> str:
    """MJCF text of the humanoid for one subject.

    Args:
        body: The body model, or subject parameters to build one from (``None``: default
            1.70 m / 70 kg subject).
        cfg: Simulation options; defaults to :class:`MjcfConfig()`.

    Returns:
        A complete ``<mujoco>`` document (nq = 76, nv = 75, nu = 69) as a string. Load it with
        :func:`grip.sim.model.load_model` or ``mujoco.MjModel.from_xml_string``.
    """
    bm = as_body_model(body)
    cfg = cfg or MjcfConfig()
    p = bm.params
    root = ET.Element("mujoco", model=f"grip_humanoid_{p.height_m:g}m_{p.mass_kg:g}kg")
    _sub(root, "compiler", angle="radian", inertiafromgeom="false", autolimits="true")
    _sub(root, "option", timestep=_num(cfg.timestep_s), integrator=cfg.integrator,
         gravity=f"0 0 {_num(-GRAVITY)}")  # fmt: skip
    _add_assets_and_defaults(root, cfg)

    world = _sub(root, "worldbody")
    _sub(world, "light", name="sun", type="directional", pos="0 0 4", dir="0.3 0.3 -1",
         castshadow="true")  # fmt: skip
    if cfg.floor:
        _sub(world, "geom", name="floor", type="plane", size="0 0 0.05", material="grid",
             contype=str(_BIT_FLOOR), conaffinity="0", condim="3",
             friction=f"{_num(cfg.friction)} 0.005 0.0001", solref=_vec(cfg.contact_solref),
             solimp=_vec(cfg.contact_solimp))  # fmt: skip

    q0 = standing_qpos(bm)
    els: list[ET.Element] = []
    for j, name in enumerate(sk.JOINT_NAMES):
        if j == 0:
            el = _sub(world, "body", name=name, pos=_vec(q0[:3]), quat=_vec(q0[3:7]))
            _sub(el, "freejoint", name=ROOT_JOINT)
            _sub(el, "light", name="track", mode="trackcom", pos="0 3 -2", dir="0 -1 0.5",
                 diffuse="0.4 0.4 0.4")  # fmt: skip
        else:
            el = _sub(els[sk.PARENTS[j]], "body", name=name, pos=_vec(bm.offsets[j]))
        i = bm.inertia_local[j]
        _sub(el, "inertial", pos=_vec(bm.com_local[j]), mass=_num(bm.masses[j]),
             fullinertia=_vec([i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]))  # fmt: skip
        if j > 0:
            for ax in sk.HINGE_ORDERS[j]:
                a = "xyz".index(ax)
                axis = np.eye(3)[a]
                _sub(el, "joint", name=f"{name}_{ax}", class_="hinge", axis=_vec(axis),
                     range=_vec(bm.hinge_range[j, a]))  # fmt: skip
        _add_geoms(el, j, bm, cfg)
        els.append(el)
    _add_sites_and_pads(els, bm, cfg, insole_site_half_sizes(bm))

    if cfg.self_collision:
        pairs = rest_overlap_pairs(bm, cfg.rest_clearance_m)
        if pairs:
            contact = _sub(root, "contact")
            for i, j in pairs:
                _sub(contact, "exclude", name=f"rest_{sk.JOINT_NAMES[i]}_{sk.JOINT_NAMES[j]}",
                     body1=sk.JOINT_NAMES[i], body2=sk.JOINT_NAMES[j])  # fmt: skip

    act = _sub(root, "actuator")
    for j in range(1, sk.N_JOINTS):
        kp, kv = bm.kp[j] * cfg.gain_scale, bm.kd[j] * cfg.gain_scale
        for ax in sk.HINGE_ORDERS[j]:
            a = "xyz".index(ax)
            jn = f"{sk.JOINT_NAMES[j]}_{ax}"
            rng = _vec(bm.hinge_range[j, a])
            if cfg.actuator == "position":
                _sub(act, "position", name=jn, joint=jn, kp=_num(kp), kv=_num(kv), ctrlrange=rng)
            else:
                _sub(act, "general", name=jn, joint=jn, ctrlrange=rng, gaintype="fixed",
                     gainprm=_num(kp), biastype="affine",
                     biasprm=f"0 {_num(-kp)} {_num(-kv)}")  # fmt: skip

    if cfg.insole_sensors or cfg.imu_sensors or cfg.foot_force_sensors:
        sensor = _sub(root, "sensor")
        if cfg.insole_sensors:
            for sites, touches in zip(insole_site_names(), touch_sensor_names(), strict=True):
                for site, touch in zip(sites, touches, strict=True):
                    _sub(sensor, "touch", name=touch, site=site)
        if cfg.foot_force_sensors:
            for side, name in zip(FOOT_SIDES, foot_force_sensor_names(), strict=True):
                _sub(sensor, "contact", name=name,
                     subtree1=sk.JOINT_NAMES[sk.FOOT_BODY[f"{side}_Foot"]],
                     body2="world", data="force torque pos", reduce="netforce",
                     num="1")  # fmt: skip
        if cfg.imu_sensors:
            for site in imu_site_names():
                _sub(sensor, "framequat", name=f"{site}_quat", objtype="site", objname=site)
                _sub(sensor, "gyro", name=f"{site}_gyro", site=site)
                _sub(sensor, "accelerometer", name=f"{site}_acc", site=site)

    keyframe = _sub(root, "keyframe")
    _sub(keyframe, "key", name=STAND_KEY, qpos=_vec(q0), ctrl=_vec(np.zeros(3 * (sk.N_JOINTS - 1))))

    ET.indent(root, space="  ")
    header = (
        "<!-- GRIP humanoid generated by grip.core.mjcf.build_mjcf from the project's body "
        f"model: height {p.height_m:g} m, mass {p.mass_kg:g} kg. Do not edit by hand. -->\n"
    )
    return header + ET.tostring(root, encoding="unicode") + "\n"
