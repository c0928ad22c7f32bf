"""Reach in 3D: bring a spatial robot's tool (a robot from URDF) to a point, or to a pose (a point and the tool's
orientation). The root pays the graded reward on the distance (Eq. 10's variant, at the robot's scale). For a point
every joint sees its rotation plane (state "plane": actors/learning/state.py plane_state); for a pose its turn (state
"turn": g_q, the move to its own best angle within its limits, frames.best_turn), and near the goal its moves are
fine (frames.move_share). `[learner] state = "plane"` or `"turn"` chooses otherwise.

```toml
[task]
kind = "reach3d"
goal = [0.5, 0.2, 0.6]            # a point (x, y, z, m); or a pose [x, y, z, roll, pitch, yaw (deg)]; or
goals = [[0.5, 0.2, 0.6], ...]    # a goal per epoch, cycled (all points, or all poses)
starts = [[0, 30, 0, -60, 0, 45, 0], ...]  # optional: the joint angles (deg, agent order) each epoch starts from,
                                  # cycled with the goals; default: the robot's home
reward = "graded"                 # graded | shaped | paper | strict (reach.reach_reward)
d_min = 0.3                       # m: Eq. 10's D_min; outside it a step pays -2 + k (D(t-1) - D(t))
c = 10.0                          # 1/m: e^(-c D) inside D_min
k = 200.0                         # 1/m: the shaping gradient
tip = "sensed"                    # computed (default) | sensed: aim by the tool point as sensed where the computed one
                                  # disagrees (an encoder that reads wrong)
```

For a pose the distance is sqrt(|tip - goal|² + (POSE_WEIGHT x the angle between the tool's orientation and the
goal's)²) (protocol/frames.py pose_distance: 0.25 m per radian, a 10° turn weighs like 4.4 cm); the metrics' error stays
the position's.

`tip = "sensed"` (actors/tasks/sensed.py, as the planar reach's): where the tool point the agents compute from their
encoders differs from the one sensed (Task.tips, which the reward is measured on) by more than 1 mm, every agent aims
at the goal point moved by that difference, so that its computed tool point at the aim is the sensed one at the goal.
For a pose only the position moves: the goal's orientation stays as it is. An encoder's offset turns the computed
tool frame too, by a rotation about that joint's axis, so the sensed orientation differs from the computed one as
well; but moving the goal's orientation by that rotation is right only for a joint turning about the base's own axis
(the iiwa's a1), and the swarm knows only the two frames, not which encoder reads wrong. On a sound robot the two
agree to single precision: the run is the same to the bit as with the setting off.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from kinswarm.actors.learning.observation import OBSERVATION_FIELDS, TURN_RANGES, Observation, plane_ranges
from kinswarm.actors.learning.settings import PLANE_SETS, TURN_LEARNER, LearnerSettings
from kinswarm.protocol import frames
from kinswarm.protocol.messages import Task
from kinswarm.protocol.topology import AgentSpec

from . import sensed
from .base import AgentTask, Head, StepView, TaskDef
from .reach import reach_reward

REWARDS = ("graded", "shaped", "paper", "strict")

Coords = tuple[float, ...]
#: metres per radian of the action size for a prismatic joint: an action of 1 (degree) moves it 1 mm
PRISMATIC_SCALE = 180.0 / (1000.0 * math.pi)


@dataclass(frozen=True)
class Reach3dSettings:
    goal: tuple[float, ...] | None = None  # (x, y, z) or (x, y, z, roll, pitch, yaw deg)
    goals: tuple[tuple[float, ...], ...] = ()  # a goal per epoch, cycled
    starts: tuple[tuple[float, ...], ...] = ()  # joint angles (deg, agent order) per epoch, cycled; () = home
    reward: str = "graded"
    d_min: float = 0.3
    c: float = 10.0
    k: float = 200.0
    tip: str = "computed"  # "sensed": aim by the sensed tool point where the computed one disagrees (above)

    def __post_init__(self) -> None:
        pts = tuple(self.goals) or ((self.goal,) if self.goal is not None else ())  # goals, when given, replace goal
        if not pts:
            raise ValueError("goal: missing (give goal = [x, y, z], or goals = [[x, y, z], ...])")
        sizes = {len(p) for p in pts}
        if not sizes <= {3, 6}:
            raise ValueError("goal: each goal is [x, y, z] or [x, y, z, roll, pitch, yaw] (deg)")
        if len(sizes) != 1:
            raise ValueError("goals: all points or all poses, not both")
        if not all(math.isfinite(c) for p in pts for c in p):
            raise ValueError("goal: expected finite numbers")
        for name in ("d_min", "c", "k"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: must be > 0, got {v}")
        sensed.check_tip(self.tip)

    @property
    def pose(self) -> bool:
        return len(self.goals[0] if self.goals else self.goal) == 6  # type: ignore[arg-type]


def wire_goal(g: tuple[float, ...]) -> Coords:
    """A goal as it travels: a point (x, y, z), or a pose (x, y, z, qx, qy, qz, qw)."""
    if len(g) == 3:
        return (float(g[0]), float(g[1]), float(g[2]))
    return (float(g[0]), float(g[1]), float(g[2]), *frames.rpy_quat(*(math.radians(a) for a in g[3:6])))


def distance(tip: Coords, goal: Coords) -> float:
    """D_goal: the tool's distance to the goal point; to a pose, with its angle to the goal's orientation."""
    D = math.dist(tip[:3], goal[:3])
    if len(goal) == 7:
        return frames.pose_distance(D, frames.angle_between(tip[3:7], goal[3:7]))
    return D


class Reach3dTask(TaskDef):
    kind = "reach3d"
    scenes = ("free",)
    Settings = Reach3dSettings
    rewards = REWARDS
    spatial = True

    def check(self) -> str | None:
        s, topo = self.settings, self.topo
        if s.reward not in REWARDS:
            return f"reward: {s.reward!r} is not one of {', '.join(REWARDS)}"
        if len(topo.end_effectors) != 1:
            return f"kind: reach3d moves one end effector; this robot has {len(topo.end_effectors)}"
        base = topo.base[:3]
        for name, pts in (("goals", list(s.goals)),) if s.goals else (("goal", [s.goal]),):
            for p in pts:
                if (d := math.dist(p[:3], base)) > topo.reach + 1e-9:
                    return (
                        f"{name}: {list(p[:3])} lies {d:.3g} m from the robot's base, beyond its reach {topo.reach:.3g}"
                    )
        n = len(topo.dof_agents)
        for i, st in enumerate(s.starts):
            if len(st) != n:
                return (
                    f"starts: entry {i} has {len(st)} angles; expected {n} (deg, agents {', '.join(topo.dof_agents)})"
                )
            for a, v in zip(topo.dof_agents, st, strict=True):
                lo, hi = topo.agents[a].limits
                if not lo - 1e-9 <= math.radians(v) <= hi + 1e-9:
                    return f"starts: entry {i}: {v:g} deg for {a} lies outside its limits"
        return None

    def goal(self, epoch: int, steps: int) -> tuple[Coords, list[Coords]]:
        s = self.settings
        g = s.goals[epoch % len(s.goals)] if s.goals else s.goal
        return wire_goal(g), []  # type: ignore[arg-type]

    def start(self, epoch: int) -> dict[str, float]:
        s = self.settings
        if not s.starts:
            return {}
        st = s.starts[epoch % len(s.starts)]
        out = {}
        for a, v in zip(self.topo.dof_agents, st, strict=True):
            lo, hi = self.topo.agents[a].limits
            out[a] = min(max(math.radians(v), lo), hi)
        return out

    def observation(self, agent: str, overrides: Mapping[str, Any]) -> Observation:
        """A point's joints see their rotation plane, a pose's their turn, unless `state` says otherwise: the plane
        does not see the orientation (0 % of poses without it); with g_rot, the turn about its own axis the tool still
        needs, added, the swarm reached 52 % of unseen poses, with the turn 90-93 % (docs/notebook/reach3d.md)."""
        given = {k: v for k, v in overrides.items() if k in OBSERVATION_FIELDS}
        if self._turns(overrides):
            return Observation(**{"state": "turn", "ranges": TURN_RANGES, **given})
        topo = self.topo
        ranges = plane_ranges(topo.reach, topo.reach_below(agent), topo.agents[agent].limits)
        return Observation(**{"state": "plane", "ranges": ranges, **given})

    def learner(self, agent: str, overrides: Mapping[str, Any]) -> LearnerSettings:
        """The fuzzy grid (and learning rate) each state kind was measured with (LearnerSettings.for_turn,
        for_plane), over the agent's observation."""
        obs = self.observation(agent, overrides)
        grid = TURN_LEARNER if obs.state == "turn" else {"n_sets": PLANE_SETS}
        own = {k: v for k, v in overrides.items() if k not in OBSERVATION_FIELDS}
        return LearnerSettings.on(obs, **{**grid, **own})

    def _turns(self, overrides: Mapping[str, Any]) -> bool:
        return overrides.get("state", "turn" if self.settings.pose else "plane") == "turn"

    def agent(self, agent: str, observation: Observation | None) -> AgentTask:
        return Reach3dAgent(self.settings, self.topo.agents[agent], self.topo.subtree_leaves(agent))


