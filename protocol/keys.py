"""Key expressions: every key of a run lives under `ks/<run-id>/`, so two runs never hear each other.

```
a/<agent>/down   a/<agent>/up      parent -> child, child -> parent (addressed by the receiver)
sim/cmd/<agent>  sim/obs/<agent>   agent -> robot, robot -> agent
sim/task                           robot -> root: the task observation (goal, end-effector tips)
ctl/<verb>                         supervisor -> everyone (epoch, checkpoint, stop)
rep/<role>/<id>                    replies to the supervisor (checkpoint written, ...)
fault/**                           anyone -> supervisor (live faults)
metrics/<topic>                    anyone -> observers (epoch results)
alive/<role>/<id>                  liveliness tokens, declared once an actor is wired and matched
```

`a/<x>/up` is what agent x *receives* from its children; `a/<x>/down` what x receives from its parent.

The step's keys are declared once (`STEP`: each kind's shape and who publishes it): the keys an actor sends on and
listens to are made from it, a received key is parsed by it (`Keys.parse_step`, never sliced), and a deploy plan's
access control (actors/deploy/plan.py) denies the agents and the sim from it (`agent_denied`, `sim_denied`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

from .topology import Topology

PREFIX = "ks"
_CHUNK = re.compile(r"^[A-Za-z0-9_-]{1,64}$")

AGENT, SIM = "agent", "sim"  # who publishes a step key: an agent, or the robot's simulator
#: the step's keys below a run's root, by kind: the shape (`{}` where the agent's id goes) and who publishes it
STEP: dict[str, tuple[str, str]] = {
    "down": ("a/{}/down", AGENT),  # parent -> child, addressed by the child
    "up": ("a/{}/up", AGENT),  # child -> parent, addressed by the parent
    "cmd": ("sim/cmd/{}", AGENT),  # agent -> the robot: the agent's joint
    "obs": ("sim/obs/{}", SIM),  # the robot -> agent: the agent's joint
    "task": ("sim/task", SIM),  # the robot -> root
}


class StepKey(NamedTuple):
    """A step key, parsed: its kind (a key of `STEP`) and the agent it names ("" for the task)."""

    kind: str
    agent: str


def step_key(kind: str, agent: str = "") -> str:
    """A step key below the run's root: `step_key("down", "a2")` is `a/a2/down`."""
    return STEP[kind][0].format(agent)


def _family(kind: str) -> str:
    """Every key of a kind whoever it names, as a key expression below the root: the shape up to the agent's id, then
    `**` (`a/**`, `sim/cmd/**`); a kind that names no agent is its one key."""
    head, named, _ = STEP[kind][0].partition("{}")
    return f"{head}**" if named else head


# (kind, the shape's text before the agent's id, after it; None for a kind that names no agent)
_SHAPES = tuple(
    (kind, *shape.split("{}")) if "{}" in shape else (kind, shape, None) for kind, (shape, _) in STEP.items()
)


@lru_cache(maxsize=1024)  # a run's step keys are a few per agent: parsed once each, then looked up
def _parse_step(below: str) -> StepKey | None:
    for kind, head, tail in _SHAPES:
        if tail is None:
            if below == head:
                return StepKey(kind, "")
        elif below.startswith(head) and below.endswith(tail):
            agent = below[len(head) : len(below) - len(tail)]
            if _CHUNK.match(agent):  # an id (check_id), no '/' or wildcard
                return StepKey(kind, agent)
    return None


def check_id(kind: str, value: str) -> str:
    """Run and actor ids become key chunks: no '/', wildcards or '$', which would change the key's meaning."""
    if not isinstance(value, str) or not _CHUNK.match(value):
        raise ValueError(f"{kind} {value!r} must be 1-64 letters, digits, '_' or '-'")
    return value


