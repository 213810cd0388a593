"""The ``Motion`` type: a clip on the project's body model, z-up world, metres."""

from __future__ import annotations

import json
import os
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from grip.core import skeleton as sk
from grip.core.atomic import atomic_write
from grip.core.body import BodyModel, BodyParams, build_body
from grip.core.fk import forward_kinematics
from grip.core.limits import InputLimits, LimitExceeded, active_limits, check_npz, safe_json_loads
from grip.core.rotations import quat_to_matrix, resample_linear, resample_quats

_FORMAT_VERSION = 1


REVERSED_SUFFIX = "-reversed"
"""Appended to the category of a time-reversed motion (:meth:`Motion.time_reversed`)."""

TIME_SCALE_RANGE = (0.5, 2.0)
"""The factors :meth:`Motion.time_scaled` accepts: beyond them a motion is no longer a plausible
faster or slower performance of itself."""


class MotionError(ValueError):
    """A motion file or array is malformed; the message names the file/key and the problem."""


@dataclass(frozen=True)
class Motion:
    """A motion on the body model.

    Attributes:
        fps: Frame rate, Hz (100 after retargeting).
        root_pos: ``(T, 3)`` pelvis joint position, world frame (z up, floor z = 0), m.
        local_quat: ``(T, 24, 4)`` joint rotations relative to the parent (w, x, y, z); row 0 is
            the pelvis' global rotation. Rest pose = SMPL-canonical T-pose (see grip.core.body).
        body: Subject parameters of the body model the motion lives on.
        name: Clip id, e.g. ``"cmu/02_01"``.
        category: Motion category, e.g. ``"walk"``.
        meta: Free-form JSON-serialisable provenance (source file, licence, retarget settings).
    """

    fps: float
    root_pos: np.ndarray
    local_quat: np.ndarray
    body: BodyParams = field(default_factory=BodyParams)
    name: str = "motion"
    category: str = "unknown"
    meta: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        check_motion_arrays(self.fps, self.root_pos, self.local_quat, where=self.name)

    @property
    def n_frames(self) -> int:
        return int(self.root_pos.shape[0])

    @property
    def duration_s(self) -> float:
        return self.n_frames / self.fps

    def local_rot(self) -> np.ndarray:
        """``(T, 24, 3, 3)`` local rotation matrices."""
        return quat_to_matrix(self.local_quat)

    def body_model(self) -> BodyModel:
        return build_body(self.body)

    def fk(self, body: BodyModel | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Global rotations ``(T, 24, 3, 3)`` and joint positions ``(T, 24, 3)``."""
        b = body or self.body_model()
        return forward_kinematics(self.local_rot(), self.root_pos, b.offsets)

    def slice(self, start: int, stop: int) -> Motion:
        """Frames ``[start, stop)`` as a new motion."""
        return replace(self, root_pos=self.root_pos[start:stop].copy(),
                       local_quat=self.local_quat[start:stop].copy())  # fmt: skip

    def time_reversed(self) -> Motion:
        """The motion played backwards, frames in reverse order (category ``"<category>-
        reversed"``, ``meta["time_reversed"]`` set; reversing again gives the original arrays
        back). Forward walking played backwards is walking backwards: the joint-angle patterns
        of backward walking are close to the time reversal of forward walking's (Winter,
        Pluck & Yang, 1989), and the rigid-body equations are even in time, so sensors
        synthesised from the reversed motion are those of a plausible backward walk."""
        meta = dict(self.meta)
        meta["time_reversed"] = not bool(meta.get("time_reversed", False))
        cat, sfx = self.category, REVERSED_SUFFIX
        cat = cat[: -len(sfx)] if cat.endswith(sfx) else cat + sfx
        return replace(self, root_pos=self.root_pos[::-1].copy(),
                       local_quat=self.local_quat[::-1].copy(), category=cat,
                       meta=meta)  # fmt: skip

    def time_scaled(self, factor: float) -> Motion:
        """The motion played ``factor`` times faster at the same frame rate (slerp for the
        rotations, linear for the root; ``1/factor`` of the duration, ``factor`` times the
        speed; ``meta["time_scale"]`` multiplied by it). A walk played 1.25-1.5 times faster is
        a faster walk of the same person (stride and cadence both up; the category stays).

        Raises:
            ValueError: ``factor`` outside :data:`TIME_SCALE_RANGE`, or a motion of one frame.
        """
        lo, hi = TIME_SCALE_RANGE
        if not lo <= float(factor) <= hi:
            raise ValueError(f"{self.name}: a time scale must be in [{lo:g}, {hi:g}], got "
                             f"{factor!r}")  # fmt: skip
        if self.n_frames < 2:
            raise ValueError(f"{self.name}: a motion of one frame cannot be time-scaled")
        t = np.arange(self.n_frames) / self.fps
        n = int(np.floor((self.n_frames - 1) / float(factor) + 1e-9)) + 1
        new_t = np.arange(n) * float(factor) / self.fps
        meta = dict(self.meta)
        meta["time_scale"] = float(meta.get("time_scale", 1.0)) * float(factor)
        return replace(self, root_pos=resample_linear(t, self.root_pos, new_t),
                       local_quat=resample_quats(t, self.local_quat, new_t), meta=meta)  # fmt: skip

    # ------------------------------------------------------------------ I/O
    def save(self, path: str | os.PathLike) -> None:
        """Write an npz atomically (temp file + rename; an existing file survives a failure)."""
        path = Path(path)
        meta = {
            "format_version": _FORMAT_VERSION,
            "name": self.name,
            "category": self.category,
            "meta": self.meta,
        }
        arrays = {
            "fps": np.array(self.fps, dtype=np.float64),
            "root_pos": self.root_pos.astype(np.float64),
            "local_quat": self.local_quat.astype(np.float64),
            "body": self.body.to_array(),
            "meta_json": np.array(json.dumps(meta)),
        }
        atomic_save_npz(path, arrays)

    @classmethod
    def load(cls, path: str | os.PathLike, *, limits: InputLimits | None = None) -> Motion:
        """Read a motion written by :meth:`save` (``allow_pickle=False``).

        Member sizes are checked from the npy headers before anything is loaded, the frame
        rate and duration before the frames are (``limits``, default
        :func:`grip.core.limits.active_limits`).

        Raises:
            MotionError: Anything wrong with the file (the message names it).
        """
        path = Path(path)
        limits = limits or active_limits()
        try:
            members = check_npz(path, limits)
            missing = [k for k in ("fps", "root_pos", "local_quat", "body", "meta_json")
                       if k not in members]  # fmt: skip
            if missing:
                raise MotionError(f"{path}: missing key(s) {', '.join(missing)}")
            with np.load(path, allow_pickle=False) as z:
                meta = safe_json_loads(str(z["meta_json"]), limits, "meta_json")
                if not isinstance(meta, dict):
                    raise MotionError(f"{path}: meta_json is not a JSON object")
                fps = float(z["fps"])
                limits.check_take(members["root_pos"][0][0] if members["root_pos"][0] else 0,
                                  fps, sk.N_JOINTS)  # fmt: skip
                root_pos = z["root_pos"]
                local_quat = z["local_quat"]
                body = BodyParams.from_array(z["body"])
        except MotionError:
            raise
        except LimitExceeded as e:
            raise MotionError(f"{path}: {e}") from None
        except Exception as e:  # any failure of zipfile/numpy/json: a corrupt or hostile file
            raise MotionError(f"{path}: cannot read motion npz ({type(e).__name__}: "
                              f"{str(e)[:300]})") from None  # fmt: skip
        try:
            return cls(fps=fps, root_pos=root_pos, local_quat=local_quat, body=body,
                       name=meta.get("name", path.stem), category=meta.get("category", "unknown"),
                       meta=meta.get("meta", {}))  # fmt: skip
        except MotionError as e:
            raise MotionError(f"{path}: {e}") from e
        except Exception as e:  # a value no check foresaw (wrong dtype, meta of a wrong type)
            raise MotionError(f"{path}: malformed motion ({type(e).__name__}: "
                              f"{str(e)[:300]})") from None  # fmt: skip


def check_motion_arrays(fps: float, root_pos: np.ndarray, local_quat: np.ndarray,
                        where: str = "motion") -> None:  # fmt: skip
    """Raise :class:`MotionError` naming ``where`` and the key if the arrays are malformed."""
    if not np.isfinite(fps) or fps <= 0:
        raise MotionError(f"{where}: fps must be a positive number, got {fps!r}")
    if root_pos.ndim != 2 or root_pos.shape[1] != 3:
        raise MotionError(f"{where}: root_pos must have shape (T, 3), got {root_pos.shape}")
    t = root_pos.shape[0]
    if local_quat.shape != (t, sk.N_JOINTS, 4):
        raise MotionError(
            f"{where}: local_quat must have shape ({t}, 24, 4), got {local_quat.shape}"
        )
    if t < 1:
        raise MotionError(f"{where}: motion has no frames")
    for key, arr in (("root_pos", root_pos), ("local_quat", local_quat)):
        if not np.all(np.isfinite(arr)):
            bad = int(np.argwhere(~np.isfinite(arr))[0][0])
            raise MotionError(f"{where}: {key} has NaN/inf values (first at frame {bad})")
    norms = np.linalg.norm(local_quat, axis=-1)
    if np.any(np.abs(norms - 1.0) > 1e-3):
        raise MotionError(f"{where}: local_quat rows are not unit quaternions")


def atomic_save_npz(path: Path, arrays: dict[str, np.ndarray]) -> None:
    """Write an uncompressed npz atomically (temp file in the same folder, then rename)."""
    atomic_write(path, lambda f: np.savez(f, **arrays))
