"""Fixtures of the policy tests."""

from __future__ import annotations

import json

import pytest

from envs.factory import make_tracking_env
from envs.tracking_env import SAMPLE_REFERENCE
from policies.train import PolicyTrainer, run_config_dict
from tests.policies.test_train import _tiny


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """``(run folder, trainer)`` of the tiny run (``test_train._tiny``) on the bundled sample,
    trained once per test module (test_train.py, test_run_exports.py)."""
    run = tmp_path_factory.mktemp("policy_run")
    cfg = _tiny()
    (run / "config.json").write_text(json.dumps({"config": run_config_dict(cfg)}))
    tr = PolicyTrainer(cfg, run, SAMPLE_REFERENCE, make_tracking_env)
    tr.train()
    return run, tr
