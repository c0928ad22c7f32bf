"""Faults on a running swarm, injected the way a user does it: `kinswarm run` in one process and
`kinswarm fault` / `kinswarm status` from another, over real Zenoh sessions on loopback."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import LIVE, free_port, swarm_pids

pytestmark = pytest.mark.timeout(240)

CLI = [sys.executable, "-m", "kinswarm.actors.cli"]


class Run:
    """`kinswarm run` as a child process, stopped (and checked for leftovers) by the test."""

    def __init__(self, tmp: Path, topo: Path, *args: str, run_id: str = "ft") -> None:
        self.out = tmp / run_id
        self.run_id = run_id
        self.endpoint = f"tcp/127.0.0.1:{free_port()}"
        argv = [*CLI, "run", str(topo), "--run-id", run_id, "--out", str(self.out), "--listen", self.endpoint]
        self.proc = subprocess.Popen(
            [*argv, "--no-progress", *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True
        )
        LIVE.append(self.proc)  # stopped with its actors when the test ends, whatever its outcome (conftest)

    def wait_epochs(self, n: int, timeout: float = 90.0) -> None:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            assert self.proc.poll() is None, self.proc.stdout.read().decode()  # type: ignore[union-attr]
            path = self.out / "metrics.jsonl"
            if path.exists() and len(path.read_text().splitlines()) >= n:
                return
            time.sleep(0.1)
        raise AssertionError(f"fewer than {n} epochs after {timeout} s")

    def wait_event(self, event: str, target: str, timeout: float = 30.0, after: float = -1.0) -> dict:
        """The first `event` of `target` logged later than `after` (the run's clock `t` of an earlier event)."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            for e in self.events():
                if e["event"] == event and e["target"] == target and e["t"] > after:
                    return e
            time.sleep(0.05)
        raise AssertionError(f"no {event} {target} within {timeout} s: {self.events()}")

    def cli(self, *args: str) -> subprocess.CompletedProcess:
        return subprocess.run([*CLI, *args, "--run-dir", str(self.out)], capture_output=True, text=True, timeout=60)

    def fault(self, *args: str) -> subprocess.CompletedProcess:
        return self.cli("fault", self.run_id, *args)

    def finish(self, timeout: float = 180.0) -> tuple[int, str]:
        try:
            text, _ = self.proc.communicate(timeout=timeout)
        finally:
            if self.proc.poll() is None:
                self.proc.kill()
                self.proc.wait()
        return self.proc.returncode, text.decode()

    def events(self) -> list[dict]:
        path = self.out / "events.jsonl"
        return [json.loads(line) for line in path.read_text().splitlines()] if path.exists() else []

    def summary(self) -> dict:
        return json.loads((self.out / "summary.json").read_text())


def test_kill_each_agent_in_turn_restarts_it_from_its_checkpoint(tmp_path, chain4):
    # Each agent is killed once the one before is back (its token alive again), so the kills never overlap however
    # slow the machine; the run is long enough that it cannot end before them and is ended by Ctrl-C.
    run = Run(tmp_path, chain4, "--epochs", "5000", "--steps", "200", "--seed", "5")
    run.wait_epochs(2)
    for agent in ("a1", "a2", "a3", "a4"):
        r = run.fault("kill", agent)
        assert r.returncode == 0 and f"kill: {agent}" in r.stdout, r.stderr
        run.wait_event("alive", agent, timeout=120, after=run.wait_event("exited", agent, timeout=120)["t"])
    back_at = len((run.out / "metrics.jsonl").read_text().splitlines())
    run.wait_epochs(back_at + 2, timeout=120)  # the run went on with all four back
    run.proc.send_signal(2)  # Ctrl-C
    code, text = run.finish()
    assert code == 130, text
    assert "liveliness token(s) went away while training" in text  # the command tells what summary.json counts
    ev = run.events()
    for agent in ("a1", "a2", "a3", "a4"):
        mine = [e for e in ev if e["target"] == agent]
        kinds = [e["event"] for e in mine]
        assert "exited" in kinds and "restart" in kinds and "restored" in kinds, kinds
        killed = kinds.index("exited")
        assert "alive" in kinds[killed:], kinds  # back after its kill
        restored = next(e["detail"] for e in mine if e["event"] == "restored")
        m = re.search(r"checkpoint sha256=(\w+) restored sha256=(\w+)", restored)
        assert m and m.group(1) == m.group(2), restored
    # (a restart takes ~0.5 s, often less than one step deadline, so adoption may not show here;
    # the freeze test below checks it)
    s = run.summary()
    assert len(s["final_error"]) >= back_at + 2 and s["restarts"] == {"a1": 1, "a2": 1, "a3": 1, "a4": 1}
    assert all(s["tokens_lost"].get(a, 0) >= 1 for a in ("a1", "a2", "a3", "a4")), s["tokens_lost"]
    assert swarm_pids(str(run.out)) == []


def test_freeze_holds_the_joint_and_the_agent_rejoins(tmp_path, chain4):
    run = Run(tmp_path, chain4, "--epochs", "500", "--steps", "200", "--deadline-ms", "300")
    run.wait_epochs(2)
    r = run.fault("freeze", "a2", "--for", "6s")
    assert r.returncode == 0, r.stderr
    run.wait_event("lost", "a2")  # within one lease (1 s)
    status = run.cli("status", run.run_id)
    assert status.returncode == 0 and "frozen" in status.stdout, status.stdout + status.stderr
    run.wait_event("handback", "a2")
    run.wait_epochs(len((run.out / "metrics.jsonl").read_text().splitlines()) + 1)
    run.proc.send_signal(2)  # Ctrl-C
    code, text = run.finish()
    assert code == 130, text
    kinds = [(e["event"], e["target"]) for e in run.events()]
    for k in [("fault", "a2"), ("lost", "a2"), ("adopt", "a2"), ("thaw", "a2"), ("alive", "a2"), ("handback", "a2")]:
        assert k in kinds, kinds
    assert ("exited", "a2") not in kinds  # it rejoined: no restart needed
    # its own links lapsed while it slept: its children's tokens went and came back, and that is no loss
    assert not [e for e in run.events() if e["event"] == "adopt" and e.get("detail", "").startswith("a2 ")], (
        run.events()
    )
    assert run.summary()["restarts"]["a2"] == 0
    rows = [json.loads(line) for line in (run.out / "metrics.jsonl").read_text().splitlines()]
    # While a2 slept and before its parent stood in, steps were ended by their deadline with a2's joint held: a
    # command counted missed (a sim that waited for a2 would have got its command after the thaw, and missed none).
    assert sum(r["missed_cmds"] for r in rows) > 0, rows
    assert swarm_pids(str(run.out)) == []


def test_restart_policy_gives_up_and_says_why(tmp_path, chain4):
    run = Run(tmp_path, chain4, "--epochs", "200", "--steps", "200", "--max-restarts", "1")
    run.wait_epochs(1)
    assert run.fault("kill", "a4").returncode == 0
    run.wait_event("alive", "a4")
    assert run.fault("kill", "a4").returncode == 0
    code, text = run.finish()
    assert code == 1, text
    assert "restart policy" in text and "a4" in text
    assert "restart policy" in run.summary()["error"]
    assert swarm_pids(str(run.out)) == []


def test_bad_faults_are_refused_with_a_reason(tmp_path, chain4):
    # enough epochs that the run cannot end by itself before the Ctrl-C below, however loaded the machine
    run = Run(tmp_path, chain4, "--epochs", "5000", "--steps", "100", "--placement", "single")
    run.wait_epochs(1)
    r = run.fault("kill", "a9")
    assert r.returncode == 2 and "'a9' is not an agent" in r.stderr
    r = run.fault("freeze", "a2")
    assert r.returncode == 2 and "needs --placement process" in r.stderr
    r = run.fault("drop", "a2")
    assert r.returncode == 2 and "needs rate" in r.stderr
    r = run.fault("disturb", "a2", "--steps", "5", "--rate", "0.5")
    assert r.returncode == 2 and "does not take rate" in r.stderr
    r = run.cli("status", run.run_id)
    assert r.returncode == 0 and all(a in r.stdout for a in ("a1", "a2", "a3", "a4", "sim")), r.stdout
    # a kill in the single placement cancels the task; it is restarted from its checkpoint
    assert run.fault("kill", "a3").returncode == 0
    run.wait_event("restored", "a3")
    run.proc.send_signal(2)  # Ctrl-C
    code, _ = run.finish()
    assert code == 130
    assert swarm_pids(str(run.out)) == []


def test_a_motor_reversed_live_is_applied_shown_and_freed(tmp_path, chain4):
    """`kinswarm fault RUN reverse a2` (and scale, offset) on a running swarm: the sim applies it (an event with its
    size), `status` shows it, `free` ends it, and a bad size is one line before anything is sent."""
    run = Run(tmp_path, chain4, "--epochs", "5000", "--steps", "100", "--placement", "single")
    run.wait_epochs(1)
    r = run.fault("reverse", "a2")
    assert r.returncode == 0 and "reverse a2" in r.stdout, r.stdout + r.stderr
    assert run.fault("scale", "a3", "--factor", "3").returncode == 0
    assert run.fault("offset", "a4", "--degrees", "-5").returncode == 0  # a negative value is not an option
    effect = run.wait_event("reverse", "a2")
    request = next(e for e in run.events() if e["event"] == "fault" and e["detail"].startswith("reverse a2"))
    # the request is stamped at the step it went out, the effect at the step the sim applied it: never before
    assert (request["epoch"], request["step"]) <= (effect["epoch"], effect["step"]), (request, effect)
    assert run.wait_event("scale", "a3")["detail"] == "scale a3 factor=3"
    assert run.wait_event("offset", "a4")["detail"] == "offset a4 degrees=-5"
    # the table's joint faults come from the sim's latest JointStatus, published a few times a second: a status
    # drawn just after the three events may still show the robot as it was one publication earlier
    shown = ("reversed", "scaled x3", "reads -5 deg")
    deadline = time.monotonic() + 120  # a bound for a stuck run, not a timing: it ends as soon as all three show
    while not all(s in (status := run.cli("status", run.run_id)).stdout for s in shown):
        assert time.monotonic() < deadline, status.stdout
        time.sleep(0.3)
    r = run.fault("scale", "a3", "--factor", "0")
    assert r.returncode == 2 and "factor must be nonzero" in r.stderr and "Traceback" not in r.stderr
    r = run.fault("lag", "a3")
    assert r.returncode == 2 and "lag: needs steps" in r.stderr
    assert run.fault("free", "all").returncode == 0
    run.wait_event("free", "a2")
    run.proc.send_signal(2)  # Ctrl-C
    code, _ = run.finish()
    assert code == 130
    assert swarm_pids(str(run.out)) == []


def test_fault_needs_the_runs_key(tmp_path):
    r = subprocess.run(
        [*CLI, "fault", "nosuchrun", "kill", "a1", "--run-dir", str(tmp_path)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "config.json not found" in r.stderr
