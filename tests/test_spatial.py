"""Robots from URDF: the tree and frames read from the file, the rotation-plane state, the reach3d task's checks and the
wire's spatial coordinates (the simulator's side: test_spatial_sim.py)."""

from __future__ import annotations

import math
import random

import numpy as np
import pytest
from conftest import IIWA, PANDA, XARM6, urdf_robot
from kinswarm.actors.files.runfile import load_run, task_of
from kinswarm.actors.learning.state import goal_along_motion, plane_state
from kinswarm.actors.step.geometry import Spatial
from kinswarm.protocol import codec, frames
from kinswarm.protocol.messages import Down, EpochStart, Up
from kinswarm.protocol.robots import parse_robot
from kinswarm.protocol.spec import SpecError

KEY = b"k" * 32


robot = urdf_robot


@pytest.mark.parametrize(
    ("table", "n", "joint1"),
    [(IIWA, 7, "lbr_iiwa_joint_1"), (PANDA, 7, "panda_joint1"), (XARM6, 6, "joint1")],
)
def test_one_agent_per_movable_joint_nested_as_the_urdf(table, n, joint1):
    topo = robot(table)
    assert topo.spatial and len(topo.dof_agents) == n
    assert topo.agents["a1"].joint == joint1 and topo.root == "a1"
    chain = [topo.root]
    while topo.agents[chain[-1]].children:
        (child,) = topo.agents[chain[-1]].children
        chain.append(child)
    assert chain == [f"a{i}" for i in range(1, n + 1)]  # a chain, parents first, as the URDF nests them
    assert topo.end_effectors == (f"a{n}",)


def test_the_panda_with_its_fingers_is_a_tree():
    topo = robot({"urdf": "franka_panda/panda.urdf"})
    assert len(topo.dof_agents) == 9
    fingers = [a for a in topo.order if topo.agents[a].prismatic]
    assert len(fingers) == 2 and set(topo.end_effectors) == set(fingers)
    assert topo.agents[fingers[0]].parent == topo.agents[fingers[1]].parent == "a7"


@pytest.mark.parametrize("table", [IIWA, PANDA, XARM6])
def test_frames_equal_pybullets_link_frames(table):
    import pybullet as pb

    topo = robot(table)
    client = pb.connect(pb.DIRECT)
    try:
        body = pb.loadURDF(topo.urdf, useFixedBase=True, physicsClientId=client)
        index = {
            pb.getJointInfo(body, j, physicsClientId=client)[1].decode(): j
            for j in range(pb.getNumJoints(body, physicsClientId=client))
        }
        for name, value in topo.held:
            pb.resetJointState(body, index[name], value, physicsClientId=client)
        rng = random.Random(3)
        for _ in range(10):
            q = {a: rng.uniform(*topo.agents[a].limits) for a in topo.dof_agents}
            for a, v in q.items():
                pb.resetJointState(body, index[topo.agents[a].joint], v, physicsClientId=client)
            links = frames.link_frames(topo, q)
            for a in topo.order:
                st = pb.getLinkState(
                    body, index[topo.agents[a].joint], computeForwardKinematics=1, physicsClientId=client
                )
                assert math.dist(st[4], links[a][:3]) < 1e-6
                assert frames.angle_between(st[5], links[a][3:]) < 1e-3  # PyBullet's float32 quaternions
    finally:
        pb.disconnect(physicsClientId=client)


@pytest.mark.parametrize(
    ("table", "field", "words"),
    [
        ({"urdf": "no/such.urdf"}, "robot.urdf", "no such file"),
        ({**IIWA, "joints": ["lbr_iiwa_joint_9"]}, "robot.joints", "not a movable joint"),
        ({**IIWA, "joints": []}, "robot.joints", "no movable joint"),
        ({**IIWA, "home_deg": [0, 200, 0, 0, 0, 0, 0]}, "robot.home_deg", "outside its limits"),
        ({**IIWA, "home_deg": [0, 0]}, "robot.home_deg", "list of 7"),
        ({**IIWA, "tool_link": "nowhere"}, "robot.tool_link", "no link"),
        ({**IIWA, "tool": [0, 0]}, "robot.tool", "x, y, z"),
        ({**IIWA, "wheels": 4}, "robot.wheels", "unknown field"),
        (
            {**PANDA, "joints": ["panda_joint1", "panda_finger_joint1", "panda_finger_joint2"], "tool_link": None},
            "",
            "",
        ),
    ],
)
def test_what_a_urdf_robot_gets_wrong_is_one_line(table, field, words):
    table = {k: v for k, v in table.items() if v is not None}
    if not field:  # a1 and the two fingers: one tree (the fingers hang from a1 through the held joints)
        topo = robot(table)
        assert topo.agents["a2"].parent == topo.agents["a3"].parent == "a1"
        return
    with pytest.raises(SpecError) as e:
        robot(table)
    assert e.value.where == field and words in e.value.what and "\n" not in str(e.value)


