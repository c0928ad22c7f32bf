"""The generalisation experiment's successive rows on the chain with joints that turn freely: the same swarms and
goals as on chain4, only the robot's limits out of reach, on test sets K and K+1; the rule's successive rows too."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.files.runfile import learner_settings, load_run, task_of
from kinswarm.actors.learning.fuzzy import memberships_1d
from kinswarm.experiments.common import Context
from kinswarm.experiments.generalisation import protocol
from kinswarm.experiments.generalisation.protocol import (
    ANY_POSE,
    FREE_JOINTS,
    LEARNER,
    Training,
    any_pose,
    train_and_test,
    training_spec,
)
from kinswarm.experiments.goals import halton
from kinswarm.experiments.swarm import CHAIN4, ROOT, RunOutcome


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
    assert len(swarms) == 4 and all(s.successive and not s.learn and s.from_dir for s in swarms)  # 2 seeds x 2 sets
    assert {s.from_dir for s in swarms} == {str(tmp_path / s.name) for s in trains}  # the level's own swarms
    rule = [s for s in free if s.controller == "rule"]
    assert len(rule) == 2 and all(s.successive for s in rule)
    # test sets K and K+1, as the level's own rows; the rule on the same two
    for runs in (swarms, rule):
        assert {s.goals for s in runs} == {tuple(halton(b)[:100]) for b in (k, k + 1)}
    assert "rule on g_perp, successive test goals, joints free" in tested.references
    assert set(tested.per["Level-3, successive test goals, joints free"]) == {f"test_set_{k}", f"test_set_{k + 1}"}


def test_the_any_pose_row_trains_on_the_free_chain_from_random_poses(tmp_path: Path, monkeypatch) -> None:
    ran = []

    def fake_run_specs(ctx, specs, desc=""):
        ran.extend(specs)
        return [RunOutcome(s, tmp_path / s.name, {}, [{"final_error": 0.1, "errors": [0.1]}] * s.epochs) for s in specs]

    monkeypatch.setattr(protocol, "run_specs", fake_run_specs)
    ctx = Context("generalisation", tmp_path, tmp_path / "runs", seeds=1, quick=False, test_set=0)
    tested = train_and_test(ctx, any_pose(), second_level=3, with_scratch=False)  # the experiment's own rows
    (train,) = [s for s in ran if s.learn and s.controller == "agents"]
    assert train.file == FREE_JOINTS and dict(train.task)["start_pose"] == "random"
    tests = [s for s in ran if not s.learn and s.controller == "agents"]
    assert {(s.successive, s.goals[0]) for s in tests} == {
        (b, tuple(halton(k)[0])) for b in (False, True) for k in (0, 1)
    }
    assert all(s.from_dir == str(tmp_path / train.name) and s.file == FREE_JOINTS for s in tests)
    assert set(tested.per[f"{ANY_POSE}, successive test goals"]) == {"test_set_0", "test_set_1"}


def q_memberships_spread(cfg: RunConfig) -> float:
    """How much an agent's memberships in its q sets change over its joint's whole range, at most over agents."""
    topo, spread = cfg.topo(), 0.0
    for agent, s in learner_settings(task_of(cfg), cfg.learner).items():
        (qlo, qhi), m = s.state_ranges[0], s.state_sets[0]
        mu = [memberships_1d(q, m, qlo, qhi, s.slope) for q in (*topo.agents[agent].limits, 0.0)]
        spread = max(spread, max(float(np.abs(a - b).max()) for a in mu for b in mu))
    return spread


def test_q_is_out_of_the_state_on_the_free_chain(tmp_path: Path) -> None:
    """Random poses on the free chain reach ±628 rad: the any-pose row and its recipe must not tell angles apart
    there (the level sweep's ±1000 rad does: 0.2-0.8), any more than the sweep's learner does on chain4's ±π."""
    row = training_spec(any_pose()[0], 0, 500).config(tmp_path)
    recipe = load_run(ROOT / "examples" / "reach-any-pose.toml")
    sweep_on_chain4 = training_spec(Training("Level-3", 3, 128, LEARNER), 0, 500).config(tmp_path)
    sweep_on_free = training_spec(Training("x", 3, 128, LEARNER, robot=FREE_JOINTS), 0, 500).config(tmp_path)
    assert q_memberships_spread(sweep_on_chain4) < 0.01
    assert q_memberships_spread(sweep_on_free) > 0.5  # the leak this row must not have
    assert q_memberships_spread(row) < 0.001
    assert q_memberships_spread(recipe) < 0.001
    assert recipe.topo().agents["a1"].limits == row.topo().agents["a1"].limits
    # the recipe's state is the row's: the same variables, sets and ranges (g_perp's 9 sets over ±0.75 too)
    grid = [(s.state_sets, s.state_ranges) for s in learner_settings(task_of(row), row.learner).values()]
    assert [(s.state_sets, s.state_ranges) for s in learner_settings(task_of(recipe), recipe.learner).values()] == grid
    assert grid[0][0][-1] == 9 and grid[0][1][-1] == (-0.75, 0.75)
