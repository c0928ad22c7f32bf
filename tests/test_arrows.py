"""The arrows point one way, checked on the source: `protocol` imports nothing of ours,
`actors/learning` imports only numpy and numba (and itself), `sim` imports no agent, task or learner code, the step
library (`actors/step`) reaches no Zenoh, asyncio or actor runtime, and the product imports nothing of `experiments`
but the CLI's lazy dispatch. Every import is counted, at module level or inside a function: a lazy import is still a
dependency. What the env loads is checked once more by importing it, in a process of its own."""

from __future__ import annotations

import ast
import subprocess
import sys
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


#: what the step library must never load: the wire, the event loop, the actor shell and the actors themselves
NOT_IN_THE_STEP = ("zenoh", "asyncio", "kinswarm.actors.runtime", "kinswarm.actors.agent", "kinswarm.actors.simulator",
                   "kinswarm.actors.supervisor")  # fmt: skip


def _source(module: str) -> Path | None:
    """The file of one of our modules (pyproject's package-dir: kinswarm.env is actors/env); None for another's."""
    parts = module.split(".")[1:]
    if parts[:1] == ["env"]:
        parts = ["actors", *parts]
    base = ROOT.joinpath(*parts)
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


def _names(path: Path) -> list[str]:
    """`_imports`' modules, with `from ours import x` also as the module `ours.x` when x is one."""
    out = [name for _, name in _imports(path)]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.ImportFrom) and not node.level and _ours(node.module or ""):
            out += [f"{node.module}.{a.name}" for a in node.names if _source(f"{node.module}.{a.name}")]
    return out


def _reached(folder: str) -> dict[str, str]:
    """Every module imported by `folder`'s files or, through our modules, by what they import (a module's packages'
    `__init__` included: importing a.b runs a's): module -> the file that imports it first."""
    todo = _files(folder)
    seen_files = set(todo)
    out: dict[str, str] = {}
    while todo:
        path = todo.pop()
        for name in _names(path):
            parts = name.split(".")
            for i in range(1, len(parts) + 1):
                prefix = ".".join(parts[:i])
                out.setdefault(prefix, str(path.relative_to(ROOT)))
                src = _source(prefix) if _ours(prefix) else None
                if src is not None and src not in seen_files:
                    seen_files.add(src)
                    todo.append(src)
    return out


def _forbidden(name: str) -> bool:
    return any(name == f or name.startswith(f + ".") for f in NOT_IN_THE_STEP)


def test_the_step_library_reaches_no_zenoh_asyncio_or_actor() -> None:
    """The step library, and everything of ours it imports, all the way down."""
    reached = _reached("actors/step")
    assert "kinswarm.actors.step.geometry" in reached and "kinswarm.actors.learning.state" in reached  # it walks
    assert [f"{by}: imports {name}" for name, by in sorted(reached.items()) if _forbidden(name)] == []


def _loaded_after(code: str) -> list[str]:
    """The forbidden modules in sys.modules after `code`, run in a fresh interpreter (no other test's imports)."""
    probe = f"{code}\nimport sys\nprint(' '.join(m for m in sys.modules))"
    r = subprocess.run([sys.executable, "-c", probe], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return sorted(m for m in r.stdout.split() if _forbidden(m))


def test_the_env_loads_no_zenoh_asyncio_or_actor() -> None:
    """A reset and a step of the PettingZoo face: the robot, its task and the step library, nothing of the actors."""
    code = (
        "from kinswarm.env import parallel_env\n"
        "env = parallel_env('examples/chain4.toml')\n"
        "env.reset(seed=0)\n"
        "_, rewards, _, _, _ = env.step({a: 1 for a in env.agents})\n"
        "assert len(rewards) == 4, rewards"
    )
    assert _loaded_after(code) == []


def test_the_load_check_sees_the_actor() -> None:
    """A check that finds nothing could not fail: importing the agent actor loads all of them."""
    loaded = _loaded_after("import kinswarm.actors.agent.actor")
    assert {"zenoh", "asyncio", "kinswarm.actors.runtime", "kinswarm.actors.agent.actor"} <= set(loaded)
    reached = _reached("actors/agent")
    assert reached["kinswarm.actors.runtime"] and reached["asyncio"]


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
