"""``Reconstruction``: the one output type of GRIP and of every baseline (numpy only).

A reconstruction is a motion of the body model over ``T`` frames at ``fps``, in the world frame
(z up, metres, radians), plus the physical quantities a method produced (ground reaction forces,
centres of pressure, joint torques, contact states, a residual root wrench, fall events). Methods
that do not produce a quantity leave it ``None``; metrics that need it are then reported as
NaN, never guessed.

File format (``.npz``, written atomically, read with ``allow_pickle=False``): one array per
attribute below under the same key, absent for ``None`` attributes, plus ``__meta__`` (JSON:
format, version, name, method, fps, ms_per_frame, notes).

==================  ===============  ==========================================================
key                 shape            meaning
==================  ===============  ==========================================================
joint_pos           (T, 24, 3)       world joint positions (SMPL order), m
global_rot          (T, 24, 3, 3)    world joint rotations
grf                 (T, 2, 3)        ground reaction force on the left, right foot (world), N
cop                 (T, 2, 3)        centre of pressure of each foot (world), m; NaN off ground
torques             (T, 69)          joint torques, N m, :func:`grip.core.mjcf.hinge_names` order
contacts            (T, 2)           left, right foot in contact (bool)
residual            (T, 6)           residual root force (N, world) and torque (N m, root frame)
ref_root_pos        (T, 3)           the pelvis the method followed (GRIP: the kinematic
                                     estimate's, integrated from its velocity, where the episode
                                     started it; not moved by fall recoveries), world, m
falls               (K, 2)           per fall event: [first replaced frame, detection frame]
==================  ===============  ==========================================================
"""

from __future__ import annotations

import dataclasses
import io
import json
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from grip.core import skeleton as sk
from grip.core.atomic import atomic_write
from grip.core.limits import InputLimits, LimitExceeded, active_limits, load_checked_npz
from grip.core.metrics import global_to_local_rot
from grip.core.text import clean_strings

FORMAT = "grip-reconstruction"
VERSION = 1
N_HINGES = 3 * (sk.N_JOINTS - 1)

# key -> trailing shape (after T); -1 = any size
_ARRAYS: dict[str, tuple[int, ...]] = {
    "joint_pos": (sk.N_JOINTS, 3),
    "global_rot": (sk.N_JOINTS, 3, 3),
    "grf": (2, 3),
    "cop": (2, 3),
    "torques": (N_HINGES,),
    "contacts": (2,),
    "residual": (6,),
    "ref_root_pos": (3,),
}
_OPTIONAL = ("grf", "cop", "torques", "contacts", "residual", "ref_root_pos")


class ReconstructionError(ValueError):
    """A reconstruction (or its file) is malformed; the message names the file and the key."""


class PoseTrack:
    """What a motion with ``joint_pos (T, 24, 3)`` and ``global_rot (T, 24, 3, 3)`` (world
    frame) derives: shared by :class:`Reconstruction` and the ground truth
    (:class:`grip.kinematics.features.GroundTruth`)."""

    joint_pos: np.ndarray
    global_rot: np.ndarray

    @property
    def n_frames(self) -> int:
        return int(self.joint_pos.shape[0])

    @property
    def root_pos(self) -> np.ndarray:
        """``(T, 3)`` pelvis trajectory, world, m."""
        return self.joint_pos[:, 0]

    @property
    def local_rot(self) -> np.ndarray:
        """``(T, 24, 3, 3)`` rotations relative to the parent (row 0 = root world rotation)."""
        return global_to_local_rot(self.global_rot)


