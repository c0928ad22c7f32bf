"""Does the paper's learner scale? §5.2's generalisation protocol on long chains and wide trees (research, beside
benchmarks/scale.py's cost curve; docs/scale.md).

For N = 4, 8, 16, 32 joints, a chain and a wide tree (experiments/arms.py: links scaled so that the tip, the leaves'
centroid on a tree, reaches 12 from the base as chain4's does, so §5.2's goal square (half 8) and its tolerance
(0.5) are the same fraction of the arm at every size: no goal region of the task needs to scale with the reach):
the generalisation experiment's learner and reward (LEARNER, REWARD) trained on Level-2's 16 quad-tree goals, twice
each (32 epochs of 500 steps; LEVEL), then frozen (learning and exploration off) on the first 50 unseen Halton goals of
test set K, 200 steps each from home. Against, on the same goals: the same swarm untrained (frozen from a zero Q), the
hand-written rule on each agent's own state (sim/baseline.py rule_increments: one step along sign(g_perp)), and the
pseudo-inverse (the chains only: on a tree it drives every leaf to the goal, not their centroid, which is what the
task measures). Every learning run in the `inprocess` placement (the same numbers as `process`, and fast). Each run's
CPU seconds are measured in the process that ran it (time.process_time) and kept beside it (cpu.json).

    python -m kinswarm.experiments.research learning_scale --jobs 2 --out runs/research   # ~10 CPU-min a seed
"""

from __future__ import annotations

import json
import math
import statistics
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from kinswarm.experiments.arms import REACH, depth, link_length, run_file
from kinswarm.experiments.common import Context, Report, frac_within, plt_module, worker_pool
from kinswarm.experiments.generalisation.protocol import EVAL_STEPS, LEARNER, LEARNER_TEXT, REPS, REWARD
from kinswarm.experiments.goals import HALF, halton, quadtree, training_order
from kinswarm.experiments.swarm import RunOutcome, Spec, find_cached, run_spec

SEEDS = 1  # one seed keeps the study near 10 CPU-minutes (a seed more: --seeds 2, the first one's runs reused)
TEST = 50  # the first goals of the test set: half §5.2's 100, to halve the tests' cost
SIZES = (4, 8, 16, 32)
SHAPES = ("chain", "tree")
# §5.2's Level-2: 16 training goals, twice each (32 epochs). Level-3 (64 goals, 128 epochs) is 4x the training CPU,
# ~12 CPU-minutes a seed over the eight robots: more than a machine shared by seven could give this study
LEVEL = 2
TOL = 0.5 * REACH / 12.0  # §5.2's tolerance, on an arm of chain4's reach
# the controls on the same goals; the pseudo-inverse where it measures what the task measures (one end effector)
REFERENCES = {"rule": ("chain", "tree"), "pinv": ("chain",)}
REF_NAMES = {"rule": "rule on g_perp", "pinv": "pseudo-inverse"}


def _timed_one(args: tuple[Spec, str]) -> tuple[RunOutcome, dict[str, float]]:
    """Run (or reuse) one spec; the CPU and wall seconds of its run, measured here when it runs, read back when
    cached."""
    spec, runs = args
    fresh = find_cached(spec, Path(runs)) is None
    c0, w0 = time.process_time(), time.perf_counter()
    out = run_spec(spec, Path(runs))
    record = out.out / "cpu.json"
    if fresh:
        took = {"cpu_seconds": time.process_time() - c0, "wall_seconds": time.perf_counter() - w0}
        record.write_text(json.dumps(took) + "\n")
    try:
        return out, json.loads(record.read_text())
    except (OSError, ValueError):  # a run made by another study: its time is not known
        return out, {"cpu_seconds": math.nan, "wall_seconds": float(out.summary.get("wall_seconds", math.nan))}


def run_timed(ctx: Context, specs: Sequence[Spec], desc: str) -> list[tuple[RunOutcome, dict[str, float]]]:
    """Every spec run or reused, in `ctx.jobs` worker processes; results in spec order, progress on stderr."""
    ctx.runs.mkdir(parents=True, exist_ok=True)
    got: dict[int, tuple[RunOutcome, dict[str, float]]] = {}

    def said(i: int) -> None:
        s = specs[i]
        print(f"{ctx.name} {desc}: {len(got)}/{len(specs)} {s.name} seed {s.seed}", flush=True)

    if ctx.jobs <= 1 or len(specs) <= 1:
        for i, s in enumerate(specs):
            got[i] = _timed_one((s, str(ctx.runs)))
            said(i)
    else:
        order = sorted(range(len(specs)), key=lambda i: -specs[i].epochs * specs[i].steps * _size(specs[i]))
        with worker_pool(ctx.jobs) as pool:
            futures = {pool.submit(_timed_one, (specs[i], str(ctx.runs))): i for i in order}
            for f in futures:  # in submission order: the longest first
                got[futures[f]] = f.result()
                said(futures[f])
    return [got[i] for i in range(len(specs))]


