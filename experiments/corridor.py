"""§5.4, Fig. 23: a 7-DOF planar chain reaching a target 2.5 deep inside a narrow corridor (examples/corridor7.toml:
links of length 1 and radius 0.1, walls 0.8 apart spanning x in [3, 6] around y = 2), and at the relaxed set-up
(walls 1.2 apart, the target 1.0 deep).

The product's corridor: Eq. 11 as printed (the paper's claim: its six state variables and the default learner) and
the recommended recipe, run from its two files: examples/corridor7-inner200.toml (200 epochs) and
examples/corridor7-blame260.toml (60 more from that swarm, the learning rate annealed to 0 and the fictitious-play
counts frozen, so the last epochs run what a frozen swarm runs, and the blame: an agent whose move was applied while
a move below it was refused pays too). The controls: the untrained swarm, and the second stage without the blame
(examples/corridor7-freeze260.toml); the recipe's rows for the independent and tabular learner kinds (KINDS), each
on its own first stage. At the relaxed set-up the same two stages with the swing margin (RELAXED1, RELAXED2: outside
D_min a link within 0.25 of a wall costs the root's reward what a refused move does), its untrained swarm, and the
two stages without the margin as the control. Each trained swarm then runs one frozen epoch with nothing added
(`--learn off --explore off --set task.collision_tabu=false`); two more frozen epochs add decision rules that change
nothing learned: the tabu, and the tabu and the shield (EVAL_SHIELD). The bars, per seed:

  training  the share of the last TAIL training epochs that end within TOL of the target with no collision (refused
            penetrating increment) in the epoch's last LAST_STEPS steps; bar: >= 80 % over 5 seeds
  frozen    the frozen epoch ends within TOL of the target with zero collisions in the whole epoch; bar: >= 4 of 5

How the recipe was found, configuration by configuration (studies 1-11): experiments/research/corridor_studies.py,
which runs the same machinery (`run_configs`) on every configuration tried, study 12's probes
experiments/research/corridor_compound.py, and docs/notebook/corridor.md.
"""

from __future__ import annotations

import dataclasses
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from kinswarm.actors.report.scene_plot import draw_chain, draw_scene, plot_scene_epochs

from .common import Context, Report, band, mean_std, plt_module, pm, run_specs
from .swarm import ROOT, RunOutcome, Spec, resolved

TOPOLOGY = ROOT / "examples" / "corridor7.toml"
STAGE1 = ROOT / "examples" / "corridor7-inner200.toml"
STAGE2 = ROOT / "examples" / "corridor7-freeze260.toml"
RECIPE = ROOT / "examples" / "corridor7-blame260.toml"  # the second stage as recommended: STAGE2 with the blame
#: the recipe at the relaxed set-up (walls 1.2 apart, the target 1.0 deep) with the swing margin, its two stages
RELAXED1 = ROOT / "examples" / "corridor7-relaxed-swing200.toml"
RELAXED2 = ROOT / "examples" / "corridor7-relaxed-swing260.toml"
TOL = 0.3  # "within 0.3 of the target"
TAIL = 50  # the last 50 training epochs
LAST_STEPS = 100  # no collision in the epoch's last 100 steps
STEPS = 500
QUICK_EPOCHS, QUICK_STEPS = 3, 100
#: the third frozen evaluation's shield ([scene] shield; study 7: 0.02 left 4 of 5 subtree-200 swarms without a
#: refusal; 0.05 kept them further from the target, 0.01 let two jam, docs/notebook/corridor.md)
EVAL_SHIELD = 0.02
SEEDS = 5  # the bars' seeds
#: the learner kinds beside the paper's (fuzzy Q over joint actions, JASM) on the same recipe: without the model of
#: the children (independent) and without the fuzzy interpolation (tabular)
KINDS = ("independent", "tabular")
REFERENCE_SEEDS = 2  # references run on fewer seeds in the full version


