"""The model-based baselines: the pseudo-inverse (1-degree steps, convergence on the paper's chain4 reaching task)
the greedy per-joint reference, the rule on g_perp and the rule on g_q."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from kinswarm.protocol.robots import load_robot
from kinswarm.sim import kinematics
from kinswarm.sim.baseline import greedy_increments, pinv_increments, rule_increments, run_baseline
from kinswarm.sim.world import World

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
GOAL = {"chain4": (4.16, 6.18), "tree5": (0.0, 5.0)}  # the example run files' [task] goals


def test_step_size_capped_and_zero_at_goal() -> None:
    topo = load_robot(EXAMPLES / "chain4.toml")
    q = topo.initial_angles()
    dq = pinv_increments(topo, q, GOAL[topo.name])
    assert set(dq) == set(topo.dof_agents)
    assert max(abs(v) for v in dq.values()) == pytest.approx(math.radians(1))
    small = pinv_increments(topo, q, GOAL[topo.name], max_step=math.radians(0.1))
    assert max(abs(v) for v in small.values()) == pytest.approx(math.radians(0.1))
    (tip,) = kinematics.tips(topo, q).values()
    assert pinv_increments(topo, q, tip[:2]) == dict.fromkeys(topo.dof_agents, 0.0)
    # The step points downhill: the tip gets closer to the goal.
    after = {a: q[a] + dq[a] for a in q}
    (tip2,) = kinematics.tips(topo, after).values()
    assert math.dist(tip2[:2], GOAL[topo.name]) < math.dist(tip[:2], GOAL[topo.name])


def test_chain4_converges_in_model_and_world() -> None:
    topo = load_robot(EXAMPLES / "chain4.toml")
    steps, q = run_baseline(topo, GOAL[topo.name], tol=0.01)
    assert steps is not None and steps < 100
    # The same increments applied to the PyBullet world reach the goal too.
    with World(topo) as world:
        for _ in range(steps):
            world.apply_increments(pinv_increments(topo, world.joint_positions(), GOAL[topo.name]))
        (tip,) = world.tip_poses().values()
        assert math.dist(tip[:2], GOAL[topo.name]) <= 0.01 + 1e-5
        assert world.joint_positions() == pytest.approx(q, abs=1e-12)
    steps_fine, _ = run_baseline(topo, GOAL[topo.name], tol=1e-6)
    assert steps_fine is not None and steps_fine < steps + 10


def test_tree5_both_leaves_reach_shared_goal() -> None:
    topo = load_robot(EXAMPLES / "tree5.toml")
    steps, q = run_baseline(topo, GOAL[topo.name], tol=0.01, max_steps=2000)
    assert steps is not None
    for x, y, _ in kinematics.tips(topo, q).values():
        assert math.dist((x, y), GOAL[topo.name]) <= 0.01


def test_greedy_moves_each_joint_alone_to_its_best_and_holds_otherwise() -> None:
    topo = load_robot(EXAMPLES / "chain4.toml")
    q = topo.initial_angles()
    step = math.radians(1)

    def dist(angles: dict[str, float]) -> float:
        ((x, y, _),) = kinematics.tips(topo, angles).values()
        return math.dist((x, y), GOAL[topo.name])

    dq = greedy_increments(topo, q, GOAL[topo.name])
    assert set(dq) == set(topo.dof_agents)
    for a in topo.dof_agents:  # by brute force: the best of -1, 0, +1 degree for this joint, the others held
        best = min((-step, 0.0, step), key=lambda d, a=a: (dist({**q, a: q[a] + d}), d != 0.0))
        assert dq[a] == pytest.approx(best)
    assert any(dq.values())
    # at the goal nobody moves (any move takes the tip away); at a joint's limit it does not push past it
    (tip,) = kinematics.tips(topo, q).values()
    assert greedy_increments(topo, q, tip[:2]) == dict.fromkeys(topo.dof_agents, 0.0)
    lo, hi = topo.agents["a1"].limits
    at_limit = {**q, "a1": hi}
    for goal in ((-5.0, 5.0), (5.0, -5.0)):
        d = greedy_increments(topo, at_limit, goal)["a1"]
        assert hi + d <= hi
    with pytest.raises(ValueError, match="max_step"):
        greedy_increments(topo, q, GOAL[topo.name], max_step=0.0)


def test_greedy_can_fold_into_a_local_minimum() -> None:
    """Why it is a reference and not the answer: for a goal far behind the start tip (Halton test goal 71 of
    set 0; the start tip is at (10.05, 4.62)) the greedy joints curl round into a joint limit and stop, far
    from the goal, in a configuration where no single joint's move brings the tip nearer."""
    topo = load_robot(EXAMPLES / "chain4.toml")
    goal = (-6.875, -6.419753)
    q = topo.initial_angles()
    for _ in range(400):
        dq = greedy_increments(topo, q, goal)
        if not any(dq.values()):
            break
        q = {a: q[a] + dq[a] for a in q}
    assert not any(greedy_increments(topo, q, goal).values())  # stuck
    ((x, y, _),) = kinematics.tips(topo, q).values()
    assert math.dist((x, y), goal) > 3.0
    assert any(q[a] == pytest.approx(topo.agents[a].limits[1]) for a in q)  # folded into a limit


