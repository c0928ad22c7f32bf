"""The corridor probes of 2026-11-22 and 23 (docs/science.md, Corridor, rounds 4-7): the `follow`
configuration of `kinswarm experiment corridor` (hard set-up, 100 x 500) with changes, then each trained swarm
frozen (`--learn off --explore off`) for one epoch, with the walls' refusals counted per agent.

    python docs/probes/corridor_probe.py OUT graded 0,2,3,4    # reward graded instead of shaped, ~12 min
    python docs/probes/corridor_probe.py OUT subtree 0,2,3,4   # clearance of the links each agent moves, ~12 min
    python docs/probes/corridor_probe.py OUT long 0,2          # follow unchanged, 200 epochs, ~20 min
    python docs/probes/corridor_probe.py OUT memory 0,2,3,4    # tabu_memory 0.1, ~12 min
    python docs/probes/corridor_probe.py OUT settle 0,2,3,4    # staying within 0.3 of the target pays, ~12 min
    python docs/probes/corridor_probe.py OUT settle+refusal 0,2,3,4  # and the collision term for refusals only
    python docs/probes/corridor_probe.py OUT frozen-memory RUN,RUN,...  # trained runs, frozen with memory
    python docs/probes/corridor_probe.py OUT settle+refusal+long 0,1,2,3,4          # round 6, ~20 min of 2 cores
    python docs/probes/corridor_probe.py OUT settle+refusal+subtree+long 0,1,2,3,4  # round 6
    python docs/probes/corridor_probe.py OUT settle+refusal+subtree+long+fine 0,1,2,3,4  # round 6
    python docs/probes/corridor_probe.py OUT settle+refusal+subtree+long+shield=0.02 0,1,2,3,4  # round 7
    python docs/probes/corridor_probe.py OUT settle+refusal+subtree+long+settle_radius=0.15 0,1,2,3,4  # round 8

frozen-memory trains nothing: it freezes the given training runs of `follow` (run directories of the
experiment's cache, `kinswarm experiment corridor --out DIR`: DIR/runs/corr-follow-*) with tabu_memory 0.1.

Changes combine with "+" (e.g. `memory+subtree`); each combination has a run cache of its own. A change NAME=VALUE
overrides one LearnerSettings field (VALUE in JSON), e.g. `settle+refusal+long+epsilon_decay=0.015`.

graded: shaped's distance gradient inside D_min too (what made the frozen reaching swarm generalise, and the
corridor lies inside D_min: the mouth is 2.5 from the target, D_min = 3).
subtree: each agent senses the smallest clearance of its own link and of every link below it (the links its
joint moves) instead of its own link's only: LearnerSettings.clearance_of = "subtree" (rounds 4-6 patched the
simulator's `Scene.clearances` instead, which gives the agents the same values).
long: `follow` itself trained for 200 epochs instead of 100 (its first 100 epochs are the experiment's runs).
memory: LearnerSettings.tabu_memory = 0.1 (round 5): a refused move stays tabu until the tip moved 0.1, not for
one step only, so a jammed agent tries each way once and then keeps.
settle: the root's reward while the tip stays within 0.3 (reward.SETTLE_RADIUS) of the target (at t - 1 and t) is
e^(-c1 D) whatever the tip did, minus the collision term as in `shaped`. `shaped` pays e^(-c1 D) for an approach,
0 for "keep" and -1 for a step away, so at the target the greedy choice is a step in or out, never "keep", and the
chain jitters against the walls (refusals in the last 100 steps of most epochs that end within 0.3).
fine: g1, g2 (the goal from the tip, in the agent's frame) with 13 sets over [-3.5, 3.5] instead of 7 over [-7, 7]
(set spacing 0.58 instead of 2.33): with `settle` on, most of the epochs that miss end 0.30-0.45 from the target,
a difference the coarse sets hardly show.
refusal: the root's collision term only for a refused move, not for a link closer than 0.1 to a wall (d_safe 0;
the bar counts refusals, and in the epochs that end within 0.3 some link is that close in 4-99 % of the last 100
steps, so sitting at the target pays about -4 there).
"""