def _size(spec: Spec) -> int:
    return int(Path(spec.file).stem.lstrip("chaintre") or 1)


def run(ctx: Context) -> dict[str, Any]:
    q = ctx.quick
    sizes = (4, 8) if q else SIZES
    level = 1 if q else LEVEL
    train_steps, eval_steps = (100, 100) if q else (500, EVAL_STEPS)
    test = halton(ctx.test_set)[: 8 if q else TEST]
    robots = {
        (shape, n): str(run_file(shape, n, ctx.out / "robots" / f"{shape}{n}.toml")) for shape in SHAPES for n in sizes
    }
    train: dict[tuple[str, int, int], Spec] = {}
    for (shape, n), file in robots.items():
        for seed in ctx.seed_list:
            train[(shape, n, seed)] = Spec(
                f"scale-train-L{level}-{shape}{n}",
                seed=seed,
                epochs=REPS * 4**level,
                steps=train_steps,
                goals=training_order(quadtree(level), REPS, seed),
                learner=LEARNER,
                reward=REWARD,
                checkpoint=True,
                file=file,
            )
    trained = dict(zip(train, run_timed(ctx, list(train.values()), "train"), strict=True))
    tests: dict[tuple[str, str, int, int], Spec] = {}
    for (shape, n), file in robots.items():
        common = {"epochs": len(test), "steps": eval_steps, "goals": tuple(test), "file": file}
        for seed in ctx.seed_list:
            tests[("trained", shape, n, seed)] = Spec(
                f"scale-test{ctx.test_set}-L{level}-{shape}{n}",
                seed=seed,
                learner=LEARNER,
                reward=REWARD,
                from_dir=str(trained[(shape, n, seed)][0].out),
                learn=False,
                explore=False,
                **common,
            )
        # frozen from a zero Q every action ties and the greedy choice is the same whatever the seed: one seed
        tests[("untrained", shape, n, 0)] = Spec(
            f"scale-test{ctx.test_set}-untrained-{shape}{n}",
            learner=LEARNER,
            reward=REWARD,
            learn=False,
            explore=False,
            **common,
        )
        for law, shapes in REFERENCES.items():
            if shape in shapes:  # deterministic: one run
                tests[(law, shape, n, 0)] = Spec(f"scale-ref{ctx.test_set}-{law}-{shape}{n}", controller=law, **common)
    tested = dict(zip(tests, run_timed(ctx, list(tests.values()), "test"), strict=True))
    return _report(ctx, robots, sizes, level, train_steps, eval_steps, test, trained, tested)


