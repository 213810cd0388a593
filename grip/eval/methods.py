"""The methods ``grip bench`` compares, behind one protocol and one registry.

A method turns one segment recording into a :class:`~grip.core.reconstruction.Reconstruction`.
The segment's first frame is the ground-truth initialisation (the GRIP protocol: every method
starts from the true pose and position at the first frame); a method reads nothing else of the
ground truth (``smpl_params``, ``imu_gt``) after frame 0. With ``MethodOptions.init ==
"standing"`` every method starts from the standing calibration instead
(:func:`grip.kinematics.features.standing_calibration`: the rest pose at the foot IMUs' heading,
at rest, where a user without motion capture starts): KinematicsNet's LSTMs and root, GRIP's
humanoid, TransPose's root, PIP's learned initialisation and the PIP physics' first state read
no ground-truth pose (only its frame-0 horizontal pelvis position, the gauge that gives the
trajectories a common origin).

Adding a method is one factory function ``factory(options) -> Method`` and one line in
:data:`METHODS` (and, when it reads a model file by default, one in :data:`MODEL_OPTIONS`, so
that a resumed benchmark notices that file changing). Factories load their models (the
expensive part) once; ``grip bench`` calls a factory once per worker process and then
``reconstruct`` once per segment.
"""

from __future__ import annotations

import dataclasses
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol, runtime_checkable

from grip.core.reconstruction import Reconstruction

__all__ = [
    "METHODS",
    "Grip",
    "KinematicsOnly",
    "KinematicsPip",
    "Method",
    "MethodFactory",
    "MethodOptions",
    "Pip",
    "TransPose",
    "UnknownMethodError",
    "kinematics_method",
    "make_method",
    "model_files",
    "parse_method_names",
    "sensor_set",
    "sweep_checkpoint",
]


@runtime_checkable
class Method(Protocol):
    """What ``grip bench`` runs.

    Attributes:
        name: Registry name (``"kinematics"``, ``"pip"``, ...), also ``Reconstruction.method``.
        supports_sensors: The method can run another sensor configuration (``--sensors``).
        can_fall: The method can fail by falling (GRIP's success rate); ``False`` makes the
            success rate "n/a" (optimisation and kinematic baselines).
    """

    name: str
    supports_sensors: bool
    can_fall: bool

    def reconstruct(self, rec) -> Reconstruction:
        """The reconstruction of one segment (a ``prism_tools`` ``Recording``), with as many
        frames as the recording, at its frame rate."""
        ...


