"""The recording (actors/report/recording.py, the optional extra kinswarm[viewer]): a run streamed into a .rrd as it
goes (`kinswarm run … --view FILE.rrd`) and a finished run saved as one (`kinswarm view RUN --save`), read back
by rerun's own tool; bad targets are one line before anything is spawned. No viewer is spawned here."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from conftest import free_port
from kinswarm.actors.cli.commands import main as cli_main

pytest.importorskip("rerun")
RERUN = Path(sys.executable).parent / "rerun"


def entities(rrd: Path) -> dict[str, int]:
    """Entity path -> how many chunks of it `rerun rrd print` shows (after `rerun rrd verify` passes)."""
    ok = subprocess.run([str(RERUN), "rrd", "verify", str(rrd)], capture_output=True, text=True, timeout=120)
    assert ok.returncode == 0, ok.stderr
    out = subprocess.run([str(RERUN), "rrd", "print", str(rrd)], capture_output=True, text=True, timeout=120).stdout
    counts: dict[str, int] = {}
    for word in out.split():
        if word.startswith(("/world/", "/error/", "/events", "/agents/")):
            key = word.rstrip(":,")
            counts[key] = counts.get(key, 0) + 1
    return counts


def test_a_run_recorded_live_and_a_finished_run_saved(tmp_path, chain4):
    scenario = tmp_path / "lock.toml"
    scenario.write_text('name = "l"\n[[event]]\nstep = 20\nepoch = 1\nfault = "lock"\ntarget = "a2"\n')
    live, out = tmp_path / "live.rrd", tmp_path / "run"
    args = ["run", str(chain4), "--epochs", "2", "--steps", "60", "--placement", "single", "--no-progress"]
    args += ["--scenario", str(scenario), "--listen", f"tcp/127.0.0.1:{free_port()}", "--out", str(out)]
    assert cli_main([*args, "--view", str(live)]) == 0
    seen = entities(live)
    for entity in ("/world/arm", "/world/joints", "/world/goal", "/error/step", "/events", "/error/final_of_epoch"):
        assert seen.get(entity), (entity, seen)
    for entity in ("/agents/a1/action", "/agents/a1/E/keep", "/agents/a1/P/a2/keep", "/agents/a4/state/g3"):
        assert seen.get(entity), (entity, seen)  # --view records the agents (run.record_agents)
    assert seen.get("/agents/a2/alive")
    saved = tmp_path / "saved.rrd"
    assert cli_main(["view", str(out), "--save", str(saved)]) == 0
    assert set(entities(saved)) == set(seen)


def test_bad_view_targets_are_one_line(tmp_path, chain4, capsys):
    assert cli_main(["run", str(chain4), "--view", "foo", "--out", str(tmp_path / "x")]) == 2
    assert "--view 'foo': expected here, web or a FILE.rrd" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()
    assert cli_main(["run", str(chain4), "--view", str(tmp_path / "no" / "x.rrd"), "--out", str(tmp_path / "y")]) == 2
    assert "no such directory" in capsys.readouterr().err
    assert cli_main(["view", str(tmp_path), "--save", str(tmp_path / "a.rrd")]) == 2
    assert "not a run directory" in capsys.readouterr().err


def test_recording_the_agents_changes_nothing_they_do(tmp_path, chain4):
    """run.record_agents only reads what the learner chose from: the same run with and without gives the same
    errors, and every agent's trace has a row per step it decided, with its E and P."""
    from kinswarm.actors.report.recording import read_agent_rows

    finals = []
    for record in (False, True):
        out = tmp_path / f"r{record}"
        args = ["run", str(chain4), "--epochs", "2", "--steps", "40", "--placement", "single", "--no-progress"]
        args += ["--listen", f"tcp/127.0.0.1:{free_port()}", "--out", str(out)]
        assert cli_main([*args, "--set", f"run.record_agents={str(record).lower()}"]) == 0
        finals.append([json.loads(line)["errors"] for line in (out / "metrics.jsonl").read_text().splitlines()])
    assert finals[0] == finals[1]
    rows = read_agent_rows(tmp_path / "rTrue")
    assert sorted(rows) == [0, 1] and sorted(r["agent"] for r in rows[0]) == ["a1", "a2", "a3", "a4"]
    for r in rows[1]:
        assert r["steps"] == list(range(40)) and len(r["states"][0]) == len(r["names"]) == 6
        assert all(len(e) == 3 for e in r["E"]) and all(a in (0, 1, 2) for a in r["actions"])
        assert len(r["P"][0]) == (0 if r["agent"] == "a4" else 3)  # a4 sees no child