@dataclass(frozen=True)
class Config:
    """One corridor configuration: a run file and what is set over it; `continues`: the configuration whose trained
    swarms it trains on (`--from`); `seeds`: how many seeds at full size (all with --quick)."""

    file: Path
    epochs: int
    reward: str | None = None
    task: dict[str, Any] = field(default_factory=dict)
    learner: dict[str, Any] = field(default_factory=dict)
    continues: str | None = None
    seeds: int = SEEDS
    text: str = ""
    untrained: bool = False  # a control: the swarm as it starts (one epoch, learning and exploration off)


def _recipe_stage2(kind: str) -> Config:
    """The recipe's second stage for another learner kind, on that kind's first stage. The independent learner has
    no counts to freeze (it refuses `count_freeze`), so it runs the first stage's file with the second stage's other
    settings (the anneal, the blame) set over it; the tabular one takes the stage file as it is."""
    if kind != "independent":
        return Config(RECIPE, 60, learner={"kind": kind}, continues=f"inner-200-{kind}", text=f"blame-260, {kind}")
    learner = {k: v for k, v in _own(STAGE2, "learner").items() if k != "count_freeze"}
    return Config(
        STAGE1,
        60,
        task=_own(RECIPE, "task"),
        learner={"kind": kind, **learner},
        continues=f"inner-200-{kind}",
        text=f"blame-260, {kind} (no counts to freeze)",
    )


def _own(file: Path, table: str) -> dict[str, Any]:
    """A run file's own [table], without its base's."""
    return dict(tomllib.loads(file.read_text()).get(table, {}))


CONFIGS: dict[str, Config] = {
    "untrained": Config(STAGE1, 0, untrained=True, text="the swarm as it starts (a control)"),
    "paper": Config(
        TOPOLOGY, 100, reward="paper", seeds=REFERENCE_SEEDS, text="Eq. 11 as printed, the paper's state, 100 epochs"
    ),
    "inner-200": Config(STAGE1, 200, text="the recipe's first stage: examples/corridor7-inner200.toml"),
    "freeze-260": Config(
        STAGE2, 60, continues="inner-200", text="its second stage: examples/corridor7-freeze260.toml, 60 epochs more"
    ),
    "blame-260": Config(
        RECIPE,
        60,
        continues="inner-200",
        text="the recipe's second stage: examples/corridor7-blame260.toml (freeze-260 with the blame), 60 epochs more",
    ),
    **{
        label: config
        for kind in KINDS
        for label, config in (
            (
                f"inner-200-{kind}",
                Config(STAGE1, 200, learner={"kind": kind}, text=f"inner-200, `--set learner.kind={kind}`"),
            ),
            (f"blame-260-{kind}", _recipe_stage2(kind)),
        )
    },
    "relaxed-untrained": Config(RELAXED1, 0, untrained=True, text="the swarm as it starts, at the relaxed set-up"),
    "relaxed-margin-200": Config(
        RELAXED1, 200, text="the relaxed recipe's first stage: examples/corridor7-relaxed-swing200.toml"
    ),
    "relaxed-margin-260": Config(
        RELAXED2,
        60,
        continues="relaxed-margin-200",
        text="its second stage: examples/corridor7-relaxed-swing260.toml (as blame-260 continues inner-200)",
    ),
    # the control: the same two stages without the swing margin (study 13's research probes relaxed-200, relaxed-blame)
    "relaxed-nomargin-200": Config(
        RELAXED1, 200, task={"swing_margin": 0.0}, text="relaxed-margin-200 without the margin"
    ),
    "relaxed-nomargin-260": Config(
        RELAXED2,
        60,
        task={"swing_margin": 0.0},
        continues="relaxed-nomargin-200",
        text="relaxed-margin-260 without the margin",
    ),
}
#: the configurations drawn in the report's figures (each figure has a panel per configuration)
FIGURES = ("paper", "freeze-260", "blame-260", "blame-260-independent", "blame-260-tabular", "relaxed-margin-260")


