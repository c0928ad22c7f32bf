"""The paper's model-based baseline (section 5.1): resolved-rate control with the Jacobian pseudo-inverse.

It knows the kinematic model (sim.kinematics; a spatial robot's protocol/frames.py) that the learning agents never
see, and moves with the same action size as they do (at most 1 degree per joint per step) so step counts are
comparable.

A planar robot's goal is a point (x, y). A spatial robot's (from URDF) is a point (x, y, z), or a pose (x, y, z, qx,
qy, qz, qw): the tool's position and orientation, the orientation's error (rad) weighed as frames.POSE_WEIGHT metres
per radian wherever it meets the position's. Near a pose goal every law moves as finely as the agents do
(move_size).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

import numpy as np
from kinswarm.protocol import frames
from kinswarm.protocol.topology import Topology
from kinswarm.sim import kinematics

Goal = Sequence[float]  # planar (x, y); spatial (x, y, z) or (x, y, z, qx, qy, qz, qw)


def _spatial_error(topo: Topology, angles: Mapping[str, float], goal: Goal) -> tuple[np.ndarray, np.ndarray]:
    """A spatial robot's stacked error (3 rows a leaf for a point goal; 6 for a pose, the orientation's error
    weighed by POSE_WEIGHT) and the matching rows of its leaves' Jacobians."""
    pose = len(goal) == 7
    rows = 6 if pose else 3
    weight = np.array([1.0, 1.0, 1.0, frames.POSE_WEIGHT, frames.POSE_WEIGHT, frames.POSE_WEIGHT])[:rows]
    errs, jacs = [], []
    for leaf, tip in frames.tips(topo, angles).items():
        err = [goal[0] - tip[0], goal[1] - tip[1], goal[2] - tip[2]]
        if pose:
            err += frames.orientation_error(tip[3:7], goal[3:7])
        errs.append(weight * np.array(err))
        jacs.append(weight[:, None] * np.array(frames.jacobian(topo, angles, leaf))[:rows])
    return np.concatenate(errs), np.vstack(jacs)


