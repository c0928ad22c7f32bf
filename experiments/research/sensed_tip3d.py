"""reach3d's `tip = "sensed"` on the iiwa with a miscalibrated encoder (research, beside `kinswarm experiment
reach3d`): the experiment's trained swarm (its points' training, one robot, seed 0: its cached run serves it) on the
first goals of its test set A, from their start poses, with the shoulder's encoder (a2) reading +10° (a scenario's
`offset`, from the first step), aiming by the tool point it computes from its encoders ("computed") or by the sensed
one where they disagree ("sensed"); frozen and still learning; and intact, where the two must be the same to the bit.
Then other encoders' offsets, frozen, computed vs sensed: is it general, or the shoulder's? And poses (`kinswarm
experiment pose3d`'s trained swarm, its set A's first poses), frozen: the sensed tip moves only the goal's point.

    nice -n 10 python -m kinswarm.experiments.research sensed_tip3d --jobs 1 --out runs/research

Measured: docs/notebook/adapt.md, Study 8.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from kinswarm.experiments import pose3d
from kinswarm.experiments import reach3d as r
from kinswarm.experiments.common import Context, Report, pm, run_specs, settings
from kinswarm.experiments.swarm import Spec
from kinswarm.protocol.robots import load_robot

SEEDS = 1
TEST = 20  # the first goals of test set A
JOINT, DEGREES = "a2", 10.0
TIPS = ("computed", "sensed")
OTHERS = (("a1", 10.0), ("a2", -20.0), ("a4", -20.0), ("a6", 20.0))  # frozen only


def _offset(ctx: Context, joint: str = JOINT, degrees: float = DEGREES) -> str:
    """`joint`'s encoder reading `degrees` off from the first step: a scenario file under the runs (its content is
    part of each run's identity)."""
    path = ctx.runs / "scenarios" / f"r3d-offset-{joint}{degrees:+g}.toml"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(
        f'name = "r3d-offset-{joint}"\n\n[[event]]\nepoch = 0\nstep = 0\nfault = "offset"\ntarget = "{joint}"\n'
        f"degrees = {degrees}\n"
    )
    return str(path)


