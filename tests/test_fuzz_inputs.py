"""Seeded fuzzing of every kind of file a user hands the toolkit.

Valid files (a recording as ``.npz`` and ``.pkl``, motion clips in each import format, a
reconstruction, a policy file, a KinematicsNet checkpoint) are mutated by a seeded generator: bytes
flipped, cut, repeated or inserted; numbers in text formats replaced by extreme values; arrays of
``.npz`` members replaced by non-finite, huge, reshaped or retyped ones; JSON metadata nested deeply
or given absurd integers; a lone surrogate put into a string of a recording or a reconstruction (the
names they expose must come back encodable); hostile pickles planted; zip members (npz, torch
files, a run's ``model.zip``) claiming gigabytes; model files with extreme settings, declared
layer sizes and observation keys; a device CSV (also with a line of megabytes). Each mutant is
loaded through the public loader and must either load or be refused with a clean error (a
``ValueError`` or ``OSError``) whose message names the file. No other exception (no
traceback), no hang (each load is bounded by an alarm) and no marker file written by a planted
payload.

The default suite runs a bounded number of mutants per kind (about a minute in all); the ``slow``
test runs ten times as many with other seeds.
"""

from __future__ import annotations

import contextlib
import io
import json
import pickle
import re
import signal
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

from tests.fuzz_model_mutators import long_line, torch_settings, zip_size_lie
from tests.fuzz_mutators import (
    BYTE_MUTATORS,
    NPZ_MUTATORS,
    PKL_MUTATORS,
    TEXT_MUTATORS,
    cut,
    flip,
    mutate_json_text,
    npz_bytes,
    npz_members,
    npz_structured,
)

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "motions"
REPO = Path(__file__).resolve().parents[1]
TIMEOUT_S = 20  # one load of a small mutant takes milliseconds; a hang is a failure


