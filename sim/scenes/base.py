"""The scene interface: what the simulator actor asks of what surrounds the robot, at fixed points of the step.

  reset()           an epoch begins (the world is at its start pose, or where the last epoch ended)
  move(deltas)      the step's increments into the world, as the scene lets them happen -> the increments applied
  agent_sense(a)    agent a's own readings for its Obs (messages.Readings)
  task_sense()      the task observation's readings for the root (Task.sense)
  error(tips, goal) the step's error for the metrics
  traces()          the epoch's per-step series for EpochDone

The base class is free space: moves happen as asked, nothing is sensed, the error is the end effector's distance
to the goal point (the centroid of several): in the plane for a planar robot's goal (x, y), in 3D for a spatial one's
(a point, or a pose's point: its orientation is the task's business, not the metrics'). A scene is a module of this
package named by its kind (`[scene] kind`); the actor names none.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import ClassVar

from kinswarm.protocol.messages import Readings
from kinswarm.protocol.scene import SceneSpec
from kinswarm.sim.world import World

Pose = tuple[float, ...]  # a tip: planar (x, y, heading), spatial a 7-float frame


class Scene:
    #: its robots may share one PyBullet client (a fleet: actors/simulator/fleet.py): nothing of one robot's world
    #: acts on another's
    shares_world: ClassVar[bool] = True

    def __init__(self, world: World, spec: SceneSpec, action_rad: float) -> None:
        self.world, self.spec, self.action_rad = world, spec, action_rad

    def reset(self) -> None:
        pass

    def move(self, deltas: Mapping[str, float]) -> dict[str, float]:
        return self.world.apply_increments(deltas)

    def agent_sense(self, agent: str) -> Readings:
        return {}

    def task_sense(self) -> Readings:
        return {}

    def error(self, tips: Mapping[str, Pose], goal: tuple[float, ...]) -> float:
        pts = list(tips.values())
        x = sum(p[0] for p in pts) / len(pts)
        y = sum(p[1] for p in pts) / len(pts)
        if len(goal) == 2:
            return math.hypot(x - goal[0], y - goal[1])
        z = sum(p[2] for p in pts) / len(pts)
        return math.dist((x, y, z), goal[:3])

    def traces(self) -> dict[str, list[float]]:
        return {}
