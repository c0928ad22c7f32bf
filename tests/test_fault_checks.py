"""A fault is checked against the run before it can be lost: a scenario's faults against the run's placement and
controller when the run file is resolved (one line, nothing started), and a fault refused while the run goes (the
live `kinswarm fault`) is on the run's record, with its reason."""

from __future__ import annotations

from pathlib import Path

import pytest
from conftest import run_config
from kinswarm.actors.cli.commands import main as cli_main
from kinswarm.actors.files.config import PLACEMENT_FAULTS
from kinswarm.actors.supervisor.placements import ProcessPlacement, SinglePlacement
from kinswarm.protocol.faults import LINK_FAULTS, PROCESS_FAULTS
from kinswarm.protocol.scenario import ScenarioError
from test_faults import Run


def _scenario(tmp_path: Path, fault: str, extra: str = "") -> Path:
    p = tmp_path / f"{fault}.toml"
    p.write_text(f'name = "{fault}"\n[[event]]\nstep = 5\nfault = "{fault}"\ntarget = "a2"\n{extra}')
    return p


def test_the_loader_knows_what_each_placement_applies():
    """The table the loader checks against is the placements' own."""
    process_faults = {p: tuple(f for f in faults if f in PROCESS_FAULTS) for p, faults in PLACEMENT_FAULTS.items()}
    assert process_faults == {"process": ProcessPlacement.supports, "single": SinglePlacement.supports, "inprocess": ()}
    assert set(PLACEMENT_FAULTS["process"]) == set(PROCESS_FAULTS + LINK_FAULTS)


@pytest.mark.parametrize(("fault", "extra"), [("freeze", "seconds = 2\n"), ("freeze", ""), ("thaw", "")])
def test_a_process_fault_the_single_placement_cannot_apply_is_refused_up_front(tmp_path, chain4, capsys, fault, extra):
    scenario = _scenario(tmp_path, fault, extra)
    out = tmp_path / "run"
    args = ["run", str(chain4), "--placement", "single", "--scenario", str(scenario), "--out", str(out)]
    assert cli_main([*args, "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert err == (
        f"kinswarm: error: {scenario}: event[0].fault: {fault}: needs --placement process "
        "(this run's placement is single)"
    )
    assert not out.exists()  # refused before anything was made or spawned
    # the same scenario in the placement that applies it
    assert run_config(chain4, ['run.placement="process"', f"run.scenario={str(scenario)!r}"]).scenario


@pytest.mark.parametrize("fault", ["kill", "restart"])
def test_a_process_fault_the_single_placement_applies_is_accepted(tmp_path, chain4, fault):
    scenario = _scenario(tmp_path, fault)
    assert run_config(chain4, ['run.placement="single"', f"run.scenario={str(scenario)!r}"]).scenario


@pytest.mark.parametrize(("fault", "extra"), [("kill", ""), ("drop", "rate = 0.1\n"), ("freeze", "")])
def test_a_baseline_run_takes_only_joint_faults(tmp_path, chain4, fault, extra):
    scenario = _scenario(tmp_path, fault, extra)
    with pytest.raises(ScenarioError) as e:
        run_config(chain4, ['run.controller="pinv"', f"run.scenario={str(scenario)!r}"])
    assert str(e.value) == (
        f"{scenario}: event[0].fault: {fault}: a baseline run (pinv) has no agents; only joint faults apply"
    )
    lock = _scenario(tmp_path, "lock")
    assert run_config(chain4, ['run.controller="pinv"', f"run.scenario={str(lock)!r}"]).scenario


@pytest.mark.timeout(240)
def test_a_fault_refused_while_the_run_goes_is_an_event_with_its_reason(tmp_path, chain4):
    run = Run(tmp_path, chain4, "--epochs", "5000", "--steps", "100", "--placement", "single", run_id="refused")
    try:
        run.wait_epochs(1)
        r = run.fault("freeze", "a2", "--for", "3s")
        assert r.returncode == 2 and "needs --placement process" in r.stderr, r.stderr
        ev = run.wait_event("refused", "a2")
        assert ev["detail"] == "freeze a2 seconds=3: freeze: needs --placement process (this run's placement is single)"
        r = run.fault("kill", "a9")
        assert r.returncode == 2
        ev = run.wait_event("refused", "a9")
        assert "'a9' is not an agent of this run" in ev["detail"], ev
        assert not [e for e in run.events() if e["event"] == "fault"]  # nothing was applied
    finally:
        run.proc.send_signal(2)  # Ctrl-C
        code, _ = run.finish()
    assert code == 130