def read_recording(rrd: Path) -> dict[str, list[dict]]:
    """Entity path -> its rows (step timeline and components), read with rerun's own reader (rerun.chunk)."""
    import pyarrow as pa
    from rerun.chunk import RrdReader

    out: dict[str, list[dict]] = {}
    for chunk in RrdReader(rrd).store().stream():
        rb = chunk.to_record_batch()
        keep = [f.name for f in rb.schema if not pa.types.is_timestamp(f.type)]  # rerun's own log_time aside
        out.setdefault(chunk.entity_path, []).extend(rb.select(keep).to_pylist())
    return out


@pytest.mark.timeout(300)
def test_a_faulted_run_writes_a_recording_with_every_step_and_event(tmp_path, chain4):
    """Every run writes its recording (run.record): a run with a scripted lock, kill and freeze, in the process
    placement, leaves recording.rrd with the robot's pose and the error at every step and each of the scenario's
    faults at its step, read back with rerun's reader and accepted by `rerun rrd verify`; and motion.gif."""
    scenario = tmp_path / "faults.toml"
    scenario.write_text(
        'name = "f"\n'
        '[[event]]\nstep = 10\nepoch = 0\nfault = "lock"\ntarget = "a2"\n'
        '[[event]]\nstep = 30\nepoch = 0\nfault = "kill"\ntarget = "a3"\n'
        '[[event]]\nstep = 20\nepoch = 1\nfault = "freeze"\ntarget = "a4"\nseconds = 1.5\n'
    )
    out, steps = tmp_path / "run", 80
    args = ["run", str(chain4), "--epochs", "3", "--steps", str(steps), "--placement", "process", "--no-progress"]
    args += ["--scenario", str(scenario), "--listen", f"tcp/127.0.0.1:{free_port()}", "--out", str(out)]
    assert cli_main([*args, "--set", "run.record=true"]) == 0
    rrd = out / "recording.rrd"
    assert entities(rrd)  # rerun rrd verify
    rec = read_recording(rrd)
    epochs = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    total = len(epochs) * steps
    assert sorted(r["step"] for r in rec["/world/arm"]) == list(range(total)), "a pose at every step"
    errors = {r["step"]: r["Scalars:scalars"][0] for r in rec["/error/step"]}
    assert [errors[e["epoch"] * steps + t] for e in epochs for t in range(steps)] == pytest.approx(
        [x for e in epochs for x in e["errors"]], abs=1e-6
    )
    logged = [(r["step"], r["TextLog:text"][0]) for r in rec["/events"]]
    for epoch, step, fault, target in ((0, 10, "lock", "a2"), (0, 30, "kill", "a3"), (1, 20, "freeze", "a4")):
        at = [s for s, text in logged if f"{fault} {target}" in text]
        assert at, (fault, logged)
        # the sim's joint faults land on their step; the supervisor's process faults at the step it last knew
        assert min(abs(s - (epoch * steps + step)) for s in at) <= (0 if fault == "lock" else 5), (fault, at)
    assert (out / "motion.gif").stat().st_size > 10_000


def test_a_robot_from_urdf_is_recorded_in_3d(tmp_path):
    """An iiwa run saved as a recording: the arm, its joints and the goal in 3D, the error of every step."""
    from conftest import EXAMPLES

    out, rrd = tmp_path / "run", tmp_path / "iiwa.rrd"
    args = ["run", str(EXAMPLES / "iiwa.toml"), "--epochs", "1", "--steps", "30", "--placement", "single"]
    args += ["--no-progress", "--listen", f"tcp/127.0.0.1:{free_port()}", "--out", str(out)]
    assert cli_main(args) == 0
    assert cli_main(["view", str(out), "--save", str(rrd)]) == 0
    seen = entities(rrd)
    assert {"/world/arm", "/world/joints", "/world/goal", "/error/step"} <= set(seen)
    printed = subprocess.run([str(RERUN), "rrd", "print", "--verbose", str(rrd)], capture_output=True, text=True)
    assert "LineStrips3D" in printed.stdout and "Points3D" in printed.stdout and "LineStrips2D" not in printed.stdout
