"""Grasp (paper §5.5): three fingers close on a fixed object (an `object` scene). The root is the compound grasp
agent: from the task observation (the scene's contacts and the net wrench on the object) it sends each finger its
own goal, reward and context (grasp_reward.GraspReward); each finger agent reaches for its goal with g_perp in its
state and, within D_fine of it, fine steps.

```toml
[task]
kind = "grasp"
reward = "shaped"     # shaped | sensed | paper | contact | global | force (grasp_reward.py)
fine_action = 0.1     # a finger near its contact goal moves fine_action x the action size
collision_state = false   # + "collided": the joint's own move of the step before was refused by the object
collision_penalty = 0.0   # (<= 0) added to the reward of a joint whose own move was refused
collision_tabu = false    # the move the object just refused is left out of the next choice
detour = false            # sensed: a finger on another face goes round the corner between it and its own face
```
The object and each fingertip's grasp point are the scene's (`[scene.object]`). Measured: docs/notebook/grasp.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from kinswarm.actors.learning.observation import Observation, StateVariable
from kinswarm.actors.learning.state import goal_along_motion
from kinswarm.protocol.messages import Task

from .base import AgentTask, Head, StepView, TaskDef, Vec2
from .grasp_reward import GRASP_REWARDS, GraspParams, GraspReward
from .refusal import COLLIDED, collided, penalised, tabu

#: the finger agents' extra state variable: the goal's component along the direction the agent's joint moves the tip
G_PERP = StateVariable("g_perp", 7, (-GraspParams.g_perp, GraspParams.g_perp))


@dataclass(frozen=True)
class GraspSettings:
    reward: str = "shaped"  # the grasp agent's reward (grasp_reward.py)
    fine_action: float = 0.1  # the fingers' action scale within D_fine of their goal (1 degree moves fn too much)
    # a move the solid object refuses leaves the state unchanged, so a frozen table would pick it again forever:
    # with the refusal in the state (as the corridor's collision_state) the table can hold another action for it
    collision_state: bool = False
    collision_penalty: float = 0.0
    collision_tabu: bool = False  # leave the move the object just refused out of the next choice (as the corridor)
    # sensed: a finger touching another face than its own first goes round the corner between the two (a point
    # `approach` out along both normals from it), not straight through the object to its pre-grasp point
    detour: bool = False

    def __post_init__(self) -> None:
        if not 0.0 < self.fine_action <= 1.0:
            raise ValueError(f"fine_action: must be in (0, 1], got {self.fine_action}")
        if not (math.isfinite(self.collision_penalty) and self.collision_penalty <= 0.0):
            raise ValueError(f"collision_penalty: must be <= 0, got {self.collision_penalty}")


class GraspTask(TaskDef):
    kind = "grasp"
    scenes = ("object",)
    Settings = GraspSettings
    rewards = GRASP_REWARDS

    def check(self) -> str | None:
        if self.settings.reward not in self.rewards:
            return f"reward: {self.settings.reward!r} is not one of {', '.join(self.rewards)}"
        if self.topo.agents[self.topo.root].has_dof:
            return "the grasp agent (the robot's root) must be compound: it holds the object, not a joint"
        return None

    def goal(self, epoch: int, steps: int) -> tuple[Vec2, list[Vec2]]:
        obj = self.scene.object
        assert obj is not None
        return obj.center, []  # unused: each fingertip's goal is the grasp agent's

    def reach(self, agent: str) -> float:
        """A finger's length: the ranges of one finger (d in [0, L], g in [-2L, 2L])."""
        topo, longest = self.topo, 0.0
        for leaf in topo.end_effectors:
            total, a = 0.0, leaf
            path = []
            while a is not None:
                path.append(a)
                a = topo.agents[a].parent
            for b in reversed(path):  # root first, the order the lengths are summed in
                total += topo.agents[b].link_length
            longest = max(longest, total)
        return longest

    def state_variables(self, agent: str) -> tuple[StateVariable, ...]:
        return (G_PERP,) + (COLLIDED,) * self.settings.collision_state

    def agent(self, agent: str, observation: Observation | None) -> AgentTask:
        if agent == self.topo.root:
            return GraspRoot(self)
        return GraspFinger(self.settings)


class GraspRoot(AgentTask):
    """The grasp agent: per finger its goal (its contact goal, or grasp point), reward and context."""

    def __init__(self, task: GraspTask) -> None:
        obj, topo = task.scene.object, task.topo
        assert obj is not None
        self.reward_of = GraspReward(
            task.settings.reward,
            obj.grasp,
            obj.center,
            obj.half_extents,
            kn=obj.kn,
            kt=obj.kt,
            fine_action=task.settings.fine_action,
            detour=task.settings.detour,
        )
        self.finger_of = {c: topo.subtree_leaves(c)[0] for c in topo.agents[topo.root].children}

    def start_epoch(self) -> None:
        self.reward_of.reset()

    def head(self, obs: Task) -> Head:
        rewards, context = self.reward_of.step(obs.tips, obs.sense)
        children = {}
        for child, leaf in self.finger_of.items():
            r = None if rewards is None else rewards[leaf]
            children[child] = (self.reward_of.goals[leaf], r, context[leaf])
        return Head(obs.goal, None, children)


class GraspFinger(AgentTask):
    def __init__(self, settings: GraspSettings) -> None:
        self.fine_action = settings.fine_action
        self.c = settings

    def state(self, view: StepView) -> list[float]:
        g = goal_along_motion(view.frame, view.tip, view.goal)
        return [g] + [collided(view)] * self.c.collision_state

    def reward(self, view: StepView, reward: float | None) -> float | None:
        return penalised(view, reward, self.c.collision_penalty)

    def avoid(self, view: StepView) -> list[int]:
        """The tabu: a refused move left the state unchanged, so a frozen table would choose it again."""
        return tabu(view, self.c.collision_tabu)

    def scale(self, view: StepView) -> float:
        """Fine steps while the grasp agent says "fine" (within D_fine of the contact goal)."""
        return self.fine_action if view.sense.get("fine", 0.0) > 0.5 else 1.0


TASK = GraspTask
