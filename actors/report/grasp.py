"""A grasp run's numbers and plots (paper §5.5, Figs. 26-29), from the per-step traces the sim records
in `metrics.jsonl` (`traces`: net_fx, net_fy, net_torque and per fingertip fn/, ft/, margin/, contact/).

A step is a *good grasp* when every fingertip touches with fn > 0, inside its friction cone (margin >= 0:
no slip), the net force is below BALANCE (10 %) of the mean normal force, and the net torque below BALANCE
of the mean normal force times the object's characteristic length L (its larger half-extent): both
bounds in the units of what they bound (force; force x length).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from kinswarm.actors.report.figure import save_figure
from kinswarm.protocol.scene import ObjectSpec
from kinswarm.protocol.topology import Topology

BALANCE = 0.1
FIG_EPOCHS = 4  # epochs shown per figure: first, two between, last


def step_quality(traces: dict[str, list[float]], tips: tuple[str, ...], i: int, L: float) -> dict[str, Any]:
    fn = [traces[f"fn/{t}"][i] for t in tips]
    touch = all(traces[f"contact/{t}"][i] > 0.5 and f > 0.0 for t, f in zip(tips, fn, strict=True))
    cone = all(traces[f"margin/{t}"][i] >= 0.0 for t in tips)
    mean_fn = sum(fn) / len(fn)
    F = math.hypot(traces["net_fx"][i], traces["net_fy"][i])
    tau = abs(traces["net_torque"][i])
    force_ok = touch and F < BALANCE * mean_fn
    torque_ok = touch and tau < BALANCE * mean_fn * L
    return {
        "touch": touch,
        "cone": touch and cone,
        "force_ok": force_ok,
        "torque_ok": torque_ok,
        "good": touch and cone and force_ok and torque_ok,
        "net_force": F,
        "net_torque": tau,
        "mean_fn": mean_fn,
    }


def epoch_quality(row: dict[str, Any], topo: Topology, obj: ObjectSpec, tail: int = 50) -> dict[str, Any]:
    """The epoch's last step, and the share of good steps among its last `tail` steps."""
    traces, tips, L = row["traces"], topo.end_effectors, obj.char_length
    n = len(traces["net_fx"])
    last = step_quality(traces, tips, n - 1, L)
    good_tail = sum(step_quality(traces, tips, i, L)["good"] for i in range(max(0, n - tail), n))
    return {**last, "good_tail_share": good_tail / min(tail, n)}


def grasp_summary(rows: list[dict[str, Any]], topo: Topology, obj: ObjectSpec, last: int = 20) -> dict[str, Any]:
    q = [epoch_quality(r, topo, obj) for r in rows if "traces" in r]
    tail = q[-last:]
    return {
        "criterion": (
            f"last step of the epoch: all fingertips touch (fn > 0) inside their friction cones, |F| < "
            f"{BALANCE} mean fn, |tau| < {BALANCE} mean fn x L (L = {obj.char_length} "
            "length units)"
        ),
        "good": [x["good"] for x in q],
        "touch": [x["touch"] for x in q],
        "net_force": [x["net_force"] for x in q],
        "net_torque": [x["net_torque"] for x in q],
        "mean_fn": [x["mean_fn"] for x in q],
        "good_share_last": sum(x["good"] for x in tail) / len(tail) if tail else 0.0,
        "touch_share_last": sum(x["touch"] for x in tail) / len(tail) if tail else 0.0,
        "last_epochs": len(tail),
    }