def run(ctx: Context) -> dict[str, Any]:
    rep = Report(ctx, "Corridor: a 7-DOF chain into a narrow corridor", "5.4, Fig. 23")
    intro = (
        "## Set-up",
        "",
        f"`{TOPOLOGY.relative_to(ROOT)}`: 7 links of length 1 (capsules of radius 0.1), walls spanning x in [3, 6] "
        "with a gap of 0.8 around y = 2, target (5.5, 2.0) 2.5 deep, start angles (90, -5, ..., -5) deg. Walls are "
        "solid: an increment that would make a link penetrate a wall is refused (the joint holds) and counted as a "
        "collision. The relaxed set-up (`examples/corridor7-relaxed-swing200.toml`): walls 1.2 apart, target (4, 2) "
        "1.0 deep, the same chain and start. Configurations: "
        + "; ".join(f"`{label}`: {c.text}" for label, c in CONFIGS.items())
        + ". Each trained swarm then runs one frozen epoch with nothing added (`--learn off --explore off --set "
        "task.collision_tabu=false`: no tabu even where training had it); a second adds the tabu "
        "(`--set task.collision_tabu=true`: a refused move is not chosen at the next step), a third the tabu and "
        f"the shield (`--set scene.shield={EVAL_SHIELD}`: the walls veto a move that alone would bring the links "
        "it moves nearer a wall than that) — decision rules at evaluation only; nothing learned changes. The "
        "recipe: `kinswarm run examples/corridor7-inner200.toml --out runs/corridor7-inner200`, then `kinswarm "
        "run examples/corridor7-blame260.toml`; at the relaxed set-up examples/corridor7-relaxed-swing200.toml, then "
        "corridor7-relaxed-swing260.toml. A bar counts as met only with >= 5 seeds.",
    )
    return run_configs(ctx, rep, CONFIGS, intro)


