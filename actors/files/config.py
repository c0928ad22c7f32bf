"""The resolved run: what every actor of a run reads. `actors/files/runfile.py` (the one loader) resolves a run file
into a RunConfig; the supervisor writes it to `<out>/config.json` (owner-only: it holds the run's secret) and every
actor process reads it back here. Plain data over protocol specs: the simulator's actor imports this, and nothing of
the agents'.

The fields of the run file's `[run]` table are the flat fields below (`from` is `from_dir`); its `[robot]`,
`[scene]`, `[task]` and `[learner]` tables are kept as resolved tables, parsed by their owners: the robot and the
scene by protocol/, the task by actors/tasks/, the learner's overrides by the task's `learner()`.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import secrets
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Any

from kinswarm.actors.files.bounds import (
    at_most,
    below,
    boolean,
    checks,
    first_problem,
    integer,
    integer_in,
    number_in,
    one_of,
    positive,
    seconds,
)
from kinswarm.protocol.faults import LINK_FAULTS, PROCESS_FAULTS
from kinswarm.protocol.keys import check_id
from kinswarm.protocol.robots import parse_robot
from kinswarm.protocol.scene import SceneSpec, parse_scene
from kinswarm.protocol.topology import Topology

PLACEMENTS = ("process", "single", "inprocess")
#: The process and link faults each placement can apply (actors/supervisor/placements.py's `supports`): a task in one
#: process can be cancelled and started again, but not stopped and continued as a process is by SIGSTOP and SIGCONT;
#: the inprocess placement's plain loop has neither processes nor messages.
PLACEMENT_FAULTS: dict[str, tuple[str, ...]] = {
    "process": PROCESS_FAULTS + LINK_FAULTS,
    "single": ("kill", "restart", *LINK_FAULTS),
    "inprocess": (),
}
LEASE_RANGE_MS = (100, 60_000)  # the Zenoh leases accepted: [run] lease_ms and a plan's [zenoh] lease_ms
#: the learning agents, or a model-based law (actors/simulator/controller.py)
CONTROLLERS = ("agents", "pinv", "greedy", "rule", "turn")
#: The supervisor's endpoint when none is given: a free port on 127.0.0.1, picked as the run starts
#: (actors/deploy/plan.py local_plan) and recorded in `<out>/net/cli.json` for the tools; so any number of runs go
#: side by side, unaware of each other. config.json keeps "auto": a resumed run picks a free port again (the old one
#: may be taken by then).
AUTO_LISTEN = "auto"
DEFAULT_LISTEN = AUTO_LISTEN
#: What a run directory was written by (config.json's "kinswarm"): `--resume` continues only a run of this version
#: (its checkpoints' learned state, its rows). The run format counts changes to what a run leaves behind.
RUN_FORMAT = 1
#: The run file's [run] keys: every field of RunConfig a user sets in a file (`from` is the field from_dir).
RUN_KEYS = (
    "epochs",
    "steps",
    "seed",
    "placement",
    "learn",
    "explore",
    "successive",
    "from",
    "scenario",
    "controller",
    "action_deg",
    "deadline_ms",
    "lease_ms",
    "checkpoint_every",
    "max_restarts",
    "restart_window_s",
    "stall_s",
    "stall_limit_s",
    "record_agents",
    "record",
    "fleet",
    "fleet_goals",
)
FLEET_GOALS = ("same", "spread")
MAX_FLEET = 1024  # robots in a fleet: a step's Batch of them stays far below the codec's 1 MiB


class ConfigError(ValueError):
    pass


def placement_problem(fault: str, placement: str) -> str:
    """What stops `placement` from applying `fault` ("" when nothing does): checked when a scenario is resolved and
    again when a fault is requested live."""
    if fault not in PROCESS_FAULTS + LINK_FAULTS or fault in PLACEMENT_FAULTS.get(placement, ()):
        return ""
    able = " or ".join(p for p, faults in PLACEMENT_FAULTS.items() if fault in faults)
    return f"{fault}: needs --placement {able} (this run's placement is {placement})"


#: a Zenoh endpoint as the runs use them: protocol/host:port (an IPv6 host in brackets), e.g. tcp/127.0.0.1:7447
ENDPOINT = re.compile(r"(tcp|tls|udp|quic|ws)/(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9._-]+):(\d{1,5})")


def check_endpoint(text: str, what: str = "listen") -> str:
    m = ENDPOINT.fullmatch(text) if isinstance(text, str) else None
    if m is None or not 0 <= int(m.group(3)) <= 65535:
        raise ConfigError(f"{what}: expected an endpoint like tcp/127.0.0.1:7447 (protocol/host:port), got {text!r}")
    return text


def _run_id(name: str, v: Any, _: Any) -> str:
    check_id("run id", v)  # a ValueError of its own, as every id's (protocol/keys.py)
    return ""


def _agents_drive_a_fleet(name: str, v: Any, cfg: RunConfig) -> str:
    if v > 1 and cfg.controller != "agents":
        return f"fleet: only the learning agents drive a fleet; controller {cfg.controller!r} drives one robot"
    return ""


def _secret(name: str, v: Any, _: Any) -> str:
    return "" if isinstance(v, str) and len(v) >= 16 else "secret: expected a string of at least 16 characters"


def _listen(name: str, v: Any, _: Any) -> str:
    if v != AUTO_LISTEN:
        check_endpoint(v, "--listen")  # its one line, as the command line's --listen gets it
    return ""


def _hosts(name: str, v: Any, _: Any) -> str:
    ok = isinstance(v, list) and all(isinstance(h, str) for h in v)
    return "" if ok else f"hosts: expected a list of host names, got {v!r}"


def _task(name: str, v: Any, _: Any) -> str:
    return "" if isinstance(v, dict) and isinstance(v.get("kind"), str) else "task: expected a table with a kind"


@dataclass(frozen=True)
class RunConfig:
    """Each field's bounds are declared beside it (`checks`, actors/files/bounds.py), and checked in this order."""

    run_id: str = field(metadata=checks(_run_id))
    out: str  # absolute path of the run directory
    robot: dict[str, Any]  # the resolved [robot] table (protocol/topology.py)
    task: dict[str, Any] = field(metadata=checks(_task))  # the resolved [task] table, `kind` first (actors/tasks/)
    scene: dict[str, Any] = field(default_factory=dict)  # the resolved [scene] table (protocol/scene.py)
    learner: dict[str, Any] = field(default_factory=dict)  # LearnerSettings overrides (actors/learning/settings.py)
    source: str = "<memory>"  # the run file it was resolved from (for messages)
    epochs: int = field(default=60, metadata=checks(integer(1)))
    steps: int = field(default=500, metadata=checks(integer(1)))  # steps per epoch
    seed: int = field(default=0, metadata=checks(integer(0), below(2**63, "2**63")))
    # one OS process per actor, all in one ("single"), or a plain loop ("inprocess")
    placement: str = field(default="process", metadata=checks(one_of(PLACEMENTS)))
    # TD updates and fictitious-play counts; off: the swarm runs as trained
    learn: bool = field(default=True, metadata=checks(boolean))
    explore: bool = field(default=True, metadata=checks(boolean))  # off: greedy actions
    # Every epoch after the first starts where the last one ended, not at the initial angles: the paper's
    # "successive on-line requests" of its test goals (§5.2).
    successive: bool = field(default=False, metadata=checks(boolean))
    from_dir: str | None = None  # start from this run's checkpoints (absolute path)
    scenario: str | None = None  # a scenario TOML (timed faults, absolute path), read by the sim
    controller: str = field(default="agents", metadata=checks(one_of(CONTROLLERS)))
    action_deg: float = field(default=1.0, metadata=checks(number_in(0, 45)))  # the size of every agent's move
    # per step: a command missing by then means its joint holds
    deadline_ms: int = field(default=500, metadata=checks(integer(1)))
    # how long a silent Zenoh peer still counts as present
    lease_ms: int = field(default=1000, metadata=checks(integer(LEASE_RANGE_MS[0]), at_most(LEASE_RANGE_MS[1])))
    # every epoch: a restarted agent loses at most one epoch of learning (~3 ms a save)
    checkpoint_every: int = field(default=1, metadata=checks(integer(0)))
    max_restarts: int = field(default=5, metadata=checks(integer(0)))  # restart policy: at most this many restarts
    restart_window_s: float = field(default=60.0, metadata=checks(positive))  # ... of one agent within this many s
    # a stall: no step of the lockstep for this long, or steps ending at the deadline without an agent's commands
    # (0: 10 s, or 4 deadlines if longer); recorded and shown, and past stall_limit_s the run ends naming the actor
    stall_s: float = field(default=0.0, metadata=checks(seconds))
    stall_limit_s: float = field(default=300.0, metadata=checks(seconds))
    # every agent sends what it saw and chose at each step, once an epoch (AgentTrace -> agents.jsonl, the viewer)
    record_agents: bool = False
    # at the end: motion.gif (kinswarm animate) and, with the extra kinswarm[viewer], recording.rrd (kinswarm view).
    # Its default comes from KINSWARM_RECORD when set: the test suite sets 0 (a few seconds a run, hundreds of runs)
    record: bool = field(default_factory=lambda: os.environ.get("KINSWARM_RECORD", "1") != "0")
    # B robots in lockstep through one swarm, each agent learning from all B (actors/agent/fleet.py and
    # actors/simulator/fleet.py); the run's metrics, recording and motion are robot 0's, EpochDone.fleet every
    # robot's final error
    fleet: int = field(default=1, metadata=checks(integer_in(1, MAX_FLEET), _agents_drive_a_fleet))
    # "same": every robot the epoch's goal; "spread": robot b of epoch e the task's goal (and start) of epoch e*B + b,
    # a goal list walked B goals an epoch (the paper's protocol is one goal an epoch: "same", or no fleet)
    fleet_goals: str = field(default="same", metadata=checks(one_of(FLEET_GOALS)))
    listen: str = field(default=DEFAULT_LISTEN, metadata=checks(_listen))  # the supervisor's endpoint
    # Several hosts (a deploy plan): the hosts whose heartbeats the sim must hear to step, within lease_ms
    hosts: list[str] = field(default_factory=list, metadata=checks(_hosts))
    # Key of the messages' MAC (codec.py): only holders of config.json can speak on this run's keys.
    secret: str = field(default_factory=lambda: secrets.token_hex(16), repr=False, metadata=checks(_secret))

    def __post_init__(self) -> None:
        if problem := first_problem(self):
            raise ConfigError(problem)

    @property
    def stall_bound(self) -> float:
        """Seconds without the lockstep's own progress that count as a stall."""
        return self.stall_s or max(10.0, 4 * self.deadline_ms / 1000)

    @property
    def action_rad(self) -> float:
        return math.radians(self.action_deg)

    def topo(self) -> Topology:
        return self._topo

    @cached_property
    def _topo(self) -> Topology:
        return parse_robot(self.robot, self.source)

    @cached_property
    def scene_spec(self) -> SceneSpec:
        return parse_scene(self.scene, self._topo, self.source)

    def to_json(self) -> str:
        return json.dumps({**dataclasses.asdict(self), "kinswarm": writer_version()}, indent=2)

    @property
    def key(self) -> bytes:
        return self.secret.encode()

    def write(self, path: Path) -> None:
        """Owner-only (0600): the file holds the run's secret. Written whole or not at all (a new file renamed into
        place): a resume rewrites the config.json of a run that must stay resumable, whatever cuts the write short."""
        path = Path(path)
        tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
        try:
            fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
            with os.fdopen(fd, "w") as f:
                f.write(self.to_json() + "\n")
                f.flush()
                os.fsync(f.fileno())
            os.chmod(tmp, 0o600)
            os.replace(tmp, path)
        except BaseException:
            tmp.unlink(missing_ok=True)
            raise

    def located(self, run_dir: str | os.PathLike[str]) -> RunConfig:
        """This run with its directory where it is now: a run directory may be moved or copied, and every actor finds
        its files in the directory it was handed, never at the path recorded when the run began."""
        here = str(Path(run_dir).resolve())
        return self if self.out == here else dataclasses.replace(self, out=here)


