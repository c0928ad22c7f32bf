"""Key expressions: every key of a run lives under `ks/<run-id>/`, so two runs never hear each other.

```
a/<agent>/down   a/<agent>/up      parent -> child, child -> parent (addressed by the receiver)
sim/cmd/<agent>  sim/obs/<agent>   agent -> robot, robot -> agent
sim/task                           robot -> root: the task observation (goal, end-effector tips)
ctl/<verb>                         supervisor -> everyone (epoch, checkpoint, stop, fault)
ctl/host/<host>  ctl/setup/<plan>  a supervisor's heartbeat; the leader's resolved run (several hosts)
rep/<role>/<id>                    replies to the supervisor (checkpoint written, goodbye, ...)
fault/<what>                       a tool or the sim -> supervisor (live faults: fault/request)
metrics/<topic>                    anyone -> observers (epoch results, events, status)
alive/<role>/<id>                  liveliness tokens, declared once an actor is wired and matched
```

`a/<x>/up` is what agent x *receives* from its children; `a/<x>/down` what x receives from its parent.

Every key's shape is declared once (`KEYS`: each kind's shape and who publishes on it): the keys an actor sends on
and listens to are made from it (`Keys.key`), a received key is parsed by it (`Keys.parse`, `Keys.parse_step`, never
sliced), and a deploy plan's access control (actors/deploy/plan.py) denies the agents and the sim every key the
declaration says is not theirs (`agent_denied`, `sim_denied`). A liveliness token's change, as an actor's mailbox
carries it, is made and read here too (`token_change`, `parse_token_change`).
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from functools import lru_cache
from typing import NamedTuple

from .topology import Topology

PREFIX = "ks"
_CHUNK = re.compile(r"^[A-Za-z0-9_-]{1,64}$")

# who publishes on a kind of key: an agent, the robot's simulator, a supervisor, a tool (`kinswarm fault`, `down`)
AGENT, SIM, SUPERVISOR, TOOL = "agent", "sim", "supervisor", "tool"

#: every key below a run's root, by kind: its shape (`{}` where a name goes: an agent's id, a verb, a topic...) and who
#: publishes on it
KEYS: dict[str, tuple[str, frozenset[str]]] = {
    # the step
    "down": ("a/{}/down", frozenset({AGENT})),  # parent -> child, addressed by the child
    "up": ("a/{}/up", frozenset({AGENT})),  # child -> parent, addressed by the parent
    "cmd": ("sim/cmd/{}", frozenset({AGENT})),  # agent -> the robot: the agent's joint
    "obs": ("sim/obs/{}", frozenset({SIM})),  # the robot -> agent: the agent's joint
    "task": ("sim/task", frozenset({SIM})),  # the robot -> root
    # the run
    "ctl": ("ctl/{}", frozenset({SUPERVISOR, TOOL})),  # epoch, checkpoint, stop (`kinswarm down` too), fault
    "host": ("ctl/host/{}", frozenset({SUPERVISOR})),  # a supervisor's heartbeat (several hosts)
    "setup": ("ctl/setup/{}", frozenset({SUPERVISOR})),  # the leader's queryable: a plan's resolved run
    "rep": ("rep/{}/{}", frozenset({SUPERVISOR, AGENT, SIM})),  # rep/<role>/<id>: replies (saved, bye, fault)
    "fault": ("fault/{}", frozenset({SIM, TOOL})),  # fault/request: `kinswarm fault`, a scenario's through the sim
    "metrics": ("metrics/{}", frozenset({SUPERVISOR, AGENT, SIM})),  # epoch, event, joints, status, agent
    "alive": ("alive/{}/{}", frozenset({SUPERVISOR, AGENT, SIM, TOOL})),  # liveliness tokens, alive/<role>/<id>
}
#: the step's kinds (the lockstep's messages, handled where they arrive): shape and who publishes, as in KEYS
STEP: dict[str, tuple[str, frozenset[str]]] = {kind: KEYS[kind] for kind in ("down", "up", "cmd", "obs", "task")}


class Key(NamedTuple):
    """A key of a run, parsed: its kind (a key of `KEYS`) and the names its shape holds, in order (`rep/bye/a2` ->
    ("rep", ("bye", "a2")); `sim/task` -> ("task", ()))."""

    kind: str
    names: tuple[str, ...]


class StepKey(NamedTuple):
    """A step key, parsed: its kind (a key of `STEP`) and the agent it names ("" for the task)."""

    kind: str
    agent: str


def shape(kind: str, *names: str) -> str:
    """A key below a run's root: `shape("down", "a2")` is `a/a2/down`."""
    return KEYS[kind][0].format(*names)


