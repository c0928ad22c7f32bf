"""A move the scene refused (a wall, the grasped object): the joint's own reading "collided" of the step before, as
a state variable, a penalty on its reward and a tabu on its next choice. The corridor and the grasp share them: a
refused move leaves the state unchanged, so a table that chose it once would choose it again."""

from __future__ import annotations

from kinswarm.actors.learning.observation import StateVariable

from .base import StepView

#: + "collided": the joint's own move of the step before was refused (2 sets over [0, 1])
COLLIDED = StateVariable("collided", 2, (0.0, 1.0))


def collided(view: StepView) -> float:
    """1.0 when my own move of the step before was refused, else 0.0 (the reading as the state takes it)."""
    return view.sense.get("collided", 0.0)


def refused(view: StepView) -> bool:
    return collided(view) > 0.5


def penalised(view: StepView, reward: float | None, penalty: float) -> float | None:
    """The reward with `penalty` (<= 0) added when my own move was refused."""
    return reward + penalty if reward is not None and refused(view) else reward


def tabu(view: StepView, on: bool) -> list[int]:
    """The move just refused, left out of the next choice (when `on`)."""
    return [view.last_action] if on and refused(view) and view.last_action is not None else []
