"""What a fleet buys on the generalisation protocol (research, beside §5.2, never replacing it): the Level-3 learner
trained on Level-3's 64 quad-tree goals by one robot, one goal an epoch (the paper's protocol, the generalisation
experiment's own training: its cached runs serve it), against fleets (`[run] fleet = B`, `fleet_goals = "spread"`:
robot b of epoch e gets the goal of epoch e*B + b, so the same seeded goal list is walked B goals an epoch) that see
the same 128 goal-episodes in 128/B epochs, and a fleet of 16 given 16x the episodes (128 epochs). Every trained
swarm is then tested as the experiment tests it: one robot, frozen (`--from`, learn and explore off), on the
experiment's first test set (100 Halton goals), each goal from the start pose.

    python -m kinswarm.experiments.research fleet_generalise --seeds 3 --jobs 2 --out runs/full

The learner's schedules run per epoch (epsilon = 0.97^epoch, lr = 0.5 (1 - 1/1050)^epoch), so a fleet walking the
goals in 8 epochs ends still exploring (epsilon 0.81 in its last epoch, the one robot's 0.02); one row rescales both
to the goal-episode (epsilon_decay 1 - 0.97^16: fleet epoch e has the one robot's schedule of epoch 16 e).

Measured (3 seeds, test set 0, 640 s; docs/results/research/fleet-generalise/): the paper protocol 98 % within 0.5,
mean 0.168; fleet 4 97 %, 0.192; fleet 16 97 %, 0.155; with the schedules per goal-episode 95 %, 0.164; fleet 16 with
16x the episodes 99 %, 0.120. A fleet of 16 learns what one robot learns from the same robot-steps, in ~0.67x the
wall time (quiet machine, back to back). (A first measurement, 62-81 %, ran a fleet learner that gave a rule a second
row of phi: fixed in actors/learning/fleet.py, redone.)
"""

from __future__ import annotations

import hashlib
import math
import os
import statistics
from dataclasses import dataclass
from typing import Any

import numpy as np
from kinswarm.experiments import generalisation as g
from kinswarm.experiments.common import Context, Report, frac_within, mean_std, pm, run_specs, settings
from kinswarm.experiments.goals import TEST_SIZE, halton, quadtree, training_order
from kinswarm.experiments.swarm import CHAIN4, RunOutcome, Spec, find_cached, resolved

SEEDS = 3
LEVEL = 3


@dataclass(frozen=True)
class FleetSpec(Spec):
    """A Spec with `[run] fleet` and `fleet_goals` set over the run file. The experiments' Spec does not know them
    (its identity hashes the run fields it names), so a fleet's identity hashes the Spec's and the fleet's together;
    fleet = 1 is the plain Spec, the same identity."""

    fleet: int = 1
    fleet_goals: str = "same"

    def overrides(self) -> list[tuple[tuple[str, ...], Any]]:
        out = super().overrides()
        if self.fleet > 1:
            out += [(("run", "fleet"), self.fleet), (("run", "fleet_goals"), self.fleet_goals)]
        return out

    def identity(self, with_epochs: bool = True) -> str:
        base = super().identity(with_epochs)
        if self.fleet == 1:
            return base
        return hashlib.sha256(f"{base}|fleet={self.fleet}|{self.fleet_goals}".encode()).hexdigest()[:16]


@dataclass(frozen=True)
class Condition:
    label: str
    fleet: int  # robots (1: the paper's protocol, the experiment's own training spec)
    epochs: int
    learner: tuple

    @property
    def episodes(self) -> int:
        return self.fleet * self.epochs


def per_episode(fleet: int) -> tuple:
    """The Level-3 learner with its per-epoch schedules rescaled so that a fleet's epoch e runs the one robot's
    epoch fleet * e (epsilon and lr decay per goal-episode)."""
    s = dict(g.LEARNER)
    eps = s.get("epsilon_decay", 0.0)
    lr = s.get("lr_decay", 1.0 / 1050.0)
    s["epsilon_decay"] = 1.0 - (1.0 - eps) ** fleet
    s["lr_decay"] = 1.0 - (1.0 - lr) ** fleet
    return settings(**s)


