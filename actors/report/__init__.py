"""What a run leaves behind, for a person to read (this package): its plots and summary (here), the arm's drawing
(arm.py), fault spans (timeline.py), motion.gif (animate.py), the rerun recording (recording.py), a scene's plots
(scene_plot.py: walls; grasp.py: the grasp).

Here: `summary.json`, `learning_curve.png`, `arm.png`, `tracking.png` — rebuilt
from the run directory alone (`kinswarm report RUN-DIR`). Runs from before faults existed (no
`events.jsonl`, no per-step `errors` in `metrics.jsonl`) still get the plots their data allows.

Plots a person reads at a glance: a linear error axis (log on request), whole epochs on the axis, legends beside
the data rather than on it, a lasting joint fault drawn as the span it lasts (actors/report/timeline.py), event labels
that never overlap, and a title that says what drove the robot."""

from __future__ import annotations

import contextlib
import json
import math
import os
from pathlib import Path
from typing import Any

from kinswarm.actors.files.config import RunConfig, load_run_config
from kinswarm.actors.report.arm import arm_axes, arm_points, draw_axes, floor_shadow, joint_points
from kinswarm.actors.report.figure import save_figure
from kinswarm.actors.report.timeline import Span, active_at_end, fault_spans, label_groups, one_per_command
from kinswarm.protocol import frames
from kinswarm.protocol.topology import Topology

TRACKED_EPOCHS = 4  # tracking.png: at most this many epochs with events (else the last epoch)


def error_line(topo: Topology) -> float:
    """The error the plots mark: 0.5 on a planar robot's scale; 5 cm on a spatial one (metres: a real arm)."""
    return 0.05 if topo.spatial else 0.5


def read_metrics(run_dir: Path) -> list[dict[str, Any]]:
    return read_jsonl(run_dir / "metrics.jsonl")


def read_events(run_dir: Path) -> list[dict[str, Any]]:
    """`events.jsonl` rows (faults, detections, restarts, ...); [] for a run that has none."""
    path = run_dir / "events.jsonl"
    return read_jsonl(path) if path.exists() else []


def read_jsonl(path: Path, skipped: list[str] | None = None) -> list[dict[str, Any]]:
    """Every whole row of a JSON-lines record; a row that is not one (a torn last line, where a killed writer
    stopped) is left out, and said in `skipped`."""
    rows = []
    for n, line in enumerate(path.read_text(errors="replace").splitlines(), 1):
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            row = None
        if isinstance(row, dict):
            rows.append(row)
        elif skipped is not None and line.strip():
            skipped.append(f"{path}:{n}: not a whole row ({len(line)} characters), left out")
    return rows


def torn_rows(run_dir: Path) -> list[str]:
    """What `kinswarm report` leaves out of a run's records, one line each."""
    skipped: list[str] = []
    for name in ("metrics.jsonl", "events.jsonl"):
        if (run_dir / name).exists():
            read_jsonl(run_dir / name, skipped)
    return skipped


def goal_text(goal: tuple[float, ...]) -> str:
    """A goal in a legend: its point, and "pose" when it names an orientation too."""
    pt = ", ".join(f"{c:.2f}" for c in goal[: 3 if len(goal) > 2 else 2])
    return f"({pt})" + (" pose" if len(goal) == 7 else "")


def _arm_3d(
    fig: Any,
    topo: Topology,
    start: dict[str, float],
    final: dict[str, float],
    goal: tuple[float, ...],
    label: str,
    faulty: dict[str, list[str]],
) -> Any:
    """arm.png of a spatial robot: the start (dotted) and final arm in 3D, the tool's point, the goal."""
    lines = {"start": arm_points(topo, start), label: arm_points(topo, final)}
    ax = arm_axes(fig, (1, 1, 1), [goal[:3], *(p for pts in lines.values() for line in pts for p in line)])
    for (name, arm), style, colour in zip(lines.items(), (":", "-"), ("grey", "C0"), strict=True):
        for pts in arm:
            ax.plot(*zip(*pts, strict=True), style, marker="o", ms=3, color=colour, label=name)
            ax.plot(*([c] for c in pts[-1]), "s", ms=5, color=colour)  # the tool point
    ax.plot([goal[0]], [goal[1]], [goal[2]], "r*", ms=14, label=f"goal {goal_text(goal)}")
    floor_shadow(ax, lines[label], goal)
    if len(goal) == 7:  # a pose: the goal's axes and the tool's, x red, y green, z blue
        for frame, style in ((goal, "-"), *((tip, "--") for tip in frames.tips(topo, final).values())):
            draw_axes(ax, frame, 0.1 * topo.reach, style)
        ax.plot([], [], "-", color="0.3", label="goal's x, y, z (red, green, blue)")
        ax.plot([], [], "--", color="0.3", label="the tool's")
    joints = joint_points(topo, final)
    for i, (a, what) in enumerate(sorted(faulty.items())):
        if a in joints:
            ax.plot(*([c] for c in joints[a]), "X", ms=11, color=f"C{3 + i}", label=f"{a}: {', '.join(what)}")
    return ax


