"""``grip policy train|eval|export|combine|distill``: DynamicsNet, the controller."""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from pathlib import Path

from grip.cli.policy_runs import build_training_reference, training_files
from grip.cli.recordings import (
    add_init_argument,
    add_limit_arguments,
    add_pace_arguments,
    add_tta_argument,
    limits_from_args,
)


def add_parser(sub: argparse._SubParsersAction) -> None:
    """Register ``grip policy`` and its subcommands on the ``grip`` subparsers."""
    from grip.cli.common import PRECISIONS, add_group, add_output_arguments

    psub = add_group(sub, "policy", "train, evaluate, export, combine and distil DynamicsNet "
                     "policies", "The controller (DynamicsNet, PPO + AMP) that drives the MuJoCo "
                     "humanoid to follow the KinematicsNet estimate, and its policy files: one "
                     "file holds one policy or an ensemble of several "
                     "(policies/controller.py).")  # fmt: skip
    p = psub.add_parser(
        "train",
        help="train the DynamicsNet controller (PPO + AMP) on a dataset",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Train the controller that drives the torque-actuated humanoid to follow the\n"
            "KinematicsNet estimate: PPO (stable-baselines3) with GRIP's reward\n"
            "0.5 r_amp + 0.5 r_imit + r_energy, an AMP discriminator trained from each rollout,\n"
            "and GRIP's two stages (early termination at 0.25 m, then without, on longer\n"
            "episodes). The training motions are the dataset's train split with KinematicsNet\n"
            "estimates (made once, RUN/reference_train.npz). Checkpoints every few rollouts to\n"
            "RUN/checkpoint/; running the same command again resumes (a larger stage2.timesteps\n"
            "extends a finished run). At the end RUN/policy.pt is exported.\n"
            "TensorBoard: tensorboard --logdir RUN/tb"
        ),
        epilog="example: grip policy train --data data/prism_synth --out runs/policy\n"
        "         grip policy train --data data/prism_synth --out runs/p "
        "--set stage1.timesteps=500000\n"
        "         grip policy train --data data/prism_synth --out runs/grip_size "
        "--set 'ppo.net_arch=[2048,1536,1024,1024,512,512]'\n"
        "         grip policy train --data data/prism_synth --out runs/p_ft "
        "--init grip/assets/policy_default.pt --config configs/policy/finetune.toml",
    )
    p.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    p.add_argument("--out", required=True, type=Path, help="run folder (created or resumed)")
    p.add_argument("--kin", type=Path, action="append", default=None,
                   help="KinematicsNet checkpoint that makes the references (default: the "
                   "shipped one); repeat it to train on every recording estimated by each, "
                   "e.g. a weaker checkpoint whose errors on the training clips resemble the "
                   "shipped one's on unseen clips; the K fold models of a split by person "
                   "('grip kin train --set train.val_source=fold --set train.fold=k') make a "
                   "cross-fitted set instead: each recording estimated once, by the model that "
                   "never saw its person")  # fmt: skip
    p.add_argument("--config", type=Path, default=None,
                   help="TOML overrides (default: configs/policy/default.toml)")  # fmt: skip
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="override one setting, e.g. --set ppo.n_envs=16 (repeatable)")  # fmt: skip
    p.add_argument("--init", type=Path, default=None, metavar="POLICY",
                   help="warm start: begin from an exported policy (e.g. "
                   "grip/assets/policy_default.pt): its policy, value network (if the file has "
                   "one), observation normaliser and discriminator; an ensemble file gives its "
                   "first member (see --init-member); usually with --config "
                   "configs/policy/finetune.toml (ignored when OUT resumes)")  # fmt: skip
    p.add_argument("--init-member", type=int, default=0, metavar="K",
                   help="with an ensemble file as --init: start from its member K (0 = the "
                   "first, in the order 'grip policy combine' joined them; training prints "
                   "the member's name); later members take the file's discriminator")  # fmt: skip
    p.add_argument("--backend", choices=("cpu", "warp"), default="cpu",
                   help="cpu: MuJoCo C in ppo.n_envs environments, SB3's PPO (default); warp: "
                   "MuJoCo Warp with ppo.n_envs worlds on --device, observations, rewards, "
                   "rollout buffer, PPO and AMP updates as device tensors (pip install -e "
                   ".[gpu]; docs/gpu.md); the same run folder and policy file")  # fmt: skip
    p.add_argument("--device", choices=("cuda", "cpu", "auto"), default=None,
                   help="with --backend warp: the device of the worlds and the learner (sets "
                   "ppo.device; default auto: cuda where there is one)")  # fmt: skip
    from grip.cli.cluster import add_ray_argument, add_tune_arguments

    add_tune_arguments(p)
    p.set_defaults(func=cmd_train)

    e = psub.add_parser(
        "eval",
        help="evaluate a DynamicsNet policy on the test split (success rate, MPJPE, ...)",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Run full episodes of the controller on test segments (500 frames by default),\n"
            "each started from the ground truth at its first frame (--init standing: from the\n"
            "standing pose, as without motion capture) and following the KinematicsNet\n"
            "estimate, without fall recovery. A segment fails when the fall\n"
            "detector fires (pelvis below 0.30 m and discriminator probability below 0.7).\n"
            "Reports success rate, MPJPE, PA-MPJPE, foot sliding, foot penetration and vGRF\n"
            "error (the keys of 'grip bench'), and the kinematics-only MPJPE on the same\n"
            "segments."
        ),
        epilog="example: grip policy eval --data data/prism_synth --json policy_eval.json\n"
        "         grip policy eval --policy runs/policy/policy.pt --data data/prism_synth "
        "--category 'walk*' --category 'run*'",
    )
    e.add_argument("--policy", type=Path, action="append", default=None,
                   help="exported policy (default: the shipped one); repeat it to play the "
                   "mean action of several (an ensemble)")  # fmt: skip
    e.add_argument("--kin", type=Path, default=None,
                   help="KinematicsNet checkpoint (default: the shipped one)")  # fmt: skip
    e.add_argument("--mirror", action="store_true",
                   help="average each action with the mirror image of the action on the "
                   "mirrored observation (policies/symmetry.py)")  # fmt: skip
    e.add_argument("--data", required=True, type=Path, help="dataset folder (with split.json)")
    e.add_argument("--split", default="test", choices=("train", "test", "all", "holdout"),
                   help="dataset split; 'holdout': the training clips held out of the "
                        "policy's training (holdout_fraction), a validation split")  # fmt: skip
    e.add_argument("--category", action="append", default=[], metavar="GLOB",
                   help="only these motion categories (glob, repeatable)")  # fmt: skip
    e.add_argument("--segment-frames", type=int, default=500, help="frames per segment")
    e.add_argument("--stride", type=int, default=0, metavar="FRAMES",
                   help="start a segment every FRAMES frames (default: the segment length, no "
                   "overlap); e.g. 100 gives about 5x more, overlapping 500-frame segments, "
                   "for a success rate with less sampling noise")  # fmt: skip
    e.add_argument("--segments", type=int, default=0, help="at most this many segments (0: all)")
    e.add_argument("--batch", type=int, default=16, metavar="N",
                   help="segments played side by side, one controller forward per frame over "
                   "all of them (default 16; 1: one after another). Each segment's numbers are "
                   "those it gets alone up to the float32 rounding of a batched forward, which "
                   "a simulation can amplify; --action-noise draws its noise in another order "
                   "than with --batch 1")  # fmt: skip
    e.add_argument("--workers", type=int, default=1, metavar="K",
                   help="processes playing the batches of --batch N segments (segment i is in "
                   "batch i // N), one thread each (default 1: in this process; 2 on a "
                   "2-core machine). The rows are bit-identical whatever K is")  # fmt: skip
    e.add_argument("--reference", default="estimate", choices=("estimate", "truth"),
                   help="what the controller follows: the KinematicsNet estimate (default, the "
                   "method) or the ground truth (a perfect KinematicsNet; tells the "
                   "controller's own falls from those the estimate causes)")  # fmt: skip
    e.add_argument("--action-noise", type=float, default=0.0, metavar="SCALE",
                   help="sample actions with the policy's trained standard deviation times "
                   "SCALE (1: the exploration noise of training) instead of the mean action "
                   "(0, the default); a diagnostic")  # fmt: skip
    e.add_argument("--seed", type=int, default=0,
                   help="seed of the action noise (each batch of --batch N segments draws "
                   "from a generator of its own: SEED for the first, one derived from SEED "
                   "and its index for the others)")  # fmt: skip
    e.add_argument("--repeats", type=int, default=1, metavar="N",
                   help="replay every segment N times with --action-noise seeds SEED, SEED+1, "
                   "...: the table pools the replays, and the success rate of each, their mean "
                   "and standard deviation are printed and written to --json (how much a "
                   "success rate moves under a small perturbation; needs --action-noise > 0)",
                   )  # fmt: skip
    add_tta_argument(e)
    add_init_argument(e, "KinematicsNet (its LSTMs and integrated root) and the humanoid",
                      "; with --reference truth the humanoid still starts standing")  # fmt: skip
    add_pace_arguments(e)
    e.add_argument("--json", type=Path, default=None, help="write the overall figures here")
    e.add_argument("--out", type=Path, default=None,
                   help="folder for the per-segment CSV and the Markdown table")  # fmt: skip
    add_ray_argument(e, "batches of --batch N segments")
    add_limit_arguments(e)
    e.set_defaults(func=cmd_eval)

    x = psub.add_parser(
        "export",
        help="write the small inference file of a 'grip policy train' run, or an ONNX graph of "
        "a run or policy file",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "By the suffix of --out:\n"
            "  FILE.pt    policy MLP (fp16), observation normaliser, value network and AMP\n"
            "             discriminator of a run in one file loaded with\n"
            "             torch.load(weights_only=True): a policy file of one member, the form\n"
            "             every command that takes --policy reads\n"
            "  FILE.onnx  an ONNX graph of a run or of a policy file (one policy or an\n"
            "             ensemble): input 'obs' (B, N) float32, the observation parts\n"
            "             concatenated in the order of the metadata's obs_keys (obs_slices:\n"
            "             their columns); output 'action' (B, A) float32, the deterministic\n"
            "             action clipped to [-1, 1] (an ensemble: the mean of its members', each\n"
            "             member with its own normaliser). The observation normalisation is\n"
            "             inside the graph; float32 weights; no discriminator, no value network.\n"
            "             Needs the onnx package (docs/exports.md: running it with onnxruntime)\n"
            "With --checkpoint, --out is a folder: the run's resume state, packed (below)"
        ),
        epilog="example: grip policy export runs/policy --out runs/policy_fp16.pt\n"
        "         grip policy export grip/assets/policy_default.pt --out policy.onnx\n"
        "         grip policy export runs/teacher --checkpoint --out experiments/resume/T1",
    )
    x.add_argument("run", type=Path, metavar="RUN|POLICY",
                   help="'grip policy train' run folder; with --out FILE.onnx also a policy "
                   "file (e.g. grip/assets/policy_default.pt)")  # fmt: skip
    x.add_argument("--out", required=True, type=Path, metavar="FILE",
                   help="output, written atomically: FILE.pt (a policy file) or FILE.onnx (an "
                   "ONNX graph)")  # fmt: skip
    x.add_argument("--precision", choices=PRECISIONS, default=None,
                   help="weights of the policy, value and discriminator networks of a .pt: fp16 "
                   "(default), fp32, or int8 with a float32 scale per row (about a third of the "
                   "fp16 file; what an ensemble stores); an ONNX graph is fp32")  # fmt: skip
    x.add_argument("--checkpoint", action="store_true",
                   help="instead: write the run's resume state (config.json and checkpoint/) to "
                   "the folder --out with both optimisers' Adam moments in bfloat16 and "
                   "model.zip deflated (0.6 of the size; weights, normaliser, counters, miner "
                   "and history exact): what a long run commits between sessions; copy it to a "
                   "run folder and rerun 'grip policy train' to resume")  # fmt: skip
    x.add_argument("--overwrite", action="store_true",
                   help="with --checkpoint: replace the resume state of another run (or a "
                   "later one of this run) already in --out (refused without it)")  # fmt: skip
    x.set_defaults(func=cmd_export)

    c = psub.add_parser(
        "combine",
        help="join policy files into one: an ensemble, a weight average, or one member",
        formatter_class=argparse.RawDescriptionHelpFormatter,
        description=(
            "Write one policy file from the members of policy files (every file is a list of\n"
            "one or more members; a single policy is an ensemble of one):\n"
            "  default    an ensemble: the mean of the members' actions, each computed with its\n"
            "             own observation normaliser, so members may come from separate runs;\n"
            "             they must drive the humanoid alike (observations, action mode and\n"
            "             scale, decision period, body); the first member's discriminator is\n"
            "             the fall detector; value networks are left out ('grip policy train\n"
            "             --init' with the file starts from one member)\n"
            "  --average  the weight average of exports of one run (or its continuations):\n"
            "             PPO's exports swing from one checkpoint to the next, their average\n"
            "             sits between the swings; the last member's normaliser, discriminator\n"
            "             and settings are kept (policies/average.py)\n"
            "  --member K only member K (0 = the first, in the order given): its actor as\n"
            "             stored, its normaliser, its file's discriminator, no value network\n"
            "  --gate C   a gate over the files (policies/gate.py): every frame one of them\n"
            "             drives, the one a small classifier of the frame's sensor features\n"
            "             (the KinematicsNet's inputs: IMUs and insoles) and their last 0.6 s\n"
            "             (--gate-window) picks: the second file for the categories of the\n"
            "             first --gate, the third for the second's, ...; the first file for\n"
            "             every other motion. The classifier learns from the train split of\n"
            "             --data (its recordings and their categories; no simulation, about a\n"
            "             minute) and the routes it takes are printed per category for the\n"
            "             train and the test split"
        ),
        epilog="example: grip policy combine runs/a/policy.pt runs/b/policy.pt --out runs/ab.pt\n"
        "         grip policy combine runs/a.pt runs/b.pt --average --out runs/avg.pt\n"
        "         grip policy combine grip/assets/policy_default.pt --member 0 --out e.pt\n"
        "         grip policy combine walk.pt sit.pt --gate sit-stand,stairs --data data/mine "
        "--out gated.pt",
    )
    c.add_argument("policies", nargs="+", type=Path, help="policy files")
    how = c.add_mutually_exclusive_group()
    how.add_argument("--average", action="store_true",
                     help="the weight average of all members instead of their ensemble")
    how.add_argument("--member", type=int, default=None, metavar="K",
                     help="write only member K of all those of the files")  # fmt: skip
    how.add_argument("--gate", action="append", default=None, metavar="CATEGORY[,CATEGORY...]",
                     help="the category globs of the next file's motions (repeat it once per "
                     "file after the first): a gate over the files")  # fmt: skip
    from grip.cli import gate

    gate.add_arguments(c)
    add_output_arguments(c, None, "actor and discriminator weights: an ensemble stores int8 "
                         "with a scale per row by default, the others as the files store "
                         "them")  # fmt: skip
    c.set_defaults(func=cmd_combine)

    from grip.cli import distill

    distill.add_parser(psub)


