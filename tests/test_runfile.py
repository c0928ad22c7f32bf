"""Run files (actors/files/runfile.py): the one loader. Overrides, layered files, paths, the resolved file that makes
the run again, and one clear line for every bad input."""

from __future__ import annotations

import dataclasses
import json
import re
import shutil

import pytest
from conftest import EXAMPLES, ROOT, free_port, run_config
from kinswarm.actors.cli.commands import main as cli_main
from kinswarm.actors.files.checkpoint import CheckpointError
from kinswarm.actors.files.config import ConfigError
from kinswarm.actors.files.runfile import load_run, parse_set, read_run_file, task_of
from kinswarm.actors.tasks import kinds
from kinswarm.protocol.spec import SpecError

CHAIN4 = EXAMPLES / "chain4.toml"


def test_defaults_are_written_once_and_resolved_in_full():
    cfg = load_run(CHAIN4, run_id="r")
    assert (cfg.epochs, cfg.steps, cfg.seed, cfg.placement) == (60, 500, 0, "process")
    assert cfg.task == {
        "kind": "reach",
        "goal": [4.16, 6.18],
        "goals": [],
        "reward": "shaped",
        "via_width": 0.0,
        "start_pose": "home",
        "start_share": 1.0,
        "start_seed": 0,
        "tip": "computed",
    }.copy() | {k: cfg.task[k] for k in ("waypoints", "waypoint_radius", "settle_radius")}
    assert cfg.scene == {"kind": "free"} and cfg.learner == {} and cfg.robot["name"] == "chain4"


@pytest.mark.parametrize(
    ("text", "path", "value"),
    [
        ("learner.gamma=0.97", ("learner", "gamma"), 0.97),
        ("task.goal=[4, 6]", ("task", "goal"), [4, 6]),
        ("task.reward=settle", ("task", "reward"), "settle"),  # a bare word is a string
        ('task.reward="settle"', ("task", "reward"), "settle"),
        ("run.learn=false", ("run", "learn"), False),
        ("scene.obstacle=[]", ("scene", "obstacle"), []),
    ],
)
def test_set_values_are_toml(text, path, value):
    assert parse_set(text) == (path, value)


@pytest.mark.parametrize(
    ("text", "why"),
    [("gamma=0.9", "SECTION.FIELD=VALUE"), ("learner.gamma", "SECTION.FIELD=VALUE"), ("lerner.gamma=1", "lerner")],
)
def test_bad_set_is_one_line(text, why):
    with pytest.raises(ConfigError, match=why):
        parse_set(text)


@pytest.mark.parametrize(
    ("sets", "where", "what"),
    [
        (["learner.gamma=1.5"], "learner", "gamma must be in [0, 1]"),
        (['learner.gamma="x"'], "learner.gamma", "expected a number, got a string 'x'"),
        (["learner.act_from=1"], "learner.act_from", "unknown field"),  # a probe measured and not kept
        (["learner.tabu_memory=0.1"], "learner.tabu_memory", "unknown field"),
        (["learner.clearance_state=true"], "learner.clearance_state", "unknown field"),  # the corridor task's now
        (['learner.state="turn"'], "learner.state", "'turn' is not a state of a planar robot; it takes: planar"),
        (  # a variable no agent computes: it would be stuck at 0
            ['learner.extra_state=[{name="g_dist", sets=5, range=[0, 1]}]'],
            "learner.extra_state",
            "a1 cannot read 'g_dist'; here it takes: g_perp",
        ),
        (["task.kind=walk"], "task.kind", "expected one of"),
        (["task.goal=[1]"], "task.goal", "expected a list of 2 values, got 1"),
        (["task.colour=1"], "task.colour", "unknown field"),
        (["run.epochs=0"], "run.epochs", "expected an integer >= 1"),
        (["run.seed=-1"], "run.seed", "expected an integer >= 0"),
        (['run.placement="cloud"'], "run.placement", "not one of process, single"),
        (["run.epochz=3"], "run.epochz", "unknown field"),
        (["run.lease_ms=50"], "run.lease_ms", "expected an integer >= 100"),
    ],
)
def test_every_field_is_checked_and_named(sets, where, what):
    with pytest.raises((SpecError, ConfigError)) as e:
        run_config(CHAIN4, sets)
    text = str(e.value)
    assert text.startswith(f"--set {sets[-1]}: {where}"), text  # the flag's problem, not the file's
    assert where in text and what in text and "\n" not in text


