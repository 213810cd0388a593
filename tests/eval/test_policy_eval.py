"""``grip policy eval``'s rows and summary count simulation blow-ups and keep their frames out."""

from __future__ import annotations

import numpy as np

import grip.eval.policy as P
from grip.kinematics.features import FeatureConfig
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
