"""KinematicsNet inference: offline (whole sequences, batched) and streaming (one frame).

Checkpoints load through :mod:`grip.nn.weights`, their settings through
:mod:`grip.kinematics.config` and the test-time symmetries come from :mod:`grip.nn.symmetry`;
inference never imports the trainer (:mod:`grip.kinematics.train`).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np
import torch

from grip.core.body import build_body
from grip.core.fk import integrate_root, joints_from_global
from grip.core.limits import active_limits, safe_json_loads
from grip.core.rotations import sixd_to_matrix
from grip.kinematics.config import run_config_from_dict
from grip.kinematics.dataset import TARGET_KEYS, Normalizer
from grip.kinematics.features import (
    TTA_MODES,
    first_state,
    input_features,
    recording_body,
    recording_calibration,
)
from grip.kinematics.model import STAGE_DIMS, STAGES, FrameStep, KinematicsNet, State
from grip.nn.symmetry import (
    mirror_features,
    mirror_site_order,
    mirror_targets,
    rotate_features,
    rotate_targets,
    yaw_matrices,
)
from grip.nn.weights import check_declared_network, load_checkpoint, unpack_weights

_OUT_SLICES: tuple[tuple[str, int, int], ...] = tuple(
    (k, sum(STAGE_DIMS[s] for s in STAGES[:i]), sum(STAGE_DIMS[s] for s in STAGES[: i + 1]))
    for i, k in enumerate(STAGES)
)
"""Each stage's columns in :class:`FrameStep`'s output row."""


@dataclass
class KinematicEstimate:
    """KinematicsNet output for one recording (world axes, m, rad).

    Attributes:
        leaf_pos: ``(T, 5, 3)`` root-relative leaf joints (the LP stage).
        joint_pos: ``(T, 24, 3)`` root-relative joints of the estimated pose: forward
            kinematics of ``global_rot`` on the subject's body, as TransPose and PIP evaluate
            their poses (posed SMPL with the true shape); closer to the truth than the FP
            stage's own joints (``grip kin eval --joints fp`` measures those).
        global_rot: ``(T, 24, 3, 3)`` global joint rotations (the FA stage).
        velocity: ``(T, 6, 3)`` world velocities of the leaves and the pelvis, m/s (LV).
        root_pos: ``(T, 3)`` pelvis trajectory integrated from the estimated pelvis velocity,
            starting at the calibration pose's root (the first frame's ground truth, when the
            recording has it).
        fp_joint_pos: ``(T, 24, 3)`` root-relative joints as the FP stage estimates them (an
            intermediate the later stages read; not constrained to the body's bone lengths).
    """

    leaf_pos: np.ndarray
    joint_pos: np.ndarray
    global_rot: np.ndarray
    velocity: np.ndarray
    root_pos: np.ndarray
    fp_joint_pos: np.ndarray


def decode_outputs(o: dict[str, np.ndarray], n: int, offsets: np.ndarray) -> tuple[np.ndarray, ...]:
    """KinematicsNet outputs of ``n`` frames (``(n, dim)`` or flat, float64) on a body with
    rest ``offsets (24, 3)`` -> root-relative joints ``(n, 24, 3)`` (forward kinematics of the
    rotations), global rotations ``(n, 24, 3, 3)`` and the velocities of the velocity joints
    ``(n, 6, 3)``: what offline and streaming inference hand on."""
    rot = sixd_to_matrix(o["fa"].reshape(n, 24, 6))
    return joints_from_global(rot, offsets), rot, o["lv"].reshape(n, 6, 3)


class Symmetries:
    """Test-time augmentation by the symmetries of the problem.

    Gravity fixes only the vertical, and the body is mirror-symmetric, so a motion turned about
    the vertical or reflected left-right is as plausible as the original, and the sensors it
    would produce follow from the originals exactly (:func:`rotate_features`,
    :func:`mirror_features`). The network is trained on such copies but is not exactly
    equivariant; running every copy and mapping each estimate back to the original world
    (:func:`rotate_targets` with the inverse turn, then :func:`mirror_targets`) averages part of
    its error out. The copies run as one batch, so streaming keeps one LSTM call per frame.

    Args:
        mode: A key of :data:`TTA_MODES`.
        sites: The estimator's IMU sites (a mirror needs each left site's right partner).
        insoles: Whether the features hold the insole values.

    Raises:
        ValueError: Unknown ``mode``, or a mirror mode for a sensor set without a mirror image.
    """

    def __init__(self, mode: str, sites: tuple[str, ...], insoles: bool) -> None:
        if mode not in TTA_MODES:
            raise ValueError(
                f"unknown test-time augmentation {mode!r}; choose one of {list(TTA_MODES)}"
            )
        n_yaw, mirror = TTA_MODES[mode]
        if mirror:
            try:
                mirror_site_order(tuple(sites))
            except ValueError as e:
                raise ValueError(
                    f"test-time augmentation {mode!r} needs a mirror image: {e}"
                ) from e
        self.mode, self.sites, self.insoles = mode, tuple(sites), insoles
        self.copies = [(m, 2.0 * np.pi * k / n_yaw) for m in ((False, True) if mirror else (False,))
                       for k in range(n_yaw)]  # fmt: skip

    @property
    def n(self) -> int:
        return len(self.copies)

    def _turn(self, yaw: float, b: int, inverse: bool = False) -> torch.Tensor:
        return yaw_matrices(torch.full((b,), -yaw if inverse else yaw))

    def features(self, x: torch.Tensor) -> torch.Tensor:
        """Raw features ``(B, T, F)`` -> the copies' ``(n B, T, F)`` (copy-major)."""
        if self.n == 1:
            return x
        out = []
        for mirror, yaw in self.copies:
            xc = mirror_features(x, self.sites, self.insoles) if mirror else x
            out.append(rotate_features(xc, self._turn(yaw, len(x)), len(self.sites)) if yaw else xc)
        return torch.cat(out)

    def first(self, first: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """First-frame states ``{stage: (B, dim)}`` -> the copies' ``(n B, dim)``."""
        y = {k: v[:, None] for k, v in first.items()}
        b = len(next(iter(first.values())))
        out = []
        for mirror, yaw in self.copies:
            yc = mirror_targets(y) if mirror else y
            out.append(rotate_targets(yc, self._turn(yaw, b)) if yaw else yc)
        return {k: torch.cat([o[k] for o in out])[:, 0] for k in y}

    def reduce(self, out: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The copies' outputs ``{stage: (n B, T, dim)}`` mapped back and averaged -> ``(B, T,
        dim)`` (6D rotations are averaged as vectors and orthonormalised when decoded)."""
        if self.n == 1:
            return out
        b = next(iter(out.values())).shape[0] // self.n
        acc: dict[str, torch.Tensor] = {}
        for i, (mirror, yaw) in enumerate(self.copies):
            y = {k: v[i * b : (i + 1) * b] for k, v in out.items()}
            if yaw:
                y = rotate_targets(y, self._turn(yaw, b, inverse=True))
            if mirror:
                y = mirror_targets(y)
            acc = y if not acc else {k: acc[k] + y[k] for k in acc}
        return {k: v / self.n for k, v in acc.items()}


class KinematicsEstimator:
    """A trained KinematicsNet with its normaliser and feature settings.

    ``tta`` (a key of :data:`TTA_MODES`, default ``"none"``) averages the estimate over turned
    and mirrored copies of the input (:class:`Symmetries`), offline and streaming alike: more
    accurate, at ``n`` times the computation.
    """

    def __init__(self, model: KinematicsNet, norm: Normalizer, cfg, tta: str = "none") -> None:
        self.model = model.eval()
        self.norm = norm
        self.cfg = cfg
        self.tta = Symmetries(tta, tuple(cfg.features.sites), cfg.features.insoles)
        self._mean = torch.from_numpy(norm.mean)
        self._std = torch.from_numpy(norm.std)
        self._frame_step: FrameStep | None = None

    @classmethod
    def from_checkpoint(cls, path: str | os.PathLike, tta: str = "none") -> KinematicsEstimator:
        ck = load_checkpoint(path)
        try:
            cfg = run_config_from_dict(safe_json_loads(ck["config"], active_limits()))
        except (TypeError, ValueError, KeyError, AttributeError) as e:
            raise ValueError(f"{path}: not a KinematicsNet checkpoint: its config is not "
                             f"readable ({str(e)[:200]})") from e  # fmt: skip
        net = cfg.net_config()
        check_declared_network(lambda: KinematicsNet(net), ck["model"], str(path),
                               f"its config (n_inputs={net.n_inputs}, hidden={net.hidden}, "
                               f"layers={net.layers}, init_hidden={net.init_hidden})",
                               {"layers": net.layers})  # fmt: skip
        model = KinematicsNet(net)
        model.load_state_dict(unpack_weights(ck["model"]))
        norm = Normalizer(ck["norm_mean"].float().numpy(), ck["norm_std"].float().numpy())
        return cls(model, norm, cfg, tta)

    def normalise(self, x: torch.Tensor) -> torch.Tensor:
        """Raw features -> the network's normalised inputs."""
        return (x - self._mean) / self._std

    # ------------------------------------------------------------------ offline
    def _first(self, recs, init: str = "truth") -> dict[str, torch.Tensor]:
        """First-frame states of the recordings' calibration poses (:func:`first_state` of
        :func:`recording_calibration`: the ground truth of frame 0, or without it or with
        ``init="standing"`` the standing pose at the sensors' heading)."""
        cfg = self.cfg.features
        firsts = [first_state(recording_calibration(r, cfg, init), recording_body(r), r.fps)
                  for r in recs]  # fmt: skip
        return {k: torch.from_numpy(np.stack([f[k] for f in firsts])) for k in TARGET_KEYS}

    def predict(self, recs, init: str = "truth") -> list[KinematicEstimate]:
        """Estimates for a list of recordings, run as one padded batch per call.

        The calibration pose (the first frame's ground truth, or without it or with
        ``init="standing"`` the standing pose: :func:`recording_calibration`) initialises the
        LSTMs and the integrated root; the initial velocities are the calibration's (the truth's
        first-frame velocities, as a training window starts; zero when standing).
        """
        feats = [input_features(r, self.cfg.features) for r in recs]
        t_max = max(len(f) for f in feats)
        x = np.zeros((len(feats), t_max, feats[0].shape[1]), dtype=np.float32)
        for i, f in enumerate(feats):
            x[i, : len(f)] = f
            x[i, len(f) :] = f[-1]  # causal model: padding never affects earlier frames
        out = self.run_features(torch.from_numpy(x), self._first(recs, init))
        res = []
        for i, rec in enumerate(recs):
            n = rec.n_frames
            o = {k: v[i, :n].numpy().astype(np.float64) for k, v in out.items()}
            res.append(self._estimate(o, rec, n, init))
        return res

    def run_features(
        self, x: torch.Tensor, first: dict[str, torch.Tensor]
    ) -> dict[str, torch.Tensor]:
        """The network on raw features ``(B, T, F)`` from first-frame states ``{stage: (B,
        dim)}`` -> outputs ``{stage: (B, T, dim)}``, averaged over the test-time copies."""
        with torch.no_grad():
            xs = self.normalise(self.tta.features(x))
            out, _ = self.model(xs, self.model.initial_state(self.tta.first(first)))
            return self.tta.reduce(out)

    def _estimate(self, o: dict[str, np.ndarray], rec, n: int, init: str) -> KinematicEstimate:
        joint_pos, global_rot, vel = decode_outputs(o, n, build_body(recording_body(rec)).offsets)
        root0 = recording_calibration(rec, self.cfg.features, init).root_pos[0]
        return KinematicEstimate(
            leaf_pos=o["lp"].reshape(n, 5, 3),
            joint_pos=joint_pos,
            global_rot=global_rot,
            velocity=vel,
            root_pos=integrate_root(root0, vel[:, -1], rec.fps),
            fp_joint_pos=o["fp"].reshape(n, 24, 3),
        )

    # ------------------------------------------------------------------ streaming
    def frame_step(self) -> FrameStep:
        """The network's one-frame step (built once, shared by every stream)."""
        if self._frame_step is None:
            self._frame_step = FrameStep(self.model)
        return self._frame_step

    def stream(self, rec_first_frame, init: str = "truth"):
        """A :class:`StreamingEstimator` initialised from a recording's first frame (its ground
        truth, or the standing pose: ``init`` as :meth:`predict`)."""
        return StreamingEstimator(self, self._first([rec_first_frame], init))

    def stream_from(self, first: dict[str, np.ndarray]) -> StreamingEstimator:
        """A :class:`StreamingEstimator` from first-frame states ``{stage: (dim,)}``
        (:func:`grip.kinematics.features.first_state`: no recording needed)."""
        return StreamingEstimator(self, {k: torch.from_numpy(v[None]) for k, v in first.items()})


class StreamingEstimator:
    """One frame in, one frame out, LSTM state carried between calls.

    Feed it normalised-ready raw feature rows (``input_features`` of one frame). Each frame
    runs :class:`grip.kinematics.model.FrameStep` (every LSTM layer's cell called directly,
    no module dispatch) in inference mode; the test-time copies, if any, are one batch.
    """

    def __init__(self, est: KinematicsEstimator, first: dict[str, torch.Tensor]) -> None:
        self.est = est
        self._step = est.frame_step()
        with torch.inference_mode():
            self._flat = self._step.flat_state(est.model.initial_state(est.tta.first(first)))
        self._n_copies = est.tta.n

    @property
    def state(self) -> State:
        """The LSTM states, per stage ``(h, c)`` of ``(layers, copies, hidden)``."""
        return self._step.state(self._flat)

    def step(self, feature_row: np.ndarray) -> dict[str, np.ndarray]:
        """``(F,)`` raw features of one frame -> ``{stage: (dim,)}``."""
        est = self.est
        x = torch.from_numpy(np.asarray(feature_row, dtype=np.float32)).view(1, -1)
        with torch.inference_mode():
            if self._n_copies == 1:
                out = self._step(est.normalise(x), self._flat)
                row = out[0].numpy()
                return {k: row[a:b] for k, a, b in _OUT_SLICES}
            x = est.normalise(est.tta.features(x[None]))[:, 0]
            out = self._step(x, self._flat)
            res = est.tta.reduce({k: out[:, None, a:b] for k, a, b in _OUT_SLICES})
            return {k: v[0, 0].numpy() for k, v in res.items()}
