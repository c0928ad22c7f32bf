"""The grasp epsilon_decay probe of 2026-11-22 (docs/science.md, Grasp): does exploration fading over the epochs
(what made the frozen reaching swarm generalise) make the trained grasp hold frozen? 3 seeds, 30 x 400, the default
reward `shaped`, then each trained swarm frozen (`--learn off --explore off`) for one epoch.

    python docs/probes/grasp_epsilon_decay.py runs/probe 0.1   # ~6 min on 2 cores
"""

import sys
from pathlib import Path

from kinswarm.actors.grasp_report import epoch_quality
from kinswarm.experiments.common import Context, run_specs, settings
from kinswarm.experiments.grasp import GRASP3, _score, frozen_spec
from kinswarm.experiments.swarm import Spec
from kinswarm.protocol.topology import load_topology

if __name__ == "__main__":
    out = Path(sys.argv[1])
    decay = float(sys.argv[2])
    ctx = Context(name="probe", out=out / "probe", runs=out / "runs", seeds=3, quick=False, jobs=2, test_set=0)
    topo = load_topology(GRASP3)
    learner = settings(epsilon_decay=decay)
    base = {"topology": str(GRASP3), "epochs": 30, "steps": 400, "learner": learner}
    specs = [Spec(name=f"grasp-ed-s{s}", seed=s, reward="shaped", checkpoint=True, **base) for s in range(3)]
    outs = run_specs(ctx, specs, "train")
    frozen = [frozen_spec(o, f"grasp-ed-frozen-s{o.spec.seed}") for o in outs]
    fz = run_specs(ctx, frozen, "frozen")
    for o, f in zip(outs, fz, strict=True):
        sc = _score(o, topo)
        q = epoch_quality(f.rows[-1], topo)
        print(
            o.spec.seed,
            "good last20",
            sc["good_share_last"],
            "frozen",
            {k: q[k] for k in ("good", "net_force", "net_torque", "mean_fn")},
        )
