"""The one table of input limits (grip.core.limits): overrides, environment, npz/JSON checks."""

from __future__ import annotations

import io
import struct
import zipfile

import numpy as np
import pytest

from grip.core.limits import (
    DEFAULT_LIMITS,
    LIMITS_ENV,
    InputLimits,
    LimitExceeded,
    active_limits,
    check_npz,
    check_tree,
    safe_json_loads,
    set_active_limits,
)


def test_overrides_parse_names_numbers_and_inf() -> None:
    lim = DEFAULT_LIMITS.with_overrides(["max_duration_s=7200", "max_frames=1e6",
                                         "max_depth=inf"])  # fmt: skip
    assert lim.max_duration_s == 7200 and lim.max_frames == 1_000_000
    assert lim.max_depth == float("inf")
    assert lim.overrides() == {"max_duration_s": 7200, "max_frames": 1_000_000,
                               "max_depth": float("inf")}  # fmt: skip
    with pytest.raises(ValueError, match=r"unknown limit 'nope'.*max_duration_s"):
        DEFAULT_LIMITS.with_overrides(["nope=1"])
    with pytest.raises(ValueError, match="not a number"):
        DEFAULT_LIMITS.with_overrides(["max_frames=lots"])
    with pytest.raises(ValueError, match=">= 0"):
        DEFAULT_LIMITS.with_overrides(["max_frames=-1"])
    with pytest.raises(ValueError, match="NAME=VALUE"):
        DEFAULT_LIMITS.with_overrides(["max_frames"])


def test_environment_overrides_and_set_active_limits(monkeypatch) -> None:
    monkeypatch.setenv(LIMITS_ENV, "max_duration_s=10, min_fps=5")
    lim = active_limits()
    assert lim.max_duration_s == 10 and lim.min_fps == 5
    set_active_limits(DEFAULT_LIMITS.with_overrides(["max_fps=500"]))
    assert active_limits() == InputLimits(max_fps=500)
    set_active_limits(DEFAULT_LIMITS)
    assert active_limits() == DEFAULT_LIMITS
    monkeypatch.setenv(LIMITS_ENV, "bogus=1")
    with pytest.raises(ValueError, match=LIMITS_ENV):
        active_limits()


def test_refusal_names_value_limit_and_override() -> None:
    with pytest.raises(LimitExceeded) as ei:
        DEFAULT_LIMITS.check_take(3, 1 / 1800)
    msg = str(ei.value)
    assert "min_fps=1" in msg and "0.000556 Hz" in msg and "--input-limit min_fps=" in msg
    assert ei.value.name == "min_fps"
    with pytest.raises(LimitExceeded, match="max_duration_s=1200"):
        DEFAULT_LIMITS.check_take(360_000, 100.0)
    with pytest.raises(LimitExceeded, match="max_frame_joints"):
        DEFAULT_LIMITS.check_take(120_000, 120.0, 100)
    DEFAULT_LIMITS.check_take(3000, 120.0, 38)  # a CMU clip


def _npy_header(shape: tuple[int, ...], descr: str = "<f8") -> bytes:
    header = f"{{'descr': '{descr}', 'fortran_order': False, 'shape': {shape!r}, }}"
    header += " " * (63 - (10 + len(header)) % 64) + "\n"
    return b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode("latin1")


def test_check_npz_reads_headers_not_arrays(tmp_path) -> None:
    """A member whose header claims 2 GiB is refused before numpy allocates it."""
    path = tmp_path / "bomb.npz"
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("ok.npy", _npy_header((3,)) + np.zeros(3).tobytes())
        zf.writestr("zeros.npy", _npy_header((2**28,)) + b"\0" * 64)
    with pytest.raises(LimitExceeded, match=r"'zeros' \(268435456,\) float64.*max_array_bytes"):
        check_npz(path, DEFAULT_LIMITS)
    # Within the limits it is recognised as truncated, still without loading anything.
    with pytest.raises(ValueError, match="truncated"):
        check_npz(path, DEFAULT_LIMITS.with_overrides(["max_array_bytes=inf"]))
    good = tmp_path / "good.npz"
    np.savez_compressed(good, a=np.zeros((4, 3), np.float32), b=np.array("text"))
    members = check_npz(good, DEFAULT_LIMITS)
    assert members["a"][0] == (4, 3) and members["a"][1] == np.float32
    assert members["b"][1].kind == "U"


def test_check_npz_declared_size_of_a_compressed_member(tmp_path) -> None:
    path = tmp_path / "z.npz"
    np.savez_compressed(path, big=np.zeros(2**20))  # 8 MiB of zeros, a few kB on disk
    assert path.stat().st_size < 100_000
    with pytest.raises(LimitExceeded, match="max_array_bytes=1000000"):
        check_npz(path, DEFAULT_LIMITS.with_overrides(["max_array_bytes=1e6"]))
    with pytest.raises(LimitExceeded, match="max_file_bytes"):
        check_npz(path, DEFAULT_LIMITS.with_overrides(["max_file_bytes=100"]))


def test_safe_json_depth_and_int_digits_without_recursion() -> None:
    assert safe_json_loads('{"a": [1, {"b": "[[[["}]}', DEFAULT_LIMITS) == {"a": [1, {"b": "[[[["}]}
    with pytest.raises(LimitExceeded, match=r"nesting depth 200000 .*max_depth=64"):
        safe_json_loads("[" * 200_000 + "]" * 200_000, DEFAULT_LIMITS)
    with pytest.raises(LimitExceeded, match="max_int_digits=100"):
        safe_json_loads('{"n": ' + "9" * 5000 + "}", DEFAULT_LIMITS)


def test_check_tree_depth_items_and_shared_arrays() -> None:
    deep: list = []
    node = deep
    for _ in range(100):
        node.append([])
        node = node[0]
    with pytest.raises(LimitExceeded, match="max_depth"):
        check_tree({"x": deep}, DEFAULT_LIMITS)
    # A structure sharing one sub-list 2**40 times is refused after max_elements visits.
    shared: list = [0]
    for _ in range(40):
        shared = [shared, shared]
    with pytest.raises(LimitExceeded, match="max_elements"):
        check_tree(shared, DEFAULT_LIMITS.with_overrides(["max_depth=inf", "max_elements=1e5"]))
    arr = np.zeros(1000)
    with pytest.raises(LimitExceeded, match="max_total_bytes"):
        check_tree([arr] * 20, DEFAULT_LIMITS.with_overrides(["max_total_bytes=100000"]))
    check_tree({"a": [arr, {"b": (1, 2)}]}, DEFAULT_LIMITS)


def test_npz_header_helper_matches_numpy() -> None:
    buf = io.BytesIO()
    np.save(buf, np.zeros(3))
    ours = _npy_header((3,)) + np.zeros(3).tobytes()
    assert np.load(io.BytesIO(ours)).shape == (3,)