def cmd_train(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from envs.factory import make_tracking_env
    from grip.cli.errors import CliError
    from grip.cli.paths import load_run_config
    from grip.cli.recordings import kin_checkpoint, split_paths
    from grip.core.rundir import RunDir
    from policies.config import PolicyRunConfig
    from policies.train import PolicyTrainer

    warp = args.backend == "warp"
    if args.device is not None and not warp:
        raise CliError("--device is the warp backend's: give --backend warp (the CPU trainer's "
                       "learner device is --set ppo.device=...)")  # fmt: skip
    if warp and (args.tune is not None or args.ray is not None):
        raise CliError("--backend warp trains on one device: --tune and --ray are not supported "
                       "with it")  # fmt: skip
    if args.tune is not None or args.ray is not None:
        from grip.cli.cluster import policy_metrics, tune_train

        def check(sets: list[str]) -> None:
            load_run_config(args.config, "policy", PolicyRunConfig(), [*args.set, *sets])

        return tune_train(args, check, policy_metrics, "reward/imit_pos", "max")
    cfg = load_run_config(args.config, "policy", PolicyRunConfig(), args.set)
    if warp:
        cfg = _warp_settings(cfg, args.device or "auto")
    if args.init is not None and not args.init.is_file():
        raise CliError(f"{args.init}: no such policy file")
    if args.init_member and args.init is None:
        raise CliError("--init-member picks a member of the --init file: give --init too")
    out: Path = args.out
    out.mkdir(parents=True, exist_ok=True)
    kins = [kin_checkpoint(k) for k in (args.kin or [None])]
    ref_path = out / "reference_train.npz"
    files = training_files(split_paths(args.data, "train"), cfg, out)
    build_training_reference(ref_path, args.data, files, kins, mirror=cfg.mirror_references,
                             follow=cfg.follow, speed_factors=tuple(cfg.speed_factors),
                             speed_categories=tuple(cfg.speed_categories))  # fmt: skip
    resuming = RunDir(out).has_checkpoint()
    if resuming:
        was = (RunDir(out).read_config() or {}).get("backend", "cpu")
        if was != args.backend:
            raise CliError(f"{out} was trained with --backend {was}: resume it with --backend "
                           f"{was} (or use another --out)")  # fmt: skip
    init = None if resuming else args.init
    try:  # (refuses to resume with settings other than RESUMABLE changed)
        if warp:
            from envs.warp.factory import make_warp_tracking_env
            from policies.warp.train import WarpPolicyTrainer

            trainer = WarpPolicyTrainer(cfg, out, ref_path, make_warp_tracking_env,
                                        progress=tqdm, init=init,
                                        init_member=args.init_member)  # fmt: skip
        else:
            trainer = PolicyTrainer(cfg, out, ref_path, make_tracking_env, progress=tqdm,
                                    init=init, init_member=args.init_member)  # fmt: skip
        # what the run started from: this call's --init, or on resume what config.json recorded
        began = (trainer.rundir.read_config() or {}) if resuming else {}
    except ValueError as e:
        raise CliError(str(e)) from e
    if args.init is not None and resuming:
        print(f"{out} resumes from its own checkpoint; --init {args.init} is ignored")
    if init is not None:
        began = {"init": str(init.resolve()), "init_member": args.init_member}
    kin = [str(k.resolve()) for k in kins] if len(kins) > 1 else str(kins[0].resolve())
    recorded = {k: began[k] for k in ("init", "init_member") if began.get(k) is not None}
    if trainer.init_members > 1:
        print(f"--init {init}: an ensemble of {trainer.init_members} policies; training starts "
              f"from its member {args.init_member}, {trainer.init_name} (ensemble files keep no "
              "value network: a fresh critic warms up first, ppo.critic_warmup_steps)")  # fmt: skip
    if warp:
        recorded["backend"] = "warp"
    trainer.rundir.write_config(cfg, data=str(args.data.resolve()), kin=kin, **recorded)
    t0 = time.perf_counter()
    try:
        trainer.train()
    except (ValueError, FileNotFoundError, NotImplementedError) as e:  # a warm-start file that
        # does not fit the run's settings, a refused or missing checkpoint file, or (warp)
        # settings MuJoCo Warp does not support yet
        raise CliError(str(e)) from e
    dt = time.perf_counter() - t0
    print(f"trained to {trainer.total_done()} steps ({trainer.wall_s():.0f} s of training in all; "
          f"this call {dt:.0f} s)")  # fmt: skip
    from policies.report import plot_curves
    from policies.runner import export_policy

    plot_curves(trainer.history, out / "curves.png")
    info = {"timesteps": trainer.total_done(), "wall_s": trainer.wall_s()}
    size = export_policy(out, out / "policy.pt", info=info)
    print(f"wrote {out / 'policy.pt'} ({size / 1e6:.1f} MB) and {out / 'curves.png'}")
    return 0


def _warp_settings(cfg, device: str):
    """``cfg`` for ``--backend warp``: ``ppo.device`` = ``device``, refused where MuJoCo Warp
    or the device is missing."""
    import dataclasses

    from envs.warp import warp_available
    from grip.cli.errors import CliError

    for key, off in (("root_speed_range", (1.0, 1.0)), ("lean_range_deg", (0.0, 0.0))):
        if tuple(getattr(cfg.env, key)) != off:
            raise CliError(f"env.{key} = {list(getattr(cfg.env, key))} is a setting of the CPU "
                           "environments only (WarpTrackingEnv follows the estimate as it is): "
                           f"train with --backend cpu, or leave it at {list(off)}")  # fmt: skip
    if not warp_available():
        raise CliError("--backend warp needs mujoco-warp and warp-lang: pip install -e .[gpu]")
    import warp as wp

    # (no banner and no line per kernel module loaded: the progress bar stays readable)
    wp.config.quiet = True
    wp.config.log_level = wp.LOG_WARNING
    if device != "cpu":
        import torch

        if not torch.cuda.is_available():
            if device == "cuda":
                raise CliError("--device cuda: torch sees no CUDA device here (--device cpu "
                               "runs MuJoCo Warp on the CPU, for checks, not speed)")  # fmt: skip
            device = "cpu"
        else:
            device = "cuda"
    return dataclasses.replace(cfg, ppo=dataclasses.replace(cfg.ppo, device=device))


def _export_checkpoint(args: argparse.Namespace) -> int:
    from grip.cli.errors import CliError
    from policies.checkpoint import pack_checkpoint

    try:
        sizes = pack_checkpoint(args.run, args.out, overwrite=args.overwrite)
    except (FileNotFoundError, ValueError) as e:
        raise CliError(str(e)) from e
    before = sum(f.stat().st_size for f in (args.run / "checkpoint").iterdir() if f.is_file())
    print(f"{args.out}: {sizes['total'] / 1e6:.1f} MB (checkpoint {before / 1e6:.1f} MB in "
          f"{args.run})")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    from grip.cli.common import write_artifact
    from grip.cli.errors import CliError
    from policies.runner import export_policy

    if args.checkpoint:
        if args.precision is not None:
            raise CliError("--precision is for a policy file, not with --checkpoint")
        return _export_checkpoint(args)
    if args.overwrite:
        raise CliError("--overwrite is for --checkpoint (a policy file is replaced atomically)")
    onnx = args.out.suffix.lower() == ".onnx"
    if not args.run.exists():
        raise CliError(f"{args.run}: no such run folder or policy file")
    if onnx and args.precision not in (None, "fp32"):
        raise CliError(f"--precision {args.precision}: an ONNX graph holds fp32 weights")
    if args.run.is_file() and not onnx:
        raise CliError(f"{args.run} is a policy file, already the inference file: --out "
                       "FILE.onnx converts it to ONNX ('grip policy combine --precision' "
                       "stores it at another precision)")  # fmt: skip

    def write_pt(out: Path, precision: str) -> int:
        from grip.core.limits import read_json_file

        state = read_json_file(args.run / "checkpoint" / "state.json", "training state")
        hist = state.get("history")
        last = hist[-1] if isinstance(hist, list) and hist and isinstance(hist[-1], dict) else {}
        return export_policy(args.run, out, precision=precision,
                             info={"timesteps": last.get("timesteps"),
                                   "wall_s": state.get("wall_s")})  # fmt: skip

    if not onnx:
        return write_artifact(args.out, lambda: write_pt(args.out, args.precision or "fp16"))

    def write_onnx() -> tuple[int, str]:
        import tempfile

        from grip.nn.onnx import read_metadata
        from policies.onnx import export_policy_onnx

        try:
            if args.run.is_dir():  # the run's policy file first, at full precision
                with tempfile.TemporaryDirectory() as tmp:
                    write_pt(Path(tmp) / "policy.pt", "fp32")
                    size, n = export_policy_onnx(Path(tmp) / "policy.pt", args.out,
                                                 source=str(args.run))  # fmt: skip
            else:
                size, n = export_policy_onnx(args.run, args.out)
            meta = read_metadata(args.out)
        except ImportError as e:
            raise CliError(str(e)) from e
        width = sum(json.loads(meta["obs_sizes"]).values())
        what = "one policy" if n == 1 else f"an ensemble of {n} policies"
        return size, (f", ONNX of {what}: obs ({width},) in the order "
                      f"{', '.join(json.loads(meta['obs_keys']))} -> action in [-1, 1]")

    return write_artifact(args.out, write_onnx)


def cmd_combine(args: argparse.Namespace) -> int:
    from grip.cli.common import write_artifact
    from policies.controller import combine

    if args.gate:
        from grip.cli.gate import cmd_gate

        return cmd_gate(args)
    if args.data is not None or args.kin is not None or args.gate_steps != 3000:
        from grip.cli.errors import CliError

        raise CliError("--data, --kin and --gate-steps belong to --gate")

    def write() -> tuple[int, str]:
        size, n = combine(args.policies, args.out, "average" if args.average else "ensemble",
                          args.member, args.precision)  # fmt: skip
        what = (f"member {args.member} of {', '.join(map(str, args.policies))}"
                if args.member is not None
                else f"the average of {len(args.policies)} policies" if args.average
                else f"an ensemble of {n} policies")  # fmt: skip
        return size, f", {what}"

    return write_artifact(args.out, write)


def cmd_eval(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from grip.assets import SHIPPED_POLICY
    from grip.cli.cluster import ray_args, ray_pool
    from grip.cli.errors import CliError
    from grip.cli.recordings import exit_status, kin_checkpoint, pace_keeper, skip_file
    from grip.eval.policy import (
        PolicySetup,
        evaluate_batches,
        markdown_table,
        summarize_rows,
        write_rows,
    )
    from grip.eval.segments import BenchError, list_segments, split_files

    limits_from_args(args)
    ray_args(args)
    pace = pace_keeper(args)
    pols = args.policy or [SHIPPED_POLICY]
    for p in pols:
        if not Path(p).is_file():
            raise CliError(f"{p}: no such policy file (train one with 'grip policy train')")
    pol = " + ".join(str(p) for p in pols)
    setup = PolicySetup(tuple(str(Path(p).resolve()) for p in pols),
                        str(kin_checkpoint(args.kin).resolve()), args.tta, args.mirror)  # fmt: skip
    try:
        runner, est = setup.build()
    except ValueError as e:
        raise CliError(str(e)) from e
    if args.repeats < 1:
        raise CliError(f"--repeats must be >= 1, got {args.repeats}")
    if args.repeats > 1 and args.action_noise <= 0:
        raise CliError("--repeats replays deterministic actions identically: give it "
                       "--action-noise SCALE > 0 (e.g. 0.1)")  # fmt: skip
    try:
        runner.use_action_noise(args.action_noise, args.seed)
    except ValueError as e:
        raise CliError(f"--action-noise with {pol}: {e}") from e
    if args.stride < 0:
        raise CliError(f"--stride must be >= 0, got {args.stride}")
    if args.batch < 1:
        raise CliError(f"--batch must be >= 1, got {args.batch}")
    if args.workers < 1:
        raise CliError(f"--workers must be >= 1, got {args.workers}")
    if runner.info.get("follow") == "truth" and args.reference != "truth":
        print(f"note: {pol} was trained to follow the ground truth (a privileged tracker, "
              "follow = \"truth\"); it is judged on its task with --reference truth")  # fmt: skip
    held = set(runner.info.get("holdout") or ()) if args.split == "holdout" else set()
    if args.split == "holdout" and not held:
        raise CliError(f"{pol}: no clips were held out of this policy's training (train "
                       "with --set holdout_fraction=0.1 for a validation split)")  # fmt: skip
    try:
        files = split_files(args.data, args.split, held)
    except (OSError, ValueError) as e:
        raise CliError(str(e)) from e
    if args.split == "holdout" and not files:
        raise CliError(f"{args.data}: its train split holds none of the {len(held)} "
                       f"sequences held out of {pol}'s training (other data?)")  # fmt: skip
    skipped: list[tuple[str, str]] = []  # unreadable files: reported, skipped, exit code 1
    unreadable: list[tuple[str, str]] = []
    try:
        segs = list_segments(files, args.segment_frames, args.category, unreadable,
                             stride=args.stride, limit=args.segments)  # fmt: skip
    except BenchError as e:
        raise CliError(str(e)) from e
    finally:
        for f, why in unreadable:
            skip_file(skipped, f, why)
    with ray_pool(args) as pool, tqdm(total=len(segs) * args.repeats, unit="seg",
                                      desc="episodes") as bar:  # fmt: skip
        try:
            got = evaluate_batches(setup, segs, args.batch, args.workers,
                                   reference=args.reference, init=args.init,
                                   action_noise=args.action_noise,
                                   seeds=[args.seed + i for i in range(args.repeats)],
                                   progress=bar.update, built=(runner, est),
                                   pool=pool, pace=pace)  # fmt: skip
        except BenchError as e:  # (a worker process died)
            raise CliError(str(e)) from e
    passes = got if args.repeats == 1 else [[dict(r, replay=i) for r in p]
                                            for i, p in enumerate(got)]  # fmt: skip
    rows = [r for p in passes for r in p]
    summary = summarize_rows(rows)
    print(markdown_table(summary))
    if args.repeats > 1:
        from grip.eval.report import replay_spread

        spread = replay_spread(passes)
        summary["overall"].update(spread)
        each = ", ".join(f"{v:.1f}" for v in spread["success_rate_replays"])
        print(f"success over {args.repeats} replays (--action-noise {args.action_noise}, seeds "
              f"{args.seed}..{args.seed + args.repeats - 1}): mean "
              f"{spread['success_rate_mean']:.1f} %, sd {spread['success_rate_sd']:.1f} "
              f"({each}); the table pools them")  # fmt: skip
    if args.out is not None:
        write_rows(rows, summary, args.out)
        print(f"wrote {args.out}/segments.csv and {args.out}/summary.md")
    if args.json is not None:
        from grip.core.atomic import atomic_write_text

        atomic_write_text(args.json, json.dumps({**summary["overall"], "init": args.init,
                                                 "pace_keeper": dataclasses.asdict(pace)},
                                                indent=1))  # fmt: skip
        print(f"wrote {args.json}")
    return exit_status(skipped, len(files))
