"""§5.2, Figs. 10-12: train on quad-tree goal sets, test the frozen swarm on unseen Halton goals.

Level-L trains one swarm on the 4^L centres of a quad-tree over the task space (goals.py), one goal per
epoch, every goal REPS times in a seeded order (Level-4: once each), then evaluates it frozen (`--from T
--learn off --explore off`: no learning, greedy actions) on 100 test goals — block K of the Halton
sequence in bases 2 and 3 (`--test-set K`; Levels 3 and 4 are also tested on block K+1, a second unseen set).
Level-3 carries the paper's number: its rows (from the start configuration and successive, the any-pose recipe's
and the learner-kind controls too) run on at least L3_SEEDS seeds.
Higher levels also train for more epochs; a control trains Level-1's 4 goals for Level-2's epoch budget,
which separates the number of goals from the amount of training. Two controls take the paper's design choices
away one at a time on Level-3's training (CONTROLS): independent learners (no JASM) and a plain Q-table (no fuzzy
interpolation). The any-pose rows get two controls of their own, tested the same way (any_pose_controls): the learner
untrained, and a swarm trained alike that sees only q. Also reported, labelled as what it is:
an untrained swarm *learning* within one episode per test goal (not a generalisation test).
"""

from __future__ import annotations

from typing import Any

from ..common import Context
from .protocol import (
    BLIND_FREE,
    COARSE_TEXT,
    CONTROLS,
    DEFAULT_LEARNER,
    EVAL_STEPS,
    FREE_JOINTS,
    FREE_LEARNER,
    G_PERP_TEXT,
    L3_SEEDS,
    LEARNER,
    LEARNER_TEXT,
    LEVELS,
    NO_EPSILON_DECAY,
    NO_G_PERP,
    PAPER,
    REPS,
    REWARD,
    SIGNED_G3,
    UNSIGNED_TEXT,
    Training,
    any_pose,
    any_pose_controls,
    controls,
    reps_for,
    run_suffix,
    train_and_test,
    training_spec,
)
from .report import cdf, report, table

__all__ = [
    "BLIND_FREE",
    "COARSE_TEXT",
    "CONTROLS",
    "DEFAULT_LEARNER",
    "EVAL_STEPS",
    "FREE_JOINTS",
    "FREE_LEARNER",
    "G_PERP_TEXT",
    "L3_SEEDS",
    "LEARNER",
    "LEARNER_TEXT",
    "NO_EPSILON_DECAY",
    "NO_G_PERP",
    "PAPER",
    "REPS",
    "REWARD",
    "SIGNED_G3",
    "UNSIGNED_TEXT",
    "Training",
    "any_pose",
    "any_pose_controls",
    "cdf",
    "controls",
    "run",
    "run_suffix",
    "table",
    "train_and_test",
    "training_spec",
]


def run(ctx: Context) -> dict[str, Any]:
    q = ctx.quick
    levels = (1,) if q else LEVELS
    control_epochs = REPS * 4**2  # Level-1's goals for Level-2's epochs
    trainings = [
        Training(f"Level-{L}", L, reps_for(L) * 4**L, LEARNER, min_seeds=L3_SEEDS if L == 3 else 0) for L in levels
    ]
    if q:
        trainings = [Training("Level-1", 1, 4, LEARNER), *controls(1, 4)]
    else:
        trainings.append(Training(f"Level-1, {control_epochs} epochs (control)", 1, control_epochs, LEARNER, False))
        # §5.2 "successive on-line requests": the Level-3 swarm, each test goal from where the last one ended
        l3 = {"min_seeds": L3_SEEDS}
        trainings.append(Training("Level-3, successive test goals", 3, REPS * 4**3, LEARNER, False, True, **l3))
        # ... and on the same chain with joints that turn freely (FREE_JOINTS): the same swarms and goals
        trainings.append(
            Training(
                "Level-3, successive test goals, joints free",
                3,
                REPS * 4**3,
                LEARNER,
                False,
                True,
                robot=FREE_JOINTS,
                **l3,
            )
        )
        # a skill from any pose: trained on the free chain from a random pose each epoch, tested from the start
        # configuration and the paper's way
        trainings += any_pose(L3_SEEDS)
        # ... and its controls: untrained, and blind to the goal (q only); on --seeds seeds
        trainings += any_pose_controls()
        # what JASM and the fuzzy sets buy: the Level-3 row with each taken away
        trainings += controls(3, REPS * 4**3, L3_SEEDS)
    t = train_and_test(ctx, trainings, second_level=1 if q else 3, with_scratch=True, free_joints=not q)
    return report(ctx, t, levels)
