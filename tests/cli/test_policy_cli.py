"""Which setting changes `grip policy train` accepts when it resumes a run."""

from __future__ import annotations

import dataclasses

from grip.core.runs import changed_settings
from policies.config import PolicyRunConfig
from policies.train import RESUMABLE, run_config_dict


def test_changed_settings_allows_resumable_and_new_default_keys():
    base = PolicyRunConfig()
    old = run_config_dict(base)
    defaults = run_config_dict(PolicyRunConfig())
    lr = dataclasses.replace(base, ppo=dataclasses.replace(base.ppo, learning_rate=1e-6))
    assert changed_settings(old, run_config_dict(lr), defaults, RESUMABLE) == []  # resumable
    arch = dataclasses.replace(base, ppo=dataclasses.replace(base.ppo, net_arch=(8,)))
    assert changed_settings(old, run_config_dict(arch), defaults, RESUMABLE) == ["ppo.net_arch"]
    # a run that began before stage1.mining_mix existed: the key is missing from its config
    older = run_config_dict(base)
    del older["stage1"]["mining_mix"]
    assert changed_settings(older, run_config_dict(base), defaults, RESUMABLE) == []
    no_defaults = changed_settings(older, run_config_dict(base), may_change=RESUMABLE)
    assert no_defaults == ["stage1.mining_mix"]
    mined = dataclasses.replace(base, stage1=dataclasses.replace(base.stage1, mining_mix=0.5))
    mined_diff = changed_settings(older, run_config_dict(mined), defaults, RESUMABLE)
    assert mined_diff == ["stage1.mining_mix"]
