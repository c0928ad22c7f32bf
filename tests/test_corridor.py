"""The corridor (paper §5.4): obstacle parsing, PyBullet clearance against geometry, solid walls, the wire
fields, Eq. 11 and its variants, the scene settings of the learner, and a swarm run through the corridor."""

from __future__ import annotations

import asyncio
import json
import math
from pathlib import Path

import numpy as np
import pytest
from conftest import EXAMPLES
from kinswarm.actors.agent import Agent, _Step, _subtree_clearance, learner_settings
from kinswarm.actors.cli import main as cli_main
from kinswarm.actors.config import RunConfig
from kinswarm.actors.learning.fuzzy import FuzzyPartition
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.reward import corridor_reward, next_waypoint, path_distance
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.experiments.common import settings
from kinswarm.experiments.swarm import Spec, _supervise
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Cmd, EpochDone, Obs, Task, Up
from kinswarm.protocol.topology import TopologyError, load_topology, parse_topology
from kinswarm.sim.kinematics import frames
from kinswarm.sim.obstacles import Scene, SceneError
from kinswarm.sim.world import World

CORRIDOR = EXAMPLES / "corridor7.toml"
GUIDED = EXAMPLES / "corridor7-guided.toml"
RADIUS = 0.1  # the capsule radius of sim/urdf.py


def _doc(obstacles: list[dict], n: int = 2, initial: float = 0.0) -> dict:
    agents = [{"id": "a1", "initial_deg": initial}]
    agents += [{"id": f"a{i}", "parent": f"a{i - 1}", "initial_deg": 0.0} for i in range(2, n + 1)]
    return {"robot": {"name": "t"}, "defaults": {"link_length": 1.0}, "agent": agents, "obstacle": obstacles}


# -- parsing ---------------------------------------------------------------------------------------
def test_examples_parse():
    topo = load_topology(CORRIDOR)
    assert [o.id for o in topo.obstacles] == ["upper", "lower"]
    upper, lower = topo.obstacles
    assert upper.center == (4.5, 4.4) and upper.half_extents == (1.5, 2.0) and upper.angle == 0.0
    gap = (upper.center[1] - upper.half_extents[1]) - (lower.center[1] + lower.half_extents[1])
    assert gap == pytest.approx(0.8)
    assert topo.goal == (5.5, 2.0) and len(topo.dof_agents) == 7 and topo.reach == pytest.approx(7.0)
    relaxed = load_topology(EXAMPLES / "corridor7-relaxed.toml").obstacles
    assert (relaxed[0].center[1] - relaxed[0].half_extents[1]) - (
        relaxed[1].center[1] + relaxed[1].half_extents[1]
    ) == pytest.approx(1.2)
    assert load_topology(EXAMPLES / "chain4.toml").obstacles == ()


@pytest.mark.parametrize(
    ("obstacle", "field", "what"),
    [
        ({"half_extents": [1, 1]}, "obstacle[0].center", "missing"),
        ({"center": [1, 1]}, "obstacle[0].half_extents", "missing"),
        ({"center": [1, 1], "half_extents": [1, 0]}, "obstacle[0].half_extents", "> 0"),
        ({"center": [1, "x"], "half_extents": [1, 1]}, "obstacle[0].center[1]", "finite number"),
        ({"center": [1], "half_extents": [1, 1]}, "obstacle[0].center", "list of 2"),
        ({"center": [1, 1], "half_extents": [1, 1], "size": 3}, "obstacle[0].size", "unknown field"),
        ({"center": [1, 1], "half_extents": [1, 1], "angle_deg": True}, "obstacle[0].angle_deg", "finite"),
        ({"center": [1, 1], "half_extents": [1, 1], "id": "a b"}, "obstacle[0].id", "letters"),
    ],
)
def test_obstacle_errors_name_file_and_field(obstacle, field, what):
    with pytest.raises(TopologyError) as e:
        parse_topology(_doc([obstacle]), source="scene.toml")
    assert e.value.source == "scene.toml" and e.value.where == field and what in e.value.what
    assert str(e.value).startswith(f"scene.toml: {field}: ")


def test_obstacle_table_errors():
    box = {"center": [1, 1], "half_extents": [1, 1], "id": "w"}
    with pytest.raises(TopologyError, match="duplicate obstacle id 'w'"):
        parse_topology(_doc([box, box]), source="s.toml")
    doc = _doc([])
    doc["obstacle"] = {"center": [1, 1]}  # [obstacle] instead of [[obstacle]]
    with pytest.raises(TopologyError, match=r"s.toml: obstacle: expected \[\[obstacle\]\]"):
        parse_topology(doc, source="s.toml")


