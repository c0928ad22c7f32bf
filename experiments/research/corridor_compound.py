"""Research (docs/notebook/corridor.md, studies 12-15): the corridor's compound refusals, taught in the recipe's
second stage. Each probe continues the product's `inner-200` swarms (the run cache of `kinswarm experiment corridor`)
as examples/corridor7-freeze260.toml does (lr annealed to 0 over 200-240, counts frozen from 200, 60 epochs), with a
setting of the corridor task added or changed:

  freeze-260     the product's second stage without the blame (the control)
  blame          + blame_penalty -5: an agent that moved while a move below it was refused pays too (the recipe's,
                 examples/corridor7-blame260.toml; run on 10 seeds to confirm)
  blame-10, -20  both penalties (collision, blame) at -10 or -20
  blame-notabu   the blame with the tabu off in training, so the lr-0 epochs are the frozen epoch
  blame-polish   100 epochs: full rate with the counts frozen to 240, then the anneal over 240-280
  long-400, long-400-blame   the recipe's two stages with a first stage of 400 epochs (the second over 400-460);
                 long-800, long-800-blame the same with 800
  via-left-200, via-left-blame   the recipe's two stages with the via at (1, 2), 1 further left (study 14)
  blame-200, blame-200-blame; blame-400, blame-400-blame   the recipe's two stages (a first stage of 200 or 400
                 epochs) with the blame from epoch 0 (study 14); blame10-200, blame10-200-blame the same with both
                 penalties at -10; blame-400-notabu   blame-400-blame with no tabu in the second stage
  swing-200, swing-200-blame   the recipe's two stages with swing_margin 0.1 from epoch 0: outside D_min (the swing
                 down to the mouth) a link within 0.1 of a wall costs the root's reward what a refusal does (study 15);
                 swing-400, swing-400-blame the same with a first stage of 400 epochs; swing25-200,
                 swing25-200-blame with a margin of 0.25
  relaxed-200, relaxed-blame   the recipe's two stages at the relaxed set-up (walls 1.2 apart, target 1.0 deep:
                 examples/corridor7-relaxed-swing200.toml and -swing260.toml with swing_margin 0);
                 relaxed-swing-200, relaxed-swing-blame the same with swing_margin 0.1 (study 15);
                 relaxed-swing25-200, relaxed-swing25-blame with 0.25 (the example files as they are: the same
                 runs as the experiment's relaxed-margin-200 and -260)
  shallow-swing25-200, -blame   swing25's two stages with the hard set-up's walls (0.8 apart) and the target 1.0 deep;
  relaxed-deep-swing25-200, -blame   with the relaxed walls (1.2 apart) and the target 2.5 deep (study 15)

  CORRIDOR_PROBES=blame python -m kinswarm.experiments.research corridor_compound --seeds 10 --jobs 2 --out runs/full
(CORRIDOR_PROBES: a comma-separated subset, run with the configurations they continue; unset, all of them.) Study 12
also measured a graded near-wall penalty, study 13 a reading of the wall's direction (`approach_state`, with a
penalty for moves towards a near wall, and a stage of short epochs for the swing), study 14 `forfeit_progress` (a step
with a refused move pays no progress): not kept, deleted from the code (commits 0f900da and 4cd4fa6 have them);
their numbers stay in the notebook.
"""

from __future__ import annotations

import dataclasses
import os
from typing import Any

from kinswarm.experiments.common import Context, Report
from kinswarm.experiments.corridor import CONFIGS, RECIPE, RELAXED1, RELAXED2, STAGE1, STAGE2, Config, run_configs

SEEDS = 5
CONFIRM = 10  # the configurations run on 5 more seeds (--seeds 10) to confirm what seeds 0-4 showed
NO_MARGIN = {"swing_margin": 0.0}  # the relaxed recipe's files without their swing margin: study 13's relaxed set-up


def _stage2(text: str, epochs: int = 60, learner: dict[str, Any] | None = None, **task: Any) -> Config:
    return Config(STAGE2, epochs, task=task, learner=learner or {}, continues="inner-200", text=text)


def _long(n: int, prefix: str = "long", **task: Any) -> dict[str, Config]:
    """The recipe's two stages with a first stage of n epochs: `{prefix}-n`, and `{prefix}-n-blame` on its swarms;
    `task`: set over both stages."""
    also = f" with {task}" if task else ""
    first = Config(STAGE1, n, task=task, seeds=CONFIRM, text=f"the recipe's first stage trained {n} epochs{also}")
    second = Config(
        RECIPE,
        60,
        task=task,
        learner={"lr_anneal": [n, n + 40], "count_freeze": n},
        continues=f"{prefix}-{n}",
        seeds=CONFIRM,
        text=f"blame-260's second stage on {prefix}-{n} (lr annealed over {n}-{n + 40}, counts frozen at {n})",
    )
    return {f"{prefix}-{n}": first, f"{prefix}-{n}-blame": second}


