"""The house rules of the package's layout: the layer order, small modules, the design table.

* A module imports only from its own layer and the layers before it (``docs/design.md``): every
  ``import`` and ``from`` is read with ``ast`` -- at the top, in functions, under ``TYPE_CHECKING``,
  relative ones -- and so is every module-path string (``"warp_critic.x.y:func"``,
  ``"warp_critic.x.y"``) that a registry imports later. The imports up a layer that exist today are
  listed in :data:`KNOWN_UPWARD`: a new one fails, and so does a listed one that is gone.
* Inside ``reproduce/`` the same holds for its own layers, :data:`REPRODUCE_LAYERS`: ``engine/``
  below ``experiments/`` below ``report/``, its root modules (``pipeline``) above all three; and the
  engine knows no paper and no method: it imports only :data:`ENGINE_MAY_IMPORT` besides itself.
* No import circle: no module reaches itself through the modules it imports (at the top, in
  functions, under ``TYPE_CHECKING``, or by a module-path string), so an import inside a function
  never hides one. A package's ``__init__`` counts as importing nothing: its exports are lazy.
* Every module has at most 400 lines (the ones still over are listed, and must stay listed only
  while they are over); every function at most 100 (the same, by module file name and function).
* ``docs/design.md``'s module table is the one ``tools/design_table.py`` generates: every module,
  described by its own docstring.

Reads source files only; imports nothing of the package.
"""

from __future__ import annotations

import ast
import re
from pathlib import Path

import pytest
from conftest import ROOT
from helpers import load_tool

PACKAGE = ROOT / "warp_critic"
MAX_LINES = 400

#: imports up a layer that exist today (module -> module it imports); a new one fails the test
KNOWN_UPWARD: set[tuple[str, str]] = set()
#: modules still over MAX_LINES (path under warp_critic/ -> why it is allowed for now)
KNOWN_LONG: dict[str, str] = {}  # module -> why it may stay over the limit for now
MAX_FUNCTION_LINES = 100
#: packages that are no layer: shipped with the package, first used by this layer
RESOURCES = {"kernels": "physics", "scenes": "physics"}
_MODULE_PATH = re.compile(r"^warp_critic(?:\.[A-Za-z_]\w*)+(?::[A-Za-z_][\w.]*)?$")


TOOL = load_tool("design_table")
LAYERS: tuple[str, ...] = TOOL.LAYERS


def module_name(path: Path, package: Path = PACKAGE) -> str:
    parts = [package.name, *path.relative_to(package).with_suffix("").parts]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def references(source: str, module: str, is_package: bool = False) -> list[tuple[str, int]]:
    """Every module of the package that ``source`` (the module ``module``) names: imported
    anywhere (relative imports resolved), or written as a module-path string. ``(name, line)``."""
    package = module if is_package else module.rpartition(".")[0]
    found: list[tuple[str, int]] = []
    for node in ast.walk(ast.parse(source)):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                stem = ".".join(base + ([node.module] if node.module else []))
            else:
                stem = node.module or ""
            # ``from . import name``: name is a module; ``from pkg import name``: pkg decides
            names = [f"{stem}.{a.name}" for a in node.names] if node.module is None else [stem]
        elif isinstance(node, ast.Constant) and isinstance(node.value, str):
            if _MODULE_PATH.match(node.value):
                names = [node.value.split(":")[0]]
        found += [(n, node.lineno) for n in names if n.split(".")[0] == "warp_critic"]
    return found


def layer(module: str) -> int:
    """The layer index of a module of the package. The package root (the public API of every
    layer, and the version) counts as the last layer: the CLI may read it, nothing below."""
    parts = module.split(".")
    if len(parts) < 2:
        return len(LAYERS) - 1
    name = RESOURCES.get(parts[1], parts[1])
    if name not in LAYERS:
        raise AssertionError(f"{module}: {parts[1]}/ is no layer of docs/design.md: {LAYERS}")
    return LAYERS.index(name)


def upward_imports(package: Path = PACKAGE) -> dict[tuple[str, str], list[str]]:
    """``(module, imported module) -> ['path:line', ...]`` for every import up a layer."""
    found: dict[tuple[str, str], list[str]] = {}
    for path in sorted(package.rglob("*.py")):
        module = module_name(path, package)
        if module == package.name:  # the package root re-exports every layer's public API
            continue
        own = layer(module)
        source = path.read_text(encoding="utf-8")
        for target, line in references(source, module, path.name == "__init__.py"):
            if layer(target) > own:
                where = f"{path.relative_to(package.parent)}:{line}"
                found.setdefault((module, target), []).append(where)
    return found


