"""Reaching in 3D on a real arm (examples/iiwa.toml: PyBullet's KUKA LBR iiwa, 7 agents): train on goals spread over
the workspace, each from a random start pose, then test the frozen swarm on unseen goals from unseen start poses,
beside its controls on the same goals and starts:

  trained, frozen     the swarm after training, learning and exploration off (`--from T --learn off --explore off`)
  untrained, frozen   the same learner never trained (its greedy choices from a zero Q)
  blind, frozen       trained alike, but its state sees only q (every other variable 2 sets over ±1000: no
                      information); what the rotation-plane state itself buys
  rule                each joint one step along sign(g_perp) (`kinswarm baseline --law rule`): no learning, no model
  rule on g_q         each joint one step toward its own best angle within its limits (`--law turn`)
  pseudo-inverse      resolved-rate control on the model (`--law pinv`); greedy per joint (`--law greedy`)

Goals are the tool points of random joint configurations (uniform within 90 % of every joint's range, so far
goals and goals behind the base occur), kept when they lie 5 cm or more above the base's plane; start poses are
other random configurations. Two disjoint test sets of 100 ("A", "B") check that a number does not hang on its set.
Poses (position and the tool's orientation) run the same protocol in their own experiment (pose3d.py). The locked-joint
scenario locks the shoulder (a2) throughout; the disturbed one shakes the elbow (a4) in steps 100-199 of every trial:
trained frozen, trained still learning, an untrained swarm learning, the rule and the pseudo-inverse, on test set A's
goals. The lost one takes the shoulder's agent away at the test's first step, for good: its process stopped (SIGSTOP,
never resumed: a killed agent is always restarted, or with --max-restarts 0 the run fails), so its joint holds and
its parent (a1) stands in for a3; `process` placement, not bit-reproducible (the stop lands where the process is).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np
from kinswarm.actors.report import read_events
from kinswarm.protocol import frames
from kinswarm.protocol.robots import load_robot
from kinswarm.protocol.topology import Topology

from .common import Context, Report, mean_std, plt_module, pm, run_specs, settings
from .swarm import DEADLINE_MS, ROOT, RunOutcome, Spec

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
# The controls (untrained, blind) and the poses' swarm run on this many seeds (the first), if the machine's time is
# short: the trained swarm's points, the claim, run on every seed of --seeds.
CONTROL_SEEDS = 3
TEST = 100
SETS = {"A": 2000, "B": 3000}  # sampling seeds of the two test sets (training: 1000)
MARGIN = 0.9  # goals and starts within this share of every joint's range, about its middle
MIN_Z = 0.05  # m above the base's plane
# q over (-pi, pi) for every joint (the learner's overrides are the same for all agents), the rest uninformative
BLIND = {"n_sets": (5, 2, 2, 2, 2, 2), "ranges": ((-math.pi, math.pi), *((-1000.0, 1000.0),) * 5)}
CONTROLLERS = {"rule": "rule", "rule on g_q": "turn", "pseudo-inverse": "pinv", "greedy per joint": "greedy"}
LOCK = ROOT / "scenarios" / "iiwa-locked-a2.toml"
DISTURB_DEG = 2.0  # the disturbed joint's random increment each step: ±2°, twice the agents' move
# The agent lost for good: the shoulder, the joint the locked scenario holds, so the two differ only in the agent
# (gone, its parent standing in, vs there and choosing moves that do nothing); the references' rows are the lock's.
LOST = "a2"


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


def _lost(ctx: Context) -> str:
    """LOST's process stopped at the first step of the test (epoch 0, step 0) and never resumed (no thaw: `freeze`
    without seconds): its token goes after the lease (~1 s), its joint holds, its parent stands in for its children
    to the end. A scenario file under the experiment's runs, like the disturbed one."""
    path = ctx.runs / "scenarios" / f"r3d-lost-{LOST}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        f'name = "r3d-lost-{LOST}"\n'
        f'description = "{LOST} stopped (SIGSTOP) at the first step of the test, never resumed"\n\n[[event]]\n'
        f'epoch = 0\nstep = 0\nfault = "freeze"\ntarget = ["{LOST}"]\n'
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