def test_bad_file_names_the_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(CORRIDOR.read_text().replace("half_extents = [1.5, 2.0]", "half_extents = [1.5, -2.0]", 1))
    with pytest.raises(TopologyError, match=rf"{p}: obstacle\[0\].half_extents: both must be > 0"):
        load_topology(p)


# -- geometry ----------------------------------------------------------------------------------------
def _exact_clearance(topo, angles: dict[str, float]) -> dict[str, float]:
    """Closed form: min over the link's axis (sampled finely, then refined) of the box's signed distance,
    minus the capsule radius; exact where the capsule is outside every box."""
    f = frames(topo, angles)
    out = {}
    for a in topo.dof_agents:
        x, y, h = f[a]
        length = topo.agents[a].link_length
        ts = np.linspace(0.0, length, 4001)
        best = min(o.signed_distance(x + t * math.cos(h), y + t * math.sin(h)) for o in topo.obstacles for t in ts)
        out[a] = best - RADIUS
    return out


def test_clearance_matches_geometry():
    topo = load_topology(CORRIDOR)
    rng = np.random.default_rng(0)
    with World(topo) as world:
        scene = Scene(world)
        checked = 0
        configs = [topo.initial_angles()]
        offset = np.array([0.7, 0, 0, 0, 0, 0, 0])  # a1 towards the walls, the others curling at random
        configs += [
            dict(zip(topo.dof_agents, (rng.uniform(-0.5, 0.5, 7) + offset).tolist(), strict=True)) for _ in range(12)
        ]
        for angles in configs:
            world.reset(angles)
            got = scene.clearances()
            want = _exact_clearance(topo, angles)
            for a in topo.dof_agents:
                if want[a] > 0.01:  # apart: PyBullet's distance is the exact capsule-box distance
                    assert got[a] == pytest.approx(want[a], abs=2e-3), (angles, a)
                    checked += 1
                elif want[a] < -0.01:
                    assert got[a] < 0.0, (angles, a)  # in penetration: negative
        assert checked > 40


def test_clearance_values_by_hand():
    """Links along known lines: the numbers can be read off the drawing."""
    topo = load_topology(CORRIDOR)
    with World(topo) as world:
        scene = Scene(world)
        c = scene.clearances()  # start: a1 straight up from (0, 0): 3 from the walls' left faces, minus 0.1
        assert c["a1"] == pytest.approx(2.9, abs=1e-4)
        # all along y = 2 (a1 at 90 deg to (0, 1), a2 at 0 deg ... no: a1 0 deg, the chain along y = 0)
        world.reset(dict.fromkeys(topo.dof_agents, 0.0))
        c = scene.clearances()
        assert c["a1"] == pytest.approx(1.9, abs=1e-4)  # x in [0, 1]: 2 from the face x = 3
        assert c["a2"] == pytest.approx(0.9, abs=1e-4)
        assert c["a3"] == pytest.approx(-0.1, abs=1e-4)  # its tip's cap is 0.1 into the lower wall
        assert c["a5"] < -1.0  # deep inside the lower wall


def _one_wall_topology(tmp_path: Path, gap: float = 0.05) -> Path:
    """Two links along +x from the origin; a wall whose bottom face lies `gap` above the capsules' surface."""
    bottom = RADIUS + gap
    p = tmp_path / "wall.toml"
    p.write_text(
        '[robot]\nname = "wall"\n[defaults]\nlink_length = 1.0\n'
        '[[agent]]\nid = "a1"\n[[agent]]\nid = "a2"\nparent = "a1"\n[task]\ngoal = [1.5, -0.5]\n'
        f"[[obstacle]]\ncenter = [1.0, {bottom + 1.0}]\nhalf_extents = [3.0, 1.0]\n"
    )
    return p


def test_penetrating_move_is_refused_and_reported(tmp_path):
    topo = load_topology(_one_wall_topology(tmp_path))
    up, down = math.radians(5.0), -math.radians(5.0)
    with World(topo) as world:
        scene = Scene(world)
        assert scene.clearances()["a2"] == pytest.approx(0.05, abs=1e-4)
        # a1 up would lift the tip 2 sin(5 deg) = 0.17 > 0.05 into the wall: refused; a2 down is free
        m = scene.move({"a1": up, "a2": down})
        assert m.refused == ("a1",)
        assert m.applied["a1"] == 0.0 and m.applied["a2"] == pytest.approx(down)
        q = world.joint_positions()
        assert q["a1"] == 0.0 and q["a2"] == pytest.approx(down)
        assert min(m.clearance.values()) >= -1e-6 and m.clearance == pytest.approx(scene.clearances())
        # both free: applied together, nothing refused
        m = scene.move({"a1": down, "a2": up})
        assert m.refused == () and m.applied == pytest.approx({"a1": down, "a2": up})
        # every joint into the wall: all refused, nothing moves
        world.reset({"a1": 0.0, "a2": 0.0})
        m = scene.move({"a1": up, "a2": up})
        assert set(m.refused) == {"a1", "a2"} and world.joint_positions() == {"a1": 0.0, "a2": 0.0}


