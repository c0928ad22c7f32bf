"""What does the joint action model (JASM, by fictitious play) buy where agents must coordinate? (research)

The paper argues that its joint action selection matters where agents must coordinate; on chain4's reach it showed no
measurable gain over independent learners (docs/results/peers, research/curves). A tree is where joints pull against
each other: examples/tree5.toml's two 2-link branches on one base joint must place the leaves' centroid together, and
one branch's move undoes the other's. Here the three learner kinds on the same seeds, goals and protocol:

  fuzzy        the paper's learner: fuzzy Q-learning with the JASM over the children's actions (the default kind)
  independent  the same fuzzy Q-learning, each agent's Q over its own actions only (no JASM)
  tabular      the JASM over a plain Q-table on the same grid (no fuzzy interpolation)

Protocol: §5.2's generalisation (the learner and reward of experiments/generalisation/protocol.py), Level-3's 64
quad-tree goals twice each (128 epochs of 500 steps, `inprocess`), then frozen (learning and exploration off) on the
first 50 unseen Halton goals of test set 0, 200 steps each from home. tree5 is written with links of 4 (its
centroid reaches 4 + 8 cos 30° = 10.9 from the base; chain4's tip reaches 12), so §5.2's goal square (half 8) and
tolerance (0.5) mean what they mean on chain4, which runs beside it as the reference. Controls on the same goals: the
swarm untrained (a zero Q, frozen) and the rule on g_perp (no learning, no model). The corridor and the grasp, the
other tasks where agents must coordinate, carry the same three rows in their own reports.

    python -m kinswarm.experiments.research coordination --seeds 5 --jobs 1 --out runs/research   # ~25 CPU-min
"""

from __future__ import annotations

import math
import statistics
from pathlib import Path
from typing import Any

from kinswarm.experiments.arms import run_file
from kinswarm.experiments.common import Context, Report, frac_within, plt_module
from kinswarm.experiments.generalisation.protocol import EVAL_STEPS, LEARNER, LEARNER_TEXT, REPS, REWARD
from kinswarm.experiments.goals import halton, quadtree, training_order
from kinswarm.experiments.research.learning_scale import run_timed
from kinswarm.experiments.swarm import CHAIN4, RunOutcome, Spec, learner_overrides

SEEDS = 5
TEST = 50  # the first goals of the test set, as learning_scale
LEVEL = 3
TOL = 0.5
KINDS = {
    "fuzzy": "fuzzy, JASM (the paper's)",
    "independent": "independent (no JASM)",
    "tabular": "tabular (JASM, no fuzzy interpolation)",
}
TREE5_LINK = 4.0


def tree5_file(path: Path) -> Path:
    """examples/tree5.toml with links of TREE5_LINK (the example's are 2: its centroid would reach 5.5, inside §5.2's
    goal square of half 8)."""
    text = (CHAIN4.parent / "tree5.toml").read_text()
    old = "link_length = 2.0"
    assert old in text, "examples/tree5.toml: its [robot.defaults] link_length changed"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text.replace(old, f"link_length = {TREE5_LINK!r}  # (experiments/research/coordination.py)", 1))
    return path


def _learner(kind: str) -> tuple[tuple[str, Any], ...]:
    extra = dict(learner_overrides(kind=kind)) if kind != "fuzzy" else {}
    return tuple(sorted({**dict(LEARNER), **extra}.items()))


def run(ctx: Context) -> dict[str, Any]:
    q = ctx.quick
    level = 1 if q else LEVEL
    train_steps = 100 if q else 500
    eval_steps = 100 if q else EVAL_STEPS
    test = halton(ctx.test_set)[: 8 if q else TEST]
    robots = {
        "tree5": str(tree5_file(ctx.out / "robots" / "tree5.toml")),
        "chain4": str(run_file("chain", 4, ctx.out / "robots" / "chain4.toml")),
    }
    train: dict[tuple[str, str, int], Spec] = {}
    for robot, file in robots.items():
        for kind in KINDS:
            for seed in ctx.seed_list:
                train[(robot, kind, seed)] = Spec(
                    f"coord-train-L{level}-{robot}-{kind}",
                    seed=seed,
                    epochs=REPS * 4**level,
                    steps=train_steps,
                    goals=training_order(quadtree(level), REPS, seed),
                    learner=_learner(kind),
                    reward=REWARD,
                    checkpoint=True,
                    file=file,
                )
    trained = dict(zip(train, run_timed(ctx, list(train.values()), "train"), strict=True))
    tests: dict[tuple[str, str, int], Spec] = {}
    for robot, file in robots.items():
        common = {"epochs": len(test), "steps": eval_steps, "goals": tuple(test), "file": file}
        for kind in KINDS:
            for seed in ctx.seed_list:
                tests[(robot, kind, seed)] = Spec(
                    f"coord-test{ctx.test_set}-L{level}-{robot}-{kind}",
                    seed=seed,
                    learner=_learner(kind),
                    reward=REWARD,
                    from_dir=str(trained[(robot, kind, seed)][0].out),
                    learn=False,
                    explore=False,
                    **common,
                )
        tests[(robot, "untrained", 0)] = Spec(
            f"coord-test{ctx.test_set}-untrained-{robot}", learner=LEARNER, reward=REWARD, learn=False,
            explore=False, **common,
        )  # fmt: skip
        tests[(robot, "rule", 0)] = Spec(f"coord-ref{ctx.test_set}-rule-{robot}", controller="rule", **common)
    tested = dict(zip(tests, run_timed(ctx, list(tests.values()), "test"), strict=True))
    return _report(ctx, robots, level, train_steps, eval_steps, test, trained, tested)


