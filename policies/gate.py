"""A gate over frozen controllers (issue 47, part 4): every frame one member drives the
humanoid, the one a classifier of the wearables' features picks.

Three students in a row, each distilled from a locomotion teacher and a specialist, kept the
walks and lost the specialist's motions (docs/teacher_student.md); a gate keeps every member as
it was trained. The gate reads only the ``"sensor"`` observation part (the KinematicsNet's
input features of the frame: the IMUs and insoles) and, with a context window, the
``"sensor_context"`` part (each feature's mean and standard deviation over the recording's last
``window`` frames, :attr:`grip.task.config.TrackingEnvConfig.sensor_context`), so it is trained
from a dataset's recordings and their motion categories, without any simulation, and decides
alike in training data, in ``grip policy eval`` and in a reconstruction. The context is the
recording's, not the controller's: it needs no state, and a recovery or a new segment changes
nothing of it. Route 0 is the default controller (every
category no family names); route ``i`` the ``i``-th family's controller
(:class:`policies.teachers.Specialist`, the ``--specialist`` syntax of ``grip policy
distill``).

A gated file is a policy file of the members (:func:`policies.ensemble.ensemble_members`) with
the gate stored beside them (:data:`GATE_KEY`); :func:`policies.controller.load_controller`
reads it as a :class:`GatedController`, and ``grip policy combine --member K`` takes one member
out of it.
"""

from __future__ import annotations

import dataclasses
import fnmatch
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from grip.task.observations import sensor_context_rows

GATE_KEY = "gate"
"""Where a policy file stores its gate (:func:`gate_payload`)."""
GATE_FORMAT = "grip-gate"


def route_of(families: Sequence[Sequence[str]], category: str) -> int:
    """The route of ``category``: 1 + the index of the first family with a matching glob, 0 (the
    default controller) when none matches."""
    for i, globs in enumerate(families):
        if any(fnmatch.fnmatch(category, g) for g in globs):
            return i + 1
    return 0


def gate_network(in_dim: int, hidden: Sequence[int], routes: int) -> nn.Sequential:
    """The classifier: an MLP with ELU from the normalised features to one logit per route."""
    sizes = [in_dim, *[int(h) for h in hidden], routes]
    layers: list[nn.Module] = []
    for i in range(len(sizes) - 1):
        layers.append(nn.Linear(sizes[i], sizes[i + 1]))
        if i < len(sizes) - 2:
            layers.append(nn.ELU())
    return nn.Sequential(*layers)


@dataclass
class Gate:
    """A trained gate.

    Attributes:
        net: :func:`gate_network`.
        mean, std: Normaliser of the classifier's input: ``(F,)`` the sensor features of the
            frame, or ``(3F,)`` with ``window > 1``: the frame's, then the context's
            (:func:`grip.task.observations.sensor_context_rows`).
        families: The category globs of routes 1, 2, ... (route 0: every other category).
        hidden: The hidden layer sizes of ``net``.
        window: Frames of context the classifier reads beside the frame (each feature's mean
            and standard deviation over the last ``window`` frames); 1: the frame alone.
    """

    net: nn.Sequential
    mean: np.ndarray
    std: np.ndarray
    families: list[tuple[str, ...]]
    hidden: tuple[int, ...]
    window: int = 1

    @property
    def in_dim(self) -> int:
        """The sensor features of one frame, F."""
        n = int(self.mean.shape[0])
        return n // 3 if self.window > 1 else n

    def recording_inputs(self, x: np.ndarray) -> np.ndarray:
        """:func:`recording_inputs` with this gate's window."""
        return recording_inputs(x, self.window)

    def recording_routes(self, x: np.ndarray) -> np.ndarray:
        """``(T,)`` the route of every frame of a recording (:meth:`recording_inputs`)."""
        return self.routes(self.recording_inputs(x))

    def route_of(self, category: str) -> int:
        """The route a clip of ``category`` is trained to take (:func:`route_of`)."""
        return route_of(self.families, category)

    @torch.no_grad()
    def probabilities(self, sensor: np.ndarray) -> np.ndarray:
        """``(B, routes)`` route probabilities of ``(B, in)`` classifier inputs (the sensor
        features, with their context when ``window > 1``)."""
        z = (np.atleast_2d(np.asarray(sensor, np.float64)) - self.mean) / self.std
        return torch.softmax(self.net(torch.from_numpy(z.astype(np.float32))), -1).numpy()

    def routes(self, sensor: np.ndarray) -> np.ndarray:
        """``(B,)`` the most probable route of every row."""
        return self.probabilities(sensor).argmax(-1)


