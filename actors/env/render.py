"""An environment's frame: the robot at its true pose and the goal, drawn with matplotlib's Agg canvas (no display,
no pyplot state) as an RGB array, the `rgb_array` render mode of Gymnasium and PettingZoo."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from kinswarm.actors.report.arm import arm_axes, arm_points
from kinswarm.protocol.topology import Topology

SIZE_IN, DPI = 4.0, 80  # 320 x 320 pixels


def frame(topo: Topology, angles: dict[str, float], goal: Sequence[float], title: str = "") -> np.ndarray:
    """(H, W, 3) uint8: the robot's links and joints, the goal as a cross."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(SIZE_IN, SIZE_IN), dpi=DPI)
    canvas = FigureCanvasAgg(fig)
    lines = arm_points(topo, angles)
    if topo.spatial:
        ax = arm_axes(fig, (1, 1, 1), [p for line in lines for p in line] + [tuple(goal[:3])])
        for line in lines:
            ax.plot(*zip(*line, strict=True), "-o", color="tab:blue", markersize=3)
        ax.scatter([goal[0]], [goal[1]], [goal[2]], marker="x", color="tab:red", s=60)
    else:
        ax = fig.add_subplot(1, 1, 1)
        r = topo.reach * 1.1
        ax.set_xlim(topo.base[0] - r, topo.base[0] + r)
        ax.set_ylim(topo.base[1] - r, topo.base[1] + r)
        ax.set_aspect("equal")
        for line in lines:
            ax.plot(*zip(*line, strict=True), "-o", color="tab:blue", markersize=3)
        ax.plot([goal[0]], [goal[1]], "x", color="tab:red", markersize=10)
    if title:
        ax.set_title(title, fontsize=9)
    canvas.draw()
    return np.asarray(canvas.buffer_rgba())[..., :3].copy()