def _report(
    ctx: Context,
    robots: dict[str, str],
    level: int,
    train_steps: int,
    eval_steps: int,
    test: list[tuple[float, float]],
    trained: dict[tuple[str, str, int], tuple[RunOutcome, dict[str, float]]],
    tested: dict[tuple[str, str, int], tuple[RunOutcome, dict[str, float]]],
) -> dict[str, Any]:
    seeds = ctx.seed_list
    per: dict[str, dict[str, Any]] = {}
    for robot in robots:
        entry: dict[str, Any] = {}
        for kind in KINDS:
            within = [frac_within(tested[(robot, kind, s)][0].final_errors, TOL) for s in seeds]
            entry[kind] = {
                "within_per_seed": within,
                "within": statistics.fmean(within),
                "within_std": statistics.stdev(within) if len(within) > 1 else 0.0,
                "mean_error_per_seed": [statistics.fmean(tested[(robot, kind, s)][0].final_errors) for s in seeds],
                "train_cpu_seconds_per_seed": [trained[(robot, kind, s)][1]["cpu_seconds"] for s in seeds],
            }
        for control in ("untrained", "rule"):
            r = tested[(robot, control, 0)][0]
            entry[control] = {
                "within": frac_within(r.final_errors, TOL),
                "mean_error": statistics.fmean(r.final_errors),
            }
        # JASM against independent, seed by seed (the same seeds, goals and training order)
        diff = [a - b for a, b in zip(entry["fuzzy"]["within_per_seed"], entry["independent"]["within_per_seed"],
                                      strict=True)]  # fmt: skip
        entry["jasm_minus_independent"] = {
            "per_seed": diff,
            "mean": statistics.fmean(diff),
            "std": statistics.stdev(diff) if len(diff) > 1 else math.nan,
            "seeds_better": sum(d > 0 for d in diff),
            "seeds_worse": sum(d < 0 for d in diff),
        }
        per[robot] = entry

    rep = Report(ctx, "What the joint action model buys where agents must coordinate (research)", "§4.3, §5.2")
    rep.text(
        f"Research, not product. On each robot, each learner kind trained on Level-{level}'s {4**level} goals, "
        f"{REPS}x each ({REPS * 4**level} epochs of {train_steps} steps, `inprocess`; the learner: {LEARNER_TEXT}; "
        f"reward `{REWARD}`), then frozen on {len(test)} unseen goals of test set {ctx.test_set}, {eval_steps} steps "
        f"each from home. Within {TOL:g}: the share of those goals ended within {TOL:g} (tree5: of the leaves' "
        f"centroid), mean ± std over seeds {seeds}, each seed in brackets. tree5 is examples/tree5.toml with links "
        f"of {TREE5_LINK:g}; chain4 is the reference where the paper's JASM showed no gain."
    )
    header = ["robot", "learner", "within (per seed)", "mean error", "train CPU s (mean)"]
    rows = []
    for robot, e in per.items():
        for kind, name in KINDS.items():
            k = e[kind]
            rows.append([
                robot, name,
                f"{100 * k['within']:.0f} ± {100 * k['within_std']:.0f} % "
                f"({', '.join(f'{100 * w:.0f}' for w in k['within_per_seed'])})",
                f"{statistics.fmean(k['mean_error_per_seed']):.3f}",
                f"{statistics.fmean(k['train_cpu_seconds_per_seed']):.0f}",
            ])  # fmt: skip
        for control, name in (("untrained", "untrained (zero Q, frozen)"), ("rule", "rule on g_perp (no learning)")):
            rows.append([robot, name, f"{100 * e[control]['within']:.0f} %", f"{e[control]['mean_error']:.3f}", "—"])
    rep.table(header, rows)
    lines = []
    for robot, e in per.items():
        d = e["jasm_minus_independent"]
        lines.append(
            f"{robot}: JASM − independent {100 * d['mean']:+.0f}"
            + (f" ± {100 * d['std']:.0f}" if len(seeds) > 1 else "")
            + " points of the test goals "
            f"(per seed {', '.join(f'{100 * x:+.0f}' for x in d['per_seed'])}); better on {d['seeds_better']} of "
            f"{len(seeds)} seeds, worse on {d['seeds_worse']}."
        )
    rep.text("Paired by seed:\n\n" + "\n".join(f"- {line}" for line in lines))
    _figure(rep, per, seeds)
    rep.results["per"] = per
    rep.results["tolerance"] = TOL
    rep.results["test_goals"] = len(test)
    all_runs = [r for r, _ in (*trained.values(), *tested.values())]
    rep.write({"learner": LEARNER, "reward": REWARD, "level": level, "kinds": list(KINDS)}, all_runs)
    return rep.results


def _figure(rep: Report, per: dict[str, dict[str, Any]], seeds: list[int]) -> None:
    plt = plt_module()
    fig, axes = plt.subplots(1, len(per), figsize=(4.2 * len(per), 3.6), sharey=True)
    for ax, (robot, e) in zip(axes, per.items(), strict=True):
        for i, kind in enumerate(KINDS):
            ws = [100 * w for w in e[kind]["within_per_seed"]]
            ax.bar(i, statistics.fmean(ws), color=f"C{i}", alpha=0.6)
            ax.plot([i] * len(ws), ws, "k.", ms=5)
        ax.axhline(100 * e["rule"]["within"], color="k", ls="--", lw=1, label="rule on g_perp")
        ax.axhline(100 * e["untrained"]["within"], color="grey", ls=":", lw=1, label="untrained")
        ax.set_xticks(range(len(KINDS)), list(KINDS))
        ax.set_title(robot)
        ax.set_ylim(0, 103)
    axes[0].set_ylabel(f"unseen goals within {TOL:g} (%)")
    axes[0].legend(fontsize=7)
    rep.save_figure(fig, "coordination.png", "Unseen goals reached, frozen: each learner kind (bar: mean; dots: seeds)")
