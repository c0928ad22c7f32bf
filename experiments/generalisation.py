"""§5.2, Figs. 10-12: train on quad-tree goal sets, test the frozen swarm on unseen Halton goals.

Level-L trains one swarm on the 4^L centres of a quad-tree over the task space (goals.py), one goal per
epoch, every goal REPS times in a seeded order (Level-4: once each), then evaluates it frozen (`--from T
--learn off --explore off`: no learning, greedy actions) on 100 test goals — block K of the Halton
sequence in bases 2 and 3 (`--test-set K`; Levels 3 and 4 are also tested on block K+1, a second unseen set).
Level-3 carries the paper's number and the issue's bar: its rows run on at least L3_SEEDS seeds.
Higher levels also train for more epochs; a control trains Level-1's 4 goals for Level-2's epoch budget,
which separates the number of goals from the amount of training. Also reported, labelled as what it is:
an untrained swarm *learning* within one episode per test goal (not a generalisation test).
"""

from __future__ import annotations

import hashlib
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
from kinswarm.actors.learning.settings import LearnerSettings, StateVariable

from .common import Context, Report, frac_within, mean_std, plt_module, pm, run_specs, settings
from .goals import HALF, TEST_SIZE, halton, quadtree, training_order
from .swarm import RunOutcome, Spec

