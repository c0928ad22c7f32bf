"""Spatial frames of a robot from URDF: the convention the agents, the sim and the references share.

A frame is 7 floats (x, y, z, qx, qy, qz, qw): a position and a unit quaternion in PyBullet's order, in the world
frame. It travels as such on the wire (a spatial robot's `Down.base`, `Up.tips`, `Task.tips`).

Agent i's link frame, given its base frame B (the parent's link frame; the robot's base for the root):

    link_i = B ∘ origin_i ∘ motion_i(q_i)      motion: rotation by q about `axis` (revolute), or a shift of q along
                                                 it (prismatic); origin_i: the URDF joint's origin, with the fixed
                                                 joints (and joints left out of the swarm) between folded in
    tip    = link_leaf ∘ tool                   a leaf's end effector (its tool frame)

Each agent composes only its own step (joint_frame); `link_frames` walks the whole tree for the sim and the
model-based references, which know the model the agents never see whole.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from .topology import AgentSpec, Topology

Frame = tuple[float, float, float, float, float, float, float]
Quat = tuple[float, float, float, float]
Vec = tuple[float, float, float]

IDENTITY: Frame = (0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0)
#: Metres per radian where a pose's distance meets its orientation's, D = sqrt(d² + (POSE_WEIGHT angle)²): a 10° turn
#: weighs like 4.4 cm of position. The form and the weight are what a joint stepping toward its own best angle
#: (best_turn) needs to reach unseen poses from random starts: 87 / 80 % within 5 cm and 15° (sets A / B) with this D,
#: 56 % with D = d + 0.3 angle. With d + W angle in the reward the swarm turned too little at W = 0.1 (35-38 %) and
#: reached 60-65 % at 0.3 (docs/notebook/reach3d.md).
POSE_WEIGHT = 0.25
#: best_turn's sweep: a revolute joint's own range looked at every degree
SWEEP = math.radians(1.0)
#: Near a pose goal moves are fine: within FINE_WITHIN (m of D_goal) a move is FINE_SHARE of its size. One degree of a
#: shoulder moves the tool ~1 cm; with whole moves the rule on best_turn ended in a jitter or stopped a few
#: centimetres short (69-80 % of unseen poses, set B), with quarter moves near the goal 84 % (set A: 90 %).
FINE_WITHIN = 0.1
FINE_SHARE = 0.25


def quat_mul(a: Sequence[float], b: Sequence[float]) -> Quat:
    """The Hamilton product a b (x, y, z, w order): rotate by b, then by a."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
        aw * bw - ax * bx - ay * by - az * bz,
    )


def rotate(q: Sequence[float], v: Sequence[float]) -> Vec:
    """v rotated by the unit quaternion q: v + 2 w (u x v) + 2 u x (u x v), u the vector part."""
    x, y, z, w = q
    vx, vy, vz = v
    tx, ty, tz = 2.0 * (y * vz - z * vy), 2.0 * (z * vx - x * vz), 2.0 * (x * vy - y * vx)
    return (vx + w * tx + y * tz - z * ty, vy + w * ty + z * tx - x * tz, vz + w * tz + x * ty - y * tx)


def compose(a: Sequence[float], b: Sequence[float]) -> Frame:
    """a ∘ b: the frame b, given relative to a, in a's parent frame."""
    px, py, pz = rotate(a[3:7], b[0:3])
    qx, qy, qz, qw = quat_mul(a[3:7], b[3:7])
    n = math.sqrt(qx * qx + qy * qy + qz * qz + qw * qw)  # keep it unit over long chains
    return (a[0] + px, a[1] + py, a[2] + pz, qx / n, qy / n, qz / n, qw / n)


def inverse(a: Sequence[float]) -> Frame:
    """The frame b with a ∘ b = identity."""
    qi = (-a[3], -a[4], -a[5], a[6])
    px, py, pz = rotate(qi, a[0:3])
    return (-px, -py, -pz, *qi)


def axis_angle(axis: Sequence[float], angle: float) -> Quat:
    """The rotation by `angle` (rad) about the unit vector `axis`."""
    s = math.sin(angle / 2.0)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2.0))