def train_spec(
    ctx: Context,
    topo: Topology,
    pose: bool,
    seed: int,
    steps: int,
    file: Path = ROBOT,
    name: str = "state",
    learner: tuple = (),
) -> Spec:
    """A swarm's training run (the training set's goal-episodes, checkpointed for the frozen tests): `name` "state"
    the swarm of the protocol, others a control trained alike with `learner` (default: settings())."""
    t_goals, t_starts = training_set(topo, pose, *QUICK_TRAINING if ctx.quick else ())
    return Spec(
        f"r3d-{'pose' if pose else 'pt'}-train-{name}", seed=seed, epochs=len(t_goals), steps=steps, file=str(file),
        task=_task(t_goals, t_starts), learner=learner or settings(), checkpoint=True,
    )  # fmt: skip


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
        "- **rule on g_q**: each joint one step toward its own best angle within its limits (`--law turn`: the turn "
        "state's rule, which the pose experiment's swarm learns on);",
        "- **pseudo-inverse** (`--law pinv`) and **greedy per joint** (`--law greedy`): they know the model.",
        "",
        f"Goals are the tool points of random joint configurations (uniform within {MARGIN:.0%} of every joint's range "
        f"about its middle, so far goals and goals behind the base occur), kept {MIN_Z * 100:.0f} cm or more above "
        "the base's plane; start poses are other random configurations. Two disjoint test sets ('A', 'B') check "
        f"that a number does not hang on its set. Training: {TRAIN_GOALS} goals x {PASSES} passes in a seeded order, "
        f"{steps} steps an episode, tests as long. The controls run on the first {min(CONTROL_SEEDS, ctx.seeds)} "
        "seed(s). Poses: `kinswarm experiment pose3d`.",
    )
    rep.results = {}
    all_runs: list[RunOutcome] = []
    rows, results, runs = _protocol(ctx, topo, False, steps, n_test)
    all_runs += runs
    rep.results["points"] = results
    rep.text(f"## Points: frozen on {n_test} unseen goals from random start poses")
    rep.table(["controller", "set", f"within {TOL * 100:.0f} cm (%)", "mean error (m)", "median (m)", "seeds"], rows)
    faults = (
        ("locked_a2", "lock", "The shoulder (a2) locked throughout", str(LOCK)),
        (
            "disturbed_a4",
            "dist",
            f"The elbow (a4) disturbed from step {steps // 4} for {steps // 4} steps (±{DISTURB_DEG:g}° a step)",
            _disturbed(ctx, steps),
        ),
    )
    f_runs_by: dict[str, list[RunOutcome]] = {}
    for key, tag, heading, scenario in faults:
        f_rows, f_results, f_runs = _faulted(ctx, topo, steps, n_test, tag, scenario)
        all_runs += f_runs
        f_runs_by[key] = f_runs
        rep.results[key] = f_results
        rep.text(f"## {heading}, test set A")
        rep.table(["condition", f"within {TOL * 100:.0f} cm (%)", "mean error (m)", "seeds"], f_rows)
    f_rows, f_results, f_runs = _faulted(ctx, topo, steps, n_test, "lost", _lost(ctx), lost=True)
    all_runs += f_runs
    rep.results[f"lost_{LOST}"] = f_results
    _lost_section(rep, topo, f_rows, f_results, f_runs_by["locked_a2"], f_runs)
    _figure(ctx, rep)
    rep.write(
        {
            "robot": "examples/iiwa.toml (kuka_iiwa/model.urdf, tool [0, 0.05, 0.1] on link 7)",
            "training": {"goals": TRAIN_GOALS, "passes": PASSES, "sampling_seed": 1000, "steps": steps},
            "test": {"goals": n_test, "sets": SETS, "steps": steps, "margin": MARGIN, "min_z": MIN_Z},
            "learner": "reach3d defaults (LearnerSettings.for_plane), reward graded (d_min 0.3, c 10, k 200)",
            "blind": BLIND,
        },
        all_runs,
    )
    return rep.results


