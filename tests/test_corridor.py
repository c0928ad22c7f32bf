"""The corridor (paper §5.4): the walls scene (parsing, PyBullet clearance against geometry, solid walls, the
look-ahead), the readings on the wire, Eq. 11 and its variants, the corridor task's state, local reward and
reflexes, and a swarm run through the corridor."""

from __future__ import annotations

import asyncio
import json
import math
import tomllib
from pathlib import Path

import numpy as np
import pytest
from conftest import EXAMPLES, run_config
from kinswarm.actors.cli.commands import main as cli_main
from kinswarm.actors.files.runfile import task_of
from kinswarm.actors.learning.fuzzy import FuzzyPartition
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.actors.tasks.base import StepView
from kinswarm.actors.tasks.corridor import CorridorAgent, corridor_reward
from kinswarm.actors.tasks.reach import next_waypoint, path_distance
from kinswarm.experiments.swarm import Spec, _supervise
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Cmd, EpochDone, Obs, Task, Up
from kinswarm.protocol.robots import load_robot, parse_robot
from kinswarm.protocol.scene import parse_scene
from kinswarm.protocol.spec import SpecError
from kinswarm.sim.kinematics import frames
from kinswarm.sim.scenes.walls import SceneError, Walls
from kinswarm.sim.world import World

CORRIDOR = EXAMPLES / "corridor7.toml"
GUIDED = EXAMPLES / "corridor7-guided.toml"
RADIUS = 0.1  # the capsule radius of sim/urdf.py
TWO_LINKS = parse_robot(
    {"name": "t", "defaults": {"link_length": 1.0}, "agent": [{"id": "a1"}, {"id": "a2", "parent": "a1"}]}
)


def _walls(obstacles: list[dict]) -> dict:
    return {"kind": "walls", "obstacle": obstacles}


def _obstacles(path: Path):
    return run_config(path).scene_spec.obstacles


# -- parsing ---------------------------------------------------------------------------------------
def test_examples_parse():
    cfg = run_config(CORRIDOR)
    topo, obstacles = cfg.topo(), cfg.scene_spec.obstacles
    assert [o.id for o in obstacles] == ["upper", "lower"]
    upper, lower = obstacles
    assert upper.center == (4.5, 4.4) and upper.half_extents == (1.5, 2.0) and upper.angle == 0.0
    gap = (upper.center[1] - upper.half_extents[1]) - (lower.center[1] + lower.half_extents[1])
    assert gap == pytest.approx(0.8)
    assert cfg.task["goal"] == [5.5, 2.0] and len(topo.dof_agents) == 7 and topo.reach == pytest.approx(7.0)
    relaxed = _obstacles(EXAMPLES / "corridor7-relaxed.toml")
    assert (relaxed[0].center[1] - relaxed[0].half_extents[1]) - (
        relaxed[1].center[1] + relaxed[1].half_extents[1]
    ) == pytest.approx(1.2)
    # the relaxed recipe: the relaxed walls, the target 1.0 deep and the swing margin; its second stage trains on
    cfg = run_config(EXAMPLES / "corridor7-relaxed-swing200.toml")
    assert cfg.scene_spec.obstacles == relaxed and cfg.task["goal"] == [4.0, 2.0] and cfg.task["swing_margin"] == 0.25
    stage2 = tomllib.loads((EXAMPLES / "corridor7-relaxed-swing260.toml").read_text())
    assert stage2["base"] == "corridor7-relaxed-swing200.toml" and stage2["task"]["blame_penalty"] < 0.0
    assert run_config(EXAMPLES / "chain4.toml").scene_spec.obstacles == ()