class Reach3dAgent(AgentTask):
    """The root pays the reward on D_goal; near a pose goal every joint's moves are fine. With tip = "sensed" the root
    sends the sensed tool point down, and every agent aims by it where its computed one disagrees."""

    def __init__(self, settings: Reach3dSettings, spec: AgentSpec, leaves: tuple[str, ...] = ()) -> None:
        self.s, self.spec = settings, spec
        self._sensed_keys = sensed.keys(leaves, "xyz")
        self.D_prev: float | None = None

    def start_epoch(self) -> None:
        self.D_prev = None

    def head(self, obs: Task) -> Head:
        (tip,) = obs.tips.values()
        D = distance(tip, obs.goal)
        s = self.s
        reward = None if self.D_prev is None else reach_reward(D, self.D_prev, s.reward, D_min=s.d_min, c=s.c, k=s.k)
        self.D_prev = D
        if s.tip != "sensed":
            return Head(obs.goal, reward)
        return Head(obs.goal, reward, context=sensed.context(obs.tips, "xyz"))

    def aim(self, view: StepView) -> Coords:
        """tip = "sensed": the goal's point moved by (computed - sensed tool point) where they differ by more than
        sensed.TIP_PRECISION (a pose's orientation as it is); else the goal."""
        if self.s.tip != "sensed":
            return view.goal
        moved = sensed.moved_goal(view.goal, view.tip, view.sense, self._sensed_keys)
        return view.goal if moved is None else moved

    def scale(self, view: StepView) -> float:
        """A prismatic joint moves its action size in millimetres (1° -> 1 mm), not as metres of radians (17 mm); near
        a pose goal (the goal it aims at) a move is fine (frames.move_share)."""
        return (PRISMATIC_SCALE if self.spec.prismatic else 1.0) * frames.move_share(view.tip, self.aim(view))


TASK = Reach3dTask