def test_look_ahead_by_hand(tmp_path):
    """Scene.ahead (the shield's reading): the links a joint moves, after its move alone, read off the drawing;
    the world is left as it was."""
    topo = load_topology(_one_wall_topology(tmp_path))  # wall bottom at y = 0.15, capsules' surface 0.05 below
    step = math.radians(5.0)
    with World(topo) as world:
        scene = Scene(world)
        c = scene.clearances()
        # a1 up lifts the tip to 2 sin 5 deg = 0.174: 0.15 - 0.174 - 0.1 into the wall; down, the base stays 0.05 off
        lo, hi = scene.ahead("a1", step, c)
        assert lo == pytest.approx(0.05, abs=1e-4) and hi == pytest.approx(0.15 - 2 * math.sin(step) - 0.1, abs=1e-4)
        # a2 moves its own link only: its tip to (1 + cos 5, sin 5 deg)
        lo, hi = scene.ahead("a2", step, c)
        assert lo == pytest.approx(0.05, abs=1e-4) and hi == pytest.approx(0.15 - math.sin(step) - 0.1, abs=1e-4)
        assert world.joint_positions() == {"a1": 0.0, "a2": 0.0} and scene.clearances() == c
        # each equals the clearances after making the move for real
        for a, d in (("a1", -step), ("a2", step), ("a1", step)):
            want = scene.ahead(a, step, c)[d > 0]
            world.apply_increments({a: d})
            assert min(scene.clearances()[b] for b in scene.moved_by[a]) == pytest.approx(want, abs=1e-9)
            world.reset({"a1": 0.0, "a2": 0.0})
    (tmp_path / "far").mkdir()  # the wall 5 away: no move of 5 degrees comes within AHEAD_FAR, so no query
    with World(load_topology(_one_wall_topology(tmp_path / "far", gap=5.0))) as world:
        scene = Scene(world)
        c = scene.clearances()
        assert c["a1"] == pytest.approx(5.0, abs=1e-4) and scene.ahead("a1", step, c) == (c["a1"], c["a1"])


def test_start_inside_a_wall_is_an_error(tmp_path):
    p = tmp_path / "in.toml"
    p.write_text(
        '[robot]\nname = "in"\n[[agent]]\nid = "a1"\nlink_length = 1.0\n'
        "[[obstacle]]\ncenter = [0.5, 0.0]\nhalf_extents = [0.2, 0.2]\n"
    )
    topo = load_topology(p)
    with World(topo) as world:
        with pytest.raises(SceneError, match=rf"{p}: initial_deg: .*\['a1'\] inside an obstacle"):
            Scene(world).check_start(topo.source)


# -- wire ------------------------------------------------------------------------------------------
def test_scene_fields_round_trip():
    key, run = b"k" * 16, "r1"
    for m in (
        Obs(epoch=1, step=2, q=0.5, clearance=0.25, collided=1),
        Obs(epoch=1, step=2, q=0.5),
        Task(epoch=0, step=3, goal=(5.5, 2.0), tips={"a7": (1.0, 2.0, 0.0)}, clearance=-0.0, collisions=2),
        EpochDone(
            epoch=0,
            steps=2,
            final_error=1.0,
            mean_error=1.0,
            errors=[1.0, 1.0],
            final_angles={"a1": 0.1},
            missed_cmds=0,
            seconds=0.1,
            max_step_seconds=0.01,
            collisions=[0, 3],
            clearance=[0.2, 0.0],
        ),
    ):
        assert codec.decode(codec.encode(m, run, "sim", key), type(m), run, key) == m


