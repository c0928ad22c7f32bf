"""Runs side by side on one machine, none aware of the others: with no --listen each takes a free port, records it in
its run directory, and `kinswarm status` / `kinswarm fault` reach each run from its id alone."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import EXAMPLES, LOCKSTEP_ARGS, swarm_pids

CHAIN4 = str(EXAMPLES / "chain4.toml")
KINSWARM = [sys.executable, "-m", "kinswarm.actors.cli.entry"]
IDS = ("left", "middle", "right")


def start(cwd: Path, run_id: str, epochs: int, steps: int) -> subprocess.Popen:
    """`kinswarm run` with no --listen and no --out (runs/RUN-ID under `cwd`), process placement."""
    argv = [*KINSWARM, "run", CHAIN4, "--epochs", str(epochs), "--steps", str(steps), "--run-id", run_id]
    argv += ["--placement", "process", "--no-progress", *LOCKSTEP_ARGS]
    return subprocess.Popen(argv, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


def endpoint(run_dir: Path) -> str:
    (where,) = json.loads((run_dir / "net" / "cli.json").read_text())["connect"]
    return where


def stop(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        if p.poll() is None:
            p.send_signal(signal.SIGINT)  # the run stops its swarm and writes its summary
    for p in procs:
        try:
            p.wait(timeout=60)
        except subprocess.TimeoutExpired:
            p.kill()
            p.wait()


@pytest.mark.timeout(600)
def test_three_runs_started_at_once_all_finish(tmp_path):
    procs = [start(tmp_path, run_id, epochs=2, steps=50) for run_id in IDS]
    try:
        outputs = [p.communicate(timeout=500)[0] for p in procs]
    finally:
        stop(procs)
    for run_id, p, text in zip(IDS, procs, outputs, strict=True):
        assert p.returncode == 0, text
        run_dir = tmp_path / "runs" / run_id
        summary = json.loads((run_dir / "summary.json").read_text())
        assert summary["run_id"] == run_id and summary["epochs"] == 2 and len(summary["final_error"]) == 2
        assert not summary["error"] and not summary["interrupted"]
        assert [json.loads(line)["epoch"] for line in (run_dir / "metrics.jsonl").read_text().splitlines()] == [0, 1]
        assert json.loads((run_dir / "config.json").read_text())["listen"] == "auto"
        assert not swarm_pids(str(run_dir / "config.json")), f"{run_id}: actors left running"
    ends = {endpoint(tmp_path / "runs" / r) for r in IDS}
    assert len(ends) == 3 and not any(e.endswith(":7447") for e in ends), ends


def wait_running(run_dir: Path, proc: subprocess.Popen, timeout: float = 300.0) -> None:
    """Until the run's first epoch is done (every actor alive, its endpoint recorded)."""
    deadline = time.monotonic() + timeout
    metrics = run_dir / "metrics.jsonl"
    while not (metrics.exists() and metrics.read_text().strip()):
        assert proc.poll() is None, proc.communicate()[0]
        assert time.monotonic() < deadline, f"{run_dir.name}: no epoch within {timeout} s"
        time.sleep(0.2)


def tool(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([*KINSWARM, *args], cwd=cwd, capture_output=True, text=True, timeout=120)


def faults_of(run_dir: Path) -> list[str]:
    rows = [json.loads(line) for line in (run_dir / "events.jsonl").read_text().splitlines()]
    return [f"{r['event']} {r['target']}" for r in rows if r["event"] == "fault"]


# ~1.5 minutes: slow suite; three runs started at once (below) keep side by side runs in the default
@pytest.mark.slow
@pytest.mark.timeout(600)
def test_status_and_fault_reach_each_run_from_its_id(tmp_path):
    procs = [start(tmp_path, run_id, epochs=10_000, steps=50) for run_id in IDS]  # ended by the test
    dirs = [tmp_path / "runs" / r for r in IDS]
    try:
        for run_dir, p in zip(dirs, procs, strict=True):
            wait_running(run_dir, p)
        for i, run_id in enumerate(IDS):
            status = tool(tmp_path, "status", run_id)
            assert status.returncode == 0, status.stderr
            assert status.stdout.startswith(f"run {run_id}  epoch"), status.stdout
            assert "a2" in status.stdout and "sim" in status.stdout
            by_dir = tool(tmp_path, "status", f"runs/{run_id}")  # its directory alone finds it too
            assert by_dir.returncode == 0 and by_dir.stdout.startswith(f"run {run_id}  epoch"), by_dir.stderr
            fault = tool(tmp_path, "fault", run_id, "lock", "a2")
            assert fault.returncode == 0, fault.stderr
            assert fault.stdout.startswith(f"{run_id}: lock a2"), fault.stdout
            # that run and no other: the ones faulted so far hold it, the others not yet
            for j, run_dir in enumerate(dirs):
                assert faults_of(run_dir) == (["fault a2"] if j <= i else []), (run_id, run_dir.name)
    finally:
        stop(procs)
    for run_dir, p in zip(dirs, procs, strict=True):
        assert p.returncode == 130, p.stdout.read() if p.stdout else ""  # interrupted by the test, summary written
        assert json.loads((run_dir / "summary.json").read_text())["interrupted"]
        assert not swarm_pids(str(run_dir / "config.json"))
    assert all(os.path.exists(d / "net" / "cli.json") for d in dirs)
