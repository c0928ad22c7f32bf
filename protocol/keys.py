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
"""

from __future__ import annotations

import re
from dataclasses import dataclass

from .topology import Topology

PREFIX = "ks"
_CHUNK = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


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

    def down(self, agent: str) -> str:
        return f"{self.root}/a/{agent}/down"

    def up(self, agent: str) -> str:
        return f"{self.root}/a/{agent}/up"

    def cmd(self, agent: str) -> str:
        return f"{self.root}/sim/cmd/{agent}"

    @property
    def cmd_all(self) -> str:
        return f"{self.root}/sim/cmd/*"

    def obs(self, agent: str) -> str:
        return f"{self.root}/sim/obs/{agent}"

    @property
    def task(self) -> str:
        return f"{self.root}/sim/task"

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
    step = [f"a/{c}/down" for c in spec.children]
    if spec.parent is not None:
        step.append(f"a/{spec.parent}/up")
    if spec.has_dof:
        step.append(f"sim/cmd/{agent}")
    stand_in = tuple(f"a/{d}/down" for d in topo.subtree(agent)[1:] if d not in spec.children)
    return tuple(step), stand_in


def step_keys(topo: Topology) -> tuple[str, ...]:
    """Every key of the step's messages, below the run's root (the robot's as patterns)."""
    return (*(f"a/{b}/{way}" for b in topo.order for way in ("down", "up")), *(f"sim/cmd/{b}" for b in topo.order),
            "sim/obs/**", "sim/task")  # fmt: skip