# -- rewards ---------------------------------------------------------------------------------------
def test_eq11_as_printed():
    r = corridor_reward
    assert r(4.0, 4.5, 1.0, 0, "paper") == -2.0  # outside D_min
    assert r(4.0, 4.5, 0.0, 3, "paper") == -2.0  # outside D_min a collision costs nothing extra
    assert r(2.0, 1.9, 1.0, 0, "paper") == -1.0  # inside, moving away
    assert r(2.0, 1.9, 0.0, 1, "paper") == -1.0  # ... with a collision: still -1 (the case order)
    assert r(2.0, 2.1, 1.0, 0, "paper") == pytest.approx(math.exp(-0.5 * 2.0))  # inside, approaching, clear
    assert r(2.0, 2.1, 0.05, 0, "paper") == pytest.approx(-math.exp(-0.5 * 0.05))  # close to collide
    assert r(2.0, 2.1, 0.3, 1, "paper") == pytest.approx(-math.exp(-0.5 * 0.3))  # a refused move
    assert r(2.0, 2.0, 1.0, 0, "paper") == pytest.approx(math.exp(-1.0))  # Delta D = 0 counts as approaching
    assert -1.0 <= r(2.0, 2.1, 0.0, 5, "paper") < 0  # the point: never below -1


def test_corridor_variants():
    r = corridor_reward
    # strict: the collision case first, replacing the rest, at most -5 e^(-c2 d_safe): below every other case
    assert r(4.0, 4.5, 0.0, 1, "strict") == pytest.approx(-5.0)
    assert r(1.0, 1.2, 0.05, 0, "strict") == pytest.approx(-5.0 * math.exp(-0.025))
    assert r(4.0, 4.5, 0.5, 0, "strict") == -2.0
    for mode in ("strict", "shaped"):
        assert r(2.0, 2.1, 0.5, 0, mode) == pytest.approx(math.exp(-1.0))  # clear: Eq. 10 inside
        assert r(2.0, 2.0, 0.5, 0, mode) == 0.0  # still: 0
    # shaped: Eq. 10 shaped, the collision term added
    assert r(4.0, 4.1, 0.5, 0, "shaped") == pytest.approx(-2.0 + 20 * 0.1)
    assert r(4.0, 4.1, 0.0, 1, "shaped") == pytest.approx(-2.0 + 20 * 0.1 - 5.0)
    assert r(1.0, 1.2, 0.05, 0, "shaped") == pytest.approx(math.exp(-0.5) - 5.0 * math.exp(-0.025))
    # settle: a refused move costs as in shaped, a link merely near a wall nothing; an arrived tip is paid
    assert r(1.0, 1.2, 0.05, 0, "settle") == pytest.approx(math.exp(-0.5))
    assert r(1.0, 1.2, 0.05, 1, "settle") == pytest.approx(r(1.0, 1.2, 0.05, 1, "shaped"))
    assert r(0.2, 0.2, 0.05, 0, "settle") == pytest.approx(math.exp(-0.1))  # shaped: 0 - 5 e^(-0.025)
    assert r(0.2, 0.1, 0.0, 1, "settle") == pytest.approx(math.exp(-0.1) - 5.0)
    # a narrower settle radius (LearnerSettings.settle_radius): 0.2 from the goal is not arrived yet, so keeping
    # still there pays what it pays in shaped (0), a step in e^(-c1 D) and a step out -1; 0.1 still is arrived
    assert r(0.2, 0.2, 0.05, 0, "settle", settle_radius=0.15) == 0.0
    assert r(0.2, 0.25, 0.05, 0, "settle", settle_radius=0.15) == pytest.approx(math.exp(-0.1))
    assert r(0.2, 0.15, 0.05, 0, "settle", settle_radius=0.15) == -1.0
    assert r(0.1, 0.05, 0.05, 0, "settle", settle_radius=0.15) == pytest.approx(math.exp(-0.05))
    assert r(0.2, 0.15, 0.05, 0, "shaped", settle_radius=0.15) == r(0.2, 0.15, 0.05, 0, "shaped")  # settle's only
    with pytest.raises(ValueError, match="unknown reward mode"):
        r(1.0, 1.0, 1.0, 0, "geodesic?")


def test_path_distance_through_via():
    goal, via = (5.5, 2.0), (2.0, 2.0)
    assert path_distance((4.0, 2.1), goal, via, 0.3) == pytest.approx(math.hypot(1.5, 0.1))  # past via: straight
    assert path_distance((2.0, 2.3), goal, via, 0.3) == pytest.approx(math.hypot(3.5, 0.3))  # on the edge: past
    assert path_distance((2.0, 2.31), goal, via, 0.3) == pytest.approx(0.31 + 3.5)  # just outside the band
    assert path_distance((1.0, 2.0), goal, via, 0.3) == pytest.approx(1.0 + 3.5)  # before via, on the axis
    # on top of the upper wall, 0.8 from the goal in a straight line, but far along the path
    assert path_distance((5.5, 2.8), goal, via, 0.3) == pytest.approx(math.hypot(3.5, 0.8) + 3.5)


