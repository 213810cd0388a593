"""A training run's checkpoint (``RUN/checkpoint/``) read without running anything it holds.

``model.zip`` is written by stable-baselines3's ``PPO.save``: a ``data`` JSON of the model's
attributes, in which some (observation and action spaces, schedules, the policy class and its
kwargs, the last observations, the episode buffers) are cloudpickled under ``":serialized:"``,
and the state dicts of the networks and of their optimiser as torch files (``policy.pth``,
``policy.optimizer.pth``). ``PPO.load`` unpickles every serialized entry, which runs whatever
code a tampered file names. :func:`read_ppo_zip` never does: it reads the two state dicts with
``torch.load(weights_only=True)`` and only plain JSON integers (the step counters) from
``data``, ignoring every serialized entry; the model itself is rebuilt from the run's own
settings (:class:`policies.train.PolicyTrainer` on resume, :func:`policies.runner.export_policy`
as plain MLPs). ``vecnorm.npz`` is read with ``allow_pickle=False`` (:func:`read_vecnorm`) and
``amp.pt`` with :func:`load_weights`.

Every reader of a run folder goes through here; any run folder written by ``grip
policy train`` (older ones included) reads this way.
"""

from __future__ import annotations

import dataclasses
import io
import os
import zipfile
import zlib
from pathlib import Path

import numpy as np
import torch

from grip.core.limits import (
    LimitExceeded,
    active_limits,
    check_file_size,
    check_npz,
    check_zip,
    safe_json_loads,
)
from grip.nn.weights import load_torch_file

PPO_COUNTERS: tuple[str, ...] = ("num_timesteps", "_n_updates", "_episode_num")
"""The attributes a resumed model takes from the ``data`` JSON (plain integers); the first is
required."""


@dataclasses.dataclass(frozen=True)
class PPOCheckpoint:
    """The state of a PPO model saved in a run's ``model.zip``.

    Attributes:
        path: The file (named in errors).
        policy: ``model.policy.state_dict()``: the policy, value network and log std, by name.
        optimizer: ``model.policy.optimizer.state_dict()`` (Adam's moments and settings).
        counters: The :data:`PPO_COUNTERS` found in the file, as ints.
    """

    path: Path
    policy: dict[str, torch.Tensor]
    optimizer: dict
    counters: dict[str, int]

    def restore(self, model) -> None:
        """Put this state into ``model``, a stable-baselines3 PPO built from the run's settings:
        network weights, optimiser state and step counters.

        Raises:
            ValueError: naming the file, when its networks do not fit ``model``'s.
        """
        params = {"policy": self.policy, "policy.optimizer": self.optimizer}
        try:
            model.set_parameters(params, exact_match=True, device=model.device)
        except (RuntimeError, ValueError, KeyError, TypeError, IndexError) as e:
            raise ValueError(f"{self.path}: its networks do not fit this run's settings "
                             f"({str(e)[:300]})") from e  # fmt: skip
        for name, value in self.counters.items():
            setattr(model, name, value)


def _torch_member(archive: zipfile.ZipFile, name: str, path: Path) -> dict:
    """Member ``name`` of the zip (its size already checked), loaded with
    :func:`grip.nn.weights.load_torch_file` (``weights_only=True``, its expansion bounded):
    a dict."""
    obj = load_torch_file(archive.read(name), "state dict", f"{path}: its {name}")
    if not isinstance(obj, dict):
        raise ValueError(f"{path}: its {name} is not a state dict ({type(obj).__name__})")
    return obj