def _report(
    ctx: Context,
    robots: dict[tuple[str, int], str],
    sizes: Sequence[int],
    level: int,
    train_steps: int,
    eval_steps: int,
    test: list[tuple[float, float]],
    trained: dict[tuple[str, int, int], tuple[RunOutcome, dict[str, float]]],
    tested: dict[tuple[str, str, int, int], tuple[RunOutcome, dict[str, float]]],
) -> dict[str, Any]:
    per: dict[str, dict[str, Any]] = {}
    for (shape, n), file in robots.items():
        key = f"{shape}{n}"
        seeds = ctx.seed_list
        within = [frac_within(tested[("trained", shape, n, s)][0].final_errors, TOL) for s in seeds]
        means = [statistics.fmean(tested[("trained", shape, n, s)][0].final_errors) for s in seeds]
        cpu = [trained[(shape, n, s)][1]["cpu_seconds"] for s in seeds]
        wall = [trained[(shape, n, s)][1]["wall_seconds"] for s in seeds]
        steps = trained[(shape, n, seeds[0])][0].spec.epochs * train_steps
        entry: dict[str, Any] = {
            "shape": shape,
            "n": n,
            "depth": depth(shape, n),
            "link_length": link_length(shape, n),
            "run_file": Path(file).name,
            "trained": {
                "within_per_seed": within,
                "within": statistics.fmean(within),
                "mean_error_per_seed": means,
                "train_cpu_seconds_per_seed": cpu,
                "train_wall_seconds_per_seed": wall,
                "train_steps": steps,
                "train_cpu_ms_per_step": 1000 * statistics.fmean(cpu) / steps,
                "train_error_last_pass": [
                    statistics.fmean(trained[(shape, n, s)][0].final_errors[-(4**level) :]) for s in seeds
                ],
            },
        }
        for control in ("untrained", *REFERENCES):
            if (control, shape, n, 0) in tested:
                r = tested[(control, shape, n, 0)][0]
                entry[control] = {
                    "within": frac_within(r.final_errors, TOL),
                    "mean_error": statistics.fmean(r.final_errors),
                }
        per[key] = entry

    rep = Report(ctx, "Does learning scale? The paper's reach on long chains and wide trees (research)", "§5.2, §6")
    rep.text(
        f"Research, not product. For each robot (experiments/arms.py: the tip reaches {REACH:g} from the base at every "
        f"size, so §5.2's goal square of half {HALF:g} and its tolerance {TOL:g} are the same share of the arm): the "
        f"generalisation learner ({LEARNER_TEXT}) and reward `{REWARD}`, trained on Level-{level}'s {4**level} goals, "
        f"{REPS}x each ({REPS * 4**level} epochs of {train_steps} steps, `inprocess`), then frozen (learn off, explore "
        f"off) on {len(test)} unseen goals of test set {ctx.test_set}, {eval_steps} steps each from home. Within "
        f"{TOL:g}: the share of those goals whose final error is at most {TOL:g}. Seeds {ctx.seed_list}: the share "
        f"per seed in brackets. Controls on the same goals: the swarm untrained (a zero Q, frozen), the rule on "
        f"g_perp (no learning, no model), the pseudo-inverse (chains only).",
    )
    header = ["robot", "depth", "trained: within (per seed)", "mean error", "untrained", "rule", "pseudo-inverse",
              "train CPU s (per seed)", "train wall s", "CPU ms/step"]  # fmt: skip
    rows = []
    for key, e in per.items():
        t = e["trained"]
        rows.append(
            [
                key,
                e["depth"],
                f"{100 * t['within']:.0f} % ({', '.join(f'{100 * w:.0f}' for w in t['within_per_seed'])})",
                f"{statistics.fmean(t['mean_error_per_seed']):.3f}",
                *(f"{100 * e[c]['within']:.0f} %" if c in e else "—" for c in ("untrained", "rule", "pinv")),
                ", ".join(f"{c:.0f}" for c in t["train_cpu_seconds_per_seed"]),
                f"{statistics.fmean(t['train_wall_seconds_per_seed']):.0f}",
                f"{t['train_cpu_ms_per_step']:.2f}",
            ]
        )
    rep.table(header, rows)
    _figure(rep, per, sizes)
    rep.results["per"] = per
    rep.results["tolerance"] = TOL
    rep.results["test_goals"] = len(test)
    all_runs = [r for r, _ in (*trained.values(), *tested.values())]
    rep.write({"learner": LEARNER, "reward": REWARD, "level": level, "sizes": list(sizes)}, all_runs)
    return rep.results


def _figure(rep: Report, per: dict[str, dict[str, Any]], sizes: Sequence[int]) -> None:
    plt = plt_module()
    fig, (ax, bx) = plt.subplots(1, 2, figsize=(10, 3.8))
    for shape, color in (("chain", "C0"), ("tree", "C1")):
        es = [per[f"{shape}{n}"] for n in sizes]
        lo = [100 * min(e["trained"]["within_per_seed"]) for e in es]
        hi = [100 * max(e["trained"]["within_per_seed"]) for e in es]
        mid = [100 * e["trained"]["within"] for e in es]
        ax.plot(sizes, mid, "o-", color=color, label=f"{shape}: trained, frozen")
        ax.fill_between(sizes, lo, hi, color=color, alpha=0.15, lw=0)
        ax.plot(sizes, [100 * e["rule"]["within"] for e in es], "s--", color=color, alpha=0.7, label=f"{shape}: rule")
        ax.plot(sizes, [100 * e["untrained"]["within"] for e in es], "x:", color=color, alpha=0.7,
                label=f"{shape}: untrained")  # fmt: skip
        if all("pinv" in e for e in es):
            ax.plot(sizes, [100 * e["pinv"]["within"] for e in es], "^-.", color=color, alpha=0.5,
                    label=f"{shape}: pseudo-inverse")  # fmt: skip
        cpu = [statistics.fmean(e["trained"]["train_cpu_seconds_per_seed"]) for e in es]
        bx.plot(sizes, cpu, "o-", color=color, label=f"{shape}: training CPU s")
    for a in (ax, bx):
        a.set_xscale("log", base=2)
        a.set_xticks(list(sizes), [str(n) for n in sizes])
        a.set_xlabel("joints N")
    ax.set_ylabel(f"unseen goals within {TOL:g} (%)")
    ax.set_ylim(-3, 103)
    ax.legend(fontsize=7)
    bx.set_yscale("log")
    bx.set_ylabel("CPU seconds to train (one seed)")
    bx.legend(fontsize=7)
    rep.save_figure(fig, "learning_scale.png", "Unseen goals reached by the frozen swarm, and its training CPU, by N")
