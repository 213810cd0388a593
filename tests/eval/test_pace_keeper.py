"""The pace keeper (docs/pace.md): the followed pelvis the controller is shown leads the
estimate's by gain x the humanoid's gap to it; the physics and the reconstruction's reference
stay the estimate's."""

from __future__ import annotations

import numpy as np
import pytest

from envs.tracking_env import SAMPLE_REFERENCE
from grip.core.reference import ReferenceSet
from grip.pipeline import GripPipeline, PaceKeeper, RecoveryConfig, start_from_clip
from grip.task.config import TrackingEnvConfig


class _StandStill:
    """Holds the humanoid's pelvis still horizontally (the estimate walks away) and records the
    gap numbers of each observation (``OAV_Jrel_root``'s last two)."""

    def __init__(self) -> None:
        self.disc, self.env_cfg = None, TrackingEnvConfig(kinematic_obs="OAV_Jrel_root",
                                                          amp_window=0)  # fmt: skip
        self.player, self.gaps = None, []

    def act(self, obs: dict) -> np.ndarray:
        self.gaps.append(np.array(obs["kinematic"][-2:], dtype=np.float64))
        self.player.h.qvel[:2] = 0.0
        return np.zeros(69)


@pytest.fixture(scope="module")
def clip():
    return ReferenceSet.load(SAMPLE_REFERENCE).clip(0)


def _play(clip, pace: PaceKeeper, frames: int = 60):
    runner = _StandStill()
    pipe = GripPipeline(runner, None, RecoveryConfig(enabled=False), pace)
    player = runner.player = pipe.player(clip.body, clip.objects)
    player.start(clip, start_from_clip(clip), clip.name, clip.fps)
    while player.t < frames and not player.advance():
        pass
    return runner.gaps, player.reconstruction(1.0)


def test_the_lead_is_gain_times_the_gap_clipped() -> None:
    np.testing.assert_allclose(PaceKeeper(gain=0.0).lead([1.0, 2.0], np.zeros(2)), [0.0, 0.0])
    np.testing.assert_allclose(PaceKeeper(gain=0.5).lead([0.2, -0.1], np.zeros(2)), [0.1, -0.05])
    far = PaceKeeper(gain=2.0, lead_max_m=0.3).lead([3.0, 4.0], np.zeros(2))
    np.testing.assert_allclose(far, [0.18, 0.24])  # along the gap, 0.3 m long
    with pytest.raises(ValueError, match="gain"):
        PaceKeeper(gain=-1.0)


def test_a_humanoid_left_behind_is_shown_a_larger_gap(clip) -> None:
    off, recon_off = _play(clip, PaceKeeper(gain=0.0))
    on, recon = _play(clip, PaceKeeper(gain=1.0, lead_max_m=5.0))
    off, on = np.array(off), np.array(on)
    grown = np.linalg.norm(off, axis=1) > 0.05  # the estimate has walked away
    assert grown.sum() > 5
    # the humanoid stands still in both runs: the shown gap is twice the true one
    np.testing.assert_allclose(on[grown], 2.0 * off[grown], rtol=0.05, atol=0.01)
    # the estimate the reconstruction reports is the estimate, not the lead
    np.testing.assert_allclose(recon.ref_root_pos, recon_off.ref_root_pos)


def test_the_lead_is_capped(clip) -> None:
    off, _ = _play(clip, PaceKeeper(gain=0.0))
    on, _ = _play(clip, PaceKeeper(gain=1.0, lead_max_m=0.05))
    gap = np.linalg.norm(np.array(off), axis=1)
    shown = np.linalg.norm(np.array(on), axis=1)
    far = gap > 0.2
    assert far.any()
    np.testing.assert_allclose(shown[far], gap[far] + 0.05, atol=0.02)


@pytest.fixture(scope="module")
def root_policy(tmp_path_factory, tiny_policy_settings):
    """A tiny ``OAV_Jrel_root`` policy export (it reads the gap the keeper changes)."""
    import shutil

    from grip.cli.main import main

    root = tmp_path_factory.mktemp("root_policy")
    (root / "data").mkdir()
    (root / "data" / "split.json").write_text('{"train": ["s0"], "test": []}')
    run = root / "run"
    run.mkdir()
    shutil.copy(SAMPLE_REFERENCE, run / "reference_train.npz")
    assert main(["policy", "train", "--data", str(root / "data"), "--out", str(run),
                 *tiny_policy_settings, "--set", "env.kinematic_obs=OAV_Jrel_root"]) == 0
    assert main(["policy", "export", str(run), "--out", str(root / "p.pt")]) == 0
    return root / "p.pt"


def test_the_bench_and_the_player_default_alike() -> None:
    from grip.eval.methods import MethodOptions

    assert MethodOptions().pace() == PaceKeeper()


def test_policy_eval_takes_the_pace_keeper(walk_takes, root_policy, tmp_path) -> None:
    """``grip policy eval --pace-gain``: it changes what the controller does, the same rows in
    worker processes as here (the keeper reaches them), the setting in the JSON, a bad value
    refused."""
    import json

    from grip.cli.main import main

    base = ["policy", "eval", "--data", str(walk_takes), "--segment-frames", "100",
            "--segments", "4", "--batch", "2", "--policy", str(root_policy)]  # fmt: skip
    csv = {}
    for name, extra in (("off", ["--pace-gain", "0"]), ("w1", ["--pace-gain", "2"]),
                        ("w2", ["--pace-gain", "2", "--workers", "2"])):  # fmt: skip
        out = tmp_path / name
        assert main([*base, *extra, "--out", str(out), "--json", str(out / "e.json")]) == 0
        csv[name] = (out / "segments.csv").read_text()
    assert csv["w1"] == csv["w2"]
    assert csv["w1"] != csv["off"]
    got = json.loads((tmp_path / "w1" / "e.json").read_text())
    assert got["pace_keeper"]["gain"] == 2.0
    assert main([*base, "--pace-gain", "-1"]) == 2



def test_bench_and_reconstruct_refuse_a_bad_keeper_by_name(walk_takes, tmp_path, capsys) -> None:
    from grip.assets import SAMPLE_RECORDING
    from grip.cli.main import main

    assert main(["bench", "--data", str(walk_takes), "--methods", "grip", "--out",
                 str(tmp_path / "b"), "--pace-gain", "-1"]) == 2  # fmt: skip
    assert "--pace-gain -1" in capsys.readouterr().err
    assert main(["reconstruct", str(SAMPLE_RECORDING), "--out", str(tmp_path / "r"),
                 "--pace-lead-max", "0"]) == 2  # fmt: skip
    assert "lead_max_m must be > 0" in capsys.readouterr().err
    assert not (tmp_path / "r").exists() or not any((tmp_path / "r").iterdir())
