"""Plots from a run directory alone: with events and per-step errors, and for runs from before both."""

from __future__ import annotations

import json
import math
from pathlib import Path

from conftest import run_config
from kinswarm.actors.report import events_by_epoch, read_events, write_plots


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
    by = events_by_epoch(events)
    assert sorted(by) == [1, 4] and len(by[1]) == 3  # the unplaced event is left out


def test_old_runs_still_get_their_plots(tmp_path, chain4):
    run = make_run(tmp_path, chain4, errors=False, events=None)
    assert [p.name for p in write_plots(run)] == ["learning_curve.png", "arm.png"]
    assert read_events(run) == []


def test_tracking_without_events_shows_the_last_epoch(tmp_path, chain4):
    run = make_run(tmp_path, chain4, errors=True, events=None)
    assert [p.name for p in write_plots(run)][-1] == "tracking.png"


def test_a_lasting_fault_is_a_span_and_close_labels_are_one():
    """A lock lasts until freed (over whole later epochs), a disturbance until it ends, a model fault until
    freed; a fault the scenario applies again every epoch continues its span; events closer than 3 % of the
    epoch share one label."""
    from kinswarm.actors.report.timeline import Span, active_at_end, fault_spans, label_groups

    events = [
        ev(1, 10, "lock", "a2"),
        ev(2, 0, "lock", "a2"),  # the scenario's step-0 lock again: the same span
        ev(3, 40, "free", "a2"),
        ev(2, 5, "disturb", "a4"),
        ev(2, 25, "disturb_end", "a4"),
        ev(3, 60, "reverse", "a1"),
        ev(-1, -1, "reverse", "a3"),  # not placed: left out
    ]
    spans = fault_spans(events)
    assert spans == [
        Span("a2", "lock", (1, 10), (3, 40)),
        Span("a4", "disturb", (2, 5), (2, 25)),
        Span("a1", "reverse", (3, 60), None),
    ]
    lock, disturb, rev = spans
    assert [lock.within(e, 100) for e in range(5)] == [None, (10, 100), (0, 100), (0, 40), None]
    assert disturb.within(2, 100) == (5, 25) and rev.within(7, 100) == (0, 100)
    assert active_at_end(events) == {"a1": ["reversed"]}
    close = [ev(0, 30, "lost", "a2"), ev(0, 31, "adopt", "a2"), ev(0, 31, "adopt", "a3"), ev(0, 60, "handback", "a2")]
    assert label_groups(close, 100) == [(30, "lost a2 · adopt a2,a3"), (60, "handback a2")]


def test_animation_of_the_chosen_epochs(tmp_path, chain4, capsys):
    """`kinswarm animate`: a GIF of the first, the last and the epochs with events (a frame for the start pose and
    at most FRAMES_PER_EPOCH more per epoch); a run without poses, or a bad --epochs, is one line."""
    from kinswarm.actors.cli.commands import main as cli_main
    from kinswarm.actors.report.animate import pick_epochs, read_poses
    from PIL import Image

    run = make_run(tmp_path, chain4, errors=True, events=[ev(2, 30, "lock", "a2"), ev(2, 31, "lost", "a3")])
    assert cli_main(["animate", str(run)]) == 2
    assert "no poses.jsonl rows" in capsys.readouterr().err
    poses = [{"epoch": e, "angles_deg": [[5.0 + s * 0.1, 20.0, 40.0, 50.0] for s in range(100)]} for e in range(6)]
    (run / "poses.jsonl").write_text("".join(json.dumps(p) + "\n" for p in poses) + '{"epoch": 6, "ang')  # torn
    assert sorted(read_poses(run)) == list(range(6))
    assert pick_epochs(list(range(6)), [2]) == [0, 2, 5]
    assert pick_epochs(list(range(20)), list(range(1, 19))) == [0, 15, 16, 17, 18, 19]
    assert cli_main(["animate", str(run), "--epochs", "0,2"]) == 0
    gif = run / "motion.gif"
    with Image.open(gif) as im:
        assert im.n_frames == 2 * (1 + 50 + 1)  # the start pose, every second of the 100 steps, and the last
    assert cli_main(["animate", str(run), "--epochs", "9"]) == 2
    assert "no poses for epoch(s) [9]" in capsys.readouterr().err
    assert cli_main(["animate", str(run), "--epochs", "x"]) == 2
    assert "--epochs: expected epochs like 0,5,9" in capsys.readouterr().err