def test_a_floating_joint_is_refused(tmp_path):
    urdf = tmp_path / "float.urdf"
    urdf.write_text(
        '<robot name="f"><link name="b"/><link name="c"/>'
        '<joint name="j" type="floating"><parent link="b"/><child link="c"/></joint></robot>'
    )
    with pytest.raises(SpecError, match="floating joint is not supported"):
        parse_robot({"urdf": str(urdf)}, str(tmp_path / "run.toml"))


def test_a_continuous_joint_gets_half_a_turn_each_way(tmp_path):
    urdf = tmp_path / "wheel.urdf"
    urdf.write_text(
        '<robot name="w"><link name="b"/><link name="c"/>'
        '<joint name="j" type="continuous"><parent link="b"/><child link="c"/><axis xyz="0 0 1"/></joint></robot>'
    )
    topo = parse_robot({"urdf": "wheel.urdf"}, str(tmp_path / "run.toml"))  # relative to the run file
    assert topo.agents["a1"].limits == (-math.pi, math.pi)


def test_the_plane_state_is_the_planar_one_in_the_plane():
    """With every axis along z, d is the planar lever and g_perp the planar goal_along_motion."""
    rng = np.random.default_rng(0)
    for _ in range(50):
        joint, tip, goal = (rng.uniform(-2, 2, 2) for _ in range(3))
        s = plane_state(0.3, (*joint, 0.0), (0.0, 0.0, 1.0), (*tip, 0.0), (*goal, 0.0))
        assert s[0] == 0.3
        assert s[1] == pytest.approx(math.dist(joint, tip))
        assert s[2] == pytest.approx(goal_along_motion((*joint, 0.0), tip, goal))
        assert s[3] == 0.0 and s[5] == pytest.approx(math.dist(tip, goal))


def test_g_perp_says_which_way_the_joint_brings_the_tip_closer():
    """A small increase of q_i moves the tip closer to the goal exactly when g_perp > 0 (the iiwa, every joint)."""
    topo = robot(IIWA)
    geom = Spatial()
    rng = random.Random(1)
    for _ in range(20):
        q = {a: rng.uniform(*topo.agents[a].limits) * 0.8 for a in topo.dof_agents}
        goal = (rng.uniform(-0.6, 0.6), rng.uniform(-0.6, 0.6), rng.uniform(0.2, 1.0))
        links = frames.link_frames(topo, q)
        (tip,) = frames.tips(topo, q).values()
        for a in topo.dof_agents:
            g_perp = geom.state(topo.agents[a], links[a], q[a], tip, goal, False, "plane")[2]
            (moved,) = frames.tips(topo, {**q, a: q[a] + 1e-5}).values()
            closer = math.dist(moved[:3], goal) < math.dist(tip[:3], goal)
            if abs(g_perp) > 1e-6:
                assert closer == (g_perp > 0), a


def test_each_agent_composes_the_frames_the_model_computes():
    """What the agents compose step by step on the wire (parent's frame -> child's) equals link_frames."""
    topo = robot(PANDA)
    geom = Spatial()
    q = {a: 0.3 * i for i, a in enumerate(topo.dof_agents)}
    expected = frames.link_frames(topo, q)
    base = topo.base
    for a in topo.order:  # a chain: each agent's end is its child's base
        frame = geom.joint_frame(topo.agents[a], base, q[a])
        assert max(abs(x - y) for x, y in zip(frame, expected[a], strict=True)) < 1e-12
        base = geom.link_end(topo.agents[a], frame)