def run_configs(ctx: Context, rep: Report, configs: dict[str, Config], intro: tuple[str, ...]) -> dict[str, Any]:
    """Train every configuration on its seeds (continuations from their base's swarms), evaluate each trained swarm
    frozen three ways, and write the report."""
    steps = QUICK_STEPS if ctx.quick else STEPS
    seeds_of = {label: ctx.seed_list if ctx.quick else ctx.seed_list[: c.seeds] for label, c in configs.items()}

    def spec(label: str, seed: int, **kw: Any) -> Spec:
        c = configs[label]
        base = dict(seed=seed, steps=steps, reward=c.reward, file=str(c.file))
        base |= dict(task=tuple(sorted(c.task.items())), learner=tuple(sorted(c.learner.items())))
        return Spec(**{**base, **kw})

    def first(label: str, seed: int) -> Spec:
        c = configs[label]
        if c.untrained:
            return spec(label, seed, name=f"corr-{label}", epochs=1, learn=False, explore=False)
        return spec(label, seed, name=f"corr-{label}", epochs=_epochs(ctx, c), checkpoint=True)

    train = {
        (label, seed): first(label, seed)
        for label, c in configs.items()
        if c.continues is None
        for seed in seeds_of[label]
    }
    trained = dict(zip(train, run_specs(ctx, list(train.values()), "train"), strict=True))
    more = {
        (label, seed): spec(
            label,
            seed,
            name=f"corr-{label}",
            epochs=_epochs(ctx, c),
            from_dir=str(trained[(c.continues, seed)].out),
            checkpoint=True,
        )
        for label, c in configs.items()
        if c.continues is not None
        for seed in seeds_of[label]
    }
    for key, out in zip(more, run_specs(ctx, list(more.values()), "continue"), strict=True):
        prior = trained[(configs[key[0]].continues, key[1])]  # type: ignore[index]
        trained[key] = dataclasses.replace(out, rows=prior.rows + out.rows)  # the whole history, base's and its own
    train |= more
    frozen_specs = {  # an untrained swarm (no checkpoint: it learned nothing) starts as a fresh one
        key: dataclasses.replace(
            s,
            name=f"{s.name}-frozen",
            epochs=1,
            from_dir=None if configs[key[0]].untrained else str(trained[key].out),
            learn=False,
            explore=False,
        )
        for key, s in train.items()
    }
    evals = {  # the frozen epoch with nothing added: no tabu even where training had it, no shield
        "frozen": {
            k: dataclasses.replace(_with(s, "plain", task={"collision_tabu": False}), name=s.name, observe=True)
            for k, s in frozen_specs.items()
        },
        "tabu": {k: _with(s, "tabu", task={"collision_tabu": True}) for k, s in frozen_specs.items()},
        "shield": {
            k: _with(s, "shield", task={"collision_tabu": True}, scene={"shield": EVAL_SHIELD})
            for k, s in frozen_specs.items()
        },
    }
    done = {
        name: dict(zip(specs, run_specs(ctx, list(specs.values()), f"frozen {name}"), strict=True))
        for name, specs in evals.items()
    }
    per: dict[str, dict[str, Any]] = {}
    for label, c in configs.items():
        seeds = {
            s: seed_metrics(trained[(label, s)], *(done[n][(label, s)] for n in ("frozen", "tabu", "shield")))
            for s in seeds_of[label]
        }
        shares = [m["success_last"] for m in seeds.values()]
        n_frozen = sum(m["frozen_success"] for m in seeds.values())
        per[label] = {
            "file": str(c.file.relative_to(ROOT)),
            "reward": c.reward,
            "task": c.task,
            "learner": c.learner,
            "continues": c.continues,
            "seeds": seeds,
            "success_last_mean": mean_std(shares)[0],
            "frozen_successes": n_frozen,
            "frozen_tabu_successes": sum(m["tabu_success"] for m in seeds.values()),
            "frozen_shield_successes": sum(m["shield_success"] for m in seeds.values()),
            "frozen_shield_zero_collisions": sum(m["shield_collisions"] == 0 for m in seeds.values()),
            "bar_training_met": bool(len(shares) >= SEEDS and mean_std(shares)[0] >= 0.8),
            "bar_frozen_met": bool(len(seeds) >= SEEDS and n_frozen >= 4),
        }
    rep.results.update({"steps": steps, "tol": TOL, "tail": TAIL, "configs": per})
    rep.text(*intro)
    _tables(rep, per)
    _figures(rep, configs, per, trained, done["frozen"], seeds_of)
    rep.write(
        {"steps_per_epoch": steps, "configs": {k: dataclasses.asdict(c) for k, c in configs.items()}},
        [
            *trained.values(),
            *(o for d in done.values() for o in d.values()),
        ],
    )
    return rep.results


def _epochs(ctx: Context, c: Config) -> int:
    return QUICK_EPOCHS if ctx.quick else c.epochs


def _with(s: Spec, what: str, task: dict[str, Any] | None = None, scene: dict[str, Any] | None = None) -> Spec:
    """A frozen evaluation with a decision rule added (nothing learned changes)."""
    t = tuple(sorted({**dict(s.task), **(task or {})}.items()))
    return dataclasses.replace(s, name=f"{s.name}-{what}", task=t, scene=tuple(sorted((scene or {}).items())))


def collisions(row: dict[str, Any]) -> list[float]:
    """An epoch's refused moves per step (the walls scene's trace)."""
    return row["traces"]["collisions"]