@pytest.mark.parametrize(
    ("obstacle", "field", "what"),
    [
        ({"half_extents": [1, 1]}, "scene.obstacle[0].center", "missing"),
        ({"center": [1, 1]}, "scene.obstacle[0].half_extents", "missing"),
        ({"center": [1, 1], "half_extents": [1, 0]}, "scene.obstacle[0].half_extents", "> 0"),
        ({"center": [1, "x"], "half_extents": [1, 1]}, "scene.obstacle[0].center[1]", "finite number"),
        ({"center": [1], "half_extents": [1, 1]}, "scene.obstacle[0].center", "list of 2"),
        ({"center": [1, 1], "half_extents": [1, 1], "size": 3}, "scene.obstacle[0].size", "unknown field"),
        ({"center": [1, 1], "half_extents": [1, 1], "angle_deg": True}, "scene.obstacle[0].angle_deg", "finite"),
        ({"center": [1, 1], "half_extents": [1, 1], "id": "a b"}, "scene.obstacle[0].id", "letters"),
    ],
)
def test_obstacle_errors_name_file_and_field(obstacle, field, what):
    with pytest.raises(SpecError) as e:
        parse_scene(_walls([obstacle]), TWO_LINKS, "scene.toml")
    assert e.value.source == "scene.toml" and e.value.where == field and what in e.value.what
    assert str(e.value).startswith(f"scene.toml: {field}: ")


def test_scene_table_errors():
    box = {"center": [1, 1], "half_extents": [1, 1], "id": "w"}
    with pytest.raises(SpecError, match="duplicate obstacle id 'w'"):
        parse_scene(_walls([box, box]), TWO_LINKS, "s.toml")
    with pytest.raises(SpecError, match=r"s.toml: scene.obstacle: expected \[\[scene.obstacle\]\]"):
        parse_scene({"kind": "walls", "obstacle": {"center": [1, 1]}}, TWO_LINKS, "s.toml")
    with pytest.raises(SpecError, match="s.toml: scene.obstacle: a walls scene needs at least one"):
        parse_scene({"kind": "walls"}, TWO_LINKS, "s.toml")
    with pytest.raises(SpecError, match="s.toml: scene.shield: must be a distance >= 0"):
        parse_scene({**_walls([box]), "shield": -0.1}, TWO_LINKS, "s.toml")
    with pytest.raises(SpecError, match=r"s.toml: scene.shield: unknown field \(expected kind\)"):
        parse_scene({"kind": "free", "shield": 0.1}, TWO_LINKS, "s.toml")
    with pytest.raises(SpecError, match="s.toml: scene.kind: expected one of free, walls, object"):
        parse_scene({"kind": "moat"}, TWO_LINKS, "s.toml")


def test_bad_file_names_the_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(CORRIDOR.read_text().replace("half_extents = [1.5, 2.0]", "half_extents = [1.5, -2.0]", 1))
    with pytest.raises(SpecError, match=rf"{p}: scene.obstacle\[0\].half_extents: both must be > 0"):
        run_config(p)


def test_tasks_and_scenes_must_fit(tmp_path):
    """The corridor task runs among walls, reaching in free space: a mismatch is one line, before anything runs."""
    with pytest.raises(SpecError, match=r"scene.kind: the corridor task runs in a walls scene, not 'free'"):
        run_config(EXAMPLES / "chain4.toml", ['task.kind="corridor"'])
    with pytest.raises(SpecError, match=r"scene.kind: the reach task runs in a free scene, not 'walls'"):
        run_config(CORRIDOR, ['task.kind="reach"'])
    with pytest.raises(SpecError, match="task.follow_leader: needs via"):
        run_config(CORRIDOR, ["task.follow_leader=1.0"])


# -- geometry ----------------------------------------------------------------------------------------
def _exact_clearance(topo, obstacles, angles: dict[str, float]) -> dict[str, float]:
    """Closed form: min over the link's axis (sampled finely, then refined) of the box's signed distance,
    minus the capsule radius; exact where the capsule is outside every box."""
    f = frames(topo, angles)
    out = {}
    for a in topo.dof_agents:
        x, y, h = f[a]
        length = topo.agents[a].link_length
        ts = np.linspace(0.0, length, 4001)
        best = min(o.signed_distance(x + t * math.cos(h), y + t * math.sin(h)) for o in obstacles for t in ts)
        out[a] = best - RADIUS
    return out