def test_via_parsing(tmp_path):
    doc = _doc([])
    doc["task"] = {"goal": [5.5, 2.0], "via": [2.0, 2.0], "via_width": 0.3}
    topo = parse_topology(doc, source="v.toml")
    assert topo.via == (2.0, 2.0) and topo.via_width == 0.3
    doc["task"] = {"goal": [5.5, 2.0], "via": [2.0, 2.0]}
    with pytest.raises(TopologyError, match=r"v.toml: task.via_width: must be > 0 with task.via"):
        parse_topology(doc, source="v.toml")
    doc["task"] = {"goal": [5.5, 2.0], "via_width": 0.3}
    with pytest.raises(TopologyError, match=r"v.toml: task.via_width: only with task.via"):
        parse_topology(doc, source="v.toml")
    assert load_topology(CORRIDOR).via is None or load_topology(CORRIDOR).via_width > 0


def test_waypoints_advance_and_distance():
    goal, wps = (5.5, 2.0), ((2.0, 2.0), (3.5, 2.0))
    # far from the first: aim at it, D = |tip - w0| + 1.5 + 2.0
    k, target, D = next_waypoint((2.0, 5.0), goal, wps, 0, 0.2)
    assert (k, target) == (0, (2.0, 2.0)) and D == pytest.approx(3.0 + 3.5)
    # within the radius of w0: the next one, D continues to fall smoothly (no jump up)
    k, target, D2 = next_waypoint((2.1, 2.1), goal, wps, 0, 0.2)
    assert (k, target) == (1, (3.5, 2.0)) and D2 == pytest.approx(math.hypot(1.4, 0.1) + 2.0)
    assert D2 < math.hypot(0.1, 0.1) + 3.5
    # k never goes back within an epoch: leaving w0 again keeps aiming at w1
    assert next_waypoint((0.0, 0.0), goal, wps, 1, 0.2)[:2] == (1, (3.5, 2.0))
    # both passed in one step, then the goal itself
    assert next_waypoint((3.45, 2.0), goal, ((3.4, 2.0), (3.5, 2.0)), 0, 0.2)[:2] == (2, goal)
    assert next_waypoint((5.0, 2.0), goal, wps, 2, 0.2) == (2, goal, pytest.approx(0.5))
    doc = _doc([])
    doc["task"] = {"goal": [5.5, 2.0], "waypoints": [[2.0, 2.0], [3.5, 2.0]], "waypoint_radius": 0.2}
    assert parse_topology(doc, source="w.toml").waypoints == wps
    doc["task"] = {"goal": [5.5, 2.0], "waypoints": [[2.0, 2.0], [3.5]], "waypoint_radius": 0.2}
    with pytest.raises(TopologyError, match=r"w.toml: task.waypoints\[1\]: expected a list of 2"):
        parse_topology(doc, source="w.toml")
    doc["task"] = {"goal": [5.5, 2.0], "waypoints": [[2.0, 2.0]]}
    with pytest.raises(TopologyError, match=r"w.toml: task.waypoint_radius: must be > 0"):
        parse_topology(doc, source="w.toml")


# -- learner settings ---------------------------------------------------------------------------------
def test_scene_state_settings():
    st = LearnerSettings(clearance_state=True, collision_state=True, clearance_sets=4)
    assert st.state_names[-2:] == ("clearance", "collided") and st.state_sets[-2:] == (4, 2)
    assert st.state_ranges[-2:] == ((0.0, 1.0), (0.0, 1.0))
    fp = FuzzyPartition(st)
    state = np.array([0.1, 0.2, 3.0, 1.0, -1.0, 0.3, 0.4, 1.0])
    rules, O = fp.activate(state)  # noqa: E741 -- Eq. 4
    ref_rules, ref_O = fp.activate_reference(state)
    assert len(rules) == 2**8 and (O > 0).all() and fp.n_rules == 1_783_600 * 4 * 2
    order, ref_order = np.argsort(rules), np.argsort(ref_rules)
    assert (rules[order] == ref_rules[ref_order]).all()
    np.testing.assert_allclose(O[order], ref_O[ref_order], rtol=1e-12)
    # the flag is felt: refused (1.0) and not (0.0) fire the same rules with different weights
    r0, o0 = fp.activate(np.concatenate((state[:-1], [0.0])))
    w1, w0 = dict(zip(rules.tolist(), O.tolist(), strict=True)), dict(zip(r0.tolist(), o0.tolist(), strict=True))
    assert w1.keys() == w0.keys() and max(abs(w1[k] - w0[k]) for k in w1) > 0.01
    assert len(LearnerSettings().state_sets) == 6
    with pytest.raises(ValueError, match="collision_penalty must be <= 0"):
        LearnerSettings(collision_penalty=1.0)
    with pytest.raises(ValueError, match="clearance_state must be true or false"):
        LearnerSettings(clearance_state=1)  # type: ignore[arg-type]
    cfg = RunConfig(run_id="r", topology=str(EXAMPLES / "chain4.toml"), out="/tmp/x", learner={"clearance_state": True})
    with pytest.raises(ValueError, match="need a scene with obstacles.*chain4.toml"):
        learner_settings(cfg, cfg.topo())
    with pytest.raises(ValueError, match="shield must be a distance >= 0"):
        LearnerSettings(shield=-0.1)
    for bad in (0.0, -0.3, float("nan"), "0.15"):
        with pytest.raises(ValueError, match="settle_radius must be a distance > 0"):
            LearnerSettings(settle_radius=bad)  # type: ignore[arg-type]
    cfg = RunConfig(run_id="r", topology=str(EXAMPLES / "chain4.toml"), out="/tmp/x", learner={"shield": 0.1})
    with pytest.raises(ValueError, match="shield need a scene with obstacles.*chain4.toml"):
        learner_settings(cfg, cfg.topo())