@dataclass(frozen=True)
class MethodOptions:
    """Settings handed to every factory (each reads the fields it needs).

    Attributes:
        kin_checkpoint: KinematicsNet checkpoint; ``None``: the shipped one.
        sensors: Sensor configuration of a sweep (``"imu4_press"``, see
            :mod:`grip.kinematics.sweep`), ``None`` for the method's default sensors.
        sweep_dir: Folder of ``grip kin train --sweep`` holding ``<sensors>/best.pt``.
        policy_checkpoint: GRIP policy export; ``None``: the shipped one.
        transpose_checkpoint, pip_checkpoint: Baseline networks (``grip kin train --baseline``);
            ``None``: the shipped ones (:data:`SHIPPED_BASELINES`).
        init: Where every method starts (:data:`grip.kinematics.features.INITS`): the ground
            truth of the segment's first frame (``"truth"``, the GRIP protocol) or the standing
            calibration (``"standing"``, no ground-truth pose read).
        restart: Where GRIP's humanoid restarts after a fall
            (:attr:`grip.player.RecoveryConfig.restart`).
        lost_gap_m: The pelvis gap at which GRIP's humanoid is lost and recovered like a fall
            (:attr:`grip.player.RecoveryConfig.lost_gap_m`; 0: off).
        pace_gain, pace_lead_max_m, lean_gain_deg, lean_max_deg: GRIP's pace and lean keepers
            (:class:`grip.player.PaceKeeper`).

    Raises:
        ValueError: ``init`` is not one of :data:`grip.kinematics.features.INITS`.
    """

    kin_checkpoint: Path | None = None
    sensors: str | None = None
    sweep_dir: Path | None = None
    policy_checkpoint: Path | None = None
    transpose_checkpoint: Path | None = None
    pip_checkpoint: Path | None = None
    init: str = "truth"
    restart: str = "estimate"
    lost_gap_m: float = 0.5  # (RecoveryConfig's: tests/eval/test_recovery_restart.py)
    pace_gain: float = 1.0  # (grip.player.PaceKeeper's defaults: tests/eval/test_pace_keeper.py)
    pace_lead_max_m: float = 0.5
    lean_gain_deg: float = 20.0
    lean_max_deg: float = 5.0

    def __post_init__(self) -> None:
        from grip.kinematics.features import INITS

        if self.init not in INITS:
            raise ValueError(f"init must be one of {list(INITS)}, got {self.init!r}")
        from grip.player import RESTARTS

        if self.restart not in RESTARTS:
            raise ValueError(f"restart must be one of {list(RESTARTS)}, got {self.restart!r}")
        self.recovery()  # (refuses a bad lost gap)
        self.pace()  # (refuses a bad gain or lead)

    def recovery(self):
        """GRIP's :class:`grip.player.RecoveryConfig`."""
        from grip.player import RecoveryConfig

        return RecoveryConfig(restart=self.restart, lost_gap_m=self.lost_gap_m)

    def pace(self):
        """GRIP's :class:`grip.player.PaceKeeper`."""
        from grip.player import PaceKeeper

        return PaceKeeper(gain=self.pace_gain, lead_max_m=self.pace_lead_max_m,
                          lean_gain_deg=self.lean_gain_deg, lean_max_deg=self.lean_max_deg)

    def to_dict(self) -> dict[str, str | None]:
        """JSON-ready form (paths as absolute strings), used to detect changed settings."""
        out: dict[str, str | None] = {}
        for f in dataclasses.fields(self):
            v = getattr(self, f.name)
            out[f.name] = str(Path(v).resolve()) if isinstance(v, Path) else v
        return out


MethodFactory = Callable[[MethodOptions], Method]


class UnknownMethodError(ValueError):
    """A method name that is not in the registry; the message lists the known ones."""


# ------------------------------------------------------------------------- kinematics only
def _shipped_kin_checkpoint() -> Path:
    from grip.assets import SHIPPED_KIN

    return SHIPPED_KIN


def sensor_set(name: str):
    """The :class:`grip.kinematics.sweep.SensorSet` called ``name`` (``"imu4_press"``).

    Raises:
        ValueError: ``name`` is not a sweep configuration; the message lists the valid ones.
    """
    from grip.kinematics.sweep import IMU_ORDER, sensor_sets

    sets = {s.name: s for s in sensor_sets(tuple(range(1, len(IMU_ORDER) + 1)))}
    if name not in sets:
        raise ValueError(f"unknown sensor configuration {name!r}; expected one of "
                         f"{', '.join(sets)}")  # fmt: skip
    return sets[name]


def sweep_checkpoint(sweep_dir: Path | None, sensors: str) -> Path:
    """``sweep_dir/<sensors>/best.pt`` (else ``last.pt``) of a ``grip kin train --sweep`` folder.

    Raises:
        ValueError: No sweep folder given, unknown configuration, or no checkpoint there.
    """
    sensor_set(sensors)
    if sweep_dir is None:
        raise ValueError(f"sensors {sensors!r} need the sweep folder of 'grip kin train --sweep' "
                         "(--sweep DIR)")  # fmt: skip
    for ck in ("best.pt", "last.pt"):
        p = Path(sweep_dir) / sensors / ck
        if p.is_file():
            return p
    raise ValueError(f"{Path(sweep_dir) / sensors}: no best.pt or last.pt (train the sweep with "
                     f"'grip kin train --sweep --out {sweep_dir}')")  # fmt: skip


