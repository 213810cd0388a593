"""Names, order and parents of the SMPL-topology skeleton, IMU sites and insole cells.

The skeleton has the 24 SMPL joints in SMPL order. Body (segment) ``j`` is the rigid part whose
proximal joint is joint ``j``: body ``L_Knee`` is the left shank, ``L_Ankle`` the left foot,
``L_Foot`` the left toes, ``L_Elbow`` the left forearm.
"""

from __future__ import annotations

import numpy as np

JOINT_NAMES: tuple[str, ...] = (
    "Pelvis", "L_Hip", "R_Hip", "Spine1", "L_Knee", "R_Knee", "Spine2", "L_Ankle", "R_Ankle",
    "Spine3", "L_Foot", "R_Foot", "Neck", "L_Collar", "R_Collar", "Head", "L_Shoulder",
    "R_Shoulder", "L_Elbow", "R_Elbow", "L_Wrist", "R_Wrist", "L_Hand", "R_Hand",
)  # fmt: skip
"""The 24 SMPL joints in SMPL order."""

PARENTS: np.ndarray = np.array(
    [-1, 0, 0, 0, 1, 2, 3, 4, 5, 6, 7, 8, 9, 9, 9, 12, 13, 14, 16, 17, 18, 19, 20, 21],
    dtype=np.int64,
)
"""Parent of each joint; -1 for the root (pelvis)."""

N_JOINTS = 24
JOINT_INDEX: dict[str, int] = {n: i for i, n in enumerate(JOINT_NAMES)}

HINGE_ORDERS: tuple[str, ...] = tuple(
    {"Shoulder": "yxz", "Elbow": "yzx"}.get(n[2:], "xyz") for n in JOINT_NAMES
)
"""Order in which the three hinges of each joint compose (intrinsic Euler order; the root's
entry is unused). Three stacked hinges lock when the middle one reaches +-90 deg, so the middle
axis is one the joint rarely turns far about. The elbow flexes about y (often past 90 deg) and
barely about z: ``yzx`` (with ``xyz`` the elbow angles of 5-6 % of the frames of the shared clips
were within 20 deg of the lock, and their rates reached 130 rad/s). The shoulders turn far about
every axis; ``yxz`` keeps 0.5-0.9 % of frames within 20 deg of the lock, the fewest of the six
orders. Every other joint: ``xyz`` (no frame within 20 deg). Measured on the training split
(``grip data reference``), /work/scratch/gimbal.py in the issue-5 notes."""

# Left/right pairs, used for mirroring and symmetric parameters.
MIRROR: np.ndarray = np.array(
    [0, 2, 1, 3, 5, 4, 6, 8, 7, 9, 11, 10, 12, 14, 13, 15, 17, 16, 19, 18, 21, 20, 23, 22],
    dtype=np.int64,
)

LEAF_JOINTS: tuple[int, ...] = (20, 21, 7, 8, 15)
"""GRIP's leaf joints (wrists, ankles, head): LP stage output."""

VELOCITY_JOINTS: tuple[int, ...] = (*LEAF_JOINTS, 0)
"""Joints whose world velocity KinematicsNet's LV stage estimates: the leaves, then the pelvis
(GRIP's d^v at wrists, ankles, head and pelvis)."""

FOOT_JOINTS: tuple[int, int] = (10, 11)
"""SMPL foot joints (toe bases) used by foot-sliding metrics."""

ANKLE_JOINTS: tuple[int, int] = (7, 8)

# PRISM IMU parts -> the body that carries the sensor (orientation = that body's global rotation).
IMU_PARTS: tuple[str, ...] = (
    "L_Foot", "R_Foot", "L_Wrist", "R_Wrist", "Head", "Pelvis", "L_Knee", "R_Knee",
)  # fmt: skip
IMU_BODY: dict[str, int] = {
    "L_Foot": JOINT_INDEX["L_Ankle"],
    "R_Foot": JOINT_INDEX["R_Ankle"],
    "L_Wrist": JOINT_INDEX["L_Elbow"],
    "R_Wrist": JOINT_INDEX["R_Elbow"],
    "Head": JOINT_INDEX["Head"],
    "Pelvis": JOINT_INDEX["Pelvis"],
    "L_Knee": JOINT_INDEX["L_Knee"],
    "R_Knee": JOINT_INDEX["R_Knee"],
}
"""Body carrying each IMU. Watches ride on the forearm and insole IMUs on the foot, as in
TransPose/GRIP (orientation of the forearm and of the foot segment)."""

IMU_NEAREST_JOINT: dict[str, int] = {
    "L_Foot": 10, "R_Foot": 11, "L_Wrist": 20, "R_Wrist": 21,
    "Head": 15, "Pelvis": 0, "L_Knee": 4, "R_Knee": 5,
}  # fmt: skip
"""PRISM's mount points expressed as the nearest SMPL joint (PRISM_FORMAT.md)."""

FEET: tuple[str, str] = ("L_Foot", "R_Foot")
FOOT_BODY: dict[str, int] = {"L_Foot": 7, "R_Foot": 8}
TOE_BODY: dict[str, int] = {"L_Foot": 10, "R_Foot": 11}

# ------------------------------------------------------------------ Moticon OpenGo insole, 16 cells
N_INSOLE_CELLS = 16
INSOLE_FRONT_CELLS: tuple[int, ...] = tuple(range(8, 16))
INSOLE_BACK_CELLS: tuple[int, ...] = (0, 1, 2, 3)

INSOLE_CELL_UV: np.ndarray = np.array(
    [
        [-0.41, 0.12],  # 0 rear heel, medial
        [-0.41, -0.12],  # 1 rear heel, lateral
        [-0.29, 0.13],  # 2 front heel, medial
        [-0.29, -0.15],  # 3 front heel, lateral
        [-0.14, 0.04],  # 4 rear midfoot, central
        [-0.14, -0.22],  # 5 rear midfoot, lateral
        [0.00, 0.20],  # 6 small medial arch
        [0.00, -0.26],  # 7 lateral arch
        [0.19, 0.27],  # 8 first metatarsal head (largest)
        [0.20, 0.12],  # 9 second metatarsal head
        [0.18, -0.02],  # 10 third metatarsal head
        [0.15, -0.15],  # 11 fourth metatarsal head
        [0.11, -0.28],  # 12 fifth metatarsal head
        [0.40, 0.24],  # 13 hallux
        [0.38, 0.02],  # 14 second/third toes
        [0.33, -0.20],  # 15 fourth/fifth toes
    ]
)
"""Cell centres in the normalised insole plane, ``(16, 2)``: u along heel->toe divided by foot
length (origin at mid-foot, the midpoint of heel and toe tip), v towards the medial side divided
by foot width. An approximation of the Moticon OpenGo layout described in PRISM_FORMAT.md."""

INSOLE_CELL_AREA_CM2: np.ndarray = np.array(
    [12.0, 12.0, 11.0, 11.0, 10.0, 10.0, 6.0, 10.0, 17.0, 9.0, 9.0, 8.0, 8.0, 10.0, 8.0, 7.0]
)
"""Approximate cell areas, cm^2, for a ~26 cm insole (scaled with foot size by the body model)."""
