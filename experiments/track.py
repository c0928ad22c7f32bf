"""Track (ours, not the paper's): the 4-joint chain follows a goal going round a circle (examples/chain4-track.toml:
radius 2 around (6, 4), one lap in an epoch's 500 steps). The task that proved the task interface: one module
(actors/tasks/track.py), one run file, no change to the agent, the supervisor or the simulator.

Per seed: a swarm trained EPOCHS epochs on the lap (reward `graded`, the file's; and `shaped` beside it), its
tracking error while learning (the last TAIL epochs), then frozen (`--learn off --explore off`, one lap); controls on
the same lap: an untrained swarm frozen, and the pseudo-inverse (the model-based reference, which follows the step's
goal). The tracking error of a lap is the mean over its steps from SKIP on (the first steps close the gap between the
start pose and the path's start), and the largest over those steps.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from .common import Context, Report, mean_std, plt_module, pm, run_specs
from .swarm import ROOT, RunOutcome, Spec, resolved

TRACK = ROOT / "examples" / "chain4-track.toml"
EPOCHS, STEPS = 60, 500
QUICK_EPOCHS = 3
TAIL = 10  # the last epochs of training
SKIP = 50  # steps left out of a lap's error: closing the gap from the start pose


def lap_error(row: dict[str, Any]) -> tuple[float, float]:
    """(mean, max) tracking error of one epoch over its steps from SKIP on."""
    e = np.asarray(row["errors"][SKIP:] or row["errors"])
    return float(e.mean()), float(e.max())


def run(ctx: Context) -> dict[str, Any]:
    epochs = QUICK_EPOCHS if ctx.quick else EPOCHS
    base = {"file": str(TRACK), "steps": STEPS}
    train = {
        (reward, s): Spec(f"track-{reward}", seed=s, epochs=epochs, reward=reward, checkpoint=True, **base)
        for reward in ("graded", "shaped")
        for s in ctx.seed_list
    }
    trained = dict(zip(train, run_specs(ctx, list(train.values()), "train"), strict=True))
    frozen_specs = {
        k: Spec(
            f"track-{k[0]}-frozen",
            seed=k[1],
            epochs=1,
            reward=k[0],
            from_dir=str(o.out),
            learn=False,
            explore=False,
            observe=True,
            **base,
        )  # fmt: skip
        for k, o in trained.items()
    }
    untrained_specs = {
        s: Spec("track-untrained-frozen", seed=s, epochs=1, learn=False, explore=False, observe=True, **base)
        for s in ctx.seed_list
    }
    pinv_spec = Spec("track-pinv", seed=0, epochs=1, controller="pinv", observe=True, **base)
    rule_spec = Spec("track-rule", seed=0, epochs=1, controller="rule", observe=True, **base)
    runs = run_specs(ctx, [*frozen_specs.values(), *untrained_specs.values(), pinv_spec, rule_spec], "evaluate")
    frozen = dict(zip(frozen_specs, runs[: len(frozen_specs)], strict=True))
    untrained = dict(zip(untrained_specs, runs[len(frozen_specs) : -2], strict=True))
    pinv, rule = runs[-2], runs[-1]

    per: dict[str, dict[str, Any]] = {}
    for reward in ("graded", "shaped"):
        per[f"learning ({reward}), last {TAIL} epochs"] = _stats(
            [[lap_error(r) for r in trained[(reward, s)].rows[-TAIL:]] for s in ctx.seed_list]
        )
        per[f"frozen ({reward})"] = _stats([[lap_error(frozen[(reward, s)].rows[0])] for s in ctx.seed_list])
    per["untrained, frozen"] = _stats([[lap_error(untrained[s].rows[0])] for s in ctx.seed_list])
    per["pseudo-inverse"] = _stats([[lap_error(pinv.rows[0])]])
    per["rule on g_perp (no learning)"] = _stats([[lap_error(rule.rows[0])]])

    rep = Report(ctx, "Track: following a goal round a circle", "ours (the task interface's test)")
    cfg = resolved(TRACK)
    circle = cfg.task["circle"]
    rep.text(
        "## Set-up",
        "",
        f"`{TRACK.relative_to(ROOT)}`: the chain of examples/chain4.toml (4 links of 3, start (0, 10, 20, 30) deg); "
        f"the goal goes round a circle of radius {circle['radius']:g} around ({circle['center'][0]:g}, "
        f"{circle['center'][1]:g}) at {cfg.task['speed']:g} per step, one lap in {STEPS} steps, starting at "
        f"({circle['center'][0] + circle['radius']:g}, {circle['center'][1]:g}), 2.1 from the start pose's tip. "
        f"Training: {epochs} epochs, the same lap each epoch. A lap's tracking error: the mean (and max) distance "
        f"from the tip to the step's goal over steps {SKIP}-{STEPS - 1}. The reward pays each move against the goal "
        "the agents saw when they chose it (actors/tasks/track.py).",
        "",
        "## Results",
        "",
    )
    rep.table(
        ["controller", "laps", "tracking error, mean over seeds", "max error in a lap (mean over seeds)"],
        [[k, v["n"], pm(v["mean_per_seed"]), pm(v["max_per_seed"])] for k, v in per.items()],
    )
    g, p, r = per["frozen (graded)"], per["pseudo-inverse"], per["rule on g_perp (no learning)"]
    rep.text(
        "",
        f"The frozen swarm tracks the lap with a mean error of {mean_std(g['mean_per_seed'])[0]:.3f} "
        f"against the pseudo-inverse's {mean_std(p['mean_per_seed'])[0]:.3f}: a model-based controller that knows the "
        "kinematics and aims at the step's goal is better at tracking, as expected; the swarm has no model. The "
        "untrained swarm frozen shows what training adds on this lap. This is one lap, trained and tested on the "
        "same path: not a generalisation test. With learning on, the swarm keeps correcting during the lap.",
        "",
        f"The rule on g_perp (each joint one step along the goal's component in its own direction of motion, no "
        f"learning, no model: `kinswarm baseline --law rule`) tracks with {mean_std(r['mean_per_seed'])[0]:.3f}: "
        + (
            "**better than the trained swarm** — on this lap learning buys nothing over the hand-written rule."
            if mean_std(r["mean_per_seed"])[0] < mean_std(g["mean_per_seed"])[0]
            else "worse than the trained swarm."
        ),
    )
    rep.results.update({"tail": TAIL, "skip": SKIP, "epochs": epochs, "steps": STEPS, "per": per})
    _figures(rep, trained, frozen, untrained, pinv, rule, ctx.seed_list[0])
    rep.write({"file": str(TRACK.relative_to(ROOT)), "task": cfg.task}, [*trained.values(), *runs])
    return rep.results


def _stats(laps: list[list[tuple[float, float]]]) -> dict[str, Any]:
    """Per seed: the mean over its laps of each lap's mean and max error."""
    return {
        "n": sum(len(x) for x in laps),
        "mean_per_seed": [float(np.mean([m for m, _ in x])) for x in laps],
        "max_per_seed": [float(np.mean([mx for _, mx in x])) for x in laps],
    }


