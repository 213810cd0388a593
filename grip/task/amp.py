"""AMP observations: the humanoid state the discriminator judges (numpy only).

One AMP frame (BASELINES_AND_METRICS 5.2, PHC's layout adapted to our hinge body), all in the
pelvis' heading frame (:func:`grip.task.observations.heading_matrix`):

====================  ====  ===========================================================
root height           1     pelvis z, m
root rotation         6     pelvis rotation in the heading frame, tan-norm 6D (first two
                            columns)
root linear velocity  3     world velocity of the pelvis, heading frame, m/s
root angular velocity 3     world angular velocity of the pelvis, heading frame, rad/s
hinge angles          69    rad (our joints are 3 hinges each, so raw angles are continuous:
                            no 6D per joint is needed)
hinge velocities      69    rad/s
key bodies            12    wrists and ankles minus the pelvis, heading frame, m
====================  ====  ===========================================================

The discriminator sees ``window`` consecutive frames, oldest first (:class:`AmpHistory`).
The same function computes the features of the simulated humanoid (in the environment) and of
the ground-truth motion (the discriminator's real samples), so both sides match by
construction.
"""

from __future__ import annotations

import numpy as np

from grip.core import skeleton as sk
from grip.task.observations import heading_matrices, heading_matrix

KEY_JOINTS: tuple[int, ...] = (20, 21, 7, 8)
"""L_Wrist, R_Wrist, L_Ankle, R_Ankle (PHC's key bodies: hands and feet)."""

N_HINGES = 3 * (sk.N_JOINTS - 1)
_SIZES = {"root_height": 1, "root_rot": 6, "root_vel": 3, "root_angvel": 3,
          "hinge_q": N_HINGES, "hinge_qd": N_HINGES, "key_pos": 3 * len(KEY_JOINTS)}
_ENDS = np.cumsum(list(_SIZES.values()))
PARTS: dict[str, slice] = {k: slice(int(e) - n, int(e))
                           for (k, n), e in zip(_SIZES.items(), _ENDS, strict=True)}  # fmt: skip
"""Where each part of an AMP frame lies (the module docstring's table, in order)."""
FRAME_DIM = PARTS["key_pos"].stop
"""Length of one AMP frame (163)."""


def amp_features(
    root_pos: np.ndarray,
    root_rot: np.ndarray,
    root_vel: np.ndarray,
    root_angvel: np.ndarray,
    hinge_q: np.ndarray,
    hinge_qd: np.ndarray,
    key_pos: np.ndarray,
) -> np.ndarray:
    """AMP frames of T states (the module docstring lists the layout).

    Args:
        root_pos: ``(T, 3)`` pelvis position, world, m.
        root_rot: ``(T, 3, 3)`` pelvis rotation, world.
        root_vel: ``(T, 3)`` pelvis linear velocity, world, m/s.
        root_angvel: ``(T, 3)`` pelvis angular velocity, world, rad/s.
        hinge_q: ``(T, 69)`` hinge angles, SMPL order, rad.
        hinge_qd: ``(T, 69)`` hinge velocities, rad/s.
        key_pos: ``(T, 4, 3)`` world positions of :data:`KEY_JOINTS`, m.

    Returns:
        ``(T, FRAME_DIM)`` float64.
    """
    t = root_pos.shape[0]
    h = heading_matrices(root_rot)  # (T, 3, 3); world row vector v -> v @ h
    local_rot = np.swapaxes(h, -1, -2) @ root_rot
    out = np.empty((t, FRAME_DIM))
    p = PARTS
    out[:, p["root_height"]] = root_pos[:, 2:3]
    out[:, p["root_rot"]] = np.swapaxes(local_rot[..., :, :2], -1, -2).reshape(t, 6)
    out[:, p["root_vel"]] = np.einsum("ti,tij->tj", root_vel, h)
    out[:, p["root_angvel"]] = np.einsum("ti,tij->tj", root_angvel, h)
    out[:, p["hinge_q"]] = hinge_q
    out[:, p["hinge_qd"]] = hinge_qd
    rel = key_pos - root_pos[:, None]
    out[:, p["key_pos"]] = np.einsum("tki,tij->tkj", rel, h).reshape(t, -1)
    return out


def reference_amp_features(clip) -> np.ndarray:
    """``(T, FRAME_DIM)`` AMP frames of a reference clip's ground truth (real samples)."""
    return amp_features(
        clip.gt_pos[:, 0], clip.gt_rot[:, 0], clip.gt_vel[:, 0], clip.gt_angvel[:, 0],
        clip.gt_qpos[:, 7:], clip.gt_qvel[:, 6:], clip.gt_pos[:, list(KEY_JOINTS)],
    )  # fmt: skip