def test_the_scanner_sees_every_form_of_import(tmp_path):
    """Each form the rule covers, in a package laid out like ours: found, with its line."""
    pkg = tmp_path / "warp_critic"
    (pkg / "physics").mkdir(parents=True)
    (pkg / "physics" / "__init__.py").write_text("")
    (pkg / "physics" / "ok.py").write_text("from warp_critic.core import errors\n")
    (pkg / "physics" / "bad.py").write_text(
        "import warp_critic.running.loop\n"
        "from typing import TYPE_CHECKING\n"
        "if TYPE_CHECKING:\n"
        "    from warp_critic.methods.ours import TrainConfig\n"
        "def f():\n"
        "    from ..learning import rollout\n"
        "    from .. import cli\n"
        "    return 'warp_critic.evaluation.metatest:meta_test'\n"
        "LAZY = {'warp_critic.reproduce.report': ('x',)}\n"
        "import warp_critic\n"
        "from warp_critic.physics.scene import Scene  # own layer: fine\n"
        "from warp_critic.kernels.kinematics import k  # a resource of physics: fine\n"
    )
    found = upward_imports(pkg)
    assert found == {
        ("warp_critic.physics.bad", "warp_critic.running.loop"): ["warp_critic/physics/bad.py:1"],
        ("warp_critic.physics.bad", "warp_critic.methods.ours"): ["warp_critic/physics/bad.py:4"],
        ("warp_critic.physics.bad", "warp_critic.learning"): ["warp_critic/physics/bad.py:6"],
        ("warp_critic.physics.bad", "warp_critic.cli"): ["warp_critic/physics/bad.py:7"],
        ("warp_critic.physics.bad", "warp_critic.evaluation.metatest"): [
            "warp_critic/physics/bad.py:8"
        ],
        ("warp_critic.physics.bad", "warp_critic.reproduce.report"): [
            "warp_critic/physics/bad.py:9"
        ],
        ("warp_critic.physics.bad", "warp_critic"): ["warp_critic/physics/bad.py:10"],
    }
    (pkg / "extra").mkdir()
    (pkg / "extra" / "x.py").write_text("")
    with pytest.raises(AssertionError, match="extra/ is no layer"):
        upward_imports(pkg)


@pytest.mark.slow
def test_no_module_imports_a_later_layer():
    found = upward_imports()
    new = {k: v for k, v in found.items() if k not in KNOWN_UPWARD}
    assert not new, "imports up a layer (docs/design.md, Layers): " + "; ".join(
        f"{a} -> {b} at {', '.join(where)}" for (a, b), where in sorted(new.items())
    )
    gone = KNOWN_UPWARD - set(found)
    assert not gone, f"no longer imported up a layer: remove from KNOWN_UPWARD: {sorted(gone)}"


#: ``reproduce/``'s own layers in import order; its root modules (``pipeline``) join all three
REPRODUCE_LAYERS = ("engine", "experiments", "report")
#: the layers the reproduce engine may import besides itself: no method, evaluation or analysis
ENGINE_MAY_IMPORT = ("core", "physics", "running")


def reproduce_layer(module: str) -> int:
    """The index of a module of ``reproduce/`` in :data:`REPRODUCE_LAYERS` (the root: after them)."""
    parts = module.split(".")
    assert parts[:2] == ["warp_critic", "reproduce"], module
    if len(parts) > 2 and parts[2] in REPRODUCE_LAYERS:
        return REPRODUCE_LAYERS.index(parts[2])
    return len(REPRODUCE_LAYERS)


def reproduce_breaches(package: Path = PACKAGE) -> dict[tuple[str, str], list[str]]:
    """``(module, imported module) -> ['path:line', ...]`` for every import of a module of
    ``reproduce/`` up one of its own layers, and every import of the engine outside itself and
    :data:`ENGINE_MAY_IMPORT`."""
    found: dict[tuple[str, str], list[str]] = {}
    for path in sorted((package / "reproduce").rglob("*.py")):
        module = module_name(path, package)
        own = reproduce_layer(module)
        source = path.read_text(encoding="utf-8")
        for target, line in references(source, module, path.name == "__init__.py"):
            parts = target.split(".")
            if parts[:2] == ["warp_critic", "reproduce"]:
                bad = reproduce_layer(target) > own
            else:
                bad = own == 0 and (len(parts) < 2 or parts[1] not in ENGINE_MAY_IMPORT)
            if bad:
                where = f"{path.relative_to(package.parent)}:{line}"
                found.setdefault((module, target), []).append(where)
    return found


