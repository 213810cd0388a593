"""Tests for prism_tools.io: round trips, restricted unpickling, corrupt files, atomic writes."""

from __future__ import annotations

import builtins
import dataclasses
import os
import pickle
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from prism_tools import Recording, RecordingError, load_recording, save_recording
from prism_tools.io import RestrictedUnpickler, load_prism_dict, take_name_from_path
from prism_tools.streams import EXTRAS_KEY, GRAVITY
from prism_tools.synthetic import make_recording


@pytest.fixture(scope="module")
def rec() -> Recording:
    return make_recording(250, seed=7, with_objects=True)


def _assert_tree_equal(a: Any, b: Any, path: str = "") -> None:
    if isinstance(a, np.ndarray):
        assert isinstance(b, np.ndarray), path
        assert a.dtype == b.dtype, f"{path}: {a.dtype} != {b.dtype}"
        np.testing.assert_array_equal(a, b, err_msg=path)
    elif isinstance(a, dict):
        assert isinstance(b, dict) and set(a) == set(b), path
        for k in a:
            _assert_tree_equal(a[k], b[k], f"{path}.{k}")
    else:
        assert a == b and type(a) is type(b), f"{path}: {a!r} != {b!r}"


@pytest.mark.parametrize("suffix", [".pkl", ".npz"])
def test_round_trip(rec: Recording, tmp_path: Path, suffix: str) -> None:
    path = tmp_path / f"subj007_take007{suffix}"
    save_recording(rec, path)
    back = load_recording(path)
    _assert_tree_equal(rec.to_prism_dict(), back.to_prism_dict())
    assert back.extras == rec.extras
    assert back.smpl_params.poses.dtype == np.float32
    assert back.insole["L_Foot"].contacts.dtype == bool
    assert back.objects is not None and back.objects["BoxSmall"].faces.dtype == np.int64
    assert sorted(p.name for p in tmp_path.iterdir()) == [path.name]


def test_round_trip_without_optional_parts(tmp_path: Path) -> None:
    rec = make_recording(120, seed=1, parts=("L_Foot", "R_Foot", "L_Wrist", "R_Wrist"))
    rec = dataclasses.replace(rec, slam=None, insole_combined=None)
    for suffix in (".pkl", ".npz"):
        save_recording(rec, tmp_path / f"r{suffix}")
        back = load_recording(tmp_path / f"r{suffix}")
        assert back.slam is None and back.objects is None and back.insole_combined is None
        assert set(back.imu) == {"L_Foot", "R_Foot", "L_Wrist", "R_Wrist"}
        _assert_tree_equal(rec.to_prism_dict(), back.to_prism_dict())


@pytest.mark.parametrize("protocol", range(pickle.HIGHEST_PROTOCOL + 1))
def test_restricted_unpickler_reads_all_protocols(rec: Recording, protocol: int) -> None:
    import io

    d = rec.to_prism_dict()
    d["numpy_scalars"] = [np.float64(1.5), np.int32(3), np.bool_(True), np.str_("x")]
    data = pickle.dumps(d, protocol=protocol)
    back = RestrictedUnpickler(io.BytesIO(data)).load()
    _assert_tree_equal(d["imu"], back["imu"])
    assert back["numpy_scalars"] == d["numpy_scalars"]


def test_numpy1_spelling_accepted(tmp_path: Path) -> None:
    arr = np.arange(6, dtype=np.float32).reshape(2, 3)
    data = pickle.dumps({"a": arr}, protocol=2)
    assert b"numpy._core.multiarray\n" in data
    old = data.replace(b"numpy._core.multiarray\n", b"numpy.core.multiarray\n")
    path = tmp_path / "old.pkl"
    path.write_bytes(old)
    np.testing.assert_array_equal(load_prism_dict(path)["a"], arr)


class _SystemCall:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, ...]:
        return (os.system, (f"touch {self.marker}",))


class _EvalCall:
    def __init__(self, marker: Path) -> None:
        self.marker = marker

    def __reduce__(self) -> tuple[Any, ...]:
        return (builtins.eval, (f"open({str(self.marker)!r}, 'w').close()",))


@pytest.mark.parametrize(
    ("payload_cls", "refused"), [(_SystemCall, "system"), (_EvalCall, "builtins.eval")]
)
def test_hostile_pickle_refused(
    rec: Recording, tmp_path: Path, payload_cls: type, refused: str
) -> None:
    marker = tmp_path / "pwned"
    d = rec.to_prism_dict()
    d["info"]["data_info"]["trial_name"] = payload_cls(marker)
    path = tmp_path / "subj001_take001.pkl"
    path.write_bytes(pickle.dumps(d, protocol=4))
    with pytest.raises(RecordingError) as exc:
        load_recording(path)
    msg = str(exc.value)
    assert msg.startswith(str(path))
    assert "refused" in msg and refused in msg
    assert not marker.exists()


