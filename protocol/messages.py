"""Typed messages of the step protocol and of supervision (docs/architecture.md: the keys, the step).

Every message travels as a msgpack map: the envelope `v` (schema version), `kind`, `run`, `src`,
then the fields below. Frames and tips are (x, y, heading) in the world frame for a planar robot, 7-float frames
for a spatial one (`Coords`); angles in radians.
The codec (`codec.py`) validates every field against these annotations.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import ClassVar

SCHEMA_VERSION = 10  # 2: faults, events, status, bye; payloads carry a MAC (codec.py). 3: Up.action is the
# sender's action of the step before (sent before it learns), plus a closing Up after an epoch's last step.
# 4: scenes with obstacles and the grasp scene: `sense` maps, `traces` on EpochDone. 5: several hosts (deploy
# plans): Setup, Heartbeat. 6: Up.clearance. 7: every scene reading and task aggregate travels in the one `sense`
# route (Readings: Obs, Task, Down, Up; the clearance/collided/collisions fields are gone), EpochDone's scene series
# only in `traces`, and EpochStart.path, the goal of every step when it moves. 8: faults in the robot's model
# (reverse, scale, deadzone, offset, lag) and their sizes, Fault.factor and Fault.degrees; EpochDone.angles, the
# robot's pose after every step; AgentTrace, what each agent saw and chose. 9: spatial robots (from URDF): goals,
# frames and tips are `Coords`, of the robot's kind; EpochStart.start, a task's start pose. 10: fleets (`run.fleet`):
# a fleet's step messages travel as a Batch, one item per robot; EpochDone.fleet, every robot's final error;
# EpochStart.goals and .starts, each robot's; Fault.robot, a joint fault on one robot.

Vec2 = tuple[float, float]
#: A goal, frame or tip of the robot's kind (COORD_SIZES: the lengths the codec takes): a planar robot's goal (x, y)
#: and frames and tips (x, y, heading); a spatial robot's (protocol/frames.py) goal point (x, y, z) or pose
#: (x, y, z, qx, qy, qz, qw), and frames and tips (x, y, z, qx, qy, qz, qw).
Coords = tuple[float, ...]
COORD_SIZES = (2, 3, 7)
#: Named readings: the one route for what a scene senses (Obs.sense: an agent's own, Task.sense: the task's) and what
#: a task passes along the tree (Down.sense: context from above, Up.sense: a subtree's aggregate). Keys are names
#: (READING_NAME in codec.py: letters, digits and ``_ + - . /``, at most 64), values finite floats; which names a
#: scene or task uses is its own content (docs/tasks.md lists them), the route and its checks are the protocol's.
Readings = dict[str, float]


@dataclass(frozen=True)
class Obs:
    """sim -> agent: its own encoder reading q_i after the joint actions of step-1, and what the scene lets it
    sense locally (e.g. the walls' "clearance" and "collided", a fingertip's contact "fn", "ft", ...)."""

    KIND: ClassVar[str] = "obs"
    epoch: int
    step: int
    q: float
    sense: Readings = field(default_factory=dict)


@dataclass(frozen=True)
class Task:
    """sim -> root: the task observation at the start of the step (the root's task computes the reward from it):
    the goal of this step, the end-effector tips, and the scene's task readings (e.g. the walls' smallest
    "clearance" and refused moves "collisions", a grasp's net wrench and contacts)."""

    KIND: ClassVar[str] = "task"
    epoch: int
    step: int
    goal: Coords
    tips: dict[str, Coords]
    sense: Readings = field(default_factory=dict)


@dataclass(frozen=True)
class Down:
    """parent -> child (top-down pass): the child's base frame, the goal, the reward r(step-1), and the task's
    context from above (e.g. a grasp finger's "fine")."""

    KIND: ClassVar[str] = "down"
    epoch: int
    step: int
    base: Coords
    goal: Coords
    reward: float | None
    sense: Readings = field(default_factory=dict)


@dataclass(frozen=True)
class Up:
    """child -> parent (bottom-up pass): the subtree's end-effector tips at `step`, and the child's own
    action at step - 1, sent before the child learns at `step` so that learning leaves the pass.

    `action` is the index in the agent's action set (0 decrease, 1 keep, 2 increase); -1 when the child
    took none at step - 1 (a compound agent, the epoch's first step, a step it missed). After the last step
    of an epoch the child sends one more, with `step` = the epoch's length and that last step's action.
    `sense`: the task's aggregate of the child's subtree (e.g. the corridor's smallest "clearance" below)."""

    KIND: ClassVar[str] = "up"
    epoch: int
    step: int
    tips: dict[str, Coords]
    action: int
    sense: Readings = field(default_factory=dict)


@dataclass(frozen=True)
class Cmd:
    """agent -> sim: the joint increment (radians) for this step."""

    KIND: ClassVar[str] = "cmd"
    epoch: int
    step: int
    delta: float


@dataclass(frozen=True)
class EpochStart:
    """supervisor -> sim (ctl/epoch): run one epoch of `steps` lockstep steps towards `goal`; when the goal moves
    (a task's goal path), `path` holds the goal of every step (path[t]; `goal` is path[0]). `start`: the joint angles
    (rad) the epoch starts from, when the task gives them (else the robot's home)."""

    KIND: ClassVar[str] = "epoch"
    epoch: int
    steps: int
    goal: Coords
    path: list[Coords] = field(default_factory=list)
    start: dict[str, float] = field(default_factory=dict)
    # a fleet whose robots train on different goals (run.fleet_goals = "spread"): robot b's goal and start pose
    goals: list[Coords] = field(default_factory=list)
    starts: list[dict[str, float]] = field(default_factory=list)


@dataclass(frozen=True)
class EpochDone:
    """sim -> observers (metrics/epoch): errors after each step's joint actions."""

    KIND: ClassVar[str] = "epoch_done"
    epoch: int
    steps: int
    final_error: float
    mean_error: float
    errors: list[float]
    final_angles: dict[str, float]
    missed_cmds: int
    seconds: float
    max_step_seconds: float  # the longest step: a missing cmd makes it as long as the deadline, never longer
    # per-step series of the scene, e.g. the walls' "collisions" (refused moves) and "clearance" (the smallest),
    # a grasp's forces
    traces: dict[str, list[float]] = field(default_factory=dict)
    # the robot's true joint angles (rad) after each step, in the topology's DOF order: the run's motion
    angles: list[list[float]] = field(default_factory=list)
    # a fleet (run.fleet = B > 1): the final error of each of its B robots (the fields above are robot 0's)
    fleet: list[float] = field(default_factory=list)


@dataclass(frozen=True)
class Checkpoint:
    """supervisor -> agents (ctl/checkpoint): write your learned state now, into your run directory's agents/
    (`directory` is the leader's; on one host the same place)."""

    KIND: ClassVar[str] = "checkpoint"
    epoch: int
    directory: str


@dataclass(frozen=True)
class Saved:
    """agent -> supervisor (rep/agent/<id>): the checkpoint was written (or why not)."""

    KIND: ClassVar[str] = "saved"
    epoch: int
    path: str
    error: str


@dataclass(frozen=True)
class Stop:
    """supervisor -> everyone (ctl/stop): leave cleanly."""

    KIND: ClassVar[str] = "stop"
    reason: str


@dataclass(frozen=True)
class Bye:
    """actor -> supervisor (rep/<role>/<id>) on stop: what it counted, for the run's summary."""

    KIND: ClassVar[str] = "bye"
    steps: int
    rejected: int


@dataclass(frozen=True)
class Fault:
    """A fault to inject (vocabulary and checks in `faults.py`).

    anyone -> supervisor on `fault/request` (the CLI, or the sim at a scenario step); the supervisor
    answers on `rep/fault/<id>` and applies it: process faults itself, joint faults through the sim and
    link faults through the targets' runtimes, both by forwarding the same message on `ctl/fault`.
    Durations: `seconds` for freeze and link faults, `steps` for disturb; None means until cleared. The faults in
    the robot's model take their size: `factor` (scale), `degrees` (deadzone, offset), `steps` (lag: how far behind)."""

    KIND: ClassVar[str] = "fault"
    id: str
    fault: str
    targets: list[str]
    seconds: float | None
    steps: int | None
    rate: float | None
    ms: float | None
    amplitude_deg: float | None
    factor: float | None = None
    degrees: float | None = None
    robot: int | None = None  # a fleet's robot a joint fault acts on (None: every robot)


@dataclass(frozen=True)
class FaultReply:
    """supervisor -> requester (rep/fault/<id>): `error` is empty when the fault was applied."""

    KIND: ClassVar[str] = "fault_reply"
    id: str
    error: str
    detail: str


@dataclass(frozen=True)
class Event:
    """anyone -> observers (metrics/event): a fault, detection, restart, re-wiring or hand-back.
    epoch and step are -1 when the sender does not know them; the supervisor adds wall time."""

    KIND: ClassVar[str] = "event"
    epoch: int
    step: int
    event: str
    target: str
    detail: str


@dataclass(frozen=True)
class JointStatus:
    """sim -> observers (metrics/joints), a few times a second: the robot as `kinswarm status` shows it."""

    KIND: ClassVar[str] = "joints"
    epoch: int
    step: int
    q: dict[str, float]
    delta: dict[str, float]
    faults: dict[str, str]
    # per agent whose commands stopped coming: how many steps in a row ended at the deadline without its command
    late: dict[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class SwarmStatus:
    """supervisor -> observers (metrics/status), a few times a second: one column per field, keyed by actor id."""

    KIND: ClassVar[str] = "status"
    epoch: int
    epochs: int
    role: dict[str, str]
    alive: dict[str, int]
    pid: dict[str, int]
    host: dict[str, str]
    restarts: dict[str, int]
    faults: dict[str, list[str]]


@dataclass(frozen=True)
class Setup:
    """leader -> the other hosts' supervisors (a reply on ctl/setup/<plan>): the resolved run, so every host
    runs the same one. Signed with the plan's digest, not the run's key (which it carries): only a host
    with the same plan file can read it, and a different plan is refused by name."""

    KIND: ClassVar[str] = "setup"
    plan: str
    config: str  # the leader's RunConfig as JSON, robot, scene and task inline (paths are the leader's)
    scenario: str  # the scenario TOML text, "" when the run has none


@dataclass(frozen=True)
class Heartbeat:
    """supervisor -> supervisors and the sim (ctl/host/<host>), every quarter lease: a host's silence is
    noticed within one lease, whatever Zenoh's own link detection does (measured: 1-10 s across a cut).
    The sim holds its next step while any host is silent: no learning on stale or missing data."""

    KIND: ClassVar[str] = "heartbeat"
    host: str
    seq: int
    leader: int  # 1 from the leading supervisor


@dataclass(frozen=True)
class AgentTrace:
    """agent -> observers (metrics/agent), once an epoch, when the run records its agents (`run.record_agents`,
    on with `--view`): what the agent saw and chose at each step it decided — its state S_i (`names`: the
    learner's state variables), its action, E of Eq. 9 (the expected value of each own action: their spread is
    how sure it was) and P of Eq. 7 (its fictitious-play estimate of each visible child's action, child by child)."""

    KIND: ClassVar[str] = "agent_trace"
    epoch: int
    agent: str
    names: list[str]
    steps: list[int]
    states: list[list[float]]
    actions: list[int]
    expected: list[list[float]]
    beliefs: list[list[float]]


@dataclass(frozen=True)
class Batch:
    """A fleet's step message (run.fleet = B > 1: B robots in lockstep through one swarm): what one actor sends on
    one step key for several robots of the fleet, in one payload. `items[i]`, a message of kind `of` (obs, task,
    down, up, cmd), is robot `robots[i]`'s (robots ascending, each in [0, B)). On the wire each item is the map of
    its fields (codec.py checks each as a message of its kind); one MAC covers the batch."""

    KIND: ClassVar[str] = "batch"
    of: str
    robots: list[int]
    items: list[Obs | Task | Down | Up | Cmd]


#: the kinds a Batch carries: the step messages
BATCHED = {m.KIND: m for m in (Obs, Task, Down, Up, Cmd)}

_ALL = (Obs, Task, Down, Up, Cmd, EpochStart, EpochDone, Checkpoint, Saved, Stop)
_ALL += (Bye, Fault, FaultReply, Event, JointStatus, SwarmStatus, Setup, Heartbeat, AgentTrace, Batch)
MESSAGE_TYPES: dict[str, type] = {m.KIND: m for m in _ALL}
