"""Imports run one way: each folder of the package imports only from the layers under it, no
module imports itself back through others (lazy imports inside functions included), and
building the command line parser loads no heavy library.

The import graph is read from the source with Python's ``ast``, not by importing it, so an
import hidden in a function counts as much as one at the top.
"""

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import tcr_accuracy

PACKAGE = Path(tcr_accuracy.__file__).resolve().parent
SRC = str(PACKAGE.parent)

#: Layers, bottom first (docs/architecture.md); a module may import from its own
#: layer and those before it.
LAYERS = ["base", "model", "io", "effects", "frames", "analysis", "diagnosis", "prediction", "asbuilt", "iso9283", "results",
          "view",
          "cli"]
BASE = {"tcr_accuracy", "tcr_accuracy.units", "tcr_accuracy.exceptions", "tcr_accuracy.input_files",
        "tcr_accuracy.hyperparameters", "tcr_accuracy.random_state"}


def _layer(module: str) -> str:
    if module in BASE or module == "tcr_accuracy.__main__":
        return "cli" if module.endswith("__main__") else "base"
    return module.split(".")[1]


def _import_graph() -> dict[str, set[str]]:
    modules = {}
    for path in PACKAGE.rglob("*.py"):
        parts = path.relative_to(PACKAGE.parent).with_suffix("").parts
        name = ".".join(parts[:-1] if parts[-1] == "__init__" else parts)
        modules[name] = path
    graph = {name: set() for name in modules}
    for name, path in modules.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                base = package.split(".")[: len(package.split(".")) - node.level + 1] if node.level else []
                target = ".".join(base + ([node.module] if node.module else [])) if node.level else node.module
                # "from . import x" names the submodule x; the package's own __init__ is
                # imported first by any import of a submodule and is not counted as an edge
                candidates = ([] if node.module is None and node.level else [target]) + \
                    [f"{target}.{alias.name}" for alias in node.names]
            elif isinstance(node, ast.Import):
                candidates = [alias.name for alias in node.names]
            else:
                continue
            for candidate in candidates:
                while candidate and candidate not in modules:
                    candidate = candidate.rpartition(".")[0]
                if candidate and candidate != name:
                    graph[name].add(candidate)
    return graph


GRAPH = _import_graph()


def test_every_module_belongs_to_a_layer():
    assert {_layer(m) for m in GRAPH} <= set(LAYERS)
    assert len(GRAPH) > 60  # the walk found the package


def test_imports_point_down_the_layers():
    upward = [f"{m} -> {t}" for m, targets in GRAPH.items() for t in targets
              if t != "tcr_accuracy" and LAYERS.index(_layer(t)) > LAYERS.index(_layer(m))]
    assert not upward, upward


def test_no_import_cycle():
    """Tarjan's strongly connected components of the import graph: each must be one module."""
    index, low, stack, on_stack, cycles = {}, {}, [], set(), []

    def visit(v):
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in GRAPH[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                cycles.append(sorted(component))

    for module in GRAPH:
        if module not in index:
            visit(module)
    # the package root re-exports the API lazily (PEP 562): it imports nothing at import time
    assert not cycles, cycles


@pytest.mark.parametrize("module, above", [
    ("analysis.scenario", ["analysis.simulate"]),  # simulate reads scenarios, never the other way round
    ("analysis.sensitivity", ["analysis.sobol", "analysis.tolerance", "analysis.random_inputs"]),
    ("analysis.random_inputs", ["analysis.sobol", "analysis.tolerance"]),
    ("view.robot_visuals", ["view.viewer"]),  # the scene draws robots, the robots know no scene
    ("view.meshcat_page", ["view.viewer", "view.robot_visuals"]),
    ("effects.base", ["effects.compliance", "diagnosis.diagnose"]),
])
def test_within_a_layer_the_arrows_run_one_way(module, above):
    reachable, todo = set(), [f"tcr_accuracy.{module}"]
    while todo:
        for target in GRAPH[todo.pop()]:
            if target not in reachable:
                reachable.add(target)
                todo.append(target)
    assert not reachable & {f"tcr_accuracy.{name}" for name in above}


def test_building_the_parser_imports_no_heavy_library():
    """``--help`` stays instant: every topic module registers its commands without numpy & co."""
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (SRC, env.get("PYTHONPATH", "")) if p)
    code = "from tcr_accuracy.cli import build_parser\nbuild_parser()"
    script = f"import json, sys\n{code}\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    loaded = set(json.loads(done.stdout.splitlines()[-1]))
    assert {"tcr_accuracy.cli.tolerance", "tcr_accuracy.cli.trajectory"} <= loaded
    assert not loaded & {"numpy", "pinocchio", "scipy", "meshcat", "SALib", "matplotlib"}


