"""An environment's frame: the robot at its true pose and the goal, drawn with matplotlib's Agg canvas (no display,
no pyplot state) as an RGB array, the `rgb_array` render mode of Gymnasium and PettingZoo; the `human` mode shows it
in a pyplot window."""

from __future__ import annotations

from collections.abc import Callable, Sequence

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


class Window:
    """render_mode "human": the frame shown in a matplotlib window, updated at each render (pyplot's, imported only
    here). Under a non-interactive backend (no display: Agg) the figure is drawn and nothing is shown."""

    def __init__(self, fps: int) -> None:
        self.fps = fps
        self.figure = None
        self.image = None

    def show(self, picture: np.ndarray) -> None:
        import matplotlib
        import matplotlib.pyplot as plt

        if self.figure is None or not plt.fignum_exists(self.figure.number):
            self.figure = plt.figure("kinswarm", figsize=(SIZE_IN, SIZE_IN), dpi=DPI)
            ax = self.figure.add_axes((0.0, 0.0, 1.0, 1.0))
            ax.set_axis_off()
            self.image = ax.imshow(picture)
        else:
            self.image.set_data(picture)
        if matplotlib.get_backend().lower() == "agg":
            self.figure.canvas.draw()
        else:
            plt.pause(1.0 / self.fps)

    def close(self) -> None:
        if self.figure is not None:
            import matplotlib.pyplot as plt

            plt.close(self.figure)
            self.figure = self.image = None


RENDER_MODES = ("rgb_array", "human")
FPS = 10


def check_mode(mode: str | None) -> None:
    if mode not in (None, *RENDER_MODES):
        raise ValueError(f"render_mode: {mode!r} is not one of None, 'rgb_array', 'human'")


class Renderer:
    """Both faces' render, as Gymnasium defines the modes: None draws nothing (render warns and returns None);
    "rgb_array" returns the frame; "human" shows it at every reset and step, and render returns None."""

    def __init__(self, picture: Callable[[], np.ndarray], mode: str | None) -> None:
        check_mode(mode)
        self.picture, self.mode = picture, mode
        self.window = Window(FPS) if mode == "human" else None

    def render(self) -> np.ndarray | None:
        if self.mode is None:
            import gymnasium

            gymnasium.logger.warn("render: this env was made with render_mode=None, which draws nothing")
            return None
        picture = self.picture()
        if self.window is None:
            return picture
        self.window.show(picture)
        return None

    def shown(self) -> None:
        """After a reset or a step: the human mode's window follows the robot."""
        if self.window is not None:
            self.window.show(self.picture())

    def close(self) -> None:
        if self.window is not None:
            self.window.close()
