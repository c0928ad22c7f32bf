"""The g_moves probe of 2026-11-22 (docs/science.md): Level-3 with g_moves in place of g_perp ("moves9") or beside
it ("both"), 6 seeds, test sets 0 and 1, through generalisation's own train-and-test (the same specs and cache).

    python docs/probes/g_moves.py moves9 runs/probe   # ~13 min on 2 cores
    python docs/probes/g_moves.py both runs/probe     # ~20 min
"""

import json
import sys
import time
from pathlib import Path

from kinswarm.experiments import generalisation as g
from kinswarm.experiments.common import Context, settings

VARIANTS = {
    "moves9": {"extra_state": ("g_moves",), "extra_sets": (9,), "extra_ranges": ((-3.5, 3.5),)},
    "both": {"extra_state": ("g_perp", "g_moves"), "extra_sets": (7, 9), "extra_ranges": ((-1.5, 1.5), (-3.5, 3.5))},
}

if __name__ == "__main__":  # spawned workers import this file
    variant, out = sys.argv[1], Path(sys.argv[2])
    learner = settings(**{**g.COARSE, **g.G3_UNSIGNED}, **VARIANTS[variant])
    g.RUN_SUFFIX[learner] = f"-{variant}"
    g.LEARNER_NAMES[learner] = variant
    ctx = Context(name="probe", out=out / "probe", runs=out / "runs", seeds=6, quick=False, jobs=2, test_set=0)
    t0 = time.time()
    # as measured: the sweep's reward before graded (and no epsilon_decay)
    row = g.Training(f"Level-3 {variant}", 3, 128, learner, True, min_seeds=6, reward="shaped")
    tested = g.train_and_test(ctx, [row], second_level=3, with_scratch=False)
    for block, e in sorted(tested.per[row.label].items()):
        per_seed = [round(p["mean"], 3) for p in e["per_seed"]]
        print(variant, block, f"mean {e['mean']:.3f} ± {e['mean_std_over_seeds']:.3f}, median {e['median']:.3f},")
        print(f"  within 0.5 {e['frac_within_0_5']:.2f}, per seed {per_seed}")
    print("wall", round(time.time() - t0), "s")
    (out / f"{variant}.json").write_text(json.dumps({b: e["errors"] for b, e in tested.per[row.label].items()}))
