"""The task interface: what the generic agent asks of a task, at fixed points of the lockstep step.

A task is a module of this package holding a `TaskDef` subclass (its settings are the run file's `[task]` table):

  supervisor    `goal(epoch)`: the goal of each epoch, and the goal of every step when it moves (a path);
                `start(epoch)`: the pose it starts from (default: the robot's home);
  every agent   `observation(agent)`: what the agent's state S_i holds (its kind, g3, bounds, the task's variables
                first among the extras); `learner(agent)`: the fuzzy learner's settings over it (the grid's defaults);
                `agent(agent)`: the agent's `AgentTask`, which the agent calls at each step:
    root          head(task observation)    -> Head: the goal, the reward r(t-1), the context every child
                                               inherits, what differs for each child;
    all           up(view)                  -> readings for the parent's `Up.sense` (a subtree's aggregate);
                  state(view)               -> values of the task's state variables;
                  reward(view, r)           -> r with the agent's local reward terms;
                  aim(view)                 -> the goal its state S_i is built from (the task's goal, or
                                               where its computed tip must go for the sensed one to reach it);
                  avoid(view)               -> actions the agent must leave out of this step's choice;
                  scale(view)               -> the factor on the agent's action size (1: as the run says).

The defaults are plain reaching: no aggregate, no extra state, no local reward, nothing left out, full steps.
The agent never names a task; docs/tasks.md walks through adding one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

from kinswarm.actors.learning.observation import OBSERVATION_FIELDS, Observation, StateVariable
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.protocol.messages import Readings, Task, Up
from kinswarm.protocol.scene import SceneSpec
from kinswarm.protocol.topology import Topology

Vec2 = tuple[float, float]
Frame = tuple[float, float, float]


@dataclass(frozen=True)
class Head:
    """What the root's task makes of a step's task observation: the goal, reward r(t-1) and context it sends down,
    and per child what differs from them (a grasp's fingers each get their own goal, reward and context)."""

    goal: Vec2
    reward: float | None
    children: Mapping[str, tuple[Vec2, float | None, Readings]] = field(default_factory=dict)
    context: Readings = field(default_factory=dict)  # what every agent below inherits (Down.sense)


@dataclass(frozen=True)
class StepView:
    """What an agent knows when it finishes a step, as its task sees it."""

    epoch: int
    step: int
    frame: Frame  # the agent's joint frame
    end: Frame  # the end of its link (its children's base)
    tip: Vec2  # the end effector below it (the centroid of several)
    goal: Vec2
    sense: Readings  # its own Obs.sense over the context from above (Down.sense)
    ups: Mapping[str, Up]  # its live children's `up` of this step
    last_action: int | None  # its own action at the step before, if it took one
    q: float = 0.0  # its own joint value (rad; m for a prismatic joint)


class AgentTask:
    """One agent's share of a task; the defaults are plain reaching."""

    def start_epoch(self) -> None:
        """A new epoch begins (per-epoch memory resets)."""

    def head(self, obs: Task) -> Head:  # the root only
        raise NotImplementedError(f"{type(self).__name__} has no root part")

    def up(self, view: StepView) -> Readings:
        return {}

    def state(self, view: StepView) -> list[float]:
        return []

    def reward(self, view: StepView, reward: float | None) -> float | None:
        return reward

    def aim(self, view: StepView) -> Vec2:
        """The goal the agent's state S_i (and its own extra variables) is built from: the task's goal as it is."""
        return view.goal

    def avoid(self, view: StepView) -> list[int]:
        return []

    def scale(self, view: StepView) -> float:
        return 1.0


class TaskDef:
    """A task: its settings and how it sets up the swarm. Subclasses set the class attributes and override what
    differs; the constructor gets the validated settings, the robot and the scene."""

    kind: ClassVar[str]
    scenes: ClassVar[tuple[str, ...]]  # the scene kinds it runs in
    Settings: ClassVar[type]  # a frozen dataclass: the [task] table's fields; __post_init__ validates them
    rewards: ClassVar[tuple[str, ...]]  # its reward modes (settings.reward), the first the default
    spatial: ClassVar[bool] = False  # True: it moves robots from URDF (3D frames), else planar robots

    def __init__(self, settings: Any, topo: Topology, scene: SceneSpec) -> None:
        self.settings, self.topo, self.scene = settings, topo, scene

    def check(self) -> str | None:
        """What is wrong with the settings for this robot and scene (None: nothing); named by field."""
        return None

    def out_of_reach(self, field: str, points: list[Vec2]) -> str | None:
        """`field: ...` when a point lies beyond the robot's reach from its base (it cannot be reached; the best the
        swarm can do is reach minus that distance away), else None."""
        t = self.topo
        base = (t.base[0], t.base[1])
        for p in points:
            d = math.hypot(p[0] - base[0], p[1] - base[1])
            if d > t.reach + 1e-9:
                return (
                    f"{field}: ({p[0]:g}, {p[1]:g}) lies {d:.3g} from the robot's base ({base[0]:g}, {base[1]:g}), "
                    f"beyond its reach {t.reach:.3g}: the nearest the tip can come is {d - t.reach:.3g} from it"
                )
        return None

    def goal(self, epoch: int, steps: int) -> tuple[Vec2, list[Vec2]]:
        """The goal of epoch `epoch`, and the goal of each of its `steps` steps when it moves (else [])."""
        raise NotImplementedError

    def start(self, epoch: int) -> dict[str, float]:
        """The joint angles (rad, every DOF agent) epoch `epoch` starts from; {}: the robot's home."""
        return {}

    def reach(self, agent: str) -> float:
        """The length scale of the agent's default state ranges (LearnerSettings.for_reach)."""
        return self.topo.reach

    def state_variables(self, agent: str) -> tuple[StateVariable, ...]:
        """The task's own state variables for this agent (they come first among the learner's extras)."""
        return ()

    def observation(self, agent: str, overrides: Mapping[str, Any]) -> Observation:
        """The agent's observation: the planar six on the task's scale (overrides: the run's [learner] fields that
        are the observation's), then the task's variables, then the run's extra ones."""
        given = {k: v for k, v in overrides.items() if k in OBSERVATION_FIELDS}
        return Observation.for_reach(self.reach(agent), **given).with_task_state(self.state_variables(agent))

    def learner(self, agent: str, overrides: Mapping[str, Any]) -> LearnerSettings:
        """The agent's learner settings: the run's [learner] overrides over the agent's observation."""
        own = {k: v for k, v in overrides.items() if k not in OBSERVATION_FIELDS}
        return LearnerSettings.on(self.observation(agent, overrides), **own)

    def agent(self, agent: str, observation: Observation | None) -> AgentTask:
        """The agent's share of the task (the root's also computes the reward)."""
        return AgentTask()


def centroid(points: Sequence[Sequence[float]]) -> Vec2:
    """The end effector below an agent: itself for a chain, the centroid of several in a tree."""
    if len(points) == 1:
        return (points[0][0], points[0][1])
    if not points:
        return (math.nan, math.nan)
    n = len(points)
    return (sum(p[0] for p in points) / n, sum(p[1] for p in points) / n)
