"""What a run leaves behind while it runs: `events.jsonl` (faults, detections, restarts, re-wirings, hand-backs,
each with its epoch and step and the time), `metrics.jsonl` (one row per epoch) and `poses.jsonl` (the robot's
joint angles after every step, one row per epoch: what `kinswarm animate` draws). Each row is flushed as it is
written, so a killed supervisor leaves every whole row behind."""

from __future__ import annotations

import json
import logging
import math
import time
from pathlib import Path
from typing import IO, Any

from kinswarm.protocol.messages import AgentTrace, EpochDone

log = logging.getLogger("kinswarm.supervisor")


class Recorder:
    def __init__(self, out: Path) -> None:
        self.out = out
        self.t0 = time.monotonic()
        self._events: IO[str] | None = None
        self._metrics: IO[str] | None = None
        self._poses: IO[str] | None = None
        self._agents: IO[str] | None = None

    def open_events(self) -> None:
        self._events = open(self.out / "events.jsonl", "a")  # noqa: SIM115 -- closed in close()

    def open_metrics(self) -> None:
        self._metrics = open(self.out / "metrics.jsonl", "a")  # noqa: SIM115 -- closed in close()
        self._poses = open(self.out / "poses.jsonl", "a")  # noqa: SIM115 -- closed in close()

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
            self._events.write(json.dumps(row) + "\n")
            self._events.flush()

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
        self._metrics.write(json.dumps(row) + "\n")
        self._metrics.flush()
        if d.angles and self._poses is not None:  # degrees to 0.001: a pose to well under a pixel
            pose = {"epoch": d.epoch, "angles_deg": [[round(math.degrees(q), 3) for q in step] for step in d.angles]}
            self._poses.write(json.dumps(pose, separators=(",", ":")) + "\n")
            self._poses.flush()

    def agent(self, tr: AgentTrace) -> None:
        """One agent's epoch (run.record_agents): agents.jsonl, opened at the first."""
        if self._agents is None:
            self._agents = open(self.out / "agents.jsonl", "a")  # noqa: SIM115 -- closed in close()
        if not self._agents.closed:
            row = {k: getattr(tr, k) for k in ("epoch", "agent", "names", "steps", "states", "actions")}
            row.update({"E": tr.expected, "P": tr.beliefs})
            self._agents.write(json.dumps(row, separators=(",", ":")) + "\n")
            self._agents.flush()

    def close(self) -> None:
        for f in (self._metrics, self._poses, self._agents, self._events):
            if f is not None:
                f.close()
