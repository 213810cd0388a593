"""The symmetries of the sensing problem: turns about the vertical and the left-right mirror.

Gravity fixes only the vertical and the body is mirror-symmetric, so a motion turned about the
vertical or reflected left-right is as plausible as the original, and the sensor readings and
KinematicsNet targets it would produce follow exactly from the originals. KinematicsNet's
training augments with these copies (:class:`grip.kinematics.train.Trainer`), its inference
averages over them (:class:`grip.kinematics.inference.Symmetries`), and the controller mirrors
its sensor observations with the same rule (:mod:`policies.symmetry`).

Raw features are ``(B, T, F)``: 15 values per IMU site (free acceleration ``(3,)`` m/s²,
angular velocity ``(3,)`` rad/s, orientation ``(3, 3)`` row-major, all world frame), then 10
insole values (per foot, left then right: force in body weights, CoP ``(2,)`` in the foot's own
frame, front and back contact; :mod:`grip.kinematics.features`). Targets are ``lp, fp, lv``
(3-vectors per joint), ``fa`` (6D global rotations, the first two columns) as ``(B, T, dim)``
and ``offsets`` ``(B, 24, 3)``. Imports torch and :mod:`grip.core` only.
"""

from __future__ import annotations

import torch

from grip.core import skeleton as sk


def yaw_matrices(angles: torch.Tensor) -> torch.Tensor:
    """Rotations about the vertical (z) axis by ``angles`` (rad, any shape ``(...)``), as
    ``(..., 3, 3)`` matrices."""
    c, s = torch.cos(angles), torch.sin(angles)
    z, o = torch.zeros_like(c), torch.ones_like(c)
    return torch.stack([c, -s, z, s, c, z, z, z, o], -1).view(*angles.shape, 3, 3)


