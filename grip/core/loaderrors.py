"""Short, truthful messages for files that ``torch.load(weights_only=True)`` refuses.

torch's own message for a refused file is several lines long and advises re-running with
``weights_only=False``, which would execute whatever a hostile pickle holds. Every loader of
this project (KinematicsNet checkpoints, policy files, run checkpoints) words the refusal
with :func:`describe_load_error` instead. stdlib only: no torch import here.
"""

from __future__ import annotations

_WEIGHTS_ONLY = "Weights only load failed"
_UNPICKLER = "WeightsUnpickler error:"


def describe_load_error(exc: BaseException) -> str:
    """One line saying why a file could not be loaded, without torch's unsafe advice.

    Args:
        exc: The exception ``torch.load(path, weights_only=True)`` raised.

    Returns:
        ``"it holds pickled Python objects, refused without running them (...)"`` when the
        file names a Python callable or class (a hostile or foreign pickle),
        ``"corrupt or not a torch file (...)"`` for any other refusal or read error; the
        parenthesis is torch's own reason, at most 200 characters.
    """
    text = str(exc).strip()
    if _WEIGHTS_ONLY not in text:
        first = text.splitlines()[0] if text else type(exc).__name__
        return f"corrupt or not a torch file ({first[:200]})"
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    for line in lines:
        if "GLOBAL" in line:  # the pickle names a callable or class: never allow-list it
            reason = line.split(_UNPICKLER)[-1].split(". Please use")[0].strip()
            return f"it holds pickled Python objects, refused without running them ({reason[:200]})"
    reason = "unreadable pickle"
    for k, line in enumerate(lines):
        if _UNPICKLER in line:
            after = line.split(_UNPICKLER)[-1].strip()
            reason = after or (lines[k + 1] if k + 1 < len(lines) else reason)
            break
    return f"corrupt or not a torch file ({reason[:200]})"