def read_ppo_zip(path: str | os.PathLike) -> PPOCheckpoint:
    """The networks, optimiser state and step counters of a stable-baselines3 PPO zip, read
    without unpickling its ``":serialized:"`` entries (they are ignored).

    Raises:
        FileNotFoundError: No such file.
        ValueError: ``"{path}: ..."``: not a zip, a member missing, a state dict that is corrupt
            or holds pickled Python objects (never executed), or no step counter.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such PPO checkpoint")
    try:
        check_file_size(path, active_limits())
        check_zip(path, active_limits(), "PPO checkpoint")
    except LimitExceeded as e:
        raise ValueError(f"{path}: {e}") from None
    except (zipfile.BadZipFile, OSError, EOFError, zlib.error) as e:
        raise ValueError(f"{path}: not a PPO checkpoint (not a readable zip: {e})") from e
    try:
        with zipfile.ZipFile(path) as archive:
            names = set(archive.namelist())
            missing = [n for n in ("data", "policy.pth", "policy.optimizer.pth") if n not in names]
            if missing:
                raise ValueError(f"{path}: not a stable-baselines3 PPO checkpoint (no "
                                 f"{', '.join(missing)})")  # fmt: skip
            try:
                data = safe_json_loads(archive.read("data").decode("utf-8"), active_limits(),
                                       "its data JSON")  # fmt: skip
            except (ValueError, UnicodeDecodeError) as e:
                raise ValueError(f"{path}: its data is not JSON ({str(e)[:300]})") from e
            policy = _torch_member(archive, "policy.pth", path)
            optimizer = _torch_member(archive, "policy.optimizer.pth", path)
    except (zipfile.BadZipFile, zipfile.LargeZipFile, EOFError, OSError, zlib.error) as e:
        raise ValueError(f"{path}: not a PPO checkpoint (not a readable zip: {e})") from e
    if not isinstance(data, dict):
        raise ValueError(f"{path}: its data is not a JSON object")
    bad = [k for k, v in policy.items() if not isinstance(k, str) or not torch.is_tensor(v)]
    if bad:
        raise ValueError(f"{path}: its policy.pth holds non-tensors ({bad[:3]})")
    if not {"state", "param_groups"} <= set(optimizer):
        raise ValueError(f"{path}: its policy.optimizer.pth is not an optimiser state")
    counters = {}
    for name in PPO_COUNTERS:
        value = data.get(name)
        if isinstance(value, int) and not isinstance(value, bool) and value >= 0:
            counters[name] = value
        elif name == PPO_COUNTERS[0]:
            raise ValueError(f"{path}: its data has no {name} (a plain non-negative integer)")
    return PPOCheckpoint(path, policy, optimizer, counters)


def load_weights(path: str | os.PathLike, what: str) -> object:
    """``torch.load(path, weights_only=True)`` on the CPU; a refusal names the file and why.

    Raises:
        FileNotFoundError: No such file.
        ValueError: ``"{path}: not a {what}: ..."`` for a corrupt file or one holding pickled
            Python objects (never executed); ``"{path}: ... the limit NAME=..."`` for one that
            would expand beyond the input limits (:func:`grip.nn.weights.load_torch_file`).
    """
    return load_torch_file(path, what)


def read_vecnorm(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """The normaliser statistics a run saved (``vecnorm.npz``: plain arrays, read with
    ``allow_pickle=False``), in the order they were written.

    Raises:
        FileNotFoundError: No such file.
        ValueError: ``"{path}: ..."`` for a corrupt file or one holding pickled objects.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such normaliser file")
    try:
        check_npz(path, active_limits())
    except LimitExceeded as e:
        raise ValueError(f"{path}: {e}") from None
    except (ValueError, OSError, EOFError, zlib.error) as e:  # a damaged zip
        raise ValueError(f"{path}: not a normaliser file ({str(e)[:200]})") from e
    try:
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except Exception as e:  # corrupt or hostile files raise many types
        raise ValueError(f"{path}: not a normaliser file ({str(e)[:200]})") from e


PACKED_MOMENTS = torch.bfloat16
"""The dtype :func:`pack_checkpoint` stores optimiser moments in: the float32 exponent range
(Adam's second moments reach 1e-12, below fp16's), half the bytes."""


def _moments_packed(optimizer: dict) -> dict:
    """An optimiser state dict whose floating tensors of more than one element (Adam's
    moments) are :data:`PACKED_MOMENTS`; scalars (the step counts) and settings unchanged.
    ``torch.optim.Optimizer.load_state_dict`` casts them back to the parameters' dtype."""
    state = {}
    for key, entry in optimizer["state"].items():
        state[key] = {name: (v.to(PACKED_MOMENTS)
                             if torch.is_tensor(v) and v.is_floating_point() and v.dim() > 0
                             else v)
                      for name, v in entry.items()}  # fmt: skip
    return {**optimizer, "state": state}


def _packed_zip(src: Path, dst: Path) -> None:
    """``src``'s PPO zip written to ``dst`` with its optimiser moments packed and every member
    deflated; the other members are copied as bytes (never loaded)."""
    ck = read_ppo_zip(src)  # validates the file; the optimiser is read without unpickling
    buf = io.BytesIO()
    torch.save(_moments_packed(ck.optimizer), buf)
    with zipfile.ZipFile(src) as zin, zipfile.ZipFile(dst, "w", zipfile.ZIP_DEFLATED) as zout:
        for info in zin.infolist():
            data = buf.getvalue() if info.filename == "policy.optimizer.pth" else zin.read(info)
            zout.writestr(info.filename, data)


def _progress(state: object) -> tuple[int, int]:
    """``(stage_index, stage_done)`` of a run's ``state.json`` (``(-1, -1)``: unreadable)."""
    if not isinstance(state, dict):
        return -1, -1
    got = [state.get(k) for k in ("stage_index", "stage_done")]
    ok = all(isinstance(v, int) and not isinstance(v, bool) for v in got)
    return (int(got[0]), int(got[1])) if ok else (-1, -1)