def conditions(quick: bool) -> list[Condition]:
    base = g.REPS * 4 ** (1 if quick else LEVEL)  # the paper protocol's epochs (goal-episodes)
    b = 4 if quick else 16
    rows = [
        Condition("paper protocol (1 robot)", 1, base, g.LEARNER),
        Condition(f"fleet {b}, spread", b, base // b, g.LEARNER),
        Condition(f"fleet {b}, spread, schedules per goal-episode", b, base // b, per_episode(b)),
        Condition(f"fleet {b}, spread, {b}x the episodes", b, base, g.LEARNER),
    ]
    if not quick:
        rows.insert(1, Condition("fleet 4, spread", 4, base // 4, g.LEARNER))
    return rows


def train_spec(c: Condition, level: int, seed: int, steps: int) -> Spec:
    """The paper row: the generalisation experiment's own training spec (its cache serves it). A fleet: the same
    seeded goal order, extended by further seeded passes when it has more episodes than the paper's 2 per goal."""
    if c.fleet == 1:
        return g.training_spec(g.Training(f"Level-{level}", level, c.epochs, c.learner), seed, steps)
    goals = quadtree(level)
    order = training_order(goals, math.ceil(c.episodes / len(goals)), seed)[: c.episodes]
    return FleetSpec(
        f"fleetgen-train-L{level}-e{c.epochs}-B{c.fleet}{g.run_suffix(c.learner, g.REWARD)}",
        seed=seed,
        epochs=c.epochs,
        steps=steps,
        goals=order,
        learner=c.learner,
        reward=g.REWARD,
        checkpoint=True,
        fleet=c.fleet,
        fleet_goals="spread",
    )


def test_spec(c: Condition, level: int, trained: RunOutcome, block: int, goals: list, steps: int) -> Spec:
    """The frozen test, one robot, as generalisation.train_and_test builds it (its name for the paper row)."""
    suffix = g.run_suffix(c.learner, g.REWARD)
    name = (
        f"gen-test{block}-L{level}{suffix}"
        if c.fleet == 1
        else f"fleetgen-test{block}-L{level}-B{c.fleet}-e{c.epochs}{suffix}"
    )
    return Spec(
        name,
        seed=trained.spec.seed,
        epochs=len(goals),
        steps=steps,
        goals=tuple(goals),
        learner=c.learner,
        reward=g.REWARD,
        from_dir=str(trained.out),
        learn=False,
        explore=False,
    )


def training_within(r: RunOutcome, last: int) -> float:
    """Share of the last `last` goal-episodes of training (every robot's) that ended within 0.5."""
    rows = r.rows
    per_epoch = [row.get("fleet_final_error") or [row["final_error"]] for row in rows]
    flat = [e for errs in per_epoch for e in errs]
    return frac_within(flat[-last:])


def run(ctx: Context) -> dict[str, Any]:
    q, k = ctx.quick, ctx.test_set
    level = 1 if q else LEVEL
    train_steps, eval_steps = (100, 100) if q else (500, g.EVAL_STEPS)
    test_goals = halton(k)[: 8 if q else TEST_SIZE]
    conds = conditions(q)
    start = {a: math.degrees(x.initial) for a, x in resolved(CHAIN4).topo().agents.items()}
    keys = [(c, s) for c in conds for s in ctx.seed_list]
    specs = [train_spec(c, level, s, train_steps) for c, s in keys]
    reused = {key: find_cached(sp, ctx.runs) is not None for key, sp in zip(keys, specs, strict=True)}
    trained = dict(zip(keys, run_specs(ctx, specs, "train"), strict=True))
    problems = _check(trained)
    tests = run_specs(ctx, [test_spec(c, level, trained[(c, s)], k, test_goals, eval_steps) for c, s in keys], "test")
    tested = dict(zip(keys, tests, strict=True))

    out: dict[str, Any] = {}
    for c in conds:
        per_seed = []
        for s in ctx.seed_list:
            tr, te = trained[(c, s)], tested[(c, s)]
            errs = te.final_errors
            misses = [r for r in te.rows if r["final_error"] > 0.5]
            per_seed.append(
                {
                    "seed": s,
                    "mean": float(np.mean(errs)),
                    "median": float(np.median(errs)),
                    "within_0_5": frac_within(errs),
                    "errors": errs,
                    "train_wall_seconds": float(tr.summary["wall_seconds"]),
                    "train_robot_steps": c.episodes * train_steps,
                    "train_robot_steps_per_second": float(
                        tr.summary.get("robot_steps_per_second", tr.summary["steps_per_second"])
                    ),
                    "train_within_0_5_last_pass": training_within(tr, 4**level),
                    "train_run": tr.out.name,
                    "train_reused": reused[(c, s)],  # from the cache: its wall time from when it ran
                    "misses": len(misses),
                    "misses_distal_at_start": sum(_distal_at_start(r, start) for r in misses),
                    "test_run": te.out.name,
                }
            )
        out[c.label] = {
            "fleet": c.fleet,
            "epochs": c.epochs,
            "goal_episodes": c.episodes,
            "learner": dict(c.learner),
            "per_seed": per_seed,
            **{
                key: mean_std(p[key] for p in per_seed)
                for key in ("mean", "within_0_5", "train_wall_seconds", "train_within_0_5_last_pass")
            },
        }
    _print(out)
    return _report(ctx, out, conds, level, train_steps, eval_steps, test_goals, problems, [*trained.values(), *tests])


def _distal_at_start(row: dict[str, Any], start: dict[str, float]) -> bool:
    """The two distal joints (a3, a4) ended the test episode at their start angles (within half a move)."""
    q = row.get("final_angles_deg") or {}
    return all(a in q and abs(q[a] - start[a]) < 0.5 for a in ("a3", "a4"))


def _check(trained: dict[tuple[Condition, int], RunOutcome]) -> list[str]:
    """What would make a fleet's numbers meaningless: a row without every robot's final error, or the wrong count."""
    out = []
    for (c, s), r in trained.items():
        if c.fleet == 1:
            continue
        if len(r.rows) != c.epochs:
            out.append(f"{c.label}, seed {s}: {len(r.rows)} metrics rows, expected {c.epochs}")
        bad = [row["epoch"] for row in r.rows if len(row.get("fleet_final_error") or []) != c.fleet]
        if bad:
            out.append(f"{c.label}, seed {s}: epochs {bad[:5]} lack {c.fleet} robots' final errors")
        if r.summary.get("fleet") != c.fleet:
            out.append(f"{c.label}, seed {s}: summary.json says fleet {r.summary.get('fleet')}")
    return out


def _print(out: dict[str, Any]) -> None:
    print(f"{'condition':52}{'within 0.5':>12}{'mean':>8}{'train s':>9}{'robot-steps':>13}")
    for label, e in out.items():
        p0 = e["per_seed"][0]
        print(
            f"{label:52}{100 * e['within_0_5'][0]:11.0f}%{e['mean'][0]:8.3f}{e['train_wall_seconds'][0]:9.0f}"
            f"{p0['train_robot_steps']:13d}"
        )


def _report(
    ctx: Context,
    out: dict[str, Any],
    conds: list[Condition],
    level: int,
    train_steps: int,
    eval_steps: int,
    test_goals: list,
    problems: list[str],
    runs: list[RunOutcome],
) -> dict[str, Any]:
    k = ctx.test_set
    rep = Report(ctx, "Fleets on the generalisation protocol (research)", "5.2 (research beside it, not replacing it)")
    b = max(c.fleet for c in conds)
    rep.text(
        "## Set-up",
        "",
        f"Research, not product. Training: the generalisation experiment's Level-{level} ({4**level} quad-tree goals, "
        f"{train_steps}-step episodes, every goal {g.REPS}x in a seeded order) with its learner ({g.LEARNER_TEXT}) and "
        f"reward `{g.REWARD}`. 'paper protocol' is the experiment's own training run (one robot, one goal an epoch; "
        'reused from the shared cache when it exists). A fleet (`[run] fleet = B`, `fleet_goals = "spread"`, '
        "docs/architecture.md 'Schema 10: fleets') runs B robots in lockstep, each agent one learner learning from "
        "all B transitions of a step; robot b of epoch e gets goal e*B + b of the same seeded list, so "
        f"'fleet {b}, spread' walks the paper's {g.REPS * 4**level} goal-episodes, in order, {b} an epoch; "
        f"'{b}x the episodes' runs as many epochs as the paper, {b}x the goal-episodes (further seeded passes over the "
        "goals). The learner's schedules are per epoch: ε = 0.97^epoch, lr = 0.5 (1 − 1/1050)^epoch, so a fleet that "
        f"walks the goals in {g.REPS * 4**level // b} epochs still explores at its end; 'schedules per goal-episode' "
        f"sets epsilon_decay = 1 − 0.97^{b} and lr_decay = 1 − (1 − 1/1050)^{b}, the one robot's schedule of epoch "
        f"{b}·e in fleet epoch e. Test: every trained swarm as the experiment tests it, one robot, frozen (`--from`, "
        f"`--learn off --explore off`), on test set {k} ({len(test_goals)} Halton goals), {eval_steps} steps per goal "
        "from the start pose, error = tip distance at the episode's end.",
        "",
        "Training wall time is summary.json's `wall_seconds` of the training run (a cached run's from when it ran; "
        f"all under `--jobs {ctx.jobs}` on a shared {_cores()}-core machine, so load differs between runs); "
        "robot-steps = epochs × steps × robots. 'training within 0.5' is the share of the last "
        f"{4**level} goal-episodes of training (every robot's) that ended within 0.5.",
    )
    rows = []
    for c in conds:
        e = out[c.label]
        ps = e["per_seed"]
        rows.append(
            [
                c.label,
                c.fleet,
                c.epochs,
                c.episodes,
                len(ps),
                f"{100 * e['within_0_5'][0]:.0f} ± {100 * e['within_0_5'][1]:.0f} %",
                f"{e['mean'][0]:.3f} ± {e['mean'][1]:.3f}",
                f"{statistics.fmean(p['median'] for p in ps):.3f}",
                pm([p["train_wall_seconds"] for p in ps], 0),
                f"{ps[0]['train_robot_steps']:,}",
                pm([p["train_robot_steps_per_second"] for p in ps], 0),
                f"{100 * e['train_within_0_5_last_pass'][0]:.0f} %",
            ]
        )
    rep.text("## Result", "", "Mean ± std over seeds.")
    rep.table(
        [
            "training",
            "robots",
            "epochs",
            "goal-episodes",
            "seeds",
            f"test set {k}: within 0.5",
            "mean error",
            "median",
            "training wall s",
            "training robot-steps",
            "robot-steps / s",
            "training within 0.5",
        ],
        rows,
    )
    seeds_rows = [
        [
            c.label,
            p["seed"],
            f"{p['mean']:.3f}",
            f"{100 * p['within_0_5']:.0f} %",
            f"{p['train_wall_seconds']:.0f}" + (" (cached)" if p["train_reused"] else ""),
            f"`{p['train_run']}`",
        ]
        for c in conds
        for p in out[c.label]["per_seed"]
    ]
    rep.text("### Per seed")
    rep.table(["training", "seed", "mean error", "within 0.5", "training wall s", "training run"], seeds_rows)
    paper = out[conds[0].label]
    pw = statistics.fmean(p["train_wall_seconds"] for p in paper["per_seed"])
    lines = ["## Reading", "", f"Against '{conds[0].label}' on test set {k} (same seeds):", ""]
    for c in conds:
        e, ps = out[c.label], out[c.label]["per_seed"]
        w = statistics.fmean(p["train_wall_seconds"] for p in ps)
        m, d = sum(p["misses"] for p in ps), sum(p["misses_distal_at_start"] for p in ps)
        lines.append(
            f"- {c.label}: within 0.5 {100 * e['within_0_5'][0]:.0f} % (paper protocol "
            f"{100 * paper['within_0_5'][0]:.0f} %), mean {e['mean'][0]:.3f} ({paper['mean'][0]:.3f}); training "
            f"wall {w:.0f} s ({w / pw:.2f}x), {c.episodes // conds[0].episodes}x the robot-steps; {m} misses "
            f"(error > 0.5, all seeds), {d} of them with a3 and a4 ended at their start angles."
        )
    rep.text(*lines)
    rep.text(
        "## Controls",
        "",
        "Not rerun here: the untrained swarm learning one episode per test goal, the rule on g_perp and the "
        "model-based references (pseudo-inverse, greedy per joint) on the same test set are in the generalisation "
        "report, docs/results/generalisation/report.md (test set 0: rule 0.133, 98 % within 0.5; its Level-3 row, "
        "6 seeds: 0.149 ± 0.052, 98 %).",
    )
    if problems:
        rep.text("## What looked wrong", "", *[f"- {p}" for p in problems])
    per = {c.label: {f"test_set_{k}": {"errors": [p["errors"] for p in out[c.label]["per_seed"]]}} for c in conds}
    g.cdf(rep, [c.label for c in conds], per, k, {})
    rep.results.update({"conditions": out, "problems": problems})
    rep.write(
        {
            "topology": "examples/chain4.toml",
            "level": level,
            "reward": g.REWARD,
            "learner": g.LEARNER_TEXT,
            "reps_per_goal": g.REPS,
            "train_steps": train_steps,
            "eval_steps": eval_steps,
            "test_set": k,
            "test_goals": len(test_goals),
            "fleet_goals": "spread",
        },
        runs,
    )
    return rep.results


def _cores() -> int:
    return os.cpu_count() or 0
