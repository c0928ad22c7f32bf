"""Research (docs/notebook/corridor.md, study 12): the corridor's compound refusals, taught in the recipe's second
stage. Each probe continues the product's `inner-200` swarms (the run cache of `kinswarm experiment corridor`) for 60
epochs as examples/corridor7-freeze260.toml does (lr annealed to 0 over 200-240, counts frozen from 200), with a
setting of the corridor task added:

  freeze-260   the product's second stage as it is (the control)
  blame        + blame_penalty: an agent that moved while a move below it was refused pays it too

  CORRIDOR_PROBES=blame python -m kinswarm.experiments.research corridor_compound --seeds 3 --jobs 1 --out runs/full
(CORRIDOR_PROBES: a comma-separated subset; unset, all of them.) Study 12 also measured a graded near-wall penalty
below a margin of the sensed clearance (-2 below 0.05): worse than the control, deleted from the code.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

from kinswarm.experiments.common import Context, Report
from kinswarm.experiments.corridor import CONFIGS, RECIPE, STAGE1, STAGE2, Config, run_configs

SEEDS = 5
CONFIRM = 10  # the configurations run on 5 more seeds (--seeds 10) to confirm what seeds 0-4 showed


def _stage2(
    text: str, epochs: int = 60, learner: dict[str, Any] | None = None, on: str = "inner-200", **task: Any
) -> Config:
    return Config(STAGE2, epochs, task=task, learner=learner or {}, continues=on, text=text)


APPROACH = {"approach_state": True}
HERE = Path(__file__).parent


PROBES: dict[str, Config] = {
    "inner-200": dataclasses.replace(CONFIGS["inner-200"], seeds=CONFIRM),
    "freeze-260": CONFIGS["freeze-260"],
    "blame": dataclasses.replace(_stage2("freeze-260 + blame_penalty -5", blame_penalty=-5.0), seeds=CONFIRM),
    "blame-polish": _stage2(
        "blame, 100 epochs: counts frozen from 200, full rate to 240, annealed over 240-280",
        100,
        {"lr_anneal": [240, 280]},
        blame_penalty=-5.0,
    ),
    "blame-10": _stage2("blame, both penalties -10", collision_penalty=-10.0, blame_penalty=-10.0),
    "blame-20": _stage2("blame, both penalties -20", collision_penalty=-20.0, blame_penalty=-20.0),
    "blame-notabu": _stage2("blame, no tabu in training", blame_penalty=-5.0, collision_tabu=False),
    "approach-200": Config(STAGE1, 200, task=APPROACH, seeds=CONFIRM, text="inner-200 + approach_state"),
    "approach-blame": Config(
        RECIPE, 60, task=APPROACH, continues="approach-200", seeds=CONFIRM, text="blame-260 on approach-200"
    ),
    "approach-freeze": dataclasses.replace(
        _stage2("freeze-260 on approach-200", on="approach-200", **APPROACH), seeds=CONFIRM
    ),
    "approach-c20": _stage2(
        "freeze-260, collision_penalty -20, on approach-200", on="approach-200", **APPROACH, collision_penalty=-20.0
    ),
    "approach-blame20": dataclasses.replace(
        _stage2(
            "blame-20 on approach-200", on="approach-200", **APPROACH, collision_penalty=-20.0, blame_penalty=-20.0
        ),
        seeds=CONFIRM,
    ),
    "approach-swing": Config(
        STAGE1,
        150,
        task={**APPROACH, "collision_penalty": -20.0, "blame_penalty": -20.0},
        steps=60,
        continues="approach-200",
        text="approach-200 trained on for 150 epochs of 60 steps (the swing past the wall), both penalties -20",
    ),
    "approach-swing-anneal": Config(
        STAGE2,
        60,
        task={**APPROACH, "collision_penalty": -20.0, "blame_penalty": -20.0},
        learner={"lr_anneal": [350, 390], "count_freeze": 350},
        continues="approach-swing",
        text="approach-swing, then blame-20's anneal over full epochs (lr to 0 over 350-390, counts frozen at 350)",
    ),
    "near-200": Config(
        STAGE1,
        200,
        task={**APPROACH, "approach_penalty": -5.0},
        text="approach-200 + approach_penalty -5 (a move towards a wall within 0.1)",
    ),
    "near-blame20": _stage2(
        "blame-20 on near-200",
        on="near-200",
        **APPROACH,
        approach_penalty=-5.0,
        collision_penalty=-20.0,
        blame_penalty=-20.0,
    ),
    "relaxed-200": Config(HERE / "corridor7-relaxed-inner200.toml", 200, text="inner-200 at the relaxed set-up"),
    "relaxed-blame": Config(
        HERE / "corridor7-relaxed-blame260.toml", 60, continues="relaxed-200", text="blame-260 at the relaxed set-up"
    ),
    "approach-c20-200": Config(
        STAGE1, 200, task={**APPROACH, "collision_penalty": -20.0}, text="approach-200 with collision_penalty -20"
    ),
}


def run(ctx: Context) -> dict[str, Any]:
    only = os.environ.get("CORRIDOR_PROBES")  # a comma-separated subset (with the configurations they continue)
    chosen = set(only.split(",")) if only else set(PROBES)
    while bases := {c.continues for k, c in PROBES.items() if k in chosen} - {None} - chosen:
        chosen |= bases  # type: ignore[arg-type]  # a continuation runs with the swarms it continues
    configs = {k: c for k, c in PROBES.items() if k in chosen}
    rep = Report(ctx, "Corridor: compound refusals in the second stage (research)", "5.4, Fig. 23")
    intro = ("## Set-up", "", "Research, not product: " + "; ".join(f"`{k}`: {c.text}" for k, c in configs.items()))
    return run_configs(ctx, rep, configs, intro)