PAPER = {1: (0.3814, 0.5596), 3: (0.2366, 0.2036)}  # §5.2: Level-1 and Level-3 mean / STD
REPS = 2  # epochs per training goal (Level-4: 1, its 256 goals are already 256 epochs)
# Steps per test goal. Not every frozen swarm has settled by then: in 600 Level-3 test episodes, 17 % still moved
# > 0.05 over steps 180-200 (3.5 % over 480-500), as many getting worse after step 200 as better; 500-step episodes
# gave means within 0.01-0.02 of these. The report also shows the error at step 100.
EVAL_STEPS = 200
SCRATCH_GOALS = 10  # test goals per seed for the learning-on (from scratch) episodes
LEVELS = (1, 2, 3, 4)  # Level-4 alone is 3 x 256 epochs, a third of this experiment's time
# Level-3's rows run on at least this many seeds. Measured with the signed-g3 learner (seeds 0-5, set 0): 0.249,
# 0.264, 0.186, 0.428, 0.336, 0.771 - a mean of 0.233 over seeds 0-2 but 0.372 over all six. Three seeds decided the
# verdict by which three they were. (These seeds replace a "Level-3, 4x per goal" row, 0.312 +- 0.139 over 3 seeds
# on 2026-11-21: more epochs on the same goals did not help. Even so `all` grew by ~1.175x in steps here, to an
# estimated ~60 min: at the hour, not re-timed; docs/results/README.md "Time".)
L3_SEEDS = 6
# The level sweep's learner: a coarser grid and q_i out of the state. q_i cannot be removed by a setting, so
# it gets 2 sets over +-1000 rad: its memberships are 0.5 +- 0.002 for every angle, i.e. the learner cannot tell
# angles apart. Measured on Level-3, seed 0 (2 epochs per goal, 100 test goals): default grid mean 0.94 / 67 %
# within 0.5, coarse grid 0.58 / 78 %, coarse without q 0.43 / 82 %. The default learner is run at Level-3 too.
_R = LearnerSettings().ranges
COARSE = {"n_sets": (2, 8, 6, 5, 5, 5), "ranges": ((-1000.0, 1000.0), *_R[1:])}
COARSE_TEXT = "n_sets (2, 8, 6, 5, 5, 5) with q over ±1000 rad (q out of the state)"
# The sweep's learner adds g_perp, the component of goal - tip along the direction the agent's own joint moves the
# tip (agent.py, state.goal_along_motion), with 7 fine sets over ±1.5: g1 and g2 (5 sets over ±24) cannot tell a
# tip 0.6 from the goal from one at the goal, so frozen swarms stopped short or overshot. Measured on Level-3 (2
# epochs per goal, seeds 0-2, 100 test goals): mean 0.446 -> 0.243, within 0.5 85 % -> 92 %.
G_PERP = {"extra_state": (StateVariable("g_perp", 7, (-1.5, 1.5)),)}
G_PERP_TEXT = f"{COARSE_TEXT}, plus g_perp (7 sets over ±1.5) as a 7th state variable"
# And g3 unsigned (LearnerSettings.g3): a goal straight behind the tip - an arm too long for a goal near it - fell
# on both ends of g3's range (+pi, -pi), which share no set; frozen swarms stopped there, error 3.5-4.4 (seed 0,
# test set 1, goals 22, 26, 58). Measured on Level-3, seeds 0-5: see the report's rows "Level-3" and
# "Level-3, signed g3".
G3_UNSIGNED = {"g3": "unsigned", "ranges": (*COARSE["ranges"][:5], (0.0, math.pi))}
UNSIGNED_TEXT = f"{G_PERP_TEXT}, and g3 unsigned (|g3|, 5 sets over [0, π])"
# And exploration fading over the epochs (LearnerSettings.epsilon_decay): epsilon(epoch) = 0.97^epoch, 0.14 by
# Level-3's epoch 64, 0.02 by its last. Each epoch explores in its first ~50 steps (T(t) = 1 + T_max e^(-s t)), so
# with a constant epsilon the greedy policy is never followed from the start pose, where every test episode
# starts: late epochs now follow and correct it. Frozen swarms had stopped far from goals near the base (the distal
# joints never moving) that the same swarm reached with learning on. Measured: ablations' "no ε decay" row.
EPSILON_DECAY = 0.03
LEARNER = settings(**{**COARSE, **G3_UNSIGNED}, **G_PERP, epsilon_decay=EPSILON_DECAY)
LEARNER_TEXT = f"{UNSIGNED_TEXT}, and epsilon_decay {EPSILON_DECAY} (ε = 0.97^epoch); other settings default"
NO_EPSILON_DECAY = settings(**{**COARSE, **G3_UNSIGNED}, **G_PERP)  # the sweep's learner before epsilon_decay
SIGNED_G3 = settings(**COARSE, **G_PERP)  # ... and before g3 unsigned
NO_G_PERP = settings(**COARSE)  # ... and before g_perp
DEFAULT_LEARNER = settings()
LEARNER_NAMES = {
    LEARNER: "sweep",
    NO_EPSILON_DECAY: "no ε decay",
    SIGNED_G3: "signed g3",
    NO_G_PERP: "no g_perp",
    DEFAULT_LEARNER: "default",
}
# run names; "" keeps older caches
RUN_SUFFIX = {
    LEARNER: "-g3u-ed",
    NO_EPSILON_DECAY: "-g3u",
    SIGNED_G3: "-gperp",
    NO_G_PERP: "",
    DEFAULT_LEARNER: "-default",
}
# The sweep's reward: `graded` (reward.py), the shaped reward's gradient k (D_prev - D) inside D_min too. With
# `shaped` (strict inside D_min: e^(-D) for a step closer, -1 for a step away, 0 for keeping still) frozen swarms
# stopped 1-3 from goals they were unsure of. Measured on Level-3, 6 seeds: ablations' rows "no ε decay" (graded)
# and "shaped reward".
REWARD = "graded"


# Model-based references on the same test goals, same start pose, steps and 1-degree moves (no learning, one run
# each: deterministic). "greedy" is each joint alone moving to bring the tip nearest (sim/baseline.py): a per-joint
# policy greedy in the distance, which is what the shaped reward pays for. Not a bound on learning (the swarm's
# median beats it). "rule" is the hand-written control on the agents' own state (sim/baseline.py rule_increments):
# no learning, no model; what learning adds is measured against it, under both protocols.
REFERENCES = {"pseudo-inverse": "pinv", "greedy per joint": "greedy", "rule on g_perp": "rule"}
SUCCESSIVE_REFERENCES = {"rule on g_perp, successive test goals": "rule"}  # on test set K, as the swarm's row


