"""What a fleet buys on the iiwa's points (research, beside `kinswarm experiment reach3d`, never replacing it): the
experiment's training (one robot, its 96 goals x 4 passes, one goal-episode an epoch: its cached runs serve it)
against a fleet of 16 (`[run] fleet = 16`, `fleet_goals = "spread"`) walking the same 384 goal-episodes 16 an epoch,
each trained swarm then tested as the experiment tests it: one robot, frozen, on test set A's 100 goals.

    python -m kinswarm.experiments.research fleet_reach3d --seeds 3 --jobs 2 --out runs/full

Measured (3 seeds, set A, within 5 cm; docs/notebook/reach3d.md): one robot 93 / 91 / 94 % (92.7), the fleet 99 / 94
/ 88 % (93.7): the same skill. Time, one training back to back on a quiet machine (single placement, seed 7): one
robot 71.9 s, the fleet 78.4 s: in one process a fleet of this 7-joint arm saves nothing (each robot's Python is the
step's cost; docs/architecture.md "Schema 10").
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np
from kinswarm.experiments import reach3d as r
from kinswarm.experiments.common import Context, Report, pm, run_specs, settings
from kinswarm.experiments.research.fleet_generalise import FleetSpec
from kinswarm.experiments.swarm import Spec
from kinswarm.protocol.robots import load_robot

SEEDS = 3
FLEET = 16


def run(ctx: Context) -> dict[str, Any]:
    topo = load_robot(r.ROBOT)
    steps, n_test = (60, 5) if ctx.quick else (r.STEPS, r.TEST)
    b = 2 if ctx.quick else FLEET
    t_goals, t_starts = r.training_set(topo, False, *r.QUICK_TRAINING if ctx.quick else ())
    task, file = r._task(t_goals, t_starts), str(r.ROBOT)
    train: dict[tuple[str, int], Spec] = {}
    for s in ctx.seed_list:  # the experiment's own training spec first: its cache serves it
        train[("one robot", s)] = Spec(
            "r3d-pt-train-state", seed=s, epochs=len(t_goals), steps=steps, file=file, task=task,
            learner=settings(), checkpoint=True,
        )  # fmt: skip
        train[(f"fleet of {b}", s)] = FleetSpec(
            f"r3d-pt-train-fleet{b}", seed=s, epochs=len(t_goals) // b, steps=steps, file=file, task=task,
            learner=settings(), checkpoint=True, fleet=b, fleet_goals="spread",
        )  # fmt: skip
    started = time.perf_counter()
    trained = dict(zip(train, run_specs(ctx, list(train.values()), "train"), strict=True))
    goals, starts = r.sample(topo, r.SETS["A"], n_test, False)
    common = {"epochs": n_test, "steps": steps, "file": file, "task": r._task(goals, starts)}
    tests = {
        key: Spec(
            "r3d-pt-A-trained" if key[0] == "one robot" else f"r3d-pt-A-fleet{b}",
            seed=key[1],
            learner=settings(),
            from_dir=str(t.out),
            learn=False,
            explore=False,
            **common,
        )  # fmt: skip
        for key, t in trained.items()
    }
    outs = dict(zip(tests, run_specs(ctx, list(tests.values()), "test"), strict=True))
    rep = Report(ctx, "A fleet on the iiwa's points (research)", "beyond the paper (3D, fleets)")
    rep.text(
        "Research, not product. Training: `kinswarm experiment reach3d`'s points (one robot, "
        f"{len(t_goals)} goal-episodes of {steps} steps from random starts, one an epoch), against a fleet of {b} "
        f'(`fleet_goals = "spread"`) walking the same goal-episodes {b} an epoch. Test: one robot, frozen, test set '
        f"A ({n_test} goals), within {r.TOL * 100:.0f} cm. Training wall times are the runs' own (a cached run's from "
        f"when it ran, under other load: compare them only within one sitting). This pass: "
        f"{time.perf_counter() - started:.0f} s of training.",
    )
    results: dict[str, Any] = {}
    rows = []
    for label in ("one robot", f"fleet of {b}"):
        keys = [k for k in outs if k[0] == label]
        within = [100.0 * float(np.mean([e <= r.TOL for e in outs[k].final_errors])) for k in keys]
        means = [float(np.mean(outs[k].final_errors)) for k in keys]
        walls = [float(trained[k].summary.get("wall_seconds", 0.0)) for k in keys]
        results[label] = {"within_pct": within, "mean": means, "train_wall_seconds": walls}
        rows.append([label, pm(within, 1), pm(means), ", ".join(f"{w:.0f}" for w in walls), len(keys)])
    rep.table(["training", f"within {r.TOL * 100:.0f} cm (%)", "mean error (m)", "training wall s", "seeds"], rows)
    rep.results = results
    rep.write({"fleet": b, "steps": steps, "test": n_test}, [*trained.values(), *outs.values()])
    return results
