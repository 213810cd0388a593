"""Foot-contact quality metrics on hand-built motions with known answers."""

from __future__ import annotations

import numpy as np
import pytest

from grip.core.body import CANONICAL_TO_WORLD, BodyParams, build_body
from grip.core.fk import forward_kinematics, rest_pose
from grip.core.rotations import matrix_to_quat
from grip.motion.motion import Motion
from grip.motion.quality import body_low_points, foot_metrics, summarize

BODY = BodyParams(height_m=1.70, mass_kg=70.0)


def _standing(n: int = 50, lift_m: float = 0.0, speed_mps: float = 0.0,
              category: str = "stand") -> Motion:  # fmt: skip
    """The rest pose standing upright on z = 0 (raised by ``lift_m``), gliding along +y."""
    body = build_body(BODY)
    rot, root = rest_pose(n)
    t = np.arange(n) / 100.0
    root[:, 1] = speed_mps * t
    root[:, 2] = body.pelvis_height + lift_m
    return Motion(fps=100.0, root_pos=root, local_quat=matrix_to_quat(rot), body=BODY,
                  name=f"test/{category}", category=category)  # fmt: skip


def test_standing_still_on_the_floor_is_perfect() -> None:
    m = foot_metrics(_standing())
    assert m["fs_mps"] == pytest.approx(0.0, abs=1e-12)
    assert m["fp_mean_mm"] == pytest.approx(0.0, abs=1e-9)
    assert m["fp_max_mm"] == pytest.approx(0.0, abs=1e-9)
    assert m["contact_fraction"] == 1.0
    assert m["float_mm"] == pytest.approx(0.0, abs=1e-9)
    assert m["stance_height_median_m"] == pytest.approx(0.0, abs=1e-12)
    assert m["n_frames"] == 50 and m["n_contact_foot_frames"] == 100


def test_sinking_counts_as_penetration() -> None:
    m = foot_metrics(_standing(lift_m=-0.01))
    assert m["fp_mean_mm"] == pytest.approx(10.0)
    assert m["fp_max_mm"] == pytest.approx(10.0)
    assert m["stance_height_median_m"] == pytest.approx(-0.01)


def test_floating_feet() -> None:
    low = foot_metrics(_standing(lift_m=0.005))
    assert low["contact_fraction"] == 1.0  # 5 mm is still contact
    assert low["float_mm"] == pytest.approx(5.0)
    high = foot_metrics(_standing(lift_m=0.10))
    assert high["contact_fraction"] == 0.0 and np.isnan(high["fs_mps"])
    assert high["float_mm"] == pytest.approx(100.0)  # still feet hovering 10 cm up


def test_sliding_speed_and_the_stepping_cap() -> None:
    slide = foot_metrics(_standing(speed_mps=0.2))
    assert slide["fs_mps"] == pytest.approx(0.2)
    assert slide["contact_fraction"] == 1.0
    fast = foot_metrics(_standing(speed_mps=2.0))  # faster than 1 m/s: not a contact
    assert fast["contact_fraction"] == 0.0


def test_body_low_points_bottom_is_the_sole_when_standing() -> None:
    body = build_body(BODY)
    rot, root = rest_pose(1)
    root[:, 2] = body.pelvis_height
    g, p = forward_kinematics(rot, root, body.offsets)
    pts = body_low_points(g, p, body)
    assert pts.shape[-1] == 3 and pts.shape[-2] > 12
    assert pts[..., 2].min() == pytest.approx(0.0, abs=1e-9)
    # Lying on the back (face up, rotated -90 deg about the left axis): a trunk shape is lowest.
    lying = rot.copy()
    lying[:, 0] = CANONICAL_TO_WORLD @ np.array([[1.0, 0, 0], [0, 0, 1.0], [0, -1.0, 0]])
    g, p = forward_kinematics(lying, root, body.offsets)
    pts = body_low_points(g, p, body)
    assert np.argmin(pts[0, :, 2]) >= 12


def test_summarize_weights_by_frames_and_groups() -> None:
    a = foot_metrics(_standing(n=30, speed_mps=0.2, category="walk"))
    b = foot_metrics(_standing(n=10, category="walk"))
    c = foot_metrics(_standing(n=20, lift_m=-0.01, category="squat"))
    out = summarize({"a": a, "b": b, "c": c})
    assert list(out) == ["squat", "walk", "all"]
    assert out["walk"]["clips"] == 2 and out["walk"]["frames"] == 40
    assert out["walk"]["fs_mps"] == pytest.approx(0.2 * 60 / 80)  # contact foot-frames weights
    assert out["all"]["fp_mean_mm"] == pytest.approx(10.0 * 20 / 60)
    assert out["all"]["fp_max_mm"] == pytest.approx(10.0)
    by_name = summarize([a, c], by="name")
    assert set(by_name) == {"test/walk", "test/squat", "all"}