@dataclass(frozen=True)
class Training:
    label: str
    level: int
    epochs: int
    learner: tuple
    main: bool = True  # part of the level sweep (else a comparison)
    successive: bool = False  # tested the paper's way: each test goal from where the last one ended (same training)
    train_successive: bool = (
        False  # trained so too: each epoch from where the last ended (research: successive_training)
    )
    min_seeds: int = 0  # at least this many seeds (the full run only)
    reward: str = REWARD

    @property
    def suffix(self) -> str:
        return run_suffix(self.learner, self.reward)


def run_suffix(learner: tuple, reward: str) -> str:
    """Run names' suffix: the learner's, then the reward unless shaped (the older caches' names)."""
    named = RUN_SUFFIX.get(learner)
    if named is None:  # a learner of research/ (not named here): known by its settings
        named = "-" + hashlib.sha256(repr(learner).encode()).hexdigest()[:6]
    return named + ("" if reward == "shaped" else f"-{reward}")


def training_spec(t: Training, seed: int, steps: int) -> Spec:
    """The run that trains row `t`'s swarm of one seed: the level's goals in a seeded order, checkpointed."""
    goals = training_order(quadtree(t.level), math.ceil(t.epochs / 4**t.level), seed)[: t.epochs]
    return Spec(
        f"gen-train-L{t.level}-e{t.epochs}{t.suffix}{'-succ' if t.train_successive else ''}",
        seed=seed,
        epochs=t.epochs,
        steps=steps,
        goals=goals,
        learner=t.learner,
        reward=t.reward,
        successive=t.train_successive,
        checkpoint=True,
    )


def reps_for(level: int) -> int:
    return 1 if level >= 4 else REPS


def stats(errors: list[float]) -> dict[str, float]:
    a = np.asarray(errors, dtype=float)
    return {
        "mean": float(a.mean()),
        "std": float(a.std(ddof=1)) if len(a) > 1 else 0.0,
        "median": float(np.median(a)),
        "frac_within_0_5": frac_within(errors),
        "max": float(a.max()),
    }


@dataclass
class Tested:
    """Trained swarms and their frozen tests (train_and_test)."""

    trainings: list[Training]
    seeds_of: Callable[[Training], list[int]]
    test_sets: dict[int, list[tuple[float, float]]]
    train_steps: int
    eval_steps: int
    trained: dict[tuple[str, int], RunOutcome]
    evals: dict[tuple[str, int, int], RunOutcome]
    scratch: dict[tuple[int, int], RunOutcome]
    references: dict[str, Any]
    per: dict[str, Any]  # label -> test_set_K -> errors, per-seed stats, their mean and std over seeds
    train_err: dict[str, list[float]]  # label -> per seed: mean final error over the last pass of training goals
    runs: list[RunOutcome]  # every run once, for the report's run list

    @property
    def scratch_err(self) -> list[float]:
        return [r.final_errors[-1] for r in self.scratch.values()]


def run(ctx: Context) -> dict[str, Any]:
    q = ctx.quick
    levels = (1,) if q else LEVELS
    control_epochs = REPS * 4**2  # Level-1's goals for Level-2's epochs
    trainings = [
        Training(f"Level-{L}", L, reps_for(L) * 4**L, LEARNER, min_seeds=L3_SEEDS if L == 3 else 0) for L in levels
    ]
    if q:
        trainings = [Training("Level-1", 1, 4, LEARNER)]
    else:
        trainings.append(Training(f"Level-1, {control_epochs} epochs (control)", 1, control_epochs, LEARNER, False))
        # §5.2 "successive on-line requests": the Level-3 swarm, each test goal from where the last one ended
        trainings.append(Training("Level-3, successive test goals", 3, REPS * 4**3, LEARNER, False, True))
    t = train_and_test(ctx, trainings, second_level=1 if q else 3, with_scratch=True)
    return _report(ctx, t, levels)