def test_collision_tabu_never_repeats_the_refused_action():
    """The greedy deadlock: the same state, the same greedy choice. With `avoid` the refused action is neither
    chosen greedily nor sampled while exploring, whatever Q says."""
    st = LearnerSettings(T_max=10.0, s=0.0)  # exploration stays high: sampling is exercised too
    learner = Learner(st, 0, seed=1)
    s0 = np.array([0.1, 0.2, 3.0, 1.0, -1.0, 0.3])
    for _ in range(30):  # teach it that action 2 is by far the best here
        learner.decide(s0, 5.0 if learner._own == 2 else -5.0)
        learner.observe([])
    learner.start_epoch(1)
    picks = {learner.decide(s0, None, learn=False, explore=False) for _ in range(20)}
    assert picks == {2}  # deadlock material: greedy always 2
    picks = set()
    for explore in (False, True):
        for _ in range(200):
            picks.add(learner.decide(s0, None, learn=False, explore=explore, avoid=[2]))
    assert 2 not in picks and picks <= {0, 1}
    # both moves refused: only "keep" is left; all three is no information and leaves the choice alone
    assert {learner.decide(s0, None, learn=False, explore=True, avoid=[0, 2]) for _ in range(100)} == {1}
    assert learner.decide(s0, None, learn=False, explore=False, avoid=[0, 1, 2]) == 2


def test_tabu_memory_holds_until_the_tip_moves(tmp_path):
    """tabu_memory: each refused action stays left out until the tip of the agent's chain has moved
    tabu_memory from where it was at that refusal; with 0 only the action refused at the step before."""

    class Quiet:  # what an Agent needs of its Node to be built
        keys = Keys("r")

    def agent(memory: float) -> Agent:
        over = {"collision_tabu": True, "tabu_memory": memory}
        cfg = RunConfig(run_id="r", topology=str(CORRIDOR), out=str(tmp_path), learner=over)
        return Agent(cfg, cfg.topo(), "a1", Quiet())  # type: ignore[arg-type]

    def step(a: Agent, n: int, action: int, refused: bool, tip: tuple[float, float]) -> list[int]:
        """Step n: my move of step n - 1 was `action`, refused or not; the tip is at `tip`."""
        a.decided = ((0, n - 1), action)
        cur = _Step((0, n), (0, 0, 0), (0, 0, 0), 0.0, (5.5, 2.0), None, frozenset(), {}, sense=(0.5, int(refused)))
        return sorted(a._tabu(cur, tip))

    one = agent(0.0)
    assert step(one, 1, 2, True, (3.0, 2.0)) == [2]
    assert step(one, 2, 0, True, (3.0, 2.0)) == [0]  # "increase" is free to be tried again: the alternation
    assert step(one, 3, 1, False, (3.0, 2.0)) == []
    mem = agent(0.1)
    assert step(mem, 1, 2, True, (3.0, 2.0)) == [2]
    assert step(mem, 2, 0, True, (3.0, 2.0)) == [0, 2]  # a jam: both ways refused, only "keep" is left
    assert step(mem, 3, 1, False, (3.05, 2.0)) == [0, 2]  # the tip moved less than 0.1: still jammed
    assert step(mem, 4, 1, False, (3.0, 2.09)) == [0, 2]  # a wiggle does not add up
    assert step(mem, 5, 1, False, (3.0, 2.1)) == []  # moved 0.1 from both refusals: try again
    assert step(mem, 6, 2, True, (3.0, 2.1)) == [2]
    with pytest.raises(ValueError, match="tabu_memory must be >= 0"):
        LearnerSettings(collision_tabu=True, tabu_memory=-1.0)
    with pytest.raises(ValueError, match="tabu_memory needs collision_tabu"):
        LearnerSettings(tabu_memory=0.1)