def test_an_unknown_field_with_a_line_break_in_its_name_is_named_on_one_line():
    """Found by tests/test_fuzz.py: a table key "\n" (TOML allows it quoted) was printed as it is."""
    from kinswarm.actors.files.runfile import resolve

    data = read_run_file(CHAIN4)
    data["run"] = {"\n": False}
    with pytest.raises(SpecError) as e:
        resolve(data, "fuzz.toml")
    assert "run.'\\n'" in str(e.value) and "\n" not in str(e.value)


def test_old_topology_files_get_a_hint(tmp_path):
    p = tmp_path / "old.toml"
    p.write_text('[robot]\nname = "x"\n[[agent]]\nid = "a"\nlink_length = 1.0\n[task]\ngoal = [1, 1]\n')
    with pytest.raises(SpecError, match=r"old.toml: agent: unknown table \(\[\[agent\]\] tables go under \[robot\]"):
        load_run(p)


def test_a_file_laid_over_its_base(tmp_path):
    """`base`: the recipe's second stage is the first with a few fields changed; lists replace, tables merge."""
    stage2 = read_run_file(EXAMPLES / "corridor7-freeze260.toml")
    stage1 = read_run_file(EXAMPLES / "corridor7-inner200.toml")
    guided = read_run_file(EXAMPLES / "corridor7-guided.toml")
    assert stage2["task"] == stage1["task"] and stage2["robot"] == stage1["robot"] == guided["robot"]
    assert stage1["task"]["via"] == guided["task"]["via"] and stage1["task"]["reward"] == "settle"
    assert stage2["learner"] == {**stage1["learner"], "lr_anneal": [200, 240], "count_freeze": 200}
    assert (stage1["run"]["epochs"], stage2["run"]["epochs"]) == (200, 60)
    assert stage2["run"]["from"] == str((ROOT / "runs" / "corridor7-inner200").resolve())  # relative to its file
    # the second stage before the first: said before anything, whether or not the first's directory exists yet
    (tmp_path / "examples").mkdir()
    for name in ("corridor7-guided.toml", "corridor7-inner200.toml", "corridor7-freeze260.toml"):
        shutil.copy(EXAMPLES / name, tmp_path / "examples" / name)
    with pytest.raises(CheckpointError, match="corridor7-inner200: no such run directory"):
        load_run(tmp_path / "examples" / "corridor7-freeze260.toml")
    (tmp_path / "runs" / "corridor7-inner200").mkdir(parents=True)
    with pytest.raises(CheckpointError, match="corridor7-inner200/agents/a1.npz: no such checkpoint"):
        load_run(tmp_path / "examples" / "corridor7-freeze260.toml")
    looped = tmp_path / "loop.toml"
    looped.write_text('base = "loop.toml"\n')
    with pytest.raises(SpecError, match="its own base"):
        load_run(looped)


def test_a_robot_file_and_paths_relative_to_the_file(tmp_path, monkeypatch):
    (tmp_path / "sub").mkdir()
    run = tmp_path / "sub" / "run.toml"
    run.write_text(
        f'robot = "{CHAIN4}"\n[task]\nkind = "reach"\ngoal = [1.0, 2.0]\n[run]\nscenario = "s.toml"\nepochs = 2\n'
    )
    (tmp_path / "sub" / "s.toml").write_text('name = "s"\n[[event]]\nstep = 0\nfault = "lock"\ntarget = "a2"\n')
    monkeypatch.chdir(tmp_path)
    cfg = load_run(run, run_id="r")
    assert cfg.topo().name == "chain4" and cfg.scenario == str(tmp_path / "sub" / "s.toml")
    (tmp_path / "s2.toml").write_text('name = "s2"\n[[event]]\nstep = 0\nfault = "lock"\ntarget = "a3"\n')
    assert load_run(run, ['run.scenario="s2.toml"'], run_id="r").scenario == str(tmp_path / "s2.toml")  # the cwd's


