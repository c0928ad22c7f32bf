"""Plots from a run directory alone: with events and per-step errors, and for runs from before both."""

from __future__ import annotations

import json
import math
from pathlib import Path

from conftest import run_config
from kinswarm.actors.report import _events_by_epoch, read_events, write_plots


def make_run(tmp_path: Path, chain4: Path, *, errors: bool, events: list[dict] | None) -> Path:
    run = tmp_path / "run"
    run.mkdir()
    run_config(chain4, run_id="r", out=str(run), steps=100).write(run / "config.json")
    rows = []
    for epoch in range(6):
        errs = [3.0 * math.exp(-s / (20 + epoch)) + 0.05 for s in range(100)]
        row = {
            "epoch": epoch,
            "final_error": errs[-1],
            "mean_error": sum(errs) / 100,
            "steps": 100,
            "seconds": 1.0,
            "missed_cmds": 0,
            "final_angles_deg": {"a1": 5.0, "a2": 20.0, "a3": 40.0, "a4": 50.0},
        }
        if errors:
            row["errors"] = errs
        rows.append(row)
    (run / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    if events is not None:
        (run / "events.jsonl").write_text("".join(json.dumps(e) + "\n" for e in events))
    return run


def ev(epoch: int, step: int, event: str, target: str) -> dict:
    return {"t": 1.0, "wall": 1.7e9, "epoch": epoch, "step": step, "event": event, "target": target, "detail": ""}


def test_plots_with_events_and_errors(tmp_path, chain4):
    events = [
        ev(1, 0, "lock", "a2"),
        ev(1, 0, "lock", "a3"),
        ev(1, 40, "free", "a3"),
        ev(4, 10, "kill", "a1"),
        ev(-1, -1, "detect", "a1"),
    ]
    run = make_run(tmp_path, chain4, errors=True, events=events)
    written = write_plots(run)
    assert [p.name for p in written] == ["learning_curve.png", "arm.png", "tracking.png"]
    assert all(p.stat().st_size > 1000 for p in written)
    assert read_events(run) == events
    by = _events_by_epoch(events)
    assert sorted(by) == [1, 4] and len(by[1]) == 3  # the unplaced event is left out


def test_old_runs_still_get_their_plots(tmp_path, chain4):
    run = make_run(tmp_path, chain4, errors=False, events=None)
    assert [p.name for p in write_plots(run)] == ["learning_curve.png", "arm.png"]
    assert read_events(run) == []


def test_tracking_without_events_shows_the_last_epoch(tmp_path, chain4):
    run = make_run(tmp_path, chain4, errors=True, events=None)
    assert [p.name for p in write_plots(run)][-1] == "tracking.png"
