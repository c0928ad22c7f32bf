"""What an epoch starts with and when its learners checkpoint: the same for the supervisor's epoch loop
(actors/supervisor/epochs.py), the inprocess loop and the env faces."""

from __future__ import annotations

from typing import TYPE_CHECKING

from kinswarm.protocol.messages import EpochStart

if TYPE_CHECKING:
    from kinswarm.actors.files.config import RunConfig
    from kinswarm.actors.tasks.base import TaskDef


def epoch_start(cfg: RunConfig, task: TaskDef, epoch: int) -> EpochStart:
    """The epoch's start: its goal, and each step's when the task's goal moves."""
    if cfg.fleet > 1 and cfg.fleet_goals == "spread":  # robot b: the task's epoch e*B + b
        goals = [task.goal(epoch * cfg.fleet + b, cfg.steps)[0] for b in range(cfg.fleet)]  # not moving (runfile)
        starts = [task.start(epoch * cfg.fleet + b) for b in range(cfg.fleet)]
        return EpochStart(epoch=epoch, steps=cfg.steps, goal=goals[0], start=starts[0], goals=goals, starts=starts)
    goal, path = task.goal(epoch, cfg.steps)
    return EpochStart(epoch=epoch, steps=cfg.steps, goal=goal, path=path, start=task.start(epoch))


def checkpoint_due(cfg: RunConfig, epoch: int) -> bool:
    """The learners checkpoint after this epoch: the last, and every `checkpoint_every`."""
    every = cfg.checkpoint_every
    return cfg.learn and (epoch == cfg.epochs - 1 or bool(every and (epoch + 1) % every == 0))
