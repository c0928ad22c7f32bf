"""A run's motion as an animation (`kinswarm animate RUN-DIR`): the robot moving step by step in the chosen
epochs — the first, the last and every epoch with an event — beside its error, with lasting joint faults drawn
on the joints they hold and every event's time marked. Needs only matplotlib and pillow and the run directory
(`poses.jsonl`, `metrics.jsonl`, `events.jsonl`, `config.json`)."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from kinswarm.actors.files.config import ConfigError, load_run_config
from kinswarm.actors.report import error_line, events_by_epoch, read_events, read_jsonl, read_metrics
from kinswarm.actors.report.arm import arm_axes, arm_points, joint_points
from kinswarm.actors.report.timeline import fault_spans, faulty_at, label_groups

MAX_EPOCHS = 6  # the first, the last, and the latest epochs with events up to this many
FRAMES_PER_EPOCH = 60  # a 500-step epoch is drawn every 9th step
FPS = 20
FAULT_COLOUR = "C3"


def read_poses(run_dir: Path) -> dict[int, list[list[float]]]:
    """Epoch -> the joint angles (degrees, DOF order) after each of its steps."""
    path = run_dir / "poses.jsonl"
    rows = read_jsonl(path) if path.exists() else []
    return {int(r["epoch"]): r["angles_deg"] for r in rows if isinstance(r.get("angles_deg"), list)}


def put(line: Any, pts: list[Any]) -> None:
    """A line's points, (x, y) or (x, y, z) each: set_data in 2D, set_data_3d in 3D."""
    three = hasattr(line, "set_data_3d")
    cols = [[p[i] for p in pts] for i in range(3 if three else 2)]
    (line.set_data_3d if three else line.set_data)(*cols)


def pick_epochs(have: list[int], with_events: list[int], most: int = MAX_EPOCHS) -> list[int]:
    """The first and last epochs the run recorded, and the latest epochs with events, at most `most` in all."""
    if not have:
        return []
    ends = {have[0], have[-1]}
    chosen = sorted(ends | set(sorted(e for e in with_events if e in have)[-(most - len(ends)) :]))
    return chosen[:most]


