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
import queue
import threading
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from kinswarm.actors.config import ConfigError, RunConfig, load_run_config
from kinswarm.actors.report import arm_points, joint_points, read_events, read_metrics
from kinswarm.actors.timeline import LASTING, fault_spans

log = logging.getLogger("kinswarm.view")
APP = "kinswarm"
FAULT = (214, 39, 40)
ARM = (31, 119, 180)
GOAL = (255, 200, 0)


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
        from kinswarm.actors.runfile import task_of

        self.task = task_of(cfg)
        self.dof = self.topo.dof_agents
        self.events: list[dict[str, Any]] = []
        self._static()

    def _static(self) -> None:
        rr, topo = self.rr, self.topo
        walls = [o.corners() + [o.corners()[0]] for o in self.cfg.scene_spec.obstacles]
        if walls:
            self.stream.log("world/walls", rr.LineStrips2D(walls, colors=[(90, 90, 90)]), static=True)
        R = topo.reach
        bx, by = topo.base[0], topo.base[1]
        box = [[bx - R, by - R], [bx + R, by - R], [bx + R, by + R], [bx - R, by + R], [bx - R, by - R]]
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
        for t, deg in enumerate(angles_deg):
            s.set_time("step", sequence=first + t)
            s.set_time("epoch", sequence=e)
            s.set_time("step_in_epoch", sequence=t)
            q = {a: math.radians(v) for a, v in zip(self.dof, deg, strict=True)}
            s.log("world/arm", rr.LineStrips2D(arm_points(topo, q), colors=[ARM], radii=0.06))
            joints = joint_points(topo, q)
            faulty = {sp.target: LASTING[sp.fault] for sp in spans if (w := sp.within(e, n)) and w[0] <= t < w[1]}
            names = list(joints)
            s.log(
                "world/joints",
                rr.Points2D(
                    [joints[a] for a in names],
                    colors=[FAULT if a in faulty else ARM for a in names],
                    radii=[0.3 if a in faulty else 0.15 for a in names],
                    labels=[f"{a} {faulty[a]}" if a in faulty else a for a in names],
                ),
            )
            g = path[t] if path else goal
            s.log("world/goal", rr.Points2D([g], colors=[GOAL], radii=0.25))
            if t < len(errors):
                s.log("error/step", rr.Scalars(errors[t]))
        for ev in events:
            s.set_time("step", sequence=first + int(ev["step"]))
            s.set_time("epoch", sequence=e)
            s.set_time("step_in_epoch", sequence=int(ev["step"]))
            text = f"{ev.get('event')} {ev.get('target')}: {ev.get('detail', '')}"
            s.log("events", rr.TextLog(text, level=rr.TextLogLevel.WARN))
        s.set_time("step", sequence=first + max(n - 1, 0))
        s.log("error/final_of_epoch", rr.Scalars(float(row["final_error"])))
        s.log("error/mean_of_epoch", rr.Scalars(float(row["mean_error"])))


def _placed(events: list[dict[str, Any]], epoch: int) -> list[dict[str, Any]]:
    return [ev for ev in events if ev.get("epoch") == epoch and isinstance(ev.get("step"), int) and ev["step"] >= 0]


def record_run(run_dir: Path, stream: Any) -> int:
    """Log a finished run directory into `stream`; returns the epochs recorded."""
    from kinswarm.actors.animate import read_poses

    cfg = load_run_config(run_dir / "config.json")
    poses = read_poses(run_dir)
    if not poses:
        raise ConfigError(f"{run_dir}: no poses.jsonl rows to show (a run from before poses were recorded?)")
    events = read_events(run_dir)
    rec = Recorder(cfg, stream)
    done = 0
    for row in read_metrics(run_dir):
        if (e := row["epoch"]) in poses:
            rec.epoch(row, poses[e], _placed(events, e))
            done += 1
    return done


def check_view(view: str) -> None:
    """`--view here|web|FILE.rrd`: the extra is installed and the target is one of those, or one line."""
    rerun_module()
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
        stream.spawn()
    return stream


class LiveRecording:
    """`kinswarm run … --view`: each epoch into the viewer as it ends. The supervisor hands over the finished
    epoch and goes on; a background thread does the logging, so the steps never wait for the viewer."""

    def __init__(self, cfg: RunConfig, view: str) -> None:
        self.out = Path(cfg.out)
        save = None if view in ("here", "web") else Path(view)
        self.stream = open_stream(cfg.run_id, save=save, web=view == "web")
        self.rec = Recorder(cfg, self.stream)
        self.queue: queue.Queue[dict[str, Any] | None] = queue.Queue()
        self.thread = threading.Thread(target=self._drain, name="kinswarm-view", daemon=True)
        self.thread.start()

    def epoch(self, row: dict[str, Any], angles: Sequence[Sequence[float]]) -> None:
        self.queue.put({**row, "angles_deg": [[math.degrees(q) for q in step] for step in angles]})

    def close(self, timeout: float = 30.0) -> None:
        """Log what is queued, then flush and end the stream (a file gets its footer)."""
        self.queue.put(None)
        self.thread.join(timeout)
        self.stream.flush()
        self.stream.disconnect()

    def _drain(self) -> None:
        while (row := self.queue.get()) is not None:
            events = _placed(read_events(self.out), row["epoch"])
            try:
                self.rec.epoch(row, row.pop("angles_deg"), events)
            except Exception as e:  # the viewer went away: the run goes on without it
                log.warning("viewer: stopped recording (%s)", e)
                return