def windows(frames: np.ndarray, window: int) -> np.ndarray:
    """``(T, window * FRAME_DIM)``: for every frame t, frames ``t - window + 1 .. t`` (the
    clip's first frame repeated before its start), oldest first."""
    t = frames.shape[0]
    idx = np.arange(t)[:, None] + np.arange(-window + 1, 1)[None, :]
    return frames[np.maximum(idx, 0)].reshape(t, -1)


class AmpHistory:
    """The last ``window`` AMP frames of one episode, as one flat vector (oldest first)."""

    def __init__(self, window: int) -> None:
        if window < 1:
            raise ValueError(f"AMP window must be >= 1, got {window}")
        self.window = window
        self._buf = np.zeros((window, FRAME_DIM))

    def reset(self, past: np.ndarray) -> None:
        """Fill the window from ``(k, FRAME_DIM)`` past frames (the newest last); the oldest
        is repeated where ``k < window``."""
        k = min(len(past), self.window)
        self._buf[self.window - k :] = past[len(past) - k :]
        self._buf[: self.window - k] = past[len(past) - k]

    def push(self, frame: np.ndarray) -> None:
        self._buf[:-1] = self._buf[1:]
        self._buf[-1] = frame

    def vector(self) -> np.ndarray:
        """``(window * FRAME_DIM,)`` float32 copy."""
        return self._buf.reshape(-1).astype(np.float32)


_KEY = np.array(KEY_JOINTS)
_HINGES = slice(PARTS["hinge_q"].start, PARTS["hinge_qd"].stop)


def amp_frames(sim_pvw: np.ndarray, sim_rot: np.ndarray, hinges: np.ndarray, h: np.ndarray,
               out: np.ndarray) -> np.ndarray:  # fmt: skip
    """:func:`amp_features` of B simulated states (the tracking environments' step): every
    vector turned into the heading frame by one stacked product.

    Args:
        sim_pvw: ``(B, 3, J, 3)`` world positions, linear and angular velocities of the bodies.
        sim_rot: ``(B, J, 3, 3)`` world rotations.
        hinges: ``(B, 138)`` hinge angles (rad) then hinge rates (rad/s).
        h: ``(B, 3, 3)`` heading matrices of the pelvis (:func:`grip.task.observations.
            heading_matrices`).
        out: ``(B, FRAME_DIM)`` buffer (any float dtype), filled and returned.
    """
    b = sim_pvw.shape[0]
    pos = sim_pvw[:, 0]
    v = np.empty((b, 8, 3))
    v[:, :2] = np.swapaxes(sim_rot[:, 0, :, :2], 1, 2)  # the rotation's first two columns
    v[:, 2:4] = sim_pvw[:, 1:, 0]
    np.subtract(pos[:, _KEY], pos[:, :1], out=v[:, 4:])
    v = v @ h  # world row vectors -> heading frame (h^T R for the rotation's columns)
    out[:, 0] = pos[:, 0, 2]
    out[:, 1:13] = v[:, :4].reshape(b, 12)  # root_rot (6), root_vel, root_angvel
    out[:, _HINGES] = hinges
    out[:, PARTS["key_pos"]] = v[:, 4:].reshape(b, 12)
    return out


def amp_frame(sim_pvw: np.ndarray, sim_rot: np.ndarray, hinge_q: np.ndarray,
              hinge_qd: np.ndarray, out: np.ndarray) -> np.ndarray:  # fmt: skip
    """The AMP frame of one simulated state: :func:`amp_features` for one frame, written out
    (the batched version's einsums cost more than the physics of a step).

    Args:
        sim_pvw: ``(3, J, 3)`` world positions, linear and angular velocities of the bodies.
        sim_rot: ``(J, 3, 3)`` world rotations.
        hinge_q: ``(69,)`` hinge angles, rad.
        hinge_qd: ``(69,)`` hinge rates, rad/s.
        out: ``(FRAME_DIM,)`` buffer, filled and returned.
    """
    h = heading_matrix(sim_rot[0])
    p = PARTS
    out[p["root_height"]] = sim_pvw[0, 0, 2]
    out[p["root_rot"]] = (h.T @ sim_rot[0])[:, :2].T.reshape(6)
    out[p["root_vel"]] = sim_pvw[1, 0] @ h
    out[p["root_angvel"]] = sim_pvw[2, 0] @ h
    out[p["hinge_q"]] = hinge_q
    out[p["hinge_qd"]] = hinge_qd
    out[p["key_pos"]] = ((sim_pvw[0, _KEY] - sim_pvw[0, 0]) @ h).reshape(-1)
    return out