def write_plots(run_dir: Path, log: bool = False) -> list[Path]:
    """Every plot the run's records allow; `log`: the learning curve's error axis logarithmic."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.ticker import MaxNLocator

    cfg = load_run_config(run_dir / "config.json")
    topo, scene = cfg.topo(), cfg.scene_spec
    rows = read_metrics(run_dir)
    goal = _goal(cfg, rows)
    events = read_events(run_dir)
    by_epoch = events_by_epoch(events)
    spans = fault_spans(events)
    written = []
    if rows:
        ep = [r["epoch"] for r in rows]
        fig, ax = plt.subplots(figsize=(8, 4.2))
        _epoch_spans(ax, spans, ep)
        ax.plot(ep, [r["mean_error"] for r in rows], label="mean error over the epoch")
        ax.plot(ep, [r["final_error"] for r in rows], label="final error (last step)")
        marked = [r for r in rows if r["epoch"] in by_epoch]
        if marked:
            ax.plot(
                [r["epoch"] for r in marked],
                [r["final_error"] for r in marked],
                "o",
                mfc="none",
                color="C3",
                label="epoch with events (faults, restarts, ...)",
            )
        line = error_line(topo)
        ax.axhline(line, color="grey", ls="--", lw=0.8, label=f"{line:g}")
        if log:
            ax.set_yscale("log")
        else:
            ax.set_ylim(bottom=0)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlabel("epoch")
        ax.set_ylabel("end-effector distance to goal")
        ax.set_title(f"{cfg.run_id}: {topo.name}, {_controller(cfg)}, seed {cfg.seed}", fontsize=10)
        _legend_beside(ax)
        fig.tight_layout()
        save_figure(fig, run_dir / "learning_curve.png", dpi=110)
        plt.close(fig)
        written.append(run_dir / "learning_curve.png")

        final = {a: math.radians(v) for a, v in rows[-1]["final_angles_deg"].items()}
        start = cfg_start(cfg, rows[-1]["epoch"], topo)
        if topo.spatial:
            fig = plt.figure(figsize=(9, 5.8))
            ax = _arm_3d(fig, topo, start, final, goal, f"epoch {rows[-1]['epoch']} final", active_at_end(events))
            _legend_beside(ax)
        else:
            fig, ax = plt.subplots(figsize=(7, 5))
            for i, (angles, style) in enumerate(((start, ":"), (final, "-"))):
                for pts in arm_points(topo, angles):
                    xs, ys = zip(*pts, strict=True)
                    label = "start" if i == 0 else f"epoch {rows[-1]['epoch']} final"
                    ax.plot(xs, ys, style, marker="o", ms=4, color="grey" if i == 0 else "C0", label=label)
            ax.plot(*goal, "r*", ms=14, label=f"goal ({goal[0]:.2f}, {goal[1]:.2f})")
            joints = joint_points(topo, final)
            for i, (a, what) in enumerate(sorted(active_at_end(events).items())):
                if a in joints:  # a joint still faulty when the run ended
                    ax.plot(*joints[a], "X", ms=11, color=f"C{3 + i}", label=f"{a}: {', '.join(what)}")
            R = topo.reach
            ax.set_xlim(topo.base[0] - R * 1.05, topo.base[0] + R * 1.05)
            ax.set_ylim(topo.base[1] - R * 1.05, topo.base[1] + R * 1.05)
            ax.set_aspect("equal")
            ax.grid(alpha=0.3)
            _legend_beside(ax)
        ax.set_title(f"{_controller(cfg)}: final error {rows[-1]['final_error']:.3f}", fontsize=10)
        fig.tight_layout()
        save_figure(fig, run_dir / "arm.png", dpi=110)
        plt.close(fig)
        written.append(run_dir / "arm.png")

    if rows and scene.obstacles:  # the chain among the walls (paper Fig. 23)
        from kinswarm.actors.report.scene_plot import write_scene_plot

        title = f"{cfg.run_id}: final configurations, {_controller(cfg)}, seed={cfg.seed}"
        write_scene_plot(run_dir / "scene.png", topo, scene.obstacles, goal, rows, title)
        written.append(run_dir / "scene.png")

    tracked = [r for r in rows if r.get("errors")]
    with_events = [r for r in tracked if r["epoch"] in by_epoch]
    chosen = with_events[-TRACKED_EPOCHS:] or tracked[-1:]
    if chosen:
        fig, axes = plt.subplots(len(chosen), 1, figsize=(10, 2.8 * len(chosen) + 0.6), squeeze=False, sharex=True)
        for ax, r in zip(axes[:, 0], chosen, strict=True):
            _tracking(ax, r, by_epoch.get(r["epoch"], []), spans, error_line(topo))
        axes[-1, 0].set_xlabel("step (error after the step's joint actions)")
        fig.suptitle(f"{cfg.run_id}: end-effector error within an epoch ({_controller(cfg)})", fontsize=10)
        fig.tight_layout()
        save_figure(fig, run_dir / "tracking.png", dpi=110)
        plt.close(fig)
        written.append(run_dir / "tracking.png")
    if scene.object is not None:  # an object to grasp (paper §5.5): the fingers, forces, friction cones
        from kinswarm.actors.report.grasp import write_grasp_plots

        written += write_grasp_plots(run_dir, topo, scene.object, rows, plt)
    return written


def events_by_epoch(events: list[dict[str, Any]]) -> dict[int, list[dict[str, Any]]]:
    """Events placed in an epoch and step; those the sender could not place (-1) are left out of plots."""
    out: dict[int, list[dict[str, Any]]] = {}
    for ev in events:
        epoch, step = ev.get("epoch", -1), ev.get("step", -1)
        if isinstance(epoch, int) and isinstance(step, int) and epoch >= 0 and step >= 0:
            out.setdefault(epoch, []).append(ev)
    return out


SPAN_COLOURS = {"locked": "C3", "disturbed": "C1", "reversed": "C4", "scaled": "C5", "dead zone": "C6",
                "reads offset": "C8", "reads late": "C9", "lost": "C7"}  # fmt: skip


def _tracking(ax: Any, row: dict[str, Any], events: list[dict[str, Any]], spans: list[Span], line: float = 0.5) -> None:
    """One epoch's error per step (the paper's Figs. 13-21): each lasting joint fault a shaded span (a lock
    from an earlier epoch shades the whole epoch), a line at every event step, one label per group of close
    events so no two labels overlap."""
    errors = row["errors"]
    n = len(errors)
    for s in spans:
        if (steps := s.within(row["epoch"], n)) is not None:
            colour = SPAN_COLOURS.get(s.label.split(" ", 1)[1], "C7")
            ax.axvspan(*steps, color=colour, alpha=0.10, lw=0, label=s.label)
    ax.plot(range(n), errors, lw=1.0, color="C0", label="error")
    ax.axhline(line, color="grey", ls="--", lw=0.8)
    ax.set_ylim(bottom=0, top=max(max(errors, default=1.0) * 1.45, 1.2 * line))  # room above the curve for the labels
    events = one_per_command(events)
    for ev in events:
        ax.axvline(ev["step"], color="C3", lw=0.7, alpha=0.6)
    for step, label in label_groups(events, n):
        ax.text(step, 0.98, f" {label}", rotation=90, va="top", ha="right", fontsize=7, color="C3",
                transform=ax.get_xaxis_transform())  # fmt: skip
    ax.set_ylabel("error")
    ax.set_title(f"epoch {row['epoch']}: final {row['final_error']:.3f}, mean {row['mean_error']:.3f}", fontsize=9)
    ax.grid(alpha=0.3)
    _legend_beside(ax)


def _epoch_spans(ax: Any, spans: list[Span], epochs: list[int]) -> None:
    """The learning curve's shading: the epochs over which each lasting joint fault held."""
    if not epochs:
        return
    last = max(epochs)
    for s in spans:
        end = last + 0.5 if s.end is None else s.end[0] + 0.5
        colour = SPAN_COLOURS.get(s.label.split(" ", 1)[1], "C7")
        ax.axvspan(s.start[0] - 0.5, end, color=colour, alpha=0.10, lw=0, label=s.label)