def test_reproduce_engine_below_experiments_below_report():
    found = reproduce_breaches()
    assert not found, "reproduce/: engine < experiments < report, the engine knows no method: " + (
        "; ".join(f"{a} -> {b} at {', '.join(w)}" for (a, b), w in sorted(found.items()))
    )


def test_the_reproduce_scanner_sees_a_breach(tmp_path):
    pkg = tmp_path / "warp_critic"
    for sub in ("engine", "experiments", "report"):
        (pkg / "reproduce" / sub).mkdir(parents=True)
    (pkg / "reproduce" / "pipeline.py").write_text("from warp_critic.reproduce.report import w\n")
    (pkg / "reproduce" / "report" / "w.py").write_text("from ..experiments import plan\n")
    (pkg / "reproduce" / "engine" / "carry.py").write_text(
        "from warp_critic.running.locks import LOCK\n"
        "def keys():\n    from warp_critic.methods.meta_critic import AUX_KEYS\n"
    )
    (pkg / "reproduce" / "experiments" / "plan.py").write_text(
        "from warp_critic.reproduce.engine import carry\n"
        "LAZY = {'warp_critic.reproduce.report.w': ('x',)}\n"
    )
    assert reproduce_breaches(pkg) == {
        ("warp_critic.reproduce.engine.carry", "warp_critic.methods.meta_critic"): [
            "warp_critic/reproduce/engine/carry.py:3"
        ],
        ("warp_critic.reproduce.experiments.plan", "warp_critic.reproduce.report.w"): [
            "warp_critic/reproduce/experiments/plan.py:2"
        ],
    }


