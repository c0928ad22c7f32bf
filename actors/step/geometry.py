"""What an agent composes of the robot's geometry at each step, by the robot's kind: its frame on the base its
parent sends, its children's base, a leaf's tip, and its state S_i. The agent never asks which kind it has.

Planar (the paper's, actors/learning/state.py): frames (x, y, heading), S_i = <q, theta, d, g1, g2, g3>.
Spatial (a robot from URDF, protocol/frames.py): 7-float frames, S_i the joint's rotation plane (state.plane_state) or
its turn (frames.best_turn), as its learner's state kind says.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from kinswarm.actors.learning import state
from kinswarm.actors.tasks.base import centroid
from kinswarm.protocol import frames
from kinswarm.protocol.topology import AgentSpec, Topology

Coords = tuple[float, ...]


class Planar:
    """A planar robot: the paper's frames and state, as they always were."""

    def joint_frame(self, spec: AgentSpec, base: Sequence[float], q: float) -> Coords:
        return state.joint_frame(base, spec.offset, q)

    def link_end(self, spec: AgentSpec, frame: Coords) -> Coords:
        return state.link_end(frame, spec.link_length)

    def tip(self, spec: AgentSpec, end: Coords) -> Coords:
        return end  # a leaf's link end is its end effector

    def centroid(self, tips: list[Coords]) -> Coords:
        return centroid(tips)

    def state(
        self, spec: AgentSpec, frame: Coords, q: float, tip: Coords, goal: Coords, unsigned_g3: bool, kind: str
    ) -> np.ndarray:
        return state.agent_state(frame, q, tip, goal, unsigned_g3)

    def extras(self, names: Sequence[str], frame: Coords, tip: Coords, goal: Coords) -> dict[str, float]:
        return state.own_extras(names, frame, tip, goal)


class Spatial:
    """A robot from URDF: each agent composes its own link frame; its children's base is that frame."""

    def joint_frame(self, spec: AgentSpec, base: Sequence[float], q: float) -> Coords:
        return frames.joint_frame(spec, base, q)

    def link_end(self, spec: AgentSpec, frame: Coords) -> Coords:
        return frame  # a child's origin is given on its parent's link frame

    def tip(self, spec: AgentSpec, end: Coords) -> Coords:
        return frames.tool_frame(spec, end)

    def centroid(self, tips: list[Coords]) -> Coords:
        """One end effector: its whole frame (a pose task needs its orientation); several: their mean position."""
        if len(tips) == 1:
            return tuple(tips[0])
        if not tips:
            return (float("nan"),) * 3
        n = len(tips)
        return tuple(sum(t[i] for t in tips) / n for i in range(3))

    def state(
        self, spec: AgentSpec, frame: Coords, q: float, tip: Coords, goal: Coords, unsigned_g3: bool, kind: str
    ) -> np.ndarray:
        axis = frames.joint_axis(spec, frame)
        if kind == "turn":
            lo, hi = spec.limits
            return np.array([frames.best_turn(axis, frame, tip, goal, (lo - q, hi - q), spec.prismatic)])
        return state.plane_state(q, frame[:3], axis, tip[:3], goal[:3], spec.prismatic)

    def extras(self, names: Sequence[str], frame: Coords, tip: Coords, goal: Coords) -> dict[str, float]:
        return {}  # g_perp is a variable of the plane state itself


def geometry_of(topo: Topology) -> Planar | Spatial:
    return Spatial() if topo.spatial else Planar()
