"""The per-step loop exists once, checked on the source: among the product's modules (actors/, sim/, protocol/) only
the step library (actors/step/) runs a robot's passes (`robot_passes`), seeds a run's learner (`agent_seed`), takes
the scenario's faults due (`.due(`), hands a learner its children's actions (`.observe(`), drops a transition
(`.resync(`) or asks a learner for its action (`.decide(`) — the learners' own code (actors/learning/,
actors/policies/) calling its own methods aside. The inprocess placement, the env faces, the agent actor and the
simulator actor call the driver (actors/step/swarm.py) for these, so a second copy of the loop cannot creep back in
unseen."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PRODUCT = ("actors", "sim", "protocol")
STEP = ROOT / "actors" / "step"
LEARNERS = (ROOT / "actors" / "learning", ROOT / "actors" / "policies")  # a learner's methods calling each other

#: functions of the step library that only it calls
FUNCTIONS = frozenset({"robot_passes", "agent_seed"})
#: methods of the robot (`due`) and of a learner (the rest) that only the step library calls
METHODS = frozenset({"due", "observe", "resync", "decide"})
LEARNER_METHODS = frozenset({"observe", "resync", "decide"})


def calls(source: str) -> list[tuple[int, str]]:
    """(line, name) of every call in `source` of one of FUNCTIONS by its name, or of METHODS on any object."""
    out = []
    for node in ast.walk(ast.parse(source)):
        if not isinstance(node, ast.Call):
            continue
        f = node.func
        if isinstance(f, ast.Name) and f.id in FUNCTIONS:
            out.append((node.lineno, f"{f.id}("))
        elif isinstance(f, ast.Attribute) and f.attr in METHODS:
            out.append((node.lineno, f".{f.attr}("))
    return sorted(out)


def _allowed(path: Path, name: str) -> bool:
    if path.is_relative_to(STEP):
        return True
    return name.strip(".(") in LEARNER_METHODS and any(path.is_relative_to(d) for d in LEARNERS)


def outside_the_step() -> list[str]:
    return [
        f"{path.relative_to(ROOT)}:{line}: {name}"
        for folder in PRODUCT
        for path in sorted((ROOT / folder).rglob("*.py"))
        for line, name in calls(path.read_text())
        if not _allowed(path, name)
    ]


def test_the_per_step_loop_exists_once() -> None:
    assert outside_the_step() == []


def test_the_check_sees_the_loop_where_it_is() -> None:
    """A check that finds nothing could not fail: the driver's own calls are found, and a copy of the inprocess loop's
    old step (passes, seeds, faults, the learner's calls written out again) would be reported line by line."""
    found = {name for _, name in calls((STEP / "swarm.py").read_text())}
    assert found == {"robot_passes(", "agent_seed(", ".due(", ".observe(", ".resync(", ".decide("}
    copy = (
        "learner = kind.build(settings, 1, agent_seed(cfg.seed, a))\n"
        "joint, _ = robot.due(epoch)\n"
        "begun, views = robot_passes(agents, order, head, q, sense, epoch, t, last)\n"
        "if ok:\n"
        "    learner.observe(acts, learn=learn)\n"
        "else:\n"
        "    learner.resync(t)\n"
        "action = learner.decide(d.state, d.reward, avoid=d.avoid)\n"
    )
    assert calls(copy) == [
        (1, "agent_seed("),
        (2, ".due("),
        (3, "robot_passes("),
        (5, ".observe("),
        (7, ".resync("),
        (8, ".decide("),
    ]
    assert not _allowed(ROOT / "actors" / "agent" / "actor.py", ".resync(")
    assert not _allowed(ROOT / "actors" / "learning" / "learner.py", ".due(")
