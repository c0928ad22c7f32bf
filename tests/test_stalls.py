"""A swarm cannot stall with nobody told. A child killed, then the root frozen: the restarted child waits for its
parent instead of leaving; the supervisor records the stall within its bound, saying what is down and since when,
shows it in `kinswarm status`, records its end after the thaw (`kinswarm fault RUN thaw a1`), and the run finishes.
Frozen past the stall limit, the run ends with an error naming the root. Nothing is left running either way."""

from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import EXAMPLES, free_port, swarm_pids

KINSWARM = [sys.executable, "-m", "kinswarm.actors.cli.entry"]
STALL_S = 3.0


EPOCHS = 16  # the freeze comes ~3 epochs in; the run must outlast it, its status check and the thaw


def _start(out: Path, limit: float) -> subprocess.Popen:
    args = ["run", str(EXAMPLES / "chain4.toml"), "--run-id", "st", "--out", str(out), "--epochs", str(EPOCHS)]
    args += ["--steps", "400", "--deadline-ms", "200", "--set", f"run.stall_s={STALL_S}"]
    args += ["--set", f"run.stall_limit_s={limit}", "--no-progress", "--listen", f"tcp/127.0.0.1:{free_port()}"]
    return subprocess.Popen([*KINSWARM, *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def _cli(out: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*KINSWARM, *args, "--run-dir", str(out)], capture_output=True, text=True, timeout=60)


def _events(out: Path) -> list[dict]:
    return [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]


def _training(out: Path, timeout: float = 60.0) -> None:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if (out / "metrics.jsonl").exists() and (out / "metrics.jsonl").read_text().count("\n") >= 1:
            return
        time.sleep(0.2)
    pytest.fail("the run did not start training")


def _kill_then_freeze_root(out: Path, seconds: str | None) -> float:
    """a2 killed, then a1 frozen (for `seconds`, or until thawed)."""
    assert _cli(out, "fault", "st", "kill", "a2").returncode == 0
    time.sleep(1.0)
    r = _cli(out, "fault", "st", "freeze", "a1", *(("--for", seconds) if seconds else ()))
    assert r.returncode == 0 and "freeze a1" in r.stdout, r.stdout + r.stderr
    return time.monotonic()


# ~1.2 minutes: slow suite; a stall past the limit (below) keeps the stall path in the default
@pytest.mark.slow
@pytest.mark.timeout(240)
def test_a_frozen_root_is_a_stall_seen_recorded_and_over_after_the_thaw(tmp_path):
    out = tmp_path / "r"
    p = _start(out, limit=300)
    try:
        _training(out)
        _kill_then_freeze_root(out, None)  # frozen until thawed: a status started late still sees the stall
        deadline = time.monotonic() + 60.0
        while "stalled" not in (status := _cli(out, "status", "st").stdout) and time.monotonic() < deadline:
            time.sleep(0.5)
        assert "stalled" in status and "down: a1 (frozen)" in status, status
        r = _cli(out, "fault", "st", "thaw", "a1")
        assert r.returncode == 0, r.stdout + r.stderr
        text, _ = p.communicate(timeout=180)
    finally:
        p.kill()
    assert p.returncode == 0, text
    events = _events(out)
    stall = next(e for e in events if e["event"] == "stall")
    end = next(e for e in events if e["event"] == "stall_end")
    freeze = next(e for e in events if e["event"] == "fault" and e["target"] == "a1")
    # seen within the bound (plus the lease a frozen process takes to count as down, 1 s, and a status tick)
    assert stall["target"] == "a1" and stall["t"] - freeze["t"] <= STALL_S + 2.5, (stall, freeze)
    assert "down: a1 (frozen)" in stall["detail"] and end["t"] > stall["t"]
    assert not any(e["event"] == "exited" and e["target"] != "a2" for e in events)  # nobody left while waiting
    assert json.loads((out / "summary.json").read_text())["epochs"] == EPOCHS
    assert swarm_pids(str(out / "config.json")) == []


@pytest.mark.timeout(240)
def test_a_stall_past_the_limit_ends_the_run_naming_the_actor(tmp_path):
    out = tmp_path / "r"
    limit = 6.0
    p = _start(out, limit=limit)
    try:
        _training(out)
        _kill_then_freeze_root(out, "120s")
        text, _ = p.communicate(timeout=120)
    finally:
        p.kill()
    assert p.returncode == 1 and "the run failed: stalled for" in text and "down: a1 (frozen)" in text, text
    events = _events(out)
    freeze = next(e for e in events if e["event"] == "fault" and e["target"] == "a1")
    failed = next(e for e in events if e["event"] == "failed")
    assert "a1 (frozen)" in failed["detail"]
    # the supervisor's own clock (its events' t), not the test's: a loaded machine may take long to shut down, and
    # a status tick (1 s) may pass on either side
    assert failed["t"] - freeze["t"] < 1.5 + STALL_S + limit + 3.0, (freeze, failed)  # the lease, the bound, the limit
    assert swarm_pids(str(out / "config.json")) == []