def test_rule_moves_each_joint_along_its_own_g_perp_and_keeps_inside_its_dead_band() -> None:
    """One step along sign(g_perp) per joint (the goal along the direction the joint moves the tip), nothing
    inside one move's arc; it reaches the example goal on the model; with a motor reversed it cannot know."""
    topo = load_robot(EXAMPLES / "chain4.toml")
    goal, deg = GOAL["chain4"], math.radians(1)
    q = topo.initial_angles()
    dq = rule_increments(topo, q, goal)
    (tip,) = kinematics.tips(topo, q).values()
    motion = kinematics.jacobian(topo, q, topo.end_effectors[0])
    w = (goal[0] - tip[0], goal[1] - tip[1])
    for i, a in enumerate(topo.dof_agents):
        assert dq[a] == pytest.approx(math.copysign(deg, w[0] * motion[0, i] + w[1] * motion[1, i]))
    near = (tip[0] + 0.001, tip[1])  # inside every joint's dead band
    assert rule_increments(topo, q, near) == dict.fromkeys(topo.dof_agents, 0.0)

    def final_error(sign_a1: float) -> float:
        q = topo.initial_angles()
        for _ in range(400):
            for a, d in rule_increments(topo, q, goal).items():
                lo, hi = topo.agents[a].limits
                q[a] = min(max(q[a] + (sign_a1 if a == "a1" else 1.0) * d, lo), hi)
        ((x, y, _),) = kinematics.tips(topo, q).values()
        return math.dist((x, y), goal)

    assert final_error(1.0) < 0.2
    assert final_error(-1.0) > 0.5, "a reversed motor: the rule pushes the wrong way"


def test_the_turn_rule_steps_each_joint_toward_its_own_best_angle_and_reaches_a_pose() -> None:
    """One step toward sign(g_q) per joint, nothing within a step of it; on the model it brings the iiwa's tool to a
    pose from the start a random configuration gives, moving finely near it; a planar robot is refused."""
    import numpy as np
    from kinswarm.protocol import frames
    from kinswarm.sim.baseline import move_size, turn_increments

    topo = load_robot(EXAMPLES / "iiwa.toml")
    deg = math.radians(1)
    rng = np.random.default_rng(5)
    lims = np.array([topo.agents[a].limits for a in topo.dof_agents])
    target = rng.uniform(-1, 1, 7) * lims[:, 1] * 0.5
    (goal,) = frames.tips(topo, dict(zip(topo.dof_agents, target, strict=True))).values()
    q = topo.initial_angles()
    links = frames.link_frames(topo, q)
    (tip,) = frames.tips(topo, q).values()
    dq = turn_increments(topo, q, goal)
    for a in topo.dof_agents:
        lo, hi = topo.agents[a].limits
        t = frames.best_turn(frames.joint_axis(topo.agents[a], links[a]), links[a], tip, goal, (lo - q[a], hi - q[a]))
        assert dq[a] == (math.copysign(deg, t) if abs(t) > deg else 0.0)
    assert turn_increments(topo, q, tip) == dict.fromkeys(topo.dof_agents, 0.0)  # at the goal: every joint keeps
    assert move_size(topo, q, goal, deg) == deg and move_size(topo, q, tip, deg) == deg * frames.FINE_SHARE
    steps, _ = run_baseline(topo, goal, angles=q, tol=0.05, max_steps=600, law="turn")
    assert steps is not None, "the turn rule did not reach the pose"
    with pytest.raises(ValueError, match="robot from URDF"):
        turn_increments(load_robot(EXAMPLES / "chain4.toml"), {}, (1.0, 1.0))


def test_a_baseline_controller_says_goodbye(tmp_path) -> None:
    """The controller answers the supervisor's Stop with its Bye, as every actor does, so the run ends without the
    supervisor's wait for it running out (its count of rejected messages is in the summary only from a Bye)."""
    import json

    from conftest import EXAMPLES, free_port
    from kinswarm.actors.cli.commands import main

    out = tmp_path / "b"
    args = ["baseline", str(EXAMPLES / "chain4.toml"), "--epochs", "1", "--steps", "10", "--no-progress"]
    args += ["--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}", "--placement", "single"]
    assert main(args) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert "pinv" in summary["rejected_by_actor"], summary["rejected_by_actor"]
