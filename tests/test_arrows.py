"""The arrows point one way, checked on the source: `protocol` imports nothing of ours,
`actors/learning` imports only numpy and numba (and itself), `sim` imports no agent, task or learner code, and the
product imports nothing of `experiments` but the CLI's lazy dispatch. Every import is counted, at module level or
inside a function: a lazy import is still a dependency."""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
STDLIB = frozenset(__import__("sys").stdlib_module_names)


def _imports(path: Path) -> list[tuple[int, str]]:
    """(line, absolute module) of every import in a file; relative imports resolved against its package."""
    package = ["kinswarm", *path.relative_to(ROOT).parent.parts]
    out = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            out += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                name = ".".join([*base, *([node.module] if node.module else [])])
            else:
                name = node.module or ""
            out.append((node.lineno, name))
    return out


def _files(folder: str) -> list[Path]:
    return sorted((ROOT / folder).rglob("*.py"))


def _violations(folder: str, allowed) -> list[str]:
    return [
        f"{path.relative_to(ROOT)}:{line}: imports {name}"
        for path in _files(folder)
        for line, name in _imports(path)
        if not allowed(name, path)
    ]


def _ours(name: str) -> bool:
    return name == "kinswarm" or name.startswith("kinswarm.")


def test_protocol_imports_nothing_of_ours() -> None:
    assert _violations("protocol", lambda n, p: not _ours(n) or n.startswith("kinswarm.protocol")) == []


def test_learning_imports_only_numpy_and_numba() -> None:
    def ok(name: str, path: Path) -> bool:
        top = name.split(".")[0]
        return top in STDLIB or top in ("numpy", "numba") or name.startswith("kinswarm.actors.learning")

    assert _violations("actors/learning", ok) == []


def test_sim_imports_nothing_of_the_actors() -> None:
    """The simulation library (the robot, its world, scenes and faults) stands on the protocol alone: the actors drive
    it (actors/simulator/, the inprocess placement), never the other way round."""
    assert _violations("sim", lambda n, p: not _ours(n) or n.startswith(("kinswarm.sim", "kinswarm.protocol"))) == []


CLI = (ROOT / "actors" / "cli" / "commands.py", ROOT / "actors" / "cli" / "parser.py")


@pytest.mark.parametrize("folder", ["actors", "sim", "protocol"])
def test_the_product_never_imports_the_lab(folder: str) -> None:
    def ok(name: str, path: Path) -> bool:
        if not name.startswith("kinswarm.experiments"):
            return True
        return path in CLI  # `kinswarm experiment`: the lazy dispatch, and its names in the parser

    assert _violations(folder, ok) == []
    for path in CLI:
        cli = [n for line, n in _imports(path) if n.startswith("kinswarm.experiments")]
        top = {n.module for n in ast.parse(path.read_text()).body if isinstance(n, ast.ImportFrom)}
        assert cli and not any(t and t.startswith("kinswarm.experiments") for t in top), "the CLI imports them lazily"


def test_the_check_sees_a_violation(tmp_path: Path) -> None:
    """The parser finds imports of every form (a check that finds nothing could not fail)."""
    names = [n for _, n in _imports(ROOT / "sim" / "robot.py")]
    assert "kinswarm.protocol.scenario" in names and "kinswarm.sim.scenes" in names
    rel = [n for _, n in _imports(ROOT / "sim" / "scenes" / "object.py")]
    assert "kinswarm.sim.scenes.contact" in rel and "kinswarm.sim.scenes.base" in rel
    found = _violations("sim", lambda n, p: not n.startswith("kinswarm.protocol.scenario"))
    assert any(v.startswith("sim/robot.py:") for v in found)  # a forbidden arrow is reported, with its line