def test_spatial_coordinates_on_the_wire():
    pose = (0.1, 0.2, 0.3, 0.0, 0.0, 0.0, 1.0)
    for msg, kind in (
        (Down(epoch=0, step=1, base=pose, goal=(0.5, 0.1, 0.4), reward=None), Down),
        (Up(epoch=0, step=1, tips={"a7": pose}, action=2), Up),
        (EpochStart(epoch=0, steps=5, goal=pose, start={"a1": 0.5}), EpochStart),
    ):
        assert codec.decode(codec.encode(msg, "r", "x", KEY), kind, "r", KEY) == msg
    with pytest.raises(codec.DecodeError, match="expected a list of 2 or 3 or 7"):
        bad = Down(epoch=0, step=1, base=(0.0,) * 5, goal=(0.5, 0.1, 0.4), reward=None)
        codec.decode(codec.encode(bad, "r", "x", KEY), Down, "r", KEY)


def _run_file(tmp_path, robot_toml: str, task_toml: str, learner_toml: str = ""):
    f = tmp_path / "run.toml"
    f.write_text(
        f"[robot]\n{robot_toml}\n[task]\n{task_toml}\n" + (f"[learner]\n{learner_toml}\n" * bool(learner_toml))
    )
    return f


IIWA_TOML = 'urdf = "kuka_iiwa/model.urdf"\ntool = [0.0, 0.05, 0.1]'


@pytest.mark.parametrize(
    ("robot_toml", "task_toml", "field", "words"),
    [
        (IIWA_TOML, 'kind = "reach"\ngoal = [0.5, 0.5]', "task.kind", "does not move a robot from URDF"),
        (
            'name = "c"\n[[robot.agent]]\nid = "a1"\nlink_length = 1.0',
            'kind = "reach3d"\ngoal = [0.5, 0.1, 0.2]',
            "task.kind",
            "does not move a planar robot",
        ),
        (IIWA_TOML, 'kind = "reach3d"\ngoal = [3.0, 0.0, 0.5]', "task.goal", "beyond its reach"),
        (IIWA_TOML, 'kind = "reach3d"\ngoals = [[0.5, 0.1, 0.2], [0.5, 0.1, 0.2, 0, 0, 0]]', "task.goals", "not both"),
        (IIWA_TOML, 'kind = "reach3d"\ngoal = [0.5, 0.1]', "task.goal", "[x, y, z]"),
        (IIWA_TOML, 'kind = "reach3d"\ngoal = [0.5, 0.1, 0.2]\nstarts = [[0, 0]]', "task.starts", "expected 7"),
        (
            IIWA_TOML,
            'kind = "reach3d"\ngoal = [0.5, 0.1, 0.2]\nstarts = [[0, 170, 0, 0, 0, 0, 0]]',
            "task.starts",
            "outside its limits",
        ),
    ],
)
def test_what_a_3d_run_file_gets_wrong_is_one_line(tmp_path, robot_toml, task_toml, field, words):
    with pytest.raises(SpecError) as e:
        task_of(load_run(_run_file(tmp_path, robot_toml, task_toml)))
    assert e.value.where == field and words in e.value.what, str(e.value)


def test_a_pose_goal_gives_every_joint_its_turn(tmp_path):
    """reach3d with a pose: goals travel as 7 floats; every agent's state is its turn (g_q), unless the run says
    "plane"; a state of the other geometry is refused in one line."""
    cfg = load_run(_run_file(tmp_path, IIWA_TOML, 'kind = "reach3d"\ngoal = [0.4, 0.2, 0.5, 180, 0, 90]'))
    task = task_of(cfg)
    goal, path = task.goal(0, 10)
    assert len(goal) == 7 and path == []
    assert frames.angle_between(goal[3:], frames.rpy_quat(math.pi, 0.0, math.pi / 2)) < 1e-12
    assert task.learner("a7", {}).state_names == ("g_q",)
    assert task.learner("a7", {"state": "plane"}).state_names == ("q", "d", "g_perp", "g_axial", "g_radial", "w")
    points = task_of(load_run(_run_file(tmp_path, IIWA_TOML, 'kind = "reach3d"\ngoal = [0.4, 0.2, 0.5]')))
    assert points.learner("a7", {}).state == "plane"
    with pytest.raises(SpecError) as e:
        load_run(_run_file(tmp_path, IIWA_TOML, 'kind = "reach3d"\ngoal = [0.4, 0.2, 0.5]', 'state = "planar"'))
    assert e.value.where == "learner.state" and "it takes: plane, turn" in e.value.what


