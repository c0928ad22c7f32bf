"""Planar agent state (paper §3.3): frames and S_i = <q_i, theta_i, d_i, g1, g2, g3>.

A frame is (x, y, heading) in the world frame.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

Frame = tuple[float, float, float]


def joint_frame(base: Sequence[float], offset: Sequence[float], q: float) -> Frame:
    """Frame of a joint mounted on base: position = base + offset_xy rotated by base heading;
    heading = base_h + offset_h + q."""
    bx, by, bh = base
    ox, oy, oh = offset
    c, s = math.cos(bh), math.sin(bh)
    return (bx + c * ox - s * oy, by + s * ox + c * oy, bh + oh + q)


def link_end(frame: Sequence[float], link_length: float) -> Frame:
    """End of a link of length l along the frame's heading; this is each child's base."""
    x, y, h = frame
    return (x + link_length * math.cos(h), y + link_length * math.sin(h), h)


def agent_state(
    frame: Sequence[float], q: float, tip_xy: Sequence[float], goal_xy: Sequence[float], g3_unsigned: bool = False
) -> np.ndarray:
    """S_i = <q_i, theta_i, d_i, g1, g2, g3> of the agent whose joint frame is frame.

    (d_i, theta_i): polar coordinates of the end effector (tip) in the agent frame (origin at the
    joint, x along its heading). (g1, g2): goal - tip in the agent frame. g3: bearing of the goal seen
    from the end effector, relative to the joint -> end effector direction (atan2(cross, dot); 0 when
    either vector is degenerate); with g3_unsigned its size |g3| (LearnerSettings.g3). When several end
    effectors lie below the agent, pass their centroid as tip_xy.
    """
    x, y, h = frame
    c, s = math.cos(h), math.sin(h)
    rx, ry = tip_xy[0] - x, tip_xy[1] - y  # joint -> tip, world frame
    wx, wy = goal_xy[0] - tip_xy[0], goal_xy[1] - tip_xy[1]  # tip -> goal, world frame
    lx, ly = c * rx + s * ry, -s * rx + c * ry  # rotate by -h into the agent frame
    d = math.hypot(lx, ly)
    theta = math.atan2(ly, lx) if d > 0.0 else 0.0
    g1, g2 = c * wx + s * wy, -s * wx + c * wy
    cross, dot = rx * wy - ry * wx, rx * wx + ry * wy
    g3 = math.atan2(cross, dot) if (rx or ry) and (wx or wy) else 0.0
    if g3_unsigned:
        g3 = abs(g3)
    return np.array([q, theta, d, g1, g2, g3])


def goal_along_motion(frame: Sequence[float], tip: Sequence[float], goal: Sequence[float]) -> float:
    """g_perp: the component of goal - tip along the direction this agent's joint moves the tip (z x
    (tip - joint), unit): > 0 means increasing the joint angle brings the tip towards the goal."""
    rx, ry = tip[0] - frame[0], tip[1] - frame[1]
    r = math.hypot(rx, ry)
    if r == 0.0:
        return 0.0
    return ((goal[0] - tip[0]) * -ry + (goal[1] - tip[1]) * rx) / r


#: the extra state variables a planar agent computes from its own geometry (own_extras)
OWN_EXTRAS = ("g_perp",)


def own_extras(
    names: Sequence[str], frame: Sequence[float], tip: Sequence[float], goal: Sequence[float]
) -> dict[str, float]:
    """The extra state variables among `names` that an agent computes from its own geometry: "g_perp"
    (goal_along_motion). The others come from its task or its readings."""
    return {"g_perp": goal_along_motion(frame, tip, goal)} if "g_perp" in names else {}


def plane_state(
    q: float,
    joint: Sequence[float],
    axis: Sequence[float],
    tip: Sequence[float],
    goal: Sequence[float],
    prismatic: bool = False,
) -> np.ndarray:
    """The rotation-plane state of a spatial robot's joint: S_i = <q_i, d_i, g_perp, g_axial, g_radial, |w|>.

    With the joint at p turning about the unit world axis a, the tip e and the goal g: r = e - p, w = g - e,
    r_perp = r - (r.a) a (the tip's lever about the axis). d = |r_perp|; g_perp = w . (a x r) / |r_perp|, the goal
    along the direction this joint moves the tip (> 0: increasing q brings the tip towards it); g_axial = w . a
    (along the axis, which this joint cannot change); g_radial = w . r_perp / |r_perp| (towards or away from the
    axis); |w|, how far the goal is. In the plane (a = z everywhere) d and g_perp are the planar d and g_perp; a
    joint whose axis passes through the tip (d = 0) has g_perp = g_radial = 0. A prismatic joint moves the tip
    along a: its g_perp is w . a, its d 0, its g_axial and g_radial the goal across that motion.
    """
    ax, ay, az = axis
    wx, wy, wz = goal[0] - tip[0], goal[1] - tip[1], goal[2] - tip[2]
    w_len = math.sqrt(wx * wx + wy * wy + wz * wz)
    along = wx * ax + wy * ay + wz * az
    if prismatic:
        across = math.sqrt(max(w_len * w_len - along * along, 0.0))
        return np.array([q, 0.0, along, 0.0, across, w_len])
    rx, ry, rz = tip[0] - joint[0], tip[1] - joint[1], tip[2] - joint[2]
    ra = rx * ax + ry * ay + rz * az
    px, py, pz = rx - ra * ax, ry - ra * ay, rz - ra * az  # r_perp
    d = math.sqrt(px * px + py * py + pz * pz)
    if d == 0.0:
        return np.array([q, 0.0, 0.0, along, 0.0, w_len])
    mx, my, mz = ay * rz - az * ry, az * rx - ax * rz, ax * ry - ay * rx  # a x r: the tip's motion per radian
    g_perp = (wx * mx + wy * my + wz * mz) / d
    g_radial = (wx * px + wy * py + wz * pz) / d
    return np.array([q, d, g_perp, along, g_radial, w_len])