class KinematicsOnly:
    """KinematicsNet alone: its pose on the root integrated from its pelvis velocity.

    The PIP ablation row "kinematics only" (BASELINES_AND_METRICS 2.4): no physics, so it cannot
    fall and has no forces. The LSTMs start from the segment's first-frame ground truth and the
    root from the true first-frame pelvis position (``init="standing"``: both from the standing
    calibration). The estimated root-relative joints are
    re-centred on the estimated pelvis (whose root-relative estimate is not exactly zero), so the
    pelvis lies on the integrated trajectory. Runs offline: the whole segment in one batch (the
    network is causal, so streaming gives the same numbers).
    """

    name = "kinematics"
    supports_sensors = True
    can_fall = False

    def __init__(self, estimator, checkpoint: Path, init: str = "truth") -> None:
        self.estimator = estimator
        self.checkpoint = Path(checkpoint)
        self.init = init

    def reconstruct(self, rec) -> Reconstruction:
        t0 = time.perf_counter()
        est = self.estimator.predict([rec], self.init)[0]
        rel = est.joint_pos - est.joint_pos[:, :1]
        pos = rel + est.root_pos[:, None]
        ms = 1000.0 * (time.perf_counter() - t0) / rec.n_frames
        feats = self.estimator.cfg.features
        return Reconstruction(
            name=rec.name, method=self.name, fps=float(rec.fps), joint_pos=pos,
            global_rot=est.global_rot, ms_per_frame=ms,
            notes={"checkpoint": str(self.checkpoint), "sites": list(feats.sites),
                   "insoles": bool(feats.insoles), "mode": "offline"},
        )  # fmt: skip


def kinematics_method(options: MethodOptions) -> KinematicsOnly:
    """Factory of :class:`KinematicsOnly`.

    The checkpoint is ``options.kin_checkpoint`` (default: the shipped one); with
    ``options.sensors`` it is that configuration's run of the sweep folder, which must have been
    trained on exactly those sensors.

    Raises:
        ValueError: Missing or unreadable checkpoint, or one trained on other sensors.
    """
    from grip.kinematics.inference import KinematicsEstimator

    if options.sensors:
        ck = sweep_checkpoint(options.sweep_dir, options.sensors)
    else:
        ck = Path(options.kin_checkpoint or _shipped_kin_checkpoint())
    if not ck.is_file():
        raise ValueError(f"{ck}: no such KinematicsNet checkpoint")
    est = KinematicsEstimator.from_checkpoint(ck)
    if options.sensors:
        s = sensor_set(options.sensors)
        feats = est.cfg.features
        if tuple(feats.sites) != s.sites or bool(feats.insoles) != s.insoles:
            raise ValueError(f"{ck}: trained on {feats.sites} (insoles={feats.insoles}), not "
                             f"the {s.name} configuration its folder names")  # fmt: skip
    return KinematicsOnly(est, ck, options.init)


# ------------------------------------------------------------------------------- GRIP
class Grip:
    """GRIP: KinematicsNet, the policy in MuJoCo, fall recovery (:mod:`grip.eval.reconstruct`).

    Starts from the segment's first-frame ground truth (``init="standing"``: KinematicsNet and
    the humanoid from the standing calibration); the success rate counts the segments in which
    the fall detector never fired (each fall is recovered, the segment still counts as a
    failure, as in GRIP).
    """

    name = "grip"
    supports_sensors = False
    can_fall = True

    def __init__(self, reconstructor, init: str = "truth") -> None:
        self.reconstructor = reconstructor
        self.init = init

    def reconstruct(self, rec) -> Reconstruction:
        return self.reconstructor.reconstruct([rec], init=self.init)[0]

    def reconstruct_many(self, recs: list, threads: int = 0) -> list:
        """:meth:`reconstruct` of each recording, all played side by side (each recording's
        KinematicsNet pass alone, as :meth:`reconstruct` runs it); the exception a recording
        raises takes its place in the list.

        Args:
            recs: The segment recordings.
            threads: Threads stepping the humanoids (0: the usable cores).
        """
        return self.reconstructor.reconstruct(recs, batch=1, play_batch=max(len(recs), 1),
                                              threads=threads, errors=True,
                                              init=self.init)  # fmt: skip


