"""The track task (actors/tasks/track.py): a goal moving along a path. Its settings, its path, its reward against
the goal the agents saw, and on the wire a real swarm whose task observation carries each step's goal and whose
error is measured against it — with no generic actor knowing the task."""

from __future__ import annotations

import asyncio
import math
from pathlib import Path

import pytest
from conftest import EXAMPLES, ROOT, run_config
from kinswarm.actors.files.runfile import task_of
from kinswarm.actors.tasks import kinds
from kinswarm.actors.tasks.reach import reach_reward
from kinswarm.actors.tasks.track import TrackAgent
from kinswarm.experiments.swarm import Spec, _supervise
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Task
from kinswarm.protocol.spec import SpecError

TRACK = EXAMPLES / "chain4-track.toml"


def test_it_is_a_module_the_generic_actors_do_not_name():
    assert "track" in kinds()
    for generic in (
        "actors/agent/actor.py",
        "actors/simulator/actor.py",
        "actors/supervisor/core.py",
        "actors/supervisor/epochs.py",
    ):
        assert "track" not in (ROOT / generic).read_text().lower(), generic


@pytest.mark.parametrize(
    ("sets", "what"),
    [
        (["task.speed=-0.1"], "task.speed: must be a number of units per step >= 0"),
        (["task.polyline=[[1.0, 1.0], [2.0, 2.0]]"], "task.circle: give exactly one path"),
        (["task.circle.radius=0"], "task.circle.radius: must be > 0"),
        (['task.circle.turn="left"'], "task.circle.turn: expected one of ccw, cw"),
        (["task.closed=true"], "task.closed: only with polyline"),
        (["task.goal=[1, 2]"], "task.goal: unknown field"),
        (['task.reward="contact"'], "task.reward: 'contact' is not one of"),
    ],
)
def test_settings_are_checked(sets, what):
    with pytest.raises(SpecError, match=what.replace("(", r"\(")):
        run_config(TRACK, sets)


def test_the_path(tmp_path):
    s = task_of(run_config(TRACK)).settings
    assert s.at(0.0) == pytest.approx((8.0, 4.0))
    assert s.at(math.pi) == pytest.approx((6.0, 6.0))  # a quarter lap of radius 2, counter-clockwise
    cw = task_of(run_config(TRACK, ['task.circle.turn="cw"'])).settings
    assert cw.at(math.pi) == pytest.approx((6.0, 2.0))
    lines = tmp_path / "lines.toml"
    lines.write_text(f'robot = "{EXAMPLES / "chain4.toml"}"\n[task]\nkind = "track"\n')
    p = task_of(run_config(lines, ["task.polyline=[[0.0, 5.0], [3.0, 5.0], [3.0, 9.0]]"])).settings
    assert p.at(1.0) == pytest.approx((1.0, 5.0)) and p.at(5.0) == pytest.approx((3.0, 7.0))
    assert p.at(100.0) == pytest.approx((3.0, 9.0))  # an open polyline ends where it ends
    closed = task_of(run_config(lines, ["task.polyline=[[0.0, 5.0], [3.0, 5.0]]", "task.closed=true"]))
    assert closed.settings.at(7.0) == pytest.approx((1.0, 5.0))  # 6 round, then 1 more
    goal, path = task_of(run_config(TRACK)).goal(3, 500)
    assert len(path) == 500 and path[0] == goal and math.dist(path[100], path[101]) == pytest.approx(0.025, rel=1e-3)


def test_the_reward_is_the_move_against_the_goal_the_agents_saw():
    task = task_of(run_config(TRACK))
    root = task.agent("a1", None)
    assert isinstance(root, TrackAgent)
    root.start_epoch()
    t0 = Task(epoch=0, step=0, goal=(8.0, 4.0), tips={"a4": (9.0, 4.0, 0.0)})
    assert root.head(t0).reward is None and root.head(t0).goal == (8.0, 4.0)
    root.start_epoch()
    root.head(t0)
    # the tip moved 0.5 towards the goal it saw (8, 4) while the goal moved on to (8, 5): paid as an approach
    t1 = Task(epoch=0, step=1, goal=(8.0, 5.0), tips={"a4": (8.5, 4.0, 0.0)})
    h = root.head(t1)
    assert h.goal == (8.0, 5.0) and h.reward == pytest.approx(reach_reward(0.5, 1.0, "graded"))


@pytest.mark.timeout(120)
def test_on_the_wire_the_goal_moves_and_the_error_follows_it(tmp_path: Path):
    spec = Spec("track", seed=1, epochs=2, steps=60, file=str(TRACK))
    cfg = spec.config(tmp_path)
    keys = Keys(cfg.run_id)
    result, captured = asyncio.run(_supervise(cfg, cfg.topo(), False, record=(keys.task,)))
    assert not result.error
    _, path = task_of(cfg).goal(0, cfg.steps)
    tasks = {}
    for _, payload in captured:
        m = codec.decode(payload, Task, cfg.run_id, cfg.key)
        tasks[(m.epoch, m.step)] = m
    assert len(tasks) == 2 * 60
    for (epoch, step), m in tasks.items():
        assert m.goal == pytest.approx(path[step]), (epoch, step)  # the root sees the step's goal
    for epoch, done in enumerate(result.epochs):
        for t in range(cfg.steps - 1):  # the error after step t's moves, against step t's goal
            (tip,) = tasks[(epoch, t + 1)].tips.values()
            assert done.errors[t] == pytest.approx(math.dist(tip[:2], path[t]), abs=1e-9)
