"""Small files that would expand into gigabytes (issue 50, item 2): every loader bounds the total
an input expands to, and the sizes a model file declares, before allocating them.

Each bomb here declares hundreds of megabytes to gigabytes in a file of kilobytes; the limits are
lowered where that keeps the test fast, and each test measures what the load allocated
(``tracemalloc`` in this process for numpy and Python objects, the peak resident memory of a
fresh process for torch): well under the bomb's size, with an error naming the file, the value
and the limit.
"""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import tracemalloc
import zipfile
from pathlib import Path

import pytest
import torch

from grip.core.limits import DEFAULT_LIMITS, LIMITS_ENV
from prism_tools.devices.common import DeviceFileError, read_text_lines
from prism_tools.errors import RecordingError
from prism_tools.io import load_prism_dict

ROOT = Path(__file__).resolve().parents[1]
ASSETS = ROOT / "grip" / "assets"
MB = 2**20


@pytest.fixture(autouse=True)
def _default_limits(monkeypatch) -> None:
    monkeypatch.delenv(LIMITS_ENV, raising=False)


def _peak_mb(fn) -> tuple[float, BaseException | None]:
    """Peak memory traced while ``fn`` runs, MiB, and the exception it raised."""
    tracemalloc.start()
    err = None
    try:
        fn()
    except Exception as e:  # the loaders' refusals
        err = e
    finally:
        peak = tracemalloc.get_traced_memory()[1] / MB
        tracemalloc.stop()
    return peak, err


_MEASURE = """
import json, resource, sys
{setup}
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
try:
    {call}
    result = "loaded"
except Exception as e:
    result = type(e).__name__ + ": " + str(e)
grown = (resource.getrusage(resource.RUSAGE_SELF).ru_maxrss - base) / 1024
print(json.dumps({{"grown_mb": grown, "result": result}}))
"""