def grip_method(options: MethodOptions) -> Grip:
    """Factory of :class:`Grip` (policy: ``options.policy_checkpoint`` or the shipped one)."""
    from grip.assets import SHIPPED_POLICY
    from grip.eval.reconstruct import GripReconstructor

    policy = Path(options.policy_checkpoint or SHIPPED_POLICY)
    kin = Path(options.kin_checkpoint or _shipped_kin_checkpoint())
    for what, p in (("policy", policy), ("KinematicsNet", kin)):
        if not p.is_file():
            raise ValueError(f"{p}: no such {what} checkpoint")
    return Grip(GripReconstructor.from_files(policy, kin, options.recovery(), options.pace()),
                options.init)  # fmt: skip


# ------------------------------------------------------------------ PIP physics on KinematicsNet
def _pip_physics(rec, global_rot, joint_vel, contact_prob, name: str, t0: float, cfg=None,
                 init: str = "truth"):  # fmt: skip
    """PIP's optimiser on a kinematic estimate of ``rec``, started from the true first-frame
    state (the GRIP protocol: the ground-truth pose and root at frame 0, the estimate after;
    ``init="standing"``: the standing calibration's pose and root at frame 0).

    Starting from the estimate's own first pose instead can leave a foot deep in the floor at
    the true root height, which makes every later QP infeasible (PIP-4's nets: 20 deg off at
    frame 0 on some segments, 498 of 500 QPs failed and the body drifted off)."""
    from grip.baselines.pip_physics import PipPhysics
    from grip.core.body import build_body
    from grip.core.fk import grounded_root
    from grip.core.metrics import global_to_local_rot
    from grip.kinematics.features import recording_body, recording_calibration, targets

    local = global_to_local_rot(global_rot)
    if init == "truth":
        first = targets(rec.slice_frames(0, 2))
        local[0] = global_to_local_rot(first.global_rot[:1])[0]
        root0 = first.root_pos[0]
    else:  # the estimate's own first pose, on the floor (no ground truth): a standing pose
        # that the reference leaves at once makes the PD error, and every QP, explode
        root0 = grounded_root(global_rot[0], recording_calibration(rec, init=init).root_pos[0],
                              build_body(recording_body(rec)))  # fmt: skip
    pip = PipPhysics(recording_body(rec), cfg)
    out = pip.reconstruct(local, joint_vel, contact_prob, root0, name=rec.name)
    out.method = name
    out.ms_per_frame = 1000.0 * (time.perf_counter() - t0) / rec.n_frames
    return out


class _OnPipPhysics:
    """A method that ends in PIP's physics optimiser (:func:`_pip_physics`) on an estimator's
    output: no other sensors, cannot fall."""

    supports_sensors = False
    can_fall = False

    def __init__(self, estimator, cfg=None, init: str = "truth") -> None:
        self.estimator = estimator
        self.cfg = cfg
        self.init = init


class KinematicsPip(_OnPipPhysics):
    """PIP's physics optimiser (:mod:`grip.baselines.pip_physics`) on KinematicsNet's estimate.

    The optimiser's inputs: local rotations from the FA estimate, joint velocities from the
    estimated joints on the integrated root (backward differences, PIP's definition), foot
    contact probabilities from the insoles (1 where the fore or rear cells report contact: the
    "insole contact" variant of BASELINES_AND_METRICS 2.4). Separates what physics adds from
    what PIP's own networks add (method ``pip``).
    """

    name = "kin+pip"

    def reconstruct(self, rec) -> Reconstruction:
        from grip.baselines.pip_dynamics import backward_velocity
        from grip.kinematics.baselines import insole_contact_prob

        t0 = time.perf_counter()
        try:
            prob = insole_contact_prob(rec)
        except KeyError as e:
            raise ValueError(f"{rec.name}: kin+pip needs both insoles ({e})") from e
        est = self.estimator.predict([rec], self.init)[0]
        pos = est.joint_pos - est.joint_pos[:, :1] + est.root_pos[:, None]
        vel = backward_velocity(pos, float(rec.fps))
        return _pip_physics(rec, est.global_rot, vel, prob, self.name, t0, self.cfg, self.init)