def pinv_increments(
    topo: Topology,
    angles: Mapping[str, float],
    goal_xy: Goal,
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

    A spatial robot: the 3 position rows of each leaf for a point goal; for a pose, 6 rows, the orientation's
    (frames.orientation_error) and its Jacobian rows weighed by POSE_WEIGHT (a least-squares compromise in metres).
    """
    if max_step <= 0:
        raise ValueError(f"max_step must be > 0, got {max_step}")
    zero = dict.fromkeys(topo.dof_agents, 0.0)
    if topo.spatial:
        err, jac = _spatial_error(topo, angles, goal_xy)
        if not topo.dof_agents or float(np.linalg.norm(err)) <= 1e-9:
            return zero
    else:
        tip = kinematics.tips(topo, angles)
        gx, gy = goal_xy
        err = np.array([c for leaf in topo.end_effectors for c in (gx - tip[leaf][0], gy - tip[leaf][1])])
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
    goal_xy: Goal,
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

    A spatial robot: the squared 3D distance; for a pose goal plus (POSE_WEIGHT x the angle to its orientation)².
    """
    if max_step <= 0:
        raise ValueError(f"max_step must be > 0, got {max_step}")
    if topo.spatial:

        def cost(q: Mapping[str, float]) -> float:
            return sum(_pose_distance2(tip, goal_xy) for tip in frames.tips(topo, q).values())

    else:
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
    goal_xy: Goal,
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

    A spatial robot (spatial_rule): a revolute joint's direction of motion is a x r (a its world axis, r its
    joint -> tip), |a x r| = |r_perp| the lever; a prismatic joint's is a, a move's arc max_step.
    """
    if max_step <= 0:
        raise ValueError(f"max_step must be > 0, got {max_step}")
    if topo.spatial:
        return _spatial_rule(topo, angles, goal_xy, max_step, deadband)
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


def _spatial_rule(
    topo: Topology, angles: Mapping[str, float], goal: Goal, max_step: float, deadband: float
) -> dict[str, float]:
    """The rule on a spatial robot: each revolute joint (world axis a at p, tip e, goal g; r = e - p, w = g - e)
    moves one step along sign(g_perp), g_perp = w . (a x r) / |r_perp|, when |g_perp| > deadband x |r_perp| x
    max_step, else keeps. A pose goal adds POSE_WEIGHT x (the tool's orientation error . a) to the signal and
    POSE_WEIGHT x max_step to the arc. A prismatic joint: w . a against max_step."""
    pose = len(goal) == 7
    n = len(topo.dof_agents)
    along = np.zeros(n)
    arc = np.zeros(n)
    prismatic = np.array([topo.agents[a].prismatic for a in topo.dof_agents], dtype=bool)
    for leaf, tip in frames.tips(topo, angles).items():
        jac = np.array(frames.jacobian(topo, angles, leaf))  # revolute: (a x r, a); prismatic: (a, 0); 0 off path
        w = np.array([goal[0] - tip[0], goal[1] - tip[1], goal[2] - tip[2]])
        lever = np.linalg.norm(jac[:3], axis=0)  # |a x r| = |r_perp|; a prismatic joint's: |a| = 1
        on_path = np.linalg.norm(jac, axis=0) > 0
        moved = lever > 0
        along[moved] += (w @ jac[:3])[moved] / lever[moved]
        leaf_arc = np.where(prismatic, max_step, lever * max_step)
        if pose:
            turn = np.array(frames.orientation_error(tip[3:7], goal[3:7]))
            along += frames.POSE_WEIGHT * (turn @ jac[3:])  # a prismatic joint's rotation rows are 0
            leaf_arc = leaf_arc + np.where(prismatic, 0.0, frames.POSE_WEIGHT * max_step)
        arc = np.maximum(arc, np.where(on_path, leaf_arc, 0.0))
    return {
        a: float(math.copysign(max_step, along[i])) if abs(along[i]) > deadband * arc[i] and arc[i] > 0 else 0.0
        for i, a in enumerate(topo.dof_agents)
    }


def turn_increments(
    topo: Topology,
    angles: Mapping[str, float],
    goal: Goal,
    *,
    max_step: float = math.radians(1),
) -> dict[str, float]:
    """The rule on the turn state, no learning: each joint one step toward its own best value within its limits
    (sign(g_q), frames.best_turn: the others held, where D_goal is least), when that lies more than a step away,
    else keeps. What a joint of a swarm with state "turn" knows; a spatial robot with one end effector."""
    if max_step <= 0:
        raise ValueError(f"max_step must be > 0, got {max_step}")
    if not topo.spatial or len(topo.end_effectors) != 1:
        raise ValueError("the turn rule moves the one end effector of a robot from URDF")
    links = frames.link_frames(topo, angles)
    (tip,) = frames.tips(topo, angles).values()
    out = {}
    for a in topo.dof_agents:
        spec = topo.agents[a]
        lo, hi = spec.limits
        axis = frames.joint_axis(spec, links[a])
        t = frames.best_turn(axis, links[a], tip, goal, (lo - angles[a], hi - angles[a]), spec.prismatic)
        out[a] = math.copysign(max_step, t) if abs(t) > max_step else 0.0
    return out


def move_size(topo: Topology, angles: Mapping[str, float], goal: Goal, max_step: float) -> float:
    """The agents' move here: max_step, or its fine share near a pose goal (frames.move_share), so that a law is
    compared with the agents at the same move sizes."""
    if not topo.spatial or len(goal) != 7:
        return max_step
    return max_step * min(frames.move_share(tip, goal) for tip in frames.tips(topo, angles).values())


def _pose_distance2(tip: Sequence[float], goal: Goal) -> float:
    """A spatial tip's squared distance to a goal: 3D; a pose's D_goal² (frames.pose_distance)."""
    d = math.dist(tip[:3], goal[:3])
    if len(goal) == 7:
        d = frames.pose_distance(d, frames.angle_between(tip[3:7], goal[3:7]))
    return d * d


def reached(topo: Topology, angles: Mapping[str, float], goal: Goal, tol: float) -> bool:
    """Every tip within `tol` of the goal: planar, in the plane; spatial, in 3D, and for a pose goal its D_goal
    (frames.pose_distance, the reach3d task's)."""
    if not topo.spatial:
        return all(math.hypot(goal[0] - x, goal[1] - y) <= tol for x, y, _ in kinematics.tips(topo, angles).values())
    for tip in frames.tips(topo, angles).values():
        d = math.dist(tip[:3], goal[:3])
        if len(goal) == 7:
            d = frames.pose_distance(d, frames.angle_between(tip[3:7], goal[3:7]))
        if d > tol:
            return False
    return True


def run_baseline(
    topo: Topology,
    goal_xy: Goal,
    *,
    angles: Mapping[str, float] | None = None,
    tol: float = 0.01,
    max_steps: int = 10_000,
    max_step: float = math.radians(1),
    gain: float = 1.0,
    law: str = "pinv",
) -> tuple[int | None, dict[str, float]]:
    """Iterate a law's increments (default pinv_increments) on the model (clipping to limits) until every tip is
    within `tol` of the goal (`reached`).

    Returns (steps taken, or None if not reached within max_steps; final angles).
    """
    step_of = {
        "pinv": lambda q: pinv_increments(topo, q, goal_xy, max_step=move_size(topo, q, goal_xy, max_step), gain=gain),
        "greedy": lambda q: greedy_increments(topo, q, goal_xy, max_step=move_size(topo, q, goal_xy, max_step)),
        "rule": lambda q: rule_increments(topo, q, goal_xy, max_step=move_size(topo, q, goal_xy, max_step)),
        "turn": lambda q: turn_increments(topo, q, goal_xy, max_step=move_size(topo, q, goal_xy, max_step)),
    }[law]
    q = dict(topo.initial_angles() if angles is None else angles)
    for step in range(max_steps + 1):
        if reached(topo, q, goal_xy, tol):
            return step, q
        if step == max_steps:
            break
        for a, d in step_of(q).items():
            lo, hi = topo.agents[a].limits
            q[a] = min(max(q[a] + d, lo), hi)
    return None, q