def _legend_beside(ax: Any) -> None:
    """One entry per label, to the right of the axes: never over the data."""
    handles, labels = ax.get_legend_handles_labels()
    uniq = dict(zip(labels, handles, strict=True))
    if uniq:
        ax.legend(uniq.values(), uniq.keys(), loc="upper left", bbox_to_anchor=(1.01, 1.0), fontsize=7,
                  frameon=False)  # fmt: skip


def write_summary(run_dir: Path, extra: dict[str, Any]) -> dict[str, Any]:
    """`summary.json`, written whole or not at all (a full disk leaves no torn summary: the run stays resumable)."""
    summary = summarize(run_dir, extra)
    path = run_dir / "summary.json"
    tmp = path.with_name(f".{path.name}.tmp")
    try:
        tmp.write_text(json.dumps(summary, indent=2) + "\n")
        os.replace(tmp, path)
    except OSError as e:  # named as the user knows it, not as its temporary file
        with contextlib.suppress(OSError):
            tmp.unlink(missing_ok=True)
        raise OSError(e.errno, e.strerror or str(e), str(path)) from None
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise
    return summary


def summarize(run_dir: Path, extra: dict[str, Any]) -> dict[str, Any]:
    """What summary.json says of the run in `run_dir` (`extra`: what its run returned), nothing written."""
    cfg = load_run_config(run_dir / "config.json")
    topo, scene = cfg.topo(), cfg.scene_spec
    rows = read_metrics(run_dir)
    sim_seconds = sum(r["seconds"] for r in rows)
    steps = sum(r["steps"] for r in rows)
    summary = {
        "run_id": cfg.run_id,
        "robot": topo.name,
        "task": cfg.task["kind"],
        "controller": cfg.controller,
        "epochs": len(rows),
        "steps_per_epoch": cfg.steps,
        "seed": cfg.seed,
        "placement": cfg.placement,
        "reward": cfg.task.get("reward"),
        "learn": cfg.learn,
        "explore": cfg.explore,
        "goal": list(_goal(cfg, rows)),
        "final_error": [r["final_error"] for r in rows],
        "mean_error": [r["mean_error"] for r in rows],
        "missed_cmds": sum(r["missed_cmds"] for r in rows),
        "steps_per_second": steps / sim_seconds if sim_seconds > 0 else 0.0,
        **extra,
    }
    if cfg.fleet > 1:  # the rows are robot 0's; every robot's final error, and the fleet's rate
        summary["fleet"] = cfg.fleet
        summary["fleet_final_error"] = [r.get("fleet_final_error", []) for r in rows]
        summary["robot_steps_per_second"] = summary["steps_per_second"] * cfg.fleet
    if scene.object is not None:  # an object to grasp: the grasp's quality per epoch
        from kinswarm.actors.report.grasp import grasp_summary

        summary["grasp"] = grasp_summary(rows, topo, scene.object)
    return summary


