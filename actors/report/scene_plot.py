"""The chain in its scene (paper Fig. 23): obstacles drawn, the final configuration of epochs across training.
Used by `kinswarm run`/`kinswarm report` (scene.png) for runs in a walls scene, and by the corridor experiment."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from kinswarm.actors.report.arm import arm_points
from kinswarm.actors.report.figure import save_figure
from kinswarm.protocol.obstacles import ObstacleSpec
from kinswarm.protocol.topology import Topology

SHOWN_EPOCHS = 8  # corridor.png: at most this many epochs' final configurations


def draw_scene(ax: Any, topo: Topology, obstacles: Sequence[ObstacleSpec], goal: tuple[float, float] | None) -> None:
    """Obstacles as filled polygons, the goal as a star; equal axes around the robot and its scene."""
    from matplotlib.patches import Polygon

    xs, ys = [topo.base[0]], [topo.base[1]]
    for o in obstacles:
        corners = o.corners()
        ax.add_patch(Polygon(corners, closed=True, facecolor="0.75", edgecolor="0.35", lw=0.8, zorder=1))
        xs += [c[0] for c in corners]
        ys += [c[1] for c in corners]
    if goal is not None:
        ax.plot(*goal, "r*", ms=13, zorder=5, label=f"target ({goal[0]:g}, {goal[1]:g})")
        xs.append(goal[0])
        ys.append(goal[1])
    R = topo.reach
    lo_x, hi_x = min(min(xs), topo.base[0] - R * 0.3), max(max(xs), topo.base[0] + R * 0.3)
    lo_y, hi_y = min(min(ys), topo.base[1] - R * 0.3), max(max(ys), topo.base[1] + R)
    ax.set_xlim(lo_x - 0.3, hi_x + 0.3)
    ax.set_ylim(lo_y - 0.3, hi_y + 0.3)
    ax.set_aspect("equal")
    ax.grid(alpha=0.25)


def draw_chain(ax: Any, topo: Topology, angles: dict[str, float], **style: Any) -> None:
    for pts in arm_points(topo, angles):
        xs, ys = zip(*pts, strict=True)
        ax.plot(xs, ys, **{"marker": "o", "ms": 3, "lw": 1.6, **style})


def pick_epochs(n: int, shown: int = SHOWN_EPOCHS) -> list[int]:
    """Up to `shown` epochs spread over 0..n-1, always with the first and the last."""
    if n <= shown:
        return list(range(n))
    return sorted({round(i * (n - 1) / (shown - 1)) for i in range(shown)})


def plot_scene_epochs(
    ax: Any,
    topo: Topology,
    obstacles: Sequence[ObstacleSpec],
    goal: tuple[float, float] | None,
    rows: Sequence[dict[str, Any]],
    title: str = "",
) -> None:
    """Fig. 23: the start configuration (dotted) and each picked epoch's final configuration, light to dark."""
    import matplotlib as mpl

    draw_scene(ax, topo, obstacles, goal)
    draw_chain(ax, topo, topo.initial_angles(), color="0.5", ls=":", label="start")
    picked = pick_epochs(len(rows))
    cmap = mpl.colormaps["viridis"]
    for i, n in enumerate(picked):
        r = rows[n]
        angles = {a: math.radians(v) for a, v in r["final_angles_deg"].items()}
        hits = round(sum(r.get("traces", {}).get("collisions", [])[-100:]))
        label = f"epoch {r['epoch']}: error {r['final_error']:.2f}, {hits} coll. in last 100"
        draw_chain(ax, topo, angles, color=cmap(0.15 + 0.8 * i / max(len(picked) - 1, 1)), label=label)
    ax.legend(loc="upper left", fontsize=6.5)
    if title:
        ax.set_title(title, fontsize=9)


def write_scene_plot(
    path: Any,
    topo: Topology,
    obstacles: Sequence[ObstacleSpec],
    goal: tuple[float, float] | None,
    rows: Sequence[dict],
    title: str,
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 6.0))
    plot_scene_epochs(ax, topo, obstacles, goal, rows, title)
    fig.tight_layout()
    save_figure(fig, path, dpi=110)
    plt.close(fig)