def test_clearance_matches_geometry():
    cfg = run_config(CORRIDOR)
    topo, obstacles = cfg.topo(), cfg.scene_spec.obstacles
    rng = np.random.default_rng(0)
    with World(topo) as world:
        scene = Walls(world, obstacles)
        checked = 0
        configs = [topo.initial_angles()]
        offset = np.array([0.7, 0, 0, 0, 0, 0, 0])  # a1 towards the walls, the others curling at random
        configs += [
            dict(zip(topo.dof_agents, (rng.uniform(-0.5, 0.5, 7) + offset).tolist(), strict=True)) for _ in range(12)
        ]
        for angles in configs:
            world.reset(angles)
            got = scene.clearances()
            want = _exact_clearance(topo, obstacles, angles)
            for a in topo.dof_agents:
                if want[a] > 0.01:  # apart: PyBullet's distance is the exact capsule-box distance
                    assert got[a] == pytest.approx(want[a], abs=2e-3), (angles, a)
                    checked += 1
                elif want[a] < -0.01:
                    assert got[a] < 0.0, (angles, a)  # in penetration: negative
        assert checked > 40


def test_clearance_values_by_hand():
    """Links along known lines: the numbers can be read off the drawing."""
    cfg = run_config(CORRIDOR)
    with World(cfg.topo()) as world:
        scene = Walls(world, cfg.scene_spec.obstacles)
        c = scene.clearances()  # start: a1 straight up from (0, 0): 3 from the walls' left faces, minus 0.1
        assert c["a1"] == pytest.approx(2.9, abs=1e-4)
        # all along y = 2 (a1 at 90 deg to (0, 1), a2 at 0 deg ... no: a1 0 deg, the chain along y = 0)
        world.reset(dict.fromkeys(cfg.topo().dof_agents, 0.0))
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
        '[robot]\nname = "wall"\n[robot.defaults]\nlink_length = 1.0\n'
        '[[robot.agent]]\nid = "a1"\n[[robot.agent]]\nid = "a2"\nparent = "a1"\n'
        '[task]\nkind = "corridor"\ngoal = [1.5, -0.5]\n[scene]\nkind = "walls"\n'
        f"[[scene.obstacle]]\ncenter = [1.0, {bottom + 1.0}]\nhalf_extents = [3.0, 1.0]\n"
    )
    return p


def _wall(world: World, path: Path) -> Walls:
    return Walls(world, _obstacles(path))


def test_penetrating_move_is_refused_and_reported(tmp_path):
    path = _one_wall_topology(tmp_path)
    up, down = math.radians(5.0), -math.radians(5.0)
    with World(load_robot(path)) as world:
        scene = _wall(world, path)
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
    """Walls.ahead (the shield's look-ahead): the links a joint moves, after its move alone, read off the drawing;
    the world is left as it was."""
    path = _one_wall_topology(tmp_path)  # wall bottom at y = 0.15, capsules' surface 0.05 below
    step = math.radians(5.0)
    with World(load_robot(path)) as world:
        scene = _wall(world, path)
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
    far = _one_wall_topology(tmp_path / "far", gap=5.0)
    with World(load_robot(far)) as world:
        scene = _wall(world, far)
        c = scene.clearances()
        assert c["a1"] == pytest.approx(5.0, abs=1e-4) and scene.ahead("a1", step, c) == (c["a1"], c["a1"])


def test_start_inside_a_wall_is_an_error(tmp_path):
    p = tmp_path / "in.toml"
    p.write_text(
        '[robot]\nname = "in"\n[[robot.agent]]\nid = "a1"\nlink_length = 1.0\n'
        '[scene]\nkind = "walls"\n[[scene.obstacle]]\ncenter = [0.5, 0.0]\nhalf_extents = [0.2, 0.2]\n'
    )
    topo = load_robot(p)
    with World(topo) as world:
        with pytest.raises(SceneError, match=rf"{p}: initial_deg: .*\['a1'\] inside an obstacle"):
            Walls(world, _obstacles_of(p, topo)).check_start(topo.source)


def _obstacles_of(p: Path, topo):
    import tomllib

    return parse_scene(tomllib.loads(p.read_text())["scene"], topo, str(p)).obstacles