@pytest.mark.timeout(120)
def test_the_resolved_file_makes_the_same_run_again(tmp_path):
    """`<run>/run.toml` holds everything: `kinswarm run` of it gives the same numbers as the original command."""
    args = ["--epochs", "2", "--steps", "60", "--placement", "single", "--no-progress"]
    sets = ["--set", "learner.gamma=0.95", "--set", "task.goal=[5.0, 5.0]", "--seed", "4"]
    first, again = tmp_path / "first", tmp_path / "again"
    port = f"tcp/127.0.0.1:{free_port()}"
    assert cli_main(["run", str(CHAIN4), *args, *sets, "--out", str(first), "--listen", port]) == 0
    assert cli_main(["run", str(first / "run.toml"), "--out", str(again), "--listen", port, "--no-progress"]) == 0
    a, b = (json.loads((d / "summary.json").read_text()) for d in (first, again))
    assert a["final_error"] == b["final_error"] and a["goal"] == [5.0, 5.0]
    ca, cb = (load_run(d / "run.toml", run_id="r") for d in (first, again))
    assert dataclasses.replace(ca, source="", secret=cb.secret) == dataclasses.replace(cb, source="")


def test_the_tasks_goal_schedule():
    task = task_of(run_config(CHAIN4, ["task.goals=[[1.0, 2.0], [3.0, 4.0]]"]))
    assert [task.goal(e, 10) for e in range(3)] == [((1.0, 2.0), []), ((3.0, 4.0), []), ((1.0, 2.0), [])]
    assert task_of(run_config(CHAIN4)).goal(7, 10) == ((4.16, 6.18), [])


def test_bad_inputs_reach_the_user_as_one_line(tmp_path, capsys):
    out = tmp_path / "x"
    for args in (
        ["run", str(tmp_path / "nope.toml")],
        ["run", str(CHAIN4), "--set", "learner.gamma=2"],
        ["run", str(CHAIN4), "--set", "gamma"],
        ["run", str(CHAIN4), "--from", str(tmp_path)],
        ["baseline", str(CHAIN4), "--set", "task.kind=grasp"],
    ):
        assert cli_main([*args, "--out", str(out), "--no-progress"]) == 2, args
        err = capsys.readouterr().err.strip()
        assert err.startswith("kinswarm: error: ") and "\n" not in err and "Traceback" not in err, err
        assert not out.exists()


@pytest.mark.parametrize(("file", "sets"), [("corridor7.toml", ["scene.shield=0.02"]), ("grasp3.toml", [])])
def test_a_scene_sends_each_agent_the_readings_it_declares(file, sets):
    """What the loader lets a learner read (protocol/scene.agent_readings) is what the sim's scene sends."""
    from kinswarm.protocol.scene import agent_readings
    from kinswarm.sim.scenes import build_scene
    from kinswarm.sim.world import World

    cfg = run_config(EXAMPLES / file, sets)
    topo, spec = cfg.topo(), cfg.scene_spec
    with World(topo) as world:
        scene = build_scene(world, spec, 0.01)
        scene.reset()
        scene.move(dict.fromkeys(topo.dof_agents, 0.01))
        for agent in topo.dof_agents:
            assert set(scene.agent_sense(agent)) == set(agent_readings(spec, topo, agent)), agent
        assert any(agent_readings(spec, topo, a) for a in topo.dof_agents)


def test_the_learner_may_read_its_scene(tmp_path):
    """A reading the scene sends is a variable the loader accepts (the shield's, on a walls scene)."""
    sets = ["scene.shield=0.02", 'learner.extra_state=[{name="shield+", sets=2, range=[0, 1]}]']
    cfg = run_config(EXAMPLES / "corridor7.toml", sets)
    assert cfg.learner["extra_state"][0]["name"] == "shield+"
    with pytest.raises(SpecError, match="cannot read 'shield\\+'; here it takes: g_perp, collided, clearance$"):
        run_config(EXAMPLES / "corridor7.toml", sets[1:])