def import_graph(package: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> the modules of the package it imports, every form (``from pkg import mod`` names
    ``pkg.mod`` where that is a module); a package ``__init__`` imports nothing (lazy exports)."""
    modules = {module_name(p, package): p for p in sorted(package.rglob("*.py"))}
    graph: dict[str, set[str]] = {}
    for module, path in modules.items():
        if path.name == "__init__.py":
            graph[module] = set()
            continue
        targets = set()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for target, _ in references(path.read_text(encoding="utf-8"), module):
            targets.add(target)
        for node in ast.walk(tree):  # ``from warp_critic.physics import derive``: the module
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                targets |= {f"{node.module}.{a.name}" for a in node.names}
        graph[module] = {t for t in targets if t in modules and t != module}
    return graph


def circles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The import circles of ``graph``: its strongly connected parts of two or more modules."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    found: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in sorted(graph[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                found.append(sorted(part))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


@pytest.mark.slow
def test_no_import_circle():
    assert circles(import_graph()) == [], (
        "modules that import each other (move the shared piece down)"
    )


def test_an_import_circle_hidden_in_a_function_is_found(tmp_path):
    pkg = tmp_path / "warp_critic"
    (pkg / "physics").mkdir(parents=True)
    (pkg / "physics" / "__init__.py").write_text("LAZY = {'warp_critic.physics.a': ('f',)}\n")
    (pkg / "physics" / "a.py").write_text("from warp_critic.physics import b\n")
    (pkg / "physics" / "b.py").write_text("def f():\n    from warp_critic.physics.c import g\n")
    (pkg / "physics" / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    import warp_critic.physics.a\n"
    )
    (pkg / "physics" / "d.py").write_text("from warp_critic.physics.a import f\n")
    assert circles(import_graph(pkg)) == [
        ["warp_critic.physics.a", "warp_critic.physics.b", "warp_critic.physics.c"]
    ]
    (pkg / "physics" / "c.py").write_text("x = 1\n")
    assert circles(import_graph(pkg)) == []


def test_every_module_has_at_most_400_lines():
    lengths = {
        str(p.relative_to(PACKAGE)): len(p.read_text(encoding="utf-8").splitlines())
        for p in sorted(PACKAGE.rglob("*.py"))
    }
    lengths.update(
        {
            f"kernels/{p.name}": len(p.read_text().splitlines())
            for p in (ROOT / "kernels").glob("*.py")
        }
    )
    long = {p: n for p, n in lengths.items() if n > MAX_LINES and p not in KNOWN_LONG}
    assert not long, f"modules over {MAX_LINES} lines (split along a seam): {long}"
    short = [p for p in KNOWN_LONG if lengths.get(p, 0) <= MAX_LINES]
    assert not short, f"now at most {MAX_LINES} lines (or gone): remove from KNOWN_LONG: {short}"


def function_lengths(package: Path = PACKAGE) -> dict[str, int]:
    """``"<module file stem>.<function>" -> lines`` of every function (nested ones too; the
    longest where a name repeats), decorators and docstring included."""
    out: dict[str, int] = {}
    for path in sorted(package.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                key = f"{path.stem}.{node.name}"
                lines = (node.end_lineno or node.lineno) - node.lineno + 1
                out[key] = max(out.get(key, 0), lines)
    return out


def test_every_function_has_at_most_100_lines(tmp_path):
    """No function in the package is over 100 lines (decorators and docstring counted): a long one
    is split into named steps that read top to bottom."""
    lengths = function_lengths()
    long = {f: n for f, n in lengths.items() if n > MAX_FUNCTION_LINES}
    assert not long, f"functions over {MAX_FUNCTION_LINES} lines (split them): {long}"
    # the counter itself: a nested function and a long one are found
    (tmp_path / "m.py").write_text(
        "def outer():\n    def inner():\n" + "        x = 1\n" * 101 + "    return inner\n"
    )
    assert function_lengths(tmp_path) == {"m.outer": 104, "m.inner": 102}


def test_the_design_table_is_complete_and_current():
    from warp_critic.core.generated import replace_block

    text = (ROOT / "docs" / "design.md").read_text(encoding="utf-8")
    assert replace_block(text, TOOL.BEGIN, TOOL.END, TOOL.table(), "design.md") == text, (
        "docs/design.md's module table is not current: python tools/design_table.py --write"
    )
    rows = text.split(TOOL.BEGIN)[1].split(TOOL.END)[0]
    for path in PACKAGE.rglob("*.py"):
        rel = path.relative_to(PACKAGE)
        if path.name != "__init__.py":
            assert f"| `{rel.with_suffix('')}` |" in rows, f"{rel} has no row in the design table"
    for name in LAYERS:  # the prose names the layers in the order the tool and this test use
        assert f"`{name}/`" in text
    order = [text.index(f"`{name}/`,") for name in LAYERS[:-1]]
    assert order == sorted(order), "docs/design.md lists the layers out of order"


def test_the_design_table_reads_each_module_s_first_sentence(tmp_path):
    pkg = tmp_path / "warp_critic"
    (pkg / "core").mkdir(parents=True)
    (pkg / "core" / "__init__.py").write_text('"""Core: the base."""\n')
    (pkg / "core" / "a.py").write_text(
        '"""Alpha, e.g. the first\nmodule (:mod:`~warp_critic.core.b`). More | text.\n\nBody."""\n'
    )
    (pkg / "core" / "b.py").write_text("x = 1\n")
    assert TOOL.table(pkg).splitlines()[2:] == [
        "| **`core/`** | Core: the base. |",
        "| `core/a` | Alpha, e.g. the first module (`b`). |",
        "| `core/b` | (no docstring) |",
    ]


def test_no_test_module_imports_another():
    """Shared test code lives in ``tests/helpers.py``, ``misuse_table.py`` and ``conftest.py``: a
    test module importing another one runs that module's tests' set-up twice and hides what is
    shared."""
    found = []
    for path in sorted((ROOT / "tests").glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = (
                [a.name for a in node.names]
                if isinstance(node, ast.Import)
                else [node.module or ""]
                if isinstance(node, ast.ImportFrom)
                else []
            )
            found += [f"{path.name}: {n}" for n in names if n.split(".")[0].startswith("test_")]
    assert not found, found


@pytest.mark.subprocess
def test_the_command_line_parser_loads_no_simulator():
    """``warp-critic --help`` and every command's flags need the method configs, never the
    simulator: building the parser imports neither Newton nor Warp nor rerun (they take seconds;
    a module that names the simulator only as a type imports it under ``TYPE_CHECKING``)."""
    import subprocess
    import sys

    code = (
        "import sys\n"
        "from warp_critic.cli.main import build_parser\n"
        "build_parser()\n"
        "print(sorted(m for m in ('newton', 'warp', 'rerun', 'pxr') if m in sys.modules))\n"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.strip().splitlines()[-1] == "[]", done.stdout
