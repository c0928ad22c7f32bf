"""A pause (SIGSTOP, then SIGCONT) of the supervisor loses nothing: the replies it waits for (an epoch's end, a
checkpoint's Saved) are asked for again until they come, and a repeated request changes nothing where it lands.

The live test pauses a `process` run's supervisor across an epoch's end (whose EpochDone, put while the links were
down, was lost for good before: `no EpochDone within 180 s`) and holds its final errors to the same seed's run in the
`inprocess` placement (the same numbers in every placement: tests/test_inprocess.py)."""

from __future__ import annotations

import asyncio
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest
from conftest import LIVE, RecordingNode, actor_pids, free_port, run_config, swarm_pids
from kinswarm.actors.simulator.actor import SimActor
from kinswarm.protocol.messages import Cmd, EpochDone, EpochStart

CLI = [sys.executable, "-m", "kinswarm.actors.cli"]
RUN = ("--epochs", "5", "--steps", "150", "--seed", "3")


def _rows(out: Path) -> list[dict]:
    path = out / "metrics.jsonl"
    return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []


def _wait(what: str, ready: Any, proc: subprocess.Popen, guard: float = 300.0) -> Any:
    """Wait for `ready()` (a line of the run's records), the run still going; `guard` only ends a hang."""
    deadline = time.monotonic() + guard
    while time.monotonic() < deadline:
        if (got := ready()) is not None and got is not False:
            return got
        assert proc.poll() is None, f"the run ended before {what}: {proc.stdout.read().decode()}"  # type: ignore[union-attr]
        time.sleep(0.05)
    raise AssertionError(f"no {what} within the {guard:.0f} s hang guard")