def seed_metrics(train: RunOutcome, frozen: RunOutcome, tabu: RunOutcome, shield: RunOutcome) -> dict[str, Any]:
    rows = train.rows
    tail = rows[-TAIL:]
    ok = [r["final_error"] <= TOL and sum(collisions(r)[-LAST_STEPS:]) == 0 for r in tail]
    within = [r["final_error"] <= TOL for r in tail]
    strict = [r["final_error"] <= TOL and sum(collisions(r)) == 0 for r in tail]
    f = frozen.rows[0]
    return {
        "success_last": sum(ok) / len(ok),  # within TOL and no collision in the last 100 steps
        "within_last": sum(within) / len(within),
        # the frozen bar's conditions (no collision in the whole epoch) on each training epoch: once the learning
        # rate is 0 (lr_anneal) the frozen epoch is one draw from these (study 9)
        "strict_last": sum(strict) / len(strict),
        "median_final_last": float(np.median([r["final_error"] for r in tail])),
        "collisions_per_epoch_last": float(np.mean([sum(collisions(r)) for r in tail])),
        "collisions_per_epoch_first10": float(np.mean([sum(collisions(r)) for r in rows[:10]])),
        "first_success_epoch": next(
            (r["epoch"] for r in rows if r["final_error"] <= TOL and sum(collisions(r)[-LAST_STEPS:]) == 0), None
        ),
        **_frozen_metrics("frozen", f),
        "frozen_collisions_last100": sum(collisions(f)[-LAST_STEPS:]),
        "frozen_min_clearance": min(f["traces"]["clearance"]),
        **_frozen_metrics("tabu", tabu.rows[0]),
        **_frozen_metrics("shield", shield.rows[0]),
        "train_run": train.out.name,
        "frozen_run": frozen.out.name,
    }


def _frozen_metrics(prefix: str, row: dict[str, Any]) -> dict[str, Any]:
    """A frozen epoch's final error, collisions and success (the frozen bar: within TOL, no collision at all)."""
    n = round(sum(collisions(row)))
    return {
        f"{prefix}_final_error": row["final_error"],
        f"{prefix}_collisions": n,
        f"{prefix}_success": bool(row["final_error"] <= TOL and n == 0),
    }


def _tables(rep: Report, per: dict[str, dict[str, Any]]) -> None:
    rows = []
    for label, p in per.items():
        for seed, m in p["seeds"].items():
            evals = [
                f"{m[f'{e}_final_error']:.3f} / {m[f'{e}_collisions']} / {'yes' if m[f'{e}_success'] else 'no'}"
                for e in ("frozen", "tabu", "shield")
            ]
            rows.append(
                [
                    label,
                    seed,
                    f"{100 * m['success_last']:.0f} %",
                    f"{100 * m['within_last']:.0f} %",
                    f"{100 * m['strict_last']:.0f} %",
                    f"{m['median_final_last']:.3f}",
                    f"{m['collisions_per_epoch_first10']:.0f} → {m['collisions_per_epoch_last']:.1f}",
                    "—" if m["first_success_epoch"] is None else m["first_success_epoch"],
                    *evals,
                ]
            )
    rep.text("## Per seed", "")
    rep.table(
        [
            "config",
            "seed",
            f"last {TAIL}: within {TOL}, no collision in last {LAST_STEPS} steps",
            f"last {TAIL}: within {TOL}",
            f"last {TAIL}: within {TOL}, no collision at all",
            f"median final error, last {TAIL}",
            "collisions / epoch (first 10 → last 50)",
            "first such epoch",
            "frozen: error / collisions / success",
            "frozen + tabu",
            "frozen + tabu + shield",
        ],
        rows,
    )
    summary = []
    for label, p in per.items():
        n = len(p["seeds"])
        shares = [m["success_last"] for m in p["seeds"].values()]
        summary.append(
            [
                label,
                n,
                pm([100 * s for s in shares], 0) + " %",
                f"{p['frozen_successes']} of {n} ({p['frozen_tabu_successes']} with tabu, "
                f"{p['frozen_shield_successes']} with tabu + shield)",
                f"{p['frozen_shield_zero_collisions']} of {n}",
                "met" if p["bar_training_met"] else "not met",
                "met" if p["bar_frozen_met"] else "not met",
            ]
        )
    rep.text(
        "## Paper | kinswarm",
        "",
        "The paper (Fig. 23) shows the chain entering the corridor and reaching the target on a collision-free path, "
        "with no numbers. The bars: over 5 seeds, >= 80 % of the last 50 training epochs within 0.3 with no "
        "collision in the last 100 steps, and the frozen swarm reaching the target with zero collisions in >= 4 of "
        "5 seeds.",
    )
    rep.table(
        [
            "config",
            "seeds",
            f"last {TAIL}: success (mean ± std)",
            "frozen successes",
            "frozen + tabu + shield: zero collisions",
            "training bar",
            "frozen bar",
        ],
        summary,
    )