class _Payload:
    """A hostile pickle: unpickling it creates the marker file."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


# --------------------------------------------------------------------------- seeds
def _recording_seeds(root: Path) -> list[Path]:
    from prism_tools.io import save_recording
    from prism_tools.synthetic import make_recording

    rec = make_recording(n_frames=150, seed=3, with_objects=True)
    out = []
    for suffix in (".npz", ".pkl"):
        p = root / f"seed_rec{suffix}"
        save_recording(rec, p)
        out.append(p)
    return out


def _head_lines(path: Path, n: int) -> list[str]:
    with open(path, encoding="utf-8", errors="replace") as f:
        return [next(f) for _ in range(n)]


def _motion_seeds(root: Path) -> dict[str, list[Path]]:
    """Small real clips: a CMU BVH, an HDM05 ASF/AMC pair, a DeepMimic clip (12 frames each), an
    AMASS-style npz and a synthetic poselib ``.npy`` (ASE's humanoid standing, 12 frames)."""
    seeds: dict[str, list[Path]] = {}
    bvh_src = SHARED / "cmu" / "bvh" / "02_01.bvh"
    if bvh_src.is_file():
        text = bvh_src.read_text(encoding="utf-8", errors="replace")
        head, _, motion = text.partition("MOTION")
        lines = motion.strip().splitlines()
        frames = [ln for ln in lines[2:] if ln.strip()][:12]
        p = root / "bvh" / "clip.bvh"
        p.parent.mkdir()
        p.write_text(f"{head}MOTION\nFrames: {len(frames)}\n{lines[1]}\n" + "\n".join(frames))
        seeds["bvh"] = [p]
    asf_dir, amc_dir = SHARED / "hdm05" / "asf", SHARED / "hdm05" / "amc"
    if asf_dir.is_dir() and amc_dir.is_dir():
        amc_src = sorted(amc_dir.glob("HDM_bd_*.amc"))[0]
        asf_src = asf_dir / "HDM_bd.asf"
        d = root / "hdm"
        (d / "asf").mkdir(parents=True)
        (d / "amc").mkdir()
        asf = d / "asf" / asf_src.name
        asf.write_bytes(asf_src.read_bytes())
        raw = amc_src.read_bytes()  # not UTF-8: its header names a Windows path
        cut = re.search(rb"\r?\n13\r?\n", raw)
        amc = d / "amc" / amc_src.name
        amc.write_bytes(raw[: cut.start() if cut else len(raw)] + b"\n")
        seeds["amc"] = [amc]
        seeds["asf"] = [asf]
    dm_src = SHARED / "deepmimic" / "humanoid3d_walk.txt"
    if dm_src.is_file():
        d = json.loads(dm_src.read_text())
        d["Frames"] = d["Frames"][:12]
        p = root / "dm" / "humanoid3d_walk.txt"
        p.parent.mkdir()
        p.write_text(json.dumps(d))
        seeds["deepmimic"] = [p]
    rng = np.random.default_rng(0)
    p = root / "amass" / "clip_poses.npz"
    p.parent.mkdir()
    np.savez(p, poses=rng.normal(scale=0.3, size=(12, 156)), trans=rng.normal(size=(12, 3)),
             mocap_framerate=np.array(60.0), betas=np.zeros(16), gender=np.array("neutral"))
    seeds["amass"] = [p]
    from tests.motion.poselib_files import write_standing_clip

    seeds["poselib"] = [write_standing_clip(root / "poselib" / "clip.npy")]
    return seeds


def _reconstruction_seed(root: Path) -> Path:
    from grip.core.reconstruction import Reconstruction
    from prism_tools.synthetic import make_recording

    rec = make_recording(n_frames=40, seed=1)
    t = rec.n_frames
    rng = np.random.default_rng(2)
    pos = rng.normal(size=(t, 24, 3))
    rot = np.broadcast_to(np.eye(3), (t, 24, 3, 3)).copy()
    r = Reconstruction(name="seed", method="grip", fps=rec.fps, joint_pos=pos, global_rot=rot,
                       grf=rng.normal(size=(t, 2, 3)), cop=rng.normal(size=(t, 2, 3)),
                       falls=np.array([[3, 5]]), notes={"blowups": 0})  # fmt: skip
    p = root / "seed_recon.npz"
    r.save(p)
    return p


# --------------------------------------------------------------------------- loaders
def _encodable(p: Path, *texts: str) -> None:
    """Names a loader exposes must be writable anywhere (cleaned where read: U+FFFD)."""
    for t in texts:
        try:
            t.encode("utf-8")
        except UnicodeEncodeError:
            raise AssertionError(f"{p}: unencodable string {t!r} loaded") from None


def _load_recording(p: Path) -> None:
    from prism_tools.io import load_recording

    rec = load_recording(p)
    _encodable(p, rec.name, rec.category or "", rec.take_name,
               json.dumps(rec.extras, ensure_ascii=False, default=str))  # fmt: skip


def _load_clip(p: Path) -> None:
    from grip.motion.catalog import load_clip

    load_clip(p)


def _load_reconstruction(p: Path) -> None:
    from grip.core.reconstruction import Reconstruction

    r = Reconstruction.load(p)
    _encodable(p, r.name, r.method, json.dumps(r.notes, ensure_ascii=False, default=str))


def _load_policy(p: Path) -> None:
    from policies.controller import load_controller

    load_controller(p)


def _load_kin(p: Path) -> None:
    from grip.kinematics.inference import KinematicsEstimator

    KinematicsEstimator.from_checkpoint(p)


def _load_imu_csv(p: Path) -> None:
    from prism_tools.devices import ImuCsvOptions, read_imu_csv

    read_imu_csv(p, ImuCsvOptions(acc_unit="g", gyro_unit="deg"))


def _imu_csv_seed(root: Path) -> Path:
    """A generic IMU CSV of 2 s at 100 Hz (a slow turn about z, gravity along z)."""
    from grip.core.rotations import axis_angle_to_quat
    from prism_tools.devices import ImuCsv, ImuCsvOptions, write_imu_csv

    t = np.arange(200) / 100.0
    aa = np.zeros((200, 3))
    aa[:, 2] = 0.5 * t
    data = ImuCsv(time_s=t, acc_mps2=np.tile([0.0, 0.0, 9.81], (200, 1)),
                  acc_kind="specific_force", gyr_rad_s=np.tile([0.0, 0.0, 0.5], (200, 1)),
                  quat_wxyz=axis_angle_to_quat(aa))  # fmt: skip
    p = root / "imu.csv"
    write_imu_csv(p, data, "generic", ImuCsvOptions(acc_unit="g", gyro_unit="deg"))
    return p


# --------------------------------------------------------------------------- harness
class _Alarm(Exception):
    pass


def _on_alarm(signum, frame):
    raise _Alarm


def _try(load: Callable[[Path], None], path: Path, marker: Path, what: str,
         also: tuple[str, ...] = ()) -> str | None:  # fmt: skip
    """Load one mutant; ``None`` when it loaded or was refused cleanly (naming ``path`` or one of
    the companion file names ``also``), else what went wrong."""
    old = signal.signal(signal.SIGALRM, _on_alarm)
    signal.alarm(TIMEOUT_S)
    problem = None
    try:
        load(path)
    except _Alarm:
        problem = f"hang (> {TIMEOUT_S} s)"
    except (ValueError, OSError) as e:
        msg = str(e)
        if not any(n in msg for n in (path.name, *also)):
            problem = f"refusal does not name the file: {type(e).__name__}: {msg[:300]}"
    except BaseException as e:
        if isinstance(e, KeyboardInterrupt):
            raise
        problem = f"{type(e).__name__}: {str(e)[:300]}"
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, old)
    if marker.exists():
        problem = "a planted payload ran (marker file written)"
    return None if problem is None else f"{what}: {problem}"


