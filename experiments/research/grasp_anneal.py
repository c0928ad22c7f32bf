"""Research (docs/notebook/grasp.md, study 5): train the table the frozen grasp runs. Studies 3-4 found the sensed
recipe's skill held by the TD updates within the epoch (lr 0.5: a finger whose move did badly changes its choice at
the next step) and a greedy approach never practised (exploration through the first 20-40 steps of every epoch).
Each probe trains examples/grasp3-sensed.toml longer, with one of the reach and corridor recipes' tools set over it,
then replays each swarm frozen (`--learn off --explore off`) for one epoch:

  long       90 epochs, nothing else (the control: study 4 measured it, 0 of 5 frozen)
  fade       + epsilon_decay: exploration fades over the epochs, so the late epochs practise the greedy approach
  anneal     + fade + lr annealed to 0 over the last epochs and the fictitious-play counts frozen as it starts, so
             the last epochs run the table the frozen swarm runs
  anneal-120 the same over 120 epochs: 60 at the full rate, the anneal over 60-100
  anneal-independent  anneal with independent learners (no model of the children, so no counts to freeze)

  GRASP_PROBES=fade,anneal python -m kinswarm.experiments.research grasp_anneal --seeds 5 --jobs 2 --out runs/g59
(GRASP_PROBES: a comma-separated subset; unset, all of them.)
"""

from __future__ import annotations

import json
import os
from typing import Any

from kinswarm.actors.report.grasp import epoch_quality
from kinswarm.experiments.common import Context, run_specs, settings
from kinswarm.experiments.grasp import SENSED, _score, frozen_spec
from kinswarm.experiments.swarm import Spec, resolved

SEEDS = 5
STEPS = 400
# name: (epochs, the learner's settings over the recipe file's, which carries `anneal` since study 5: every probe
# sets all three, so it runs what it ran before the file changed)
OFF = {"epsilon_decay": 0.0, "lr_anneal": (0, 0), "count_freeze": 0}
ANNEAL = {"epsilon_decay": 0.05, "lr_anneal": (50, 80), "count_freeze": 50}
PROBES: dict[str, tuple[int, dict[str, Any]]] = {
    "long": (90, OFF),
    "fade": (90, {**OFF, "epsilon_decay": 0.05}),
    "anneal": (90, ANNEAL),
    "anneal-120": (120, {"epsilon_decay": 0.05, "lr_anneal": (60, 100), "count_freeze": 60}),
    "anneal-independent": (90, {**ANNEAL, "kind": "independent", "count_freeze": 0}),
}
QUICK_EPOCHS, QUICK_STEPS = 4, 60
QUICK_ANNEAL = {"lr_anneal": (1, 3)}


def run(ctx: Context) -> dict[str, Any]:
    cfg = resolved(SENSED)
    topo, obj = cfg.topo(), cfg.scene_spec.object
    steps = QUICK_STEPS if ctx.quick else STEPS
    only = os.environ.get("GRASP_PROBES")
    probes = {k: v for k, v in PROBES.items() if not only or k in only.split(",")}
    specs = []
    for name, (epochs, learner) in probes.items():
        if ctx.quick:
            epochs, learner = QUICK_EPOCHS, {**learner}
            if learner.get("lr_anneal", (0, 0)) != (0, 0):
                learner.update(QUICK_ANNEAL, count_freeze=1 if learner.get("count_freeze") else 0)
        for s in ctx.seed_list:
            specs.append(
                Spec(
                    name=f"grasp-{name}-s{s}",
                    seed=s,
                    file=str(SENSED),
                    epochs=epochs,
                    steps=steps,
                    learner=settings(**learner),
                    checkpoint=True,
                )
            )
    outs = run_specs(ctx, specs, "train")
    frozen = run_specs(ctx, [frozen_spec(o, f"{o.spec.name}-frozen") for o in outs], "frozen")
    out: dict[str, Any] = {}
    for o, f in zip(outs, frozen, strict=True):
        q = epoch_quality(f.rows[-1], topo, obj)
        name = o.spec.name.rsplit("-s", 1)[0].removeprefix("grasp-")
        row = {
            "good_last20": _score(o, topo, obj)["good_share_last"],
            "frozen": {k: q[k] for k in ("good", "good_tail_share", "net_force", "net_torque", "mean_fn")},
        }
        out.setdefault(name, {})[str(o.spec.seed)] = row
        print(name, o.spec.seed, row, flush=True)
    ctx.out.mkdir(parents=True, exist_ok=True)
    (ctx.out / "results.json").write_text(json.dumps(out, indent=1) + "\n")
    return out
