from pathlib import Path

import pytest

from grip.config import ConfigError, load_config
from grip.kinematics.config import KinematicsRunConfig


def test_toml_and_overrides(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text('hidden = 64\n[features]\nsites = ["L_Foot"]\n[train]\nlr = 1\n')
    cfg = load_config(p, KinematicsRunConfig(), ["train.batch_size=8", "features.insoles=false"])
    assert cfg.hidden == 64 and cfg.features.sites == ("L_Foot",)
    assert cfg.train.lr == 1.0 and isinstance(cfg.train.lr, float)
    assert cfg.train.batch_size == 8 and cfg.features.insoles is False


def test_unknown_keys_and_bad_types_name_the_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text("[train]\nlrr = 1\n")
    with pytest.raises(ConfigError, match=r"bad\.toml.*lrr"):
        load_config(p, KinematicsRunConfig())
    with pytest.raises(ConfigError, match="hidden"):
        load_config(None, KinematicsRunConfig(), ['hidden="big"'])
    with pytest.raises(ConfigError, match="Nose"):
        load_config(None, KinematicsRunConfig(), ['features.sites=["Nose"]'])


def test_shipped_default_config_loads():
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "configs" / "kinematics" / "default.toml"
    assert load_config(path, KinematicsRunConfig()).hidden > 0


@pytest.mark.parametrize("name", ["default", "finetune", "teacher", "teacher_gpu"])
def test_policy_recipes_load(name: str) -> None:
    """Every training recipe of configs/policy loads into valid settings; the GPU teacher is the
    CPU teacher's task at GRIP's network size and batch."""
    from grip.cli.paths import load_run_config
    from policies.config import PolicyRunConfig

    root = Path(__file__).resolve().parents[1] / "configs" / "policy"
    cfg = load_run_config(root / f"{name}.toml", "policy", PolicyRunConfig(), [])
    assert cfg.total_timesteps() > 0
    if name == "teacher_gpu":
        cpu = load_run_config(root / "teacher.toml", "policy", PolicyRunConfig(), [])
        assert cfg.ppo.net_arch == (2048, 1536, 1024, 1024, 512, 512)
        assert (cfg.ppo.n_envs, cfg.ppo.batch_size, cfg.amp.batch_size) == (4096, 32768, 8192)
        assert cfg.env == cpu.env and cfg.follow == cpu.follow == "truth"
        for a, b in ((cfg.stage1, cpu.stage1), (cfg.stage2, cpu.stage2)):
            assert (a.categories, a.mining_mix, a.fall_below_reference_m) == (
                b.categories, b.mining_mix, b.fall_below_reference_m)  # fmt: skip


def test_a_stage_passes_its_pelvis_gap_termination_to_the_environment() -> None:
    """``stage2.termination_root_gap_m`` reaches the stage's environment settings (and only
    that stage's); a negative distance is refused with the setting's name."""
    from grip.cli.errors import CliError
    from grip.cli.paths import load_run_config
    from policies.config import PolicyRunConfig

    cfg = load_run_config(None, "policy", PolicyRunConfig(), ["stage2.termination_root_gap_m=0.5"])
    assert cfg.env_config(cfg.stage2).termination_root_gap_m == 0.5
    assert cfg.env_config(cfg.stage1).termination_root_gap_m == 0.0
    with pytest.raises(CliError, match=r"stage2.*termination_root_gap_m must be >= 0"):
        load_run_config(None, "policy", PolicyRunConfig(), ["stage2.termination_root_gap_m=-1"])
