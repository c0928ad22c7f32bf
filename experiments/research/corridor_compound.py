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

import os
from typing import Any

from kinswarm.experiments.common import Context, Report
from kinswarm.experiments.corridor import CONFIGS, STAGE2, Config, run_configs

SEEDS = 5


def _stage2(text: str, **task: Any) -> Config:
    return Config(STAGE2, 60, task=task, continues="inner-200", text=text)


PROBES: dict[str, Config] = {
    "inner-200": CONFIGS["inner-200"],
    "freeze-260": CONFIGS["freeze-260"],
    "blame": _stage2("freeze-260 + blame_penalty -5", blame_penalty=-5.0),
}


def run(ctx: Context) -> dict[str, Any]:
    only = os.environ.get("CORRIDOR_PROBES")  # a comma-separated subset (inner-200, their base, always runs)
    configs = {k: c for k, c in PROBES.items() if not only or k in only.split(",") or k == "inner-200"}
    rep = Report(ctx, "Corridor: compound refusals in the second stage (research)", "5.4, Fig. 23")
    intro = ("## Set-up", "", "Research, not product: " + "; ".join(f"`{k}`: {c.text}" for k, c in configs.items()))
    return run_configs(ctx, rep, configs, intro)