def _relaxed(prefix: str, **task: Any) -> dict[str, Config]:
    """The relaxed recipe's two stages (its example files) with `task` set over both, the margin off unless `task`
    sets it: `relaxed-{prefix}-200` and `relaxed-{prefix}-blame`."""
    task = {**NO_MARGIN, **task}
    first = Config(RELAXED1, 200, task=task, seeds=CONFIRM, text=f"relaxed-200 with {task}")
    second = Config(
        RELAXED2, 60, task=task, continues=f"relaxed-{prefix}-200", seeds=CONFIRM, text=f"relaxed-blame with {task}"
    )
    return {f"relaxed-{prefix}-200": first, f"relaxed-{prefix}-blame": second}


PROBES: dict[str, Config] = {
    "inner-200": dataclasses.replace(CONFIGS["inner-200"], seeds=CONFIRM),
    "freeze-260": CONFIGS["freeze-260"],
    "blame": dataclasses.replace(_stage2("freeze-260 + blame_penalty -5", blame_penalty=-5.0), seeds=CONFIRM),
    "blame-10": _stage2("blame, both penalties -10", collision_penalty=-10.0, blame_penalty=-10.0),
    "blame-20": _stage2("blame, both penalties -20", collision_penalty=-20.0, blame_penalty=-20.0),
    "blame-notabu": _stage2("blame, no tabu in training", blame_penalty=-5.0, collision_tabu=False),
    "blame-polish": _stage2(
        "blame, 100 epochs: counts frozen from 200, full rate to 240, annealed over 240-280",
        100,
        {"lr_anneal": [240, 280]},
        blame_penalty=-5.0,
    ),
    **_long(400),
    **_long(800),
    # the first stage changed, the second stage the recipe's (blame-260) on its swarms
    "via-left-200": Config(STAGE1, 200, task={"via": [1.0, 2.0]}, text="inner-200 with the via 1 further left"),
    "via-left-blame": Config(
        RECIPE, 60, task={"via": [1.0, 2.0]}, continues="via-left-200", text="blame-260 on via-left-200"
    ),
    **_long(200, "blame", blame_penalty=-5.0),  # the blame from epoch 0
    **_long(400, "blame", blame_penalty=-5.0),
    **_long(200, "blame10", blame_penalty=-10.0, collision_penalty=-10.0),  # both penalties -10 from epoch 0
    **_long(200, "swing", swing_margin=0.1),  # outside D_min a link within 0.1 of a wall costs as a refusal
    **_long(400, "swing", swing_margin=0.1),
    **_long(200, "swing25", swing_margin=0.25),  # a margin as wide as the clearance's sets are apart
    "blame-400-notabu": dataclasses.replace(
        _long(400, "blame", blame_penalty=-5.0)["blame-400-blame"],
        task={"blame_penalty": -5.0, "collision_tabu": False},
        text="blame-400-blame with no tabu in the second stage, so its lr-0 epochs are the frozen epoch",
    ),
    "relaxed-200": Config(
        RELAXED1, 200, task=NO_MARGIN, seeds=CONFIRM, text="inner-200 at the relaxed set-up (the margin off)"
    ),
    "relaxed-blame": Config(
        RELAXED2, 60, task=NO_MARGIN, continues="relaxed-200", seeds=CONFIRM, text="blame-260 at the relaxed set-up"
    ),
    **_relaxed("swing", swing_margin=0.1),
    **_relaxed("swing25", swing_margin=0.25),
    # which of the hard set-up's two differences from the relaxed one the margin does not get past (study 15)
    **_long(200, "shallow-swing25", goal=[4.0, 2.0], swing_margin=0.25),  # walls 0.8 apart, the target 1.0 deep
    **_relaxed("deep-swing25", goal=[5.5, 2.0], swing_margin=0.25),  # walls 1.2 apart, the target 2.5 deep
}


def run(ctx: Context) -> dict[str, Any]:
    only = os.environ.get("CORRIDOR_PROBES")  # a comma-separated subset (with the configurations they continue)
    chosen = set(only.split(",")) if only else set(PROBES)
    if unknown := chosen - set(PROBES):
        raise ValueError(f"CORRIDOR_PROBES: no probe {', '.join(sorted(unknown))}; the probes: {', '.join(PROBES)}")
    while bases := {c.continues for k, c in PROBES.items() if k in chosen} - {None} - chosen:
        chosen |= bases  # type: ignore[arg-type]  # a continuation runs with the swarms it continues
    configs = {k: c for k, c in PROBES.items() if k in chosen}
    rep = Report(ctx, "Corridor: compound refusals in the second stage (research)", "5.4, Fig. 23")
    intro = ("## Set-up", "", "Research, not product: " + "; ".join(f"`{k}`: {c.text}" for k, c in configs.items()))
    return run_configs(ctx, rep, configs, intro)
