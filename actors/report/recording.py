"""A run as a rerun recording (the optional extra `kinswarm[viewer]`): the robot's pose at every step, the goal,
the error, joints with a lasting fault marked, every event of `events.jsonl` as a log line at its step, and each
epoch's final and mean error — on the timelines `step` (through the whole run), `epoch` and `step_in_epoch`, so
the viewer scrubs back and forth across faults. rerun is what LeRobot and dora-rs record with; its .rrd files
open in the standard viewer.

`kinswarm view RUN-DIR` opens a finished run; `kinswarm run … --view` streams each epoch as it ends (the
supervisor's recorder calls `LiveRecording.epoch`, off the step's critical path). Nothing leaves the machine:
the recording goes to a file, a viewer spawned on this machine, or a viewer served from it.
"""

from __future__ import annotations

import logging
import math
import multiprocessing
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from kinswarm.actors.files.config import ConfigError, RunConfig, load_run_config
from kinswarm.actors.report import events_by_epoch, read_events, read_jsonl, read_metrics
from kinswarm.actors.report.arm import arm_points, joint_points
from kinswarm.actors.report.timeline import fault_spans, faulty_at

log = logging.getLogger("kinswarm.view")
APP = "kinswarm"
FAULT = (214, 39, 40)
ARM = (31, 119, 180)
GOAL = (255, 200, 0)
ACTIONS = ("decrease", "keep", "increase")  # an agent's actions 0, 1, 2


def up(p: Sequence[float]) -> tuple[float, float]:
    """World (x, y) as rerun's 2D view draws it: its y axis points down, so up is -y."""
    return (float(p[0]), -float(p[1]))


def as_is(p: Sequence[float]) -> tuple[float, ...]:
    """A spatial robot's (x, y, z): rerun's 3D view takes the world as it is (z up, logged once as static)."""
    return tuple(float(c) for c in p[:3])


def rerun_module() -> Any:
    """rerun, or one line saying how to get it."""
    try:
        import rerun
    except ImportError:
        raise ConfigError("the viewer needs the optional extra: pip install 'kinswarm[viewer]' (rerun-sdk)") from None
    return rerun


