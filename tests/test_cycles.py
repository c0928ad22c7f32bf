"""No import cycle between the package's modules, nor between its packages: a module (a package) that needs another
never needs it back, directly or round a loop. Every import counts, at module level or inside a function (a lazy
import is still a dependency); only an import for type checking (under `if TYPE_CHECKING:`) does not. A string
registry (`importlib.import_module` of a name held in a table: the experiments by name, the learner kinds, the tasks,
the scenes) counts too: each module that imports by name has its names declared below, read from the registry
itself, and a module that imports by name without being declared here fails the check. So does a module run by name
in a process of its own (`python -m kinswarm.x`, a command line's "-m" and the module's name): the zygote, the hub, a
run launched by an experiment.

The packages are `protocol`, `sim` and `experiments` (each with its subpackages) and each package of `actors`
(`actors/files`, `actors/supervisor`...): a module belongs to the first of those it is in."""

from __future__ import annotations

import ast
import importlib
import pkgutil
from collections.abc import Callable
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("protocol", "actors", "sim", "experiments")


def _module(path: Path) -> str:
    parts = path.relative_to(ROOT).with_suffix("").parts
    if parts[:2] == ("actors", "env"):  # installed as kinswarm.env (pyproject's package-dir)
        parts = parts[1:]
    return ".".join(("kinswarm", *(parts[:-1] if parts[-1] == "__init__" else parts)))


def _typing_only(tree: ast.AST) -> set[int]:
    """ids of the import nodes under `if TYPE_CHECKING:`."""
    out: set[int] = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
            out |= {id(n) for stmt in node.body for n in ast.walk(stmt)}
    return out


def _package_modules(package: str) -> list[str]:
    """Every module of one of our packages, found as the package finds them (pkgutil over its path)."""
    path = importlib.import_module(package).__path__
    return [f"{package}.{m.name}" for m in pkgutil.iter_modules(path)]


def _experiments() -> list[str]:
    from kinswarm.experiments import BY_NAME, EXPERIMENTS

    return [f"kinswarm.experiments.{n}" for n in (*EXPERIMENTS, *BY_NAME)]


def _learner_kinds() -> list[str]:
    from kinswarm.actors.policies.registry import KINDS

    return [k.module for k in KINDS.values()]


def _compiled() -> list[str]:
    from kinswarm.actors.learning import _COMPILED

    return [f"kinswarm.actors.learning.{m}" for m in _COMPILED.values()]


#: the modules that import by name, and the names they may import (each read from its registry)
REGISTRIES: dict[str, Callable[[], list[str]]] = {
    "kinswarm.experiments": _experiments,
    "kinswarm.experiments.research.__main__": lambda: _package_modules("kinswarm.experiments.research"),
    "kinswarm.actors.learning": _compiled,
    "kinswarm.actors.policies.registry": _learner_kinds,
    "kinswarm.actors.tasks": lambda: _package_modules("kinswarm.actors.tasks"),
    "kinswarm.sim.scenes": lambda: _package_modules("kinswarm.sim.scenes"),
}


def _imports_by_name(tree: ast.AST) -> bool:
    """Whether a module calls `import_module` (or `__import__`): an import the statements do not show."""
    return any(
        isinstance(n, ast.Call) and ast.unparse(n.func).rsplit(".", 1)[-1] in ("import_module", "__import__")
        for n in ast.walk(tree)
    )


def _run_by_name(tree: ast.AST) -> list[str]:
    """The modules a module runs by name in a process of its own: "-m" followed by a name, in a command line's list
    or tuple (`[sys.executable, "-m", "kinswarm.actors.process.main", ...]`) or a call's arguments."""
    out = []
    for node in ast.walk(tree):
        items = node.elts if isinstance(node, ast.List | ast.Tuple) else node.args if isinstance(node, ast.Call) else []
        for a, b in zip(items, items[1:], strict=False):
            if isinstance(a, ast.Constant) and a.value == "-m" and isinstance(b, ast.Constant):
                out.append(str(b.value))
    return out


def graph() -> dict[str, set[str]]:
    """Every module of the package and the modules of ours it imports, by statement, by a registry's name or by
    running it (`-m`: the package's `__main__` when it has one)."""
    files = {_module(p): p for pkg in PACKAGES for p in sorted((ROOT / pkg).rglob("*.py"))}
    edges: dict[str, set[str]] = {m: set() for m in files}
    for mod, path in files.items():
        tree = ast.parse(path.read_text(), str(path))
        skip = _typing_only(tree)
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            if isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - node.level + 1]
                    base = ".".join([*up, *([node.module] if node.module else [])])
                # `from pkg import name`: the submodule pkg.name if there is one, else pkg itself
                names = [f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names]
            else:
                continue
            edges[mod] |= {n for n in names if n in files and n != mod}
        if _imports_by_name(tree):
            assert mod in REGISTRIES, f"{mod} imports by name: declare its registry in tests/test_cycles.py"
            named = REGISTRIES[mod]()
            assert named and all(n in files for n in named), (mod, [n for n in named if n not in files])
            edges[mod] |= {n for n in named if n != mod}
        for name in _run_by_name(tree):
            run = f"{name}.__main__" if f"{name}.__main__" in files else name
            if name.startswith("kinswarm."):
                assert run in files, f"{mod} runs {name} by name: no such module"
                edges[mod] |= {run} - {mod}
    return edges