def rpy_quat(roll: float, pitch: float, yaw: float) -> Quat:
    """URDF's rpy (fixed axes x, y, z in that order: R = Rz(yaw) Ry(pitch) Rx(roll)) as a quaternion."""
    return quat_mul(
        axis_angle((0.0, 0.0, 1.0), yaw),
        quat_mul(axis_angle((0.0, 1.0, 0.0), pitch), axis_angle((1.0, 0.0, 0.0), roll)),
    )


def rotation_vector(q: Sequence[float]) -> Vec:
    """The rotation q as axis * angle (angle in [0, pi]): how far and about what a frame must turn."""
    x, y, z, w = q
    if w < 0.0:  # q and -q are the same rotation: take the short way
        x, y, z, w = -x, -y, -z, -w
    s = math.sqrt(x * x + y * y + z * z)
    if s < 1e-12:
        return (2.0 * x, 2.0 * y, 2.0 * z)
    angle = 2.0 * math.atan2(s, w)
    return (x / s * angle, y / s * angle, z / s * angle)


def orientation_error(current: Sequence[float], goal: Sequence[float]) -> Vec:
    """The rotation (world axis * angle) that turns the orientation `current` into `goal` (quaternions)."""
    cx, cy, cz, cw = current
    return rotation_vector(quat_mul(goal, (-cx, -cy, -cz, cw)))


def angle_between(a: Sequence[float], b: Sequence[float]) -> float:
    """The angle (rad, in [0, pi]) of the rotation between two orientations (atan2 of the relative rotation's parts:
    acos of their dot product loses half the digits near 0)."""
    x, y, z, w = quat_mul(a, (-b[0], -b[1], -b[2], b[3]))
    return 2.0 * math.atan2(math.sqrt(x * x + y * y + z * z), abs(w))


def pose_distance(d: float, angle: float) -> float:
    """A pose goal's D_goal from the tool's distance d (m) and its angle (rad) to the goal's orientation."""
    return math.hypot(d, POSE_WEIGHT * angle)


def move_share(tip: Sequence[float], goal: Sequence[float]) -> float:
    """The share of its size a move takes at this tip: FINE_SHARE within FINE_WITHIN of a pose goal, else 1."""
    if len(goal) != 7:
        return 1.0
    d = pose_distance(math.dist(tip[:3], goal[:3]), angle_between(tip[3:7], goal[3:7]))
    return FINE_SHARE if d < FINE_WITHIN else 1.0


def best_turn(
    axis: Sequence[float],
    joint: Sequence[float],
    tip: Sequence[float],
    goal: Sequence[float],
    travel: tuple[float, float],
    prismatic: bool = False,
) -> float:
    """g_q: the move (rad; m for a prismatic joint) from where this joint is to the value within its travel (lo, hi:
    how far it may still move down and up) at which, every other joint held, the tool's D_goal is least.

    A joint turning by t about its world axis a through `joint` takes the tool's point e = joint + r to joint +
    R(t) r, R(t) r = (r.a) a + cos t r_perp + sin t (a x r), so with v = goal - joint

        |w(t)|² = |v|² + |r|² - 2 (v.(r.a) a + cos t v.r_perp + sin t v.(a x r)),

    and turns the tool's orientation: the rotation still to make, e = goal tool^-1, becomes e R(-t), whose angle is
    2 acos|e_w cos(t/2) + (e_xyz.a) sin(t/2)|. Swept over the travel every SWEEP (and at 0); a prismatic joint's
    shift s gives |w - s a|², its orientation unchanged. What a joint knows: its frame, the tool (sent up), the goal
    and its limits; the global best of its own 1-D D_goal, so a joint whose short way is barred by its limit sees the
    long way round."""
    lo, hi = travel
    a = np.asarray(axis[:3], dtype=float)
    r = np.subtract(tip[:3], joint[:3])
    v = np.subtract(goal[:3], joint[:3])
    if prismatic:
        t = np.append(np.linspace(lo, hi, 201), 0.0)
        w = v - r
        d2 = w @ w - 2.0 * t * (w @ a) + t * t
        if len(goal) == 7:
            d2 = d2 + (POSE_WEIGHT * angle_between(tip[3:7], goal[3:7])) ** 2
        return float(t[np.argmin(d2)])
    n = max(2, math.ceil((hi - lo) / SWEEP) + 1)
    t = np.append(np.linspace(lo, hi, n), 0.0)
    ra = (r @ a) * a
    d2 = v @ v + r @ r - 2.0 * (v @ ra + np.cos(t) * (v @ (r - ra)) + np.sin(t) * (v @ np.cross(a, r)))
    if len(goal) == 7:
        ex, ey, ez, ew = quat_mul(goal[3:7], (-tip[3], -tip[4], -tip[5], tip[6]))
        c = np.abs(ew * np.cos(t / 2.0) + (ex * a[0] + ey * a[1] + ez * a[2]) * np.sin(t / 2.0))
        d2 = d2 + (POSE_WEIGHT * 2.0 * np.arccos(np.minimum(c, 1.0))) ** 2
    return float(t[np.argmin(d2)])


