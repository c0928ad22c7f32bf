"""Fleets (run.fleet = B): B robots in lockstep through one swarm, each agent learning from all B."""

from __future__ import annotations

import copy
import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import EXAMPLES, LOCKSTEP_ARGS, free_port, run_config, swarm_pids
from kinswarm.actors.cli.commands import main as cli_main
from kinswarm.actors.control.client import ControlError, make_fault
from kinswarm.actors.files.runfile import learner_settings, task_of
from kinswarm.actors.learning.fleet import EPISODE, LearnerLane
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.runtime import Node
from kinswarm.actors.step.seed import agent_seed
from kinswarm.protocol.messages import Batch, Cmd, Obs
from kinswarm.sim import kinematics

pytestmark = pytest.mark.timeout(180)
CHAIN4 = EXAMPLES / "chain4.toml"


def run(tmp_path: Path, name: str, *args: str) -> dict:
    out = tmp_path / name
    argv = ["run", str(CHAIN4), "--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}", "--no-progress"]
    assert cli_main([*argv, *LOCKSTEP_ARGS, *args]) == 0
    return json.loads((out / "summary.json").read_text())


def test_a_fleet_runs_the_same_in_both_placements(tmp_path):
    common = ("--epochs", "3", "--steps", "80", "--seed", "5", "--set", "run.fleet=3")
    a = run(tmp_path, "s", "--placement", "single", *common)
    b = run(tmp_path, "p", "--placement", "process", *common)
    assert a["fleet"] == 3 and len(a["fleet_final_error"]) == 3
    assert all(len(row) == 3 for row in a["fleet_final_error"])
    assert a["final_error"] == [row[0] for row in a["fleet_final_error"]]  # the run's rows are robot 0's
    assert a["fleet_final_error"] == b["fleet_final_error"] and a["mean_error"] == b["mean_error"]
    assert b["missed_cmds"] == 0
    # the robots explore apart (one random generator, drawn in robot order): they do not move as one
    assert len({round(e, 9) for e in a["fleet_final_error"][-1]}) > 1
    assert swarm_pids(str(tmp_path / "p")) == []


def test_a_fleet_of_one_is_the_swarm_of_one_robot(tmp_path):
    """B = 1 is today's swarm on today's path (no Batch, no lane: tests/test_golden.py holds its numbers)."""
    s = run(tmp_path, "one", "--placement", "single", "--epochs", "1", "--steps", "30")
    assert "fleet" not in s and "fleet_final_error" not in s
    metrics = (tmp_path / "one" / "metrics.jsonl").read_text()
    assert "fleet_final_error" not in metrics


def test_a_joint_fault_on_one_robot_leaves_the_others(tmp_path):
    """Every joint of robot 1 locked from the first step: it never moves (its error stays the start's), while
    robot 0, the same swarm, learns to reach; the events name the robot."""
    scenario = tmp_path / "lock-robot1.toml"
    scenario.write_text('name = "lock robot 1"\n\n[[event]]\nstep = 0\nepoch = 0\nfault = "lock"\ntarget = "all"\n'
                        'robot = 1\n')  # fmt: skip
    s = run(tmp_path, "r", "--placement", "single", "--epochs", "3", "--steps", "150", "--set", "run.fleet=2",
            "--scenario", str(scenario))  # fmt: skip
    cfg = run_config(CHAIN4)
    topo = cfg.topo()
    tip = kinematics.tips(topo, topo.initial_angles())[topo.end_effectors[0]]
    goal = cfg.task["goal"]
    start_error = math.hypot(tip[0] - goal[0], tip[1] - goal[1])
    robot1 = [row[1] for row in s["fleet_final_error"]]
    robot0 = [row[0] for row in s["fleet_final_error"]]
    assert robot1 == pytest.approx([start_error] * 3, abs=1e-6)  # PyBullet's link states are single precision
    assert min(robot0) < start_error / 2
    events = [json.loads(line) for line in (tmp_path / "r" / "events.jsonl").read_text().splitlines()]
    locks = [e for e in events if e.get("event") == "lock"]
    assert {e["target"] for e in locks} == {"a1", "a2", "a3", "a4"}
    assert all("robot=1" in e["detail"] for e in locks)