class Recorder:
    """Logs a run's epochs into one rerun recording stream."""

    def __init__(self, cfg: RunConfig, stream: Any) -> None:
        self.rr = rerun_module()
        self.cfg, self.topo, self.stream = cfg, cfg.topo(), stream
        from kinswarm.actors.files.runfile import task_of

        self.task = task_of(cfg)
        self.dof = self.topo.dof_agents
        self.events: list[dict[str, Any]] = []
        # a planar robot in rerun's 2D view (y flipped), a robot from URDF in its 3D view
        rr = self.rr
        if self.topo.spatial:
            self.place, self.Strips, self.Points, self.scale = as_is, rr.LineStrips3D, rr.Points3D, 0.1
        else:
            self.place, self.Strips, self.Points, self.scale = up, rr.LineStrips2D, rr.Points2D, 1.0
        self._static()

    def _layout(self) -> Any:
        """The viewer's default layout: the robot large on the left; the error, the events and the agents on the
        right (each agent's liveliness, action and E in tabs)."""
        import rerun.blueprint as rrb

        dof = self.dof
        agents = rrb.Tabs(
            rrb.TimeSeriesView(name="alive", origin="/agents", contents=[f"/agents/{a}/alive" for a in dof]),
            rrb.TimeSeriesView(name="action", origin="/agents", contents=[f"/agents/{a}/action" for a in dof]),
            *(rrb.TimeSeriesView(name=f"{a}: E (Eq. 9)", origin=f"/agents/{a}/E") for a in dof),
            *(rrb.TimeSeriesView(name=f"{a}: state", origin=f"/agents/{a}/state") for a in dof),
        )
        right = rrb.Vertical(
            rrb.TimeSeriesView(name="error", origin="/error"),
            rrb.TextLogView(name="events", origin="/events"),
            agents,
            row_shares=[2, 1, 2],
        )
        view = rrb.Spatial3DView if self.topo.spatial else rrb.Spatial2DView
        robot = view(name="robot", origin="/world")
        return rrb.Blueprint(rrb.Horizontal(robot, right, column_shares=[3, 2]), collapse_panels=True)

    def _static(self) -> None:
        rr, topo = self.rr, self.topo
        self.stream.send_blueprint(self._layout())
        if topo.spatial:  # z up, metres; the base's plane as a square of the arm's reach
            self.stream.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
            R, (bx, by, bz) = topo.reach, topo.base[:3]
            square = [(bx - R, by - R, bz), (bx + R, by - R, bz), (bx + R, by + R, bz), (bx - R, by + R, bz)]
            self.stream.log(
                "world/reach", rr.LineStrips3D([[*square, square[0]]], colors=[(220, 220, 220)]), static=True
            )
            return
        walls = [[up(c) for c in [*o.corners(), o.corners()[0]]] for o in self.cfg.scene_spec.obstacles]
        if walls:
            self.stream.log("world/walls", rr.LineStrips2D(walls, colors=[(90, 90, 90)]), static=True)
        R = topo.reach
        bx, by = topo.base[0], topo.base[1]
        corners = ((bx - R, by - R), (bx + R, by - R), (bx + R, by + R), (bx - R, by + R), (bx - R, by - R))
        box = [up(c) for c in corners]
        self.stream.log("world/reach", rr.LineStrips2D([box], colors=[(220, 220, 220)]), static=True)

    def epoch(self, row: dict[str, Any], angles_deg: Sequence[Sequence[float]], events: list[dict[str, Any]]) -> None:
        """One finished epoch: its steps' poses and errors, its events, its summary."""
        rr, s, topo = self.rr, self.stream, self.topo
        e = int(row["epoch"])
        n = len(angles_deg)
        self.events += events
        spans = fault_spans(self.events)
        goal, path = self.task.goal(e, n)
        errors = row.get("errors") or []
        first = e * self.cfg.steps
        # One column per entity for the whole epoch (send_columns): a few calls into rerun, not four per step.
        times = [
            rr.TimeColumn("step", sequence=range(first, first + n)),
            rr.TimeColumn("epoch", sequence=[e] * n),
            rr.TimeColumn("step_in_epoch", sequence=range(n)),
        ]
        place, size = self.place, self.scale  # 2D (y flipped) or 3D; sizes in the robot's units
        strips: list[list[tuple[float, ...]]] = []
        points: list[tuple[float, ...]] = []
        colours: list[tuple[int, int, int]] = []
        radii: list[float] = []
        labels: list[str] = []
        goals: list[tuple[float, ...]] = []
        for t, deg in enumerate(angles_deg):
            q = {a: math.radians(v) for a, v in zip(self.dof, deg, strict=True)}
            strips += [[place(p) for p in strip] for strip in arm_points(topo, q)]
            joints = joint_points(topo, q)
            faulty = faulty_at(spans, e, n, t)
            for a, xy in joints.items():
                points.append(place(xy))
                colours.append(FAULT if a in faulty else ARM)
                radii.append((0.3 if a in faulty else 0.15) * size)
                labels.append(f"{a} {faulty[a]}" if a in faulty else a)
            goals.append(place(path[t] if path else goal))
        k, m = len(topo.end_effectors), len(topo.order)
        arm = self.Strips.columns(strips=strips, colors=[ARM] * len(strips), radii=[0.06 * size] * len(strips))
        s.send_columns("world/arm", indexes=times, columns=arm.partition([k] * n))
        joints_cols = self.Points.columns(positions=points, colors=colours, radii=radii, labels=labels)
        s.send_columns("world/joints", indexes=times, columns=joints_cols.partition([m] * n))
        goal_cols = self.Points.columns(positions=goals, colors=[GOAL] * n, radii=[0.25 * size] * n)
        s.send_columns("world/goal", indexes=times, columns=goal_cols.partition([1] * n))
        if len(errors) >= n:
            s.send_columns("error/step", indexes=times, columns=rr.Scalars.columns(scalars=errors[:n]))
        for ev in events:
            s.set_time("step", sequence=first + int(ev["step"]))
            s.set_time("epoch", sequence=e)
            s.set_time("step_in_epoch", sequence=int(ev["step"]))
            text = f"{ev.get('event')} {ev.get('target')}: {ev.get('detail', '')}"
            s.log("events", rr.TextLog(text, level=rr.TextLogLevel.WARN))
        s.set_time("step", sequence=first + max(n - 1, 0))
        s.log("error/final_of_epoch", rr.Scalars(float(row["final_error"])))
        s.log("error/mean_of_epoch", rr.Scalars(float(row["mean_error"])))
        lost = [sp for sp in spans if sp.fault == "lost"]
        for a in self.dof:  # liveliness: 0 while the agent is lost (its parent stands in)
            down = [w for sp in lost if sp.target == a and (w := sp.within(e, n)) is not None]
            alive = [0.0 if any(lo <= t < hi for lo, hi in down) else 1.0 for t in range(n)]
            s.send_columns(f"agents/{a}/alive", indexes=times, columns=rr.Scalars.columns(scalars=alive))

    def agents(self, rows: Sequence[dict[str, Any]]) -> None:
        """What each agent saw and chose (agents.jsonl rows of one epoch): its state variables, action, E of
        Eq. 9 per own action, P of Eq. 7 per visible child and action."""
        rr, s = self.rr, self.stream
        for row in rows:
            a, e, steps = row["agent"], int(row["epoch"]), row["steps"]
            if not steps:
                continue
            first = e * self.cfg.steps
            times = [
                rr.TimeColumn("step", sequence=[first + t for t in steps]),
                rr.TimeColumn("epoch", sequence=[e] * len(steps)),
                rr.TimeColumn("step_in_epoch", sequence=steps),
            ]

            def column(path: str, values: Sequence[float], times: list[Any] = times) -> None:
                s.send_columns(path, indexes=times, columns=rr.Scalars.columns(scalars=values))

            column(f"agents/{a}/action", [x - 1 for x in row["actions"]])  # -1, 0, +1: decrease, keep, increase
            for i, name in enumerate(row["names"]):
                column(f"agents/{a}/state/{name}", [st[i] for st in row["states"]])
            for i, act in enumerate(ACTIONS):
                column(f"agents/{a}/E/{act}", [x[i] for x in row["E"]])
            visible = [c for c in self.topo.agents[a].children if self.topo.agents[c].has_dof]
            for j, child in enumerate(visible):
                for i, act in enumerate(ACTIONS):
                    column(f"agents/{a}/P/{child}/{act}", [p[j * len(ACTIONS) + i] for p in row["P"]])