def step_key(kind: str, agent: str = "") -> str:
    """A step key below the run's root: `step_key("down", "a2")` is `a/a2/down`."""
    return STEP[kind][0].format(agent)


def head(kind: str) -> str:
    """A kind's shape up to its first name (`a/`, `sim/cmd/`, `ctl/host/`); a kind that names nothing is its key."""
    return KEYS[kind][0].partition("{}")[0]


def _family(kind: str) -> str:
    """Every key of a kind whatever it names, as a key expression below the root: the shape up to its first name,
    then `**` (`a/**`, `sim/cmd/**`); a kind that names nothing is its one key."""
    before, named, _ = KEYS[kind][0].partition("{}")
    return f"{before}**" if named else before


def every_run(below: str) -> str:
    """A key expression below the root of every run (`ks/*/ctl/**`): a deploy plan's rules, a host asking whose
    run it is."""
    return f"{PREFIX}/*/{below}"


def run_of(key: str) -> str | None:
    """The run a key of some run belongs to (`ks/<run>/...` -> run); None for a key outside every run."""
    prefix, sep, rest = key.partition("/")
    run = rest.partition("/")[0]
    return run if prefix == PREFIX and sep and _CHUNK.match(run) else None


# each kind's shape as chunks: a literal, or None where a name goes
_CHUNKS = tuple((kind, tuple(None if c == "{}" else c for c in s.split("/"))) for kind, (s, _) in KEYS.items())


@lru_cache(maxsize=4096)  # a run's keys are a few per actor: parsed once each, then looked up
def parse_below(below: str) -> Key | None:
    """A key below a run's root -> its kind and names, by the declaration; None for anything it does not declare
    (a name with a '/' or a wildcard, a chunk too many or too few)."""
    chunks = below.split("/")
    for kind, want in _CHUNKS:
        if len(want) != len(chunks):
            continue
        names = []
        for w, c in zip(want, chunks, strict=True):
            if w is None and _CHUNK.match(c):  # an id (check_id), no '/' or wildcard
                names.append(c)
            elif w != c:
                break
        else:
            return Key(kind, tuple(names))
    return None


@lru_cache(maxsize=1024)
def _parse_step(below: str) -> StepKey | None:
    k = parse_below(below)
    if k is None or k.kind not in STEP:
        return None
    return StepKey(k.kind, k.names[0] if k.names else "")


# a liveliness token's change, as an actor's mailbox carries it: its sign, then the token's key
UP, GONE, HELD = "+", "-", "?"  # the token came, went; a loss held as its holder woke (actors/runtime/wake.py)


def token_change(sign: str, key: str) -> str:
    """`+ks/r/alive/agent/a2`: the token of `key` came (UP), went (GONE), or a held loss looked at again (HELD)."""
    return sign + key