def recording_inputs(x: np.ndarray, window: int) -> np.ndarray:
    """The classifier's input rows of a whole recording's sensor features ``(T, F)``: the
    frames, with their context when ``window > 1`` (what the environment's ``sensor_context``
    observation gives frame by frame)."""
    x = np.asarray(x, np.float64)
    return np.hstack([x, sensor_context_rows(x, window)]) if window > 1 else x


def fit_gate(features: Sequence[np.ndarray], categories: Sequence[str],
             families: Sequence[Sequence[str]], hidden: Sequence[int] = (128, 128),
             steps: int = 3000, batch: int = 512, lr: float = 1e-3, noise: float = 0.05,
             stride: int = 2, seed: int = 0, window: int = 1,
             progress=None) -> tuple[Gate, list[float]]:  # fmt: skip
    """Train a gate on recordings' sensor features ``(T_i, F)`` and their categories: every
    ``stride``-th frame labelled with its category's route, the routes weighted to equal
    shares (the rare families are a few per cent of the frames), Gaussian noise of ``noise``
    standard deviations on the normalised features. With ``window > 1`` the classifier reads
    each frame's context over the last ``window`` frames too (:attr:`Gate.window`).

    Returns:
        The gate and the loss of every step.

    Raises:
        ValueError: No recordings, features of different widths, or a route without frames.
    """
    if not features or len(features) != len(categories):
        raise ValueError("a gate needs recordings, each with its category")
    if len({f.shape[-1] for f in features}) != 1:
        raise ValueError("the recordings' sensor features differ in width")
    if window < 1:
        raise ValueError(f"the gate's window must be >= 1 frame, got {window}")
    fams = [tuple(f) for f in families]
    xs = [recording_inputs(f, window)[::stride] for f in features]
    ys = [np.full(len(x), route_of(fams, c), np.int64) for x, c in zip(xs, categories, strict=True)]
    x, y = np.concatenate(xs), np.concatenate(ys)
    routes = len(fams) + 1
    counts = np.bincount(y, minlength=routes)
    if np.any(counts == 0):
        empty = [("the default" if i == 0 else ",".join(fams[i - 1]))
                 for i in np.flatnonzero(counts == 0)]  # fmt: skip
        raise ValueError(f"no training frames for the route(s) {empty}")
    mean, std = x.mean(0), x.std(0) + 1e-3
    gen = torch.Generator().manual_seed(seed)
    torch.manual_seed(seed)
    net = gate_network(x.shape[1], hidden, routes)
    xt = torch.from_numpy(((x - mean) / std).astype(np.float32))
    yt = torch.from_numpy(y)
    weight = torch.tensor(len(y) / (routes * counts), dtype=torch.float32)
    opt = torch.optim.Adam(net.parameters(), lr=lr)
    losses = []
    for _ in range(steps):
        i = torch.randint(0, len(xt), (batch,), generator=gen)
        xb = xt[i] + noise * torch.randn(batch, xt.shape[1], generator=gen)
        loss = nn.functional.cross_entropy(net(xb), yt[i], weight=weight)
        opt.zero_grad()
        loss.backward()
        opt.step()
        losses.append(loss.item())
        if progress is not None:
            progress(losses[-1])
    net.eval()
    return Gate(net, mean, std, fams, tuple(int(h) for h in hidden), int(window)), losses


