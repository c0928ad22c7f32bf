"""Successive training (docs/notebook/reaching.md): Level-3 trained with each epoch starting where
the last ended (the arm meets every training goal from another pose) instead of from the start pose, then tested as
the generalisation tests are (frozen, each test goal from the start pose), on test sets 0 and 1. Measured with the
sweep's learner before epsilon_decay and `graded` (reward `shaped`): 0.598 ± 0.102 / 0.602 ± 0.135, 72 % / 74 %
within 0.5 (6 seeds), worse than training from the start pose. Not kept.
"""

from __future__ import annotations

import json
from typing import Any

from kinswarm.experiments import generalisation as g
from kinswarm.experiments.common import Context

SEEDS = 6


def run(ctx: Context) -> dict[str, Any]:
    row = g.Training(
        "Level-3 successive training",
        3,
        8 if ctx.quick else 128,
        g.NO_EPSILON_DECAY,
        True,
        min_seeds=0 if ctx.quick else SEEDS,
        reward="shaped",
        train_successive=True,
    )
    tested = g.train_and_test(ctx, [row], second_level=3, with_scratch=False)
    out: dict[str, Any] = {}
    for block, e in sorted(tested.per[row.label].items()):
        per_seed = [round(p["mean"], 3) for p in e["per_seed"]]
        out[str(block)] = {"mean": e["mean"], "within_0_5": e["frac_within_0_5"], "per_seed": per_seed}
        print(
            f"test set {block}: mean {e['mean']:.3f} ± {e['mean_std_over_seeds']:.3f}, median {e['median']:.3f}, "
            f"within 0.5 {e['frac_within_0_5']:.2f}, per seed {per_seed}"
        )
    ctx.out.mkdir(parents=True, exist_ok=True)
    (ctx.out / "results.json").write_text(json.dumps(out, indent=1) + "\n")
    return out
