"""Reaching in 3D on a real arm (examples/iiwa.toml: PyBullet's KUKA LBR iiwa, 7 agents): train on goals spread over
the workspace, each from a random start pose, then test the frozen swarm on unseen goals from unseen start poses,
beside its controls on the same goals and starts:

  trained, frozen     the swarm after training, learning and exploration off (`--from T --learn off --explore off`)
  untrained, frozen   the same learner never trained (its greedy choices from a zero Q)
  blind, frozen       trained alike, but its state sees only q (every other variable 2 sets over ±1000: no
                      information); what the rotation-plane state itself buys
  rule                each joint one step along sign(g_perp) (`kinswarm baseline --law rule`): no learning, no model
  pseudo-inverse      resolved-rate control on the model (`--law pinv`); greedy per joint (`--law greedy`)

Goals are the tool points of random joint configurations (uniform within 90 % of every joint's range, so far
goals and goals behind the base occur), kept when they lie 5 cm or more above the base's plane; start poses are
other random configurations. Two disjoint test sets of 100 ("A", "B") check that a number does not hang on its set.
Poses (position and the tool's orientation, success within 5 cm and 15°) run the same protocol. The locked-joint
scenario locks the shoulder (a2) throughout; the disturbed one shakes the elbow (a4) in steps 100-199 of every trial:
trained frozen, trained still learning, an untrained swarm learning, the rule and the pseudo-inverse, on test set A's
goals.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from kinswarm.protocol import frames
from kinswarm.protocol.topology import Topology, load_robot

from .common import Context, Report, mean_std, plt_module, pm, run_specs, settings
from .swarm import ROOT, RunOutcome, Spec

ROBOT = ROOT / "examples" / "iiwa.toml"
TOL = 0.05  # m
TOL_DEG = 15.0
# Per episode: 1-degree moves carry the tool up to ~1.5 cm a step. Measured in a plain loop of the same learners,
# state and reward (seed 0, set A / B): 300 steps 92 % / -, 400 steps 97 % / 92 % (seed 1: 96 % / 93 %).
STEPS = 400
# Training: each goal PASSES times, in a seeded order. The same loop, 300 steps, set A: 48 goals 89 %, 96 goals 92 %,
# 128 goals x 3 passes 89 %; q out of the state 78 %, g_perp in 11 sets 96 % / 90 % (400 steps, seed 1: 92 / 86).
TRAIN_GOALS, PASSES = 96, 4
QUICK_TRAINING = (6, 2)
# The controls (untrained, blind) and the pose protocol run on this many seeds (the first), if the machine's time is
# short: the trained swarm's points, the claim, run on every seed of --seeds.
CONTROL_SEEDS = 3
TEST = 100
SETS = {"A": 2000, "B": 3000}  # sampling seeds of the two test sets (training: 1000)
MARGIN = 0.9  # goals and starts within this share of every joint's range, about its middle
MIN_Z = 0.05  # m above the base's plane
# q over (-pi, pi) for every joint (the learner's overrides are the same for all agents), the rest uninformative
BLIND = {"n_sets": (5, 2, 2, 2, 2, 2), "ranges": ((-math.pi, math.pi), *((-1000.0, 1000.0),) * 5)}
CONTROLLERS = {"rule": "rule", "pseudo-inverse": "pinv", "greedy per joint": "greedy"}
LOCK = ROOT / "scenarios" / "iiwa-locked-a2.toml"
DISTURB_DEG = 2.0  # the disturbed joint's random increment each step: ±2°, twice the agents' move


def _disturbed(ctx: Context, steps: int) -> str:
    """The elbow (a4) disturbed through the episode's second quarter (steps 100-199 of 400): a scenario file under
    the experiment's runs (its content is part of each run's identity), its steps fitted to the episode."""
    path = ctx.runs / "scenarios" / "r3d-disturbed-a4.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        'name = "r3d-disturbed-a4"\n\n[[event]]\n'
        f'step = {steps // 4}\nfault = "disturb"\ntarget = ["a4"]\n'
        f"steps = {steps // 4}\namplitude_deg = {DISTURB_DEG}\n"
    )
    return str(path)


def sample(topo: Topology, seed: int, n: int, pose: bool) -> tuple[list[list[float]], list[list[float]]]:
    """n (goal, start) pairs: goals the tool of random configurations above MIN_Z, starts other random
    configurations (degrees, agent order)."""
    rng = np.random.default_rng(seed)
    dof = topo.dof_agents
    lims = np.array([topo.agents[a].limits for a in dof])
    mid, half = lims.mean(axis=1), (lims[:, 1] - lims[:, 0]) / 2 * MARGIN

    def config() -> np.ndarray:
        return mid + rng.uniform(-1, 1, len(dof)) * half

    goals: list[list[float]] = []
    starts: list[list[float]] = []
    while len(goals) < n:
        q = config()
        (tip,) = frames.tips(topo, dict(zip(dof, q.tolist(), strict=True))).values()
        if tip[2] - topo.base[2] < MIN_Z:
            continue
        goal = [round(c, 4) for c in tip[:3]]
        if pose:
            goal += [round(math.degrees(a), 3) for a in _rpy(tip[3:7])]
        goals.append(goal)
        starts.append([round(math.degrees(v), 3) for v in config()])
    return goals, starts


def _rpy(q: tuple[float, ...]) -> tuple[float, float, float]:
    """URDF rpy of a quaternion (the inverse of frames.rpy_quat)."""
    x, y, z, w = q
    roll = math.atan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = math.asin(max(-1.0, min(1.0, 2 * (w * y - z * x))))
    yaw = math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def training_set(
    topo: Topology, pose: bool, n: int = TRAIN_GOALS, passes: int = PASSES
) -> tuple[list[list[float]], list[list[float]]]:
    """n goals (and start poses), each `passes` times in a seeded order."""
    goals, starts = sample(topo, 1000, n, pose)
    order = np.random.default_rng(1001).permutation(np.tile(np.arange(n), passes))
    return [goals[i] for i in order], [starts[i] for i in order]


def seeds(ctx: Context, pose: bool, control: bool) -> list[int]:
    """The seeds a condition runs on: every seed for the trained swarm on points, the first CONTROL_SEEDS else."""
    return ctx.seed_list if not (pose or control) else ctx.seed_list[:CONTROL_SEEDS]


def _task(goals: list[list[float]], starts: list[list[float]]) -> tuple[tuple[str, Any], ...]:
    return (("goals", goals), ("starts", starts))


def orientation_errors(topo: Topology, out: RunOutcome, goals: list[list[float]]) -> list[float]:
    """The tool's angle (deg) to each pose goal at the episode's end (from the final joint angles)."""
    errs = []
    for row, g in zip(out.rows, goals, strict=True):
        q = {a: math.radians(v) for a, v in row["final_angles_deg"].items()}
        (tip,) = frames.tips(topo, q).values()
        goal_q = frames.rpy_quat(*(math.radians(a) for a in g[3:6]))
        errs.append(math.degrees(frames.angle_between(tip[3:7], goal_q)))
    return errs


def run(ctx: Context) -> dict[str, Any]:
    topo = load_robot(ROBOT)
    steps = 60 if ctx.quick else STEPS
    n_test = 5 if ctx.quick else TEST
    rep = Report(ctx, "Reaching in 3D: the KUKA iiwa from URDF, frozen on unseen goals", "beyond the paper (3D, §6)")
    rep.text(
        "The iiwa (`examples/iiwa.toml`: PyBullet's `kuka_iiwa/model.urdf`, seven agents nested as its chain, a tool "
        "point beside the flange) learns to reach goals spread over its workspace, each from a random start pose; "
        "then, frozen (`--learn off --explore off`), it meets goals and start poses it never saw. Beside it, on the "
        "same goals and starts:",
        "",
        "- **untrained, frozen**: the same learner never trained (its greedy choices from a zero Q);",
        "- **blind (q only), frozen**: trained alike, but every state variable but q has 2 sets over ±1000 (no "
        "information): what the rotation-plane state buys;",
        "- **rule**: each joint one step along sign(g_perp) (`kinswarm baseline --law rule`): no learning, no model;",
        "- **pseudo-inverse** (`--law pinv`) and **greedy per joint** (`--law greedy`): they know the model.",
        "",
        f"Goals are the tool points of random joint configurations (uniform within {MARGIN:.0%} of every joint's range "
        f"about its middle, so far goals and goals behind the base occur), kept {MIN_Z * 100:.0f} cm or more above "
        "the base's plane; start poses are other random configurations. Two disjoint test sets ('A', 'B') check "
        f"that a number does not hang on its set. Training: {TRAIN_GOALS} goals x {PASSES} passes in a seeded order, "
        f"{steps} steps an episode, tests as long. The controls and the poses run on the first "
        f"{min(CONTROL_SEEDS, ctx.seeds)} seed(s), the poses on set A only (the machine's time).",
    )
    rep.results = {}
    all_runs: list[RunOutcome] = []
    for pose in (False, True):
        kind = "poses" if pose else "points"
        rows, results, runs = _protocol(ctx, topo, pose, steps, n_test)
        all_runs += runs
        rep.results[kind] = results
        head = f"within {TOL * 100:.0f} cm" + (f" and {TOL_DEG:.0f}°" if pose else "")
        rep.text(f"## {kind.capitalize()}: frozen on {n_test} unseen goals from random start poses")
        rep.table(["controller", "set", f"{head} (%)", "mean error (m)", "median (m)", "seeds"], rows)
    faults = (
        ("locked_a2", "lock", "The shoulder (a2) locked throughout", str(LOCK)),
        (
            "disturbed_a4",
            "dist",
            f"The elbow (a4) disturbed from step {steps // 4} for {steps // 4} steps (±{DISTURB_DEG:g}° a step)",
            _disturbed(ctx, steps),
        ),
    )
    for key, tag, heading, scenario in faults:
        f_rows, f_results, f_runs = _faulted(ctx, topo, steps, n_test, tag, scenario)
        all_runs += f_runs
        rep.results[key] = f_results
        rep.text(f"## {heading}, test set A")
        rep.table(["condition", f"within {TOL * 100:.0f} cm (%)", "mean error (m)", "seeds"], f_rows)
    _figure(ctx, rep)
    rep.write(
        {
            "robot": "examples/iiwa.toml (kuka_iiwa/model.urdf, tool [0, 0.05, 0.1] on link 7)",
            "training": {"goals": TRAIN_GOALS, "passes": PASSES, "sampling_seed": 1000, "steps": steps},
            "test": {"goals": n_test, "sets": SETS, "steps": steps, "margin": MARGIN, "min_z": MIN_Z},
            "learner": "reach3d defaults (LearnerSettings.for_plane), reward graded (d_min 0.3, c 10, k 200)",
            "pose_weight": f"{frames.POSE_WEIGHT} m/rad: a pose's distance |tip - goal| + this x the angle (reward, "
            "the references' pose error, their stop test)",
            "blind": BLIND,
        },
        all_runs,
    )
    return rep.results


def _protocol(
    ctx: Context, topo: Topology, pose: bool, steps: int, n_test: int
) -> tuple[list[list[Any]], dict[str, Any], list[RunOutcome]]:
    tag = "pose" if pose else "pt"
    t_goals, t_starts = training_set(topo, pose, *QUICK_TRAINING if ctx.quick else ())
    file = str(ROBOT)
    train = {
        (name, s): Spec(
            f"r3d-{tag}-train-{name}",
            seed=s,
            epochs=len(t_goals),
            steps=steps,
            file=file,
            task=_task(t_goals, t_starts),
            learner=learner,
            checkpoint=True,
        )
        for name, learner in (("state", settings()), ("blind", settings(**BLIND)))
        for s in seeds(ctx, pose, name == "blind")
    }
    trained = dict(zip(train, run_specs(ctx, list(train.values()), f"{tag} train"), strict=True))
    # poses: set A only (the machine's time)
    sets = {
        k: sample(topo, seed + (7 if pose else 0), n_test, pose) for k, seed in SETS.items() if not pose or k == "A"
    }
    specs: dict[tuple[str, str, int], Spec] = {}
    for set_name, (goals, starts) in sets.items():
        common = {"epochs": n_test, "steps": steps, "file": file, "task": _task(goals, starts)}
        for s in ctx.seed_list:
            for cond, learner, src in (
                ("trained, frozen", settings(), trained.get(("state", s))),
                ("untrained, frozen", settings(), None),
                ("blind (q only), frozen", settings(**BLIND), trained.get(("blind", s))),
            ):
                if s not in seeds(ctx, pose, cond != "trained, frozen"):
                    continue
                specs[(cond, set_name, s)] = Spec(
                    f"r3d-{tag}-{set_name}-{cond.split(',')[0].split(' ')[0]}",
                    seed=s,
                    learner=learner,
                    from_dir=str(src.out) if src is not None else None,
                    learn=False,
                    explore=False,
                    **common,
                )
        for label, law in CONTROLLERS.items():
            specs[(label, set_name, 0)] = Spec(f"r3d-{tag}-{set_name}-{law}", controller=law, **common)
    outs = dict(zip(specs, run_specs(ctx, list(specs.values()), f"{tag} test"), strict=True))
    rows, results = [], {}
    labels = ["trained, frozen", "untrained, frozen", "blind (q only), frozen", *CONTROLLERS]
    for label in labels:
        for set_name, (goals, _) in sets.items():
            keys = [k for k in outs if k[0] == label and k[1] == set_name]
            within, means, medians = [], [], []
            for k in keys:
                err = outs[k].final_errors
                ok = [e <= TOL for e in err]
                if pose:
                    ang = orientation_errors(topo, outs[k], goals)
                    ok = [o and a <= TOL_DEG for o, a in zip(ok, ang, strict=True)]
                within.append(100.0 * sum(ok) / len(ok))
                means.append(float(np.mean(err)))
                medians.append(float(np.median(err)))
            results[f"{label} | {set_name}"] = {"within_pct": within, "mean": means, "median": medians}
            rows.append([label, set_name, pm(within, 1), pm(means), pm(medians), len(keys)])
    return rows, results, [*trained.values(), *outs.values()]


def _faulted(
    ctx: Context, topo: Topology, steps: int, n_test: int, tag: str, scenario: str
) -> tuple[list[list[Any]], dict[str, Any], list]:
    """Test set A's points with a scenario's faults in every trial: the trained swarm frozen and still learning, an
    untrained swarm learning, the rule and the pseudo-inverse."""
    goals, starts = sample(topo, SETS["A"], n_test, False)
    t_goals, t_starts = training_set(topo, False, *QUICK_TRAINING if ctx.quick else ())
    file = str(ROBOT)
    trained = run_specs(
        ctx,
        [
            Spec(
                "r3d-pt-train-state",
                seed=s,
                epochs=len(t_goals),
                steps=steps,
                file=file,
                task=_task(t_goals, t_starts),
                learner=settings(),
                checkpoint=True,
            )
            for s in ctx.seed_list
        ],
        f"{tag} train",
    )
    common = {"epochs": n_test, "steps": steps, "file": file, "task": _task(goals, starts), "scenario": scenario}
    specs: dict[tuple[str, int], Spec] = {}
    for s, t in zip(ctx.seed_list, trained, strict=True):
        specs[("trained, frozen", s)] = Spec(
            f"r3d-{tag}-frozen", seed=s, from_dir=str(t.out), learn=False, explore=False, **common
        )
        specs[("trained, learning", s)] = Spec(f"r3d-{tag}-learning", seed=s, from_dir=str(t.out), **common)
        specs[("untrained, learning", s)] = Spec(f"r3d-{tag}-scratch", seed=s, **common)
    specs[("pseudo-inverse", 0)] = Spec(f"r3d-{tag}-pinv", controller="pinv", **common)
    specs[("rule", 0)] = Spec(f"r3d-{tag}-rule", controller="rule", **common)
    outs = dict(zip(specs, run_specs(ctx, list(specs.values()), tag), strict=True))
    rows, results = [], {}
    for label in ("trained, frozen", "trained, learning", "untrained, learning", "rule", "pseudo-inverse"):
        keys = [k for k in outs if k[0] == label]
        within = [100.0 * float(np.mean([e <= TOL for e in outs[k].final_errors])) for k in keys]
        means = [float(np.mean(outs[k].final_errors)) for k in keys]
        results[label] = {"within_pct": within, "mean": means}
        rows.append([label, pm(within, 1), pm(means), len(keys)])
    return rows, results, list(outs.values())


def _figure(ctx: Context, rep: Report) -> None:
    """Share of test goals within 5 cm per controller (points, set A), seeds as dots."""
    plt = plt_module()
    res = rep.results["points"]
    labels = [k.split(" | ")[0] for k in res if k.endswith("| A")]
    fig, ax = plt.subplots(figsize=(8, 3.2))
    for i, label in enumerate(labels):
        vals = res[f"{label} | A"]["within_pct"]
        ax.bar(i, mean_std(vals)[0], color=f"C{i}", alpha=0.7)
        ax.plot([i] * len(vals), vals, "k.", ms=4)
    ax.set_xticks(range(len(labels)), labels, rotation=20, fontsize=8, ha="right")
    ax.set_ylabel(f"within {TOL * 100:.0f} cm (%)")
    ax.set_ylim(0, 100)
    ax.axhline(90, color="grey", ls="--", lw=0.8)
    ax.grid(alpha=0.3, axis="y")
    rep.save_figure(fig, "within.png", "Points, test set A: share of unseen goals reached within 5 cm (dots: seeds)")
