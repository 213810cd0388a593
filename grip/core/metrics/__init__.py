"""Evaluation metrics of BASELINES_AND_METRICS.md section 4.2 as pure numpy functions.

Conventions: world frame z-up with the floor at ``z = 0``; positions in m, rotations as
``(..., 3, 3)`` matrices acting on column vectors; ``T`` frames, ``J`` joints (24 SMPL joints in
SMPL order unless stated). Each function returns the unit given in its docstring (mm for position
errors, deg for angles, SI otherwise).

Protocol (section 4.1): every metric is computed per 500-frame segment (values averaged over the
frames and joints of the segment), then :func:`summarize` averages the segment values.

Not implemented here: "Mesh err" (needs the 6,890-vertex SMPL mesh, which the project does not
ship); foot penetration is measured on the body model's sole corner points instead of SMPL foot
vertices (:func:`grip.core.fk.sole_points`).

Modules: :mod:`.pose` (joint position/rotation errors, jitter), :mod:`.sip` (SIP-masked pose
metrics), :mod:`.physical` (feet, GRF, ZMP), :mod:`.translation` (root translation), :mod:`.pace`
(horizontal distance of a simulated pelvis to the one it follows and to the truth),
:mod:`.aggregate` (success rate, segment means). Import the names from this package.
"""

from __future__ import annotations

from grip.core.metrics.aggregate import success_rate, summarize
from grip.core.metrics.pace import (
    PACE_KEYS,
    PACE_TIMES_S,
    ROOT_GT_KEYS,
    Gap,
    Pace,
    distance_at,
    drift_rate,
    horizontal_distance,
    horizontal_gap,
    measure_pace,
)
from grip.core.metrics.physical import (
    contacts_from_motion,
    foot_penetration,
    foot_sliding,
    net_external_wrench,
    vgrf_error,
    zero_moment_point,
    zmp_distance,
    zmp_distances,
)
from grip.core.metrics.pose import (
    acceleration_error,
    jitter,
    mpjpe,
    mpjre,
    mpjre_local,
    pa_mpjpe,
    pel_mpjpe,
    procrustes,
    procrustes_align,
)
from grip.core.metrics.sip import (
    SIP_EVAL_JOINTS,
    SIP_MASKED_JOINTS,
    angular_error_masked,
    global_to_local_rot,
    local_to_global_rot,
    position_error_masked,
    sip_error,
    sip_masked_joint_positions,
    sip_masked_pose,
)
from grip.core.metrics.translation import (
    TranslationErrorCurve,
    cumulative_translation_error,
    root_error_xy,
    translation_error_by_distance,
    translation_error_by_time,
    travel_ratio,
)

__all__ = [
    "PACE_KEYS",
    "PACE_TIMES_S",
    "ROOT_GT_KEYS",
    "SIP_EVAL_JOINTS",
    "SIP_MASKED_JOINTS",
    "Gap",
    "Pace",
    "TranslationErrorCurve",
    "acceleration_error",
    "angular_error_masked",
    "contacts_from_motion",
    "cumulative_translation_error",
    "distance_at",
    "drift_rate",
    "foot_penetration",
    "foot_sliding",
    "global_to_local_rot",
    "horizontal_distance",
    "horizontal_gap",
    "jitter",
    "local_to_global_rot",
    "measure_pace",
    "mpjpe",
    "mpjre",
    "mpjre_local",
    "net_external_wrench",
    "pa_mpjpe",
    "pel_mpjpe",
    "position_error_masked",
    "procrustes",
    "procrustes_align",
    "root_error_xy",
    "sip_error",
    "sip_masked_joint_positions",
    "sip_masked_pose",
    "success_rate",
    "summarize",
    "translation_error_by_distance",
    "translation_error_by_time",
    "travel_ratio",
    "vgrf_error",
    "zero_moment_point",
    "zmp_distance",
    "zmp_distances",
]