def kinematics_pip_method(options: MethodOptions) -> KinematicsPip:
    """Factory of :class:`KinematicsPip` (KinematicsNet checkpoint as for ``kinematics``)."""
    kin = kinematics_method(dataclasses.replace(options, sensors=None))
    return KinematicsPip(kin.estimator, init=options.init)


# ------------------------------------------------------------------- PIP and TransPose


def _baseline_estimator(name: str, path: Path | None):
    from grip.assets import SHIPPED_BASELINES
    from grip.kinematics.baselines import BaselineEstimator

    p = Path(path or SHIPPED_BASELINES[name])
    if not p.is_file():
        raise ValueError(f"{p}: no {name} checkpoint; train one with 'grip kin train --baseline "
                         f"{name} --data DIR --out RUN' and pass RUN/best.pt")  # fmt: skip
    return BaselineEstimator.from_checkpoint(p)


class TransPose:
    """TransPose-4 (BASELINES_AND_METRICS 2.2): the pose nets, then the root from the supporting
    foot fused with Trans-B2's velocity (:func:`grip.baselines.transpose_translation.
    root_translation`), from the true first-frame root (``init="standing"``: the standing
    calibration's). Offline (bidirectional) mode."""

    name = "transpose"
    supports_sensors = False
    can_fall = False

    def __init__(self, estimator, init: str = "truth") -> None:
        self.estimator = estimator
        self.init = init

    def reconstruct(self, rec) -> Reconstruction:
        from grip.baselines.transpose_translation import joint_floor_height, root_translation
        from grip.core.body import build_body
        from grip.core.fk import joints_from_global
        from grip.kinematics.features import recording_body, recording_calibration, targets

        t0 = time.perf_counter()
        est = self.estimator.predict([rec])[0]
        body = build_body(recording_body(rec))
        if self.init == "truth":
            root0 = targets(rec.slice_frames(0, 2)).root_pos[0]
        else:
            root0 = recording_calibration(rec, init=self.init).root_pos[0]
        root = root_translation(est.global_rot, est.contact_prob, est.root_vel, body.offsets,
                                root0, joint_floor_height(body))  # fmt: skip
        # the pose is the rotations, posed on the subject's body (as TransPose evaluates it)
        pos = joints_from_global(est.global_rot, body.offsets) + root[:, None]
        return Reconstruction(
            name=rec.name, method=self.name, fps=float(rec.fps), joint_pos=pos,
            global_rot=est.global_rot, ms_per_frame=1e3 * (time.perf_counter() - t0) / rec.n_frames,
        )  # fmt: skip


class Pip(_OnPipPhysics):
    """PIP-4 (BASELINES_AND_METRICS 2.3 and 1): PIP's networks (learned RNN initialisation from
    the first frame: its ground truth, or the standing calibration with ``init="standing"``)
    feed its physics optimiser, contacts from its contact net."""

    name = "pip"

    def reconstruct(self, rec) -> Reconstruction:
        t0 = time.perf_counter()
        est = self.estimator.predict([rec], init=self.init)[0]
        return _pip_physics(rec, est.global_rot, est.joint_vel, est.contact_prob, self.name, t0,
                            self.cfg, self.init)  # fmt: skip


def transpose_method(options: MethodOptions) -> TransPose:
    """Factory of :class:`TransPose`."""
    return TransPose(_baseline_estimator("transpose", options.transpose_checkpoint), options.init)


