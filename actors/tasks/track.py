"""Track: the goal moves along a path given in the file — a circle or a polyline — at a speed in units per step, and
the swarm follows it. The supervisor sends each epoch's path (the goal of every step, EpochStart.path); the simulator
publishes the step's goal in the task observation and measures the tracking error against it; the root pays each
step's move against the goal the agents saw when they chose it.

```toml
[task]
kind = "track"
speed = 0.025              # units per step along the path
reward = "graded"          # reach's modes (reach.reach_reward), on the goal the agents saw
[task.circle]              # a circle ...
center = [6.0, 4.0]
radius = 2.0
start_deg = 0.0            # where on it the goal starts (0: at center + (radius, 0))
turn = "ccw"               # or "cw"
# polyline = [[8.0, 4.0], [6.0, 7.0], [4.0, 4.0]]   # ... or a polyline (exactly one of the two)
# closed = true            # a closed polyline goes round; an open one ends at its last point, where the goal stays
```

The reward. r(t-1) rewards the move the swarm made at t-1 against the goal it saw then, g(t-1): D_prev = |tip(t-1) -
g(t-1)|, D = |tip(t) - g(t-1)|, r = R(D, D_prev) with reach's reward modes. Measured against the moving goal itself,
D(t) - D(t-1) would also count the goal's own move, which no agent made: every step of a goal moving away would be
punished whatever the swarm did. Reaching is the special case of a goal that does not move. Measured on the circle of
examples/chain4-track.toml (docs/results/track/, 3 seeds, 60 epochs): `graded` (the gradient inside D_min too)
tracks with a mean error of 0.144 while learning and 0.391 frozen; `shaped`, whose weak pull inside D_min (e^(-D)
for a step closer, 0 for keeping still) lets the goal drift off, 0.267 and 0.707. The pseudo-inverse: 0.000.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from kinswarm.actors.learning.observation import Observation
from kinswarm.protocol.messages import Task

from .base import AgentTask, Head, TaskDef, Vec2, centroid
from .reach import REWARD_MODES, reach_reward

TURNS = ("ccw", "cw")


@dataclass(frozen=True)
class Circle:
    center: Vec2
    radius: float
    start_deg: float = 0.0
    turn: str = "ccw"

    def __post_init__(self) -> None:
        if not (math.isfinite(self.radius) and self.radius > 0):
            raise ValueError(f"radius: must be > 0, got {self.radius}")
        if self.turn not in TURNS:
            raise ValueError(f"turn: expected one of {', '.join(TURNS)}, got {self.turn!r}")


@dataclass(frozen=True)
class TrackSettings:
    speed: float = 0.025  # units per step along the path
    reward: str = "graded"
    circle: Circle | None = None
    polyline: tuple[Vec2, ...] = ()
    closed: bool = False

    def __post_init__(self) -> None:
        if (self.circle is None) == (not self.polyline):
            raise ValueError("circle: give exactly one path, a [task.circle] table or polyline = [[x, y], ...]")
        if not (math.isfinite(self.speed) and self.speed >= 0):
            raise ValueError(f"speed: must be a number of units per step >= 0, got {self.speed}")
        if self.polyline and len(self.polyline) < 2:
            raise ValueError(f"polyline: needs at least 2 points, got {len(self.polyline)}")
        if self.closed and not self.polyline:
            raise ValueError("closed: only with polyline (a circle is closed)")
        if any(not math.isfinite(c) for p in self.polyline for c in p):
            raise ValueError("polyline: expected finite numbers")

    def at(self, s: float) -> Vec2:
        """The path's point at arc length s from its start."""
        c = self.circle
        if c is not None:
            a = math.radians(c.start_deg) + (s / c.radius) * (1.0 if c.turn == "ccw" else -1.0)
            return (c.center[0] + c.radius * math.cos(a), c.center[1] + c.radius * math.sin(a))
        pts = [*self.polyline, self.polyline[0]] if self.closed else list(self.polyline)
        lengths = [math.dist(a, b) for a, b in zip(pts, pts[1:], strict=False)]
        total = sum(lengths)
        if total == 0.0:
            return pts[0]
        s = s % total if self.closed else min(s, total)
        for (a, b), n in zip(zip(pts, pts[1:], strict=False), lengths, strict=True):
            if s <= n and n > 0:
                f = s / n
                return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))
            s -= n
        return pts[-1]


class TrackTask(TaskDef):
    kind = "track"
    scenes = ("free",)
    Settings = TrackSettings
    rewards = REWARD_MODES

    def check(self) -> str | None:
        s = self.settings
        if s.reward not in self.rewards:
            return f"reward: {s.reward!r} is not one of {', '.join(self.rewards)}"
        lap = [s.at(k * 0.05) for k in range(4000)] if s.circle is not None else list(s.polyline)
        return self.out_of_reach("circle" if s.circle is not None else "polyline", lap)

    def goal(self, epoch: int, steps: int) -> tuple[Vec2, list[Vec2]]:
        path = [self.settings.at(self.settings.speed * t) for t in range(steps)]
        return path[0], path

    def agent(self, agent: str, observation: Observation | None) -> AgentTask:
        return TrackAgent(self.settings, self.topo.subtree_leaves(agent))


class TrackAgent(AgentTask):
    """The root pays each move against the goal the agents saw when they chose it (the module's doc)."""

    def __init__(self, settings: TrackSettings, leaves: tuple[str, ...]) -> None:
        self.s, self.leaves = settings, leaves
        self.before: tuple[Vec2, Vec2] | None = None  # (tip, goal) at the step before

    def start_epoch(self) -> None:
        self.before = None

    def head(self, obs: Task) -> Head:
        tip = centroid([obs.tips[leaf] for leaf in self.leaves if leaf in obs.tips])
        reward = None
        if self.before is not None:
            tip0, seen = self.before
            D_prev = math.hypot(tip0[0] - seen[0], tip0[1] - seen[1])
            D = math.hypot(tip[0] - seen[0], tip[1] - seen[1])
            reward = reach_reward(D, D_prev, self.s.reward)
        self.before = (tip, obs.goal)
        return Head(obs.goal, reward)


TASK = TrackTask