def _shown(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    if len(rows) <= FIG_EPOCHS:
        return rows
    idx = sorted({0, len(rows) // 10, len(rows) // 2, len(rows) - 1})
    return [rows[i] for i in idx]


def write_grasp_plots(
    run_dir: Path, topo: Topology, obj: ObjectSpec, rows: list[dict[str, Any]], plt: Any
) -> list[Path]:
    """grasp.png (the fingers around the object at the end of some epochs, Figs. 24a/29),
    grasp_forces.png (net force and torque over the steps of some epochs, Figs. 26-27),
    grasp_cone.png (each finger's |ft| against mu fn over those epochs, Fig. 28),
    grasp_epochs.png (the last step's net force, torque and mean fn over the epochs)."""
    from kinswarm.actors.report.arm import arm_points

    rows = [r for r in rows if "traces" in r]
    if obj is None or not rows:
        return []
    written = []
    shown = _shown(rows)
    cx, cy = obj.center
    hx, hy = obj.half_extents

    fig, axes = plt.subplots(1, len(shown), figsize=(3.3 * len(shown), 3.6), squeeze=False)
    for ax, r in zip(axes[0], shown, strict=True):
        ax.add_patch(plt.Rectangle((cx - hx, cy - hy), 2 * hx, 2 * hy, color="0.8"))
        final = {a: math.radians(v) for a, v in r["final_angles_deg"].items()}
        for i, pts in enumerate(arm_points(topo, final)):
            xs, ys = zip(*pts[3:], strict=True)  # from the finger's base: not the hand's frame (world base, hand)
            ax.plot(xs, ys, "-o", ms=3, color=f"C{i}")
        for i, (_, g) in enumerate(obj.grasp.items()):
            ax.plot(*g, "*", color=f"C{i}", ms=10, mec="k")
        q = epoch_quality(r, topo, obj)
        ax.set_title(f"epoch {r['epoch']}: |F| {q['net_force']:.2f}, |tau| {q['net_torque']:.2f}", fontsize=8)
        ax.set_aspect("equal")
        ax.set_xlim(-3.3, 3.3)
        ax.set_ylim(-2.6, 2.6)
    fig.suptitle("fingers at the end of the epoch (stars: grasp points)", fontsize=9)
    fig.tight_layout()
    written.append(_save(fig, plt, run_dir / "grasp.png"))

    fig, axes = plt.subplots(2, len(shown), figsize=(3.3 * len(shown), 5), squeeze=False, sharey="row")
    for j, r in enumerate(shown):
        t = r["traces"]
        F = [math.hypot(x, y) for x, y in zip(t["net_fx"], t["net_fy"], strict=True)]
        fns = [[t[f"fn/{tip}"][i] for tip in topo.end_effectors] for i in range(len(F))]
        mean_fn = [sum(f) / len(f) for f in fns]
        axes[0, j].plot(F, label="|net force|")
        axes[0, j].plot([BALANCE * m for m in mean_fn], "--", label=f"{BALANCE} x mean fn")
        axes[0, j].set_title(f"epoch {r['epoch']}", fontsize=9)
        axes[1, j].plot([abs(x) for x in t["net_torque"]], color="C2", label="|net torque|")
        axes[1, j].plot([BALANCE * m * obj.char_length for m in mean_fn], "--", color="C1", label="bound")
        axes[1, j].set_xlabel("step")
    axes[0, 0].set_ylabel("force")
    axes[1, 0].set_ylabel("torque (force x length)")
    axes[0, 0].legend(fontsize=7)
    axes[1, 0].legend(fontsize=7)
    fig.tight_layout()
    written.append(_save(fig, plt, run_dir / "grasp_forces.png"))

    fig, axes = plt.subplots(1, len(shown), figsize=(3.3 * len(shown), 3.4), squeeze=False, sharey=True)
    for ax, r in zip(axes[0], shown, strict=True):
        t = r["traces"]
        top = 0.0
        for i, tip in enumerate(topo.end_effectors):
            fn, ft = t[f"fn/{tip}"], [abs(v) for v in t[f"ft/{tip}"]]
            ax.plot(fn, ft, ".", ms=2, color=f"C{i}", label=tip)
            top = max(top, *fn, 1e-3)
        ax.plot([0, top], [0, obj.mu * top], "k--", lw=1, label=f"cone |ft| = {obj.mu} fn")
        ax.set_xlabel("fn")
        ax.set_title(f"epoch {r['epoch']}", fontsize=9)
    axes[0, 0].set_ylabel("|ft|")
    axes[0, 0].legend(fontsize=7)
    fig.tight_layout()
    written.append(_save(fig, plt, run_dir / "grasp_cone.png"))

    q = [epoch_quality(r, topo, obj) for r in rows]
    ep = [r["epoch"] for r in rows]
    fig, ax = plt.subplots(figsize=(7, 3.6))
    ax.plot(ep, [x["net_force"] for x in q], label="|net force|")
    ax.plot(ep, [x["net_torque"] for x in q], label="|net torque|")
    ax.plot(ep, [x["mean_fn"] for x in q], label="mean fn")
    good = [e for e, x in zip(ep, q, strict=True) if x["good"]]
    ax.plot(good, [0.0] * len(good), "g|", ms=12, label="good grasp")
    ax.set_xlabel("epoch")
    ax.set_title("the epoch's last step", fontsize=9)
    ax.legend(fontsize=7)
    fig.tight_layout()
    written.append(_save(fig, plt, run_dir / "grasp_epochs.png"))
    return written


def _save(fig: Any, plt: Any, path: Path) -> Path:
    save_figure(fig, path, dpi=100)
    plt.close(fig)
    return path
