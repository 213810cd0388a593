"""benchmarks/train_profile.py: its warm-up rollouts are run and left out of the profile."""

from __future__ import annotations

from tests.cli.test_data_cli import _benchmark

P = _benchmark("train_profile")
TINY = ["ppo.n_envs=2", "ppo.n_steps=32", "ppo.batch_size=64", "ppo.n_epochs=1",
        "ppo.net_arch=[32,32]", "amp.window=3", "amp.hidden=[32]", "amp.batch_size=32",
        "amp.replay_size=500"]  # fmt: skip


def test_warmup_rollouts_reach_the_profile(monkeypatch, tmp_path):
    got = {}

    def fake(overrides, rollouts, config=None, reference=None, cpu=False, warmup=0):
        got.update(rollouts=rollouts, cpu=cpu, warmup=warmup)
        return {"vec_env": "dummy", "n_envs": 2, "action_repeat": 1, "decisions": 64,
                "wall_s": 1.0, "env_steps_per_s": 64.0, "ms_per_decision": 1.0,
                "share": {}, "ms_per_decision_by_part": {}}  # fmt: skip

    monkeypatch.setattr(P, "profile_training", fake)
    assert P.main(["--rollouts", "2", "--warmup-rollouts", "3", "--clock", "cpu",
                   "--json", str(tmp_path / "p.json")]) == 0  # fmt: skip
    assert got == {"rollouts": 2, "cpu": True, "warmup": 3}


def test_the_warmup_is_trained_but_not_counted():
    """One warm-up rollout and one timed: the profile counts the timed rollout's decisions,
    and its parts sum to its total."""
    res = P.profile_training(TINY, 1, warmup=1, cpu=True)
    assert res["decisions"] == 64
    assert sum(res["seconds"].values()) > 0
    assert abs(sum(res["share"].values()) - 1.0) < 1e-9
