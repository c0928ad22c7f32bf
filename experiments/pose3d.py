"""Reaching poses in 3D on a real arm (examples/iiwa-pose.toml: PyBullet's KUKA LBR iiwa, 7 agents): the tool to a
point and an orientation, success within 5 cm and 15°. reach3d.py's protocol (train on 96 goals x 4 passes, each from
a random start pose; test frozen on two unseen sets of 100 goals from unseen starts), with the pose's state and
controls:

  trained, frozen     every joint sees its turn (state "turn": g_q, the move to its own best angle within its limits,
                      the others held; protocol/frames.py best_turn), moves finely near the goal (frames.move_share)
  untrained, frozen   the same learner never trained
  blind, frozen       trained alike on the plane state with every variable but q uninformative: q only
  rule                each joint one step along sign(g_perp + POSE_WEIGHT phi.a) (`--law rule`): the plane state's
  rule on g_q         each joint one step toward sign(g_q) (`--law turn`): the turn state's rule, no learning
  pseudo-inverse, greedy per joint   the model-based references (`--law pinv`, `--law greedy`)

Every law moves as the agents do (whole steps, quarter steps near the goal: sim/baseline.py move_size). D_goal for a
pose is sqrt(d² + (0.25 angle)²) (frames.pose_distance); docs/notebook/reach3d.md has how the state, the weight and
the fine moves were chosen, and what did not work (the plane state with g_rot: 52 %).
"""

from __future__ import annotations

from typing import Any

from kinswarm.protocol import frames
from kinswarm.protocol.robots import load_robot

from . import reach3d as r3
from .common import Context, Report, mean_std, plt_module
from .swarm import ROOT

#: the pose swarm's file: the iiwa of reach3d with a pose goal (the experiment gives every run its goals and starts)
FILE = ROOT / "examples" / "iiwa-pose.toml"
CONTROLLERS = {"rule on g_perp": "rule", "rule on g_q": "turn", "pseudo-inverse": "pinv", "greedy per joint": "greedy"}
#: the blind swarm: the plane state (q only: every other variable 2 sets over ±1000); the turn state has no q
BLIND = {**r3.BLIND, "state": "plane"}


def run(ctx: Context) -> dict[str, Any]:
    topo = load_robot(r3.ROBOT)
    steps = 60 if ctx.quick else r3.STEPS
    n_test = 5 if ctx.quick else r3.TEST
    n_train, passes = r3.QUICK_TRAINING if ctx.quick else (r3.TRAIN_GOALS, r3.PASSES)
    rep = Report(ctx, "Reaching poses in 3D: the KUKA iiwa, frozen on unseen poses", "beyond the paper (3D, §6)")
    rep.text(
        "The iiwa (`examples/iiwa-pose.toml`: PyBullet's `kuka_iiwa/model.urdf`, seven agents nested as its chain, a "
        "tool point beside the flange) learns to bring its tool to a pose, a point and an orientation, from a random "
        "start; then, frozen (`--learn off --explore off`), it meets poses and start poses it never saw. Each joint "
        "sees its **turn** g_q: how far, and which way, it would move to its own best angle within its limits with "
        "the other joints held (D_goal = sqrt(d² + (0.25 m/rad x angle)²)), in 9 fuzzy sets over ±15°; within 0.1 m "
        "of D_goal its moves are a quarter degree. Beside it, on the same goals and starts:",
        "",
        "- **untrained, frozen**: the same learner never trained;",
        "- **blind (q only), frozen**: trained alike on the plane state with every variable but q uninformative;",
        "- **rule on g_perp** (`--law rule`): each joint one step along the plane state's signal, no learning;",
        "- **rule on g_q** (`--law turn`): each joint one step toward sign(g_q): the turn state's own rule;",
        "- **pseudo-inverse** (`--law pinv`) and **greedy per joint** (`--law greedy`): they know the model.",
        "",
        "Every law moves as the agents do (quarter steps near the goal). Goals are the tool poses of random joint "
        f"configurations (within {r3.MARGIN:.0%} of every joint's range about its middle, {r3.MIN_Z * 100:.0f} cm or "
        "more above the base's plane); start poses are other random configurations; two disjoint test sets ('A', "
        f"'B'). Training: {n_train} poses x {passes} passes in a seeded order, {steps} steps an episode, "
        f"tests as long; the swarm on the first {min(r3.CONTROL_SEEDS, ctx.seeds)} seed(s). Success: within "
        f"{r3.TOL * 100:.0f} cm and {r3.TOL_DEG:.0f}°.",
    )
    rows, results, runs = r3._protocol(ctx, topo, True, steps, n_test, CONTROLLERS, BLIND, file=FILE)
    rep.results = {"poses": results}
    rep.text(f"## Poses: frozen on {n_test} unseen goals from random start poses")
    head = f"within {r3.TOL * 100:.0f} cm and {r3.TOL_DEG:.0f}° (%)"
    rep.table(["controller", "set", head, "mean error (m)", "median (m)", "seeds"], rows)
    _figure(ctx, rep)
    rep.write(
        {
            "robot": "examples/iiwa-pose.toml (kuka_iiwa/model.urdf, tool [0, 0.05, 0.1] on link 7)",
            "training": {"goals": n_train, "passes": passes, "sampling_seed": 1000, "steps": steps},
            "test": {"goals": n_test, "sets": {k: v + 7 for k, v in r3.SETS.items()}, "steps": steps},
            "learner": "state turn (LearnerSettings.for_turn: g_q, 9 sets over ±15°), reward graded (d_min 0.3, c 10, "
            "k 200)",
            "pose_distance": f"sqrt(d² + ({frames.POSE_WEIGHT} m/rad x angle)²): reward, the laws' error, stop test",
            "fine_moves": f"{frames.FINE_SHARE} of a move within {frames.FINE_WITHIN} m of D_goal (agents and laws)",
            "blind": BLIND,
        },
        runs,
    )
    return rep.results


def _figure(ctx: Context, rep: Report) -> None:
    """Share of test poses reached per controller, both sets, seeds as dots."""
    plt = plt_module()
    res = rep.results["poses"]
    labels = list(dict.fromkeys(k.split(" | ")[0] for k in res))
    fig, ax = plt.subplots(figsize=(8.5, 3.2))
    for i, label in enumerate(labels):
        for j, (set_name, shade) in enumerate((("A", 0.8), ("B", 0.45))):
            vals = res[f"{label} | {set_name}"]["within_pct"]
            x = i + (j - 0.5) * 0.38
            ax.bar(x, mean_std(vals)[0], width=0.36, color=f"C{i}", alpha=shade, label=set_name if i == 0 else None)
            ax.plot([x] * len(vals), vals, "k.", ms=4)
    ax.set_xticks(range(len(labels)), labels, rotation=20, fontsize=8, ha="right")
    ax.set_ylabel(f"within {r3.TOL * 100:.0f} cm and {r3.TOL_DEG:.0f}° (%)")
    ax.set_ylim(0, 100)
    ax.axhline(80, color="grey", ls="--", lw=0.8)
    ax.legend(title="test set", fontsize=8)
    ax.grid(alpha=0.3, axis="y")
    rep.save_figure(fig, "within.png", "Poses: share of unseen poses reached within 5 cm and 15° (dots: seeds)")
