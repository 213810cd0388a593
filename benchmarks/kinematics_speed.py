"""KinematicsNet speed: streaming latency (batch 1, one thread) and offline throughput.

Each figure is printed with a reference measured in the same run on the same thread count: a
bare ``torch.nn.LSTM`` of the same width and depth (one stage's recurrent core; the network has
four such stages, so about 4 is the floor of both ratios). The ratio is what to compare across
machines; the absolute numbers depend on the CPU and its load, so every timing runs in several
rounds that take turns with its reference and the medians are kept.

- stream: one frame at batch 1 through the streaming path (:class:`FrameStep`, what
  ``StreamingEstimator`` runs); ``module_stream``: ``KinematicsNet.forward`` on a one-frame
  sequence, for comparison.
- offline: 32 sequences of 500 frames through ``KinematicsNet.forward``, on ``--threads``
  threads (default 1; the bare LSTM reference runs on as many); per second of wall time and
  per second of the process's CPU time (``offline_frames_per_cpu_s``: on a machine other
  processes share, what a core of its own would do, less their effect on the caches).

    python benchmarks/kinematics_speed.py [--model CKPT] [--hidden 256 --layers 2] [--json PATH]
    python benchmarks/kinematics_speed.py --model CKPT --tta full

With ``--model`` it also times the estimator's whole streaming step (normalisation and
output conversion included), without test-time augmentation and with ``--tta MODE``.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import torch

from grip.kinematics.model import FrameStep, KinematicsNet, KinematicsNetConfig


def _time(fn, repeats: int, cpu: list | None = None) -> float:
    """Wall seconds per call (``cpu``: the process's CPU seconds per call appended)."""
    fn()  # warm-up
    c0, t0 = time.process_time(), time.perf_counter()
    for _ in range(repeats):
        fn()
    if cpu is not None:
        cpu.append((time.process_time() - c0) / repeats)
    return (time.perf_counter() - t0) / repeats


def _interleaved(fns: dict, repeats: int, rounds: int,
                 cpu: dict | None = None) -> dict[str, float]:  # fmt: skip
    """Median seconds per call of each function over ``rounds`` rounds that take turns, so
    that a change in the machine's load hits the figures and their reference alike (``cpu``:
    filled with the medians of the process's CPU seconds per call, which other processes on
    a shared machine do not inflate)."""
    got: dict[str, list[float]] = {k: [] for k in fns}
    used: dict[str, list[float]] = {k: [] for k in fns}
    for _ in range(rounds):
        for k, fn in fns.items():
            got[k].append(_time(fn, repeats, used[k]))
    if cpu is not None:
        cpu.update({k: statistics.median(v) for k, v in used.items()})
    return {k: statistics.median(v) for k, v in got.items()}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--model", default=None, help="checkpoint (else a random net of the sizes)")
    ap.add_argument("--hidden", type=int, default=256)
    ap.add_argument("--layers", type=int, default=2)
    ap.add_argument("--inputs", type=int, default=70)
    ap.add_argument("--frames", type=int, default=2000, help="streamed frames per round")
    ap.add_argument("--rounds", type=int, default=5, help="rounds of every timing, in turns")
    ap.add_argument("--tta", default="full", help="test-time augmentation timed with --model")
    ap.add_argument("--json", default=None, help="also write the figures here")
    ap.add_argument(
        "--threads",
        type=int,
        default=1,
        help="torch threads of the offline figures (streaming always runs on one)",
    )
    args = ap.parse_args()
    torch.set_num_threads(1)
    if args.model:
        from grip.kinematics.inference import KinematicsEstimator

        net = KinematicsEstimator.from_checkpoint(args.model).model
        cfg = net.cfg
    else:
        cfg = KinematicsNetConfig(n_inputs=args.inputs, hidden=args.hidden, layers=args.layers)
        net = KinematicsNet(cfg).eval()
    first = {k: torch.zeros(1, s.head.out_features) for k, s in net.stages.items()}
    ref = torch.nn.LSTM(cfg.hidden, cfg.hidden, cfg.layers, batch_first=True).eval()
    step = FrameStep(net)

    x1 = torch.randn(1, 1, cfg.n_inputs)
    r1 = torch.randn(1, 1, cfg.hidden)
    # the bare LSTM and the module path at batch 1 run without oneDNN (~5x faster: DESIGN.md)
    prev = torch.backends.mkldnn.set_flags(False)
    with torch.inference_mode():
        state = net.initial_state(first)
        flat = step.flat_state(state)

        def frame_step():  # the streaming path (StreamingEstimator)
            step(x1[0], flat)

        def module_step():  # KinematicsNet.forward on a one-frame sequence
            nonlocal state
            _, state = net(x1, state)

        ref_state = None

        def ref_step():
            nonlocal ref_state
            _, ref_state = ref(r1, ref_state)

        stream = _interleaved({"frame": frame_step, "module": module_step, "ref": ref_step},
                              args.frames, args.rounds)  # fmt: skip
    torch.backends.mkldnn.set_flags(prev[0])

    torch.set_num_threads(args.threads)
    xb = torch.randn(32, 500, cfg.n_inputs)
    rb = torch.randn(32, 500, cfg.hidden)
    with torch.inference_mode():
        s32 = net.initial_state({k: v.expand(32, -1) for k, v in first.items()})
        off_cpu: dict[str, float] = {}
        off = _interleaved({"net": lambda: net(xb, s32), "ref": lambda: ref(rb)}, 1,
                           args.rounds, off_cpu)  # fmt: skip
    frames = 32 * 500
    torch.set_num_threads(1)
    steps = _estimator_steps(args.model, args.tta, args.frames) if args.model else {}
    res = {
        "stream_ms_per_frame": stream["frame"] * 1e3,
        "module_stream_ms_per_frame": stream["module"] * 1e3,
        "ref_lstm_stream_ms_per_frame": stream["ref"] * 1e3,
        "stream_ratio_to_ref": stream["frame"] / stream["ref"],
        "module_stream_ratio_to_ref": stream["module"] / stream["ref"],
        "offline_frames_per_s": frames / off["net"],
        "ref_lstm_offline_frames_per_s": frames / off["ref"],
        "offline_ratio_to_ref": off["ref"] / off["net"],
        # (per second of the process's CPU time: what a core of its own would do)
        "offline_frames_per_cpu_s": frames / off_cpu["net"],
        "ref_lstm_offline_frames_per_cpu_s": frames / off_cpu["ref"],
        "hidden": cfg.hidden,
        "layers": cfg.layers,
        "parameters": int(sum(p.numel() for p in net.parameters())),
        "threads": 1,
        "offline_threads": args.threads,
        "rounds": args.rounds,
        **steps,
    }
    for k, v in res.items():
        print(f"{k:32s} {v:.4g}" if isinstance(v, float) else f"{k:32s} {v}")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(res, f, indent=1)


def _estimator_steps(model: str, tta: str, frames: int) -> dict[str, float]:
    """ms per frame of ``StreamingEstimator.step`` without and with test-time augmentation."""
    import numpy as np

    from grip.kinematics.features import input_features
    from grip.kinematics.inference import KinematicsEstimator
    from prism_tools.synthetic import make_recording

    rec = make_recording(50, seed=0)
    res = {}
    for mode in ("none", tta):
        est = KinematicsEstimator.from_checkpoint(model, tta=mode)
        row = input_features(rec, est.cfg.features)[10].astype(np.float32)
        stream = est.stream(rec)
        res[f"step_ms_per_frame_tta_{mode}"] = (
            _time(lambda s=stream, r=row: s.step(r), frames) * 1e3
        )
    return res


if __name__ == "__main__":
    main()