def motion(spec: AgentSpec, q: float) -> Frame:
    """What joint angle (or travel) q does to a joint's frame: a rotation about its axis, or a shift along it."""
    ax, ay, az = spec.axis
    if spec.prismatic:
        return (ax * q, ay * q, az * q, 0.0, 0.0, 0.0, 1.0)
    return (0.0, 0.0, 0.0, *axis_angle(spec.axis, q))


def joint_frame(spec: AgentSpec, base: Sequence[float], q: float) -> Frame:
    """Agent `spec`'s link frame on its base frame at joint value q (a compound agent's q is 0)."""
    return compose(compose(base, spec.origin), motion(spec, 0.0 if spec.compound else q))


def joint_axis(spec: AgentSpec, frame: Sequence[float]) -> Vec:
    """The joint's axis in the world (it does not turn with q)."""
    return rotate(frame[3:7], spec.axis)


def tool_frame(spec: AgentSpec, link: Sequence[float]) -> Frame:
    """A leaf's end effector: its tool frame on its link frame."""
    return compose(link, spec.tool)


def link_frames(topo: Topology, angles: Mapping[str, float]) -> dict[str, Frame]:
    """Every agent's link frame, parents first; missing angles count as 0."""
    out: dict[str, Frame] = {}
    for aid in topo.order:
        a = topo.agents[aid]
        base = topo.base if a.parent is None else out[a.parent]
        out[aid] = joint_frame(a, base, float(angles.get(aid, 0.0)))
    return out


def tips(topo: Topology, angles: Mapping[str, float]) -> dict[str, Frame]:
    """Every leaf's end-effector frame."""
    links = link_frames(topo, angles)
    return {leaf: tool_frame(topo.agents[leaf], links[leaf]) for leaf in topo.end_effectors}


def jacobian(topo: Topology, angles: Mapping[str, float], leaf: str) -> list[list[float]]:
    """d(tip position, tip rotation)/dq, 6 rows x n_dof columns (`topo.dof_agents` order); 0 off the leaf's path.

    A revolute joint with world axis a at p moves the tip e along a x (e - p) and turns it about a; a prismatic one
    shifts it along a and does not turn it."""
    links = link_frames(topo, angles)
    e = tool_frame(topo.agents[leaf], links[leaf])
    on_path = set()
    a = leaf
    while a is not None:
        on_path.add(a)
        a = topo.agents[a].parent
    cols = []
    for aid in topo.dof_agents:
        if aid not in on_path:
            cols.append((0.0,) * 6)
            continue
        spec, f = topo.agents[aid], links[aid]
        ax, ay, az = joint_axis(spec, f)
        if spec.prismatic:
            cols.append((ax, ay, az, 0.0, 0.0, 0.0))
            continue
        rx, ry, rz = e[0] - f[0], e[1] - f[1], e[2] - f[2]
        cols.append((ay * rz - az * ry, az * rx - ax * rz, ax * ry - ay * rx, ax, ay, az))
    return [[c[r] for c in cols] for r in range(6)]
