"""The fault-tolerance acceptance checks on full training runs (slow: `pytest -m slow tests/test_faults_acceptance.py`).

Each compares a faulted run with the fault-free run of the same seed; the numbers go into the note."""

from __future__ import annotations

import json
import re
import time

import pytest
from conftest import swarm_pids
from test_faults import Run

pytestmark = [pytest.mark.slow, pytest.mark.timeout(3600)]

EPOCHS, STEPS = "60", "500"


def success(summary: dict) -> float:
    last = summary["final_error"][-20:]
    return sum(e <= 0.5 for e in last) / len(last)


@pytest.fixture(scope="module")
def fault_free(tmp_path_factory, chain4_module):
    run = Run(tmp_path_factory.mktemp("ff"), chain4_module, "--epochs", EPOCHS, "--steps", STEPS, "--seed", "0")
    code, text = run.finish(timeout=1800)
    assert code == 0, text
    return run.summary()


@pytest.fixture(scope="module")
def chain4_module():
    from conftest import EXAMPLES

    return EXAMPLES / "chain4.toml"


def test_kill_each_agent_during_training(tmp_path, chain4_module, fault_free):
    run = Run(tmp_path, chain4_module, "--epochs", EPOCHS, "--steps", STEPS, "--seed", "0")
    for n, agent in enumerate(("a1", "a2", "a3", "a4")):
        run.wait_epochs(8 + 10 * n, timeout=900)
        assert run.fault("kill", agent).returncode == 0
        # back before the next kill, however slow the machine (when does not matter: that it does)
        run.wait_event("alive", agent, timeout=600, after=run.wait_event("exited", agent, timeout=600)["t"])
    code, text = run.finish(timeout=1800)
    assert code == 0, text
    s = run.summary()
    ev = run.events()
    for agent in ("a1", "a2", "a3", "a4"):
        mine = [e for e in ev if e["target"] == agent]
        kinds = [e["event"] for e in mine]
        assert "alive" in kinds[kinds.index("exited") :], kinds  # back after its kill
        restored = next(e["detail"] for e in mine if e["event"] == "restored")
        m = re.search(r"checkpoint sha256=(\w+) restored sha256=(\w+)", restored)
        assert m and m.group(1) == m.group(2), restored  # from its own checkpoint
    assert len(s["final_error"]) == int(EPOCHS) and s["restarts"] == {"a1": 1, "a2": 1, "a3": 1, "a4": 1}
    print(f"\nkill each: success {success(s):.2f} vs fault-free {success(fault_free):.2f}; restarts {s['restarts']}")
    assert abs(success(s) - success(fault_free)) <= 0.10
    assert swarm_pids(str(run.out)) == []


def test_drop_five_percent_on_every_agent_for_the_whole_run(tmp_path, chain4_module, fault_free):
    # A lost message stalls its step until the deadline; 20 ms keeps the run's length reasonable.
    run = Run(tmp_path, chain4_module, "--epochs", EPOCHS, "--steps", STEPS, "--seed", "0", "--deadline-ms", "20")
    deadline = time.monotonic() + 120
    while not (run.out / "metrics.jsonl").exists():  # training has begun once the file is there
        assert time.monotonic() < deadline
        time.sleep(0.05)
    assert run.fault("drop", "all", "--rate", "0.05").returncode == 0
    code, text = run.finish(timeout=3000)
    assert code == 0, text
    s = run.summary()
    seconds = sum(json.loads(line)["seconds"] for line in (run.out / "metrics.jsonl").read_text().splitlines())
    ff_seconds = fault_free["epochs"] * fault_free["steps_per_epoch"] / fault_free["steps_per_second"]
    print(
        f"\ndrop 5%: success {success(s):.2f} (fault-free {success(fault_free):.2f}), "
        f"missed cmds {s['missed_cmds']}, {seconds:.0f} s of stepping vs {ff_seconds:.0f} s "
        f"({seconds / ff_seconds:.1f}x slower)"
    )
    assert success(s) >= 0.8
