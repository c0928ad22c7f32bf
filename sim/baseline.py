"""The paper's model-based baseline (section 5.1): resolved-rate control with the Jacobian pseudo-inverse.

It knows the kinematic model (sim.kinematics) that the learning agents never see, and moves with the same
action size as they do (at most 1 degree per joint per step) so step counts are comparable.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from kinswarm.protocol.topology import Topology
from kinswarm.sim import kinematics


def pinv_increments(
    topo: Topology,
    angles: Mapping[str, float],
    goal_xy: tuple[float, float],
    *,
    max_step: float = math.radians(1),
    gain: float = 1.0,
) -> dict[str, float]:
    """One resolved-rate step: dq = J^+ gain (goal - tip), scaled uniformly so max |dq_i| <= max_step.

    Several end effectors: every leaf is driven towards the same goal, by stacking the leaves' Jacobians
    (2m x n) and errors (2m) into one least-squares problem. That is the reaching task of a tree whose
    leaves all aim at one point; joints shared by several leaves get the LS compromise. The uniform scaling
    keeps the direction of the pseudo-inverse step. Joint limits are not modelled here: World clips.
    Returns an increment (rad) for every DOF agent; all zeros once the stacked error norm is <= 1e-9.
    """
    if max_step <= 0:
        raise ValueError(f"max_step must be > 0, got {max_step}")
    tip = kinematics.tips(topo, angles)
    gx, gy = goal_xy
    err = np.array([c for leaf in topo.end_effectors for c in (gx - tip[leaf][0], gy - tip[leaf][1])])
    zero = dict.fromkeys(topo.dof_agents, 0.0)
    if not topo.dof_agents or float(np.linalg.norm(err)) <= 1e-9:
        return zero
    jac = np.vstack([kinematics.jacobian(topo, angles, leaf) for leaf in topo.end_effectors])
    dq = np.linalg.pinv(jac) @ (gain * err)
    biggest = float(np.max(np.abs(dq)))
    if biggest > max_step:
        dq *= max_step / biggest
    return {a: float(v) for a, v in zip(topo.dof_agents, dq, strict=True)}


def greedy_increments(
    topo: Topology,
    angles: Mapping[str, float],
    goal_xy: tuple[float, float],
    *,
    max_step: float = math.radians(1),
) -> dict[str, float]:
    """Each joint greedy on its own: each DOF agent takes the one of -max_step, 0, +max_step that, with
    every other joint held, leaves the squared distance of its tips to the goal smallest (hold unless a move
    is strictly better; limits respected); then all move at once.

    A reference, not a learner: it knows the model, but like an agent it decides from its own effect on the
    tip alone, greedily in the distance (what the shaped reward pays for). It can fold into a configuration
    where no single joint's move helps (a local minimum of the distance); the pseudo-inverse moves all joints
    together, though it too can end folded against a joint limit.
    """
    if max_step <= 0:
        raise ValueError(f"max_step must be > 0, got {max_step}")
    gx, gy = goal_xy

    def cost(q: Mapping[str, float]) -> float:
        return sum((gx - x) ** 2 + (gy - y) ** 2 for x, y, _ in kinematics.tips(topo, q).values())

    now = cost(angles)
    out = {}
    for a in topo.dof_agents:
        lo, hi = topo.agents[a].limits
        best, move = now, 0.0
        for d in (-max_step, max_step):
            qa = min(max(angles[a] + d, lo), hi)
            if qa != angles[a] and (c := cost({**angles, a: qa})) < best:
                best, move = c, qa - angles[a]
        out[a] = move
    return out


RULE_DEADBAND = 1.0  # in moves: keep while the goal is within one move's arc of the tip along my motion


def rule_increments(
    topo: Topology,
    angles: Mapping[str, float],
    goal_xy: tuple[float, float],
    *,
    max_step: float = math.radians(1),
    deadband: float = RULE_DEADBAND,
) -> dict[str, float]:
    """The simplest hand-written rule on an agent's own state, no learning: each joint moves one step along
    sign(g_perp), g_perp being the goal's component along the direction its own joint moves the tip, when
    |g_perp| > deadband · |joint → tip| · max_step (a move's arc at the tip), else keeps.

    It uses what an agent's state already holds (its joint's position, from the encoder readings and link
    lengths, and the tip), no Jacobian, no model of the other joints. The control every learning result is
    measured against: what learning adds beyond it. Several end effectors: the g_perp of the tips the joint
    moves are summed, against the largest arc.
    """
    if max_step <= 0:
        raise ValueError(f"max_step must be > 0, got {max_step}")
    gx, gy = goal_xy
    tip = kinematics.tips(topo, angles)
    along = np.zeros(len(topo.dof_agents))
    arc = np.zeros(len(topo.dof_agents))
    for leaf in topo.end_effectors:
        motion = kinematics.jacobian(topo, angles, leaf)  # column a: z x (tip - joint a), |.| = |joint a -> tip|
        lever = np.hypot(motion[0], motion[1])
        w = np.array([gx - tip[leaf][0], gy - tip[leaf][1]])
        moved = lever > 0
        along[moved] += (w @ motion)[moved] / lever[moved]
        arc = np.maximum(arc, lever * max_step)
    return {
        a: float(math.copysign(max_step, along[i])) if abs(along[i]) > deadband * arc[i] and arc[i] > 0 else 0.0
        for i, a in enumerate(topo.dof_agents)
    }


def run_baseline(
    topo: Topology,
    goal_xy: tuple[float, float],
    *,
    angles: Mapping[str, float] | None = None,
    tol: float = 0.01,
    max_steps: int = 10_000,
    max_step: float = math.radians(1),
    gain: float = 1.0,
) -> tuple[int | None, dict[str, float]]:
    """Iterate pinv_increments on the model (clipping to limits) until every tip is within `tol` of the goal.

    Returns (steps taken, or None if not reached within max_steps; final angles).
    """
    q = dict(topo.initial_angles() if angles is None else angles)
    for step in range(max_steps + 1):
        tip = kinematics.tips(topo, q)
        if all(math.hypot(goal_xy[0] - x, goal_xy[1] - y) <= tol for x, y, _ in tip.values()):
            return step, q
        if step == max_steps:
            break
        for a, d in pinv_increments(topo, q, goal_xy, max_step=max_step, gain=gain).items():
            lo, hi = topo.agents[a].limits
            q[a] = min(max(q[a] + d, lo), hi)
    return None, q
