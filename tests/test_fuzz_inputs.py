"""Seeded fuzzing of every kind of file a user hands the toolkit.

Valid files (a recording as ``.npz`` and ``.pkl``, motion clips in each import format, a
reconstruction, a policy file, a KinematicsNet checkpoint) are mutated by a seeded generator: bytes
flipped, cut, repeated or inserted; numbers in text formats replaced by extreme values; arrays of
``.npz`` members replaced by non-finite, huge, reshaped or retyped ones; JSON metadata nested deeply
or given absurd integers; a lone surrogate put into a string of a recording or a reconstruction (the
names they expose must come back encodable); hostile pickles planted. Each mutant is loaded through
the public loader and must either load or be refused with a clean error (a ``ValueError`` or
``OSError``) whose message names the file. No other exception (no traceback), no hang (each load is
bounded by an alarm) and no marker file written by a planted payload.

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
import zipfile
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest

SHARED = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "motions"
REPO = Path(__file__).resolve().parents[1]
TIMEOUT_S = 20  # one load of a small mutant takes milliseconds; a hang is a failure
EXTREMES = ("nan", "inf", "-inf", "1e308", "1e30", "-1e30", "0", "-0", "1800", "1e-9",
            "9" * 5000, "1e-320", "abc", "", "0x10", "-1")  # fmt: skip


class _Payload:
    """A hostile pickle: unpickling it creates the marker file."""

    def __init__(self, marker: Path) -> None:
        self.marker = str(marker)

    def __reduce__(self):
        return (open, (self.marker, "w"))


# --------------------------------------------------------------------------- mutators
def _flip(rng: np.random.Generator, b: bytes) -> bytes:
    a = bytearray(b)
    for i in rng.integers(0, len(a), size=int(rng.integers(1, 9))):
        a[i] = int(rng.integers(0, 256))
    return bytes(a)


def _cut(rng: np.random.Generator, b: bytes) -> bytes:
    return b[: int(rng.integers(0, len(b)))]


def _delete(rng: np.random.Generator, b: bytes) -> bytes:
    i = int(rng.integers(0, len(b)))
    return b[:i] + b[i + int(rng.integers(1, 200)):]


def _repeat(rng: np.random.Generator, b: bytes) -> bytes:
    i = int(rng.integers(0, len(b)))
    chunk = b[i: i + int(rng.integers(1, 200))]
    return b[:i] + chunk * int(rng.integers(2, 50)) + b[i:]


def _insert(rng: np.random.Generator, b: bytes) -> bytes:
    i = int(rng.integers(0, len(b)))
    return b[:i] + rng.integers(0, 256, size=int(rng.integers(1, 64))).astype(np.uint8).tobytes() \
        + b[i:]


BYTE_MUTATORS = (_flip, _cut, _delete, _repeat, _insert)


def _text_number(rng: np.random.Generator, b: bytes) -> bytes:
    """Replace one to three numeric tokens by extreme or malformed values."""
    toks = b.split(b" ")
    numeric = [i for i, t in enumerate(toks) if t.strip()[:1] in b"-0123456789"]
    if not numeric:
        return _flip(rng, b)
    for i in rng.choice(numeric, size=min(len(numeric), int(rng.integers(1, 4))), replace=False):
        tail = b"\n" if toks[i].endswith(b"\n") else b""
        toks[i] = EXTREMES[int(rng.integers(len(EXTREMES)))].encode() + tail
    return b" ".join(toks)


def _text_lines(rng: np.random.Generator, b: bytes) -> bytes:
    """Delete, repeat or swap lines."""
    lines = b.split(b"\n")
    i, j = (int(x) for x in rng.integers(0, len(lines), size=2))
    op = int(rng.integers(3))
    if op == 0:
        del lines[i]
    elif op == 1:
        lines[i:i] = [lines[i]] * int(rng.integers(2, 400))
    else:
        lines[i], lines[j] = lines[j], lines[i]
    return b"\n".join(lines)


TEXT_MUTATORS = (*BYTE_MUTATORS, _text_number, _text_number, _text_lines, _text_lines)


def _npz_members(b: bytes) -> dict[str, bytes]:
    with zipfile.ZipFile(io.BytesIO(b)) as z:
        return {n: z.read(n) for n in z.namelist()}


def _npz_bytes(members: dict[str, bytes]) -> bytes:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for n, data in members.items():
            z.writestr(n, data)
    return buf.getvalue()


def _npy(arr: np.ndarray) -> bytes:
    buf = io.BytesIO()
    np.save(buf, arr, allow_pickle=False)
    return buf.getvalue()


def _lying_header(shape: tuple[int, ...]) -> bytes:
    """An ``.npy`` whose header claims ``shape`` (float64) but holds a few bytes: a bomb."""
    header = repr({"descr": "<f8", "fortran_order": False, "shape": shape}).encode()
    header += b" " * (63 - (len(header) + 10) % 64) + b"\n"
    return b"\x93NUMPY\x01\x00" + len(header).to_bytes(2, "little") + header + b"\0" * 64


def _deep(depth: int) -> str:
    return "[" * depth + "]" * depth


def _mutate_json_text(rng: np.random.Generator, text: str) -> str:
    op = int(rng.integers(5))
    if op == 0:
        return _deep(int(rng.choice([1000, 200_000])))
    if op == 1:
        return text.replace(":", ": " + "9" * 5000 + ", \"x\":", 1)
    if op == 2:
        try:
            d = json.loads(text)
        except ValueError:
            return text[: len(text) // 2]
        if isinstance(d, dict) and d:
            k = list(d)[int(rng.integers(len(d)))]
            d[k] = [None, "x", -1, 1e308, {}, [], True][int(rng.integers(7))]
        return json.dumps(d)
    if op == 3:
        return '{"a": ' + _deep(50_000) + "}"
    return text[: int(rng.integers(0, len(text) + 1))]


def _npz_structured(rng: np.random.Generator, b: bytes) -> bytes:
    """Replace, reshape, retype or delete one member, lie in a header or break the metadata."""
    members = _npz_members(b)
    names = list(members)
    name = names[int(rng.integers(len(names)))]
    meta = [n for n in names if "meta" in n]
    op = int(rng.integers(7))
    if op == 0 and meta:
        m = meta[0]
        arr = np.load(io.BytesIO(members[m]), allow_pickle=False)
        members[m] = _npy(np.array(_mutate_json_text(rng, str(arr))))
        return _npz_bytes(members)
    arr = np.load(io.BytesIO(members[name]), allow_pickle=False)
    if op == 1:
        del members[name]
    elif op == 2 and arr.dtype.kind == "f" and arr.size:
        bad = arr.copy()
        flat = bad.reshape(-1)
        idx = rng.integers(0, flat.size, size=max(1, flat.size // 50))
        flat[idx] = [np.nan, np.inf, 1e30, -1e30, 0.0][int(rng.integers(5))]
        members[name] = _npy(bad if rng.random() < 0.5 else arr * 1000.0)
    elif op == 3 and arr.ndim:
        members[name] = _npy(arr[:-1] if rng.random() < 0.5 else arr.reshape(-1))
    elif op == 4 and arr.dtype.kind in "fiub":
        dtype = [np.int8, np.bool_, np.float16, "U3"][int(rng.integers(4))]
        members[name] = _npy(arr.astype(dtype))
    elif op == 5:
        members[name] = _lying_header((200_000, 10_000))
    else:
        members[name] = _npy(np.zeros((0, *arr.shape[1:]), dtype=arr.dtype))
    return _npz_bytes(members)


def _surrogate_in(rng: np.random.Generator, tree):
    """``tree`` (JSON-like) with a lone surrogate (``os.fsdecode(b"\\xff")``) put into one of its
    strings, a value or a key."""
    spots = []  # (container, key, whether the key itself is the string)
    stack = [tree]
    while stack:
        node = stack.pop()
        pairs = node.items() if isinstance(node, dict) else enumerate(node)
        for k, v in list(pairs):
            if isinstance(node, dict) and isinstance(k, str):
                spots.append((node, k, True))
            if isinstance(v, str):
                spots.append((node, k, False))
            elif isinstance(v, dict | list):
                stack.append(v)
    if spots:
        node, k, is_key = spots[int(rng.integers(len(spots)))]
        if is_key:
            node[k[:1] + "\udcff" + k[1:]] = node.pop(k)
        else:
            node[k] = node[k][:1] + "\udcff" + node[k][1:]
    return tree


def _npz_surrogates(rng: np.random.Generator, b: bytes) -> bytes:
    """A lone surrogate in one string of the JSON metadata (as a ``"\\udcff"`` escape)."""
    members = _npz_members(b)
    meta = next((n for n in members if "meta" in n), None)
    if meta is None:  # (an AMASS clip: no strings of ours)
        return _npz_structured(rng, b)
    arr = np.load(io.BytesIO(members[meta]), allow_pickle=False)
    members[meta] = _npy(np.array(json.dumps(_surrogate_in(rng, json.loads(str(arr))))))
    return _npz_bytes(members)


def _pickle_surrogates(rng: np.random.Generator, b: bytes) -> bytes:
    """A lone surrogate in one string of a (trusted, seed) pickle."""
    return pickle.dumps(_surrogate_in(rng, pickle.loads(b)), protocol=4)


NPZ_MUTATORS = (*BYTE_MUTATORS, _npz_structured, _npz_structured, _npz_structured,
                _npz_surrogates)  # fmt: skip
PKL_MUTATORS = (*BYTE_MUTATORS, _pickle_surrogates)


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
        p.write_bytes(_npz_bytes({"poses.npy": buf.getvalue(), "trans.npy": buf.getvalue(),
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
    small = [(REPO / "grip" / "assets" / "policy_default.pt", _load_policy),
             (REPO / "grip" / "assets" / "kinematics_default.pt", _load_kin)]
    for src, loader in small:
        problems += _fuzz(src, loader, BYTE_MUTATORS, max(4, n // 8), seed + 40, marker, work)
    return problems


def _json_mutator(rng: np.random.Generator, b: bytes) -> bytes:
    return _mutate_json_text(rng, b.decode("utf-8", "replace")).encode()


def _zip_member_mutator(member: str, inner) -> Callable:
    """Mutate one member of a zip (the ``data`` JSON or a state dict of SB3's ``model.zip``)."""

    def mutate(rng: np.random.Generator, b: bytes) -> bytes:
        members = _npz_members(b)
        members[member] = inner(rng, members[member])
        return _npz_bytes(members)

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
                                          _zip_member_mutator("policy.pth", _flip),
                                          _zip_member_mutator("policy.pth", _cut)),
        ck / "checkpoint" / "vecnorm.npz": NPZ_MUTATORS,
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
    for i, mut in enumerate((_cut, _npz_structured, _flip)):
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