def test_the_lanes_learn_as_one_learner():
    """Lane b's call computes exactly what one learner computes from the Q, the counts and the random generator the
    calls before it left, with lane b's own transition: checked call by call, robots interleaved."""
    cfg = run_config(CHAIN4)
    settings = learner_settings(task_of(cfg), cfg.learner, cfg.source)["a3"]
    shared = Learner(settings, 1, agent_seed(0, "a3"))
    lanes = [LearnerLane(shared) for _ in range(3)]
    rng = np.random.default_rng(1)
    for lane in lanes:
        lane.start_epoch(0)
    for t in range(40):
        for lane in lanes:
            state = rng.uniform(-1, 1, size=len(settings.n_sets))
            reward = None if t == 0 else float(rng.normal())
            one = copy.deepcopy(shared)  # one learner: the shared state, and this lane's transition
            for name in EPISODE:
                setattr(one, name, copy.deepcopy(lane._own_state[name]))
            one._rules_and_O = [(one._fired[i, 0], one._w[i]) for i in (0, 1)]
            one._fired[one._latest, 1] = one.q.lookup(one._fired[one._latest, 0])  # one learner's rows are current
            sel, nv = one._selection, one.n_visible  # deepcopy detaches views: the learner's are views of one array
            one.counts, one._P, one._E, one._z = sel[:nv], sel[nv : 2 * nv], sel[2 * nv], sel[2 * nv + 1]
            expected = one.decide(state, reward)
            assert lane.decide(state, reward) == expected
            seen = [int(rng.integers(0, 3))]
            one.observe(seen)
            lane.observe(seen)
            assert np.array_equal(shared.q.phi, one.q.phi) and np.array_equal(shared.counts, one.counts)
            assert lane._own_state["_pending"] == one._pending and lane._own_state["t"] == one.t
    assert shared.rules_used > 0


def test_gathering_sends_one_batch_per_key_and_a_second_for_a_robot_sending_twice():
    node = Node.__new__(Node)  # the gathering alone: no session (what send() does with a Batch is the runtime's)
    node._gathered, node._later = None, []
    node._step_prefixes = ("ks/r/sim/", "ks/r/a/")
    sent: list[tuple[str, object]] = []
    node.send = lambda key, msg: sent.append((key, msg))  # type: ignore[method-assign]
    cmd = [Cmd(epoch=0, step=1, delta=float(b)) for b in range(3)]
    with node.gathering():
        for b in range(3):
            node.send_as(b, "ks/r/sim/cmd/a1", cmd[b])
            node.send_as(b, "ks/r/a/a1/up", cmd[b])
            if b == 1:
                node.send_as(b, "ks/r/a/a1/up", cmd[b])  # a closing `up` after the step's
            node.send_as(b, "ks/r/metrics/event", "not a step message")
        with node.gathering():  # within a gathering, another adds to it
            node.send_as(2, "ks/r/sim/obs/a1", Obs(epoch=0, step=1, q=0.0))
        assert [k for k, _ in sent] == ["ks/r/metrics/event"] * 3  # what is not a step message goes at once
    batches = [(k, m) for k, m in sent if isinstance(m, Batch)]
    assert [(k, m.robots) for k, m in batches] == [
        ("ks/r/sim/cmd/a1", [0, 1, 2]),
        ("ks/r/a/a1/up", [0, 1, 2]),
        ("ks/r/a/a1/up", [1]),
        ("ks/r/sim/obs/a1", [2]),
    ]
    assert batches[0][1].items == cmd and batches[0][1].of == "cmd"
    with pytest.raises(RuntimeError), node.gathering():
        node.send_as(0, "ks/r/sim/cmd/a1", cmd[0])
        raise RuntimeError("the handler failed")
    assert len([m for _, m in sent if isinstance(m, Batch)]) == 4  # nothing of a failed handler went out