def _figures(
    rep: Report,
    trained: dict[tuple[str, int], RunOutcome],
    frozen: dict[tuple[str, int], RunOutcome],
    untrained: dict[int, RunOutcome],
    pinv: RunOutcome,
    rule: RunOutcome,
    seed: int,
) -> None:
    plt = plt_module()
    fig, axes = plt.subplots(1, 2, figsize=(13, 4.5))
    ax = axes[0]
    runs = {
        f"learning, last epoch (seed {seed})": trained[("graded", seed)].rows[-1],
        "frozen (graded)": frozen[("graded", seed)].rows[0],
        "untrained, frozen": untrained[seed].rows[0],
        "pseudo-inverse": pinv.rows[0],
        "rule on g_perp": rule.rows[0],
    }
    for i, (label, row) in enumerate(runs.items()):
        ax.plot(row["errors"], label=label, lw=1.0, color=f"C{i}")
    ax.axvline(SKIP, color="grey", ls=":", lw=0.8)
    ax.set_xlabel("step")
    ax.set_ylabel("distance from the tip to the step's goal")
    ax.set_ylim(0, max(1.0, min(4.0, max(max(r["errors"]) for r in runs.values()))))
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    ax = axes[1]
    path = np.array(resolved_path())
    ax.plot(path[:, 0], path[:, 1], "k--", lw=1.0, label="the goal's path")
    for i, (label, out) in enumerate(
        (
            ("frozen (graded)", frozen[("graded", seed)]),
            ("untrained, frozen", untrained[seed]),
            ("pseudo-inverse", pinv),
            ("rule on g_perp", rule),
        )
    ):
        tip = out.trace()["tip"]
        ax.plot(tip[:, 0], tip[:, 1], lw=1.0, color=f"C{i + 1}", label=f"tip: {label}")
    ax.set_aspect("equal")
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="lower left")
    ax.set_title(f"one lap, seed {seed}", fontsize=9)
    rep.save_figure(fig, "tracking.png", "The tracking error over a lap, and the tip's path against the goal's")


def resolved_path() -> list[tuple[float, float]]:
    from kinswarm.actors.files.runfile import task_of

    return task_of(resolved(TRACK)).goal(0, STEPS)[1]
