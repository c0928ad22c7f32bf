"""Scenario files: the shipped paper scenarios load; bad files are refused naming the file and field."""

from __future__ import annotations

from pathlib import Path

import pytest
from kinswarm.protocol.robots import load_robot
from kinswarm.protocol.scenario import ScenarioError, load_scenario
from test_sim_kinematics import compound_tree

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"


@pytest.fixture
def topo(chain4):
    return load_robot(chain4)


def timeline(path: Path, topo) -> list[tuple[int | None, int, str, list[str], int | None]]:
    s = load_scenario(path, topo)
    return [(e.epoch, e.step, e.fault.fault, e.fault.targets, e.fault.steps) for e in s.entries]


def test_paper_scenarios(topo):
    assert sorted(p.name for p in SCENARIOS.glob("*.toml")) == [
        "iiwa-locked-a2.toml",  # experiments/reach3d.py
        "lock-then-reverse.toml",  # the README's animation
        "paper-fail-disturb-fail.toml",
        "paper-locked.toml",
        "paper-recovery.toml",
        "reverse-at-goal.toml",  # the README's second animation
    ]
    assert timeline(SCENARIOS / "paper-recovery.toml", topo) == [
        (None, 0, "lock", ["a1", "a2", "a3"], None),
        (None, 100, "free", ["a3"], None),
        (None, 500, "free", ["a1"], None),
        (None, 1000, "free", ["a2"], None),
    ]
    assert timeline(SCENARIOS / "paper-fail-disturb-fail.toml", topo) == [
        (None, 0, "lock", ["a2", "a3"], None),
        (None, 700, "disturb", ["a2", "a3"], 300),
        (None, 1000, "lock", ["a2", "a3"], None),
    ]
    assert timeline(SCENARIOS / "paper-locked.toml", topo) == [(None, 0, "lock", ["a2", "a3"], None)]
    for p in SCENARIOS.glob("paper-*.toml"):
        s = load_scenario(p, topo)
        assert s.name == p.stem and "--steps 1500" in s.description and "5.3" in p.read_text()


def test_optional_fields_and_non_joint_faults(tmp_path, topo):
    p = tmp_path / "s.toml"
    p.write_text(
        'name = "mixed"\n'
        '[[event]]\nstep = 5\nepoch = 2\nfault = "drop"\ntarget = "all"\nrate = 0.05\nseconds = 30\n'
        '[[event]]\nstep = 0\nfault = "freeze"\ntarget = "a3"\nseconds = 5\n'
    )
    s = load_scenario(p, topo)
    assert s.description == "" and s.source == str(p)
    drop, freeze = s.entries
    assert (drop.epoch, drop.step, drop.fault.targets, drop.fault.rate, drop.fault.seconds) == (
        2,
        5,
        ["all"],
        0.05,
        30.0,
    )
    assert not drop.is_joint and freeze.fault.seconds == 5.0 and freeze.epoch is None


def test_faults_in_the_robots_model(tmp_path, topo):
    p = tmp_path / "s.toml"
    p.write_text(
        'name = "model"\n'
        '[[event]]\nstep = 0\nfault = "reverse"\ntarget = ["a1", "a2"]\n'
        '[[event]]\nstep = 3\nfault = "scale"\ntarget = "a2"\nfactor = 0.3\n'
        '[[event]]\nstep = 4\nfault = "deadzone"\ntarget = "a3"\ndegrees = 0.5\n'
        '[[event]]\nstep = 5\nfault = "offset"\ntarget = "a4"\ndegrees = -10\n'
        '[[event]]\nstep = 6\nfault = "lag"\ntarget = "a1"\nsteps = 5\n'
    )
    rev, scale, dead, off, lag = load_scenario(p, topo).entries
    assert all(e.is_joint for e in (rev, scale, dead, off, lag)), "applied by the sim, not the supervisor"
    assert rev.fault.targets == ["a1", "a2"] and scale.fault.factor == 0.3 and dead.fault.degrees == 0.5
    assert off.fault.degrees == -10.0 and lag.fault.steps == 5


HEAD = 'name = "bad"\n'
LOCK = '[[event]]\nstep = 0\nfault = "lock"\ntarget = "a2"\n'


