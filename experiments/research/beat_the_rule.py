"""A frozen skill that beats the rule (research): the recommended reaching learner, trained on Level-3 and frozen,
against the hand-written rule on g_perp (`kinswarm baseline --law rule`) on the generalisation report's test sets
0 and 1, with what might get it there — finer sets on g_perp, the variable the rule acts on. Each row is trained
and tested as the generalisation report's Level-3 (128 epochs, frozen, each test goal from the start pose).

    python -m kinswarm.experiments.research beat_the_rule --seeds 3 --jobs 2 --out runs/full

Measured (3 seeds, 307 s on the generalisation report's cache; docs/results/research/beat-the-rule/): none beats
the rule (0.133 / 0.171 on test sets 0 / 1, 98 % / 96 % within 0.5). The recommended learner 0.168 / 0.276 (its 6
seeds in the generalisation report: 0.149 / 0.191); g_perp in 11 sets over ±1.5: 0.754 / 0.684, worse; in 9 sets
over ±0.75: 0.218 / 0.192 (97 % / 97 %), nearer on set 1, not below. Not tried: training from varied poses (the
successive-training study went the wrong way), more epochs.
"""

from __future__ import annotations

import json
from typing import Any

from kinswarm.actors.learning.settings import StateVariable
from kinswarm.experiments import generalisation as g
from kinswarm.experiments.common import Context, settings

SEEDS = 3
# (label, g_perp's sets and range): the recommended 7 over ±1.5, then finer
VARIANTS = {
    "Level-3 (the recommended learner)": (7, 1.5),
    "g_perp 11 sets over ±1.5": (11, 1.5),
    "g_perp 9 sets over ±0.75": (9, 0.75),
}


def learner_with(sets: int, half: float) -> tuple:
    base = dict(g.LEARNER)
    base["extra_state"] = (StateVariable("g_perp", sets, (-half, half)),)
    return settings(**base)


def run(ctx: Context) -> dict[str, Any]:
    rows = [
        g.Training(label, 3 if not ctx.quick else 1, (g.REPS * 4**3) if not ctx.quick else 4, learner_with(n, h))
        for label, (n, h) in VARIANTS.items()
    ]
    tested = g.train_and_test(ctx, rows, second_level=1, with_scratch=False)
    rule = tested.references["rule on g_perp"]
    out: dict[str, Any] = {
        "rule": {b: {"mean": e["mean"], "within_0_5": e["frac_within_0_5"]} for b, e in rule.items()}
    }
    print(f"{'':36}{'test set':>9}{'mean':>8}{'within 0.5':>12}")
    for b, e in sorted(rule.items()):
        print(f"{'rule on g_perp (no learning)':36}{b[-1]:>9}{e['mean']:8.3f}{100 * e['frac_within_0_5']:11.0f}%")
    for row in rows:
        for b, e in sorted(tested.per[row.label].items()):
            out.setdefault(row.label, {})[b] = {
                "mean": e["mean"],
                "mean_std_over_seeds": e["mean_std_over_seeds"],
                "within_0_5": e["frac_within_0_5"],
                "per_seed": [round(p["mean"], 3) for p in e["per_seed"]],
            }
            beats = "beats the rule" if e["mean"] < rule[b]["mean"] else "does not"
            print(f"{row.label:36}{b[-1]:>9}{e['mean']:8.3f}{100 * e['frac_within_0_5']:11.0f}%   {beats}")
    ctx.out.mkdir(parents=True, exist_ok=True)
    (ctx.out / "results.json").write_text(json.dumps(out, indent=1) + "\n")
    return out
