"""The robot drawn: its polylines and joints from the agents' own frame composition (planar or spatial), and the 3D
axes, floor shadow and frame axes the plots, the animation and the scene plots draw it with."""

from __future__ import annotations

from typing import Any

from kinswarm.actors.learning.state import joint_frame, link_end
from kinswarm.protocol import frames
from kinswarm.protocol.topology import Topology
from kinswarm.sim.kinematics import path_to


def joint_points(topo: Topology, angles: dict[str, float]) -> dict[str, tuple[float, ...]]:
    """Where each agent's joint sits, from the agents' own frame composition: (x, y) for a planar robot, (x, y, z)
    for a spatial one (its link frame's origin, on the joint's axis)."""
    if topo.spatial:
        return {a: f[:3] for a, f in frames.link_frames(topo, angles).items()}
    return {a: f[:2] for a, f in _frames(topo, angles)[0].items()}


def _frames(
    topo: Topology, angles: dict[str, float]
) -> tuple[dict[str, tuple[float, float, float]], dict[str, tuple[float, float, float]]]:
    ends: dict[str, tuple[float, float, float]] = {}
    starts: dict[str, tuple[float, float, float]] = {}
    for a in topo.order:
        spec = topo.agents[a]
        base = topo.base if spec.parent is None else ends[spec.parent]
        frame = joint_frame(base, spec.offset, angles.get(a, 0.0))
        starts[a], ends[a] = frame, link_end(frame, spec.link_length)
    return starts, ends


def arm_points(topo: Topology, angles: dict[str, float]) -> list[list[tuple[float, ...]]]:
    """Polylines of the robot, one per root-to-leaf path, from the agents' own frame composition: (x, y) points
    of a planar robot's joints and link ends; (x, y, z) of a spatial one's base, joints and tool point."""
    if topo.spatial:
        links, tips = frames.link_frames(topo, angles), frames.tips(topo, angles)
        return [[topo.base[:3], *(links[a][:3] for a in path_to(topo, leaf)), tips[leaf][:3]] for leaf in tips]
    starts, ends = _frames(topo, angles)
    lines = []
    for leaf in topo.end_effectors:
        pts = [(topo.base[0], topo.base[1])]
        for b in path_to(topo, leaf):
            pts += [starts[b][:2], ends[b][:2]]
        lines.append(pts)
    return lines


def arm_axes(fig: Any, where: tuple[int, ...], points: list[tuple[float, ...]]) -> Any:
    """The axes a spatial robot is drawn in (`fig.add_subplot(*where)`): 3D, equal scales, a cube about the
    `points` it must show (the arm's, the goal's), the view from the front-right above."""
    ax = fig.add_subplot(*where, projection="3d")
    lo = [min(p[i] for p in points) for i in range(3)]
    hi = [max(p[i] for p in points) for i in range(3)]
    half = max(0.55 * max(h - low for h, low in zip(hi, lo, strict=True)), 0.05)
    for (low, h), set_lim in zip(zip(lo, hi, strict=True), (ax.set_xlim, ax.set_ylim, ax.set_zlim), strict=True):
        set_lim((low + h) / 2 - half, (low + h) / 2 + half)
    ax.set_box_aspect((1.0, 1.0, 1.0))
    ax.view_init(elev=22, azim=-60)
    for set_label, name in zip((ax.set_xlabel, ax.set_ylabel, ax.set_zlabel), "xyz", strict=True):
        set_label(f"{name} (m)", fontsize=8, labelpad=-6)
    ax.tick_params(labelsize=6, pad=-2)
    return ax


def floor_shadow(ax: Any, arm: list[list[tuple[float, ...]]], goal: tuple[float, ...]) -> list[Any]:
    """Where the arm and the goal lie over the floor of a 3D axes: the arm's shadow, a drop line from the goal."""
    z0 = ax.get_zlim()[0]
    out = [ax.plot([p[0] for p in pts], [p[1] for p in pts], z0, color="0.75", lw=1.0)[0] for pts in arm]
    out += ax.plot([goal[0], goal[0]], [goal[1], goal[1]], [z0, goal[2]], ":", color="r", lw=0.8)
    out += ax.plot([goal[0]], [goal[1]], [z0], "x", color="r", ms=6)
    return out


def draw_axes(ax: Any, frame: tuple[float, ...], length: float, style: str = "-") -> list[Any]:
    """A frame's x, y, z axes (red, green, blue) as lines of `length` in a 3D axes."""
    lines = []
    for axis, colour in zip(((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)), ("r", "g", "b"), strict=True):
        end = [p + length * c for p, c in zip(frame[:3], frames.rotate(frame[3:7], axis), strict=True)]
        lines += ax.plot(*([p, e] for p, e in zip(frame[:3], end, strict=True)), style, color=colour, lw=1.2)
    return lines
