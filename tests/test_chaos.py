"""Every fault at once, and what it found: the supervisor's own events at the sim's exact step
(its clock, protocol/clock.py), a restore naming its checkpoint's epoch in a field of its own, one command drawn as
one line, and a process fault refused while the swarm is not training."""

from __future__ import annotations

import time

import pytest
from kinswarm.actors.report.timeline import one_per_command
from kinswarm.protocol.clock import ClockReader, ClockWriter, clock_path
from test_faults import Run


def test_the_clock_reads_what_the_sim_wrote_and_follows_a_new_sim(tmp_path):
    reader = ClockReader(clock_path(tmp_path))
    assert reader.read() is None  # no sim on this host (yet)
    first = ClockWriter(clock_path(tmp_path))
    assert reader.read() == (-1, 0)  # a sim that has run no step
    first.set(0, 0)
    assert reader.read() == (0, 0)
    first.set(41, 4999)
    assert reader.read() == (41, 4999)
    second = ClockWriter(clock_path(tmp_path))  # a resumed run's sim: a new file, not one truncated under the map
    second.set(7, 3)
    assert reader.read() == (7, 3)
    first.set(50, 1)  # the old sim's map is no longer the run's clock
    assert reader.read() == (7, 3)
    for c in (first, second, reader):
        c.close()


def _ev(event: str, target: str, epoch: int, step: int, detail: str = "", t: float = 0.0) -> dict:
    return {"event": event, "target": target, "epoch": epoch, "step": step, "detail": detail, "t": t}


def test_one_command_is_one_line():
    events = [
        _ev("fault", "a2", 3, 262, "lock a2"),  # the request, as the supervisor passed it on
        _ev("lock", "a2", 3, 263, "locked at 10.0 deg"),  # the sim's record of it: the line drawn
        _ev("fault", "a3", 3, 300, "kill a3 (kill: a3)"),  # a process fault: only the supervisor records it
        _ev("scenario", "a1", 4, 10, "freeze a1 seconds=2 requested"),
        _ev("fault", "a1", 4, 11, "freeze a1 seconds=2 (freeze: a1)"),
        _ev("fault", "all", 5, 0, "reverse all"),
        _ev("reverse", "a4", 5, 0, "reversed"),
    ]
    kept = one_per_command(events)
    assert [(e["event"], e["target"]) for e in kept] == [
        ("lock", "a2"),
        ("fault", "a3"),
        ("scenario", "a1"),
        ("reverse", "a4"),
    ]


@pytest.mark.timeout(240)
def test_the_supervisors_events_are_at_the_sims_step(tmp_path, chain4):
    """A joint fault's request and its effect at the same step (they were 100-200 steps apart, or at step -1); a
    restore at the moment it happened, its checkpoint's epoch in its own field; a kill refused before training."""
    run = Run(tmp_path, chain4, "--epochs", "5000", "--steps", "200", "--seed", "3")
    while True:  # as soon as the supervisor answers: most likely still starting, so refused, not the run's end
        assert run.proc.poll() is None
        r = run.fault("kill", "a3")
        if r.returncode == 0 or "not training" in r.stdout + r.stderr:
            break
        time.sleep(0.05)  # no config.json yet, or nobody answering on its endpoint yet
    if r.returncode == 2:
        assert "not training" in r.stdout + r.stderr
    run.wait_epochs(2)
    for joint in ("a2", "a4"):
        assert run.fault("lock", joint).returncode == 0
        run.wait_event("lock", joint)
    assert run.fault("kill", "a3").returncode == 0
    restored = run.wait_event("restored", "a3", timeout=120)
    run.proc.send_signal(2)
    code, text = run.finish()
    assert code == 130, text
    ev = run.events()
    for joint in ("a2", "a4"):
        asked = next(e for e in ev if e["event"] == "fault" and e["target"] == joint)
        done = next(e for e in ev if e["event"] == "lock" and e["target"] == joint)
        assert asked["epoch"] == done["epoch"] and abs(asked["step"] - done["step"]) <= 2, (asked, done)
    assert all(e["epoch"] >= 0 and e["step"] >= 0 for e in ev), [e for e in ev if e["step"] < 0]
    restart = next(e for e in ev if e["event"] == "restart" and e["target"] == "a3")
    assert (restored["epoch"], restored["step"]) >= (restart["epoch"], restart["step"])
    assert 0 <= restored["checkpoint_epoch"] < restored["epoch"]
    assert restored["checkpoint_epoch"] >= restored["newest_saved"] >= 0
