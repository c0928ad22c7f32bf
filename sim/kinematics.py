"""Closed-form planar kinematics of a Topology: the model the baseline and the tests check PyBullet against.

Frame convention (the agents compute the same thing on their side): for agent i with incoming base frame
(bx, by, bh) -- topology.base for the root, the parent's link end otherwise --
    joint position = (bx, by) + R(bh) (offset_x, offset_y)
    joint heading  h_i = bh + offset_h + q_i          (q_i = 0 for compound agents)
    link end       = joint position + link_length (cos h_i, sin h_i), heading h_i
A leaf's link end is an end-effector tip.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from kinswarm.protocol.topology import Topology

Pose = tuple[float, float, float]


def _walk(topo: Topology, angles: Mapping[str, float]) -> tuple[dict[str, Pose], dict[str, Pose]]:
    """Joint frames and link ends of every agent, parents first; missing DOF angles default to 0."""
    joints: dict[str, Pose] = {}
    ends: dict[str, Pose] = {}
    for aid in topo.order:
        a = topo.agents[aid]
        bx, by, bh = topo.base if a.parent is None else ends[a.parent]
        ox, oy, oh = a.offset
        c, s = math.cos(bh), math.sin(bh)
        jx, jy = bx + c * ox - s * oy, by + s * ox + c * oy
        h = bh + oh + (0.0 if a.compound else float(angles.get(aid, 0.0)))
        joints[aid] = (jx, jy, h)
        ends[aid] = (jx + a.link_length * math.cos(h), jy + a.link_length * math.sin(h), h)
    return joints, ends


def frames(topo: Topology, angles: Mapping[str, float]) -> dict[str, Pose]:
    """Joint frame (x, y, heading) of every agent, compound agents included."""
    return _walk(topo, angles)[0]


def link_ends(topo: Topology, angles: Mapping[str, float]) -> dict[str, Pose]:
    """Link-end frame (x, y, heading) of every agent: the base frame of its children."""
    return _walk(topo, angles)[1]


def tips(topo: Topology, angles: Mapping[str, float]) -> dict[str, Pose]:
    """End-effector tip pose of every leaf."""
    ends = _walk(topo, angles)[1]
    return {leaf: ends[leaf] for leaf in topo.end_effectors}


def path_to(topo: Topology, aid: str) -> list[str]:
    """Agents from the root down to `aid` (inclusive)."""
    path = [aid]
    while (p := topo.agents[path[-1]].parent) is not None:
        path.append(p)
    return path[::-1]


def jacobian(topo: Topology, angles: Mapping[str, float], leaf_id: str) -> np.ndarray:
    """d(tip xy)/dq, shape (2, n_dof), columns in `topo.dof_agents` order; 0 off the leaf's path.

    A revolute joint j moves everything beyond it on a circle about its own position, so the column is
    z x (tip - joint_j) = (-(ty - jy), tx - jx); the joint's position does not depend on q_j.
    """
    joints, ends = _walk(topo, angles)
    tx, ty, _ = ends[leaf_id]
    on_path = set(path_to(topo, leaf_id))
    jac = np.zeros((2, len(topo.dof_agents)))
    for col, aid in enumerate(topo.dof_agents):
        if aid in on_path:
            jx, jy, _ = joints[aid]
            jac[0, col] = -(ty - jy)
            jac[1, col] = tx - jx
    return jac


class ModelWorld:
    """A planar robot's world in closed form, with `sim/world.World`'s interface (reset, joint_positions,
    apply_increments, tip_poses, close): the robot without PyBullet, for the benchmarks' in-process floor. Its tips
    are double precision where PyBullet's link states are single, so a run on it takes other paths than on the real
    world after a few steps: a floor for speed, not a stand-in for results."""

    def __init__(self, topo: Topology) -> None:
        if topo.spatial:
            raise ValueError(f"{topo.name}: the model world is planar; a robot from URDF needs PyBullet's")
        self.topo = topo
        self._limits = {a: topo.agents[a].limits for a in topo.dof_agents}
        self._q = topo.initial_angles()

    def reset(self, angles: Mapping[str, float] | None = None) -> None:
        q = self.topo.initial_angles() if angles is None else dict(angles)
        for a, v in q.items():
            lo, hi = self._limits[a]
            if not lo <= v <= hi:
                raise ValueError(f"reset angle for {a!r}: {v} outside limits [{lo}, {hi}]")
        self._q = {a: float(q[a]) for a in self._limits}

    def joint_positions(self) -> dict[str, float]:
        return dict(self._q)

    def apply_increments(self, deltas: Mapping[str, float]) -> dict[str, float]:
        applied = dict.fromkeys(self._limits, 0.0)
        for a, d in deltas.items():
            lo, hi = self._limits[a]
            new = min(max(self._q[a] + d, lo), hi)
            applied[a] = new - self._q[a]
            self._q[a] = new
        return applied

    def tip_poses(self) -> dict[str, Pose]:
        return tips(self.topo, self._q)

    def close(self) -> None:
        pass