def _pose_D(topo, q, goal) -> float:
    (tip,) = frames.tips(topo, q).values()
    if len(goal) == 3:
        return math.dist(tip[:3], goal)
    return frames.pose_distance(math.dist(tip[:3], goal[:3]), frames.angle_between(tip[3:7], goal[3:7]))


def test_g_q_is_where_the_joint_alone_brings_d_goal_lowest_within_its_limits():
    """best_turn against a brute-force sweep of the model, joint by joint, on random poses and points: the D_goal it
    reaches is the sweep's best (to a degree's sampling)."""
    topo = robot(IIWA)
    rng = np.random.default_rng(3)
    lims = np.array([topo.agents[a].limits for a in topo.dof_agents])
    for trial in range(6):
        q = dict(zip(topo.dof_agents, rng.uniform(lims[:, 0], lims[:, 1]), strict=True))
        (g,) = frames.tips(topo, dict(zip(topo.dof_agents, rng.uniform(lims[:, 0], lims[:, 1]), strict=True))).values()
        goal = g if trial % 2 else g[:3]
        links = frames.link_frames(topo, q)
        (tip,) = frames.tips(topo, q).values()
        for a in topo.dof_agents:
            spec = topo.agents[a]
            lo, hi = spec.limits
            t = frames.best_turn(frames.joint_axis(spec, links[a]), links[a], tip, goal, (lo - q[a], hi - q[a]))
            assert lo - 1e-9 <= q[a] + t <= hi + 1e-9
            sweep = min(_pose_D(topo, {**q, a: v}, goal) for v in np.linspace(lo, hi, 2000))
            assert _pose_D(topo, {**q, a: q[a] + t}, goal) <= sweep + 2e-3


def test_g_q_sees_the_long_way_round_when_the_short_one_is_barred():
    """a1's goal lies just past its limit: g_perp says turn up, g_q says turn down the long way (the only way)."""
    topo = robot(IIWA)
    lo, hi = topo.agents["a1"].limits
    q = dict.fromkeys(topo.dof_agents, 0.0) | {"a2": 0.6, "a1": hi - 0.05}
    (goal,) = frames.tips(topo, {**q, "a1": hi - 0.05 + 0.4 - 2 * math.pi}).values()  # = hi + 0.35, mod 2 pi
    links = frames.link_frames(topo, q)
    (tip,) = frames.tips(topo, q).values()
    axis = frames.joint_axis(topo.agents["a1"], links["a1"])
    state = plane_state(q["a1"], links["a1"][:3], axis, tip[:3], goal[:3])
    t = frames.best_turn(axis, links["a1"], tip, goal, (lo - q["a1"], hi - q["a1"]))
    assert state[2] > 0 and t < -math.pi  # the goal is just up, out of reach; more than half a turn down


def test_a_prismatic_joints_turn_is_its_shift():
    t = frames.best_turn((0.0, 0.0, 1.0), (0, 0, 0, 0, 0, 0, 1), (0, 0, 0.1), (0.2, 0.0, 0.13), (-0.05, 0.05), True)
    assert t == pytest.approx(0.03, abs=1e-3)
    assert frames.best_turn((0.0, 0.0, 1.0), (0, 0, 0, 0, 0, 0, 1), (0, 0, 0.1), (0, 0, 0.3), (-0.05, 0.05), True) == (
        pytest.approx(0.05)
    )


def test_moves_are_fine_near_a_pose_goal_only():
    goal = (0.5, 0.0, 0.5, 0.0, 0.0, 0.0, 1.0)
    assert frames.move_share((0.5, 0.0, 0.45, 0.0, 0.0, 0.0, 1.0), goal) == frames.FINE_SHARE
    assert frames.move_share((0.5, 0.0, 0.3, 0.0, 0.0, 0.0, 1.0), goal) == 1.0
    turned = (0.5, 0.0, 0.5, *frames.axis_angle((1.0, 0.0, 0.0), 0.5))  # on the point, 29° off: D = 0.125
    assert frames.move_share(turned, goal) == 1.0
    assert frames.move_share((0.5, 0.0, 0.45), goal[:3]) == 1.0  # a point goal: whole moves