def run(ctx: Context) -> dict[str, Any]:
    topo = load_robot(r.ROBOT)
    steps, n_test = (60, 5) if ctx.quick else (r.STEPS, TEST)
    file = str(r.ROBOT)
    train = [r.train_spec(ctx, topo, False, s, steps) for s in ctx.seed_list]
    trained = dict(zip(ctx.seed_list, run_specs(ctx, train, "train"), strict=True))
    goals, starts = r.sample(topo, r.SETS["A"], n_test, False)
    scenario = _offset(ctx)
    tests: dict[tuple[str, str, str, int], Spec] = {}
    for s, t in trained.items():
        for mode, learn in (("frozen", False), ("learning", True)):
            for robot, scen in (("intact", None), (f"{JOINT} reads {DEGREES:+g}°", scenario)):
                for tip in TIPS:
                    tests[(mode, robot, tip, s)] = Spec(
                        f"r3d-tip-{mode}-{'offset' if scen else 'intact'}-{tip}", seed=s, epochs=n_test,
                        steps=steps, file=file, task=(*r._task(goals, starts), ("tip", tip)), learner=settings(),
                        from_dir=str(t.out), learn=learn, explore=learn, scenario=scen,
                    )  # fmt: skip
        for joint, deg in OTHERS:
            for tip in TIPS:
                tests[("frozen", f"{joint} reads {deg:+g}°", tip, s)] = Spec(
                    f"r3d-tip-frozen-offset-{tip}", seed=s, epochs=n_test, steps=steps, file=file,
                    task=(*r._task(goals, starts), ("tip", tip)), learner=settings(), from_dir=str(t.out),
                    learn=False, explore=False, scenario=_offset(ctx, joint, deg),
                )  # fmt: skip
    outs = dict(zip(tests, run_specs(ctx, list(tests.values()), "test"), strict=True))
    pose_rows, pose_results, pose_runs = _poses(ctx, steps, n_test, scenario)
    rep = Report(ctx, "The sensed tip on the iiwa (research)", "beyond the paper (3D, adaptation)")
    rep.text(
        f"Research, not product. The trained swarm of `kinswarm experiment reach3d` (points, {train[0].epochs} "
        f"goal-episodes of {steps} steps) on the first {n_test} goals of test set A from their start poses, "
        f"frozen (learning and exploration off) and still learning, intact and with {JOINT}'s encoder reading "
        f"+{DEGREES:g}° from the first step; `[task] tip` computed or sensed. Within {r.TOL * 100:.0f} cm.",
    )
    results: dict[str, Any] = {}
    rows = []
    for key, out in outs.items():
        mode, robot, tip, s = key
        err = out.final_errors
        within = 100.0 * float(np.mean([e <= r.TOL for e in err]))
        label = f"{mode} | {robot} | {tip}"
        results.setdefault(label, {"within_pct": [], "mean": [], "final_errors": []})
        results[label]["within_pct"].append(within)
        results[label]["mean"].append(float(np.mean(err)))
        results[label]["final_errors"].append(err)
    for label, v in results.items():
        rows.append([*label.split(" | "), pm(v["within_pct"], 1), pm(v["mean"], 3), len(v["mean"])])
    rep.table(["swarm", "robot", "tip", f"within {r.TOL * 100:.0f} cm (%)", "mean error (m)", "seeds"], rows)
    same = {
        mode: all(
            outs[(mode, "intact", "computed", s)].final_errors == outs[(mode, "intact", "sensed", s)].final_errors
            and outs[(mode, "intact", "computed", s)].mean_errors == outs[(mode, "intact", "sensed", s)].mean_errors
            for s in trained
        )
        for mode in ("frozen", "learning")
    }
    rep.text(f"Intact, computed and sensed give the same final and mean errors to the bit: {same}.")
    results["intact_identical"] = same
    rep.text(
        f"## Poses, frozen (pose3d's trained swarm, its set A's first {n_test} poses)",
        "",
        "The sensed tip moves the goal's point; its orientation stays the goal's (actors/tasks/reach3d.py).",
    )
    head = f"within {r.TOL * 100:.0f} cm and {r.TOL_DEG:.0f}° (%)"
    rep.table(["robot", "tip", head, f"within {r.TOL * 100:.0f} cm (%)", "mean error (m)", "mean angle (°)"], pose_rows)
    results["poses"] = pose_results
    rep.results = results
    rep.write(
        {"steps": steps, "test": n_test, "joint": JOINT, "degrees": DEGREES, "others": OTHERS},
        [*trained.values(), *outs.values(), *pose_runs],
    )
    return results


def _poses(ctx: Context, steps: int, n_test: int, scenario: str) -> tuple[list[list[Any]], dict[str, Any], list]:
    """pose3d's trained swarm (seed 0), frozen, on its set A's first poses: intact and offset, tip computed, sensed."""
    topo = load_robot(r.ROBOT)
    file = str(pose3d.FILE)
    s = ctx.seed_list[0]
    (trained,) = run_specs(ctx, [r.train_spec(ctx, topo, True, s, steps, pose3d.FILE)], "pose train")
    goals, starts = r.sample(topo, r.SETS["A"] + 7, n_test, True)
    keys = [(robot, tip) for robot in ("intact", f"{JOINT} reads {DEGREES:+g}°") for tip in TIPS]
    specs = [
        Spec(
            f"r3d-tip-pose-{'intact' if robot == 'intact' else 'offset'}-{tip}",
            seed=s,
            epochs=n_test,
            steps=steps,
            file=file,
            task=(*r._task(goals, starts), ("tip", tip)),
            learner=settings(),
            from_dir=str(trained.out),
            learn=False,
            explore=False,
            scenario=None if robot == "intact" else scenario,
        )  # fmt: skip
        for robot, tip in keys
    ]
    outs = run_specs(ctx, specs, "pose test")
    rows, results = [], {}
    for (robot, tip), out in zip(keys, outs, strict=True):
        err, ang = out.final_errors, r.orientation_errors(topo, out, goals)
        both = 100.0 * float(np.mean([e <= r.TOL and a <= r.TOL_DEG for e, a in zip(err, ang, strict=True)]))
        pos = 100.0 * float(np.mean([e <= r.TOL for e in err]))
        results[f"{robot} | {tip}"] = {"within_pct": both, "within_position_pct": pos, "mean": float(np.mean(err)),
                                       "mean_angle_deg": float(np.mean(ang))}  # fmt: skip
        rows.append([robot, tip, f"{both:.0f}", f"{pos:.0f}", f"{np.mean(err):.3f}", f"{np.mean(ang):.1f}"])
    return rows, results, [trained, *outs]
