"""The left-right mirror image of the controller's observations and actions, and a policy that
averages its action with the mirror image of its action on the mirrored observation.

The mirror is the reflection of the world through a vertical plane with left and right swapped,
the convention of :func:`grip.kinematics.reference.mirror_reference_clip` (world ``x -> -x``;
every vertical plane is the same up to a turn, and the observations are turn-free). In the
humanoid's heading frame (x forward, y left, z up) it is ``y -> -y`` (``M = diag(1, -1, 1)``):
positions and velocities map to ``M v``, angular velocities (pseudo-vectors) to ``-M w``, global
rotations to ``M R B`` with ``B = diag(-1, 1, 1)`` the body's own left axis (so 6D columns
``(c0, c1) -> (-M c0, M c1)``), rotation differences ``D = E S^T`` to ``M D M`` (``(M c0, -M
c1)``); joints swap with their partners (:data:`grip.core.skeleton.MIRROR`), the height map
flips about the forward axis, the sensor features mirror as KinematicsNet's do
(:func:`grip.nn.symmetry.mirror_features`). A hinge action keeps its sign about x and
flips about y and z, and moves to the partner joint (the ranges of the right side mirror the
left's, so the same rule holds for relative and absolute actions).

Exact for the mirror-symmetric body of :func:`grip.core.body.build_body`: the mirrored
observation is what the mirrored humanoid on the mirrored clip observes (tested), so a policy
trained on mirrored references (``mirror_references``) is asked nothing new.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np
import torch

from grip.core import skeleton as sk
from grip.nn.symmetry import mirror_features
from grip.task import observations as O
from grip.task.config import TrackingEnvConfig
from grip.task.observations import heightmap_grid

if TYPE_CHECKING:
    from policies.controller import Controller

_MH = np.array([1.0, -1.0, 1.0])  # y -> -y in the heading frame
_PERM = np.asarray(sk.MIRROR)
_IMU_PERM = [O.IMU_JOINTS.index(int(_PERM[j])) for j in O.IMU_JOINTS]
_VEL_PERM = [sk.VELOCITY_JOINTS.index(int(_PERM[j])) for j in sk.VELOCITY_JOINTS]
_HINGE_PERM = _PERM[1:] - 1  # joints 1..23 as rows 0..22
_HINGE_SIGN = np.array([[1.0 if a == "x" else -1.0 for a in sk.HINGE_ORDERS[j]]
                        for j in range(1, sk.N_JOINTS)])  # fmt: skip


def _vec_rows(x: np.ndarray, n: int, perm, sign: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Mirror ``n`` rows of 3-vectors at the start of ``x`` (``(..., F)``); returns them and the
    rest."""
    rows = x[..., : 3 * n].reshape(*x.shape[:-1], n, 3)[..., perm, :] * sign
    return rows.reshape(*x.shape[:-1], 3 * n), x[..., 3 * n :]


def _six_rows(x: np.ndarray, n: int, perm, s0: np.ndarray, s1: np.ndarray):
    """Mirror ``n`` 6D rotations ``(c0, c1)`` at the start of ``x``: ``c0 * s0``, ``c1 * s1``."""
    r = x[..., : 6 * n].reshape(*x.shape[:-1], n, 2, 3)[..., perm, :, :]
    r = np.stack([r[..., 0, :] * s0, r[..., 1, :] * s1], axis=-2)
    return r.reshape(*x.shape[:-1], 6 * n), x[..., 6 * n :]


