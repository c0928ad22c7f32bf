"""Reach (paper §4.2, §5.1-5.3): bring the end effector to a goal. The root turns the distance to the goal into the
global reward (Eq. 10 and its variants); a goal per epoch (`goals`) is the generalisation protocol (§5.2).

```toml
[task]
kind = "reach"
goal = [4.16, 6.18]       # the goal (x, y); or
goals = [[1, 2], [3, 4]]  # a goal per epoch, cycled
reward = "shaped"         # paper | strict | shaped | graded | settle (reach_reward below)
via = [2.0, 2.0]          # optional: the distance is measured along an approach path through via (path_distance)
via_width = 0.3
waypoints = [[8.0, 4.0]]  # optional: sub-goals handed down one after the other (next_waypoint)
waypoint_radius = 0.5
settle_radius = 0.3       # reward settle: within this the tip has arrived
start_pose = "random"     # home (default) | random: each epoch from joint angles drawn within the joint limits
start_share = 1.0         # random: the share of epochs drawn (the others start from home)
start_seed = 0            # random: the draws are a function of (start_seed, epoch) alone
tip = "sensed"            # computed (default) | sensed: aim by the tip as sensed where the computed one disagrees
```

`tip`: "sensed" aims by the tip as sensed (Task.tips, which the reward is measured on) wherever the tip the agents
compute from their encoders disagrees with it (actors/tasks/sensed.py, shared with reach3d): with a1 reading +10°
every agent sees the arm turned 10° about the base, brings its computed tip to the goal, and the real one stays
2 r sin 5° away; aiming at the goal moved by the difference brings the real one there. On a sound robot: bit for bit
the same run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from kinswarm.actors.learning.observation import Observation
from kinswarm.protocol.messages import Task

from . import sensed
from .base import AgentTask, Head, StepView, TaskDef, Vec2, centroid

REWARD_MODES: tuple[str, ...] = ("shaped", "paper", "strict", "graded", "settle")
#: settle: within this of the goal (at t - 1 and t) the tip has arrived (default: the corridor's success tolerance)
SETTLE_RADIUS = 0.3
START_POSES: tuple[str, ...] = ("home", "random")


@dataclass(frozen=True)
class ReachSettings:
    goal: Vec2 | None = None  # the goal (x, y); required unless `goals` is given
    goals: tuple[Vec2, ...] = ()  # a goal per epoch, cycled (the generalisation protocol, §5.2)
    reward: str = "shaped"  # Eq. 10 as printed ("paper") or a variant (reach_reward)
    via: Vec2 | None = None  # measure the goal distance along an approach path through this point
    via_width: float = 0.0  # ... once the tip is within this of the line via -> goal, straight to the goal
    waypoints: tuple[Vec2, ...] = ()  # sub-goals, one after the other
    waypoint_radius: float = 0.0  # ... the next one once the tip is within this
    settle_radius: float = SETTLE_RADIUS  # reward "settle": within this of the goal the tip has arrived
    # Where each epoch starts. A swarm trained from home only learns a way out of home: frozen and asked for each
    # goal from where the last one ended (§5.2's successive requests) it stopped far from goals it reached from home.
    start_pose: str = "home"  # home | random (uniform within every joint's limits, per epoch)
    start_share: float = 1.0  # random: the share of epochs that start from a drawn pose, the others from home
    start_seed: int = 0  # random: the poses drawn depend on (start_seed, epoch) only, so a rerun or resume repeats them
    # "sensed": where the tip computed from the encoders disagrees with the sensed one, aim by the sensed one (above)
    tip: str = "computed"

    def __post_init__(self) -> None:
        if self.goal is None and not self.goals:
            raise ValueError("goal: missing (give goal = [x, y], or goals = [[x, y], ...])")
        for name, pts in (("goal", (self.goal,) if self.goal is not None else ()), ("goals", self.goals)):
            if not all(math.isfinite(c) for p in pts for c in p):
                raise ValueError(f"{name}: expected finite numbers")
        if self.via is not None and not self.via_width > 0:
            raise ValueError(f"via_width: must be > 0 with via, got {self.via_width}")
        if self.via is None and self.via_width:
            raise ValueError("via_width: only with via")
        if self.waypoints and not self.waypoint_radius > 0:
            raise ValueError(f"waypoint_radius: must be > 0 with waypoints, got {self.waypoint_radius}")
        if not self.waypoints and self.waypoint_radius:
            raise ValueError("waypoint_radius: only with waypoints")
        if not (math.isfinite(self.settle_radius) and self.settle_radius > 0.0):
            raise ValueError(f"settle_radius: must be a distance > 0, got {self.settle_radius}")
        if self.start_pose not in START_POSES:
            raise ValueError(f"start_pose: {self.start_pose!r} is not one of {', '.join(START_POSES)}")
        if not (isinstance(self.start_share, (int, float)) and 0.0 <= self.start_share <= 1.0):
            raise ValueError(f"start_share: must be a share in [0, 1], got {self.start_share}")
        if self.start_pose != "random" and (self.start_share != 1.0 or self.start_seed != 0):
            raise ValueError('start_share, start_seed: only with start_pose = "random"')
        if isinstance(self.start_seed, bool) or not isinstance(self.start_seed, int) or self.start_seed < 0:
            raise ValueError(f"start_seed: must be an integer >= 0, got {self.start_seed!r}")
        sensed.check_tip(self.tip)


class ReachTask(TaskDef):
    kind = "reach"
    scenes = ("free",)
    Settings = ReachSettings
    rewards = REWARD_MODES

    def check(self) -> str | None:
        s = self.settings
        if s.reward not in self.rewards:
            return f"reward: {s.reward!r} is not one of {', '.join(self.rewards)}"
        if s.start_pose == "random":
            for a in self.topo.dof_agents:
                lo, hi = self.topo.agents[a].limits
                if not (math.isfinite(lo) and math.isfinite(hi)):
                    return f"start_pose: random draws within the joint limits; {a} has none that are finite"
        return self.out_of_reach("goal", [s.goal] if s.goal is not None else []) or self.out_of_reach(
            "goals", list(s.goals)
        )

    def goal(self, epoch: int, steps: int) -> tuple[Vec2, list[Vec2]]:
        s = self.settings
        goal = s.goals[epoch % len(s.goals)] if s.goals else s.goal
        return (float(goal[0]), float(goal[1])), []

    def start(self, epoch: int) -> dict[str, float]:
        """Home, or with start_pose = "random" (in start_share of the epochs) every DOF agent's angle drawn uniformly
        within its limits, from a generator seeded by (start_seed, epoch): the same poses in every placement."""
        s = self.settings
        if s.start_pose != "random":
            return {}
        rng = np.random.default_rng([s.start_seed, epoch])
        if rng.random() >= s.start_share:
            return {}
        return {a: float(rng.uniform(*self.topo.agents[a].limits)) for a in self.topo.dof_agents}

    def agent(self, agent: str, observation: Observation | None) -> AgentTask:
        return ReachAgent(self.settings, self.topo.subtree_leaves(agent))


class ReachAgent(AgentTask):
    """The root measures D_goal(t) from the task observation and pays R(D(t), D(t-1)) (Eq. 10); with tip = "sensed"
    it sends the sensed tips down, and every agent aims by them where its computed tip disagrees."""

    def __init__(self, settings: ReachSettings, leaves: tuple[str, ...]) -> None:
        self.s, self.leaves = settings, leaves
        self._sensed_keys = sensed.keys(leaves, "xy")
        self.D_prev: float | None = None  # D_goal(t-1)
        self.waypoint = 0  # the current sub-goal of `waypoints` in this epoch

    def start_epoch(self) -> None:
        self.D_prev, self.waypoint = None, 0

    def head(self, obs: Task) -> Head:
        s, goal = self.s, obs.goal
        tip = centroid([obs.tips[leaf] for leaf in self.leaves if leaf in obs.tips])
        if s.waypoints:  # the swarm aims at the current sub-goal
            self.waypoint, goal, D = next_waypoint(tip, goal, s.waypoints, self.waypoint, s.waypoint_radius)
        elif s.via is not None:
            D = path_distance(tip, goal, s.via, s.via_width)
        else:
            D = math.hypot(tip[0] - goal[0], tip[1] - goal[1])
        reward = None if self.D_prev is None else self.global_reward(D, self.D_prev, obs)
        self.D_prev = D
        if s.tip != "sensed":
            return Head(goal, reward)
        return Head(goal, reward, context=sensed.context(obs.tips, "xy"))

    def aim(self, view: StepView) -> Vec2:
        """tip = "sensed": the goal moved by (computed tip - sensed tip) where they differ by more than the sensor's
        precision (sensed.TIP_PRECISION), so that bringing the computed tip to the aim brings the sensed one to the
        goal; else the goal."""
        if self.s.tip != "sensed":
            return view.goal
        moved = sensed.moved_goal(view.goal, view.tip, view.sense, self._sensed_keys)
        return view.goal if moved is None else (moved[0], moved[1])

    def global_reward(self, D: float, D_prev: float, obs: Task) -> float:
        return reach_reward(D, D_prev, self.s.reward, settle_radius=self.s.settle_radius)


def reach_reward(
    D: float,
    D_prev: float,
    mode: str,
    D_min: float = 3.0,
    c: float = 1.0,
    k: float = 20.0,
    settle_radius: float = SETTLE_RADIUS,
) -> float:
    """R(t) from the goal distance D = D_goal(t) and D_prev = D_goal(t-1); Delta D = D - D_prev.

    paper (Eq. 10 as printed):
        D <= D_min and Delta D <= 0  ->  e^(-c D)
        D >  D_min                   ->  -2
        D <  D_min and Delta D > 0   ->  -1
      Eq. 10 leaves D == D_min with Delta D > 0 undefined; we treat it as inside and moving away: -1.
    strict: as paper, but 0 inside D_min when the arm did not move (|Delta D| < 1e-12), so "keep" is
      not rewarded like an approach.
    shaped: strict inside D_min; outside r = -2 + k (D_prev - D), a gradient towards the goal.
    graded: shaped with the gradient inside D_min too, r = strict + k (D_prev - D). Inside D_min an approach
      earns e^(-c D) (0.05-0.37 at D = 1-3) against -1 for a step away, so "keep" (0) beat moving wherever the
      policy was unsure; frozen swarms stopped 1-3 from unseen goals. Measured in docs/notebook/reaching.md ("graded").
    settle: shaped, but while the tip stays within settle_radius of the goal (at t - 1 and t) it earns e^(-c D)
      whatever it did. Shaped pays there e^(-c D) for a step in, 0 for "keep" and -1 for a step out, so an arrived
      chain never learns to keep still; in a corridor its jitter is pushed into the walls.
    """
    if mode not in REWARD_MODES:
        raise ValueError(f"unknown reward mode {mode!r}; allowed modes: {', '.join(REWARD_MODES)}")
    dD = D - D_prev
    if mode == "settle" and D <= settle_radius and D_prev <= settle_radius:
        return math.exp(-c * D)
    if D > D_min:
        if mode in ("shaped", "graded", "settle"):
            return -2.0 + k * (D_prev - D)
        return -2.0
    gradient = k * (D_prev - D) if mode == "graded" else 0.0
    if mode != "paper" and abs(dD) < 1e-12:
        return 0.0
    if dD <= 0.0:
        return math.exp(-c * D) + gradient
    return -1.0 + gradient


def path_distance(tip: Vec2, goal: Vec2, via: Vec2, width: float) -> float:
    """D_goal measured along an approach path through `via` (e.g. a corridor's axis): straight to the goal once the
    tip is "past" via -- ahead of it towards the goal and within `width` of the line via -> goal -- else
    |tip - via| + |via - goal|. This is the task designer's knowledge of the scene in the reward (the agents still
    sense only their own readings): it turns the corridor's mouth from a dead end of the Euclidean distance into a
    way point on a path along the corridor's axis."""
    ux, uy = goal[0] - via[0], goal[1] - via[1]
    length = math.hypot(ux, uy)
    dx, dy = tip[0] - via[0], tip[1] - via[1]
    if length > 0.0:
        along = (dx * ux + dy * uy) / length
        across = abs(dx * uy - dy * ux) / length
        if along >= 0.0 and across <= width:
            return math.hypot(tip[0] - goal[0], tip[1] - goal[1])
    return math.hypot(dx, dy) + length


def next_waypoint(tip: Vec2, goal: Vec2, waypoints: tuple[Vec2, ...], k: int, radius: float) -> tuple[int, Vec2, float]:
    """Sub-goals along a path: the root aims the swarm at waypoint k until the tip comes within `radius` of it, then
    at the next one, and at the goal after the last. Returns (k, the current target, D_goal = |tip - target| + the
    path's length from the target to the goal), so D_goal falls steadily along the path and barely jumps when k
    advances. k only grows within an epoch."""
    while k < len(waypoints) and math.hypot(tip[0] - waypoints[k][0], tip[1] - waypoints[k][1]) <= radius:
        k += 1
    points = [*waypoints[k:], goal]
    rest = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(points, points[1:], strict=False))
    target = points[0]
    return k, target, math.hypot(tip[0] - target[0], tip[1] - target[1]) + rest


TASK = ReachTask