def _grown_mb(setup: str, call: str, limits: str = "") -> tuple[float, str]:
    """Peak resident memory a fresh process gained while running ``call`` (after ``setup``,
    which imports what it needs), MiB, and ``"loaded"`` or ``"ErrorType: message"``."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    env.pop(LIMITS_ENV, None)
    if limits:
        env[LIMITS_ENV] = limits
    out = subprocess.run([sys.executable, "-c", _MEASURE.format(setup=setup, call=call)],
                         capture_output=True, text=True, timeout=300, cwd=ROOT,
                         env=env)  # fmt: skip
    assert out.returncode == 0, out.stderr[-3000:]
    got = json.loads(out.stdout.strip().splitlines()[-1])
    return got["grown_mb"], got["result"]


def _deflated_zip(path: Path, members: dict[str, bytes], big: dict[str, int]) -> Path:
    """A zip of ``members`` (deflated) and members ``big`` of that many zero bytes, written in
    chunks (the file stays about 1/1000 of what it declares)."""
    chunk = bytes(MB)
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            z.writestr(name, data)
        for name, size in big.items():
            with z.open(name, "w", force_zip64=True) as f:
                for _ in range(size // MB):
                    f.write(chunk)
    return path


def _torch_bytes(obj) -> bytes:
    buf = io.BytesIO()
    torch.save(obj, buf)
    return buf.getvalue()


def _torch_bomb(path: Path, obj: dict, size: int) -> Path:
    """``obj`` saved by torch with its first storage record replaced by ``size`` deflated zero
    bytes (torch's reader allocates a record's declared size before it looks at it)."""
    src = zipfile.ZipFile(io.BytesIO(_torch_bytes(obj)))
    names = [i.filename for i in src.infolist()]
    storage = next(n for n in names if n.endswith("/data/0"))
    return _deflated_zip(path, {n: src.read(n) for n in names if n != storage}, {storage: size})


# ----------------------------------------------------------------------------------- pickles
def test_pickle_total_is_bounded_before_it_is_built(tmp_path: Path, monkeypatch) -> None:
    """Twenty 30 MB bytearrays (each under max_array_bytes) or twenty lists of a million ints
    (each under max_elements): 600-700 MB from a file of a few hundred bytes."""
    monkeypatch.setenv(LIMITS_ENV, "max_array_bytes=40e6,max_total_bytes=100e6")
    blobs = tmp_path / "blobs.pkl"
    blobs.write_bytes(b"(" + b"c__builtin__\nbytearray\n(I30000000\ntR" * 20 + b"l.")
    lists = tmp_path / "lists.pkl"
    lists.write_bytes(b"(" + b"c__builtin__\nlist\n(c__builtin__\nrange\n(I1000000\ntRtR" * 20
                      + b"l.")  # fmt: skip
    for path in (blobs, lists):
        assert path.stat().st_size < 2000
        peak, err = _peak_mb(lambda p=path: load_prism_dict(p))
        assert isinstance(err, RecordingError), err
        assert str(err).startswith(str(path)) and "max_total_bytes=100000000" in str(err), err
        assert peak < 150, f"{path.name}: {peak:.0f} MiB allocated before the refusal"


# --------------------------------------------------------------------------------------- npz
def test_run_folder_normaliser_npz_total_is_bounded(tmp_path: Path, monkeypatch) -> None:
    from policies.checkpoint import read_vecnorm

    monkeypatch.setenv(LIMITS_ENV, "max_total_bytes=100e6")
    header = b"\x93NUMPY\x01\x00" + b"v\x00"
    text = "{'descr': '<f8', 'fortran_order': False, 'shape': (10000000,), }"
    header += (text + " " * (118 - len(text) - 1) + "\n").encode()
    path = tmp_path / "vecnorm.npz"
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for k in range(4):  # 4 x 80 MB, each under max_array_bytes
            with z.open(f"obs/part{k}/mean.npy", "w") as f:
                f.write(header)
                for _ in range(80):
                    f.write(bytes(1_000_000))
    assert path.stat().st_size < 2 * MB
    peak, err = _peak_mb(lambda: read_vecnorm(path))
    assert isinstance(err, ValueError) and str(err).startswith(str(path)), err
    assert "max_total_bytes=100000000" in str(err), err
    assert peak < 120, f"{peak:.0f} MiB allocated before the refusal"


# ------------------------------------------------------------------------------- torch files
def test_torch_file_of_deflated_zeros_is_refused_before_inflating(tmp_path: Path) -> None:
    """A policy file whose storage record declares 400 MB (the file: 400 kB)."""
    path = _torch_bomb(tmp_path / "policy.pt", {"format": "grip-policy", "w": torch.zeros(4)},
                       400 * MB)  # fmt: skip
    assert path.stat().st_size < MB
    grown, result = _grown_mb("from policies.runner import read_policy_file",
                              f"read_policy_file({str(path)!r})",
                              "max_total_bytes=100e6")  # fmt: skip
    assert result.startswith(f"ValueError: {path}") and "max_total_bytes=100000000" in result, (
        result)  # fmt: skip
    assert grown < 100, f"{grown:.0f} MiB"


def test_run_folder_model_zip_is_bounded(tmp_path: Path) -> None:
    path = _deflated_zip(tmp_path / "model.zip",
                         {"data": b'{"num_timesteps": 1}', "policy.pth": _torch_bytes({})},
                         {"policy.optimizer.pth": 400 * MB})  # fmt: skip
    assert path.stat().st_size < MB
    grown, result = _grown_mb("from policies.checkpoint import read_ppo_zip",
                              f"read_ppo_zip({str(path)!r})", "max_total_bytes=100e6")  # fmt: skip
    assert result.startswith(f"ValueError: {path}"), result
    assert "policy.optimizer.pth" in result and "max_total_bytes=100000000" in result, result
    assert grown < 100, f"{grown:.0f} MiB"


def test_tensor_views_count_in_full(tmp_path: Path) -> None:
    """A one-element storage viewed as 10^9 elements (stride 0): 4 GB when first converted."""
    from grip.nn.weights import load_checkpoint

    path = tmp_path / "views.pt"
    path.write_bytes(_torch_bytes({"version": 1, "config": "{}", "norm_mean": torch.zeros(1),
                                   "norm_std": torch.zeros(1),
                                   "model": {"w": torch.zeros(1).expand(10**9)}}))  # fmt: skip
    with pytest.raises(ValueError, match=rf"{path.name}: .*max_total_bytes="):
        load_checkpoint(path)


def _policy_member() -> dict:
    from policies.runner import read_policy_file

    members, _ = read_policy_file(ASSETS / "policy_default.pt")
    return dict(members[0])


def test_policy_file_declaring_a_huge_network_is_refused_before_building(tmp_path) -> None:
    """The shipped policy with ``actor_sizes`` declaring 12,000-wide layers (576 MB to build)
    around its own small weights."""
    from policies.runner import write_policy_file

    member = _policy_member()
    member["actor_sizes"] = [1275, 12000, 12000, 69]
    path = tmp_path / "wide.pt"
    write_policy_file([member], ["wide"], path)
    grown, result = _grown_mb("from policies.runner import PolicyRunner",
                              f"PolicyRunner.load({str(path)!r})")  # fmt: skip
    assert result.startswith(f"ValueError: {path}") and "actor_sizes" in result, result
    assert grown < 100, f"{grown:.0f} MiB"


def _kin_bomb(tmp_path: Path, **net) -> Path:
    ck = torch.load(ASSETS / "kinematics_default.pt", weights_only=True)
    cfg = json.loads(ck["config"])
    cfg.update(net)
    ck["config"] = json.dumps(cfg)
    path = tmp_path / ("kin_" + "_".join(f"{k}{v}" for k, v in net.items()) + ".pt")
    path.write_bytes(_torch_bytes(ck))
    return path


@pytest.mark.parametrize("net", [{"layers": 60}, {"hidden": 100_000}, {"layers": 10**7}],
                         ids=["layers", "hidden", "absurd-layers"])  # fmt: skip
def test_kinematics_checkpoint_declared_sizes_are_checked_before_building(tmp_path,
                                                                          net) -> None:  # fmt: skip
    """60 LSTM layers: 500 MB to build around 2 layers of weights; 100,000 hidden units: 640 G
    parameters; 10^7 layers: no time to even describe them."""
    path = _kin_bomb(tmp_path, **net)
    grown, result = _grown_mb("from grip.kinematics.inference import KinematicsEstimator",
                              f"KinematicsEstimator.from_checkpoint({str(path)!r})")  # fmt: skip
    name, value = next(iter(net.items()))
    assert result.startswith(f"ValueError: {path}"), result
    assert name in result and str(value) in result, result
    assert grown < 100, f"{grown:.0f} MiB"


def test_declared_parameters_follow_the_limit(monkeypatch) -> None:
    from grip.kinematics.inference import KinematicsEstimator

    KinematicsEstimator.from_checkpoint(ASSETS / "kinematics_default.pt")  # the shipped one
    monkeypatch.setenv(LIMITS_ENV, "max_model_params=1000")
    with pytest.raises(ValueError, match=r"kinematics_default\.pt: .*max_model_params=1000"):
        KinematicsEstimator.from_checkpoint(ASSETS / "kinematics_default.pt")


# ------------------------------------------------------------------------------- device CSVs
def test_device_csv_is_read_line_limited(tmp_path: Path) -> None:
    """One 50 MB line (a file of one 1 GB line took 7.2 GB): refused at that line, read in
    bounded pieces."""
    path = tmp_path / "imu.csv"
    with path.open("wb") as f:
        f.write(b"time,ax,ay,az,gx,gy,gz\n0.0,")
        for _ in range(50):
            f.write(b"1" * MB)
        f.write(b"\n")
    peak, err = _peak_mb(lambda: read_text_lines(path))
    assert isinstance(err, DeviceFileError), err
    assert str(err).startswith(f"{path}: line 2") and "max_line_bytes=1048576" in str(err), err
    assert peak < 10, f"{peak:.0f} MiB allocated reading a file of {path.stat().st_size} bytes"
    lines = read_text_lines(path, DEFAULT_LIMITS.with_overrides(["max_line_bytes=inf"]))
    assert len(lines) == 2 and len(lines[1]) == 50 * MB + 4


def test_device_csv_lines_and_encodings_read_as_before(tmp_path: Path) -> None:
    path = tmp_path / "ok.csv"
    path.write_bytes(b"\xef\xbb\xbftime,a\r\n0.0,1\r\n1.0,2\n\n2.0,3")
    assert read_text_lines(path) == ["time,a", "0.0,1", "1.0,2", "", "2.0,3"]
    path.write_bytes("t,f [N/cm²]\n0,1\n".encode("cp1252"))
    assert read_text_lines(path) == ["t,f [N/cm²]", "0,1"]


@pytest.mark.parametrize("net", [{"layers": 10**7}, {"width": 100_000}], ids=["layers", "width"])
def test_baseline_checkpoint_declared_sizes_are_checked_before_building(tmp_path, net) -> None:
    ck = torch.load(ASSETS / "pip4.pt", weights_only=True)
    cfg = json.loads(ck["config"])
    cfg["net"].update(net)
    ck["config"] = json.dumps(cfg)
    path = tmp_path / "pip.pt"
    path.write_bytes(_torch_bytes(ck))
    grown, result = _grown_mb("from grip.kinematics.baselines import BaselineEstimator",
                              f"BaselineEstimator.from_checkpoint({str(path)!r})")  # fmt: skip
    name, value = next(iter(net.items()))
    assert result.startswith(f"ValueError: {path}"), result
    assert f"{name}={value}" in result, result
    assert grown < 100, f"{grown:.0f} MiB"
