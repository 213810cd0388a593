"""The policy file: one list of members in every file written now, and every layout written
before still loading (ensembles in the layout of the one shipped until 2026-12-06, single
policies exported before version 2)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from grip.assets import SHIPPED_POLICY
from policies.controller import Controller, combine, load_controller
from policies.ensemble import PolicyEnsemble, member_payloads
from policies.runner import FORMAT, LEGACY_ENSEMBLE_FORMAT, PolicyRunner, read_policy_file
from policies.symmetry import MirrorAveragedPolicy

pytestmark = pytest.mark.skipif(not Path(SHIPPED_POLICY).is_file(), reason="no shipped policy")


def _obs(runner: PolicyRunner, shift: float = 0.5) -> dict:
    """An observation near the policy's normaliser mean (no environment needed)."""
    rng = np.random.default_rng(0)
    return {k: np.asarray(runner.obs_mean[k]) + shift * np.sqrt(runner.obs_var[k])
            * rng.standard_normal(runner.obs_mean[k].shape) for k in runner.obs_keys}  # fmt: skip


def test_an_ensemble_of_the_old_layout_loads_as_before(ensemble_policy) -> None:
    raw = torch.load(ensemble_policy, weights_only=True)
    assert raw["format"] == LEGACY_ENSEMBLE_FORMAT  # written before version 2
    ctrl = load_controller(ensemble_policy)
    assert isinstance(ctrl, PolicyEnsemble) and isinstance(ctrl, Controller)
    assert len(ctrl.members) == len(raw["members"]) and ctrl.disc is not None
    obs = _obs(ctrl.members[0])
    mean = np.mean([m.act(obs) for m in ctrl.members], axis=0)
    np.testing.assert_allclose(ctrl.act(obs), mean, atol=1e-5)


def test_new_files_hold_a_list_of_members_and_act_as_the_old_ones(
        tmp_path: Path, ensemble_policy) -> None:  # fmt: skip
    old = load_controller(ensemble_policy)
    obs = _obs(old.members[0])
    # a single policy exported before version 2 (the policy at the top level) still loads
    payload, _ = member_payloads(ensemble_policy)[0]
    v1 = tmp_path / "v1.pt"
    torch.save({**payload, "format": FORMAT, "version": 1}, v1)
    single = load_controller(v1)
    assert isinstance(single, PolicyRunner) and single.disc is not None
    np.testing.assert_allclose(single.act(obs), old.members[0].act(obs), atol=1e-6)
    # ... and rewritten, it is a file of one member in the one layout
    one = tmp_path / "one.pt"
    assert combine([v1], one, member=0)[1] == 1
    raw = torch.load(one, weights_only=True)
    assert raw["format"] == FORMAT and raw["version"] == 2 and len(raw["members"]) == 1
    assert "format" not in raw["members"][0]
    np.testing.assert_allclose(PolicyRunner.load(one).act(obs), single.act(obs), atol=1e-6)
    # the ensemble rewritten as stored acts as the old file does, member for member
    ens = tmp_path / "ens.pt"
    assert combine([ensemble_policy], ens, precision="fp32")[1] == len(old.members)
    members, names = read_policy_file(ens)
    assert len(members) == len(names) == len(old.members)
    assert "disc" in members[0] and all("disc" not in m for m in members[1:])
    new = load_controller(ens)
    np.testing.assert_allclose(new.act(obs), old.act(obs), atol=1e-5)
    assert new.info["members"] == [f"{ens} (member {i}: {n})" for i, n in enumerate(names)]
    width = old.env_cfg.amp_window * int(members[0]["amp_frame_dim"])
    amp = np.random.default_rng(1).standard_normal((3, width)).astype(np.float32)
    np.testing.assert_allclose(new.fall_probability(amp), old.fall_probability(amp), atol=1e-6)


def test_mirror_averaging_is_an_option_of_loading(ensemble_policy) -> None:
    ens = load_controller(ensemble_policy)
    sites = ("L_Wrist", "R_Wrist", "L_Foot", "R_Foot")
    mir = load_controller(ensemble_policy, mirror=(sites, True))
    assert isinstance(mir, MirrorAveragedPolicy) and isinstance(mir, Controller)
    assert mir.info["mirror_averaged"] and mir.env_cfg == ens.env_cfg
    obs = _obs(ens.members[0])
    want = 0.5 * (ens.act(obs) + mir.mirror.action(ens.act(mir.mirror.observation(obs))))
    np.testing.assert_allclose(mir.act(obs), want, atol=1e-6)


def test_refusals_name_the_file(tmp_path: Path, ensemble_policy) -> None:
    junk = tmp_path / "junk.pt"
    torch.save({"format": "something-else"}, junk)
    with pytest.raises(ValueError, match=r"junk\.pt: not a GRIP policy file"):
        load_controller(junk)
    empty = tmp_path / "empty.pt"
    torch.save({"format": FORMAT, "version": 2, "members": [], "names": "[]"}, empty)
    with pytest.raises(ValueError, match=r"empty\.pt: policy file without its list"):
        load_controller(empty)
    n = len(read_policy_file(ensemble_policy)[0])
    with pytest.raises(ValueError, match=f"an ensemble of {n} policies"):
        PolicyRunner.load(ensemble_policy)
    with pytest.raises(ValueError, match="no policy file given"):
        load_controller([])
    with pytest.raises(ValueError, match="how='median'"):
        combine([SHIPPED_POLICY], tmp_path / "x.pt", how="median")  # type: ignore[arg-type]
    assert not (tmp_path / "x.pt").exists()
