"""The pseudo-inverse baseline: 1-degree steps, convergence on the paper's chain4 reaching task."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from kinswarm.protocol.topology import load_topology
from kinswarm.sim import kinematics
from kinswarm.sim.baseline import pinv_increments, run_baseline
from kinswarm.sim.world import World

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


def test_step_size_capped_and_zero_at_goal() -> None:
    topo = load_topology(EXAMPLES / "chain4.toml")
    q = topo.initial_angles()
    dq = pinv_increments(topo, q, topo.goal)
    assert set(dq) == set(topo.dof_agents)
    assert max(abs(v) for v in dq.values()) == pytest.approx(math.radians(1))
    small = pinv_increments(topo, q, topo.goal, max_step=math.radians(0.1))
    assert max(abs(v) for v in small.values()) == pytest.approx(math.radians(0.1))
    (tip,) = kinematics.tips(topo, q).values()
    assert pinv_increments(topo, q, tip[:2]) == dict.fromkeys(topo.dof_agents, 0.0)
    # The step points downhill: the tip gets closer to the goal.
    after = {a: q[a] + dq[a] for a in q}
    (tip2,) = kinematics.tips(topo, after).values()
    assert math.dist(tip2[:2], topo.goal) < math.dist(tip[:2], topo.goal)


def test_chain4_converges_in_model_and_world() -> None:
    topo = load_topology(EXAMPLES / "chain4.toml")
    steps, q = run_baseline(topo, topo.goal, tol=0.01)
    assert steps is not None and steps < 100
    # The same increments applied to the PyBullet world reach the goal too.
    with World(topo) as world:
        for _ in range(steps):
            world.apply_increments(pinv_increments(topo, world.joint_positions(), topo.goal))
        (tip,) = world.tip_poses().values()
        assert math.dist(tip[:2], topo.goal) <= 0.01 + 1e-5
        assert world.joint_positions() == pytest.approx(q, abs=1e-12)
    steps_fine, _ = run_baseline(topo, topo.goal, tol=1e-6)
    assert steps_fine is not None and steps_fine < steps + 10


def test_tree5_both_leaves_reach_shared_goal() -> None:
    topo = load_topology(EXAMPLES / "tree5.toml")
    steps, q = run_baseline(topo, topo.goal, tol=0.01, max_steps=2000)
    assert steps is not None
    for x, y, _ in kinematics.tips(topo, q).values():
        assert math.dist((x, y), topo.goal) <= 0.01
