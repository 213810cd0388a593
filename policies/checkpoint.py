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
``amp.pt`` with :func:`policies.runner.load_weights`.

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

from grip.core.limits import active_limits, safe_json_loads
from grip.core.loaderrors import describe_load_error

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
    """Member ``name`` of the zip, loaded with ``torch.load(weights_only=True)``: a dict."""
    try:
        obj = torch.load(io.BytesIO(archive.read(name)), map_location="cpu", weights_only=True)
    except Exception as e:  # corrupt or hostile members raise many types
        raise ValueError(f"{path}: its {name} is not a state dict: "
                         f"{describe_load_error(e)}") from e  # fmt: skip
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
        with np.load(path, allow_pickle=False) as z:
            return {k: z[k] for k in z.files}
    except Exception as e:  # corrupt or hostile files raise many types
        raise ValueError(f"{path}: not a normaliser file ({str(e)[:200]})") from e
