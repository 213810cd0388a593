"""The tracking task on MuJoCo Warp (``pip install -e .[gpu]``): N worlds on one device, with
observations, rewards and AMP frames computed as torch tensors where the state lives.

Importing this package imports neither warp nor torch; :mod:`envs.warp.env` needs both.
"""

from __future__ import annotations

import importlib.util


def warp_available() -> bool:
    """Whether ``mujoco_warp`` and ``warp`` can be imported (the ``gpu`` extra)."""
    return all(importlib.util.find_spec(m) is not None for m in ("warp", "mujoco_warp"))