def test_what_a_lane_leaves_for_later_runs_once_the_gathered_batches_have_left():
    """An agent's `up` leaves before any robot learns (Node.after_sending): a fleet's learning stays off the step's
    critical path, as one robot's is; the later work runs in the order the lanes left it, and what it sends is
    gathered again."""
    node = Node.__new__(Node)
    node._gathered, node._later = None, []
    node._step_prefixes = ("ks/r/a/", "ks/r/sim/")
    sent: list[tuple[str, object]] = []
    node.send = lambda key, msg: sent.append((key, msg))  # type: ignore[method-assign]
    ran: list[tuple[int, int]] = []

    def learn(b: int) -> None:
        ran.append((b, len(sent)))  # how much had left when robot b learned
        node.send_as(b, "ks/r/sim/cmd/a2", Cmd(epoch=0, step=0, delta=0.0))

    node.after_sending(lambda: ran.append((-1, len(sent))))  # outside a gathering: at once
    with node.gathering():
        for b in range(3):
            node.send_as(b, "ks/r/a/a1/up", Cmd(epoch=0, step=0, delta=0.0))
            node.after_sending(lambda b=b: learn(b))
        assert ran == [(-1, 0)] and sent == []
    assert ran == [(-1, 0), (0, 1), (1, 1), (2, 1)]  # every robot's up had left, as one batch, before any learned
    assert [(k, m.robots) for k, m in sent] == [("ks/r/a/a1/up", [0, 1, 2]), ("ks/r/sim/cmd/a2", [0, 1, 2])]


@pytest.mark.parametrize(
    "sets, why",
    [
        (["run.fleet=0"], "fleet: expected an integer in [1, 1024], got 0"),
        (["run.fleet=5000"], "fleet: expected an integer in [1, 1024], got 5000"),
        (['run.fleet="many"'], "fleet"),
        (["run.fleet=2", 'run.controller="pinv"'], "only the learning agents drive a fleet"),
    ],
)
def test_a_bad_fleet_is_one_line_before_anything_starts(tmp_path, capsys, sets, why):
    argv = ["run", str(CHAIN4), "--out", str(tmp_path / "x"), "--no-progress"]
    for s in sets:
        argv += ["--set", s]
    assert cli_main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert why in err and len(err.splitlines()) == 1
    assert not (tmp_path / "x").exists()


def test_a_robot_outside_the_fleet_and_a_robot_for_an_agent_fault_are_refused(tmp_path, capsys):
    scenario = tmp_path / "s.toml"
    scenario.write_text('name = "s"\n\n[[event]]\nstep = 0\nfault = "lock"\ntarget = "a2"\nrobot = 2\n')
    argv = ["run", str(CHAIN4), "--out", str(tmp_path / "x"), "--no-progress", "--set", "run.fleet=2"]
    assert cli_main([*argv, "--scenario", str(scenario)]) == 2
    err = capsys.readouterr().err.strip()
    assert "event[0].robot" in err and "fleet has 2" in err and len(err.splitlines()) == 1
    with pytest.raises(ControlError, match="only joint faults take a robot"):
        make_fault("kill", ["a2"], robot=1)
    assert make_fault("lock", ["a2"], robot=1).robot == 1