def test_the_package_root_exports_the_api_lazily():
    """``import tcr_accuracy`` loads nothing heavy; each exported name is the object its module defines."""
    import importlib

    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (SRC, env.get("PYTHONPATH", "")) if p)
    script = "import json, sys\nimport tcr_accuracy\nprint(json.dumps(sorted(sys.modules)))"
    done = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, timeout=120)
    assert done.returncode == 0, done.stderr[-2000:]
    assert not set(json.loads(done.stdout.splitlines()[-1])) & {"numpy", "pinocchio", "scipy"}
    for name, module in tcr_accuracy._EXPORTS.items():
        defined = getattr(importlib.import_module(f"tcr_accuracy.{module}"), name)
        assert getattr(tcr_accuracy, name) is defined, name
    with pytest.raises(AttributeError, match="no attribute 'diagnosis_of'"):
        tcr_accuracy.diagnosis_of  # noqa: B018


# ---------------------------------------------------------------------------------------
# What only the edges do
# ---------------------------------------------------------------------------------------
EDGES = ("view", "cli")
PLOTTING = ("matplotlib", "meshcat")


def _library_modules():
    """(name, path, tree) of every module below the edges (view/ and cli/)."""
    for name, path in sorted((m, PACKAGE.parent.joinpath(*m.split(".")).with_suffix(".py")) for m in GRAPH):
        if name == "tcr_accuracy" or _layer(name) in EDGES or name.endswith("__main__"):
            continue
        if not path.exists():
            path = path.with_suffix("") / "__init__.py"
        yield name, path, ast.parse(path.read_text())


def test_nothing_below_the_edges_prints_plots_or_parses_arguments():
    """The library computes: no print(), no sys.stdout/stderr writes, no matplotlib or meshcat, no
    argparse, no sys.argv below view/ and cli/ (read from the source, as the import graph)."""
    found = []
    for name, path, tree in _library_modules():
        for node in ast.walk(tree):
            where = f"{path.relative_to(PACKAGE.parent)}:{getattr(node, 'lineno', '?')}"
            if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "print":
                found.append(f"{where} print()")
            elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "sys" \
                    and node.attr in ("stdout", "stderr", "argv"):
                found.append(f"{where} sys.{node.attr}")
            elif isinstance(node, (ast.Import, ast.ImportFrom)):
                modules = [a.name for a in node.names] if isinstance(node, ast.Import) else [node.module or ""]
                for module in modules:
                    if module.split(".")[0] in PLOTTING + ("argparse",):
                        found.append(f"{where} imports {module}")
    assert not found, found


#: A command-line flag as it is typed: two dashes, a lower-case letter (``<!-- -->`` of XML is none).
FLAG = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")

#: Modules below the edges allowed to name a flag in a string, with the reason (none today: a
#: library message names the Python parameter, the command line words it as its flag).
FLAG_ALLOWED: dict[str, str] = {}


def _docstrings(tree) -> set[int]:
    """ids of the docstring constants of a module, its classes and functions."""
    found = set()
    for node in ast.walk(tree):
        if isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef)) and node.body:
            first = node.body[0]
            if isinstance(first, ast.Expr) and isinstance(first.value, ast.Constant) \
                    and isinstance(first.value.value, str):
                found.add(id(first.value))
    return found


def test_nothing_below_the_edges_names_a_command_line_flag():
    """A library error, warning or result text names the Python parameter (``folds=1``), never the
    flag (``--folds 1``): a Python user has no flags, and the command line words the parameter as
    its own (:mod:`tcr_accuracy.cli.flag_names`). Every string constant below view/ and cli/ is read
    (f-string parts included), docstrings aside: they may say which flag a parameter comes from."""
    found = []
    for name, path, tree in _library_modules():
        if name in FLAG_ALLOWED:
            continue
        docstrings = _docstrings(tree)
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str) and id(node) not in docstrings:
                flags = FLAG.findall(node.value)
                if flags:
                    found.append(f"{path.relative_to(PACKAGE.parent)}:{node.lineno} {', '.join(flags)}")
    assert not found, found
    assert set(FLAG_ALLOWED) <= set(GRAPH)  # an allowance for a module that is gone is stale


def test_the_flag_rule_sees_flags_in_messages_and_not_in_docstrings():
    """The rule above on a module written here: it must flag the message, not the docstring."""
    tree = ast.parse('"""Module: set by --folds."""\n'
                     'def f(folds):\n    """folds: --folds on the command line."""\n'
                     '    raise ValueError(f"--folds {folds}: need at least 2")\n')
    docstrings = _docstrings(tree)
    hits = [FLAG.findall(n.value) for n in ast.walk(tree)
            if isinstance(n, ast.Constant) and isinstance(n.value, str) and id(n) not in docstrings]
    assert [h for h in hits if h] == [["--folds"]]
    assert FLAG.findall("<!-- generated -->; a-b--c; x--y") == []
