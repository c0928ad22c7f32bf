"""The generalisation experiment's successive rows on the chain with joints that turn freely: the same swarms and
goals as on chain4, only the robot's limits out of reach; the rule's successive row likewise; --test-set K holds."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from kinswarm.actors.run.runfile import load_run
from kinswarm.experiments.common import Context
from kinswarm.experiments.generalisation import protocol
from kinswarm.experiments.generalisation.protocol import FREE_JOINTS, LEARNER, Training, train_and_test
from kinswarm.experiments.goals import halton
from kinswarm.experiments.swarm import CHAIN4, RunOutcome


def test_the_free_chain_is_chain4_with_its_limits_out_of_reach() -> None:
    free, chain4 = load_run(FREE_JOINTS).topo(), load_run(CHAIN4).topo()
    assert free.dof_agents == chain4.dof_agents and free.initial_angles() == chain4.initial_angles()
    for a in free.dof_agents:
        assert free.agents[a].link_length == chain4.agents[a].link_length
        lo, hi = free.agents[a].limits
        assert lo <= -100 * 2 * math.pi and hi >= 100 * 2 * math.pi  # 100 turns each way


@pytest.mark.parametrize("k", [0, 3])
def test_successive_rows_test_the_level_swarms_on_the_free_chain(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, k: int
) -> None:
    ran = []

    def fake_run_specs(ctx, specs, desc=""):  # no swarm runs: what would run, and a row per goal
        ran.extend(specs)
        return [RunOutcome(s, tmp_path / s.name, {}, [{"final_error": 0.1, "errors": [0.1]}] * s.epochs) for s in specs]

    monkeypatch.setattr(protocol, "run_specs", fake_run_specs)
    ctx = Context("generalisation", tmp_path, tmp_path / "runs", seeds=2, quick=False, test_set=k)
    rows = [
        Training("Level-3", 3, 128, LEARNER),
        Training("Level-3, successive test goals", 3, 128, LEARNER, False, True),
        Training("Level-3, successive test goals, joints free", 3, 128, LEARNER, False, True, robot=FREE_JOINTS),
    ]
    tested = train_and_test(ctx, rows, second_level=3, with_scratch=False, free_joints=True)
    trains = [s for s in ran if s.learn and s.controller == "agents"]
    assert len(trains) == 2 and all(s.file == str(CHAIN4) for s in trains)  # one training per seed, on chain4
    free = [s for s in ran if s.file == FREE_JOINTS]
    swarms = [s for s in free if s.controller == "agents"]
    assert len(swarms) == 2 and all(s.successive and not s.learn and s.from_dir for s in swarms)
    assert {s.from_dir for s in swarms} == {str(tmp_path / s.name) for s in trains}  # the level's own swarms
    rule = [s for s in free if s.controller == "rule"]
    assert len(rule) == 1 and rule[0].successive
    assert all(s.goals == tuple(halton(k)[:100]) for s in [*swarms, *rule])  # test set K, as the other rows
    assert "rule on g_perp, successive test goals, joints free" in tested.references
    assert f"test_set_{k}" in tested.per["Level-3, successive test goals, joints free"]


def test_the_any_pose_row_trains_on_the_free_chain_from_random_poses(tmp_path: Path, monkeypatch) -> None:
    ran = []

    def fake_run_specs(ctx, specs, desc=""):
        ran.extend(specs)
        return [RunOutcome(s, tmp_path / s.name, {}, [{"final_error": 0.1, "errors": [0.1]}] * s.epochs) for s in specs]

    monkeypatch.setattr(protocol, "run_specs", fake_run_specs)
    ctx = Context("generalisation", tmp_path, tmp_path / "runs", seeds=1, quick=False, test_set=0)
    label = "Level-3, random starts, joints free"
    rows = [
        Training(label, 3, 128, LEARNER, False, random_starts=1.0, robot=FREE_JOINTS),
        Training(
            f"{label}, successive", 3, 128, LEARNER, False, True, random_starts=1.0, trained_as=label, robot=FREE_JOINTS
        ),
    ]
    tested = train_and_test(ctx, rows, second_level=3, with_scratch=False)
    (train,) = [s for s in ran if s.learn and s.controller == "agents"]
    assert train.file == FREE_JOINTS and dict(train.task)["start_pose"] == "random"
    tests = [s for s in ran if not s.learn and s.controller == "agents"]
    assert {(s.successive, s.goals[0]) for s in tests} == {
        (b, tuple(halton(k)[0])) for b in (False, True) for k in (0, 1)
    }
    assert all(s.from_dir == str(tmp_path / train.name) and s.file == FREE_JOINTS for s in tests)
    assert set(tested.per[f"{label}, successive"]) == {"test_set_0", "test_set_1"}
