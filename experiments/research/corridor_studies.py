"""The corridor's studies (docs/notebook/corridor.md, studies 1-11): every configuration tried on the way to the
recipe, on the product's machinery (experiments/corridor.py `run_configs`). Its report is
docs/results/research/corridor-studies/; the product's corridor experiment runs only the recipe and the paper.

  kinswarm          the paper's state plus each agent's clearance and refused-move flag, a local collision penalty,
                    slow exploration (s 0.01) fading over the epochs, finer g1, g2 sets
  kinswarm-relaxed  the same on the relaxed set-up (examples/corridor7-relaxed.toml: gap 1.2, target 1.0 deep)
  guided            the same plus the tabu, with the goal distance along the corridor's axis (via)
  follow            guided plus follow-the-leader (40) and gamma 0.97 (study 2)
  settle            follow with the reward `settle` (study 5)
  subtree-200       settle with the clearance of the links each agent moves, 200 epochs (study 6)
  inner-200         subtree-200 with settle_radius 0.15 (study 8): examples/corridor7-inner200.toml
  anneal-260        inner-200 continued 60 epochs with the learning rate annealed to 0 over epochs 200-240 (study 9)
  freeze-260        anneal-260 with the counts frozen from epoch 200 (study 10): examples/corridor7-freeze260.toml
Study 8's `near-200` added the tip's distance to the goal (g_dist) as a state variable: measured, not kept, and
deleted from the code (its numbers are in the committed report).
"""

from __future__ import annotations

import math
from typing import Any

from kinswarm.experiments.common import Context, Report
from kinswarm.experiments.corridor import EVAL_SHIELD, REFERENCE_SEEDS, Config, run_configs
from kinswarm.experiments.swarm import ROOT

SEEDS = 5
TOPOLOGY = ROOT / "examples" / "corridor7.toml"
RELAXED = ROOT / "examples" / "corridor7-relaxed.toml"
GUIDED = ROOT / "examples" / "corridor7-guided.toml"
_PI = math.pi
_REACH = 7.0
#: g1, g2 over [-reach, reach] rather than the default [-2 reach, 2 reach]: finer sets where the goal is
RANGES = ((-_PI, _PI), (-_PI, _PI), (0.0, _REACH), (-_REACH, _REACH), (-_REACH, _REACH), (-_PI, _PI))
_LEARNER: dict[str, Any] = {"s": 0.01, "epsilon_decay": 0.03, "ranges": RANGES}
_SENSE: dict[str, Any] = {"clearance_state": True, "collision_state": True, "collision_penalty": -5.0}
_FOLLOW: dict[str, Any] = {**_SENSE, "collision_tabu": True, "follow_leader": 40.0}
_SUBTREE: dict[str, Any] = {**_FOLLOW, "clearance_of": "subtree"}
_INNER: dict[str, Any] = {**_SUBTREE, "settle_radius": 0.15}
ANNEAL = [200, 240]

STUDIES: dict[str, Config] = {
    "kinswarm": Config(TOPOLOGY, 100, reward="shaped", task=_SENSE, learner=_LEARNER),
    "kinswarm-relaxed": Config(RELAXED, 100, reward="shaped", task=_SENSE, learner=_LEARNER, seeds=REFERENCE_SEEDS),
    "guided": Config(
        GUIDED, 100, reward="shaped", task={**_SENSE, "collision_tabu": True}, learner=_LEARNER, seeds=REFERENCE_SEEDS
    ),
    "follow": Config(GUIDED, 100, reward="shaped", task=_FOLLOW, learner={**_LEARNER, "gamma": 0.97}),
    "settle": Config(GUIDED, 100, reward="settle", task=_FOLLOW, learner={**_LEARNER, "gamma": 0.97}),
    "subtree-200": Config(GUIDED, 200, reward="settle", task=_SUBTREE, learner={**_LEARNER, "gamma": 0.97}),
    "inner-200": Config(GUIDED, 200, reward="settle", task=_INNER, learner={**_LEARNER, "gamma": 0.97}),
    "anneal-260": Config(
        GUIDED,
        60,
        reward="settle",
        task=_INNER,
        learner={**_LEARNER, "gamma": 0.97, "lr_anneal": ANNEAL},
        continues="inner-200",
    ),
    "freeze-260": Config(
        GUIDED,
        60,
        reward="settle",
        task=_INNER,
        learner={**_LEARNER, "gamma": 0.97, "lr_anneal": ANNEAL, "count_freeze": ANNEAL[0]},
        continues="inner-200",
    ),
}


def run(ctx: Context) -> dict[str, Any]:
    rep = Report(ctx, "Corridor studies (research): every configuration tried", "5.4, Fig. 23")
    intro = (
        "## Set-up",
        "",
        "Research, not product: the configurations of the corridor's studies 1-11 (docs/notebook/corridor.md), "
        "each trained on the hard set-up (the relaxed one for `kinswarm-relaxed`), then frozen three ways (plain; "
        f"with the tabu; with the tabu and the shield {EVAL_SHIELD}). The product's corridor experiment runs the "
        "recipe alone.",
    )
    return run_configs(ctx, rep, STUDIES, intro)
