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


@dataclass(frozen=True)
class RunConfig:
    run_id: str
    out: str  # absolute path of the run directory
    robot: dict[str, Any]  # the resolved [robot] table (protocol/topology.py)
    task: dict[str, Any]  # the resolved [task] table, `kind` first (actors/tasks/)
    scene: dict[str, Any] = field(default_factory=dict)  # the resolved [scene] table (protocol/scene.py)
    learner: dict[str, Any] = field(default_factory=dict)  # LearnerSettings overrides (actors/learning/settings.py)
    source: str = "<memory>"  # the run file it was resolved from (for messages)
    epochs: int = 60
    steps: int = 500  # steps per epoch
    seed: int = 0
    placement: str = "process"  # one OS process per actor, all in one ("single"), or a plain loop ("inprocess")
    learn: bool = True  # TD updates and fictitious-play counts; off: the swarm runs as trained
    explore: bool = True  # off: greedy actions
    # Every epoch after the first starts where the last one ended, not at the initial angles: the paper's
    # "successive on-line requests" of its test goals (§5.2).
    successive: bool = False
    from_dir: str | None = None  # start from this run's checkpoints (absolute path)
    scenario: str | None = None  # a scenario TOML (timed faults, absolute path), read by the sim
    controller: str = "agents"
    action_deg: float = 1.0  # the size of every agent's move
    deadline_ms: int = 500  # per step: a command missing by then means its joint holds
    lease_ms: int = 1000  # how long a silent Zenoh peer still counts as present
    checkpoint_every: int = 1  # every epoch: a restarted agent loses at most one epoch of learning (~3 ms a save)
    max_restarts: int = 5  # restart policy: at most this many restarts of one agent ...
    restart_window_s: float = 60.0  # ... within this many seconds, else the run fails
    # a stall: no step of the lockstep for this long, or steps ending at the deadline without an agent's commands
    # (0: 10 s, or 4 deadlines if longer); recorded and shown, and past stall_limit_s the run ends naming the actor
    stall_s: float = 0.0
    stall_limit_s: float = 300.0
    # every agent sends what it saw and chose at each step, once an epoch (AgentTrace -> agents.jsonl, the viewer)
    record_agents: bool = False
    # at the end: motion.gif (kinswarm animate) and, with the extra kinswarm[viewer], recording.rrd (kinswarm view).
    # Its default comes from KINSWARM_RECORD when set: the test suite sets 0 (a few seconds a run, hundreds of runs)
    record: bool = field(default_factory=lambda: os.environ.get("KINSWARM_RECORD", "1") != "0")
    # B robots in lockstep through one swarm, each agent learning from all B (actors/agent/fleet.py and
    # actors/simulator/fleet.py); the run's metrics, recording and motion are robot 0's, EpochDone.fleet every
    # robot's final error
    fleet: int = 1
    # "same": every robot the epoch's goal; "spread": robot b of epoch e the task's goal (and start) of epoch e*B + b,
    # a goal list walked B goals an epoch (the paper's protocol is one goal an epoch: "same", or no fleet)
    fleet_goals: str = "same"
    listen: str = DEFAULT_LISTEN  # the supervisor's endpoint
    # Several hosts (a deploy plan): the hosts whose heartbeats the sim must hear to step, within lease_ms
    hosts: list[str] = field(default_factory=list)
    # Key of the messages' MAC (codec.py): only holders of config.json can speak on this run's keys.
    secret: str = field(default_factory=lambda: secrets.token_hex(16), repr=False)

    def __post_init__(self) -> None:
        check_id("run id", self.run_id)
        ints = (("epochs", 1), ("steps", 1), ("seed", 0), ("deadline_ms", 1), ("checkpoint_every", 0))
        ints += (("max_restarts", 0), ("lease_ms", LEASE_RANGE_MS[0]))
        for name, lo in ints:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ConfigError(f"{name}: expected an integer >= {lo}, got {v!r}")
        if isinstance(self.fleet, bool) or not isinstance(self.fleet, int) or not 1 <= self.fleet <= MAX_FLEET:
            raise ConfigError(f"fleet: expected an integer in [1, {MAX_FLEET}], got {self.fleet!r}")
        if self.fleet_goals not in FLEET_GOALS:
            raise ConfigError(f"fleet_goals: {self.fleet_goals!r} is not one of {', '.join(FLEET_GOALS)}")
        if self.fleet > 1 and self.controller != "agents":
            raise ConfigError(
                f"fleet: only the learning agents drive a fleet; controller {self.controller!r} drives one robot"
            )
        if self.seed >= 2**63:
            raise ConfigError(f"seed: expected an integer below 2**63, got {self.seed}")
        if self.lease_ms > LEASE_RANGE_MS[1]:
            raise ConfigError(f"lease_ms: expected at most {LEASE_RANGE_MS[1]}, got {self.lease_ms}")
        for name in ("learn", "explore", "successive"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"{name}: expected true or false, got {getattr(self, name)!r}")
        if self.placement not in PLACEMENTS:
            raise ConfigError(f"placement: {self.placement!r} is not one of {', '.join(PLACEMENTS)}")
        if self.controller not in CONTROLLERS:
            raise ConfigError(f"controller: {self.controller!r} is not one of {', '.join(CONTROLLERS)}")
        ok = isinstance(self.action_deg, (int, float)) and not isinstance(self.action_deg, bool)
        if not (ok and 0 < self.action_deg <= 45):
            raise ConfigError(f"action_deg: expected a number in (0, 45], got {self.action_deg!r}")
        w = self.restart_window_s
        if not (isinstance(w, (int, float)) and not isinstance(w, bool) and math.isfinite(w) and w > 0):
            raise ConfigError(f"restart_window_s: expected a number > 0, got {self.restart_window_s!r}")
        for name in ("stall_s", "stall_limit_s"):
            v = getattr(self, name)
            if not (isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v >= 0):
                raise ConfigError(f"{name}: expected a number of seconds >= 0, got {v!r}")
        if not (isinstance(self.secret, str) and len(self.secret) >= 16):
            raise ConfigError("secret: expected a string of at least 16 characters")
        if self.listen != AUTO_LISTEN:
            check_endpoint(self.listen, "--listen")
        if not (isinstance(self.hosts, list) and all(isinstance(h, str) for h in self.hosts)):
            raise ConfigError(f"hosts: expected a list of host names, got {self.hosts!r}")
        if not (isinstance(self.task, dict) and isinstance(self.task.get("kind"), str)):
            raise ConfigError("task: expected a table with a kind")

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
