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