def gate_payload(gate: Gate) -> dict:
    """What a policy file stores of ``gate`` (tensors and JSON-able values only)."""
    return {
        "format": GATE_FORMAT,
        "hidden": list(gate.hidden),
        "families": [list(f) for f in gate.families],
        "window": int(gate.window),
        "mean": torch.from_numpy(gate.mean.astype(np.float64)),
        "std": torch.from_numpy(gate.std.astype(np.float64)),
        "net": {k: v.detach().clone() for k, v in gate.net.state_dict().items()},
    }


def gate_from_payload(d: object, where: str) -> Gate:
    """The gate of a policy file (``where`` names it in errors).

    Raises:
        ValueError: naming ``where``, when the stored gate is malformed.
    """
    try:
        if not isinstance(d, dict) or d.get("format") != GATE_FORMAT:
            raise ValueError("not a gate")
        fams = [tuple(str(g) for g in f) for f in d["families"]]
        hidden = tuple(int(h) for h in d["hidden"])
        window = int(d.get("window", 1))  # (gates before the context window read one frame)
        mean = d["mean"].double().numpy()
        std = d["std"].double().numpy()
        if mean.shape != std.shape or mean.ndim != 1 or not np.all(std > 0):
            raise ValueError("normaliser of the wrong shape or with a zero deviation")
        if window < 1 or (window > 1 and mean.shape[0] % 3):
            raise ValueError(f"a window of {window} frames over {mean.shape[0]} inputs")
        net = gate_network(int(mean.shape[0]), hidden, len(fams) + 1)
        net.load_state_dict(d["net"])
    except (KeyError, TypeError, AttributeError, RuntimeError, ValueError) as e:
        raise ValueError(f"{where}: malformed gate ({e})") from e
    net.eval()
    return Gate(net, mean, std, fams, hidden, window)


class GatedController:
    """Members of which one drives each row, by :class:`Gate`: a
    :class:`policies.controller.Controller`.

    Args:
        members: The default controller, then one per family of ``gate`` (each a
            :class:`policies.runner.PolicyRunner`), driving the humanoid alike
            (:func:`policies.ensemble.check_same_driving`).
        names: What errors call each member.
        gate: Its families must be as many as the members after the first.

    Raises:
        ValueError: Members and routes differ in number, or members do not drive alike.
    """

    def __init__(self, members: Sequence, names: Sequence[str], gate: Gate) -> None:
        from policies.ensemble import check_same_driving

        if len(members) != len(gate.families) + 1:
            raise ValueError(f"a gate of {len(gate.families) + 1} routes over {len(members)} "
                             "policies: one policy per route expected")  # fmt: skip
        check_same_driving(members, names)
        self.members = list(members)
        self.gate = gate
        first = members[0]
        self.obs_keys = list(first.obs_keys)
        # (a gate with context needs the environment's sensor_context observation part)
        self.env_cfg = dataclasses.replace(first.env_cfg, sensor_context=gate.window
                                           if gate.window > 1 else 0)  # fmt: skip
        self.amp_window = first.amp_window
        self.disc = first.disc
        self.info = dict(first.info, members=list(names),
                         gate=["default"] + [",".join(f) for f in gate.families],
                         gate_window=gate.window)  # fmt: skip
        self.last_routes: np.ndarray | None = None

    def use_action_noise(self, scale: float, seed: int = 0) -> None:
        for i, m in enumerate(self.members):
            m.use_action_noise(scale, seed + i)

    def act(self, obs: dict) -> np.ndarray:
        """The action of each row's routed member (``last_routes``: the routes taken)."""
        sensor = np.asarray(obs["sensor"])
        if sensor.shape[-1] != self.gate.in_dim:
            raise ValueError(
                f"the gate reads {self.gate.in_dim} sensor features, the "
                f"observation has {sensor.shape[-1]} (another sensor set?)"
            )
        single = sensor.ndim == 1
        if self.gate.window > 1:
            if "sensor_context" not in obs:
                raise ValueError(f"the gate reads {self.gate.window} frames of context: build "
                                 "the environment from the controller's env_cfg (its "
                                 "sensor_context observation part)")  # fmt: skip
            sensor = np.concatenate([np.atleast_2d(sensor),
                                     np.atleast_2d(np.asarray(obs["sensor_context"]))], -1)
        routes = self.gate.routes(sensor)
        self.last_routes = routes
        if single:
            return self.members[int(routes[0])].act(obs)
        out = None
        for r in np.unique(routes):
            rows = np.flatnonzero(routes == r)
            a = self.members[int(r)].act({k: np.asarray(v)[rows] for k, v in obs.items()})
            if out is None:
                out = np.empty((len(routes), a.shape[-1]), a.dtype)
            out[rows] = a
        return out

    def fall_probability(self, amp_obs: np.ndarray) -> np.ndarray:
        """The default member's discriminator probability (GRIP's fall detector)."""
        return self.members[0].fall_probability(amp_obs)


