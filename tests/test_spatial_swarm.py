"""Robots from URDF as a real swarm: the iiwa (to a point and to a pose), the Panda and the xArm6 example files train in
both placements with the same results for the same seed, and faults (lock, kill, freeze) reach an iiwa's agents live."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from conftest import EXAMPLES, free_port, swarm_pids
from kinswarm.actors.cli.commands import main
from test_faults import Run

SMALL = ["--epochs", "2", "--steps", "40", "--no-progress", "--deadline-ms", "10000"]


def _run(file: Path, placement: str, out: Path) -> dict:
    listen = f"tcp/127.0.0.1:{free_port()}"
    args = ["run", str(file), "--placement", placement, "--out", str(out), "--run-id", out.name, "--listen", listen]
    assert main([*args, *SMALL]) == 0
    return json.loads((out / "summary.json").read_text())


# the iiwa in the default suite; the panda and the xarm6 (~14 s each) in the slow suite
@pytest.mark.parametrize(
    "name",
    ["iiwa", "iiwa-pose", pytest.param("panda", marks=pytest.mark.slow), pytest.param("xarm6", marks=pytest.mark.slow)],
)
def test_a_urdf_arm_trains_alike_in_both_placements(tmp_path, name):
    single = _run(EXAMPLES / f"{name}.toml", "single", tmp_path / "single")
    process = _run(EXAMPLES / f"{name}.toml", "process", tmp_path / "process")
    assert single["final_error"] == process["final_error"]
    assert single["mean_error"] == process["mean_error"]
    assert all(0.0 <= e < 2.0 for e in single["final_error"])  # metres: the tool stayed within the arm's reach
    assert swarm_pids(str(tmp_path / "process")) == []


def test_faults_reach_an_iiwa_swarm_live(tmp_path):
    # The run outlasts its faults (ended by Ctrl-C once each has shown): the killed agent's return is waited for as
    # its `alive` event, not expected within some epochs a loaded machine can run through before the restart is done
    run = Run(tmp_path, EXAMPLES / "iiwa.toml", "--epochs", "5000", "--steps", "100", "--seed", "1")
    run.wait_epochs(1, timeout=120)
    r = run.fault("lock", "a2")
    assert r.returncode == 0, r.stderr
    run.wait_event("lock", "a2")
    r = run.fault("kill", "a5")
    assert r.returncode == 0, r.stderr
    exited = run.wait_event("exited", "a5")
    r = run.fault("freeze", "a3", "--for", "0.5s")
    assert r.returncode == 0, r.stderr
    run.wait_event("thaw", "a3")  # frozen (SIGSTOP) for half a second, then SIGCONT
    restored = run.wait_event("restored", "a5", timeout=180, after=exited["t"])  # restarted from its checkpoint
    run.wait_event("alive", "a5", timeout=180, after=exited["t"])  # and back in the swarm
    run.proc.send_signal(2)  # Ctrl-C
    code, text = run.finish(timeout=120)
    assert code == 130, text
    assert "sha256" in restored["detail"] or "no good checkpoint" in restored["detail"], restored
    assert run.summary()["restarts"]["a5"] == 1
    assert swarm_pids(str(run.out)) == []
