"""The tracking task's per-step math as torch functions on batches (the device twins of the
numpy row kernels that :class:`envs.batched.BatchedTrackingEnv` uses).

Each function here equals a numpy function of :mod:`grip.task.observations`,
:mod:`grip.task.amp`, :mod:`envs.rewards` or :mod:`envs.heightfield` to float rounding, whatever
the dtype and device of its inputs (``tests/warp/test_torch_task.py`` checks each pair in
float64). They exist so that :class:`envs.warp.env.WarpTrackingEnv` computes observations,
rewards and AMP frames where the simulation state lives, without a copy to the host.

Shapes: B batch, J = 24 joints. ``pvw (B, 3, J, 3)`` = world positions (m), linear (m/s) and
angular (rad/s) velocities of the bodies; ``rot (B, J, 3, 3)`` their world rotations.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch

from envs.heightfield import HeightField
from grip.core import skeleton as sk
from grip.task import amp as A
from grip.task import observations as O
from grip.task.config import RewardConfig

_IMU = list(O.IMU_JOINTS)
_VEL = list(sk.VELOCITY_JOINTS)
_N_IMU = len(_IMU)
_N_SELF_VEC = (sk.N_JOINTS - 1) + 2 * sk.N_JOINTS
_KEY = list(A.KEY_JOINTS)


def heading_matrices(root_rot: torch.Tensor) -> torch.Tensor:
    """:func:`grip.task.observations.heading_matrices`: ``(..., 3, 3)`` yaw rotations whose x
    axis is the pelvis' facing direction on the floor (identity where it faces straight up or
    down)."""
    fx, fy = root_rot[..., 0, 2], root_rot[..., 1, 2]
    n = torch.hypot(fx, fy)
    ok = n > 1e-9
    safe = torch.where(ok, n, torch.ones_like(n))
    c = torch.where(ok, fx / safe, torch.ones_like(n))
    s = torch.where(ok, fy / safe, torch.zeros_like(n))
    z, one = torch.zeros_like(n), torch.ones_like(n)
    return torch.stack([c, -s, z, s, c, z, z, z, one], dim=-1).reshape(*n.shape, 3, 3)


def observation_parts(variant: str, h: torch.Tensor, sim_pvw: torch.Tensor,
                      sim_rot: torch.Tensor, est_rows: torch.Tensor
                      ) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """:func:`grip.task.observations.observation_rows`: O^kin and O^self of B states.

    Args:
        variant: One of :data:`grip.task.config.KINEMATIC_OBS` (GRIP Table 4).
        h: ``(B, 3, 3)`` heading matrices of the simulated pelvis.
        sim_pvw, sim_rot: The simulated states.
        est_rows: ``(B, OBS_ROW_DIM)`` estimate rows (:data:`grip.task.observations.OBS_ROW`;
            the root already offset to the episode's start).

    Returns:
        ``kinematic (B, kinematic_dim(variant))`` and ``self (B, SELF_DIM)``, in the dtype of
        the inputs.
    """
    b, r, nj = est_rows.shape[0], O.OBS_ROW, sk.N_JOINTS
    est_pos = est_rows[:, r["est_pos"]].reshape(b, nj, 3)
    e_leaf = est_rows[:, r["leaf_rot"]].reshape(b, _N_IMU, 3, 3)
    est_vel = est_rows[:, r["est_vel"]].reshape(b, -1, 3)
    est_leaf_angvel = est_rows[:, r["leaf_angvel"]].reshape(b, _N_IMU, 3)
    pos, vel, w = sim_pvw[:, 0], sim_pvw[:, 1], sim_pvw[:, 2]
    rel = pos - pos[:, :1]
    rows = [rel[:, 1:], vel, w, est_leaf_angvel - w[:, _IMU]]
    if variant != "OA":
        rows.append(est_vel - vel[:, _VEL])
    if variant.startswith("OAV_Jrel"):
        rows += [est_pos - rel, est_pos]
    elif variant == "OAV_Jglo":
        rows += [(est_rows[:, None, r["est_root_pos"]] + est_pos) - pos, est_pos]
    gap = variant == "OAV_Jrel_root"
    if gap:  # the followed pelvis minus the simulated one, horizontal (a yaw keeps it so)
        g = est_rows[:, r["est_root_pos"]] - pos[:, 0]
        rows.append(torch.cat([g[:, :2], torch.zeros_like(g[:, 2:])], dim=1)[:, None])
    vecs = torch.cat(rows, dim=1) @ h
    d_rot = e_leaf @ sim_rot[:, _IMU].transpose(-1, -2)
    cols = torch.cat([sim_rot[..., :2], e_leaf[..., :2], d_rot @ h[:, None, :, :2]], dim=1)
    six = (cols.transpose(-1, -2).reshape(b, -1, 3) @ h).reshape(b, -1, 6)
    self_vec = torch.cat([pos[:, 0, 2:3], vecs[:, :_N_SELF_VEC].reshape(b, -1),
                          six[:, :nj].reshape(b, -1)], dim=1)  # fmt: skip
    parts = [six[:, nj + _N_IMU :].reshape(b, -1), six[:, nj : nj + _N_IMU].reshape(b, -1),
             vecs[:, _N_SELF_VEC : vecs.shape[1] - gap].reshape(b, -1)]
    if gap:
        parts.append(vecs[:, -1, :2].clamp(-O.ROOT_GAP_CLIP_M, O.ROOT_GAP_CLIP_M))
    return torch.cat(parts, dim=1), self_vec


def tracking_terms(sim_pvw: torch.Tensor, sim_rot: torch.Tensor, ref_pvw: torch.Tensor,
                   ref_rot: torch.Tensor, cfg: RewardConfig, align_root_xy: bool,
                   sim_disp: torch.Tensor, ref_disp: torch.Tensor, seconds: float,
                   root_gap: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:  # fmt: skip
    """:func:`envs.rewards.tracking_terms_rows`: the imitation terms, ``root_vel`` and
    ``root_pos`` of B states.

    Args:
        sim_pvw, sim_rot: The simulated states.
        ref_pvw, ref_rot: The ground truth of the same frames, same shapes.
        cfg: Kernel coefficients and form.
        align_root_xy: Compare positions with the simulated pelvis moved over the reference's
            horizontally.
        sim_disp, ref_disp: ``(B, 2)`` horizontal pelvis displacements over ``seconds``, m.
        seconds: Length of the root-velocity window, s.
        root_gap: ``(B, 2)`` followed pelvis minus simulated pelvis, horizontal, m.

    Returns:
        ``(B, 6)`` terms in :data:`envs.rewards.TERMS` order (``imit_pos, imit_rot, imit_vel,
        imit_angvel, root_vel, root_pos``) and ``(B, 3, J)`` per-joint squared position (aligned as
        asked), velocity and angular-velocity errors.
    """
    e = sim_pvw - ref_pvw
    if align_root_xy:
        # every joint's xy error minus the pelvis' (heights and velocities as they are)
        shift = torch.cat([e[:, :1, :1, :2], torch.zeros_like(e[:, :1, :1, :1])], dim=-1)
        e = torch.cat([e[:, :1] - shift, e[:, 1:]], dim=1)
    sq = (e * e).sum(dim=-1)  # (B, 3, J)
    tot = sq.sum(dim=-1)  # pos, vel, angvel
    tr = (sim_rot * ref_rot).sum(dim=(-1, -2))
    ang = torch.arccos(((tr - 1.0) * 0.5).clamp(-1.0, 1.0))
    x = torch.stack([tot[:, 0], (ang * ang).sum(dim=1), tot[:, 1], tot[:, 2]], dim=1)
    j = sim_rot.shape[1]
    x = x * (1.0 / j) if cfg.form == "mean_sq" else torch.sqrt(x)
    d = (sim_disp - ref_disp) / seconds
    k = torch.tensor([cfg.k_pos, cfg.k_rot, cfg.k_vel, cfg.k_angvel], dtype=x.dtype,
                     device=x.device)  # fmt: skip
    terms = torch.cat([torch.exp(-k * x), torch.exp(-cfg.k_root_vel * (d * d).sum(dim=1))[:, None],
                       torch.exp(-cfg.k_root_pos * (root_gap * root_gap).sum(dim=1))[:, None]],
                      dim=1)  # fmt: skip
    return terms, sq


def amp_frames(sim_pvw: torch.Tensor, sim_rot: torch.Tensor, hinges: torch.Tensor,
               h: torch.Tensor) -> torch.Tensor:  # fmt: skip
    """:func:`grip.task.amp.amp_frames`: ``(B, FRAME_DIM)`` AMP frames of B simulated states.

    Args:
        sim_pvw, sim_rot: The simulated states.
        hinges: ``(B, 138)`` hinge angles (rad) then hinge rates (rad/s), SMPL order.
        h: ``(B, 3, 3)`` heading matrices of the pelvis.
    """
    b = sim_pvw.shape[0]
    pos = sim_pvw[:, 0]
    v = torch.cat([sim_rot[:, 0, :, :2].transpose(1, 2), sim_pvw[:, 1:, 0],
                   pos[:, _KEY] - pos[:, :1]], dim=1) @ h  # fmt: skip
    return torch.cat([pos[:, 0, 2:3], v[:, :4].reshape(b, 12), hinges, v[:, 4:].reshape(b, 12)],
                     dim=1)  # fmt: skip


class TorchHeightFields:
    """:meth:`envs.heightfield.HeightField.sample` of several height fields on a device, each
    batch row reading its own field: bilinear terrain heights, 0 outside a field's grid and on
    the flat floor.

    Args:
        fields: The F height fields.
        device, dtype: Where and how their coefficients are kept (the cells of every field
            concatenated, with each field's origin, spacing, size and first cell).
    """

    def __init__(self, fields: Sequence[HeightField], device: torch.device | str,
                 dtype: torch.dtype = torch.float32) -> None:  # fmt: skip
        if not fields:
            raise ValueError("TorchHeightFields needs at least one height field")
        coefs, first = [], [0]
        for hf in fields:
            h = np.asarray(hf.heights, dtype=np.float64)
            a = h[:-1, :-1]
            coef = np.stack([a, h[:-1, 1:] - a, h[1:, :-1] - a,
                             h[1:, 1:] - h[1:, :-1] - h[:-1, 1:] + a], axis=-1)  # fmt: skip
            coefs.append(coef.reshape(-1, 4))
            first.append(first[-1] + len(coefs[-1]))
        self.coef = torch.as_tensor(np.concatenate(coefs), dtype=dtype, device=device)
        f = dict(dtype=dtype, device=device)
        self.origin = torch.as_tensor(np.array([hf.origin_xy for hf in fields]), **f)  # (F, 2)
        self.inv = torch.as_tensor([1.0 / float(hf.cell_m) for hf in fields], **f)
        self.nx = torch.as_tensor([hf.shape[1] for hf in fields], **f)
        self.ny = torch.as_tensor([hf.shape[0] for hf in fields], **f)
        self.first = torch.as_tensor(first[:-1], dtype=torch.int64, device=device)
        self.max_height = np.array([hf.max_height for hf in fields])  # (F,) m, on the host

    def sample(self, xy: torch.Tensor, field: torch.Tensor) -> torch.Tensor:
        """Heights ``(B, P)`` at world points ``xy (B, P, 2)``, m, row ``b`` on field
        ``field[b]`` (``(B,)`` int64; -1: the flat floor)."""
        k = field.clamp(min=0)
        inv = self.inv[k][:, None]
        nx, ny = self.nx[k][:, None], self.ny[k][:, None]
        uv = (xy - self.origin[k][:, None]) * inv[..., None]
        u, v = uv[..., 0], uv[..., 1]
        # (a non-finite point reads cell 0 and comes out 0: it is outside the grid)
        iu = torch.minimum(torch.nan_to_num(torch.floor(u)).clamp(min=0.0), nx - 2)
        iv = torch.minimum(torch.nan_to_num(torch.floor(v)).clamp(min=0.0), ny - 2)
        fu, fv = u - iu, v - iv
        cell = self.first[k][:, None] + (iv * (nx - 1) + iu).long()
        c = self.coef[cell]  # (B, P, 4)
        r = c[..., 0] + c[..., 1] * fu + (c[..., 2] + c[..., 3] * fu) * fv
        inside = (u >= 0.0) & (u <= nx - 1) & (v >= 0.0) & (v <= ny - 1) & (field >= 0)[:, None]
        return torch.where(inside, r, torch.zeros_like(r))

    def around(self, center_xy: torch.Tensor, h: torch.Tensor, grid: torch.Tensor,
               field: torch.Tensor) -> torch.Tensor:  # fmt: skip
        """:func:`envs.heightfield.sample_heightmap` of B frames: heights ``(B, N)`` at
        ``center_xy (B, 2) + grid (N, 2) @ rot2.T`` with ``rot2 = h[:, :2, :2]``, on the field
        of each row (``field (B,)``, -1: the flat floor)."""
        pts = center_xy[:, None, :] + grid[None] @ h[:, :2, :2].transpose(1, 2)
        return self.sample(pts, field)