def rotate_batch(
    x: torch.Tensor, y: dict[str, torch.Tensor], rot: torch.Tensor, n_sites: int
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Rotate raw features and targets of each window by a world rotation ``rot (B, 3, 3)``.

    Accelerations, angular velocities, orientations, leaf/joint positions, 6D global rotations and
    velocities all rotate; insole values do not.
    """
    return rotate_features(x, rot, n_sites), rotate_targets(y, rot)


def rotate_features(x: torch.Tensor, rot: torch.Tensor, n_sites: int) -> torch.Tensor:
    """Raw features ``(B, T, F)`` of ``n_sites`` IMUs (and insoles) seen in a world turned by
    ``rot (B, 3, 3)`` (:func:`rotate_batch`'s rule for the inputs)."""
    b, t, _ = x.shape
    r = rot[:, None]  # (B, 1, 3, 3)
    imu = x[..., : 15 * n_sites].reshape(b, t, n_sites, 15)
    acc = torch.einsum("btij,btsj->btsi", r, imu[..., 0:3])
    gyr = torch.einsum("btij,btsj->btsi", r, imu[..., 3:6])
    ori = (r[:, :, None] @ imu[..., 6:15].reshape(b, t, n_sites, 3, 3)).reshape(b, t, n_sites, 9)
    return torch.cat([torch.cat([acc, gyr, ori], -1).reshape(b, t, -1), x[..., 15 * n_sites :]], -1)


def rotate_targets(y: dict[str, torch.Tensor], rot: torch.Tensor) -> dict[str, torch.Tensor]:
    """Targets or outputs ``{stage: (B, T, dim)}`` in a world turned by ``rot (B, 3, 3)``
    (:func:`rotate_batch`'s rule; other keys pass unchanged)."""
    r = rot[:, None]
    out = {}
    for k, v in y.items():
        b, t = v.shape[:2]
        if k in ("lp", "fp", "lv"):
            out[k] = torch.einsum("btij,btnj->btni", r, v.reshape(b, t, -1, 3)).reshape(b, t, -1)
        elif k == "fa":
            cols = v.reshape(b, t, 24, 2, 3)
            out[k] = torch.einsum("btij,btncj->btnci", r, cols).reshape(b, t, -1)
        else:
            out[k] = v
    return out


def mirror_site_order(sites: tuple[str, ...]) -> list[int]:
    """Index of each site's mirror partner in ``sites`` (``L_X`` <-> ``R_X``; ``Head`` and
    ``Pelvis`` are their own).

    Raises:
        ValueError: A site's partner is not in the set (such a set has no mirror image).
    """
    swap = {"L_": "R_", "R_": "L_"}
    partner = [swap.get(s[:2], s[:2]) + s[2:] for s in sites]
    missing = [p for p in partner if p not in sites]
    if missing:
        raise ValueError(f"mirror_augment needs every site's left/right partner; "
                         f"{list(sites)} lacks {missing}")  # fmt: skip
    return [sites.index(p) for p in partner]


_M = torch.tensor([-1.0, 1.0, 1.0])  # the reflection x -> -x, as a diagonal
_LEAF_MIRROR = [sk.LEAF_JOINTS.index(int(sk.MIRROR[j])) for j in sk.LEAF_JOINTS]
_VEL_MIRROR = [sk.VELOCITY_JOINTS.index(int(sk.MIRROR[j])) for j in sk.VELOCITY_JOINTS]


def mirror_batch(
    x: torch.Tensor, y: dict[str, torch.Tensor], sites: tuple[str, ...], insoles: bool
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """Raw features and targets of the left-right mirror image of each window.

    The world is reflected through the plane ``x = 0`` (``M = diag(-1, 1, 1)``; with random yaw
    this covers every vertical mirror plane) and left and right swap: positions, velocities and
    accelerations map to ``M v``, world angular velocities (pseudo-vectors) to ``-M w``,
    rotations and IMU orientations to ``M R M``, the two insoles swap (their CoP is in the
    foot's own forward/medial frame, which the mirror keeps), and the rest offsets of the body
    map to ``M o``. Exact for a mirror-symmetric body with mirror-symmetric sensor mounts.

    Args:
        x: ``(B, T, F)`` raw (unnormalised) features of ``sites`` (and the insoles).
        y: Targets ``lp, fp, fa, lv`` ``(B, T, dim)`` and ``offsets (B, 24, 3)``.

    Raises:
        ValueError: ``sites`` is not closed under the mirror, or ``y`` has an unknown key.
    """
    return mirror_features(x, sites, insoles), mirror_targets(y)


def mirror_features(x: torch.Tensor, sites: tuple[str, ...], insoles: bool) -> torch.Tensor:
    """Raw features ``(B, T, F)`` of the mirror image (:func:`mirror_batch`'s rule for the
    inputs).

    Raises:
        ValueError: ``sites`` is not closed under the mirror.
    """
    order = mirror_site_order(tuple(sites))
    b, t, _ = x.shape
    n = len(sites)
    m = _M.to(x.dtype)
    imu = x[..., : 15 * n].reshape(b, t, n, 15)[:, :, order]
    acc = imu[..., 0:3] * m
    gyr = -imu[..., 3:6] * m
    ori = (imu[..., 6:15].reshape(b, t, n, 3, 3) * (m[:, None] * m[None, :])).reshape(b, t, n, 9)
    parts = [torch.cat([acc, gyr, ori], -1).reshape(b, t, -1)]
    if insoles:
        parts.append(x[..., 15 * n : 15 * n + 10].reshape(b, t, 2, 5).flip(2).reshape(b, t, 10))
    return torch.cat(parts, -1)


def mirror_targets(y: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """Targets or outputs of the mirror image (:func:`mirror_batch`'s rule): ``lp, fp, fa,
    lv`` as ``(B, T, dim)``, ``offsets`` as ``(B, 24, 3)``. Mirroring twice is the identity.

    Raises:
        ValueError: ``y`` has a key without a mirror rule.
    """
    perm = torch.from_numpy(sk.MIRROR)
    out = {}
    for k, v in y.items():
        m = _M.to(v.dtype)
        if k in ("lp", "fp", "lv"):
            b, t = v.shape[:2]
            idx = {"lp": _LEAF_MIRROR, "fp": perm, "lv": _VEL_MIRROR}[k]
            out[k] = (v.reshape(b, t, -1, 3)[:, :, idx] * m).reshape(b, t, -1)
        elif k == "fa":
            # the columns c0, c1 of R become those of M R M: -M c0, M c1
            b, t = v.shape[:2]
            cols = v.reshape(b, t, 24, 2, 3)[:, :, perm]
            sign = torch.stack([-m, m])
            out[k] = (cols * sign).reshape(b, t, -1)
        elif k == "offsets":
            out[k] = v[:, perm] * m
        else:
            raise ValueError(f"mirror_batch: no mirror rule for target {k!r}")
    return out

