"""Scenario files: a TOML timeline of faults, read by the simulator (`kinswarm run ... --scenario FILE`).

```toml
name = "paper-locked"
description = "agents 2 and 3 locked throughout; run with --steps 1500"

[[event]]
step = 0                 # required: the step (within an epoch) at whose start the fault is applied
epoch = 3                # optional: only in this epoch (absent: in every epoch)
fault = "lock"           # see protocol/faults.py
target = ["a2", "a3"]    # an agent id, a list of them, or "all"
# as the fault takes them: seconds, steps, rate, ms, amplitude_deg, factor, degrees
```

The sim applies joint faults (lock, free, disturb, and reverse, scale, deadzone, offset, lag in the robot's model)
itself and forwards the others to the supervisor. When the run file is resolved (actors/files/runfile.py), every entry
is checked against the run too: a step or epoch it never reaches, a process fault its placement cannot apply (`single`
cannot freeze), a fault on agents a baseline run does not have.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from kinswarm.protocol.faults import ALL, JOINT_FAULTS, check_fault
from kinswarm.protocol.messages import Fault
from kinswarm.protocol.spec import one_line, read_toml, shown
from kinswarm.protocol.topology import Topology


class ScenarioError(ValueError):
    """A scenario file that does not fit the format; the message names the file, the entry/field and the fault."""

    def __init__(self, source: str, where: str, what: str) -> None:
        super().__init__(f"{shown(source)}: {shown(where)}: {one_line(what)}")
        self.source, self.where, self.what = source, where, what

    def __reduce__(self) -> tuple[Any, ...]:  # raised in an experiment's worker process, it must come back whole
        return (type(self), (self.source, self.where, self.what))


@dataclass(frozen=True)
class ScenarioEntry:
    epoch: int | None  # None: every epoch
    step: int
    fault: Fault

    @property
    def is_joint(self) -> bool:
        return self.fault.fault in JOINT_FAULTS


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    entries: tuple[ScenarioEntry, ...]  # in file order
    source: str = "<memory>"


_TOP_KEYS = {"name", "description", "event"}
_FLOATS = ("seconds", "rate", "ms", "amplitude_deg", "factor", "degrees")
_EVENT_KEYS = {"step", "epoch", "fault", "target", "steps", "robot", *_FLOATS}


def _int(src: str, where: str, v: Any) -> int:
    if isinstance(v, bool) or not isinstance(v, int) or v < 0:
        raise ScenarioError(src, where, f"expected an integer >= 0, got {v!r}")
    return v


def _float(src: str, where: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise ScenarioError(src, where, f"expected a finite number, got {v!r}")
    return float(v)


def _entry(src: str, i: int, row: Any, topo: Topology) -> ScenarioEntry:
    at = f"event[{i}]"
    if not isinstance(row, dict):
        raise ScenarioError(src, at, "must be a table")
    bad = set(row) - _EVENT_KEYS
    if bad:
        raise ScenarioError(src, f"{at}.{sorted(bad)[0]}", f"unknown field (expected {', '.join(sorted(_EVENT_KEYS))})")
    for name in ("step", "fault", "target"):
        if name not in row:
            raise ScenarioError(src, f"{at}.{name}", "missing")
    step = _int(src, f"{at}.step", row["step"])
    epoch = _int(src, f"{at}.epoch", row["epoch"]) if "epoch" in row else None
    kind = row["fault"]
    if not isinstance(kind, str):
        raise ScenarioError(src, f"{at}.fault", f"expected a string, got {kind!r}")
    target = row["target"]
    targets = [target] if isinstance(target, str) else target
    if not isinstance(targets, list) or not targets or not all(isinstance(t, str) for t in targets):
        raise ScenarioError(src, f"{at}.target", f"expected an agent id or a list of them, got {target!r}")
    steps = _int(src, f"{at}.steps", row["steps"]) if "steps" in row else None
    robot = _int(src, f"{at}.robot", row["robot"]) if "robot" in row else None
    floats = {n: _float(src, f"{at}.{n}", row[n]) if n in row else None for n in _FLOATS}
    f = Fault(id=f"scenario-{i}", fault=kind, targets=targets, steps=steps, robot=robot, **floats)  # type: ignore[arg-type]
    problem = check_fault(f, list(topo.order))
    if problem:
        raise ScenarioError(src, at, problem)
    if kind in JOINT_FAULTS:  # a compound agent has no joint to lock
        for t in targets:
            if t != ALL and not topo.agents[t].has_dof:
                raise ScenarioError(src, f"{at}.target", f"{kind}: {t!r} is a compound agent, it has no joint")
    return ScenarioEntry(epoch=epoch, step=step, fault=f)


def parse_scenario(data: dict[str, Any], topo: Topology, source: str = "<memory>") -> Scenario:
    """Validate a parsed TOML document against the run's topology; errors name source and field."""
    src = source
    bad = set(data) - _TOP_KEYS
    if bad:
        raise ScenarioError(src, sorted(bad)[0], "unknown key (expected name, description, event)")
    name = data.get("name")
    if not isinstance(name, str) or not name:
        raise ScenarioError(src, "name", f"expected a non-empty string, got {name!r}")
    description = data.get("description", "")
    if not isinstance(description, str):
        raise ScenarioError(src, "description", f"expected a string, got {description!r}")
    rows = data.get("event")
    if not isinstance(rows, list) or not rows:
        raise ScenarioError(src, "event", "expected at least one [[event]] table")
    entries = tuple(_entry(src, i, row, topo) for i, row in enumerate(rows))
    return Scenario(name=name, description=description, entries=entries, source=src)


def load_scenario(path: str | Path, topo: Topology) -> Scenario:
    data = read_toml(path, ScenarioError)
    return parse_scenario(data, topo, source=str(path))
