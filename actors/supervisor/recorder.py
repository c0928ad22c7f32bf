"""What a run leaves behind while it runs: `events.jsonl` (faults, detections, restarts, re-wirings, hand-backs,
each with its epoch and step and the time), `metrics.jsonl` (one row per epoch) and `poses.jsonl` (the robot's
joint angles after every step, one row per epoch: what `kinswarm animate` draws). Each row is flushed as it is
written, so a killed supervisor leaves every whole row behind; a row it left torn is ended before the next is
appended (else the two would read as one bad row, and the next would be lost with it).

A record that cannot be written (a full disk, a directory made read-only) stops the run with one line naming the file
and the cause (RecordError), its checkpoints and whole rows kept: `--resume` goes on once the cause is gone. An event
that cannot be written is said in the log instead (events are written while the run fails, too)."""

from __future__ import annotations

import json
import logging
import math
import os
import time
from pathlib import Path
from typing import IO, Any

from kinswarm.protocol.messages import AgentTrace, EpochDone

from .result import RecordError, cannot_write

log = logging.getLogger("kinswarm.supervisor")


def open_append(path: Path) -> IO[str]:
    """`path` opened to append rows, a torn last line (a writer killed mid-row) ended first."""
    f = open(path, "a+", encoding="utf-8")  # noqa: SIM115 -- the caller closes it
    try:
        size = os.fstat(f.fileno()).st_size
        if size and os.pread(f.fileno(), 1, size - 1) != b"\n":
            f.write("\n")
            f.flush()
    except BaseException:
        f.close()
        raise
    return f


class Recorder:
    def __init__(self, out: Path) -> None:
        self.out = out
        self.t0 = time.monotonic()
        self._events: IO[str] | None = None
        self._metrics: IO[str] | None = None
        self._poses: IO[str] | None = None
        self._agents: IO[str] | None = None
        self._unwritten: set[str] = set()  # the files whose failure was said (once each)

    def _open(self, name: str) -> IO[str]:
        try:
            return open_append(self.out / name)
        except OSError as e:
            raise RecordError(cannot_write(self.out / name, e)) from None

    def _write(self, f: IO[str], text: str) -> None:
        try:
            f.write(text)
            f.flush()
        except OSError as e:
            raise RecordError(cannot_write(f.name, e)) from None

    def open_events(self) -> None:
        self._events = self._open("events.jsonl")

    def open_metrics(self) -> None:
        self._metrics = self._open("metrics.jsonl")
        self._poses = self._open("poses.jsonl")

    def event(self, epoch: int, step: int | None, event: str, target: str, detail: str, **extra: object) -> None:
        row: dict[str, Any] = {
            "t": round(time.monotonic() - self.t0, 4),
            "wall": round(time.time(), 4),
            "epoch": epoch,
            "step": step,
            "event": event,
            "target": target,
            "detail": detail,
            **extra,
        }
        log.info("event %s", row)
        if self._events is not None and not self._events.closed:
            try:
                self._write(self._events, json.dumps(row) + "\n")
            except RecordError as e:  # said once; the run's end says why it failed
                if "events.jsonl" not in self._unwritten:
                    self._unwritten.add("events.jsonl")
                    log.error("%s (events from here on are in this log only)", e)
                log.warning("event not recorded: %s", row)

    def epoch(self, d: EpochDone) -> None:
        row: dict[str, Any] = {
            "epoch": d.epoch,
            "final_error": d.final_error,
            "mean_error": d.mean_error,
            "steps": d.steps,
            "seconds": d.seconds,
            "missed_cmds": d.missed_cmds,
            "max_step_seconds": d.max_step_seconds,
            "final_angles_deg": {a: round(math.degrees(q), 4) for a, q in d.final_angles.items()},
            "errors": [round(e, 5) for e in d.errors],
        }
        if d.traces:  # the scene's per-step series (refused moves and clearance among walls, a grasp's forces)
            row["traces"] = d.traces
        if d.fleet:  # a fleet: the row is robot 0's; this is every robot's final error
            row["fleet_final_error"] = d.fleet
        assert self._metrics is not None
        self._write(self._metrics, json.dumps(row) + "\n")
        if d.angles and self._poses is not None:  # degrees to 0.001: a pose to well under a pixel
            pose = {"epoch": d.epoch, "angles_deg": [[round(math.degrees(q), 3) for q in step] for step in d.angles]}
            self._write(self._poses, json.dumps(pose, separators=(",", ":")) + "\n")

    def agent(self, tr: AgentTrace) -> None:
        """One agent's epoch (run.record_agents): agents.jsonl, opened at the first."""
        if self._agents is None:
            self._agents = self._open("agents.jsonl")
        if not self._agents.closed:
            row = {k: getattr(tr, k) for k in ("epoch", "agent", "names", "steps", "states", "actions")}
            row.update({"E": tr.expected, "P": tr.beliefs})
            self._write(self._agents, json.dumps(row, separators=(",", ":")) + "\n")

    def close(self) -> None:
        for f in (self._metrics, self._poses, self._agents, self._events):
            if f is not None:
                try:
                    f.close()  # what a full disk left in the buffer is lost with it: the rows before it are whole
                except OSError as e:
                    log.error("%s", cannot_write(f.name, e))
