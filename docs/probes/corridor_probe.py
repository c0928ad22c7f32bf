"""The corridor probes of 2026-11-22 (docs/science.md, Corridor, round 4): the `follow` configuration of
`kinswarm experiment corridor` (hard set-up, 100 x 500) with one change, then each trained swarm frozen
(`--learn off --explore off`) for one epoch, with the walls' refusals counted per agent.

    python docs/probes/corridor_round4.py OUT graded 0,2,3,4    # reward graded instead of shaped, ~12 min
    python docs/probes/corridor_round4.py OUT subtree 0,2,3,4   # clearance of the links each agent moves, ~12 min
    python docs/probes/corridor_round4.py OUT long 0,2           # follow unchanged, 200 epochs, ~20 min

graded: shaped's distance gradient inside D_min too (what made the frozen reaching swarm generalise, and the
corridor lies inside D_min: the mouth is 2.5 from the target, D_min = 3).
subtree: each agent senses the smallest clearance of its own link and of every link below it (the links its
joint moves) instead of its own link's only. The simulator computes it here, patched into `Scene.clearances`
(the walls' refusals do not change: a penetration anywhere still shows as a negative value somewhere).
long: `follow` itself trained for 200 epochs instead of 100 (its first 100 epochs are the experiment's runs).
"""

import asyncio
import collections
import sys
import tempfile
from pathlib import Path
from typing import Any

from kinswarm.experiments.common import Context, run_specs, settings
from kinswarm.experiments.corridor import CONFIGS, EPOCHS, STEPS, seed_metrics
from kinswarm.experiments.swarm import RunOutcome, Spec, _supervise
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Obs
from kinswarm.protocol.topology import load_topology
from kinswarm.sim import obstacles

_own_clearances = obstacles.Scene.clearances


def subtree_clearances(self: obstacles.Scene) -> dict[str, float]:
    own = _own_clearances(self)
    agents = self.world.topo.agents
    out = {}
    for a in own:
        stack, best = [a], own[a]
        while stack:
            c = stack.pop()
            best = min(best, own.get(c, best))
            stack.extend(agents[c].children)
        out[a] = best
    return out


VARIANT = next((v for v in ("graded", "subtree", "long") if v in sys.argv[2:3]), "")
if VARIANT == "subtree":  # at import: spawned workers import this file too
    obstacles.Scene.clearances = subtree_clearances


def refusals_by_agent(frozen: Spec) -> dict[str, list[int]]:
    """Rerun a frozen spec with an observer of the simulator's Obs: per agent, its refused moves per 100 steps.
    An Obs reports the refusals of the step before it, so the epoch's last move is not counted here."""
    with tempfile.TemporaryDirectory() as d:
        cfg = frozen.config(Path(d))
        _, captured = asyncio.run(_supervise(cfg, load_topology(cfg.topology), None, True))
    prefix = Keys(cfg.run_id).obs("")
    counts: dict[str, list[int]] = collections.defaultdict(lambda: [0] * (STEPS // 100))
    for key, payload in captured:
        if key.startswith(prefix):
            m = codec.decode(payload, Obs, cfg.run_id, cfg.key)
            counts[key[len(prefix) :]][m.step // 100] += m.collided
    return dict(sorted(counts.items()))


if __name__ == "__main__":
    if not VARIANT or len(sys.argv) != 4:
        raise SystemExit("usage: corridor_round4.py OUT graded|subtree|long SEEDS (e.g. 0,2,3,4)")
    out, seeds = Path(sys.argv[1]), [int(s) for s in sys.argv[3].split(",")]
    reward, over, topology = CONFIGS["follow"]
    reward = "graded" if VARIANT == "graded" else reward
    # a cache of its own per variant: `subtree` is not in a run's identity (a patch, not a setting)
    runs = out / f"runs-{VARIANT}"
    ctx = Context(name="probe", out=out / "probe", runs=runs, seeds=len(seeds), quick=False, jobs=2, test_set=0)
    common: dict[str, Any] = {"steps": STEPS, "reward": reward, "learner": settings(**over), "topology": str(topology)}
    epochs = 2 * EPOCHS if VARIANT == "long" else EPOCHS
    specs = [Spec(f"corr4-{VARIANT}", seed=s, epochs=epochs, checkpoint=True, **common) for s in seeds]
    trained: list[RunOutcome] = run_specs(ctx, specs, "train")
    frozen_specs = [
        Spec(
            f"corr4-{VARIANT}-frozen",
            seed=o.spec.seed,
            epochs=1,
            from_dir=str(o.out),
            learn=False,
            explore=False,
            **common,
        )
        for o in trained
    ]
    frozen = run_specs(ctx, frozen_specs, "frozen")
    keys = ("success_last", "within_last", "median_final_last", "collisions_per_epoch_last", "frozen_final_error")
    for o, f, fs in zip(trained, frozen, frozen_specs, strict=True):
        m = seed_metrics(o, f, f)
        print(
            VARIANT, "seed", o.spec.seed, {k: round(m[k], 3) for k in keys}, "frozen collisions", m["frozen_collisions"]
        )
        print("  frozen refusals per 100 steps, by agent:", refusals_by_agent(fs))