def _figures(
    rep: Report,
    configs: dict[str, Config],
    per: dict[str, Any],
    trained: dict[tuple[str, int], RunOutcome],
    frozen: dict[tuple[str, int], RunOutcome],
    seeds_of: dict[str, list[int]],
) -> None:
    plt = plt_module()
    labels = [label for label in configs if label in FIGURES] or list(configs)
    scenes = {label: resolved(configs[label].file) for label in labels}

    def scene_of(label: str) -> tuple[Any, Any, tuple[float, float]]:
        cfg = scenes[label]
        return cfg.topo(), cfg.scene_spec.obstacles, tuple(cfg.task["goal"])

    # Fig. 23: the final configuration over training epochs (first seed), per configuration
    fig, axes = plt.subplots(1, len(labels), figsize=(6.2 * len(labels), 6.0), squeeze=False)
    for ax, label in zip(axes[0], labels, strict=True):
        seed = seeds_of[label][0]
        topo, walls, goal = scene_of(label)
        plot_scene_epochs(
            ax, topo, walls, goal, trained[(label, seed)].rows, f"{label}, seed {seed}: final configurations"
        )
    rep.save_figure(fig, "corridor.png", "Fig. 23 analogue: the chain's final configuration across training epochs")

    # the frozen swarm's path: the chain every 50 steps and the tip's path, per seed
    seeds = max(len(seeds_of[label]) for label in labels)
    fig, axes = plt.subplots(len(labels), seeds, figsize=(4.2 * seeds, 4.2 * len(labels)), squeeze=False)
    for row, label in enumerate(labels):
        topo, walls, goal = scene_of(label)
        for col in range(seeds):
            ax = axes[row, col]
            if col >= len(seeds_of[label]):
                ax.axis("off")
                continue
            seed = seeds_of[label][col]
            tr = frozen[(label, seed)].trace()
            draw_scene(ax, topo, walls, goal)
            q, agents = tr["q"], [str(a) for a in tr["agents"]]
            picks = list(range(0, len(q), 50)) + [len(q) - 1]
            cmap = plt.get_cmap("viridis")
            for i, n in enumerate(picks):
                angles = dict(zip(agents, q[n].tolist(), strict=True))
                draw_chain(ax, topo, angles, color=cmap(i / max(len(picks) - 1, 1)), lw=1.0, ms=2)
            ax.plot(tr["tip"][:, 0], tr["tip"][:, 1], color="C3", lw=0.8)
            m = per[label]["seeds"][seed]
            ax.set_title(
                f"{label}, seed {seed}: frozen, error {m['frozen_final_error']:.2f}, {m['frozen_collisions']} coll.",
                fontsize=8,
            )
    caption = "The frozen swarm (no learning, no exploration): the chain every 50 steps, tip path red"
    rep.save_figure(fig, "frozen.png", caption)

    # learning: final error and collisions per epoch, mean over seeds with a min-max band
    fig, axes = plt.subplots(1, 2, figsize=(12, 4))
    for i, label in enumerate(labels):
        runs = [trained[(label, s)] for s in seeds_of[label]]
        band(axes[0], [r.final_errors for r in runs], label, color=f"C{i}")
        band(axes[1], [[sum(collisions(row)) for row in r.rows] for r in runs], label, color=f"C{i}")
    axes[0].axhline(TOL, color="grey", ls="--", lw=0.8)
    axes[0].set_ylabel("final error")
    axes[1].set_ylabel("collisions (refused increments) per epoch")
    for ax in axes:
        ax.set_xlabel("epoch")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8, loc="upper right")
    caption = "Final error and collisions per training epoch (mean over seeds, band min-max)"
    rep.save_figure(fig, "learning.png", caption)
