"""The any-pose rows over many seeds, without the rest of the generalisation experiment (research, not product).

The experiment's own rows (protocol.any_pose: Level-3 trained on the free chain from a random pose each epoch, tested
frozen from the start configuration and the paper's way on test sets K and K+1) through its own train_and_test, a
batch of seeds at a time so every finished batch is kept (the runs directory caches each run); and the rule on
g_perp tested the paper's way on the free chain on both sets, one run each (the rule has no seed: it neither learns
nor explores). Writes OUT/any_pose_seeds.json after each batch and prints per set: mean, standard error over seeds,
spread and the worst seeds.

    python -m kinswarm.experiments.generalisation.any_pose_seeds --seeds 20 --jobs 2 --runs /tmp/runs --out /tmp/out

`--g-perp SETS,HALF_RANGE` trains and tests the same rows with g_perp's sets changed (a variant to compare on the
same seeds; default the recipe's, FREE_LEARNER: 9 over ±0.75).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

import numpy as np
from kinswarm.actors.learning.settings import StateVariable

from ..common import Context, run_specs
from ..goals import TEST_SIZE, halton
from ..swarm import Spec
from .protocol import (
    ANY_POSE,
    EVAL_STEPS,
    FREE_JOINTS,
    FREE_LEARNER,
    FREE_REFERENCES,
    any_pose,
    stats,
    train_and_test,
)
from .report import spread

ROWS = {"from the start pose": ANY_POSE, "successive": f"{ANY_POSE}, successive test goals"}


def rule_free(ctx: Context, blocks: list[int]) -> dict[int, dict[str, float]]:
    """The rule tested the paper's way on the free chain, as train_and_test's FREE_REFERENCES row, on each block."""
    ((_, controller),) = FREE_REFERENCES.items()
    specs = [
        Spec(
            f"gen-ref{b}-{controller}-succ-free",
            epochs=TEST_SIZE,
            steps=EVAL_STEPS,
            goals=tuple(halton(b)[:TEST_SIZE]),
            controller=controller,
            successive=True,
            file=FREE_JOINTS,
        )
        for b in blocks
    ]
    return {b: stats(r.final_errors) for b, r in zip(blocks, run_specs(ctx, specs, "rule"), strict=True)}


def summary(per_seed: list[dict[str, float]], seeds: list[int]) -> dict[str, Any]:
    """The report's spread of a row over seeds (report.spread: mean, standard errors, range, worst seeds), with how many
    seeds meet the issue's bar on their own and every seed's numbers."""
    means = np.array([p["mean"] for p in per_seed])
    within = np.array([p["frac_within_0_5"] for p in per_seed])
    return {
        **spread(per_seed, seeds),
        "seeds_within_bar": int(np.sum((means <= 0.3) & (within >= 0.9))),
        "per_seed": {str(s): p for s, p in zip(seeds, per_seed, strict=True)},
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20, help="seeds 0..N-1")
    ap.add_argument("--batch", type=int, default=2, help="seeds trained and tested per batch")
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--test-set", type=int, default=0, help="K: tested on K and K+1")
    ap.add_argument("--runs", type=Path, required=True)
    ap.add_argument("--out", type=Path, required=True)
    ap.add_argument("--g-perp", default="", help="SETS,HALF_RANGE: g_perp's sets in a variant of the learner")
    a = ap.parse_args(argv)
    learner = FREE_LEARNER
    if a.g_perp:
        sets, half = a.g_perp.split(",")
        g_perp = (StateVariable("g_perp", int(sets), (-float(half), float(half))),)
        learner = tuple(sorted({**dict(FREE_LEARNER), "extra_state": g_perp}.items()))
    a.out.mkdir(parents=True, exist_ok=True)
    k = a.test_set
    ctx = Context("generalisation", a.out, a.runs, seeds=1, quick=False, jobs=a.jobs, test_set=k)
    rule = rule_free(ctx, [k, k + 1])
    for n in range(min(a.batch, a.seeds), a.seeds + a.batch, a.batch):
        ctx.seeds = min(n, a.seeds)
        t = train_and_test(ctx, any_pose(learner=learner), second_level=3, with_scratch=False)
        seeds = t.seeds_of(t.trainings[0])
        res: dict[str, Any] = {"g_perp": a.g_perp or "9,0.75", "test_set": k, "seeds": seeds, "rule_successive": {}}
        res["train_last64_within_0_5"] = {
            str(s): float(np.mean(np.asarray(t.trained[(ANY_POSE, s)].final_errors[-64:]) < 0.5)) for s in seeds
        }
        for b in (k, k + 1):
            res["rule_successive"][f"test_set_{b}"] = rule[b]
            for name, label in ROWS.items():
                entry = t.per[label][f"test_set_{b}"]
                res.setdefault(name, {})[f"test_set_{b}"] = summary(entry["per_seed"], seeds)
        (a.out / f"any_pose_seeds{'-g' + a.g_perp if a.g_perp else ''}.json").write_text(json.dumps(res, indent=1))
        print(f"seeds 0-{seeds[-1]} ({len(seeds)}):", flush=True)
        for name in ROWS:
            for b in (k, k + 1):
                s = res[name][f"test_set_{b}"]
                worst = ", ".join(f"{w['seed']}: {w['mean']:.3f} ({w['within_0_5']:.0%})" for w in s["worst"])
                print(
                    f"  {name:20s} set {b}: {s['mean']:.3f} ± {s['mean_se']:.3f} (seeds {s['mean_min']:.3f}-"
                    f"{s['mean_max']:.3f}), within 0.5 {s['within_0_5']:.1%} ± {s['within_se']:.1%} (min "
                    f"{s['within_min']:.0%}), {s['seeds_within_bar']} seeds within the bar; worst {worst}",
                    flush=True,
                )
        for b in (k, k + 1):
            r = rule[b]
            print(f"  rule, successive     set {b}: {r['mean']:.3f}, within 0.5 {r['frac_within_0_5']:.0%}", flush=True)
        if ctx.seeds >= a.seeds:
            break


if __name__ == "__main__":
    main()
