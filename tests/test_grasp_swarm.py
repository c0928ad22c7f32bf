"""The grasp swarm end to end: 13 agents (a compound grasp agent over three 4-joint fingers) and the
PyBullet grasp scene over the real wire, one OS process per actor."""

from __future__ import annotations

import json

import pytest
from conftest import EXAMPLES, LOCKSTEP_ARGS, LOCKSTEP_LEASE_MS, free_port, swarm_pids
from kinswarm.actors.cli.commands import main as cli_main

pytestmark = pytest.mark.timeout(240)

GRASP3 = EXAMPLES / "grasp3.toml"


def test_grasp_swarm_runs_in_processes(tmp_path):
    out = tmp_path / "g"
    args = ["run", str(GRASP3), "--placement", "process", "--epochs", "1", "--steps", "40", "--seed", "2"]
    args += LOCKSTEP_ARGS
    args += ["--listen", f"tcp/127.0.0.1:{free_port()}", "--out", str(out), "--no-progress"]
    rc = cli_main(args)
    summary = json.loads((out / "summary.json").read_text())
    assert rc == 0, summary.get("error")
    # every actor's session carries the test's lease (the flag reaches the processes it spawns)
    assert {json.loads(f.read_text())["lease_ms"] for f in (out / "net").glob("*.json")} == {LOCKSTEP_LEASE_MS}
    assert summary["missed_cmds"] == 0 and len(summary["final_error"]) == 1
    assert sorted(p.stem for p in (out / "agents").glob("*.npz")) == sorted(
        f"f{i}_{j}" for i in (1, 2, 3) for j in (1, 2, 3, 4)
    )  # twelve learners; the grasp agent has no DOF and nothing to save
    row = json.loads((out / "metrics.jsonl").read_text().splitlines()[0])
    traces = row["traces"]
    for name in ("net_fx", "net_fy", "net_torque", "fn/f1_4", "ft/f2_4", "margin/f3_4", "contact/f1_4"):
        assert len(traces[name]) == 40, name
    assert all(v >= 0.0 for v in traces["fn/f1_4"])
    for f in ("grasp.png", "grasp_forces.png", "learning_curve.png"):
        assert (out / f).is_file(), f
    assert swarm_pids(str(out / "config.json")) == []


def test_grasp_rejects_a_reaching_reward(tmp_path, capsys):
    args = ["run", str(GRASP3), "--reward", "strict", "--out", str(tmp_path / "x"), "--no-progress"]
    assert cli_main(args) == 2
    assert (
        "task.reward: 'strict' is not one of shaped, sensed, paper, contact, global, force" in capsys.readouterr().err
    )
    assert not (tmp_path / "x").exists()


def test_reach_rejects_a_grasp_reward(tmp_path, chain4, capsys):
    assert cli_main(["run", str(chain4), "--reward", "contact", "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    assert "task.reward: 'contact' is not one of shaped, paper" in capsys.readouterr().err


def _final_angles(tmp_path, name: str, extra: list[str]) -> dict:
    out = tmp_path / name
    args = ["run", str(GRASP3), "--placement", "single", "--epochs", "1", "--steps", "200", "--seed", "0"]
    args += ["--listen", f"tcp/127.0.0.1:{free_port()}", "--out", str(out), "--no-progress", *extra]
    assert cli_main(args) == 0
    return json.loads((out / "metrics.jsonl").read_text().splitlines()[0])["final_angles_deg"]


def test_fingers_near_their_contact_goals_move_with_fine_steps(tmp_path):
    """From whole-degree start angles, 1-degree steps keep every angle whole; the default `shaped` grasp
    sends "fine" near a contact goal and those fingers move 0.1 degree (fine_action)."""
    fine = _final_angles(tmp_path, "fine", [])
    coarse = _final_angles(tmp_path, "coarse", ["--set", "task.fine_action=1.0"])
    frac = lambda a: abs(a - round(a))  # noqa: E731
    assert all(frac(a) < 1e-6 for a in coarse.values()), coarse
    assert any(frac(a) > 0.05 for a in fine.values()), fine