class ObservationMirror:
    """Mirror images of the tracking env's observation dicts and actions.

    Args:
        env_cfg: The policy's environment settings (observation variant, height map).
        sites: Sensor sites of the ``sensor`` part (the KinematicsNet's, e.g. ``("L_Wrist",
            "R_Wrist", "L_Foot", "R_Foot")``).
        insoles: Whether the ``sensor`` part holds the insoles.

    Raises:
        ValueError: A site set without every left/right partner.
    """

    def __init__(self, env_cfg: TrackingEnvConfig, sites: tuple[str, ...], insoles: bool) -> None:
        self.variant = env_cfg.kinematic_obs
        self.sites, self.insoles = tuple(sites), bool(insoles)
        mirror_features(torch.zeros(1, 1, 15 * len(sites) + 10 * insoles), self.sites,
                        self.insoles)  # refuses a set without a mirror image  # fmt: skip
        grid = heightmap_grid(env_cfg.heightmap_size, env_cfg.heightmap_extent_m)
        flipped = grid * np.array([1.0, -1.0])
        d = np.abs(flipped[:, None, :] - grid[None, :, :]).sum(-1)
        self._hm_perm = d.argmin(1)

    def observation(self, obs: dict) -> dict:
        """The mirrored observation (a dict of one frame, or a batch with leading axes)."""
        out = dict(obs)
        mh, neg = _MH, -_MH
        if "self" in obs:
            x = np.asarray(obs["self"], np.float64)
            h, rest = x[..., :1], x[..., 1:]
            rel, rest = _vec_rows(rest, sk.N_JOINTS - 1, _HINGE_PERM, mh)
            vel, rest = _vec_rows(rest, sk.N_JOINTS, _PERM, mh)
            ang, rest = _vec_rows(rest, sk.N_JOINTS, _PERM, neg)
            rot, rest = _six_rows(rest, sk.N_JOINTS, _PERM, neg, mh)
            out["self"] = np.concatenate([h, rel, vel, ang, rot, rest], -1).astype(np.float32)
        if "kinematic" in obs:
            x = np.asarray(obs["kinematic"], np.float64)
            n = len(O.IMU_JOINTS)
            d_rot, rest = _six_rows(x, n, _IMU_PERM, mh, neg)
            leaf, rest = _six_rows(rest, n, _IMU_PERM, neg, mh)
            d_w, rest = _vec_rows(rest, n, _IMU_PERM, neg)
            parts = [d_rot, leaf, d_w]
            if self.variant != "OA":
                d_v, rest = _vec_rows(rest, len(sk.VELOCITY_JOINTS), _VEL_PERM, mh)
                parts.append(d_v)
            if self.variant.startswith("OAV_J"):
                d_p, rest = _vec_rows(rest, sk.N_JOINTS, _PERM, mh)
                p, rest = _vec_rows(rest, sk.N_JOINTS, _PERM, mh)
                parts += [d_p, p]
            if self.variant == "OAV_Jrel_root":  # (forward, left) of the followed pelvis
                parts.append(rest[..., :2] * np.array([1.0, -1.0]))
                rest = rest[..., 2:]
            out["kinematic"] = np.concatenate([*parts, rest], -1).astype(np.float32)
        if "environment" in obs:
            out["environment"] = np.asarray(obs["environment"])[..., self._hm_perm]
        if "sensor" in obs:
            out["sensor"] = self._features(obs["sensor"])
        if "sensor_context" in obs:  # (a gate's: means mirror as features, deviations too,
            x = np.asarray(obs["sensor_context"], np.float32)  # the mirror's signs dropped)
            mean, sd = np.split(x, 2, axis=-1)
            out["sensor_context"] = np.concatenate([self._features(mean),
                                                    np.abs(self._features(sd))], -1)
        return out

    def _features(self, x) -> np.ndarray:
        """Sensor features ``(..., F)`` of the mirror image: a signed permutation
        (:func:`grip.nn.symmetry.mirror_features`)."""
        x = np.asarray(x, np.float32)
        t = torch.from_numpy(np.ascontiguousarray(x.reshape(1, -1, x.shape[-1])))
        m = mirror_features(t, self.sites, self.insoles).numpy()
        return m.reshape(x.shape).astype(np.float32)

    @staticmethod
    def action(a: np.ndarray) -> np.ndarray:
        """The mirrored action(s) ``(..., 69)``: hinge targets about x keep their sign, about y
        and z flip, joints swap with their partners."""
        a = np.asarray(a)
        rows = a.reshape(*a.shape[:-1], sk.N_JOINTS - 1, 3)[..., _HINGE_PERM, :] * _HINGE_SIGN
        return rows.reshape(a.shape).astype(a.dtype)


class MirrorAveragedPolicy:
    """A policy (or ensemble) whose action is the mean of its action and the mirror image of its
    action on the mirrored observation: left-right symmetric by construction, and an ensemble
    of two for one network (the controller's counterpart of KinematicsNet's ``--tta mirror``).

    A :class:`policies.controller.Controller`; the fall detector, settings and notes are the
    wrapped policy's.
    """

    def __init__(self, policy: Controller, sites: tuple[str, ...], insoles: bool) -> None:
        self.policy = policy
        self.mirror = ObservationMirror(policy.env_cfg, sites, insoles)
        self.obs_keys = policy.obs_keys
        self.env_cfg = policy.env_cfg
        self.amp_window = policy.env_cfg.amp_window
        self.disc = policy.disc
        self.info = dict(policy.info, mirror_averaged=True)

    def use_action_noise(self, scale: float, seed: int = 0) -> None:
        """The wrapped policy's action noise (both of its actions sample it)."""
        self.policy.use_action_noise(scale, seed)

    def act(self, obs: dict) -> np.ndarray:
        """The mean of the action on ``obs`` and the mirror image of the action on the mirrored
        observation."""
        a = self.policy.act(obs)
        b = self.mirror.action(self.policy.act(self.mirror.observation(obs)))
        return 0.5 * (a + b)

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        """The wrapped policy's fall detector."""
        return self.policy.fall_probability(amp_obs)