def _goal(cfg: RunConfig, rows: list[dict[str, Any]]) -> tuple[float, float]:
    """The goal of the run's last epoch (the task's goal schedule)."""
    from kinswarm.actors.files.runfile import task_of

    epoch = rows[-1]["epoch"] if rows else 0
    return task_of(cfg).goal(epoch, cfg.steps)[0]


def cfg_start(cfg: RunConfig, epoch: int, topo: Topology) -> dict[str, float]:
    """The joint angles epoch `epoch` started from: the task's start pose, else the robot's home."""
    from kinswarm.actors.files.runfile import task_of

    return task_of(cfg).start(epoch) or topo.initial_angles()


LAW_NAMES = {
    "pinv": "pseudo-inverse (model-based)",
    "greedy": "greedy per joint (model-based)",
    "rule": "rule on g_perp (no learning)",
    "turn": "rule on g_q (no learning)",
}


def _controller(cfg: RunConfig) -> str:
    """What drove the robot: the agents (learning or frozen) and their reward, or the law that replaced them."""
    if cfg.controller != "agents":
        return LAW_NAMES.get(cfg.controller, cfg.controller)
    how = "learning" if cfg.learn else "frozen"
    return f"{cfg.task['kind']}, agents {how}, reward {cfg.task.get('reward', '-')}"