def parse_token_change(change: str) -> tuple[str, str]:
    """`token_change`'s (sign, key)."""
    return change[:1], change[1:]


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

    def key(self, kind: str, *names: str) -> str:
        """A key of this run, by its kind's shape (`KEYS`)."""
        return f"{self.root}/{shape(kind, *names)}"

    def prefix(self, kind: str) -> str:
        """What every key of a kind starts with, whatever it names (`ks/<run>/sim/cmd/`)."""
        return f"{self.root}/{head(kind)}"

    def family(self, kind: str) -> str:
        """Every key of a kind, as a key expression (`ks/<run>/rep/**`)."""
        return f"{self.root}/{_family(kind)}"

    @property
    def step_prefixes(self) -> tuple[str, ...]:
        """What the step's keys start with (a tuple for str.startswith: the node's fast path)."""
        return tuple(dict.fromkeys(self.prefix(kind) for kind in STEP))

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

    def parse(self, key: str) -> Key | None:
        """A key of this run -> (kind, names); None for any other key (another run's, a mailbox's own item)."""
        root = self.root
        if len(key) > len(root) and key[len(root)] == "/" and key.startswith(root):
            return parse_below(key[len(root) + 1 :])
        return None

    def parse_step(self, key: str) -> StepKey | None:
        """A step key of this run -> (kind, agent); None for any other key (another run's, a control key, ...)."""
        root = self.root
        if len(key) > len(root) and key[len(root)] == "/" and key.startswith(root):
            return _parse_step(key[len(root) + 1 :])
        return None

    def ctl(self, verb: str) -> str:
        return self.key("ctl", verb)

    def host(self, name: str) -> str:
        """A supervisor's heartbeat (several hosts); under ctl/ so only supervisors may speak there."""
        return self.key("host", name)

    def setup(self, plan: str) -> str:
        """The leader's queryable: the resolved run of a deploy plan, for the other hosts."""
        return self.key("setup", plan)

    @property
    def ctl_all(self) -> str:
        return self.key("ctl", "*")

    def rep(self, role: str, ident: str) -> str:
        return self.key("rep", role, ident)

    @property
    def rep_all(self) -> str:
        return self.family("rep")

    def metrics(self, topic: str) -> str:
        return self.key("metrics", topic)

    def fault(self, what: str) -> str:
        return self.key("fault", what)

    def alive(self, role: str, ident: str) -> str:
        return self.key("alive", role, ident)

    @property
    def alive_all(self) -> str:
        return self.family("alive")

    def parse_alive(self, key: str) -> tuple[str, str] | None:
        """`ks/<run>/alive/<role>/<id>` -> (role, id); None for anything else."""
        k = self.parse(key)
        return (k.names[0], k.names[1]) if k is not None and k.kind == "alive" else None


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
    ours = [step_key(kind, b) for b in topo.order for kind, (_, by) in STEP.items() if AGENT in by]
    return (*ours, *(_family(kind) for kind, (_, by) in STEP.items() if AGENT not in by))


def _not_published_by(who: str, kinds: dict[str, tuple[str, frozenset[str]]]) -> list[str]:
    """The families of the kinds `who` does not publish, none inside another (`ctl/**` holds `ctl/host/**`)."""
    families = [_family(kind) for kind, (_, by) in kinds.items() if who not in by]
    inside = {f for f in families for g in families if g != f and g.endswith("**") and f.startswith(g[:-2])}
    return list(dict.fromkeys(f for f in families if f not in inside))


def agent_denied(topo: Topology, agent: str) -> tuple[str, ...]:
    """The keys `agent` may not publish, below any run's root: every kind the agents do not publish, and of the
    step's kinds they do, every key but its own (`agent_keys`, its stand-in's included)."""
    step, stand_in = agent_keys(topo, agent)
    own = {*step, *stand_in}
    ours = [step_key(kind, b) for b in topo.order for kind, (_, by) in STEP.items() if AGENT in by]
    return (*_not_published_by(AGENT, KEYS), *(k for k in ours if k not in own))


def sim_denied() -> tuple[str, ...]:
    """The keys the sim may not publish, below any run's root: every kind it does not publish."""
    return tuple(_not_published_by(SIM, KEYS))