# -- wire ------------------------------------------------------------------------------------------
def test_scene_fields_round_trip():
    key, run = b"k" * 16, "r1"
    for m in (
        Obs(epoch=1, step=2, q=0.5, sense={"clearance": 0.25, "collided": 1.0, "shield-": 1.0, "shield+": 0.0}),
        Obs(epoch=1, step=2, q=0.5),
        Task(
            epoch=0, step=3, goal=(5.5, 2.0), tips={"a7": (1.0, 2.0, 0.0)}, sense={"clearance": -0.0, "collisions": 2.0}
        ),
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
            traces={"collisions": [0.0, 3.0], "clearance": [0.2, 0.0]},
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
    # a narrower settle radius (the task's settle_radius): 0.2 from the goal is not arrived yet, so keeping
    # still there pays what it pays in shaped (0), a step in e^(-c1 D) and a step out -1; 0.1 still is arrived
    assert r(0.2, 0.2, 0.05, 0, "settle", settle_radius=0.15) == 0.0
    assert r(0.2, 0.25, 0.05, 0, "settle", settle_radius=0.15) == pytest.approx(math.exp(-0.1))
    assert r(0.2, 0.15, 0.05, 0, "settle", settle_radius=0.15) == -1.0
    assert r(0.1, 0.05, 0.05, 0, "settle", settle_radius=0.15) == pytest.approx(math.exp(-0.05))
    assert r(0.2, 0.15, 0.05, 0, "shaped", settle_radius=0.15) == r(0.2, 0.15, 0.05, 0, "shaped")  # settle's only
    # swing_margin: outside D_min a link within the margin costs as a refusal does; inside D_min nothing changes
    assert r(4.0, 4.1, 0.05, 0, "settle", swing_margin=0.1) == pytest.approx(r(4.0, 4.1, 0.05, 1, "settle"))
    assert r(4.0, 4.1, 0.05, 0, "settle", swing_margin=0.1) == pytest.approx(-2.0 + 2.0 - 5.0 * math.exp(-0.025))
    assert r(4.0, 4.1, 0.15, 0, "settle", swing_margin=0.1) == pytest.approx(-2.0 + 2.0)  # beyond the margin
    assert r(1.0, 1.2, 0.05, 0, "settle", swing_margin=0.1) == r(1.0, 1.2, 0.05, 0, "settle")  # inside D_min
    assert r(4.0, 4.1, 0.05, 0, "paper", swing_margin=0.1) == -2.0  # Eq. 11's case order: -2 outside D_min
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


def test_via_settings():
    cfg = run_config(GUIDED)
    assert cfg.task["via"] == [2.0, 2.0] and cfg.task["via_width"] == 0.3
    with pytest.raises(SpecError, match=r"^--set task.via_width=0: task.via_width: must be > 0 with via"):
        run_config(GUIDED, ["task.via_width=0"])
    with pytest.raises(SpecError, match=r"^--set task.via_width=0.3: task.via_width: only with via"):
        run_config(CORRIDOR, ["task.via_width=0.3"])


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
    wp = ["task.waypoints=[[2.0, 2.0], [3.5, 2.0]]", "task.waypoint_radius=0.2"]
    assert task_of(run_config(CORRIDOR, wp)).settings.waypoints == wps
    with pytest.raises(
        SpecError,
        match=r"^--set task.waypoints=\[\[2.0, 2.0\], \[3.5\]\]: task.waypoints\[1\]: expected a list of 2 values",
    ):
        run_config(CORRIDOR, ["task.waypoints=[[2.0, 2.0], [3.5]]", "task.waypoint_radius=0.2"])
    with pytest.raises(SpecError, match=r"corridor7.toml: task.waypoint_radius: must be > 0"):
        run_config(CORRIDOR, ["task.waypoints=[[2.0, 2.0]]"])


# -- the corridor task: state, local reward, reflexes ---------------------------------------------------------
KINSWARM = ["task.clearance_state=true", "task.collision_state=true", "task.collision_penalty=-5"]


def test_the_task_adds_its_state_variables_first():
    cfg = run_config(CORRIDOR, [*KINSWARM, 'learner.extra_state=[{name = "g_perp", sets = 7, range = [-1.5, 1.5]}]'])
    st = task_of(cfg).learner(
        "a3", {"extra_state": LearnerSettings(extra_state=[("g_perp", 7, (-1.5, 1.5))]).extra_state}
    )
    assert st.state_names[6:] == ("clearance", "collided", "g_perp") and st.state_sets[6:] == (5, 2, 7)
    assert st.state_ranges[6:8] == ((0.0, 1.0), (0.0, 1.0))
    fp = FuzzyPartition(st.replace(extra_state=st.extra_state[:2]))
    state = np.array([0.1, 0.2, 3.0, 1.0, -1.0, 0.3, 0.4, 1.0])
    rules, O = fp.activate(state)  # noqa: E741 -- Eq. 4
    ref_rules, ref_O = fp.activate_reference(state)
    assert len(rules) == 2**8 and (O > 0).all()
    order, ref_order = np.argsort(rules), np.argsort(ref_rules)
    assert (rules[order] == ref_rules[ref_order]).all()
    np.testing.assert_allclose(O[order], ref_O[ref_order], rtol=1e-12)
    # the flag is felt: refused (1.0) and not (0.0) fire the same rules with different weights
    r0, o0 = fp.activate(np.concatenate((state[:-1], [0.0])))
    w1, w0 = dict(zip(rules.tolist(), O.tolist(), strict=True)), dict(zip(r0.tolist(), o0.tolist(), strict=True))
    assert w1.keys() == w0.keys() and max(abs(w1[k] - w0[k]) for k in w1) > 0.01
    assert len(task_of(run_config(CORRIDOR)).learner("a3", {}).state_sets) == 6  # the paper's six by default
    for bad, why in [
        ("task.collision_penalty=1.0", "task.collision_penalty: must be <= 0"),
        ("task.clearance_state=1", "task.clearance_state: expected true or false, got an integer 1"),
        ("task.settle_radius=0.0", "task.settle_radius: must be a distance > 0"),
        ('task.settle_radius="0.15"', "task.settle_radius: expected a number, got a string '0.15'"),
        ('task.clearance_of="chain"', "task.clearance_of: expected one of link, subtree"),
        ('task.clearance_of="subtree"', "task.clearance_of: needs clearance_state"),
    ]:
        with pytest.raises(SpecError, match=why):
            run_config(CORRIDOR, [bad])


def _view(step: int, sense: dict, last: int | None = None, ups: dict | None = None) -> StepView:
    return StepView(0, step, (0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (5.0, 2.0), (5.5, 2.0), sense, ups or {}, last)


def _agent(agent: str, sets: list[str]) -> CorridorAgent:
    task = task_of(run_config(GUIDED, sets))
    a = task.agent(agent, task.learner(agent, {}))
    assert isinstance(a, CorridorAgent)
    return a


def test_collision_tabu_leaves_out_the_refused_move_and_the_shield_what_it_vetoes():
    """The tabu: right after the wall refused my move, that move is left out (a refused move left the state
    unchanged); the shield: the scene's vetoes. Nothing without them."""
    tabu = _agent("a3", ["task.collision_tabu=true"])
    assert tabu.avoid(_view(5, {"collided": 1.0}, last=2)) == [2]
    assert tabu.avoid(_view(5, {"collided": 0.0}, last=2)) == []
    assert tabu.avoid(_view(5, {"collided": 1.0}, last=None)) == []  # I took no action at the step before
    assert tabu.avoid(_view(5, {"collided": 1.0, "shield-": 1.0, "shield+": 0.0}, last=0)) == [0, 0]
    assert sorted(tabu.avoid(_view(5, {"shield-": 1.0, "shield+": 1.0}))) == [0, 2]
    plain = _agent("a3", [])
    assert plain.avoid(_view(5, {"collided": 1.0}, last=2)) == []


def test_collision_penalty_and_follow_the_leader_are_local_terms():
    a = _agent("a7", ["task.collision_penalty=-5", "task.follow_leader=40.0"])
    a.start_epoch()
    assert a.reward(_view(1, {"collided": 1.0}), None) is None  # no reward yet, but D_i is remembered
    r = a.reward(_view(2, {"collided": 1.0}), 1.0)  # the link end did not move: only the penalty
    assert r == pytest.approx(1.0 - 5.0)
    far = StepView(0, 3, (0.0, 0.0, 0.0), (4.5, 2.0, 0.0), (4.5, 2.0), (5.5, 2.0), {}, {}, None)
    # a7's end from (1, 0), before the corridor's mouth (|end - via| + |via - goal|), to 1 from the goal on the axis
    assert a.reward(far, 0.0) == pytest.approx(40.0 * (math.hypot(1.0, 2.0) + 3.5 - 1.0))
    assert _agent("a1", ["task.follow_leader=40.0"]).behind is None  # only the last 4 agents


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


def test_subtree_clearance_is_the_smallest_below():
    """clearance_of "subtree": the state holds the smallest of my link's clearance and my children's `Up`
    clearances (each their own subtree's); "link" keeps my own link's; `up` sends my subtree's."""

    def state(of: str, own: float, below: dict[str, float | None]) -> float:
        a = _agent("a6", ["task.clearance_state=true", f'task.clearance_of="{of}"'])
        ups = {
            c: Up(epoch=0, step=3, tips={"a7": (5.0, 2.0, 0.0)}, action=1, sense={} if v is None else {"clearance": v})
            for c, v in below.items()
        }
        view = _view(3, {"clearance": own, "collided": 0.0}, ups=ups)
        (value,) = a.state(view)
        assert a.up(view) == {"clearance": min([own, *(v for v in below.values() if v is not None)])}
        return value

    assert state("subtree", 0.8, {"a7": 0.05}) == 0.05  # my chain is against a wall, my own link is not
    assert state("subtree", 0.02, {"a7": 0.4}) == 0.02
    assert state("subtree", 0.8, {"a7": None}) == 0.8  # a child that knows none
    assert state("link", 0.8, {"a7": 0.05}) == 0.8


def _recorded(spec: Spec, tmp_path: Path, *keys_of) -> tuple:
    cfg = spec.config(tmp_path)
    keys = Keys(cfg.run_id)
    _, captured = asyncio.run(_supervise(cfg, cfg.topo(), False, record=tuple(k(keys) for k in keys_of)))
    return cfg, keys, captured


@pytest.mark.timeout(120)
def test_up_carries_each_subtrees_smallest_clearance(tmp_path):
    """On the wire, a real run: every child's `Up` at a step carries the smallest of the sim's clearances at that
    step (`Obs`) over the child's own link and all links below it."""
    task = (("clearance_state", True), ("clearance_of", "subtree"), ("collision_state", True), ("collision_tabu", True))
    spec = Spec("up", seed=3, epochs=1, steps=40, reward="settle", task=task, file=str(GUIDED))
    cfg, keys, captured = _recorded(spec, tmp_path, lambda k: k.obs("*"), lambda k: k.up("*"))
    topo = cfg.topo()
    obs: dict[tuple[int, str], float] = {}
    ups: list[tuple[str, Up]] = []
    for key, payload in captured:
        if key.startswith(keys.obs("")):
            m = codec.decode(payload, Obs, cfg.run_id, cfg.key)
            obs[(m.step, key[len(keys.obs("")) :])] = m.sense["clearance"]
        else:
            parent = key[len(keys.root) + 3 : -3]  # <root>/a/<parent>/up
            ups.append((parent, codec.decode(payload, Up, cfg.run_id, cfg.key)))
    checked = 0
    for parent, m in ups:
        if m.step == cfg.steps:
            continue  # the closing `up`: an action only
        (child,) = [c for c in topo.agents[parent].children if set(topo.subtree_leaves(c)) == set(m.tips)]
        assert m.sense["clearance"] == min(obs[(m.step, a)] for a in topo.subtree(child)), (parent, m.step)
        checked += 1
    assert checked == 6 * cfg.steps  # a2..a7, every step
    assert min(obs.values()) < 0.5 < max(obs.values())  # near and far links both seen


@pytest.mark.timeout(120)
def test_shield_never_moves_where_the_look_ahead_forbids(tmp_path):
    """On the wire, a real run with a wide shield: every agent's obs carries the scene's vetoes, and no agent ever
    commands a move its obs vetoed; some moves are vetoed (the check can fail)."""
    task = (("clearance_state", True), ("collision_state", True), ("collision_tabu", True))
    spec = Spec("shield", seed=3, epochs=1, steps=60, reward="settle", task=task, scene=(("shield", 0.5),))
    spec = Spec(**{**spec.__dict__, "file": str(GUIDED)})
    cfg, keys, captured = _recorded(spec, tmp_path, lambda k: k.obs("*"), lambda k: k.cmd("*"))
    veto: dict[tuple[int, str], tuple[float, float]] = {}
    cmds: dict[tuple[int, str], float] = {}
    for key, payload in captured:
        if key.startswith(keys.obs("")):
            m = codec.decode(payload, Obs, cfg.run_id, cfg.key)
            veto[(m.step, key[len(keys.obs("")) :])] = (m.sense["shield-"], m.sense["shield+"])
        else:
            c = codec.decode(payload, Cmd, cfg.run_id, cfg.key)
            cmds[(c.step, key[len(keys.cmd("")) :])] = c.delta
    assert len(veto) == len(cmds) == 7 * cfg.steps
    blocked = 0
    for k, delta in cmds.items():
        lo, hi = veto[k]
        assert not (delta < 0 and lo) and not (delta > 0 and hi), (k, delta, lo, hi)
        blocked += lo + hi
    assert blocked > 20


# -- a run through the corridor ---------------------------------------------------------------------
@pytest.mark.timeout(120)
def test_corridor_run_walls_are_solid(tmp_path, endpoint):
    out = tmp_path / "run"
    args = ["run", str(CORRIDOR), "--placement", "single", "--epochs", "2", "--steps", "250", "--seed", "1"]
    args += ["--listen", endpoint, "--out", str(out), "--no-progress", "--reward", "shaped"]
    for s in KINSWARM:
        args += ["--set", s]
    assert cli_main(args) == 0
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert len(rows) == 2
    for r in rows:
        assert len(r["traces"]["collisions"]) == len(r["traces"]["clearance"]) == 250
        assert min(r["traces"]["clearance"]) >= -1e-5  # never inside a wall
    assert sum(sum(r["traces"]["collisions"]) for r in rows) > 0  # exploring from scratch, it bumps into the walls
    for f in ("scene.png", "learning_curve.png", "arm.png", "summary.json", "run.toml"):
        assert (out / f).is_file(), f


def test_blame_falls_on_an_agent_that_moved_when_a_move_below_was_refused():
    """A compound refusal: my move was applied, a move below me was refused (the walls take back increments root
    first, so the one below is the one refused). The blame reaches every agent above that moved, through `Up`."""
    a = _agent("a5", ["task.collision_penalty=-5", "task.blame_penalty=-3"])

    def view(collided: float, below: float, last: int | None) -> StepView:
        ups = {"a6": Up(epoch=0, step=3, tips={"a7": (5.0, 2.0, 0.0)}, action=1, sense={"refused": below})}
        return _view(3, {"clearance": 0.3, "collided": collided}, last=last, ups=ups)

    assert a.reward(view(0.0, 1.0, last=2), 1.0) == pytest.approx(1.0 - 3.0)  # I moved: blamed
    assert a.reward(view(0.0, 1.0, last=1), 1.0) == pytest.approx(1.0)  # I held: not
    assert a.reward(view(0.0, 0.0, last=0), 1.0) == pytest.approx(1.0)  # nothing refused below
    assert a.reward(view(1.0, 1.0, last=0), 1.0) == pytest.approx(1.0 - 5.0)  # refused myself: that penalty only
    # up: whether a move in my subtree (mine or below) was refused, for my parent
    assert a.up(view(0.0, 1.0, last=2))["refused"] == 1.0 and a.up(view(1.0, 0.0, last=2))["refused"] == 1.0
    assert a.up(view(0.0, 0.0, last=2))["refused"] == 0.0
    assert "refused" not in _agent("a5", []).up(view(1.0, 1.0, last=2))  # off: nothing more on the wire
    with pytest.raises(SpecError, match="task.blame_penalty: must be <= 0"):
        run_config(GUIDED, ["task.blame_penalty=2.0"])