def write_gated_policy(files: Sequence, gate: Gate, out, precision: str | None = None) -> int:
    """Write the policy files ``files`` (the default controller, then one per family of
    ``gate``, each one policy) and ``gate`` as one gated policy file; returns its size in bytes.

    Raises:
        ValueError: naming the file, when one is not a single policy, or they do not drive the
            humanoid alike (:func:`policies.ensemble.ensemble_members`).
    """
    from policies.ensemble import ensemble_members, member_payloads
    from policies.runner import repack, write_policy_file

    if len(files) != len(gate.families) + 1:
        raise ValueError(f"a gate of {len(gate.families) + 1} routes needs as many policies, "
                         f"got {len(files)}")  # fmt: skip
    payloads, names = [], []
    for f in files:
        got = member_payloads(f)
        if len(got) != 1:
            raise ValueError(f"{f}: an ensemble of {len(got)} policies; a gate routes to single "
                             "policies (grip policy combine --member K takes one out)")  # fmt: skip
        payloads.append(got[0][0])
        names.append(str(f))
    kept = ensemble_members(payloads, names)  # (refuses members that drive otherwise)
    if precision is not None:
        kept = [repack(m, precision) for m in kept]
    return write_policy_file(kept, names, out, gate=gate_payload(gate))


def route_counts(
    gate: Gate, features: Sequence[np.ndarray], categories: Sequence[str]
) -> dict[str, np.ndarray]:
    """Per category (sorted), ``(routes,)`` how many of its frames the gate sends to each
    route."""
    routes = len(gate.families) + 1
    counts: dict[str, np.ndarray] = {}
    for f, c in zip(features, categories, strict=True):
        n = np.bincount(gate.recording_routes(f), minlength=routes)
        counts[c] = counts.get(c, 0) + n
    return dict(sorted(counts.items()))


def route_table(
    gate: Gate,
    features: Sequence[np.ndarray],
    categories: Sequence[str],
    route_names: Sequence[str],
) -> str:
    """Markdown: per category, its frames, the route it is trained to take and the share of its
    frames the gate sends to each route (:func:`route_counts`)."""
    counts = route_counts(gate, features, categories)
    head = (
        "| category | frames | trained route | "
        + " | ".join(f"to {n} %" for n in route_names)
        + " |"
    )
    lines = [head, "|---|---:|---|" + "---:|" * len(route_names)]
    for c, n in counts.items():
        lines.append(
            f"| {c} | {int(n.sum())} | {route_names[gate.route_of(c)]} | "
            + " | ".join(f"{100 * v / max(n.sum(), 1):.1f}" for v in n)
            + " |"
        )
    return "\n".join(lines)