def package(module: str) -> str:
    """The package a module belongs to: `kinswarm.actors.<x>` for the actors' modules, else the top package
    (`kinswarm.sim`, `kinswarm.experiments`...)."""
    parts = module.split(".")
    return ".".join(parts[:3] if parts[1] == "actors" and len(parts) > 2 else parts[:2])


def packages(edges: dict[str, set[str]]) -> dict[str, set[str]]:
    """The module graph one level up: package -> the packages its modules import (its own left out)."""
    out: dict[str, set[str]] = {}
    for mod, deps in edges.items():
        out.setdefault(package(mod), set()).update(package(d) for d in deps)
    return {p: deps - {p} for p, deps in out.items()}


def why(edges: dict[str, set[str]], cycle: list[str]) -> list[str]:
    """The module imports that make a package cycle: `a.x -> b.y` for each arrow between two of its packages."""
    return sorted(
        f"{m} -> {d}"
        for m, deps in edges.items()
        for d in deps
        if package(m) in cycle and package(d) in cycle and package(m) != package(d)
    )


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components of more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(edges[v]):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in sorted(edges):
        if v not in index:
            visit(v)
    return out


def test_no_import_cycle_between_modules() -> None:
    assert cycles(graph()) == []


def test_no_import_cycle_between_packages() -> None:
    edges = graph()
    assert [(c, why(edges, c)) for c in cycles(packages(edges))] == []


def test_the_check_sees_a_cycle() -> None:
    """A check that finds nothing could not fail: a loop of three and a lazy import are seen."""
    assert cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]
    edges = graph()
    assert "kinswarm.actors.step.passes" in edges["kinswarm.actors.agent.actor"]
    assert "kinswarm.sim.robot" in edges["kinswarm.actors.run.inprocess"]
    # and a registry's names: the CLI reaches each experiment through `kinswarm.experiments`' table of names
    assert "kinswarm.experiments.peers" in edges["kinswarm.experiments"]
    assert "kinswarm.actors.policies.onnx" in edges["kinswarm.actors.policies.registry"]
    assert "kinswarm.actors.learning.tabular" in edges["kinswarm.actors.policies.registry"]
    assert "kinswarm.sim.scenes.walls" in edges["kinswarm.sim.scenes"]


def test_the_check_sees_an_import_by_name() -> None:
    assert _imports_by_name(ast.parse("import importlib\nm = importlib.import_module(f'pkg.{name}')"))
    assert _imports_by_name(ast.parse("from importlib import import_module\ndef f(n):\n    return import_module(n)"))
    assert not _imports_by_name(ast.parse("import importlib\nimport pkg.mod"))


def test_the_check_sees_a_module_run_by_name() -> None:
    tree = ast.parse('import subprocess, sys\nsubprocess.Popen([sys.executable, "-m", "kinswarm.actors.cli", "run"])')
    assert _run_by_name(tree) == ["kinswarm.actors.cli"]
    edges = graph()
    assert "kinswarm.actors.process.main" in edges["kinswarm.actors.supervisor.placements"]  # the zygote, by name


def test_the_check_sees_a_package_cycle() -> None:
    """Modules in no cycle of their own still make one between their packages: the check one level up sees it."""
    edges = {
        "kinswarm.actors.a.x": {"kinswarm.actors.b.y"},
        "kinswarm.actors.b.y": set(),
        "kinswarm.actors.b.z": {"kinswarm.actors.a.w"},
        "kinswarm.actors.a.w": set(),
        "kinswarm.sim.robot": {"kinswarm.sim.scenes.walls"},
        "kinswarm.sim.scenes.walls": {"kinswarm.sim.robot"},
    }
    assert cycles({m: set(d) for m, d in edges.items() if not m.startswith("kinswarm.sim")}) == []
    assert cycles(packages(edges)) == [["kinswarm.actors.a", "kinswarm.actors.b"]]
    assert why(edges, ["kinswarm.actors.a", "kinswarm.actors.b"]) == [
        "kinswarm.actors.a.x -> kinswarm.actors.b.y",
        "kinswarm.actors.b.z -> kinswarm.actors.a.w",
    ]