def train_and_test(ctx: Context, trainings: list[Training], second_level: int, with_scratch: bool) -> Tested:
    """Train every row's swarms (one per seed), test each frozen on test set K (the sweep's rows from
    `second_level` up on K+1 too), run the model-based references on the same goals, and, `with_scratch`,
    the learning-on episodes from scratch."""
    q = ctx.quick
    train_steps, eval_steps = (100, 100) if q else (500, EVAL_STEPS)
    n_test = 8 if q else TEST_SIZE
    k = ctx.test_set
    test_sets = {k: halton(k)[:n_test], k + 1: halton(k + 1)[:n_test]}

    def seeds_of(t: Training) -> list[int]:
        return ctx.seed_list if q else list(range(max(ctx.seeds, t.min_seeds)))

    train_specs = {}
    for t in trainings:
        label = t.label
        if t.successive:  # the same training as the level's own row (added below)
            continue
        for seed in seeds_of(t):
            train_specs[(label, seed)] = training_spec(t, seed, train_steps)
    trained = dict(zip(train_specs, run_specs(ctx, [*train_specs.values()], "train"), strict=True))
    for t in trainings:
        if t.successive:
            for seed in seeds_of(t):
                trained[(t.label, seed)] = trained[(f"Level-{t.level}", seed)]

    eval_specs: dict[tuple[str, int, int], Spec] = {}
    for t in trainings:
        label, level = t.label, t.level
        sets = [k, k + 1] if level >= second_level and t.main else [k]
        for block in sets:
            for seed in seeds_of(t):
                eval_specs[(label, block, seed)] = Spec(
                    f"gen-test{block}-L{level}{t.suffix}",
                    seed=seed,
                    epochs=len(test_sets[block]),
                    steps=eval_steps,
                    goals=tuple(test_sets[block]),
                    learner=t.learner,
                    reward=t.reward,  # not used with learning off, but the run says what it was trained with
                    from_dir=str(trained[(label, seed)].out),
                    learn=False,
                    explore=False,
                    successive=t.successive,
                )
    scratch_specs = {
        (i, seed): Spec(
            f"gen-scratch-g{i}{run_suffix(LEARNER, REWARD)}",
            seed=seed,
            epochs=1,
            steps=train_steps,
            goals=(g,),
            learner=LEARNER,
            reward=REWARD,
        )
        for seed in (ctx.seed_list if with_scratch else ())
        for i, g in enumerate(test_sets[k][: 2 if q else SCRATCH_GOALS])
    }
    ref_specs = {
        (name, block): Spec(
            f"gen-ref{block}-{controller}{'-succ' if successive else ''}",
            epochs=len(test_sets[block]),
            steps=eval_steps,
            goals=tuple(test_sets[block]),
            controller=controller,
            successive=successive,
        )
        for refs, successive in ((REFERENCES, False), (SUCCESSIVE_REFERENCES, True))
        for name, controller in refs.items()
        for block in (test_sets if not successive else [k])
    }
    done = run_specs(ctx, [*eval_specs.values(), *scratch_specs.values(), *ref_specs.values()], "test")
    evals = dict(zip(eval_specs, done[: len(eval_specs)], strict=True))
    scratch_runs = dict(zip(scratch_specs, done[len(eval_specs) : len(eval_specs) + len(scratch_specs)], strict=True))
    refs = dict(zip(ref_specs, done[len(eval_specs) + len(scratch_specs) :], strict=True))
    references: dict[str, Any] = {}
    for (name, block), r in refs.items():
        references.setdefault(name, {})[f"test_set_{block}"] = {**stats(r.final_errors), "errors": r.final_errors}

    per: dict[str, Any] = {}
    for (label, block, _seed), r in evals.items():
        entry = per.setdefault(label, {}).setdefault(f"test_set_{block}", {"per_seed": [], "errors": []})
        entry["errors"].append(r.final_errors)
        half = [x["errors"][len(x["errors"]) // 2 - 1] for x in r.rows]
        entry.setdefault("mean_at_half_episode", []).append(float(np.mean(half)))
        entry["per_seed"].append(stats(r.final_errors))
    for sets in per.values():
        for entry in sets.values():
            ps = entry["per_seed"]
            for key in ("mean", "std", "median", "frac_within_0_5"):
                m, s = mean_std(p[key] for p in ps)
                entry[key] = m
                entry[f"{key}_std_over_seeds"] = s
            entry["pooled"] = stats([e for errs in entry["errors"] for e in errs])
    train_err = {
        t.label: [float(np.mean(trained[(t.label, s)].final_errors[-min(4**t.level, t.epochs) :])) for s in seeds_of(t)]
        for t in trainings
    }

    return Tested(
        trainings=trainings,
        seeds_of=seeds_of,
        test_sets=test_sets,
        train_steps=train_steps,
        eval_steps=eval_steps,
        trained=trained,
        evals=evals,
        scratch=scratch_runs,
        references=references,
        per=per,
        train_err=train_err,
        runs=[*{r.out: r for r in trained.values()}.values(), *done],  # a shared training once
    )


def _report(ctx: Context, tested: Tested, levels: tuple[int, ...]) -> dict[str, Any]:
    q, k = ctx.quick, ctx.test_set
    trainings, per, seeds_of = tested.trainings, tested.per, tested.seeds_of
    train_steps, eval_steps, test_sets = tested.train_steps, tested.eval_steps, tested.test_sets
    scratch_err, references = tested.scratch_err, tested.references
    n_test = len(test_sets[k])
    rep = Report(ctx, "Generalisation: quad-tree training goals, unseen Halton test goals", "5.2, Figs. 10-12")
    rep.results.update(
        {
            "levels": {
                t.label: {
                    "level": t.level,
                    "training_epochs": t.epochs,
                    "learner": dict(t.learner),
                    "reward": t.reward,
                    "sweep": t.main,
                    "seeds": seeds_of(t),
                }
                for t in trainings
            },
            "task_space": [[-HALF, HALF], [-HALF, HALF]],
            "test_sets": {str(b): [list(g) for g in pts] for b, pts in test_sets.items()},
            "train_steps": train_steps,
            "eval_steps": eval_steps,
            "per_level": per,
            "training_final_error_last_pass": tested.train_err,
            "learning_on_scratch": {"final_error": scratch_err, **stats(scratch_err)},
            "references": references,
            "paper": {f"Level-{lv}": {"mean": m, "std": s} for lv, (m, s) in PAPER.items()},
        }
    )
    rep.text(
        "## Result",
        "",
        f"Task space: the square [−{HALF:g}, {HALF:g}]² around the base (every point reachable; the start tip "
        f"(10.05, 4.62) lies outside it). Training: one goal per epoch of {train_steps} steps, every goal "
        f"{REPS}× in a seeded order"
        + ("" if 4 in levels else " (Level-4's 256 goals were left out of this run to keep it within the time budget)")
        + f". Test: the frozen swarm, one episode of {eval_steps} steps per "
        f"test goal from the start configuration, error = end-effector distance at the episode's end. Per level: "
        f"mean, STD, median and the fraction within 0.5 over the {n_test} test goals, each then mean ± std over "
        "seeds.",
    )
    table(rep, tested)
    rep.text(
        f"Learner: {LEARNER_TEXT} (the configuration the README recommends for generalisation; what each of its "
        "parts buys: `kinswarm experiment ablations`, docs/results/ablations/report.md). Reward `graded` "
        "(`--reward graded`: the shaped reward's gradient inside D_min too; the control rows likewise). "
        f"Level-3's rows run on at least {L3_SEEDS} seeds: with the signed-g3 learner, seeds 0-2 gave a mean of "
        "0.233 and seeds 0-5 0.372. 'Successive test goals' tests the Level-3 swarms the "
        'paper\'s way (§5.2: "successive on-line requests"): each test goal from where the last one ended, not '
        "from the start configuration."
    )
    rep.text(
        f"Learning on, from scratch (**not** a generalisation test): an untrained swarm given one "
        f"{train_steps}-step learning episode per test goal ({len(scratch_err) // max(ctx.seeds, 1)} goals × "
        f"{ctx.seeds} seeds) ends within 0.5 in {100 * frac_within(scratch_err):.0f} % of them (mean error "
        f"{np.mean(scratch_err):.3f}, median {np.median(scratch_err):.3f})."
    )
    _references(rep, references, per, trainings[0].label if q else "Level-3", k)
    _verdict(rep, per, trainings, k, q, references)
    _figures(ctx, rep, trainings, per, tested.evals, test_sets, k, references)
    rep.write(
        {
            "topology": "examples/chain4.toml",
            "reward": REWARD,
            "learner": LEARNER_TEXT,
            "reps_per_goal": REPS,
            "train_steps": train_steps,
            "eval_steps": eval_steps,
            "test_set": k,
            "test_goals": n_test,
        },
        tested.runs,
    )
    return rep.results


def table(rep: Report, tested: Tested) -> None:
    """One row per training and test set: the paper's numbers where they apply, ours as mean ± std over seeds."""
    k = rep.ctx.test_set
    per, seeds_of, eval_steps = tested.per, tested.seeds_of, tested.eval_steps
    header = [
        "training",
        "learner",
        "reward",
        "epochs",
        "seeds",
        "test set",
        "paper mean / STD",
        "mean",
        "STD",
        "median",
        "within 0.5",
        f"mean at step {eval_steps // 2}",
    ]
    rows = []
    for t in tested.trainings:
        for block, entry in sorted(per[t.label].items()):
            paper = PAPER.get(t.level) if "control" not in t.label and block == f"test_set_{k}" else None
            rows.append(
                [
                    t.label,
                    LEARNER_NAMES.get(t.learner, t.label),
                    t.reward,
                    t.epochs,
                    len(seeds_of(t)),
                    block.rsplit("_", 1)[-1],
                    f"{paper[0]} / {paper[1]}" if paper else "—",
                    f"{entry['mean']:.3f} ± {entry['mean_std_over_seeds']:.3f}",
                    f"{entry['std']:.3f} ± {entry['std_std_over_seeds']:.3f}",
                    f"{entry['median']:.3f} ± {entry['median_std_over_seeds']:.3f}",
                    f"{100 * entry['frac_within_0_5']:.0f} ± {100 * entry['frac_within_0_5_std_over_seeds']:.0f} %",
                    pm(entry["mean_at_half_episode"]),
                ]
            )
    rep.table(header, rows)


def _references(rep: Report, references: dict, per: dict, swarm: str, k: int) -> None:
    """The model-based references' table, and how many of the swarm's misses the greedy one misses too."""
    rows = [
        [
            name,
            block.rsplit("_", 1)[-1],
            f"{e['mean']:.3f}",
            f"{e['std']:.3f}",
            f"{e['median']:.3f}",
            f"{100 * e['frac_within_0_5']:.0f} %",
            f"{e['max']:.2f}",
        ]
        for name, sets in references.items()
        for block, e in sorted(sets.items())
    ]
    rep.text(
        "### References: model-based controllers, no learning",
        "",
        "The same test goals, start configuration, episode length and 1° moves, through the same simulator; one run "
        "each (deterministic). 'pseudo-inverse' is `kinswarm baseline`; 'greedy per joint' is `kinswarm baseline "
        "--law greedy`: each joint alone takes the move (−1°, 0, +1°) that, the others held, brings the tip "
        "nearest. It knows the model; like an agent it sees only its own effect and is greedy in the distance, "
        "which is what the shaped reward pays for. Neither bounds what learning can reach: on some goals "
        "behind the start tip both end folded against a joint's ±180° limit. 'rule on g_perp' is `kinswarm baseline "
        "--law rule`: each joint one step along the sign of g_perp (the goal along the direction its own joint moves "
        "the tip), kept inside a one-move dead band; no learning and no model beyond the agent's own state — the "
        "control for what learning adds. Its successive row runs the test goals the paper's way, each from where "
        "the last ended.",
    )
    rep.table(["reference", "test set", "mean", "STD", "median", "within 0.5", "max"], rows)
    greedy = references["greedy per joint"][f"test_set_{k}"]["errors"]
    hard = {i for i, e in enumerate(greedy) if e > 0.5}
    missed = [
        (i, s) for s, errs in enumerate(per[swarm][f"test_set_{k}"]["errors"]) for i, e in enumerate(errs) if e > 0.5
    ]
    if missed:
        shared = sum(i in hard for i, _ in missed)
        rep.text(
            f"Of the {swarm} swarms' misses (error > 0.5) on test set {k}, {shared} of {len(missed)} (all seeds) are "
            f"at the {len(hard)} goals the greedy reference misses too."
        )


def _verdict(rep: Report, per: dict, trainings: list, k: int, quick: bool, references: dict) -> None:
    lines = ["## Paper | kinswarm", ""]
    for t in trainings:
        label, level = t.label, t.level
        if level not in PAPER or "control" in label:
            continue
        e = per[label][f"test_set_{k}"]
        pm_, ps_ = PAPER[level]
        ok = e["mean"] <= pm_
        lines.append(
            f"- {label} ({len(e['per_seed'])} seeds): paper mean {pm_} (STD {ps_}); kinswarm {e['mean']:.3f} ± "
            f"{e['mean_std_over_seeds']:.3f} "
            f"(STD {e['std']:.3f}), {100 * e['frac_within_0_5']:.0f} % within 0.5 — "
            + ("**as good or better**" if ok else "**worse than the paper**")
        )
    for label, entry in per.items():
        if f"test_set_{k + 1}" in entry:
            e2 = entry[f"test_set_{k + 1}"]
            lines.append(
                f"- {label} on the second test set (block {k + 1}, {len(e2['per_seed'])} seeds): mean "
                f"{e2['mean']:.3f} ± {e2['mean_std_over_seeds']:.3f}, {100 * e2['frac_within_0_5']:.0f} % within 0.5."
            )
    refs = ", ".join(
        f"{name} {e['mean']:.3f} ({100 * e['frac_within_0_5']:.0f} % within 0.5)"
        for name, sets in references.items()
        for e in (sets[f"test_set_{k}"],)
    )
    lines.append(
        f"- The model-based references (no learning) on test set {k}: {refs}; "
        f"the paper's Level-3 mean is {PAPER[3][0]}."
    )
    lines += _against_the_rule(per, references, k)
    ctl = [t for t in trainings if "control" in t.label]
    if ctl:
        c = per[ctl[0].label][f"test_set_{k}"]
        lines.append(
            f"- Goals vs epochs: Level-1's 4 goals trained for {ctl[0].epochs} epochs reach mean {c['mean']:.3f}, "
            f"{100 * c['frac_within_0_5']:.0f} % within 0.5 (Level-2's 16 goals in the same epochs: "
            f"{per['Level-2'][f'test_set_{k}']['mean']:.3f}, "
            f"{100 * per['Level-2'][f'test_set_{k}']['frac_within_0_5']:.0f} %)."
        )
    rep.text(*lines)


def _against_the_rule(per: dict, references: dict, k: int) -> list[str]:
    """What learning adds over the hand-written rule on the same state: the Level-3 frozen swarm against the rule,
    on both test sets and under the successive protocol, said plainly either way."""
    rule, rule_succ = references.get("rule on g_perp"), references.get("rule on g_perp, successive test goals")
    pairs = [
        (f"test set {b}", per.get("Level-3", {}).get(f"test_set_{b}"), (rule or {}).get(f"test_set_{b}"))
        for b in (k, k + 1)
    ]
    pairs.append(
        (
            "successive test goals",
            per.get("Level-3, successive test goals", {}).get(f"test_set_{k}"),
            (rule_succ or {}).get(f"test_set_{k}"),
        )
    )
    out = []
    for what, swarm, r in pairs:
        if swarm is None or r is None:
            continue
        verdict = "the trained swarm is **better**" if swarm["mean"] < r["mean"] else "**the rule is better**"
        out.append(
            f"- Against the rule on g_perp (no learning, no model), {what}: Level-3 frozen {swarm['mean']:.3f} "
            f"({100 * swarm['frac_within_0_5']:.0f} % within 0.5), the rule {r['mean']:.3f} "
            f"({100 * r['frac_within_0_5']:.0f} %): {verdict}."
        )
    return out


def _figures(
    ctx: Context,
    rep: Report,
    trainings: list,
    per: dict,
    evals: dict[tuple[str, int, int], RunOutcome],
    test_sets: dict,
    k: int,
    references: dict,
) -> None:
    plt = plt_module()
    # Fig. 12: mean and STD per level.
    main = [t for t in trainings if t.main]
    fig, ax = plt.subplots(figsize=(6, 4))
    xs = [t.level for t in main]
    for key, fmt, label in (("mean", "o-", "kinswarm mean"), ("std", "s--", "kinswarm STD")):
        ax.errorbar(
            xs,
            [per[t.label][f"test_set_{k}"][key] for t in main],
            [per[t.label][f"test_set_{k}"][f"{key}_std_over_seeds"] for t in main],
            fmt=fmt,
            capsize=3,
            label=label,
        )
    ax.plot(list(PAPER), [m for m, _ in PAPER.values()], "k*", ms=10, label="paper mean")
    ax.plot(list(PAPER), [s for _, s in PAPER.values()], "kx", ms=9, label="paper STD")
    ax.set_xticks(xs, [f"L{x}\n({4**x} goals)" for x in xs])
    ax.set_ylabel("test error over 100 goals")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    ax.set_title("Fig. 12 analogue: error on unseen goals per training level (± std over seeds)", fontsize=9)
    rep.save_figure(fig, "levels.png", "Fig. 12 analogue: mean and STD of the test error per level")

    # Fig. 11: error map (seed 0), lowest and highest level.
    show = [main[0], main[-1]] if len(main) > 1 else main
    fig, axes = plt.subplots(1, len(show), figsize=(5.4 * len(show), 4.8), squeeze=False)
    for ax, (label, level) in zip(axes[0], ((t.label, t.level) for t in show), strict=True):
        r = evals[(label, k, 0)]
        pts = np.array(test_sets[k])
        err = np.array(r.final_errors)
        sc = ax.scatter(
            pts[:, 0],
            pts[:, 1],
            c=np.clip(err, 1e-3, None),
            cmap="viridis_r",
            s=36,
            norm=_lognorm(),
            edgecolors="k",
            linewidths=0.3,
        )
        tg = np.array(quadtree(level))
        ax.plot(tg[:, 0], tg[:, 1], "r+", ms=6, label="training goals")
        ax.plot(0, 0, "ks", ms=6, label="base")
        ax.plot(10.05, 4.62, "k^", ms=6, label="start tip")
        ax.add_patch(plt.Rectangle((-HALF, -HALF), 2 * HALF, 2 * HALF, fill=False, ls=":", color="grey"))
        ax.set_aspect("equal")
        ax.set_title(f"{label}: final error per test goal (seed 0)", fontsize=9)
        ax.legend(fontsize=7, loc="lower left")
        fig.colorbar(sc, ax=ax, label="final error")
    rep.save_figure(
        fig, "error_map.png", "Fig. 11 analogue: error over the task space for the lowest and highest level"
    )

    cdf(rep, [t.label for t in trainings], per, k, references)


def cdf(rep: Report, labels: list[str], per: dict, k: int, references: dict) -> None:
    """cdf.png: the test errors' distribution per training, the model-based references dashed."""
    plt = plt_module()
    fig, ax = plt.subplots(figsize=(7, 3.8))
    for i, label in enumerate(labels):
        errs = np.sort(np.concatenate([np.asarray(e) for e in per[label][f"test_set_{k}"]["errors"]]))
        ax.plot(np.clip(errs, 1e-3, None), np.arange(1, len(errs) + 1) / len(errs), color=f"C{i}", label=label)
    for ls, (name, sets) in zip(("--", ":"), references.items(), strict=False):
        errs = np.sort(sets[f"test_set_{k}"]["errors"])
        ax.plot(
            np.clip(errs, 1e-3, None), np.arange(1, len(errs) + 1) / len(errs), "k" + ls, label=f"{name} (no learning)"
        )
    ax.axvline(0.5, color="grey", ls="--", lw=0.8)
    ax.set_xscale("log")
    ax.set_xlabel("final error on a test goal")
    ax.set_ylabel("fraction of test goals (all seeds)")
    ax.legend(fontsize=7)
    ax.grid(alpha=0.3)
    rep.save_figure(fig, "cdf.png", "Cumulative distribution of the test errors per training configuration")


def _lognorm() -> Any:
    from matplotlib.colors import LogNorm

    return LogNorm(vmin=1e-2, vmax=10)