def _fuzz(seed_path: Path, load: Callable[[Path], None], mutators, n: int, seed: int,
          marker: Path, work: Path, keep_name: bool = False,
          also: tuple[str, ...] = ()) -> list[str]:  # fmt: skip
    """``n`` mutants of ``seed_path`` loaded by ``load``; the problems found."""
    rng = np.random.default_rng(seed)
    original = seed_path.read_bytes()
    problems = []
    for i in range(n):
        mut = mutators[int(rng.integers(len(mutators)))]
        data = mut(rng, original)
        if keep_name:  # loaders that find companions by name (ASF next to AMC) mutate in place
            target = seed_path
        else:
            target = work / f"m{i:04d}_{seed_path.name}"
        target.write_bytes(data)
        try:
            p = _try(load, target, marker, f"{seed_path.name} mutant {i} ({mut.__name__})",
                     also)  # fmt: skip
        finally:
            if keep_name:
                target.write_bytes(original)
            else:
                target.unlink(missing_ok=True)
        if p:
            problems.append(p)
    return problems


def _hostile_files(root: Path, marker: Path) -> list[tuple[Path, Callable[[Path], None]]]:
    """Files that carry a payload in each container a loader might unpickle."""
    payload = pickle.dumps({"imu": _Payload(marker)}, protocol=4)
    out: list[tuple[Path, Callable[[Path], None]]] = []
    p = root / "hostile_rec.pkl"
    p.write_bytes(payload)
    out.append((p, _load_recording))
    obj = np.empty(1, dtype=object)
    obj[0] = _Payload(marker)
    for name, loader in (("hostile_rec.npz", _load_recording),
                         ("hostile_recon.npz", _load_reconstruction),
                         ("hostile_clip_poses.npz", _load_clip)):  # fmt: skip
        buf = io.BytesIO()
        np.save(buf, obj, allow_pickle=True)
        p = root / name
        p.write_bytes(npz_bytes({"poses.npy": buf.getvalue(), "trans.npy": buf.getvalue(),
                                  "__meta__.json.npy": buf.getvalue()}))  # fmt: skip
        out.append((p, loader))
    from tests.motion.poselib_files import write_poselib

    p = write_poselib(root / "hostile_clip.npy", {"rotation": {"arr": _Payload(marker)},
                                                  "fps": 30.0})  # fmt: skip
    out.append((p, _load_clip))
    import torch

    for name, loader in (("hostile_policy.pt", _load_policy), ("hostile_kin.pt", _load_kin)):
        p = root / name
        torch.save({"payload": _Payload(marker)}, p)
        out.append((p, loader))
    return out