def test_refuses_arbitrary_class(tmp_path: Path) -> None:
    import collections

    path = tmp_path / "x.pkl"
    path.write_bytes(pickle.dumps({"c": collections.Counter("ab")}))
    with pytest.raises(RecordingError, match=r"refused to unpickle global 'collections\.Counter'"):
        load_prism_dict(path)


@pytest.mark.parametrize("suffix", [".pkl", ".npz"])
def test_truncated_and_garbage_files(rec: Recording, tmp_path: Path, suffix: str) -> None:
    good = tmp_path / f"good{suffix}"
    save_recording(rec, good)
    data = good.read_bytes()
    for name, content in [
        ("half", data[: len(data) // 2]),
        ("tiny", data[:10]),
        ("empty", b""),
        ("garbage", b"\x00\x01 not a recording" * 10),
    ]:
        path = tmp_path / f"{name}{suffix}"
        path.write_bytes(content)
        with pytest.raises(RecordingError) as exc:
            load_recording(path)
        assert str(exc.value).startswith(str(path)), str(exc.value)


def test_missing_file_and_unknown_suffix(tmp_path: Path) -> None:
    with pytest.raises(FileNotFoundError, match=r"nope\.pkl: no such recording file"):
        load_recording(tmp_path / "nope.pkl")
    (tmp_path / "x.txt").write_text("hi")
    with pytest.raises(RecordingError, match=r"x\.txt: unknown recording format"):
        load_recording(tmp_path / "x.txt")


def test_invalid_content_error_starts_with_path(rec: Recording, tmp_path: Path) -> None:
    d = rec.to_prism_dict()
    d["imu"]["Head"]["ori_world"] = d["imu"]["Head"]["ori_world"][:-1]
    path = tmp_path / "subj001" / "take002.pkl"
    path.parent.mkdir()
    path.write_bytes(pickle.dumps(d))
    with pytest.raises(RecordingError) as exc:
        load_recording(path)
    assert str(exc.value) == (
        f"{path}: imu.Head.ori_world: expected shape (F, 3, 3) with F=250, got (249, 3, 3)"
    )


def test_save_refuses_invalid(rec: Recording, tmp_path: Path) -> None:
    bad = dataclasses.replace(rec, fps=-1.0)
    with pytest.raises(RecordingError, match="refusing to save"):
        save_recording(bad, tmp_path / "bad.npz")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize(
    ("rel", "expected"),
    [("subj001/take002.pkl", "subj001_take002"), ("subj001_take002.pkl", "subj001_take002")],
)
def test_real_prism_paths_and_force_unit(
    rec: Recording, tmp_path: Path, rel: str, expected: str
) -> None:
    assert take_name_from_path(rel) == expected
    d = rec.to_prism_dict()
    del d[EXTRAS_KEY]  # as in a real PRISM file
    for foot in ("L_Foot", "R_Foot"):
        d["insole"][foot]["force"] = d["insole"][foot]["force"] * GRAVITY
    path = tmp_path / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(pickle.dumps(d, protocol=pickle.HIGHEST_PROTOCOL))
    back = load_recording(path)
    assert back.extras["take_name"] == expected
    assert back.take_name == expected
    assert back.extras["force_unit_detected"] == "n_per_kg"
    np.testing.assert_allclose(back.insole["L_Foot"].force, rec.insole["L_Foot"].force)


@pytest.mark.parametrize("suffix", [".pkl", ".npz"])
def test_atomic_write_failure_keeps_old_file(
    rec: Recording, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, suffix: str
) -> None:
    path = tmp_path / f"take{suffix}"
    save_recording(rec, path)
    before = path.read_bytes()

    def fail_midway(f: Any) -> None:
        f.write(b"partial content")
        raise OSError("disk full")

    if suffix == ".pkl":
        monkeypatch.setattr(pickle, "dump", lambda obj, f, **kw: fail_midway(f))
    else:
        monkeypatch.setattr(np, "savez_compressed", lambda f, **arrays: fail_midway(f))
    other = make_recording(100, seed=99)
    with pytest.raises(OSError, match="disk full"):
        save_recording(other, path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [path.name]
    monkeypatch.undo()
    assert load_recording(path).n_frames == rec.n_frames


def test_atomic_write_failure_at_replace(
    rec: Recording, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    path = tmp_path / "take.npz"
    save_recording(rec, path)
    before = path.read_bytes()

    def no_replace(src: Any, dst: Any) -> None:
        raise OSError("rename failed")

    monkeypatch.setattr(os, "replace", no_replace)
    with pytest.raises(OSError, match="rename failed"):
        save_recording(make_recording(100, seed=5), path)
    assert path.read_bytes() == before
    assert [p.name for p in tmp_path.iterdir()] == [path.name]


def test_npz_loads_without_pickle(rec: Recording, tmp_path: Path) -> None:
    path = tmp_path / "r.npz"
    save_recording(rec, path)
    with np.load(path, allow_pickle=False) as z:
        assert "imu/L_Wrist/ori_world" in z.files
        assert "__meta__.json" in z.files
