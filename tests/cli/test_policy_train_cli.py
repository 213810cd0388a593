"""The ``grip policy`` commands end to end on the dataset of three real shared clips
(``conftest.built``; in-process, small): training on its references, evaluation, export,
ensembles and distillation. The ``grip data`` and ``grip kin`` commands: test_data_cli.py."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

from grip.assets import SHIPPED_KIN
from grip.cli.main import main
from grip.core.reference import ReferenceSet

MOTIONS = Path(__file__).resolve().parents[2].parent / "shared" / "data" / "motions"
pytestmark = pytest.mark.skipif(not MOTIONS.is_dir(), reason="shared motion clips not found")


def test_train_policy_eval_policy_and_export(built: Path, tmp_path: Path, capsys,
                                             tiny_policy_settings) -> None:  # fmt: skip
    run = tmp_path / "policy"
    args = ["policy", "train", "--data", str(built), "--out", str(run), *tiny_policy_settings]
    assert main(args) == 0
    cfg = json.loads((run / "config.json").read_text())
    assert cfg["config"]["ppo"]["net_arch"] == [16] and "git" in cfg and "kin" in cfg
    assert (run / "policy.pt").is_file() and (run / "curves.png").is_file()
    assert main([*args, "--set", "stage2.timesteps=128"]) == 0  # extends the finished run
    done = [*args[:-2], "--set", "stage2.timesteps=128"]
    assert main([*done, "--set", "ppo.learning_rate=1e-4"]) == 0  # optimiser settings may change
    assert main([*done, "--set", "ppo.net_arch=[32]"]) == 2  # the network may not: refused
    assert "ppo.net_arch" in capsys.readouterr().err
    assert main([*done, "--init-member", "1"]) == 2  # a member of no --init file
    assert "give --init too" in capsys.readouterr().err
    exported = tmp_path / "small.pt"
    assert main(["policy", "export", str(run), "--out", str(exported)]) == 0
    js = tmp_path / "eval.json"
    assert main(["policy", "eval", "--policy", str(exported), "--data", str(built), "--split",
                 "all", "--segment-frames", "100", "--segments", "2", "--json", str(js),
                 "--out", str(tmp_path / "ev")]) == 0  # fmt: skip
    res = json.loads(js.read_text())
    for key in ("success_rate", "MPJPE_mm", "PA_MPJPE_mm", "FS_mps", "FP_mm", "vGRF_N"):
        assert key in res
    assert res["segments"] == 2
    assert main(["policy", "eval", "--policy", str(tmp_path / "none.pt"), "--data",
                 str(built)]) == 2  # fmt: skip
    # replays under action noise: each one's success rate, their mean (the pooled rate) and sd
    rep = ["policy", "eval", "--policy", str(exported), "--data", str(built), "--split", "all",
           "--segment-frames", "100", "--segments", "2", "--json", str(js)]  # fmt: skip
    assert main([*rep, "--repeats", "3", "--action-noise", "1", "--out", str(tmp_path / "r")]) == 0
    res = json.loads(js.read_text())
    assert len(res["success_rate_replays"]) == 3 and res["segments"] == 6
    assert res["success_rate_mean"] == pytest.approx(res["success_rate"])
    assert res["success_rate_sd"] >= 0 and "success over 3 replays" in capsys.readouterr().out
    head = (tmp_path / "r" / "segments.csv").read_text().splitlines()
    assert head[0].split(",")[1] == "replay" and len(head) == 7
    assert main([*rep, "--repeats", "2"]) == 2  # deterministic replays would be identical
    assert "--action-noise" in capsys.readouterr().err
    # an int8 export is smaller than the fp16 one and evaluates
    small = tmp_path / "int8.pt"
    assert main(["policy", "export", str(run), "--out", str(small), "--precision", "int8"]) == 0
    assert small.stat().st_size < exported.stat().st_size
    # an ensemble: from repeated --policy, or from one 'grip policy combine' file
    ens = tmp_path / "ens.pt"
    # (the exports' own precision: same actions)
    assert main(["policy", "combine", str(exported), str(run / "policy.pt"), "--out", str(ens),
                 "--precision", "fp16"]) == 0  # fmt: skip
    js2 = tmp_path / "eval2.json"
    assert main(["policy", "eval", "--policy", str(exported), "--policy", str(run / "policy.pt"),
                 "--data", str(built), "--split", "all", "--segment-frames", "100",
                 "--segments", "2", "--json", str(js2)]) == 0  # fmt: skip
    assert main(["policy", "eval", "--policy", str(ens), "--data", str(built), "--split", "all",
                 "--segment-frames", "100", "--segments", "2", "--json", str(js)]) == 0  # fmt: skip
    assert js.read_text() == js2.read_text()
    assert main(["policy", "eval", "--policy", str(ens), "--mirror", "--data", str(built),
                 "--split", "all", "--segment-frames", "100", "--segments", "2",
                 "--json", str(js2)]) == 0  # fmt: skip
    assert json.loads(js2.read_text())["segments"] == 2
    assert main(["policy", "combine", str(exported), "--out", str(tmp_path / "one.pt")]) == 2
    assert "at least two" in capsys.readouterr().err
    # a member written out alone acts as the ensemble's member (with the file's fall detector)
    from policies.controller import load_controller

    one = tmp_path / "member1.pt"
    assert main(["policy", "combine", str(ens), "--member", "1", "--out", str(one)]) == 0
    alone, whole = load_controller(one), load_controller(ens)
    assert alone.disc is not None and alone.critic is None
    for a, b in zip(alone.actor.state_dict().values(), whole.members[1].actor.state_dict().values(),
                    strict=True):  # fmt: skip
        assert a.equal(b)
    assert main(["policy", "combine", str(ens), "--member", "2", "--out",
                 str(tmp_path / "m2.pt")]) == 2  # fmt: skip
    assert "no member 2" in capsys.readouterr().err and not (tmp_path / "m2.pt").exists()
    # two KinematicsNets: the references hold every training recording once per estimator
    kin = str(SHIPPED_KIN)
    two = tmp_path / "policy_two_kin"
    argv = [*args[:4], "--out", str(two), *args[6:], "--kin", kin, "--kin", kin,
            "--set", "mirror_references=true"]  # fmt: skip
    assert main(argv) == 0
    one = ReferenceSet.load(run / "reference_train.npz")
    both = ReferenceSet.load(two / "reference_train.npz")
    names = [*(c.name for c in one.clips), *(f"{c.name}#1" for c in one.clips)]
    assert [c.name for c in both.clips] == [*names, *(f"{n}~mirror" for n in names)]
    resolved = str(Path(kin).resolve())
    assert json.loads((two / "config.json").read_text())["kin"] == [resolved, resolved]
    # reconstruct: npz + exports per recording, summary, resume, errors named
    recs = sorted((built / "sequences").glob("*.npz"))[:2]
    out = tmp_path / "recon"
    argv = ["reconstruct", *map(str, recs), "--out", str(out), "--policy", str(ens),
            "--max-frames", "60", "--formats", "npz,bvh,png"]  # fmt: skip
    assert main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert len(summary["recordings"]) == 2 and summary["history_frames"] == 30
    from grip.core.reconstruction import Reconstruction

    for row in summary["recordings"]:
        assert len(row["written"]) == 3 and all(Path(w).is_file() for w in row["written"])
        r = Reconstruction.load(row["written"][0])
        assert r.n_frames == 60 and r.method == "grip" and r.grf.shape == (60, 2, 3)
    capsys.readouterr()
    assert main(argv) == 0 and "2 already done" in capsys.readouterr().out
    assert main(["reconstruct", str(tmp_path / "missing.npz"), "--out", str(out),
                 "--policy", str(exported)]) == 2  # fmt: skip
    assert "missing.npz" in capsys.readouterr().err
    assert main([*argv[:-1], "npz,gif"]) == 2
    # the demo: the bundled sample with GRIP and the four other methods, the stream, exports
    demo = tmp_path / "demo"
    assert main(["demo", "--out", str(demo), "--policy", str(exported), "--no-video"]) == 0
    table = (demo / "metrics.md").read_text()
    assert all(f"| {m} |" in table for m in ("grip", "kinematics", "kin+pip", "transpose", "pip"))
    out = capsys.readouterr().out
    assert "frames pushed" in out
    assert len(list(demo.glob("*.npz"))) == 5 and len(list(demo.glob("*.png"))) == 1
    assert len(list(demo.glob("*.bvh"))) == 1 and len(list(demo.glob("*.glb"))) == 1
    # then the held-out clip with props: the steps in the scene and in the viewer
    assert "3 object(s) in the scene: prop_00 top 0.23 m" in out
    table = (demo / "props" / "metrics.md").read_text()
    assert all(f"| {m} |" in table for m in ("grip", "kinematics", "kin+pip"))
    assert "transpose" not in table and len(list((demo / "props").glob("*.npz"))) == 3
    html = next((demo / "props").glob("*.html")).read_text()
    assert "prop_02" in html


def test_policy_holdout_clips_are_kept_out_of_training_and_evaluated(
    built: Path, tmp_path: Path, capsys, tiny_policy_settings
) -> None:
    data = tmp_path / "data"  # the fixture's dataset with all three clips in training
    shutil.copytree(built, data)
    split = json.loads((data / "split.json").read_text())
    split["train"], split["test"] = sorted(split["train"] + split["test"]), []
    (data / "split.json").write_text(json.dumps(split))
    run = tmp_path / "held"
    args = ["policy", "train", "--data", str(data), "--out", str(run), *tiny_policy_settings,
            "--set", "holdout_fraction=0.5"]  # fmt: skip
    assert main(args) == 0
    held = json.loads((run / "holdout.json").read_text())["sequences"]
    train = split["train"]
    assert held and set(held) < set(train)  # some, not all, of the training sequences
    ref = ReferenceSet.load(run / "reference_train.npz")
    assert len(ref.clips) == len(train) - len(held)  # one clip per training recording
    exported = tmp_path / "held.pt"
    assert main(["policy", "export", str(run), "--out", str(exported)]) == 0
    js = tmp_path / "held.json"
    assert main(["policy", "eval", "--policy", str(exported), "--data", str(data), "--split",
                 "holdout", "--segment-frames", "100", "--json", str(js)]) == 0  # fmt: skip
    assert json.loads(js.read_text())["segments"] >= 1
    # a policy trained on every clip has no validation split: a clear error
    assert main(["policy", "train", "--data", str(data), "--out", str(tmp_path / "all"),
                 *tiny_policy_settings]) == 0  # fmt: skip
    assert main(["policy", "eval", "--policy", str(tmp_path / "all" / "policy.pt"), "--data",
                 str(data), "--split", "holdout"]) == 2  # fmt: skip
    assert "no clips were held out" in capsys.readouterr().err
    assert main([*args, "--set", "holdout_fraction=1.5"]) == 2  # out of range: refused
    everything = ["policy", "train", "--data", str(data), "--out", str(tmp_path / "none"),
                  *tiny_policy_settings, "--set", "holdout_fraction=0.99"]  # fmt: skip
    assert main(everything) == 2 and "nothing to train on" in capsys.readouterr().err


def test_time_reversed_motions_join_the_policy_references(
    built: Path, tmp_path: Path, capsys, tiny_policy_settings
) -> None:
    import numpy as np

    from grip.dataset.augment import time_reversed_recordings
    from grip.dataset.build import safe_name
    from grip.motion.motion import Motion
    from prism_tools.io import load_recording

    manifest = json.loads((built / "manifest.json").read_text())
    split = json.loads((built / "split.json").read_text())
    clip = next(c for c in manifest["clips"] if len(c["sequences"]) == 1
                and c["sequences"][0] in split["train"])  # fmt: skip
    fwd = Motion.load(built / "motions" / f"{safe_name(clip['clip_id'])}.npz")
    back = fwd.time_reversed()  # played backwards; twice gives the clip back
    np.testing.assert_array_equal(back.root_pos, fwd.root_pos[::-1])
    assert back.category == f"{fwd.category}-reversed" and back.meta["time_reversed"]
    again = back.time_reversed()
    np.testing.assert_array_equal(again.local_quat, fwd.local_quat)
    assert again.category == fwd.category and not again.meta["time_reversed"]
    recs = time_reversed_recordings(built, split["train"], [clip["category"]])
    mine = [r for r in recs if r.name.startswith(f"synthetic_{clip['clip_id']}-reversed_seq")]
    assert len(mine) == len(clip["sequences"]) and mine[0].category.endswith("-reversed")
    # the reversed sensors' ground truth: positions backwards, velocities negated (central
    # differences), the same accelerations (even in time)
    orig = load_recording(built / "sequences" / f"{clip['sequences'][0]}.npz")
    n = min(orig.n_frames, mine[0].n_frames)
    assert n == orig.n_frames > 2
    g, h = orig.imu_gt["L_Foot"], mine[0].imu_gt["L_Foot"]
    np.testing.assert_allclose(h.pos_world, g.pos_world[::-1], atol=1e-5)
    np.testing.assert_allclose(h.vel_world[1:-1], -g.vel_world[::-1][1:-1], atol=1e-3)
    np.testing.assert_allclose(h.acc_world[1:-1], g.acc_world[::-1][1:-1], atol=1e-2)
    # only clips with a sequence among those given contribute (a test clip never does)
    others = time_reversed_recordings(built, split["test"], [clip["category"]])
    assert not any(r.name.startswith(f"synthetic_{clip['clip_id']}-") for r in others)
    bare = tmp_path / "bare"  # a dataset without its motions: the missing file is named
    bare.mkdir()
    shutil.copy(built / "manifest.json", bare / "manifest.json")
    with pytest.raises(ValueError, match=r"motions/.*\.npz: motion file of clip"):
        time_reversed_recordings(bare, split["train"], [clip["category"]])
    with pytest.raises(ValueError, match="manifest"):
        time_reversed_recordings(tmp_path, split["train"], ["*"])
    # grip policy distill's reference set: the reversed recordings join the references once
    from grip.cli.errors import CliError
    from grip.cli.policy_runs import build_training_reference
    from grip.cli.recordings import kin_checkpoint, split_paths

    ref_path, files = tmp_path / "rev.npz", split_paths(built, "train")
    build_training_reference(ref_path, built, files, [kin_checkpoint(None)], (clip["category"],))
    names = [c.name for c in ReferenceSet.load(ref_path).clips]
    assert len(names) == len(split["train"]) + len(recs)
    assert sum(n.endswith(tuple(f"-reversed_seq{i:03d}" for i in range(9))) for n in names) \
        == len(recs)  # fmt: skip
    assert "time-reversed recordings" in capsys.readouterr().out
    with pytest.raises(CliError, match="no training clip"):
        build_training_reference(tmp_path / "none.npz", built, files, [kin_checkpoint(None)],
                                 ("no-such-category",))  # fmt: skip


def test_both_references_hold_each_clip_with_its_estimate_and_its_truth(built, tmp_path):
    """``follow = "both"`` (and ``grip policy distill``'s ``truth_references``): every training
    clip twice, the second named ``#truth`` with the ground truth as its estimate."""
    from grip.cli.policy_runs import build_training_reference
    from grip.cli.recordings import kin_checkpoint, split_paths

    files = split_paths(built, "train")
    ref_path = tmp_path / "both.npz"
    build_training_reference(ref_path, built, files, [kin_checkpoint(None)], follow="both")
    clips = {c.name: c for c in ReferenceSet.load(ref_path).clips}
    est = [n for n in clips if not n.endswith("#truth")]
    assert len(est) == len(files) and sorted(clips) == sorted(est + [f"{n}#truth" for n in est])
    for n in est:
        a, b = clips[n], clips[f"{n}#truth"]
        np.testing.assert_array_equal(a.gt_qpos, b.gt_qpos)
        np.testing.assert_allclose(b.est_rot, b.gt_rot, atol=1e-5)  # the truth is the reference
        assert np.abs(a.est_rot - a.gt_rot).max() > 1e-2  # the estimate is not


TINY_DISTILL = ["--set", "iterations=2", "--set", "decisions_per_iteration=64",
                "--set", "n_envs=2", "--set", "max_samples=256", "--set", "categories=[]",
                "--set", "reverse_categories=[]", "--set", "mirror_references=false",
                "--set", "max_episode_frames=40", "--set", "epochs=30",
                "--set", "batch_size=64", "--set", "learning_rate=1e-2"]  # fmt: skip
"""A DAgger run of a few seconds (``grip policy distill`` settings)."""


def test_distill_policy_learns_the_ensembles_action_resumes_and_refuses(
    built: Path, tmp_path: Path, capsys, tiny_policy_settings
) -> None:
    import numpy as np
    import torch

    from policies.controller import load_controller

    pols = []
    for seed in (0, 1):  # two tiny policies that act differently: the teacher is their mean
        run = tmp_path / f"p{seed}"
        assert main(["policy", "train", "--data", str(built), "--out", str(run),
                     *tiny_policy_settings, "--set", f"seed={seed}"]) == 0  # fmt: skip
        pols.append(run / "policy.pt")
    # member 0 pushes every action by +0.4: the mean action is member 1's + 0.2
    from grip.nn.weights import pack_weights
    from policies.runner import linear_layers

    payload = torch.load(pols[0], weights_only=True)
    shifted = load_controller(pols[0])
    with torch.no_grad():
        linear_layers(shifted.actor)[-1].bias += 0.4
    payload["members"][0]["actor"] = pack_weights(shifted.actor.state_dict(), "fp32")
    pols[0] = tmp_path / "shifted.pt"
    torch.save(payload, pols[0])
    out = tmp_path / "distill"
    args = ["policy", "distill", "--teacher", str(pols[0]), "--teacher", str(pols[1]),
            "--data", str(built), "--out", str(out), *TINY_DISTILL,
            "--set", "init_member=1"]  # fmt: skip
    assert main(args) == 0
    state = json.loads((out / "checkpoint" / "state.json").read_text())
    hist = state["history"]
    assert state["iteration"] == 2 and [h["iteration"] for h in hist] == [1, 2]
    assert [h["beta"] for h in hist] == [1.0, 0.5] and all(h["decisions"] == 64 for h in hist)
    # the student starts as member 1 and ends much closer to the members' mean action
    assert hist[0]["onpolicy_mse"] > 0 and hist[-1]["fit_mse"] < 0.5 * hist[0]["onpolicy_mse"]
    assert sorted(p.name for p in (out / "data").iterdir()) == ["iter_000.npz", "iter_001.npz"]
    assert (out / "curves.png").read_bytes()[:4] == b"\x89PNG"
    student, teacher = load_controller(out / "policy.pt"), load_controller(pols[1])
    assert json.loads((out / "config.json").read_text())["config"]["init_member"] == 1
    assert student.info["distilled"]["iterations"] == 2 and student.disc is not None
    assert student.obs_keys == teacher.obs_keys and np.allclose(student._mean, teacher._mean)
    changed = [not a.equal(b) for a, b in zip(student.actor.state_dict().values(),
                                              teacher.actor.state_dict().values(),
                                              strict=True)]  # fmt: skip
    assert any(changed)
    with np.load(out / "data" / "iter_001.npz") as z:  # teacher labels of the student's states
        x, y = torch.from_numpy(z["x"]).float(), z["y"].astype(np.float32)
    both = load_controller(pols[0]), teacher
    with torch.no_grad():  # (x holds member 1's normalised inputs: member 1 acts on it directly)
        a1 = np.clip(both[1].actor(x).numpy(), -1, 1)
    assert np.abs(a1 - y).max() > 1e-3  # the label is not member 1's own action
    # resume: more iterations continue the run; other settings are refused by name
    assert main([*args, "--set", "iterations=3"]) == 0
    state = json.loads((out / "checkpoint" / "state.json").read_text())
    assert state["iteration"] == 3
    assert [h["samples"] for h in state["history"]] == [64, 128, 192]  # the resumed fit read
    # the earlier iterations' files
    assert len(list((out / "data").glob("iter_*.npz"))) == 3
    capsys.readouterr()
    assert main([*args, "--set", "iterations=3", "--set", "beta_decay=0.9"]) == 2
    assert "beta_decay" in capsys.readouterr().err
    rec = json.loads((out / "config.json").read_text())  # a run from before a setting existed
    del rec["config"]["action_noise"]
    (out / "config.json").write_text(json.dumps(rec))
    assert main([*args, "--set", "iterations=3"]) == 0  # resumes: the new setting's default
    assert main([*args, "--set", "iterations=3", "--set", "action_noise=0.2"]) == 2
    # the distilled file plays like any policy; bad members and teachers are named
    js = tmp_path / "d.json"
    assert main(["policy", "eval", "--policy", str(out / "policy.pt"), "--data", str(built),
                 "--split", "all", "--segment-frames", "100", "--segments", "1",
                 "--json", str(js)]) == 0  # fmt: skip
    assert json.loads(js.read_text())["segments"] == 1
    bad = ["policy", "distill", "--teacher", str(pols[0]), "--data", str(built), "--out",
           str(tmp_path / "d2"), *TINY_DISTILL]  # fmt: skip
    assert main([*bad, "--set", "init_member=3"]) == 2
    assert "init_member 3" in capsys.readouterr().err
    assert main([*bad[:3], str(tmp_path / "none.pt"), *bad[4:]]) == 2
    assert "none.pt" in capsys.readouterr().err
    assert main([*bad, "--set", "beta0=2"]) == 2
    assert main([*bad, "--set", "action_noise=-1"]) == 2
    # truth_references: the student's rollouts also follow the ground truth of every clip
    mixed = tmp_path / "d_truth"
    assert main(["policy", "distill", "--teacher", str(pols[1]), "--data", str(built), "--out",
                 str(mixed), *TINY_DISTILL, "--set", "iterations=1",
                 "--set", "truth_references=true"]) == 0  # fmt: skip
    names = [c.name for c in ReferenceSet.load(mixed / "reference_train.npz").clips]
    assert len(names) == 2 * sum(n.endswith("#truth") for n in names) > 0
    # the data kept: the newest max_samples, across iterations
    from envs.factory import make_tracking_env
    from policies.distill import DistillConfig, Distiller

    keep = Distiller(DistillConfig(decisions_per_iteration=64, max_samples=256), [pols[1]],
                     tmp_path / "keep", out / "reference_train.npz", make_tracking_env)  # fmt: skip
    for i in range(4):
        xa, ya = keep._add_data(np.full((100, 3), i, np.float16), np.full((100, 2), i, np.float16))
    values, counts = np.unique(xa[:, 0], return_counts=True)  # iteration 0's samples are gone
    assert len(xa) == 256 and values.tolist() == [1, 2, 3] and counts.tolist() == [56, 100, 100]
    assert (ya[:, 0] == xa[:, 0]).all() and np.shares_memory(xa, keep._add_data(xa[:0], ya[:0])[0])
    # noise on the played actions moves the rollouts off the teacher's own states
    noisy = tmp_path / "noisy"
    assert main([*args[:9], str(noisy), *TINY_DISTILL, "--set", "init_member=1",
                 "--set", "iterations=1", "--set", "action_noise=0.5"]) == 0  # fmt: skip
    with np.load(out / "data" / "iter_000.npz") as a, np.load(noisy / "data" / "iter_000.npz") as b:
        assert a["x"].shape == b["x"].shape and not np.array_equal(a["x"], b["x"])
        np.testing.assert_array_equal(a["x"][:2], b["x"][:2])  # the same first states


def test_a_teacher_run_follows_the_ground_truth(built: Path, tmp_path: Path, capsys,
                                                tiny_policy_settings) -> None:  # fmt: skip
    """``follow = "truth"`` (configs/policy/teacher.toml): the run's references are the ground
    truth with the KinematicsNet's sensor features, the export says so, and ``grip policy eval``
    notes that such a policy is judged with ``--reference truth``."""
    import numpy as np

    from grip.assets import REPO_ROOT
    from grip.cli.recordings import load_recordings, split_paths
    from grip.kinematics.features import targets
    from policies.controller import load_controller

    run = tmp_path / "teacher"
    args = ["policy", "train", "--data", str(built), "--out", str(run), "--config",
            str(REPO_ROOT / "configs" / "policy" / "teacher.toml"), *tiny_policy_settings,
            "--set", "stage1.termination_anneal_steps=0"]  # fmt: skip
    assert main(args) == 0
    assert json.loads((run / "config.json").read_text())["config"]["follow"] == "truth"
    ref = ReferenceSet.load(run / "reference_train.npz")
    (rec,) = load_recordings(split_paths(built, "train"))
    (clip,) = ref.clips
    t = targets(rec)
    np.testing.assert_allclose(clip.est_pos, t.joint_pos, atol=1e-6)
    np.testing.assert_allclose(clip.est_hinge, clip.gt_qpos[:, 7:], atol=1e-5)
    assert "ground truth as the reference" in capsys.readouterr().err

    assert load_controller(run / "policy.pt").info["follow"] == "truth"
    ev = ["policy", "eval", "--policy", str(run / "policy.pt"), "--data", str(built), "--split",
          "train", "--segment-frames", "60", "--segments", "1",
          "--out", str(tmp_path / "ev")]  # fmt: skip
    assert main(ev) == 0
    assert "judged on its task with --reference truth" in capsys.readouterr().out
    assert main([*ev, "--reference", "truth"]) == 0
    assert "--reference truth" not in capsys.readouterr().out
    assert main([*args, "--set", "follow=nothing"]) == 2
    assert "follow must be one of" in capsys.readouterr().err
    # distilled into a student that follows the estimate: the teacher acts on the truth's
    # observation of the student's states, its action shifted to the estimate's targets
    import torch

    out = tmp_path / "student"
    dist = ["policy", "distill", "--teacher", str(run / "policy.pt"), "--data", str(built),
            "--out", str(out), *TINY_DISTILL]  # fmt: skip
    assert main(dist) == 0
    student, teacher = load_controller(out / "policy.pt"), load_controller(run / "policy.pt")
    assert "follow" not in student.info
    stored = torch.load(out / "policy.pt", weights_only=True)["members"][0]["config"]
    assert json.loads(stored)["follow"] == "estimate"
    with np.load(out / "data" / "iter_000.npz") as z:  # beta0 = 1: the teacher's own rollout
        x, y = torch.from_numpy(z["x"]).float(), z["y"].astype(np.float32)
    with torch.no_grad():  # (the student's inputs are normalised as the teacher's)
        on_estimate = np.clip(teacher.actor(x).numpy(), -1, 1)
    assert np.abs(on_estimate - y).max() > 1e-2  # the labels are not its action on the estimate
    # a teacher whose members follow different references is refused
    plain = tmp_path / "plain"
    assert main(["policy", "train", "--data", str(built), "--out", str(plain),
                 *tiny_policy_settings]) == 0  # fmt: skip
    assert main(["policy", "distill", "--teacher", str(run / "policy.pt"), "--teacher",
                 str(plain / "policy.pt"), "--data", str(built), "--out",
                 str(tmp_path / "mixed"), *TINY_DISTILL]) == 2  # fmt: skip
    assert "follow different references" in capsys.readouterr().err


@pytest.mark.parametrize("setting", ["env.root_speed_range=[0.9,1.1]",
                                     "env.lean_range_deg=[-5,5]"])
def test_the_warp_backend_refuses_the_cpu_augmentations(tmp_path: Path, capsys,
                                                        setting: str) -> None:  # fmt: skip
    """``env.root_speed_range`` and ``env.lean_range_deg`` are built in the CPU environments
    only: ``--backend warp`` refuses them before anything is read or built."""
    args = ["policy", "train", "--data", str(tmp_path / "none"), "--out", str(tmp_path / "r"),
            "--backend", "warp", "--set", setting]  # fmt: skip
    assert main(args) == 2
    assert setting.split("=")[0] in capsys.readouterr().err
    assert not (tmp_path / "r").exists()