def _refuse_foreign(run_dir: Path, out_dir: Path, state: dict) -> None:
    """Refuse to pack over a folder holding another run's resume state (its ``config.json``
    differs or is missing) or a later state of this run (packing would roll it back).

    Raises:
        ValueError: naming ``out_dir``, why, and the way out (another folder, ``--overwrite``).
    """
    from grip.core.rundir import CONFIG_FILE, RunDir

    target = RunDir(out_dir)
    if not target.has_checkpoint():
        return
    hint = "choose another --out, or pass --overwrite to replace it"
    theirs = out_dir / CONFIG_FILE
    if not theirs.is_file() or theirs.read_bytes() != (run_dir / CONFIG_FILE).read_bytes():
        raise ValueError(f"{out_dir}: holds the resume state of another run (its "
                         f"{CONFIG_FILE} differs from {run_dir}'s); packing would overwrite it: "
                         f"{hint}")  # fmt: skip
    try:
        old = _progress(target.read_state())
    except ValueError:
        old = (-1, -1)
    new = _progress(state)
    if old > new:
        raise ValueError(f"{out_dir}: holds this run's resume state from further on (stage "
                         f"{old[0]}, {old[1]} steps; {run_dir} is at stage {new[0]}, {new[1]}): "
                         f"packing would roll it back: {hint}")  # fmt: skip


def pack_checkpoint(run_dir: str | os.PathLike, out_dir: str | os.PathLike,
                    overwrite: bool = False) -> dict[str, int]:  # fmt: skip
    """Write the resume state of a ``grip policy train`` run (``config.json`` and
    ``checkpoint/``) to ``out_dir`` with the Adam moments of the policy's and of the
    discriminator's optimiser in bfloat16 (:data:`PACKED_MOMENTS`) and ``model.zip``
    deflated: the form a long run commits between sessions. The network weights, the
    normaliser and the counters are kept exactly; a run resumed from it continues as from the
    original up to the moments' rounding (a relative 0.4 %). Nothing in the run is unpickled.

    Returns:
        Bytes per file written (``checkpoint/model.zip``, ...), and ``"total"``.

    ``out_dir`` may hold an earlier packed copy of the same run (the same ``config.json``,
    not further on), which is replaced; another run's resume state there is refused unless
    ``overwrite``.

    Raises:
        FileNotFoundError: ``run_dir`` has no ``checkpoint/`` or ``config.json``.
        ValueError: naming the file, for a corrupt checkpoint; ``out_dir`` is ``run_dir``, or
            holds another run's resume state or this run's from further on (without
            ``overwrite``).
    """
    from grip.core.rundir import CHECKPOINT_DIR, CONFIG_FILE, STATE_FILE, RunDir

    run_dir, out_dir = Path(run_dir), Path(out_dir)
    ck_dir = run_dir / CHECKPOINT_DIR
    names = ("model.zip", "amp.pt", "vecnorm.npz", STATE_FILE)
    missing = [n for n in names if not (ck_dir / n).is_file()]
    if missing or not (run_dir / CONFIG_FILE).is_file():
        raise FileNotFoundError(f"{run_dir}: not a 'grip policy train' run with a checkpoint "
                                f"(missing {', '.join(missing) or CONFIG_FILE})")  # fmt: skip
    if out_dir.exists() and out_dir.resolve() == run_dir.resolve():
        raise ValueError(f"{out_dir}: is the run itself; pack into another folder")
    read_vecnorm(ck_dir / "vecnorm.npz")  # refuse a corrupt or pickled normaliser
    amp = load_weights(ck_dir / "amp.pt", "discriminator checkpoint")
    if not isinstance(amp, dict) or not isinstance(amp.get("opt"), dict):
        raise ValueError(f"{ck_dir / 'amp.pt'}: not a discriminator checkpoint (no 'opt')")
    amp = {**amp, "opt": _moments_packed(amp["opt"])}
    state_text = (ck_dir / STATE_FILE).read_text()
    state = safe_json_loads(state_text, active_limits(), str(STATE_FILE))
    if not overwrite:
        _refuse_foreign(run_dir, out_dir, state)

    def write(tmp: Path) -> None:
        _packed_zip(ck_dir / "model.zip", tmp / "model.zip")
        torch.save(amp, tmp / "amp.pt")
        (tmp / "vecnorm.npz").write_bytes((ck_dir / "vecnorm.npz").read_bytes())

    out_dir.mkdir(parents=True, exist_ok=True)
    rundir = RunDir(out_dir)
    rundir.save_checkpoint(write, state)
    (out_dir / CONFIG_FILE).write_bytes((run_dir / CONFIG_FILE).read_bytes())
    sizes = {f"{CHECKPOINT_DIR}/{n}": (out_dir / CHECKPOINT_DIR / n).stat().st_size
             for n in names}  # fmt: skip
    sizes[CONFIG_FILE] = (out_dir / CONFIG_FILE).stat().st_size
    sizes["total"] = sum(sizes.values())
    return sizes