@pytest.mark.parametrize(
    ("robot", "shown"),
    [
        ("\\n", "/\\n' (no such file)"),  # TOML's escape: the string holds a line break
        ("", "got '' (not a file)"),
        (" ", "/ ' (no such file)"),
        ("\\t", "/\\t' (no such file)"),
        ("\\u0000", "got '\\x00' (no such file)"),  # no path holds a NUL: not made absolute, not opened
        ("nope.toml", "/nope.toml' (no such file)"),
        (".", "' (not a file)"),  # the run file's own directory
    ],
)
def test_a_robot_that_is_no_file_is_named_on_one_line(tmp_path, capsys, robot, shown):
    p = tmp_path / "bad.toml"
    p.write_text(f'robot = "{robot}"\n[task]\nkind = "reach"\ngoal = [1.0, 2.0]\n')
    with pytest.raises(SpecError) as e:
        load_run(p)
    text = str(e.value)
    assert text.startswith(f'{p}: robot: expected a [robot] table or robot = "a robot file", got ') and shown in text
    assert text.isprintable(), text
    assert cli_main(["run", str(p), "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err == f"kinswarm: error: {text}\n"


def test_a_file_or_field_name_that_breaks_the_line_is_quoted():
    e = SpecError("run\n.toml", "task.\n", "got 'x'\nand more")
    assert str(e) == "'run\\n.toml': 'task.\\n': got 'x'\\nand more"
    assert (e.source, e.where, e.what) == ("run\n.toml", "task.\n", "got 'x'\nand more")  # kept as they were


def test_what_is_missing_is_said_in_the_files_words(tmp_path):
    """A joint without a length said `got None` of a field never written, and nothing of the [task] not given."""
    p = tmp_path / "r.toml"
    robot = '[robot]\nname = "x"\n[[robot.agent]]\nid = "a1"\n'
    p.write_text(robot)
    with pytest.raises(SpecError) as e:
        load_run(p)
    assert str(e.value) == f"{p}: task: missing: give a [task] table with kind = one of {', '.join(kinds())}"
    p.write_text(robot + '[task]\nkind = "reach"\ngoal = [1.0, 2.0]\n')
    with pytest.raises(SpecError) as e:
        load_run(p)
    assert (
        str(e.value)
        == f"{p}: robot.agent[0].link_length: missing: a1's link needs a length, here or in [robot.defaults]"
    )
    p.write_text('[task]\nkind = "reach"\ngoal = [1.0, 2.0]\n')
    with pytest.raises(SpecError, match=r"r.toml: robot: missing: give a \[robot\] table"):
        load_run(p)
    p.write_text(robot.replace('id = "a1"', 'id = "a1"\nlink_length = 2.0') + '[task]\nkind = "reach"\ngoal = [1, 1]\n')
    assert load_run(p, run_id="r").topo().agents["a1"].link_length == 2.0


def test_what_opens_a_toml_value_must_be_one():
    """`task.goal=[1,` was taken as the string "[1," and refused later in msgspec's words, blamed on the file."""
    for text in ("task.goal=[1,", 'task.reward="settle', "scene.object={mu = }"):
        with pytest.raises(ConfigError) as e:
            parse_set(text)
        assert str(e.value).startswith(f"--set {text!r}: the value is not TOML (") and "\n" not in str(e.value)
    assert parse_set("run.scenario=faults/a b.toml") == (("run", "scenario"), "faults/a b.toml")  # a bare word


@pytest.mark.parametrize(
    ("args", "line"),
    [
        (["--set", "task.goal=[1,"], "--set 'task.goal=[1,': the value is not TOML (invalid value): a list is [1, 2]"),
        (["--set", "task.goal=abc"], "--set task.goal=abc: task.goal: expected a list, got a string 'abc'"),
        (["--set", 'task.goal=[1, "a"]'], '--set task.goal=[1, "a"]: task.goal[1]: expected a number, got a string'),
        (["--set", "task.goal={a = 1}"], "--set task.goal={a = 1}: task.goal: expected a list, got a table"),
        (["--set", "learner.top_k=1.5"], "--set learner.top_k=1.5: learner.top_k: expected an integer, got a number"),
        (["--set", "learner.gamma=2"], "--set learner.gamma=2: learner: gamma must be in [0, 1], got 2"),
        (["--set", "run.learn=1"], "--set run.learn=1: run.learn: expected true or false, got an integer 1"),
        (["--epochs", "0"], "--epochs 0: run.epochs: expected an integer >= 1, got 0"),
        (["--lease-ms", "5"], "--lease-ms 5: run.lease_ms: expected an integer >= 100, got 5"),
        (["--reward", "nice"], "--reward nice: task.reward: 'nice' is not one of"),
        (["--goal=90,0"], "--goal: task.goal: (90, 0) lies 90 from the robot's base (0, 0), beyond its reach 12"),
    ],
)
def test_a_problem_of_the_command_line_names_the_flag_in_tomls_words(tmp_path, capsys, args, line):
    assert cli_main(["run", str(CHAIN4), *args, "--out", str(tmp_path / "x"), "--no-progress"]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"kinswarm: error: {line}") and err.count("\n") == 1, err
    assert str(CHAIN4) not in err and "`" not in err and not re.search(r"\b(array|null|str|float|int|object)\b", err)


def test_the_files_own_problem_stays_the_files(tmp_path):
    """An override elsewhere does not take the blame for a field of the file, nor a robot file's for the run's."""
    p = tmp_path / "r.toml"
    p.write_text(CHAIN4.read_text().replace("goal = [4.16, 6.18]", 'goal = "up"'))
    with pytest.raises(SpecError) as e:
        load_run(p, ["learner.gamma=0.5", "task.reward=strict"])
    assert str(e.value) == f"{p}: task.goal: expected a list, got a string 'up'"
    # a plan's overrides come with the place they were written in
    with pytest.raises(SpecError) as e:
        load_run(CHAIN4, [("run.epochs=0", "plan.toml: run.set")])
    assert str(e.value) == "plan.toml: run.set: run.epochs: expected an integer >= 1, got 0"


@pytest.mark.parametrize("file", ["chain4.toml", "grasp3.toml", "iiwa-pose.toml", "reach-generalise.toml"])
def test_the_resolved_file_holds_the_learner_settings_used(tmp_path, monkeypatch, file):
    """run.toml's [learner] was the overrides only (empty for the default run): a change of a default in the code
    changed what `kinswarm run run.toml` made. Now it holds the values used; the same settings come out of it."""
    from kinswarm.actors.files.resolved import write_resolved
    from kinswarm.actors.files.runfile import learner_settings
    from kinswarm.actors.learning.settings import TURN_LEARNER, LearnerSettings

    cfg = load_run(EXAMPLES / file, run_id="r", out=tmp_path)
    written = read_run_file(write_resolved(cfg, tmp_path / "run.toml"))["learner"]
    assert set(cfg.learner) <= set(written) and {"lr", "gamma", "T_max", "s", "epsilon", "slope"} <= set(written)
    used = learner_settings(task_of(cfg), cfg.learner)
    again = load_run(tmp_path / "run.toml", run_id="r")
    assert learner_settings(task_of(again), again.learner) == used
    # a default changed in the code: a run of the example follows it, one of the resolved file does not
    made = LearnerSettings.on.__func__  # every task builds its learners' settings here, over their observation
    monkeypatch.setattr(
        LearnerSettings, "on", classmethod(lambda c, o, _made=made, **own: _made(c, o, **{"lr": 0.1, **own}))
    )
    monkeypatch.setitem(TURN_LEARNER, "lr", 0.1)  # the turn state's own default (tasks/reach3d.py)
    changed = load_run(EXAMPLES / file, run_id="r")
    assert {s.lr for s in learner_settings(task_of(changed), changed.learner).values()} == {0.1}
    again = load_run(tmp_path / "run.toml", run_id="r")
    assert learner_settings(task_of(again), again.learner) == used


def test_a_baseline_run_is_named_as_one():
    """`kinswarm baseline` runs went to runs/chain4-<time>-<hex> like the learning runs, told apart by nothing."""
    learning = load_run(CHAIN4)
    assert re.fullmatch(r"chain4-\d{8}-\d{6}-[0-9a-f]{4}", learning.run_id), learning.run_id
    for law in ("pinv", "greedy", "rule"):
        cfg = load_run(CHAIN4, [f'run.controller="{law}"'])
        assert re.fullmatch(rf"baseline-{law}-chain4-\d{{8}}-\d{{6}}-[0-9a-f]{{4}}", cfg.run_id), cfg.run_id
        assert cfg.out.endswith(f"/runs/{cfg.run_id}")
    assert load_run(CHAIN4, ['run.controller="pinv"'], run_id="mine").run_id == "mine"  # a given id is kept
    with pytest.raises(SpecError, match="run.controller: 'x y' is not one of"):  # the field's problem, not the id's
        load_run(CHAIN4, ['run.controller="x y"'])