@pytest.mark.parametrize(
    "text, where, what",
    [
        ('name = "x"\n' + LOCK + "[oops]\n", "oops", "unknown key"),
        (LOCK, "name", "non-empty string"),
        (HEAD, "event", "at least one [[event]]"),
        (HEAD + LOCK.replace("step = 0", "step = -1"), "event[0].step", "integer >= 0"),
        (HEAD + LOCK.replace("step = 0", "step = 1.5"), "event[0].step", "integer >= 0"),
        (HEAD + LOCK.replace("step = 0\n", ""), "event[0].step", "missing"),
        (HEAD + LOCK + LOCK.replace("step = 0", "step = 0\nepoch = true"), "event[1].epoch", "integer >= 0"),
        (HEAD + LOCK.replace('"lock"', '"explode"'), "event[0]", "unknown fault 'explode'"),
        (HEAD + LOCK.replace('"a2"', '"a9"'), "event[0]", "'a9' is not an agent"),
        (HEAD + LOCK.replace('"a2"', "[]"), "event[0].target", "agent id or a list"),
        (HEAD + LOCK.replace('"a2"', "[1]"), "event[0].target", "agent id or a list"),
        (HEAD + LOCK + "speed = 3\n", "event[0].speed", "unknown field"),
        (HEAD + LOCK + "seconds = 3\n", "event[0]", "lock: does not take seconds"),
        (HEAD + LOCK.replace('"lock"', '"disturb"'), "event[0]", "disturb: needs steps"),
        (HEAD + LOCK.replace('"lock"', '"disturb"') + "steps = 0\n", "event[0]", "steps must be >= 1"),
        (HEAD + LOCK.replace('"lock"', '"drop"') + 'rate = "lots"\n', "event[0].rate", "finite number"),
        (HEAD + LOCK.replace('"lock"', '"drop"') + "rate = 2.0\n", "event[0]", "rate must be in [0, 1]"),
        (HEAD + "event = [3]\n", "event[0]", "must be a table"),
        (HEAD + "event = 3\n", "event", "at least one"),
        (HEAD + "[[event\n", "toml", ""),
        (HEAD + LOCK.replace('"lock"', '"scale"'), "event[0]", "scale: needs factor"),
        (HEAD + LOCK.replace('"lock"', '"scale"') + "factor = 0\n", "event[0]", "factor must be nonzero"),
        (HEAD + LOCK.replace('"lock"', '"deadzone"') + "degrees = 0\n", "event[0]", "degrees must be in (0, 180]"),
        (HEAD + LOCK.replace('"lock"', '"reverse"') + "degrees = 3\n", "event[0]", "reverse: does not take degrees"),
        (HEAD + LOCK.replace('"lock"', '"lag"') + "steps = 0\n", "event[0]", "steps must be >= 1"),
    ],
)
def test_bad_scenarios_name_file_and_field(tmp_path, topo, text, where, what):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(ScenarioError) as ei:
        load_scenario(p, topo)
    assert ei.value.where == where and what in ei.value.what
    assert str(ei.value).startswith(f"{p}: {where}: ")


def test_joint_fault_on_compound_agent_and_missing_file(tmp_path):
    topo = compound_tree()
    compound = next(a for a in topo.order if not topo.agents[a].has_dof)
    p = tmp_path / "c.toml"
    p.write_text(f'name = "c"\n[[event]]\nstep = 0\nfault = "lock"\ntarget = "{compound}"\n')
    with pytest.raises(ScenarioError, match="compound agent"):
        load_scenario(p, topo)
    p.write_text(f'name = "c"\n[[event]]\nstep = 0\nfault = "kill"\ntarget = "{compound}"\n')
    assert load_scenario(p, topo).entries[0].fault.fault == "kill"  # processes of compound agents exist
    with pytest.raises(ScenarioError, match="cannot read"):
        load_scenario(tmp_path / "nope.toml", topo)


def test_a_scenario_error_survives_a_process_boundary():
    """Raised in an experiment's worker process it comes back whole (an exception that does not unpickle breaks the
    whole pool instead of naming the bad file)."""
    import pickle

    e = pickle.loads(pickle.dumps(ScenarioError("s.toml", "event[0].step", "step 100 is beyond the run's 5 steps")))
    assert (e.source, e.where, e.what) == ("s.toml", "event[0].step", "step 100 is beyond the run's 5 steps")
    assert str(e) == "s.toml: event[0].step: step 100 is beyond the run's 5 steps"