def pip_method(options: MethodOptions) -> Pip:
    """Factory of :class:`Pip`."""
    return Pip(_baseline_estimator("pip", options.pip_checkpoint), init=options.init)


# ------------------------------------------------------------------------------- registry
METHODS: dict[str, MethodFactory] = {
    "kinematics": kinematics_method,
    "kin+pip": kinematics_pip_method,
    "transpose": transpose_method,
    "pip": pip_method,
    "grip": grip_method,
}
"""Method name -> factory. The baselines (``pip``, ``transpose``) and ``grip`` register here."""

MODEL_OPTIONS: dict[str, tuple[str, ...]] = {
    "kinematics": ("kin_checkpoint",),
    "kin+pip": ("kin_checkpoint",),
    "transpose": ("transpose_checkpoint",),
    "pip": ("pip_checkpoint",),
    "grip": ("policy_checkpoint", "kin_checkpoint"),
}
"""Method name -> the :class:`MethodOptions` model fields it reads, the shipped file when unset."""


def model_files(name: str, options: MethodOptions) -> dict[str, Path]:
    """The model files whose contents the results of method ``name`` with ``options`` depend on.

    Every model file ``options`` names (all of them are part of a run's settings), the shipped
    file of each field in :data:`MODEL_OPTIONS` ``[name]`` left unset, and with
    ``options.sensors`` the sweep folder's checkpoint (``"sweep_checkpoint"``, where it exists)
    instead of the shipped KinematicsNet.

    Returns:
        ``{field: resolved path}``; the files need not exist.
    """
    from grip.assets import SHIPPED_BASELINES, SHIPPED_POLICY

    shipped = {"kin_checkpoint": _shipped_kin_checkpoint(), "policy_checkpoint": SHIPPED_POLICY,
               "transpose_checkpoint": SHIPPED_BASELINES["transpose"],
               "pip_checkpoint": SHIPPED_BASELINES["pip"]}  # fmt: skip
    files: dict[str, Path] = {}
    for key, default in shipped.items():
        given = getattr(options, key)
        if given is None and key == "kin_checkpoint" and options.sensors:
            continue  # (the sweep's checkpoint takes the shipped KinematicsNet's place)
        if given is not None or key in MODEL_OPTIONS.get(name, ()):
            files[key] = Path(given if given is not None else default).resolve()
    if options.sensors:
        try:
            ck = sweep_checkpoint(options.sweep_dir, options.sensors)
        except ValueError:  # (no checkpoint: the method cannot be built either)
            ck = None
        if ck is not None:
            files["sweep_checkpoint"] = ck.resolve()
    return files


def make_method(
    name: str, options: MethodOptions, registry: Mapping[str, MethodFactory] = METHODS
) -> Method:
    """Build a registered method.

    Raises:
        UnknownMethodError: ``name`` is not registered (the message lists the known names).
    """
    if name not in registry:
        raise UnknownMethodError(f"unknown method {name!r}; known methods: "
                                 f"{', '.join(sorted(registry)) or '(none)'}")  # fmt: skip
    method = registry[name](options)
    if not isinstance(method, Method):
        raise TypeError(f"factory of {name!r} returned {type(method).__name__}, which lacks "
                        "name/supports_sensors/can_fall/reconstruct")  # fmt: skip
    return method


def parse_method_names(text: str, registry: Mapping[str, MethodFactory] = METHODS) -> list[str]:
    """``"pip,kinematics"`` -> ``["pip", "kinematics"]``, each checked against the registry.

    Raises:
        UnknownMethodError: An unknown name (listing the known ones).
        ValueError: No name, or a name given twice.
    """
    names = [t.strip() for t in text.split(",") if t.strip()]
    if not names:
        raise ValueError("--methods: no method given")
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ValueError(f"--methods: {dup} given more than once")
    unknown = [n for n in names if n not in registry]
    if unknown:
        raise UnknownMethodError(f"unknown method(s) {unknown}; known methods: "
                                 f"{', '.join(sorted(registry)) or '(none)'}")  # fmt: skip
    return names
