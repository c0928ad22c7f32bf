"""What a seeded reset draws, so that seeds give different episodes (Gymnasium's convention: `reset(seed)` draws the
episode) and a vector env's copies, seeded `seed + i`, step different episodes.

- The goal of a reach task (reach, reach3d): the end-effector pose of joint angles drawn uniformly within the joint
  limits, read from the robot's own PyBullet world. The task's goal region is where its tip can go: a point drawn
  this way is reachable by construction, on any robot (planar, branching, URDF), and a pose goal is one the arm can
  take. A spatial arm's goal lies above its base (poses are drawn again until it does): not in the floor it stands
  on. Other tasks keep theirs: grasp's goal is its object, a corridor's lies behind walls a random pose may cross,
  a track's moves.
- The start, where the task starts each epoch from a random pose (`start_pose = "random"`): every joint uniformly
  within its limits.
"""

from __future__ import annotations

import math

import numpy as np
from kinswarm.actors.tasks.base import TaskDef
from kinswarm.protocol.topology import Topology
from kinswarm.sim.world import World

GOAL_KINDS = ("reach", "reach3d")  # the tasks whose goal a seed draws
ABOVE_TRIES = 100  # a spatial arm's draws until its tip is above the base: about half of them are


def draws_goal(task: TaskDef) -> bool:
    return task.kind in GOAL_KINDS


def draws_start(task: TaskDef) -> bool:
    return getattr(task.settings, "start_pose", "home") == "random"


def draw_pose(topo: Topology, rng: np.random.Generator) -> dict[str, float]:
    """Every DOF joint uniformly within its limits (an unlimited one within a turn)."""
    out = {}
    for a in topo.dof_agents:
        lo, hi = topo.agents[a].limits
        lo, hi = (lo, hi) if math.isfinite(lo) and math.isfinite(hi) else (-math.pi, math.pi)
        out[a] = float(rng.uniform(lo, hi))
    return out


def draw_goal(world: World, topo: Topology, rng: np.random.Generator, length: int) -> tuple[float, ...]:
    """A goal the robot reaches: where the end effectors are at a drawn pose (their centroid for a branching robot),
    its first `length` numbers (a planar point; a spatial point, or point and quaternion). The world is left at that
    pose: the episode's start sets it again."""
    for _ in range(ABOVE_TRIES):
        world.reset(draw_pose(topo, rng))
        tips = list(world.tip_poses().values())
        if not topo.spatial or tips[0][2] >= topo.base[2]:
            break
    if length == 2:  # a planar reach: the centroid of the tips, as the root measures it (reach.py)
        return (float(np.mean([t[0] for t in tips])), float(np.mean([t[1] for t in tips])))
    return tuple(float(v) for v in tips[0][:length])  # reach3d: one end effector
