"""The PyBullet World against the closed-form kinematics; every client is closed by its context manager."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from kinswarm.protocol.robots import load_robot
from kinswarm.protocol.topology import Topology
from kinswarm.sim import kinematics
from kinswarm.sim.urdf import write_urdf
from kinswarm.sim.world import World, pb  # world imports pybullet with its banner silenced
from test_sim_kinematics import compound_tree

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
TOL = 1e-5  # PyBullet link poses come back as float32


def wrap(a: float) -> float:
    return math.atan2(math.sin(a), math.cos(a))


def assert_tips_match(world: World, topo: Topology) -> None:
    want = kinematics.tips(topo, world.joint_positions())
    got = world.tip_poses()
    assert set(got) == set(want) == set(topo.end_effectors)
    for leaf, (x, y, h) in got.items():
        wx, wy, wh = want[leaf]
        assert abs(x - wx) < TOL and abs(y - wy) < TOL, (leaf, got[leaf], want[leaf])
        assert abs(wrap(h - wh)) < TOL, (leaf, h, wh)


@pytest.mark.parametrize("name", ["chain4.toml", "tree5.toml", "compound"])
def test_tip_poses_match_kinematics_random(name: str, tmp_path: Path) -> None:
    topo = compound_tree() if name == "compound" else load_robot(EXAMPLES / name)
    rng = np.random.default_rng(0)
    with World(topo, urdf_dir=tmp_path) as world:
        assert_tips_match(world, topo)
        for _ in range(50):
            q = {a: float(rng.uniform(*topo.agents[a].limits)) for a in topo.dof_agents}
            world.reset(q)
            assert world.joint_positions() == q
            assert_tips_match(world, topo)
    assert not list(tmp_path.iterdir()), "close() removes the URDF it wrote"


def test_increments_match_kinematics() -> None:
    topo = load_robot(EXAMPLES / "tree5.toml")
    rng = np.random.default_rng(1)
    with World(topo) as world:
        for _ in range(50):
            step = {a: float(rng.choice([-1, 0, 1])) * math.radians(1) for a in topo.dof_agents}
            world.apply_increments(step)
            assert_tips_match(world, topo)


def test_reset_defaults_to_initial_and_validates() -> None:
    topo = load_robot(EXAMPLES / "chain4.toml")
    with World(topo) as world:
        world.apply_increments({"a1": 0.3})
        world.reset()
        assert world.joint_positions() == topo.initial_angles()
        with pytest.raises(ValueError):
            world.reset({"a1": 0.0})  # missing agents
        with pytest.raises(ValueError):
            world.reset({**topo.initial_angles(), "a2": 4.0})  # beyond 180 deg


def test_limits_clip_and_report_applied(tmp_path: Path) -> None:
    topo = load_robot(EXAMPLES / "chain4.toml")
    with World(topo) as world:
        lo, hi = topo.agents["a1"].limits
        world.reset({**topo.initial_angles(), "a1": hi - math.radians(0.5)})
        applied = world.apply_increments({"a1": math.radians(1)})
        assert applied["a1"] == pytest.approx(math.radians(0.5))
        assert world.joint_positions()["a1"] == hi
        assert world.apply_increments({"a1": math.radians(1)})["a1"] == 0.0
        assert world.joint_positions()["a1"] == hi
        # PyBullet itself holds the clipped value (its resetJointState ignores limits).
        assert pb.getJointState(world.body, world.joint_index["a1"], physicsClientId=world.client)[0] == hi
        world.reset({**topo.initial_angles(), "a1": lo})
        assert world.apply_increments({"a1": -0.1})["a1"] == 0.0
        assert_tips_match(world, topo)


def test_missing_increments_hold_and_unknown_rejected() -> None:
    topo = load_robot(EXAMPLES / "chain4.toml")
    with World(topo) as world:
        before = world.joint_positions()
        applied = world.apply_increments({"a3": 0.01})
        after = world.joint_positions()
        assert applied == {"a1": 0.0, "a2": 0.0, "a3": pytest.approx(0.01), "a4": 0.0}
        assert {a: after[a] for a in ("a1", "a2", "a4")} == {a: before[a] for a in ("a1", "a2", "a4")}
        assert after["a3"] == pytest.approx(before["a3"] + 0.01, abs=1e-15)
        world.apply_increments({})
        assert world.joint_positions() == after
        with pytest.raises(KeyError):
            world.apply_increments({"nope": 0.1})
        with pytest.raises(ValueError):
            world.apply_increments({"a1": math.nan})


def test_compound_agent_is_fixed() -> None:
    topo = compound_tree()
    with World(topo) as world:
        assert "hand" not in world.joint_positions()
        info = pb.getJointInfo(world.body, world.joint_index["hand"], physicsClientId=world.client)
        assert info[2] == pb.JOINT_FIXED
        with pytest.raises(KeyError):
            world.apply_increments({"hand": 0.1})


def test_two_worlds_do_not_interfere() -> None:
    chain = load_robot(EXAMPLES / "chain4.toml")
    tree = load_robot(EXAMPLES / "tree5.toml")
    with World(chain) as w1, World(chain) as w2, World(tree) as w3:
        assert len({w1.client, w2.client, w3.client}) == 3
        assert w1.urdf_path != w2.urdf_path
        tip2 = w2.tip_poses()
        tip3 = w3.tip_poses()
        for _ in range(10):
            w1.apply_increments({"a1": 0.05, "a4": -0.05})
        assert w2.tip_poses() == tip2 and w3.tip_poses() == tip3
        assert w2.joint_positions() == chain.initial_angles()
        assert_tips_match(w1, chain)
        w1.close()
        w1.close()  # idempotent
        assert w2.tip_poses() == tip2
        assert_tips_match(w3, tree)


def test_urdf_names_unique(tmp_path: Path) -> None:
    topo = load_robot(EXAMPLES / "chain4.toml")
    paths = {write_urdf(topo, tmp_path) for _ in range(20)}
    assert len(paths) == 20


def test_base_pose_applied() -> None:
    topo = compound_tree()  # base (1, -2, 30 deg)
    with World(topo) as world:
        pos, orn = pb.getBasePositionAndOrientation(world.body, physicsClientId=world.client)
        assert pos[:2] == pytest.approx((1.0, -2.0))
        assert pb.getEulerFromQuaternion(orn)[2] == pytest.approx(math.radians(30))
