"""The successive-training probe of 2026-11-22 (docs/science.md): Level-3 trained with each epoch starting where the
last ended (`--successive`: the arm meets every training goal from another pose) instead of from the start pose,
then tested as generalisation tests (frozen, each test goal from the start pose), 6 seeds, test sets 0 and 1.

    python docs/probes/successive_training.py runs/probe   # ~13 min on 2 cores
"""

import json
import sys
import time
from pathlib import Path
from typing import Any

from kinswarm.experiments import generalisation as g
from kinswarm.experiments.common import Context
from kinswarm.experiments.swarm import Spec


def successive_training(name: str, **kw: Any) -> Spec:
    return Spec(name, **{**kw, "successive": kw.get("successive", False) or name.startswith("gen-train")})


if __name__ == "__main__":  # spawned workers import this file
    out = Path(sys.argv[1])
    g.Spec = successive_training  # train_and_test builds its specs through this name
    g.RUN_SUFFIX[g.NO_EPSILON_DECAY] += "-succ"
    ctx = Context(name="probe", out=out / "probe", runs=out / "runs", seeds=6, quick=False, jobs=2, test_set=0)
    t0 = time.time()
    # as measured: the sweep's learner and reward before epsilon_decay and graded
    row = g.Training("Level-3 successive training", 3, 128, g.NO_EPSILON_DECAY, True, min_seeds=6, reward="shaped")
    tested = g.train_and_test(ctx, [row], second_level=3, with_scratch=False)
    for block, e in sorted(tested.per[row.label].items()):
        per_seed = [round(p["mean"], 3) for p in e["per_seed"]]
        print(block, f"mean {e['mean']:.3f} ± {e['mean_std_over_seeds']:.3f}, median {e['median']:.3f},")
        print(f"  within 0.5 {e['frac_within_0_5']:.2f}, per seed {per_seed}")
    print("wall", round(time.time() - t0), "s")
    (out / "successive.json").write_text(json.dumps({b: e["errors"] for b, e in tested.per[row.label].items()}))