def record_run(run_dir: Path, stream: Any) -> int:
    """Log a finished run directory into `stream`; returns the epochs recorded."""
    from kinswarm.actors.report.animate import read_poses

    cfg = load_run_config(run_dir / "config.json")
    poses = read_poses(run_dir)
    if not poses:
        raise ConfigError(f"{run_dir}: no poses.jsonl rows to show (a run from before poses were recorded?)")
    placed = events_by_epoch(read_events(run_dir))
    traces = read_agent_rows(run_dir)
    rec = Recorder(cfg, stream)
    done = 0
    for row in read_metrics(run_dir):
        if (e := row["epoch"]) in poses:
            rec.epoch(row, poses[e], placed.get(e, []))
            rec.agents(traces.get(e, []))
            done += 1
    return done


def shown_epochs(run_dir: Path) -> list[int]:
    """The epochs `record_run` shows: those with both a metrics row and their poses."""
    from kinswarm.actors.report.animate import read_poses

    poses = read_poses(run_dir)
    if not poses or not (run_dir / "metrics.jsonl").exists():
        return []
    return [r["epoch"] for r in read_metrics(run_dir) if r.get("epoch") in poses]


def read_agent_rows(run_dir: Path) -> dict[int, list[dict[str, Any]]]:
    """agents.jsonl (run.record_agents) by epoch; {} for a run that did not record its agents."""
    path = run_dir / "agents.jsonl"
    out: dict[int, list[dict[str, Any]]] = {}
    for row in read_jsonl(path) if path.exists() else []:
        out.setdefault(int(row.get("epoch", -1)), []).append(row)
    return out


def check_view(view: str) -> None:
    """`--view here|web|FILE.rrd`: the extra is installed and the target is one of those, or one line."""
    rerun_module()
    if view == "here":
        check_screen()
    if view in ("here", "web"):
        return
    if not view.endswith(".rrd"):
        raise ConfigError(f"--view {view!r}: expected here, web or a FILE.rrd to write")
    if not Path(view).parent.is_dir():
        raise ConfigError(f"--view {view}: no such directory {Path(view).parent}")


def open_stream(run_id: str, save: Path | None = None, web: bool = False) -> Any:
    """A recording stream to a file (`save`), a viewer served from this machine (`web`), or a viewer spawned here."""
    rr = rerun_module()
    stream = rr.RecordingStream(APP, recording_id=run_id, send_properties=False)
    if save is not None:
        stream.save(str(save))
    elif web:
        uri = rr.serve_grpc(recording=stream)
        rr.serve_web_viewer(connect_to=uri, open_browser=False)
        print(f"kinswarm: the viewer is served on http://localhost:9090 (recording {uri})")
    else:
        spawn_viewer(stream)
    return stream