def _run_all(tmp_path: Path, n: int, seed: int) -> list[str]:
    marker = tmp_path / "MARKER"
    work = tmp_path / "mutants"
    work.mkdir()
    problems: list[str] = []
    for i, p in enumerate(_recording_seeds(tmp_path)):
        problems += _fuzz(p, _load_recording, NPZ_MUTATORS if p.suffix == ".npz"
                          else PKL_MUTATORS, n, seed + i, marker, work)  # fmt: skip
    motions = _motion_seeds(tmp_path)
    for kind, paths in motions.items():
        for p in paths:
            if kind == "asf":  # the skeleton is read through its AMC clip
                amc = motions["amc"][0]
                problems += _fuzz(p, lambda _p, amc=amc: _load_clip(amc), TEXT_MUTATORS,
                                  n // 2, seed + 10, marker, work, keep_name=True,
                                  also=(amc.name,))  # fmt: skip
                continue
            mutators = {".npz": NPZ_MUTATORS, ".npy": BYTE_MUTATORS}.get(p.suffix,
                                                                         TEXT_MUTATORS)  # fmt: skip
            problems += _fuzz(p, _load_clip, mutators, n, seed + 20 + len(problems), marker, work,
                              keep_name=kind in ("amc", "deepmimic"))  # fmt: skip
    problems += _fuzz(_reconstruction_seed(tmp_path), _load_reconstruction, NPZ_MUTATORS, n,
                      seed + 30, marker, work)  # fmt: skip
    for p, loader in _hostile_files(tmp_path, marker):
        problem = _try(loader, p, marker, p.name)
        if problem:
            problems.append(problem)
    # model files: bytes, members claiming gigabytes, extreme settings and declared sizes
    models = (*BYTE_MUTATORS, zip_size_lie, torch_settings, torch_settings, torch_settings)
    small = [(REPO / "grip" / "assets" / "policy_default.pt", _load_policy),
             (REPO / "grip" / "assets" / "kinematics_default.pt", _load_kin)]
    for src, loader in small:
        problems += _fuzz(src, loader, models, max(8, n // 8), seed + 40, marker, work)
    problems += _fuzz(_imu_csv_seed(tmp_path), _load_imu_csv, (*TEXT_MUTATORS, long_line),
                      max(8, n // 4), seed + 50, marker, work)  # fmt: skip
    return problems


def _json_mutator(rng: np.random.Generator, b: bytes) -> bytes:
    return mutate_json_text(rng, b.decode("utf-8", "replace")).encode()


def _zip_member_mutator(member: str, inner) -> Callable:
    """Mutate one member of a zip (the ``data`` JSON or a state dict of SB3's ``model.zip``)."""

    def mutate(rng: np.random.Generator, b: bytes) -> bytes:
        members = npz_members(b)
        members[member] = inner(rng, members[member])
        return npz_bytes(members)

    mutate.__name__ = f"{member}:{getattr(inner, '__name__', 'mutate')}"
    return mutate


def _fuzz_run_folder(run: Path, n: int, seed: int, marker: Path, work: Path) -> list[str]:
    """Mutants of each file of a training run folder, read as ``grip policy export`` reads
    them (through the command, so that its clean errors count and a traceback does not)."""
    from grip.cli.main import main

    def export(_p: Path) -> None:
        err = io.StringIO()
        with contextlib.redirect_stderr(err):
            rc = main(["policy", "export", str(ck), "--out", str(work / "p.pt")])
        if rc == 2:  # a clean refusal: its message must name the file
            raise ValueError(err.getvalue())
        if rc != 0:
            raise AssertionError(f"policy export: exit status {rc}")

    ck = work / "run"
    if ck.exists():
        import shutil

        shutil.rmtree(ck)
    (ck / "checkpoint").mkdir(parents=True)
    for f in ("config.json", "holdout.json"):
        if (run / f).is_file():
            (ck / f).write_bytes((run / f).read_bytes())
    for f in (run / "checkpoint").iterdir():
        if f.is_file():
            (ck / "checkpoint" / f.name).write_bytes(f.read_bytes())
    payload = _serialized_payload(marker)
    targets = {
        ck / "checkpoint" / "model.zip": (*BYTE_MUTATORS,
                                          _zip_member_mutator("data", _json_mutator),
                                          _zip_member_mutator("data", payload),
                                          _zip_member_mutator("policy.pth", flip),
                                          _zip_member_mutator("policy.pth", cut),
                                          zip_size_lie,
                                          _zip_member_mutator("policy.pth", zip_size_lie)),
        ck / "checkpoint" / "vecnorm.npz": (*NPZ_MUTATORS, zip_size_lie),
        ck / "config.json": (*BYTE_MUTATORS, _json_mutator, _json_mutator),
        ck / "checkpoint" / "state.json": (*BYTE_MUTATORS, _json_mutator, _json_mutator),
    }  # fmt: skip
    problems = []
    for i, (target, mutators) in enumerate(targets.items()):
        problems += _fuzz(target, export, mutators, n, seed + i, marker, work, keep_name=True)
    return problems


def _serialized_payload(marker: Path) -> Callable:
    """A mutator planting an SB3 ``":serialized:"`` entry that would write the marker."""
    import base64

    import cloudpickle

    blob = base64.b64encode(cloudpickle.dumps(_Payload(marker))).decode()

    def plant(rng: np.random.Generator, b: bytes) -> bytes:
        d = json.loads(b)
        keys = list(d)
        d[keys[int(rng.integers(len(keys)))]] = {":type:": "x", ":serialized:": blob}
        return json.dumps(d).encode()

    plant.__name__ = "serialized_payload"
    return plant


def _report(problems: list[str]) -> str:
    return f"{len(problems)} problem(s):\n" + "\n".join(problems[:40])


def test_fuzzed_inputs_load_or_are_refused_cleanly(tmp_path: Path) -> None:
    problems = _run_all(tmp_path, n=300, seed=0)
    assert not problems, _report(problems)


def test_fuzzed_run_folders_are_refused_cleanly(tiny_policy_run, tmp_path: Path) -> None:
    _, run = tiny_policy_run
    (tmp_path / "w").mkdir()
    problems = _fuzz_run_folder(run, 40, 0, tmp_path / "MARKER", tmp_path / "w")
    assert not problems, _report(problems)


def test_a_batch_with_fuzzed_recordings_goes_on(tmp_path: Path, capsys) -> None:
    """``grip reconstruct`` and ``grip data info`` over good and damaged recordings: no
    traceback, each damaged file named, the good ones done, exit status 1."""
    from grip.cli.main import main
    from prism_tools.io import save_recording
    from prism_tools.synthetic import make_recording

    rng = np.random.default_rng(5)
    seqs = tmp_path / "ds" / "sequences"
    seqs.mkdir(parents=True)
    good = []
    for i in range(2):
        p = seqs / f"good{i}.npz"
        save_recording(make_recording(n_frames=60, seed=i), p)
        good.append(p)
    bad = []
    for i, mut in enumerate((cut, npz_structured, flip)):
        p = seqs / f"bad{i}.npz"
        p.write_bytes(mut(rng, good[0].read_bytes()))
        bad.append(p)
    (tmp_path / "ds" / "split.json").write_text(json.dumps(
        {"train": [], "test": [p.stem for p in good + bad]}))
    rc = main(["reconstruct", *map(str, good + bad), "--out", str(tmp_path / "rc"),
               "--max-frames", "30"])  # fmt: skip
    err = capsys.readouterr().err
    refused = [p for p in bad if p.name in err]
    assert rc == (1 if refused else 0), err
    assert len(list((tmp_path / "rc").glob("good*.npz"))) == 2
    assert "Traceback" not in err
    rc = main(["data", "info", str(tmp_path / "ds")])
    err = capsys.readouterr().err
    assert "Traceback" not in err and rc in (0, 1)
    assert all(p.name in err for p in refused), err


@pytest.mark.slow
def test_fuzzed_inputs_many_seeds(tmp_path: Path, tiny_policy_run) -> None:
    problems = _run_all(tmp_path, n=3000, seed=1000)
    (tmp_path / "w").mkdir()
    problems += _fuzz_run_folder(tiny_policy_run[1], 400, 1000, tmp_path / "MARKER",
                                 tmp_path / "w")  # fmt: skip
    assert not problems, _report(problems)
