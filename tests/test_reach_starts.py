"""The planar reach task's start poses: home by default, or drawn per epoch within the joint limits (start_pose =
"random"), seeded so every placement and rerun draws the same, and the run really starts there."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from kinswarm.actors.cli.commands import main
from kinswarm.actors.files.runfile import load_run, task_of
from kinswarm.protocol.spec import SpecError

ROBOT = '[robot]\nname = "c"\n[robot.defaults]\nlink_length = 3.0\nlimits_deg = [-90.0, 120.0]\n' + "".join(
    f'[[robot.agent]]\nid = "a{i}"\n' + (f'parent = "a{i - 1}"\n' if i > 1 else "") for i in (1, 2, 3)
)


def _task(tmp_path: Path, extra: str):
    f = tmp_path / "run.toml"
    f.write_text(f'{ROBOT}[task]\nkind = "reach"\ngoal = [3.0, 4.0]\n{extra}\n')
    return f


def test_home_unless_asked(tmp_path: Path) -> None:
    task = task_of(load_run(_task(tmp_path, "")))
    assert [task.start(e) for e in range(3)] == [{}, {}, {}]


def test_random_poses_lie_within_the_limits_and_depend_on_seed_and_epoch_only(tmp_path: Path) -> None:
    task = task_of(load_run(_task(tmp_path, 'start_pose = "random"\nstart_seed = 4')))
    again = task_of(load_run(_task(tmp_path, 'start_pose = "random"\nstart_seed = 4')))
    other = task_of(load_run(_task(tmp_path, 'start_pose = "random"\nstart_seed = 5')))
    poses = [task.start(e) for e in range(200)]
    assert poses == [again.start(e) for e in range(200)]  # a rerun (or a resumed run) draws the same
    assert poses[:5] != [other.start(e) for e in range(5)]
    lo, hi = math.radians(-90.0), math.radians(120.0)
    angles = [v for p in poses for v in p.values()]
    assert all(set(p) == {"a1", "a2", "a3"} for p in poses)
    assert all(lo <= v <= hi for v in angles)
    # spread over the whole range, not near home: a quarter of the draws in each quarter of the range, roughly
    quarters = [sum(lo + q * (hi - lo) / 4 <= v < lo + (q + 1) * (hi - lo) / 4 for v in angles) for q in range(4)]
    assert min(quarters) > len(angles) / 8, quarters


def test_a_share_of_the_epochs_starts_from_home(tmp_path: Path) -> None:
    task = task_of(load_run(_task(tmp_path, 'start_pose = "random"\nstart_share = 0.5')))
    home = sum(task.start(e) == {} for e in range(400))
    assert 150 < home < 250, home
    none = task_of(load_run(_task(tmp_path, 'start_pose = "random"\nstart_share = 0.0')))
    assert all(none.start(e) == {} for e in range(50))


@pytest.mark.parametrize(
    ("extra", "field", "words"),
    [
        ('start_pose = "anywhere"', "task.start_pose", "not one of home, random"),
        ('start_pose = "random"\nstart_share = 1.5', "task.start_share", "share in [0, 1]"),
        ('start_pose = "random"\nstart_seed = -1', "task.start_seed", "integer >= 0"),
        ("start_seed = 3", "task", 'only with start_pose = "random"'),
    ],
)
def test_bad_start_settings_are_one_line(tmp_path: Path, extra: str, field: str, words: str) -> None:
    with pytest.raises(SpecError) as e:
        task_of(load_run(_task(tmp_path, extra)))
    assert e.value.where == field and words in e.value.what, str(e.value)


def test_the_run_starts_each_epoch_from_its_drawn_pose(tmp_path: Path) -> None:
    f = _task(tmp_path, 'start_pose = "random"\nstart_seed = 1')
    out = tmp_path / "out"
    args = ["run", str(f), "--epochs", "3", "--steps", "2", "--placement", "inprocess", "--out", str(out)]
    assert main([*args, "--run-id", "starts"]) == 0
    task = task_of(load_run(f))
    rows = [json.loads(line) for line in (out / "poses.jsonl").read_text().splitlines()]
    assert [r["epoch"] for r in rows] == [0, 1, 2]
    for r in rows:
        drawn = [math.degrees(task.start(r["epoch"])[a]) for a in ("a1", "a2", "a3")]
        first = r["angles_deg"][0]  # after the first step: at most one 1-degree move per joint from the start
        assert all(abs(a - b) <= 1.0 + 1e-3 for a, b in zip(first, drawn, strict=True)), (first, drawn)


def test_a_generalisation_row_trains_from_random_poses_and_its_successive_row_tests_those_swarms() -> None:
    from kinswarm.experiments.generalisation.protocol import LEARNER, Training, training_spec

    home = Training("Level-3", 3, 128, LEARNER)
    rs = Training("Level-3, random starts", 3, 128, LEARNER, random_starts=0.5)
    succ = Training(
        "Level-3, random starts, successive", 3, 128, LEARNER, False, True, 0, random_starts=0.5, trained_as=rs.label
    )
    assert training_spec(home, 2, 500).task == ()
    spec = training_spec(rs, 2, 500)
    assert dict(spec.task) == {"start_pose": "random", "start_share": 0.5, "start_seed": 2}
    assert spec.name != training_spec(home, 2, 500).name and spec.identity() != training_spec(home, 2, 500).identity()
    assert succ.suffix == rs.suffix  # its test runs are named as the swarm it tests