def check_screen() -> None:
    if sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ConfigError("no screen here to open the viewer on: `web` serves it for a browser, or save a .rrd")


def spawn_viewer(stream: Any) -> None:
    """The viewer on this machine's screen (the `rerun` executable next to this Python, as the extra installs it),
    or one line saying what to do instead."""
    check_screen()
    rr = rerun_module()
    exe = Path(sys.executable).parent / "rerun"
    try:
        rr.spawn(recording=stream, executable_path=str(exe) if exe.exists() else None)
    except RuntimeError as e:
        raise ConfigError(f"cannot start the rerun viewer: {str(e).splitlines()[0]}") from None


class LiveRecording:
    """`kinswarm run … --view`: each epoch into the viewer as it ends. The supervisor hands the finished epoch to
    a process of its own and goes on: the logging never holds the GIL the actors' loop needs. Measured with
    `python benchmarks/recording_cost.py --repeats 5 --epochs 3 --steps 300` on a 2-core machine busy with other
    runs: a thread logging step by step made the run 0.57 as fast; this process, logging in columns, 0.91
    (median of paired ratios; medians 720 steps/s without, 760 with: within that machine's noise)."""

    def __init__(self, cfg: RunConfig, view: str) -> None:
        self.view, self.out = view, cfg.out
        ctx = multiprocessing.get_context("spawn")
        self.queue: Any = ctx.Queue()
        config = Path(cfg.out) / "config.json"
        self.proc = ctx.Process(target=_live, args=(str(config), view, self.queue), name="kinswarm-view", daemon=True)
        self.proc.start()

    def epoch(self, row: dict[str, Any], angles: Sequence[Sequence[float]]) -> None:
        self.queue.put({**row, "angles_deg": [[math.degrees(q) for q in step] for step in angles]})

    def close(self, timeout: float = 60.0) -> None:
        """Let the recorder log what is queued, end its stream (a file gets its footer) and exit."""
        self.queue.put(None)
        self.proc.join(timeout)
        if self.proc.is_alive():
            log.warning("viewer: the recorder did not finish within %.0f s; stopped", timeout)
            self.proc.kill()
            self.proc.join()
        if self.view == "web":  # the served viewer lives in the recorder's process: it went with it
            print(web_gone(self.out), file=sys.stderr, flush=True)


def web_gone(out: str) -> str:
    """What `--view web` says when its viewer goes away with the run, and how to see the run again."""
    return f"kinswarm: the live viewer stopped with the run; `kinswarm view {out} --web` serves the whole run again"


def serve_until_interrupted() -> None:
    """`kinswarm view … --web`: the viewer is served from this process, so it waits here until Ctrl-C, then ends the
    process at once. Left to the interpreter's exit, the served stream's own shutdown (RecordingStream.__del__, rerun's
    atexit flush) ran with the interrupt and printed `Exception ignored in: RecordingStream.__del__`; nothing it
    would flush has anywhere to go once the process that serves it ends."""
    print("kinswarm: serving; Ctrl-C to stop", flush=True)
    try:
        while True:
            time.sleep(3600)
    except KeyboardInterrupt:
        print("kinswarm: the viewer stopped", file=sys.stderr, flush=True)
        sys.stdout.flush()
        os._exit(130)


def _live(config: str, view: str, rows: Any) -> None:
    """The recorder process: one epoch at a time from `rows` until None."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C is the run's; it ends us through close()
    cfg = load_run_config(Path(config))
    save = None if view in ("here", "web") else Path(view)
    try:
        stream = open_stream(cfg.run_id, save=save, web=view == "web")
    except (ConfigError, OSError, RuntimeError) as e:  # the run goes on without a viewer
        log.warning("viewer: not recording (%s)", e)
        while rows.get() is not None:
            pass
        return
    rec = Recorder(cfg, stream)
    out = Path(config).parent
    while (row := rows.get()) is not None:
        try:
            rec.epoch(row, row.pop("angles_deg"), events_by_epoch(read_events(out)).get(row["epoch"], []))
            rec.agents(read_agent_rows(out).get(row["epoch"], []))  # those in by now; `kinswarm view` has all
        except Exception as e:  # the viewer went away: the run goes on without it
            log.warning("viewer: stopped recording (%s)", e)
            break
    stream.flush()
    stream.disconnect()