def test_subtree_clearance_is_the_smallest_below(tmp_path):
    """clearance_of "subtree": the state holds the smallest of my link's clearance and my children's `Up`
    clearances (each their own subtree's); "link" keeps my own link's."""

    class Quiet:  # what an Agent needs of its Node to be built
        keys = Keys("r")

    def state(of: str, own: float, below: dict[str, float | None]) -> float:
        over = {"clearance_state": True, "clearance_of": of}
        cfg = RunConfig(run_id="r", topology=str(CORRIDOR), out=str(tmp_path), learner=over)
        a = Agent(cfg, cfg.topo(), "a6", Quiet())  # type: ignore[arg-type]
        ups = {c: Up(epoch=0, step=3, tips={"a7": (5.0, 2.0, 0.0)}, action=1, clearance=v) for c, v in below.items()}
        cur = _Step((0, 3), (0, 0, 0), (0, 0, 0), 0.0, (5.5, 2.0), None, frozenset(below), {}, ups, (own, 0))
        s, _ = a._scene_state(np.zeros(6), None, cur.sense, _subtree_clearance(cur))
        return float(s[-1])

    assert state("subtree", 0.8, {"a7": 0.05}) == 0.05  # my chain is against a wall, my own link is not
    assert state("subtree", 0.02, {"a7": 0.4}) == 0.02
    assert state("subtree", 0.8, {"a7": None}) == 0.8  # a child that knows none
    assert state("link", 0.8, {"a7": 0.05}) == 0.8
    with pytest.raises(ValueError, match="clearance_of must be one of"):
        LearnerSettings(clearance_state=True, clearance_of="chain")
    with pytest.raises(ValueError, match="clearance_of needs clearance_state"):
        LearnerSettings(clearance_of="subtree")


@pytest.mark.timeout(120)
def test_up_carries_each_subtrees_smallest_clearance(tmp_path):
    """On the wire, a real run: every child's `Up` at a step carries the smallest of the sim's clearances at that
    step (`Obs`) over the child's own link and all links below it."""
    learner = settings(clearance_state=True, clearance_of="subtree", collision_state=True, collision_tabu=True)
    spec = Spec("up", seed=3, epochs=1, steps=40, reward="settle", learner=learner, topology=str(GUIDED))
    cfg = spec.config(tmp_path)
    topo = cfg.topo()
    keys = Keys(cfg.run_id)
    _, captured = asyncio.run(_supervise(cfg, topo, None, False, record=(keys.obs("*"), keys.up("*"))))
    obs: dict[tuple[int, str], float] = {}
    ups: list[tuple[str, Up]] = []
    for key, payload in captured:
        if key.startswith(keys.obs("")):
            m = codec.decode(payload, Obs, cfg.run_id, cfg.key)
            obs[(m.step, key[len(keys.obs("")) :])] = m.clearance
        else:
            parent = key[len(keys.root) + 3 : -3]  # <root>/a/<parent>/up
            ups.append((parent, codec.decode(payload, Up, cfg.run_id, cfg.key)))
    checked = 0
    for parent, m in ups:
        if m.step == cfg.steps:
            continue  # the closing `up`: an action only
        (child,) = [c for c in topo.agents[parent].children if set(topo.subtree_leaves(c)) == set(m.tips)]
        below, stack = [], [child]
        while stack:
            below.append(stack.pop())
            stack.extend(topo.agents[below[-1]].children)
        assert m.clearance == min(obs[(m.step, a)] for a in below), (parent, m.step)
        checked += 1
    assert checked == 6 * cfg.steps  # a2..a7, every step
    assert min(obs.values()) < 0.5 < max(obs.values())  # near and far links both seen