@dataclass(frozen=True)
class Keys:
    run: str

    def __post_init__(self) -> None:
        check_id("run id", self.run)

    @property
    def root(self) -> str:
        return f"{PREFIX}/{self.run}"

    @property
    def everything(self) -> str:
        return f"{self.root}/**"

    def step(self, kind: str, agent: str = "") -> str:
        """A step key of this run (`STEP`'s kinds)."""
        return f"{self.root}/{step_key(kind, agent)}"

    def down(self, agent: str) -> str:
        return self.step("down", agent)

    def up(self, agent: str) -> str:
        return self.step("up", agent)

    def cmd(self, agent: str) -> str:
        return self.step("cmd", agent)

    @property
    def cmd_all(self) -> str:
        return self.step("cmd", "*")

    def obs(self, agent: str) -> str:
        return self.step("obs", agent)

    @property
    def task(self) -> str:
        return self.step("task")

    def parse_step(self, key: str) -> StepKey | None:
        """A step key of this run -> (kind, agent); None for any other key (another run's, a control key, ...)."""
        root = self.root
        if len(key) > len(root) and key[len(root)] == "/" and key.startswith(root):
            return _parse_step(key[len(root) + 1 :])
        return None

    def ctl(self, verb: str) -> str:
        return f"{self.root}/ctl/{verb}"

    def host(self, name: str) -> str:
        """A supervisor's heartbeat (several hosts); under ctl/ so only supervisors may speak there."""
        return f"{self.root}/ctl/host/{name}"

    def setup(self, plan: str) -> str:
        """The leader's queryable: the resolved run of a deploy plan, for the other hosts."""
        return f"{self.root}/ctl/setup/{plan}"

    @property
    def ctl_all(self) -> str:
        return f"{self.root}/ctl/*"

    def rep(self, role: str, ident: str) -> str:
        return f"{self.root}/rep/{role}/{ident}"

    @property
    def rep_all(self) -> str:
        return f"{self.root}/rep/**"

    def metrics(self, topic: str) -> str:
        return f"{self.root}/metrics/{topic}"

    def fault(self, what: str) -> str:
        return f"{self.root}/fault/{what}"

    def alive(self, role: str, ident: str) -> str:
        return f"{self.root}/alive/{role}/{ident}"

    @property
    def alive_all(self) -> str:
        return f"{self.root}/alive/**"

    def parse_alive(self, key: str) -> tuple[str, str] | None:
        """`ks/<run>/alive/<role>/<id>` -> (role, id); None for anything else."""
        parts = key.split("/")
        if len(parts) == 5 and parts[:3] == [PREFIX, self.run, "alive"]:
            return parts[3], parts[4]
        return None

    def last_chunk(self, key: str) -> str:
        return key.rsplit("/", 1)[-1]


def agent_keys(topo: Topology, agent: str) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """What an agent publishes, below the run's root: (at every step: its children's `down`, its parent's `up`, its
    joint's `cmd`; and when it stands in for lost descendants: their children's `down` too). The agent declares the
    first (actors/agent/actor.py), a deploy plan's access control allows both and denies the rest of the step's keys
    (actors/deploy/plan.py)."""
    spec = topo.agents[agent]
    step = [step_key("down", c) for c in spec.children]
    if spec.parent is not None:
        step.append(step_key("up", spec.parent))
    if spec.has_dof:
        step.append(step_key("cmd", agent))
    stand_in = tuple(step_key("down", d) for d in topo.subtree(agent)[1:] if d not in spec.children)
    return tuple(step), stand_in


def step_keys(topo: Topology) -> tuple[str, ...]:
    """Every key of the step's messages, below the run's root: the agents' kinds for every agent (each agent may send
    on some of them only), the robot's kinds as families (all of them are the sim's)."""
    ours = [step_key(kind, b) for b in topo.order for kind, (_, by) in STEP.items() if by == AGENT]
    return (*ours, *(_family(kind) for kind, (_, by) in STEP.items() if by == SIM))


def agent_denied(topo: Topology, agent: str) -> tuple[str, ...]:
    """The step keys `agent` may not publish: every one but its own (`agent_keys`, its stand-in's included)."""
    step, stand_in = agent_keys(topo, agent)
    own = {*step, *stand_in}
    return tuple(k for k in step_keys(topo) if k not in own)


def sim_denied() -> tuple[str, ...]:
    """The step keys the sim may not publish: every key of the kinds the agents publish."""
    return tuple(dict.fromkeys(_family(kind) for kind, (_, by) in STEP.items() if by == AGENT))