def write_animation(
    run_dir: Path, epochs: list[int] | None = None, out: Path | None = None, frames: int = FRAMES_PER_EPOCH
) -> Path:
    """Write the run's animation (GIF) and return its path; ConfigError when the run has no poses to draw."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np
    from PIL import Image

    cfg = load_run_config(run_dir / "config.json")
    topo = cfg.topo()
    poses = read_poses(run_dir)
    if not poses:
        raise ConfigError(f"{run_dir}: no poses.jsonl rows to animate (a run from before poses were recorded?)")
    rows = {r["epoch"]: r for r in read_metrics(run_dir)}
    events = read_events(run_dir)
    by_epoch = events_by_epoch(events)
    have = sorted(poses)
    if epochs is None:
        epochs = pick_epochs(have, sorted(by_epoch))
    missing = [e for e in epochs if e not in poses]
    if missing:
        raise ConfigError(f"{run_dir}: no poses for epoch(s) {missing}; the run recorded {have[0]}-{have[-1]}")
    spans = fault_spans(events)
    dof = topo.dof_agents
    from kinswarm.actors.files.runfile import task_of

    task = task_of(cfg)
    start = {a: math.degrees(v) for a, v in topo.initial_angles().items()}

    # (epoch, step index into the epoch's poses; -1: the pose the epoch started from)
    plan: list[tuple[int, int]] = []
    for e in epochs:
        n = len(poses[e])
        stride = max(1, math.ceil(n / frames))
        plan += [(e, -1), *((e, t) for t in range(0, n, stride))]
        if (n - 1) % stride:
            plan.append((e, n - 1))

    def angles(e: int, t: int) -> dict[str, float]:
        if t < 0:
            prev = poses.get(e - 1)
            first = {a: math.degrees(v) for a, v in task.start(e).items()} or start  # the task's start pose, or home
            deg = prev[-1] if cfg.successive and prev else [first[a] for a in dof]
        else:
            deg = poses[e][t]
        return {a: math.radians(v) for a, v in zip(dof, deg, strict=True)}

    fig, (ax, ax_err) = plt.subplots(1, 2, figsize=(10, 4.6), dpi=72, gridspec_kw={"width_ratios": [1.0, 1.25]})
    fig.subplots_adjust(left=0.05, right=0.98, bottom=0.12, top=0.86, wspace=0.22)
    fig.suptitle(f"{cfg.run_id}: {topo.name}", fontsize=10)
    R = topo.reach
    bx, by = topo.base[0], topo.base[1]
    scene = cfg.scene_spec
    dim = 3 if topo.spatial else 2
    if topo.spatial:  # 3D: a cube about every pose and goal on show
        where = ax.get_subplotspec()
        ax.remove()
        on_show = [p for e, t in plan for line in arm_points(topo, angles(e, t)) for p in line]
        on_show += [g[:3] for e in epochs for g in (task.goal(e, len(poses[e]))[0],)]
        ax = arm_axes(fig, (where,), on_show)
    elif scene.obstacles:
        from kinswarm.actors.report.scene_plot import draw_scene

        draw_scene(ax, topo, scene.obstacles, None)
    else:
        ax.set_xlim(bx - R * 1.05, bx + R * 1.05)
        ax.set_ylim(by - R * 1.05, by + R * 1.05)
        ax.set_aspect("equal")
        ax.grid(alpha=0.25)
    # The artists are made once and moved each frame (a redraw from scratch costs ~5x more per frame).
    none = [[]] * dim
    (path_line,) = ax.plot(*none, ":", color="0.6", lw=0.8)
    chains = [ax.plot(*none, "-o", color="C0", lw=2.2, ms=4)[0] for _ in topo.end_effectors]
    (faulty_marks,) = ax.plot(*none, "X", ms=13, color=FAULT_COLOUR, zorder=6, ls="none")
    (goal_mark,) = ax.plot(*none, "r*", ms=14, zorder=5)
    # 3D: the arm's shadow on the floor and the goal's drop line, to read where in depth they are
    shadows = [ax.plot(*none, color="0.75", lw=1.0)[0] for _ in chains] if topo.spatial else []
    drop = [ax.plot(*none, ":", color="r", lw=0.8)[0], ax.plot(*none, "x", color="r", ms=6)[0]] if topo.spatial else []
    floor = ax.get_zlim()[0] if topo.spatial else 0.0
    arm_title = ax.set_title("", fontsize=10)
    notes: list[Any] = []
    (curve,) = ax_err.plot([], [], color="C0", lw=1.0)
    cursor = ax_err.axvline(0, color="k", lw=0.8)
    (dot,) = ax_err.plot([], [], "o", color="k", ms=4)
    ax_err.axhline(error_line(topo), color="grey", ls="--", lw=0.8)
    ax_err.set_xlabel("step")
    ax_err.set_ylabel("distance from the tip to the goal")
    ax_err.grid(alpha=0.3)
    err_title = ax_err.set_title("", fontsize=9)
    per_epoch: list[Any] = []  # the error axes' marks of the epoch on show
    shown = {"epoch": -1}
    moving = [*shadows, *drop, path_line, *chains, faulty_marks, goal_mark, arm_title, cursor, dot, err_title]
    for artist in moving:
        artist.set_animated(True)
    background: list[Any] = [None]

    def show_epoch(e: int, n: int, errs: list[float]) -> None:
        for artist in per_epoch:
            artist.remove()
        per_epoch.clear()
        curve.set_data(range(len(errs)), errs)
        for sp in spans:
            if (w := sp.within(e, n)) is not None:
                per_epoch.append(ax_err.axvspan(*w, color=FAULT_COLOUR, alpha=0.08, lw=0))
        here = by_epoch.get(e, [])
        for ev in here:
            per_epoch.append(ax_err.axvline(ev["step"], color=FAULT_COLOUR, lw=0.7, alpha=0.6))
        for s_at, label in label_groups(here, n):
            per_epoch.append(
                ax_err.text(
                    s_at,
                    0.98,
                    f" {label}",
                    rotation=90,
                    va="top",
                    ha="right",
                    fontsize=7,
                    color=FAULT_COLOUR,
                    transform=ax_err.get_xaxis_transform(),
                )  # fmt: skip
            )
        ax_err.set_xlim(0, n)
        ax_err.set_ylim(0, max(max(errs, default=1.0) * 1.4, 1.2 * error_line(topo)))
        shown["epoch"] = e
        # Blitting: what stays for the epoch (axes, ticks, the error curve, its events) is drawn once here; each
        # frame puts it back and draws only what moves. Drawing the whole figure per frame cost ~10x more.
        fig.canvas.draw()
        background[0] = fig.canvas.copy_from_bbox(fig.bbox)

    def frame(i: int) -> Any:
        e, t = plan[i]
        step = max(t, 0)
        n = len(poses[e])
        errs = rows.get(e, {}).get("errors") or []
        if shown["epoch"] != e:
            show_epoch(e, n, errs)
        q = angles(e, t)
        goal, path = task.goal(e, n)
        g = path[step] if path else goal
        put(path_line, [p[:dim] for p in path])
        arms = arm_points(topo, q)
        for line, pts in zip(chains, arms, strict=True):
            put(line, pts)
        if topo.spatial:
            for line, pts in zip(shadows, arms, strict=True):
                put(line, [(p[0], p[1], floor) for p in pts])
        faulty = faulty_at(spans, e, n, step)
        joints = joint_points(topo, q)
        marked = [a for a in faulty if a in joints]
        put(faulty_marks, [joints[a] for a in marked])
        for note in notes:
            note.remove()
        notes.clear()
        for a in marked:
            if topo.spatial:
                notes.append(ax.text(*joints[a], f"  {a} {faulty[a]}", fontsize=8, color=FAULT_COLOUR, animated=True))
                continue
            notes.append(ax.annotate(f"{a} {faulty[a]}", joints[a], xytext=(6, 6), textcoords="offset points",
                                     fontsize=8, color=FAULT_COLOUR, animated=True))  # fmt: skip
        put(goal_mark, [g[:dim]])
        if drop:
            put(drop[0], [(g[0], g[1], floor), g[:3]])
            put(drop[1], [(g[0], g[1], floor)])
        arm_title.set_text(f"epoch {e}, step {step}")
        cursor.set_xdata([step, step])
        if errs:
            dot.set_data([step], [errs[min(step, len(errs) - 1)]])
        what = ", ".join(f"{a} {w}" for a, w in faulty.items()) or "no joint fault"
        err_title.set_text(f"error; {what}")
        fig.canvas.restore_region(background[0])
        for artist in [*moving, *notes]:
            fig.draw_artist(artist)
        return Image.fromarray(np.asarray(fig.canvas.buffer_rgba())[..., :3].copy())

    out = out or run_dir / "motion.gif"
    images = [frame(i) for i in range(len(plan))]
    plt.close(fig)
    # one palette for the whole animation: the frames share their colours, and the file is smaller
    palette = images[len(images) // 2].quantize(colors=48, method=Image.Quantize.MEDIANCUT)
    frames = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    frames[0].save(out, save_all=True, append_images=frames[1:], duration=int(1000 / FPS), loop=0, optimize=True)
    return out