@pytest.fixture(scope="module")
def clean_final_errors(tmp_path_factory: pytest.TempPathFactory) -> list[float]:
    """RUN's final errors undisturbed (the inprocess placement: the same numbers as process, without processes)."""
    ref = tmp_path_factory.mktemp("clean") / "ref"
    chain4 = Path(__file__).resolve().parents[1] / "examples" / "chain4.toml"
    clean = subprocess.run(
        [*CLI, "run", str(chain4), *RUN, "--placement", "inprocess", "--out", str(ref), "--no-progress"],
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert clean.returncode == 0, clean.stdout + clean.stderr
    want = [r["final_error"] for r in _rows(ref)]
    assert len(want) == 5
    return want


def _start(out: Path, chain4: Path, *args: str) -> subprocess.Popen:
    argv = [*CLI, "run", str(chain4), *RUN, "--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}", *args]
    proc = subprocess.Popen(
        [*argv, "--no-progress"], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True
    )
    LIVE.append(proc)  # stopped with its actors whatever the outcome (conftest)
    return proc


@pytest.mark.timeout(600)
def test_a_supervisor_paused_3_s_finishes_with_the_clean_runs_final_errors(tmp_path, chain4, clean_final_errors):
    want = clean_final_errors
    out = tmp_path / "paused"
    proc = _start(out, chain4)
    _wait("epoch 1's end", lambda: len(_rows(out)) >= 1, proc)
    os.kill(proc.pid, signal.SIGSTOP)  # the supervisor: the swarm steps on without it, its links lapse
    try:
        time.sleep(3.0)  # the pause itself (what is asserted below waits on the run's records, not on time)
    finally:
        os.kill(proc.pid, signal.SIGCONT)
    text, _ = proc.communicate(timeout=300)
    assert proc.returncode == 0, text.decode()
    assert [r["final_error"] for r in _rows(out)] == want  # to the bit
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    woke = [e for e in events if e["event"] == "woke" and e["target"] == "supervisor"]
    assert woke and woke[0]["seconds"] >= 2.0, events  # it saw its own pause, and said how long
    # its pause is no one's fault: no actor counted lost, no stall
    assert not [e for e in events if e["event"] in ("lost", "stall", "failed")], events
    assert swarm_pids(str(out)) == []


@pytest.mark.slow  # a failed run and its resume against a reference: minutes on 2 cores (`pytest -m slow`)
@pytest.mark.timeout(600)
def test_a_run_that_failed_with_good_checkpoints_resumes_saying_what_failed(tmp_path, chain4, clean_final_errors):
    # No restart allowed: an agent killed after two epochs fails the run (its checkpoints are good)
    out = tmp_path / "failed"
    proc = _start(out, chain4, "--max-restarts", "0", "--run-id", "fr")
    _wait("epoch 1's end", lambda: len(_rows(out)) >= 2, proc)
    (a2,) = actor_pids(out, "agent", "a2")
    os.kill(a2, signal.SIGKILL)  # a crash
    text, _ = proc.communicate(timeout=300)
    summary = json.loads((out / "summary.json").read_text())
    if proc.returncode == 0:  # the kill came after the last epoch's checkpoint: nothing failed, nothing to test
        pytest.skip("the run ended before the kill landed")
    assert proc.returncode == 1 and "restart policy: at most 0" in summary["error"], text.decode()
    resumed = subprocess.run([*CLI, "run", "--resume", str(out), "--no-progress"], capture_output=True, text=True)
    assert resumed.returncode == 0, resumed.stdout + resumed.stderr
    assert "failed (agent a2 exited" in resumed.stderr, resumed.stderr  # it says what failed, and goes on
    assert [r["final_error"] for r in _rows(out)] == clean_final_errors  # to the bit
    final = json.loads((out / "summary.json").read_text())
    assert not final.get("error") and len(final["final_error"]) == 5, final
    resume = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    assert any(e["event"] == "resume" and "after it failed (" in e["detail"] for e in resume), resume
    assert swarm_pids(str(out)) == []


# -- what a repeated request does where it lands ------------------------------------------------------------------


def test_the_sim_answers_a_finished_epochs_start_again_and_ignores_the_running_ones(tmp_path, chain4):
    async def body() -> None:
        cfg = run_config(chain4, run_id="t", out=str(tmp_path), deadline_ms=60_000)
        sim = SimActor(cfg, cfg.topo(), RecordingNode())  # type: ignore[arg-type]
        try:
            start = EpochStart(epoch=0, steps=2, goal=(4.16, 6.18))
            sim._on_epoch(start)
            sim._on_epoch(start)  # asked again while it runs: nothing restarts
            assert sim.t == 0 and sim.node.of(EpochDone) == []
            for t in range(2):
                for a in sorted(sim.waiting):
                    sim._on_cmd(a, Cmd(epoch=0, step=t, delta=0.01))
            (done,) = sim.node.of(EpochDone)
            angles = sim.world.joint_positions()
            sim._on_epoch(start)  # its end was lost: the same end again, the world untouched
            assert sim.node.of(EpochDone) == [done, done]
            assert sim.world.joint_positions() == angles and sim.epoch is None and sim.last_epoch == 0
            sim._on_epoch(EpochStart(epoch=1, steps=2, goal=(4.16, 6.18)))  # the next one starts as ever
            assert sim.epoch is not None and sim.epoch.epoch == 1
            sim._on_epoch(start)  # an older epoch's start: nothing
            assert sim.node.of(EpochDone) == [done, done] and sim.epoch.epoch == 1
        finally:
            sim.world.close()

    asyncio.run(body())


def test_an_agent_answers_a_repeated_checkpoint_request_without_saving_again(tmp_path, chain4):
    from kinswarm.actors.agent.actor import Agent
    from kinswarm.protocol.messages import Checkpoint, Saved

    async def body() -> None:
        cfg = run_config(chain4, run_id="t", out=str(tmp_path))
        node = RecordingNode()
        node.role, node.ident = "agent", "a2"
        agent = Agent(cfg, cfg.topo(), "a2", node)  # type: ignore[arg-type]
        request = Checkpoint(epoch=0, directory=str(tmp_path / "agents"))
        agent.memory.save(request)
        path = tmp_path / "agents" / "a2.npz"
        first = path.stat().st_mtime_ns
        agent.memory.save(request)  # its Saved was lost: the same answer, the file as it was
        (saved, again) = node.of(Saved)
        assert saved == again and saved.epoch == 0 and not saved.error and path.stat().st_mtime_ns == first
        agent.memory.save(Checkpoint(epoch=1, directory=request.directory))  # the next epoch's: saved
        assert [s.epoch for s in node.of(Saved)] == [0, 0, 1]
        agent.memory.save(request)  # a stale one after a newer: no answer, and the newer file stays
        assert [s.epoch for s in node.of(Saved)] == [0, 0, 1]

    asyncio.run(body())