@dataclass(eq=False)
class Reconstruction(PoseTrack):
    """Reconstructed motion of one recording (see the module docstring for every array).

    Attributes:
        name: Recording (or segment) name.
        method: ``"grip"``, ``"pip"``, ``"transpose"``, ``"kinematics"``, ...
        fps: Frame rate, Hz.
        joint_pos, global_rot: The motion (required).
        grf, cop, torques, contacts, residual: Physical quantities, ``None`` if the method has
            none.
        ref_root_pos: ``(T, 3)`` the pelvis a tracking method followed (world, m; the pace
            metrics of :mod:`grip.core.metrics.pace`), ``None`` for the others.
        falls: ``(K, 2)`` int fall events ``[first replaced frame, detection frame]``.
        ms_per_frame: Wall time the method spent per frame (0 if not measured).
        notes: Free-form facts about the run (solver failures, repaired frames, ...).
    """

    name: str
    method: str
    fps: float
    joint_pos: np.ndarray
    global_rot: np.ndarray
    grf: np.ndarray | None = None
    cop: np.ndarray | None = None
    torques: np.ndarray | None = None
    contacts: np.ndarray | None = None
    residual: np.ndarray | None = None
    ref_root_pos: np.ndarray | None = None
    falls: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), dtype=np.int64))
    ms_per_frame: float = 0.0
    notes: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        where = f"reconstruction {self.name!r} ({self.method})"
        if not self.fps > 0:
            raise ReconstructionError(f"{where}: fps must be positive, got {self.fps}")
        if self.joint_pos is None:
            raise ReconstructionError(f"{where}: no joint positions ('joint_pos')")
        t = np.shape(self.joint_pos)[0] if np.ndim(self.joint_pos) else 0
        if t < 1:
            raise ReconstructionError(f"{where}: no frames")
        for key, tail in _ARRAYS.items():
            a = getattr(self, key)
            if a is None:
                if key not in _OPTIONAL:
                    raise ReconstructionError(f"{where}: {key} is required")
                continue
            a = np.asarray(a, dtype=bool if key == "contacts" else np.float64)
            if a.shape != (t, *tail):
                raise ReconstructionError(f"{where}: {key} has shape {a.shape}, expected "
                                          f"{(t, *tail)}")  # fmt: skip
            if key in ("joint_pos", "global_rot") and not np.isfinite(a).all():
                bad = int(np.argwhere(~np.isfinite(a.reshape(t, -1)).all(axis=1))[0, 0])
                raise ReconstructionError(f"{where}: {key} has non-finite values (frame {bad})")
            setattr(self, key, a)
        f = np.asarray(self.falls, dtype=np.int64).reshape(-1, 2)
        if f.size and (f.min() < 0 or f.max() >= t or (f[:, 0] > f[:, 1]).any()):
            raise ReconstructionError(f"{where}: fall events {f.tolist()} outside 0..{t - 1}")
        self.falls = f


    @property
    def fell(self) -> bool:
        """Whether any fall was detected (GRIP's success criterion)."""
        return bool(self.falls.shape[0])

    def slice_frames(self, start: int, stop: int) -> Reconstruction:
        """Frames ``start:stop`` (fall events outside are dropped, inside shifted)."""
        kw = {k: (None if getattr(self, k) is None else getattr(self, k)[start:stop])
              for k in _ARRAYS}  # fmt: skip
        f = self.falls[(self.falls[:, 1] >= start) & (self.falls[:, 1] < stop)] - start
        return dataclasses.replace(self, **kw, falls=np.maximum(f, 0))

    # ------------------------------------------------------------------ files
    def save(self, path: str | os.PathLike) -> None:
        """Write the ``.npz`` file (atomic: a crash never leaves a half-written file)."""
        meta = {"format": FORMAT, "version": VERSION, "name": self.name, "method": self.method,
                "fps": float(self.fps), "ms_per_frame": float(self.ms_per_frame),
                "notes": self.notes}  # fmt: skip
        arrays = {k: getattr(self, k) for k in _ARRAYS if getattr(self, k) is not None}
        arrays["falls"] = self.falls
        arrays["__meta__"] = np.array(json.dumps(meta))

        def write(f) -> None:
            buf = io.BytesIO()
            np.savez_compressed(buf, **arrays)
            f.write(buf.getvalue())

        atomic_write(path, write)

    @classmethod
    def load(cls, path: str | os.PathLike, *, limits: InputLimits | None = None
             ) -> Reconstruction:  # fmt: skip
        """Read a file written by :meth:`save`; any problem raises
        :class:`ReconstructionError` naming the file.

        Member sizes are checked from the npy headers before any array is loaded, the JSON
        metadata's depth and integer digits before it is parsed, the frame rate and duration
        before the reconstruction is built (``limits``, default
        :func:`grip.core.limits.active_limits`). The name, method and notes are cleaned
        (:func:`grip.core.text.clean_strings`: a code point UTF-8 cannot encode is U+FFFD), so
        every writer downstream can print or store them."""
        path = Path(path)
        limits = limits or active_limits()
        data, meta = load_checked_npz(path, limits, ReconstructionError)
        if (not isinstance(meta, dict) or meta.get("format") != FORMAT
                or meta.get("version") != VERSION):  # fmt: skip
            raise ReconstructionError(f"{path}: not a {FORMAT} file of version {VERSION}")
        try:
            meta = clean_strings(meta)
        except ValueError as e:
            raise ReconstructionError(f"{path}: '__meta__': {e}") from None
        try:
            fps = float(meta["fps"])
            n = int(np.shape(data.get("joint_pos"))[0]) if np.ndim(data.get("joint_pos")) else 0
            limits.check_take(n, fps)
        except LimitExceeded as e:
            raise ReconstructionError(f"{path}: {e}") from None
        except (KeyError, TypeError, ValueError) as e:
            raise ReconstructionError(f"{path}: bad or missing fps in '__meta__' ({e})") from None
        try:
            return cls(name=str(meta["name"]), method=str(meta["method"]),
                       fps=float(meta["fps"]), ms_per_frame=float(meta.get("ms_per_frame", 0)),
                       notes=dict(meta.get("notes") or {}),
                       falls=data.get("falls", np.zeros((0, 2), dtype=np.int64)),
                       **{k: data.get(k) for k in _ARRAYS})  # fmt: skip
        except KeyError as e:
            raise ReconstructionError(f"{path}: missing key {e}") from e
        except ReconstructionError as e:
            raise ReconstructionError(f"{path}: {e}") from e
        except Exception as e:  # a value no check foresaw (wrong dtype, notes not a dict, ...)
            raise ReconstructionError(f"{path}: malformed reconstruction "
                                      f"({type(e).__name__}: {str(e)[:300]})") from None