import asyncio
import collections
import json
import sys
import tempfile
from pathlib import Path
from typing import Any

from kinswarm.actors import agent
from kinswarm.actors.learning import reward as rewards
from kinswarm.experiments.common import Context, run_specs, settings
from kinswarm.experiments.corridor import CONFIGS, EPOCHS, RANGES, STEPS, seed_metrics
from kinswarm.experiments.swarm import RunOutcome, Spec, _supervise
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Obs
from kinswarm.protocol.topology import load_topology


def probe_reward(D: float, D_prev: float, clearance: float, collisions: int, mode: str, **kw: float) -> float:
    """`settle` and `refusal`: the root's reward (the agent module's corridor_reward) with either change; both
    together are `--reward settle` (the probe patched them in before that reward existed)."""
    d_safe = 0.0 if "refusal" in PARTS else rewards.CORRIDOR_D_SAFE
    return rewards.corridor_reward(
        D, D_prev, clearance, collisions, "settle" if "settle" in PARTS else mode, d_safe=d_safe, **kw
    )


CHANGES = ("graded", "subtree", "long", "memory", "settle", "refusal", "fine", "frozen-memory")
FINE_RANGES = (*RANGES[:3], (-3.5, 3.5), (-3.5, 3.5), RANGES[5])
VARIANT = sys.argv[2] if len(sys.argv) > 2 else ""
PARTS = {p for p in VARIANT.split("+") if "=" not in p}
OVERRIDES = {k: json.loads(v) for k, v in (p.split("=", 1) for p in VARIANT.split("+") if "=" in p)}
EVAL = "frozen-memory" in PARTS
if PARTS & {"settle", "refusal"}:
    agent.corridor_reward = probe_reward  # type: ignore[assignment]


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
    if len(sys.argv) != 4 or not PARTS <= set(CHANGES):
        raise SystemExit(
            f"usage: corridor_probe.py OUT CHANGE[+CHANGE...] SEEDS (e.g. 0,2,3,4); CHANGE: {CHANGES} or FIELD=VALUE"
        )
    settings(**OVERRIDES)  # a wrong field or value fails here, before any run
    out, args = Path(sys.argv[1]), sys.argv[3].split(",")
    seeds = [json.loads((Path(a) / "config.json").read_text())["seed"] for a in args] if EVAL else [*map(int, args)]
    reward, over, topology = CONFIGS["follow"]
    reward = "graded" if "graded" in PARTS else reward
    over = {**over, "tabu_memory": 0.1} if "memory" in PARTS else over
    over = {**over, "clearance_of": "subtree"} if "subtree" in PARTS else over
    if "fine" in PARTS:
        over = {**over, "n_sets": (20, 20, 13, 13, 13, 7), "ranges": FINE_RANGES}
    over = {**over, **OVERRIDES}
    # a cache of its own per variant: the reward patches are not in a run's identity
    runs = out / f"runs-{VARIANT}"
    ctx = Context(name="probe", out=out / "probe", runs=runs, seeds=len(seeds), quick=False, jobs=2, test_set=0)
    common: dict[str, Any] = {"steps": STEPS, "reward": reward, "learner": settings(**over), "topology": str(topology)}
    epochs = 2 * EPOCHS if "long" in PARTS else EPOCHS
    specs = [Spec(f"corr4-{VARIANT}", seed=s, epochs=epochs, checkpoint=True, **common) for s in seeds]
    if EVAL:  # the given runs as they are (their metrics rows for seed_metrics)
        trained = [
            RunOutcome(s, Path(a).resolve(), {}, [json.loads(line) for line in (Path(a) / "metrics.jsonl").open()])
            for s, a in zip(specs, args, strict=True)
        ]
    else:
        trained = run_specs(ctx, specs, "train")
    frozen_specs = [
        Spec(
            f"corr4-{VARIANT}-frozen",
            seed=o.spec.seed,
            epochs=1,
            from_dir=str(o.out),
            learn=False,
            explore=False,
            **{**common, "learner": settings(**{**over, "tabu_memory": 0.1})} if EVAL else common,
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