def test_spread_goals_give_each_robot_the_task_goal_of_its_own_epoch(tmp_path):
    """Learning and exploring off, a robot's run depends on its goal alone: robot b of a spread fleet at epoch e ends
    as one robot on the task's goal of epoch e*B + b does."""
    goals = "task.goals=[[4.16, 6.18], [-5.0, 7.0], [3.0, -6.0], [8.0, 2.0]]"
    run(tmp_path, "t", "--epochs", "4", "--steps", "200", "--placement", "single", "--set", goals)
    frozen = ("--learn", "off", "--explore", "off", "--steps", "60", "--placement", "single", "--set", goals)
    frozen += ("--from", str(tmp_path / "t"))  # trained: its greedy choices are not ties (an untrained Q's are all
    # ties, broken by the random generator, which the robots share)
    fleet = run(tmp_path, "f", "--epochs", "2", "--set", "run.fleet=2", "--set", 'run.fleet_goals="spread"', *frozen)
    one = run(tmp_path, "o", "--epochs", "4", *frozen)
    assert [e for row in fleet["fleet_final_error"] for e in row] == one["final_error"]
    same = run(tmp_path, "s", "--epochs", "1", "--set", "run.fleet=3", *frozen)
    assert same["fleet_final_error"] == [[one["final_error"][0]] * 3]


def test_spread_goals_refuse_a_moving_goal(tmp_path, capsys):
    argv = ["run", str(EXAMPLES / "chain4-track.toml"), "--out", str(tmp_path / "x"), "--no-progress"]
    assert cli_main([*argv, "--set", "run.fleet=2", "--set", 'run.fleet_goals="spread"']) == 2
    err = capsys.readouterr().err.strip()
    assert "fleet_goals" in err and "moves" in err and len(err.splitlines()) == 1


# ~45 s: slow suite; tests/test_faults.py's kills keep the restart path in the default
@pytest.mark.slow
def test_an_agent_killed_in_a_fleet_is_restarted_for_every_robot(tmp_path):
    """kill acts on the agent, so on that joint of every robot: it is back from its checkpoint (its parent standing in
    meanwhile, when the restart takes longer than a step: timing), and the fleet's run goes on to its end."""
    scenario = tmp_path / "kill.toml"
    scenario.write_text('name = "kill a3"\n\n[[event]]\nstep = 60\nepoch = 1\nfault = "kill"\ntarget = "a3"\n')
    s = run(tmp_path, "k", "--placement", "process", "--epochs", "3", "--steps", "150", "--set", "run.fleet=3",
            "--scenario", str(scenario))  # fmt: skip
    assert len(s["fleet_final_error"]) == 3 and all(len(row) == 3 for row in s["fleet_final_error"])
    events = [json.loads(line) for line in (tmp_path / "k" / "events.jsonl").read_text().splitlines()]
    kinds = {(e.get("event"), e.get("target")) for e in events}
    assert {("exited", "a3"), ("restart", "a3"), ("restored", "a3")} <= kinds, kinds
    assert swarm_pids(str(tmp_path / "k")) == []


def test_a_rule_has_one_row_of_phi_however_the_robots_interleave():
    """A rule s(t-1) fired that no update had touched when robot b decided may have been given its phi row by another
    robot's update since: robot b's update must find that row, not give the rule a second one (which would orphan
    what the first learned)."""
    cfg = run_config(CHAIN4)
    settings = learner_settings(task_of(cfg), cfg.learner, cfg.source)["a4"]
    shared = Learner(settings, 0, agent_seed(0, "a4"))
    lanes = [LearnerLane(shared) for _ in range(4)]
    for lane in lanes:
        lane.start_epoch(0)
    state = np.zeros(len(settings.n_sets))
    for t in range(30):
        for b, lane in enumerate(lanes):  # the robots in nearby states: the rules they fire overlap
            lane.decide(state + 0.01 * b + 0.002 * t, None if t == 0 else 1.0)
            lane.observe([])
    index, n = shared.q.index, int(shared.q.index.size[0])
    rules, rows = index.entries[0, :n].tolist(), index.entries[1, :n].tolist()
    assert n > 0 and len(set(rules)) == n
    assert sorted(rows) == list(range(n))  # rows 0..n-1, each one rule's: none orphaned, none shared
