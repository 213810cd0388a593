"""Dependency rules of STYLE.md section 2, checked statically on every module's imports.

Every module of ``grip/``, ``envs/``, ``policies/`` and ``prism_tools/`` is parsed with
:mod:`ast`; its imports (module level and inside functions; not those under
``if TYPE_CHECKING:``, which never run) give the project's import graph. The tests assert that

* the graph has no cycle (:data:`KNOWN_CYCLES` aside),
* nothing outside ``grip.cli`` imports ``grip.cli`` (the edge depends on the library, never the
  reverse),
* each layer imports only what its row of :data:`ALLOWED` permits: project layers, and of the
  external packages those in :data:`CHECKED_EXTERNAL` (stdlib, scipy, matplotlib, trimesh, tqdm
  and the like are not checked), with no exception (:data:`KNOWN_EXCEPTIONS` is empty),

and that the checker finds each kind of violation in a synthetic tree. One runtime probe checks
that importing the numpy layers (``grip.core``, ``grip.task``, ``prism_tools``) pulls in no
heavy package by any route (a package ``__init__``, a third-party import).
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES: tuple[str, ...] = ("grip", "envs", "policies", "prism_tools")
CHECKED_EXTERNAL: tuple[str, ...] = ("numpy", "torch", "mujoco", "gymnasium", "stable_baselines3",
                                     "ray")
EDGE = "*"  # a row that may import anything

# STYLE.md's layer table, with the layers added since (grip.nn, grip.sim, grip.motion, ...).
# A row names a layer (a package, or a module that is stricter than its package) and what its
# modules may import besides their own layer: project layers or modules, and external packages
# of CHECKED_EXTERNAL (a dotted entry such as "gymnasium.spaces" allows only that part).
ALLOWED: dict[str, tuple[str, ...] | str] = {
    "grip": (),  # the package __init__: nothing heavy
    "grip.config": (),  # stdlib only
    "grip.assets": (),  # shipped files' paths, stdlib only
    "grip.core": ("numpy",),
    "prism_tools": ("numpy", "grip.core"),
    "grip.motion": ("numpy", "grip.core"),
    "grip.dataset": ("numpy", "grip.core", "grip.config", "grip.motion", "prism_tools"),
    # torch ring shared by the two learning layers: they may import it, it imports neither
    "grip.nn": ("numpy", "torch", "grip.core"),
    "grip.kinematics": ("numpy", "torch", "grip.core", "grip.config", "grip.nn", "prism_tools"),
    "grip.kinematics.features": ("numpy", "grip.core", "prism_tools"),  # numpy only
    "grip.kinematics.feature_stream": ("numpy", "grip.core", "grip.kinematics.features"),
    "grip.sim": ("numpy", "mujoco", "grip.core", "grip.config"),
    # numpy ring shared by the env, the policies and the pipeline: the tracking task's settings
    # and its observation and AMP layouts (the env computes them, the policies read them)
    "grip.task": ("numpy", "grip.core"),
    "envs": ("numpy", "mujoco", "gymnasium", "grip.core", "grip.config", "grip.sim", "grip.task"),
    # the task on MuJoCo Warp: the env's definitions computed as torch tensors on a device
    "envs.warp": ("numpy", "torch", "mujoco", "grip.core", "grip.config", "grip.sim", "grip.task",
                  "envs"),
    "policies": ("numpy", "torch", "stable_baselines3", "gymnasium.spaces", "grip.core",
                 "grip.config", "grip.nn", "grip.task"),
    "grip.baselines": ("numpy", "mujoco", "grip.core", "grip.config", "grip.sim", "prism_tools"),
    "grip.export": ("numpy", "mujoco", "grip.core", "grip.sim", "grip.kinematics.features",
                    "grip.assets"),  # (the viewer page's three.js files)
    # inference without a training task: sensors -> KinematicsNet -> controller -> humanoid
    "grip.player": ("numpy", "grip.core", "grip.config", "grip.sim", "grip.kinematics.features",
                    "grip.task"),
    "grip.pipeline": ("numpy", "torch", "grip.core", "grip.config", "grip.sim", "grip.kinematics",
                      "grip.task", "grip.player", "envs.scenes"),
    # the commands' units of work as Ray tasks and Tune sweeps (Ray imported only when used)
    "grip.cluster": ("ray", "grip.core"),
    "grip.eval": EDGE,
    "grip.cli": EDGE,
}

# Imports the table forbids that are known and tolerated, (importing layer, imported module).
# None: what the policies share with the env (its settings, observation and AMP layouts) lives
# in grip.task, under both.
KNOWN_EXCEPTIONS: frozenset[tuple[str, str]] = frozenset()

# Import cycles known and tolerated, each as its set of modules.
KNOWN_CYCLES: tuple[frozenset[str], ...] = ()


# ------------------------------------------------------------------------------ the checker
@dataclass(frozen=True)
class Import:
    """One import statement's target, as seen from the importing module.

    Attributes:
        source: The importing module (dotted).
        target: A project module (the longest importable prefix of the name), or the dotted
            name of an external module.
        line: Line of the statement.
        project: Whether ``target`` is a project module.
    """

    source: str
    target: str
    line: int
    project: bool


def find_modules(root: Path, packages: tuple[str, ...]) -> dict[str, Path]:
    """Dotted module name -> file, for every ``.py`` file of ``packages`` under ``root``."""
    mods = {}
    for pkg in packages:
        for p in sorted((root / pkg).rglob("*.py")):
            parts = list(p.relative_to(root).with_suffix("").parts)
            if parts[-1] == "__init__":
                parts = parts[:-1]
            mods[".".join(parts)] = p
    return mods


def _is_type_checking(node: ast.If) -> bool:
    t = node.test
    return (isinstance(t, ast.Name) and t.id == "TYPE_CHECKING") or (
        isinstance(t, ast.Attribute) and t.attr == "TYPE_CHECKING"
    )


def _import_nodes(tree: ast.AST):
    """Every Import/ImportFrom node of ``tree``, skipping ``if TYPE_CHECKING:`` bodies."""
    stack = [tree]
    while stack:
        node = stack.pop()
        if isinstance(node, ast.Import | ast.ImportFrom):
            yield node
        elif isinstance(node, ast.If) and _is_type_checking(node):
            stack.extend(node.orelse)
        else:
            stack.extend(ast.iter_child_nodes(node))


def imports_of(module: str, path: Path, modules: dict[str, Path]) -> list[Import]:
    """The imports of one module, resolved against the project's ``modules``."""

    def project(name: str) -> str | None:
        while name and name not in modules:
            name = name.rpartition(".")[0]
        return name or None

    out: dict[tuple[str, int], Import] = {}
    for node in _import_nodes(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            names = [a.name for a in node.names]
        else:
            base = node.module or ""
            if node.level:  # relative: counted from the importing package
                pkg = module.split(".") if path.name == "__init__.py" else module.split(".")[:-1]
                pkg = pkg[: len(pkg) - node.level + 1]
                base = ".".join([*pkg, *([node.module] if node.module else [])])
            names = [f"{base}.{a.name}" if a.name != "*" else base for a in node.names]
        for name in names:
            target = project(name)
            if target != module:
                imp = Import(module, target or name, node.lineno, target is not None)
                out.setdefault((imp.target, imp.line), imp)
    return sorted(out.values(), key=lambda i: (i.line, i.target))


def all_imports(root: Path, packages: tuple[str, ...] = PACKAGES) -> list[Import]:
    mods = find_modules(root, packages)
    return [imp for m, p in mods.items() for imp in imports_of(m, p, mods)]


def import_cycles(imports: list[Import]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan), each sorted."""
    graph: dict[str, set[str]] = {}
    for imp in imports:
        graph.setdefault(imp.source, set())
        if imp.project:
            graph[imp.source].add(imp.target)
            graph.setdefault(imp.target, set())
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                found.append(sorted(comp))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


def _within(name: str, entry: str) -> bool:
    return name == entry or name.startswith(entry + ".")


def layer_of(module: str, allowed: dict[str, tuple[str, ...] | str] = ALLOWED) -> str | None:
    """The most specific row of ``allowed`` that ``module`` falls under (``"grip"`` holds only
    the package ``__init__``)."""
    rows = [k for k in allowed if module == k or (k != "grip" and module.startswith(k + "."))]
    return max(rows, key=len) if rows else None


def layer_violations(imports: list[Import],
                     allowed: dict[str, tuple[str, ...] | str] = ALLOWED,
                     exceptions: frozenset[tuple[str, str]] = KNOWN_EXCEPTIONS,
                     checked: tuple[str, ...] = CHECKED_EXTERNAL) -> list[str]:  # fmt: skip
    """``"source:line imports target (layer may import ...)"`` for every import its layer's row
    does not allow; modules without a row are reported too."""
    bad = []
    for imp in imports:
        layer = layer_of(imp.source, allowed)
        if layer is None:
            bad.append(f"{imp.source}: no row of the layer table covers this module")
            continue
        row = allowed[layer]
        if row == EDGE:
            continue
        if not imp.project and imp.target.split(".")[0] not in checked:
            continue
        if imp.project and _within(layer_of(imp.target, allowed) or "", layer):
            continue  # within its own layer (a stricter row inside it included)
        if any(_within(imp.target, e) for e in row):
            continue
        if any(layer == x and _within(imp.target, t) for x, t in exceptions):
            continue
        bad.append(f"{imp.source}:{imp.line} imports {imp.target} "
                   f"({layer} may import {', '.join(row) or 'no checked package'})")  # fmt: skip
    return bad


def cli_arrows(imports: list[Import]) -> list[str]:
    """Imports of ``grip.cli`` from any module outside it."""
    return [f"{i.source}:{i.line} imports {i.target}" for i in imports
            if i.project and _within(i.target, "grip.cli")
            and not _within(i.source, "grip.cli")]  # fmt: skip


# ------------------------------------------------------------------------------ the tests
IMPORTS = all_imports(ROOT)


def test_no_import_cycles() -> None:
    cycles = [c for c in import_cycles(IMPORTS) if frozenset(c) not in KNOWN_CYCLES]
    assert not cycles, "import cycles: " + "; ".join(" <-> ".join(c) for c in cycles)


def test_nothing_below_the_edge_imports_the_cli() -> None:
    bad = cli_arrows(IMPORTS)
    assert not bad, "arrows into grip.cli:\n" + "\n".join(bad)


def test_each_layer_imports_only_what_its_row_allows() -> None:
    bad = layer_violations(IMPORTS)
    assert not bad, "layering violations (STYLE.md section 2):\n" + "\n".join(bad)


def test_known_exceptions_name_real_layers() -> None:
    """An exception or allowed cycle that names no real module is a typo, not a rule."""
    mods = set(find_modules(ROOT, PACKAGES))
    for layer, target in KNOWN_EXCEPTIONS:
        assert layer in ALLOWED
        assert target.partition(".")[0] in PACKAGES
    for cycle in KNOWN_CYCLES:
        assert cycle <= mods, f"{sorted(cycle - mods)} are not modules"


def test_the_checker_finds_each_kind_of_violation(tmp_path: Path) -> None:
    """A synthetic tree with one violation of each kind: all are reported, nothing else."""
    files = {
        "grip/__init__.py": "",
        "grip/core/__init__.py": "",
        "grip/core/a.py": "import numpy as np\nfrom grip.core import b\n",
        "grip/core/b.py": "def f():\n    from grip.core.a import np  # a cycle, in a function\n",
        "grip/core/heavy.py": "from torch import nn\n",
        "grip/core/typed.py": "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n"
                              "    import torch\n",
        "grip/eval/__init__.py": "from grip.cli import main\n",
        "grip/cli/__init__.py": "from .main import run\n",
        "grip/cli/main.py": "import torch\nfrom grip.eval import x\ndef run(): ...\n",
        "policies/__init__.py": "",
        "policies/p.py": "from gymnasium import spaces\nimport gymnasium\nimport envs.sim\n"
                         "from envs import observations\n",
        "envs/__init__.py": "",
        "envs/sim.py": "import mujoco\n",
        "envs/observations.py": "import numpy\n",
    }  # fmt: skip
    for rel, text in files.items():
        (tmp_path / rel).parent.mkdir(parents=True, exist_ok=True)
        (tmp_path / rel).write_text(text)
    imports = all_imports(tmp_path, ("grip", "envs", "policies"))
    assert import_cycles(imports) == [["grip.cli.main", "grip.eval"],
                                      ["grip.core.a", "grip.core.b"]]  # fmt: skip
    assert cli_arrows(imports) == ["grip.eval:1 imports grip.cli.main"]
    bad = layer_violations(imports, exceptions=frozenset({("policies", "envs.observations")}))
    assert [b.split(" (")[0] for b in bad] == [
        "grip.core.heavy:1 imports torch.nn",
        "policies.p:2 imports gymnasium",
        "policies.p:3 imports envs.sim",
    ]
    assert layer_of("grip.kinematics.features") == "grip.kinematics.features"
    assert layer_of("grip.kinematics.train") == "grip.kinematics"
    assert layer_of("grip.config") == "grip.config" and layer_of("grip") == "grip"


_PROBE = """
import importlib, json, pkgutil, sys
import grip, grip.config
for pkg in ("grip.core", "grip.task", "prism_tools"):
    m = importlib.import_module(pkg)
    for info in pkgutil.walk_packages(m.__path__, pkg + "."):
        importlib.import_module(info.name)
print(json.dumps(sorted(sys.modules)))
"""


def test_the_numpy_core_pulls_in_no_heavy_package() -> None:
    """At run time, by any route (package ``__init__``s, third-party imports); the numpy ring
    :mod:`grip.task` included."""
    out = subprocess.run([sys.executable, "-c", _PROBE], capture_output=True, text=True,
                         check=True, cwd=ROOT)  # fmt: skip
    loaded = set(json.loads(out.stdout))
    heavy = ("torch", "mujoco", "gymnasium", "stable_baselines3", "envs", "policies")
    bad = sorted(m for m in loaded if m.split(".")[0] in heavy)
    assert not bad, f"importing grip.core/grip.task/prism_tools pulled in {bad[:10]}"
    assert "grip.core.rotations" in loaded and "numpy" in loaded  # the probe did import them
    assert "grip.task.amp" in loaded