@pytest.mark.timeout(120)
def test_shield_never_moves_where_the_look_ahead_forbids(tmp_path):
    """On the wire, a real run with a wide shield: every agent's obs carries the look-ahead, and no agent ever
    commands a move whose look-ahead (in that step's obs) is nearer a wall than the shield; some moves are left
    out (the check can fail)."""
    shield = 0.5
    learner = settings(clearance_state=True, collision_state=True, collision_tabu=True, shield=shield)
    spec = Spec("shield", seed=3, epochs=1, steps=60, reward="settle", learner=learner, topology=str(GUIDED))
    cfg = spec.config(tmp_path)
    topo = cfg.topo()
    keys = Keys(cfg.run_id)
    _, captured = asyncio.run(_supervise(cfg, topo, None, False, record=(keys.obs("*"), keys.cmd("*"))))
    ahead: dict[tuple[int, str], tuple[float, float]] = {}
    cmds: dict[tuple[int, str], float] = {}
    for key, payload in captured:
        if key.startswith(keys.obs("")):
            m = codec.decode(payload, Obs, cfg.run_id, cfg.key)
            ahead[(m.step, key[len(keys.obs("")) :])] = (m.sense["ahead-"], m.sense["ahead+"])
        else:
            c = codec.decode(payload, Cmd, cfg.run_id, cfg.key)
            cmds[(c.step, key[len(keys.cmd("")) :])] = c.delta
    assert len(ahead) == len(cmds) == 7 * cfg.steps
    blocked = 0
    for k, delta in cmds.items():
        lo, hi = ahead[k]
        assert not (delta < 0 and lo < shield) and not (delta > 0 and hi < shield), (k, delta, lo, hi)
        blocked += (lo < shield) + (hi < shield)
    assert blocked > 20


# -- a run through the corridor ---------------------------------------------------------------------
@pytest.mark.timeout(120)
def test_corridor_run_walls_are_solid(tmp_path, endpoint):
    out = tmp_path / "run"
    args = ["run", str(CORRIDOR), "--placement", "single", "--epochs", "2", "--steps", "250", "--seed", "1"]
    args += ["--listen", endpoint, "--out", str(out), "--no-progress", "--reward", "shaped"]
    args += ["--learner", "clearance_state=true", "--learner", "collision_state=true"]
    args += ["--learner", "collision_penalty=-5"]
    assert cli_main(args) == 0
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert len(rows) == 2
    for r in rows:
        assert len(r["collisions"]) == len(r["clearance"]) == 250
        assert min(r["clearance"]) >= -1e-5  # never inside a wall
    assert sum(sum(r["collisions"]) for r in rows) > 0  # exploring from scratch, it bumps into the walls
    for f in ("corridor.png", "learning_curve.png", "arm.png", "summary.json"):
        assert (out / f).is_file(), f


# -- the experiment ----------------------------------------------------------------------------------
@pytest.mark.timeout(180)
def test_quick_corridor_experiment(tmp_path):
    out = tmp_path / "x"
    assert cli_main(["experiment", "corridor", "--quick", "--seeds", "1", "--out", str(out)]) == 0
    d = out / "corridor"
    report = (d / "report.md").read_text()
    assert "kinswarm experiment corridor" in report and "seeds:" in report and "single" in report
    assert "| " in report and "paper" in report.lower() and "quick" in report
    for fig in ("corridor.png", "frozen.png", "learning.png"):
        assert (d / fig).stat().st_size > 1000, fig
        assert f"]({fig})" in report
    res = json.loads((d / "results.json").read_text())
    assert res["experiment"] == "corridor" and res["quick"] is True and res["steps"] == 100
    assert res["configs"]["follow"]["learner"]["follow_leader"] == 40.0
    for label in ("paper", "kinswarm", "follow"):
        per = res["configs"][label]
        seed = per["seeds"]["0"]
        assert 0.0 <= seed["success_last"] <= 1.0 and seed["frozen_collisions"] >= 0
        assert 0.0 <= seed["strict_last"] <= seed["success_last"]  # no collision at all: within the last 100 too
        assert seed["frozen_min_clearance"] >= -1e-5  # solid walls in the frozen run too
        assert isinstance(seed["frozen_success"], bool) and isinstance(seed["tabu_success"], bool)
        assert isinstance(seed["shield_success"], bool) and seed["shield_collisions"] >= 0
        assert per["bar_training_met"] is False and per["bar_frozen_met"] is False  # one seed never meets a bar
    # a continued configuration trains on from its base configuration's trained swarm (`--from`), annealed
    for label, count_freeze in (("anneal-260", None), ("freeze-260", 200)):
        cont = res["configs"][label]
        assert cont["learner"]["lr_anneal"] == [200, 240] and cont["learner"].get("count_freeze") == count_freeze
        cfg = json.loads((out / "runs" / cont["seeds"]["0"]["train_run"] / "config.json").read_text())
        assert Path(cfg["from_dir"]).name == res["configs"]["inner-200"]["seeds"]["0"]["train_run"]
