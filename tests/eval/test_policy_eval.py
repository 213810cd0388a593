"""``grip policy eval``'s rows and summary count simulation blow-ups and keep their frames out,
and carry the pace of the humanoid against the pelvis it followed."""

from __future__ import annotations

import math
import types

import numpy as np
import pytest

import grip.eval.policy as P
from grip.core.reconstruction import Reconstruction
from grip.kinematics.features import FeatureConfig, ground_truth
from grip.pipeline import GripPipeline
from grip.task.config import TrackingEnvConfig
from prism_tools.io import load_recording


class _BlowingRunner:
    """Zero actions; before the step to ``frame`` the pelvis gets 1 km/s upwards (a state
    MuJoCo integrates without a warning)."""

    disc = None
    env_cfg = TrackingEnvConfig(amp_window=2)

    def __init__(self, frame: int) -> None:
        self.frame, self.player = frame, None

    def act(self, obs: dict) -> np.ndarray:
        if self.player.t + 1 == self.frame:
            self.player.h.data.qvel[2] = 1e3
        return np.zeros(69)


def test_a_blow_up_fails_its_segment_and_is_counted(monkeypatch, tmp_path) -> None:
    runner = _BlowingRunner(60)

    player = GripPipeline.player

    def player_of(self, *args, **kw):
        runner.player = player(self, *args, **kw)
        return runner.player

    monkeypatch.setattr(GripPipeline, "player", player_of)
    rec = load_recording("grip/assets/sample_recording.npz").slice_frames(0, 120)
    est = type("Est", (), {"cfg": type("Cfg", (), {"features": FeatureConfig()})()})()
    (row,) = P.evaluate_policy(runner, est, [rec], reference="truth")
    assert row["blowups"] == 1 and row["fell"] and row["frames"] == 60
    assert row["MPJPE_mm"] < 500  # the frame that flew off is not in the metrics
    s = P.summarize_rows([row, dict(row, blowups=0)])
    assert s["overall"]["blowups"] == 1
    assert "1 simulation blow-up(s)" in P.markdown_table(s)
    P.write_rows([row], s, tmp_path)
    assert "blowups" in (tmp_path / "segments.csv").read_text().splitlines()[0]
    # the followed pelvis is the truth's (integrated from its velocity: within millimetres)
    assert set(P.PACE_KEYS) <= set(row)
    assert row["pace_end_m"] == pytest.approx(row["root_gt_end_m"], abs=0.01)
    assert math.isnan(row["pace_5s_m"]) and math.isnan(row["pace_1s_m"])  # ended at frame 59
    assert row["kin_root_gt_end_m"] < 0.01  # "kinematics only" is the truth here


def test_a_humanoid_that_stands_still_while_the_estimate_walks_away(tmp_path) -> None:
    """The row of an episode whose humanoid never left its first pose while what it followed
    (here the truth's walk) went on: the pace is the ground the walk covered."""
    rec = load_recording("grip/assets/sample_recording.npz")
    gt = ground_truth(rec)
    n = gt.n_frames
    still = Reconstruction(name=rec.name, method="grip", fps=gt.fps,
                           joint_pos=np.repeat(gt.joint_pos[:1], n, axis=0),
                           global_rot=np.repeat(gt.global_rot[:1], n, axis=0),
                           ref_root_pos=gt.root_pos)  # fmt: skip
    clip = types.SimpleNamespace(est_pos=gt.joint_pos, est_root_pos=gt.root_pos, fps=gt.fps)
    row = {"category": "walk", **P.segment_row(still, clip, rec)}
    walked = np.linalg.norm(gt.root_pos[:, :2] - gt.root_pos[0, :2], axis=1)
    assert n == 500 and walked[-1] > 3.0  # the sample walk: 5 s
    assert row["pace_5s_m"] == pytest.approx(walked[499]) == pytest.approx(row["pace_end_m"])
    assert row["pace_1s_m"] == pytest.approx(walked[99])
    assert row["root_gt_5s_m"] == pytest.approx(walked[499])
    speed = np.polyfit(np.arange(n) / gt.fps, walked, 1)[0]
    assert row["drift_mps"] == pytest.approx(speed) and row["drift_mps"] > 0.5
    assert row["kin_root_gt_5s_m"] == 0.0
    s = P.summarize_rows([row, dict(row, pace_5s_m=float("nan"))])
    assert s["overall"]["pace_5s_m"] == pytest.approx(walked[499])  # NaN segments left out
    assert s["overall"]["segments_5s"] == 1
    text = P.markdown_table(s)
    assert f"| {walked[499]:.2f} |" in text and "reached 5 s" in text
    P.write_rows([row], s, tmp_path)
    head = (tmp_path / "segments.csv").read_text().splitlines()[0].split(",")
    assert set(P.PACE_KEYS) <= set(head)
