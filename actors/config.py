"""The run configuration: resolved once by the CLI, written to `<out>/config.json`, and read back by
every actor process through `load_run_config` (the one config loader)."""

from __future__ import annotations

import dataclasses
import json
import math
import os
import secrets
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from kinswarm.actors.learning.grasp import GRASP_REWARDS
from kinswarm.actors.learning.reward import REWARD_MODES
from kinswarm.protocol.keys import check_id
from kinswarm.protocol.topology import Topology, load_topology

# the reaching modes, then the grasp ones (actors/learning/grasp.py's scene_reward_problem says which fit a scene)
REWARDS = tuple(dict.fromkeys((*REWARD_MODES, *GRASP_REWARDS)))
PLACEMENTS = ("process", "single")
LEASE_RANGE_MS = (100, 60_000)  # the Zenoh leases accepted: --lease-ms and a plan's [zenoh] lease_ms
CONTROLLERS = ("agents", "baseline", "greedy")  # the learning agents, or a model-based law (sim/controller.py)


class ConfigError(ValueError):
    pass


@dataclass(frozen=True)
class RunConfig:
    run_id: str
    topology: str  # absolute path of the topology TOML
    out: str  # absolute path of the run directory
    epochs: int = 60
    steps: int = 500
    seed: int = 0
    goal: tuple[float, float] | None = None  # None: the topology's [task] goal
    reward: str = "shaped"
    placement: str = "process"
    listen: str = "tcp/127.0.0.1:7447"
    from_dir: str | None = None
    learn: bool = True
    explore: bool = True
    # Every epoch after the first starts where the last one ended, not at the initial angles: the paper's
    # "successive on-line requests" of its test goals (§5.2).
    successive: bool = False
    deadline_ms: int = 500
    action_deg: float = 1.0
    checkpoint_every: int = 1  # every epoch: a restarted agent loses at most one epoch of learning (~3 ms a save)
    controller: str = "agents"
    learner: dict[str, Any] = field(default_factory=dict)  # LearnerSettings overrides
    scenario: str | None = None  # absolute path of a scenario TOML (timed faults), read by the sim
    max_restarts: int = 5  # restart policy: at most this many restarts of one agent ...
    restart_window_s: float = 60.0  # ... within this many seconds, else the run fails
    # Several hosts (a deploy plan): the hosts whose heartbeats the sim must hear to step, within lease_ms
    hosts: list[str] = field(default_factory=list)
    lease_ms: int = 1000
    # Key of the messages' MAC (codec.py): only holders of config.json can speak on this run's keys.
    secret: str = field(default_factory=lambda: secrets.token_hex(16), repr=False)

    def __post_init__(self) -> None:
        check_id("run id", self.run_id)
        ints = (("epochs", 1), ("steps", 1), ("deadline_ms", 1), ("checkpoint_every", 0), ("max_restarts", 0))
        ints += (("lease_ms", LEASE_RANGE_MS[0]),)
        for name, lo in ints:
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < lo:
                raise ConfigError(f"{name}: expected an integer >= {lo}, got {v!r}")
        if self.lease_ms > LEASE_RANGE_MS[1]:
            raise ConfigError(f"lease_ms: expected at most {LEASE_RANGE_MS[1]}, got {self.lease_ms}")
        if self.reward not in REWARDS:
            raise ConfigError(f"reward: {self.reward!r} is not one of {', '.join(REWARDS)}")
        if self.placement not in PLACEMENTS:
            raise ConfigError(f"placement: {self.placement!r} is not one of {', '.join(PLACEMENTS)}")
        if self.controller not in CONTROLLERS:
            raise ConfigError(f"controller: {self.controller!r} is not one of {', '.join(CONTROLLERS)}")
        if not (isinstance(self.action_deg, (int, float)) and 0 < self.action_deg <= 45):
            raise ConfigError(f"action_deg: expected a number in (0, 45], got {self.action_deg!r}")
        if not (isinstance(self.restart_window_s, (int, float)) and self.restart_window_s > 0):
            raise ConfigError(f"restart_window_s: expected a number > 0, got {self.restart_window_s!r}")
        if not (isinstance(self.secret, str) and len(self.secret) >= 16):
            raise ConfigError("secret: expected a string of at least 16 characters")
        if not (isinstance(self.hosts, list) and all(isinstance(h, str) for h in self.hosts)):
            raise ConfigError(f"hosts: expected a list of host names, got {self.hosts!r}")
        if self.goal is not None and (len(self.goal) != 2 or not all(math.isfinite(g) for g in self.goal)):
            raise ConfigError(f"goal: expected two finite numbers, got {self.goal!r}")

    @property
    def action_rad(self) -> float:
        return math.radians(self.action_deg)

    def topo(self) -> Topology:
        return load_topology(self.topology)

    def resolved_goal(self, topo: Topology) -> tuple[float, float]:
        goal = self.goal if self.goal is not None else topo.goal
        if goal is None:
            raise ConfigError(f"no goal: pass --goal X,Y or give [task] goal in {topo.source}")
        return (float(goal[0]), float(goal[1]))

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), indent=2)

    @property
    def key(self) -> bytes:
        return self.secret.encode()

    def write(self, path: Path) -> None:
        """Owner-only (0600): the file holds the run's secret."""
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(self.to_json() + "\n")
        os.chmod(path, 0o600)


def load_run_config(path: str | Path) -> RunConfig:
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, json.JSONDecodeError) as e:
        raise ConfigError(f"{path}: cannot read run config: {e}") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{path}: expected a JSON object")
    known = {f.name for f in dataclasses.fields(RunConfig)}
    unknown = set(data) - known
    if unknown:
        raise ConfigError(f"{path}: unknown field {sorted(unknown)[0]!r}")
    if data.get("goal") is not None:
        data["goal"] = tuple(data["goal"])
    try:
        return RunConfig(**data)
    except TypeError as e:
        raise ConfigError(f"{path}: {e}") from None