def config_from_json(text: str, source: str = "<memory>") -> RunConfig:
    """A RunConfig from its JSON (config.json, a Setup message); unknown or mistyped fields are refused."""
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise ConfigError(f"{source}: not JSON: {e}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{source}: expected a JSON object")
    data.pop("kinswarm", None)  # who wrote it: recorded_version
    known = {f.name for f in dataclasses.fields(RunConfig)}
    unknown = set(data) - known
    if unknown:
        raise ConfigError(f"{source}: unknown field {sorted(unknown)[0]!r}")
    try:
        return RunConfig(**data)
    except TypeError as e:
        raise ConfigError(f"{source}: {e}") from None


def writer_version() -> str:
    """This kinswarm's version and run format, as config.json records them."""
    from importlib.metadata import PackageNotFoundError, version

    try:
        v = version("kinswarm")
    except PackageNotFoundError:  # run from a source tree that was never installed
        v = "0+unknown"
    return f"{v}+run{RUN_FORMAT}"


def recorded_version(path: Path) -> str | None:
    """The version that wrote the run's config.json (None: written before versions were recorded, or unreadable)."""
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, ValueError):
        return None
    v = data.get("kinswarm") if isinstance(data, dict) else None
    return v if isinstance(v, str) else None


def load_run_config(path: str | Path) -> RunConfig:
    try:
        text = Path(path).read_text()
    except OSError as e:
        raise ConfigError(f"{path}: cannot read run config: {e}") from None
    return config_from_json(text, str(path))