def _protocol(
    ctx: Context,
    topo: Topology,
    pose: bool,
    steps: int,
    n_test: int,
    controllers: dict[str, str] = CONTROLLERS,
    blind: dict[str, Any] = BLIND,
    file: Path = ROBOT,
) -> tuple[list[list[Any]], dict[str, Any], list[RunOutcome]]:
    """Train (the swarm and the blind one), then test frozen on both sets beside the untrained swarm and the laws."""
    tag = "pose" if pose else "pt"
    path = str(file)
    train = {
        (name, s): train_spec(ctx, topo, pose, s, steps, file, name, learner)
        for name, learner in (("state", settings()), ("blind", settings(**blind)))
        for s in seeds(ctx, pose, name == "blind")
    }
    trained = dict(zip(train, run_specs(ctx, list(train.values()), f"{tag} train"), strict=True))
    sets = {k: sample(topo, seed + (7 if pose else 0), n_test, pose) for k, seed in SETS.items()}
    specs: dict[tuple[str, str, int], Spec] = {}
    for set_name, (goals, starts) in sets.items():
        common = {"epochs": n_test, "steps": steps, "file": path, "task": _task(goals, starts)}
        for s in ctx.seed_list:
            for cond, learner, src in (
                ("trained, frozen", settings(), trained.get(("state", s))),
                ("untrained, frozen", settings(), None),
                ("blind (q only), frozen", settings(**blind), trained.get(("blind", s))),
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
        for label, law in controllers.items():
            specs[(label, set_name, 0)] = Spec(f"r3d-{tag}-{set_name}-{law}", controller=law, **common)
    outs = dict(zip(specs, run_specs(ctx, list(specs.values()), f"{tag} test"), strict=True))
    rows, results = [], {}
    labels = ["trained, frozen", "untrained, frozen", "blind (q only), frozen", *controllers]
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


def _lost_section(
    rep: Report,
    topo: Topology,
    rows: list[list[Any]],
    results: dict[str, Any],
    locked: list[RunOutcome],
    lost: list[RunOutcome],
) -> None:
    parent = topo.agents[LOST].parent
    rep.text(
        f"## The shoulder's agent ({LOST}) lost for good at the start of the test, test set A",
        "",
        f"At the first step of the test (epoch 0, step 0) the process of agent {LOST} is stopped (SIGSTOP) and never "
        "resumed: once its liveliness token lapses (the 1 s lease) the swarm runs on without it to the end, its joint "
        f"holding (at each trial's start angle, as the locked shoulder's), its parent ({parent}) standing in for its "
        f"children (composing their frames from {LOST}'s encoder). A kill cannot do this: a killed agent is restarted "
        "from its checkpoint, and with `--max-restarts 0` its exit ends the run; the stopped process stays, gone for "
        "the swarm but never exiting, so nothing restarts it. These runs use `process` placement (one OS process per "
        "actor, as `kinswarm run --placement process`). **Not bit-reproducible**, unlike every other row: the stop "
        "lands wherever the process is, by the clock; the step it is lost in ends at the step deadline "
        f"({DEADLINE_MS / 1000:g} s here), {parent} holding (it waits for {LOST}'s `up`) and the joints below "
        f"{LOST} too if its frames had not gone down yet; {parent} stands in from the next step. The learning swarms' "
        "updates around that step vary with the timing. The rule and the pseudo-inverse have no agents to lose: "
        f"their rows are the equivalent locked joint ({LOST} locked throughout: the same runs as above).",
    )
    rep.table(["condition", f"within {TOL * 100:.0f} cm (%)", "mean error (m)", "seeds"], rows)
    swarms = {label: r for label, r in results.items() if "stood_in_from" in r}
    stood = "; ".join(
        f"{label}: "
        + ", ".join(f"{e}/{st} ({m})" for (e, st), m in zip(r["stood_in_from"], r["held_cmds"], strict=True))
        for label, r in swarms.items()
    )
    lapsed = [t for r in swarms.values() for t in r["tokens_lost"]]
    frozen = {o.spec.seed: o for o in locked if o.spec.name.endswith("-frozen")}
    same = [
        sum(a == b for a, b in zip(o.final_errors, frozen[o.spec.seed].final_errors, strict=True))
        for o in lost
        if o.spec.name.endswith("-frozen")
    ]
    rep.text(
        f"Where {parent} began to stand in for {LOST} (epoch/step, and in brackets the commands the first trial "
        f"missed, each a joint holding for a step; a run per seed): {stood}. "
        + (
            f"No other agent's liveliness token lapsed in these runs, {LOST}'s once in each. "
            if all(t == {LOST: 1} for t in lapsed)
            else "Liveliness tokens lapsed, per run (a process starved past the lease, besides the stop): "
            + "; ".join(", ".join(f"{a} {n}x" for a, n in sorted(t.items())) for t in lapsed)
            + ". "
        )
        + f"Frozen, the swarm without {LOST} ends {', '.join(map(str, same))} of its {len(lost[0].rows)} trials "
        f"(a run per seed) at exactly the error of the frozen swarm with {LOST} locked and its agent there (the "
        "locked shoulder's table)"
        + (
            f": every trial but the first, where the stop landed; {parent}'s stand-in sends down the frames {LOST} "
            "would have."
            if all(n >= len(lost[0].rows) - 1 for n in same)
            else "."
        )
    )


def _faulted(
    ctx: Context, topo: Topology, steps: int, n_test: int, tag: str, scenario: str, lost: bool = False
) -> tuple[list[list[Any]], dict[str, Any], list]:
    """Test set A's points with a scenario's faults in every trial: the trained swarm frozen and still learning, an
    untrained swarm learning, the rule and the pseudo-inverse. `lost`: the scenario stops LOST's process; the swarms
    run in `process` placement (each run's stand-in checked in its events), the references with LOST locked."""
    goals, starts = sample(topo, SETS["A"], n_test, False)
    file = str(ROBOT)
    trained = run_specs(ctx, [train_spec(ctx, topo, False, s, steps) for s in ctx.seed_list], f"{tag} train")
    common: dict[str, Any] = {"epochs": n_test, "steps": steps, "file": file, "task": _task(goals, starts)}
    ref = {**common, "scenario": str(LOCK) if lost else scenario}  # the rule's and pseudo-inverse's
    common.update(scenario=scenario, placement="process" if lost else "single")
    specs: dict[tuple[str, int], Spec] = {}
    for s, t in zip(ctx.seed_list, trained, strict=True):
        specs[("trained, frozen", s)] = Spec(
            f"r3d-{tag}-frozen", seed=s, from_dir=str(t.out), learn=False, explore=False, **common
        )
        specs[("trained, learning", s)] = Spec(f"r3d-{tag}-learning", seed=s, from_dir=str(t.out), **common)
        specs[("untrained, learning", s)] = Spec(f"r3d-{tag}-scratch", seed=s, **common)
    ref_tag = "lock" if lost else tag  # the lock's own runs (the cache): the same specs
    refs = {"pseudo-inverse": "pinv", "rule": "rule"}
    for label, law in refs.items():
        specs[(label, 0)] = Spec(f"r3d-{ref_tag}-{law}", controller=law, **ref)
    outs = dict(zip(specs, run_specs(ctx, list(specs.values()), tag), strict=True))
    rows, results = [], {}
    for label in ("trained, frozen", "trained, learning", "untrained, learning", "rule", "pseudo-inverse"):
        keys = [k for k in outs if k[0] == label]
        within = [100.0 * float(np.mean([e <= TOL for e in outs[k].final_errors])) for k in keys]
        means = [float(np.mean(outs[k].final_errors)) for k in keys]
        name = f"{label} ({LOST} locked instead)" if lost and label in refs else label
        results[name] = {"within_pct": within, "mean": means}
        if lost and label not in refs:
            results[name]["stood_in_from"] = [_stood_in(outs[k]) for k in keys]
            results[name]["tokens_lost"] = [outs[k].summary.get("tokens_lost", {}) for k in keys]
            results[name]["held_cmds"] = [outs[k].rows[0]["missed_cmds"] for k in keys]
        rows.append([name, pm(within, 1), pm(means), len(keys)])
    return rows, results, list(outs.values())


def _stood_in(out: RunOutcome) -> tuple[int, int]:
    """(epoch, step) where LOST's parent began to stand in for it (its `adopt` event): the stop took, for good (no
    `handback`). Else the run is not what its row says, and the report is not written."""
    events = read_events(out.out)
    adopt = [(e["epoch"], e["step"]) for e in events if e["event"] == "adopt" and e["target"] == LOST]
    back = [e for e in events if e["event"] in ("handback", "restart", "thaw") and e["target"] == LOST]
    if len(adopt) != 1 or back:
        raise RuntimeError(f"{out.out}: {LOST} was to be lost for good: adopt at {adopt}, then {back}")
    return adopt[0]


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
