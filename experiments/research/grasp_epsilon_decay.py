"""Exploration fading over the epochs on the grasp (docs/notebook/grasp.md): does epsilon_decay, which made the
frozen reaching swarm generalise, make the trained grasp hold frozen? 3 seeds, 30 x 400, the reward `shaped`, each
trained swarm then frozen for one epoch. Measured with epsilon_decay 0.1: training 90-100 % good, frozen still 0 of 3
(|F| 1.1-6.6). Not kept.
"""

from __future__ import annotations

import json
from typing import Any

from kinswarm.actors.report.grasp import epoch_quality
from kinswarm.experiments.common import Context, run_specs, settings
from kinswarm.experiments.grasp import GRASP3, _score, frozen_spec
from kinswarm.experiments.swarm import Spec, resolved

SEEDS = 3
DECAY = 0.1


def run(ctx: Context) -> dict[str, Any]:
    cfg = resolved(GRASP3)
    topo, obj = cfg.topo(), cfg.scene_spec.object
    epochs, steps = (2, 60) if ctx.quick else (30, 400)
    base = {"file": str(GRASP3), "epochs": epochs, "steps": steps, "learner": settings(epsilon_decay=DECAY)}
    specs = [Spec(name=f"grasp-ed-s{s}", seed=s, reward="shaped", checkpoint=True, **base) for s in ctx.seed_list]
    outs = run_specs(ctx, specs, "train")
    frozen = run_specs(ctx, [frozen_spec(o, f"grasp-ed-frozen-s{o.spec.seed}") for o in outs], "frozen")
    out: dict[str, Any] = {}
    for o, f in zip(outs, frozen, strict=True):
        q = epoch_quality(f.rows[-1], topo, obj)
        out[str(o.spec.seed)] = {
            "good_last20": _score(o, topo, obj)["good_share_last"],
            "frozen": {k: q[k] for k in ("good", "net_force", "net_torque", "mean_fn")},
        }
        print(o.spec.seed, out[str(o.spec.seed)])
    ctx.out.mkdir(parents=True, exist_ok=True)
    (ctx.out / "results.json").write_text(json.dumps(out, indent=1) + "\n")
    return out
