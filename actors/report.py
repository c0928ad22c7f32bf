"""What a run leaves behind: `summary.json`, `learning_curve.png`, `arm.png` — rebuilt from the run
directory alone (`kinswarm report RUN-DIR`)."""

from __future__ import annotations

import json
import math
from pathlib import Path
from typing import Any

from kinswarm.actors.config import load_run_config
from kinswarm.actors.learning.state import joint_frame, link_end
from kinswarm.protocol.topology import Topology


def read_metrics(run_dir: Path) -> list[dict[str, Any]]:
    path = run_dir / "metrics.jsonl"
    rows = []
    for n, line in enumerate(path.read_text().splitlines(), 1):
        try:
            rows.append(json.loads(line))
        except json.JSONDecodeError as e:
            raise ValueError(f"{path}:{n}: not JSON ({e})") from None
    return rows


def arm_points(topo: Topology, angles: dict[str, float]) -> list[list[tuple[float, float]]]:
    """Polylines of the robot, one per root-to-leaf path, from the agents' own frame composition."""
    ends: dict[str, tuple[float, float, float]] = {}
    starts: dict[str, tuple[float, float, float]] = {}
    for a in topo.order:
        spec = topo.agents[a]
        base = topo.base if spec.parent is None else ends[spec.parent]
        frame = joint_frame(base, spec.offset, angles.get(a, 0.0))
        starts[a], ends[a] = frame, link_end(frame, spec.link_length)
    lines = []
    for leaf in topo.end_effectors:
        path, a = [], leaf
        while a is not None:
            path.append(a)
            a = topo.agents[a].parent
        pts = [(topo.base[0], topo.base[1])]
        for b in reversed(path):
            pts += [starts[b][:2], ends[b][:2]]
        lines.append(pts)
    return lines


def write_plots(run_dir: Path) -> list[Path]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cfg = load_run_config(run_dir / "config.json")
    topo = cfg.topo()
    goal = cfg.resolved_goal(topo)
    rows = read_metrics(run_dir)
    written = []
    if rows:
        ep = [r["epoch"] for r in rows]
        fig, ax = plt.subplots(figsize=(7, 4))
        ax.plot(ep, [r["mean_error"] for r in rows], label="mean error over the epoch")
        ax.plot(ep, [r["final_error"] for r in rows], label="final error (last step)")
        ax.axhline(0.5, color="grey", ls="--", lw=0.8, label="0.5")
        ax.set_yscale("log")
        ax.set_xlabel("epoch")
        ax.set_ylabel("end-effector distance to goal")
        ax.set_title(f"{cfg.run_id}: {topo.name}, {cfg.controller}, reward={cfg.reward}, seed={cfg.seed}")
        ax.legend()
        fig.tight_layout()
        fig.savefig(run_dir / "learning_curve.png", dpi=110)
        plt.close(fig)
        written.append(run_dir / "learning_curve.png")

        final = {a: math.radians(v) for a, v in rows[-1]["final_angles_deg"].items()}
        fig, ax = plt.subplots(figsize=(5, 5))
        for i, (angles, style) in enumerate(((topo.initial_angles(), ":"), (final, "-"))):
            for pts in arm_points(topo, angles):
                xs, ys = zip(*pts, strict=True)
                label = "start" if i == 0 else f"epoch {rows[-1]['epoch']} final"
                ax.plot(xs, ys, style, marker="o", ms=4, color="grey" if i == 0 else "C0", label=label)
        ax.plot(*goal, "r*", ms=14, label=f"goal ({goal[0]:.2f}, {goal[1]:.2f})")
        R = topo.reach
        ax.set_xlim(topo.base[0] - R * 1.05, topo.base[0] + R * 1.05)
        ax.set_ylim(topo.base[1] - R * 1.05, topo.base[1] + R * 1.05)
        ax.set_aspect("equal")
        ax.grid(alpha=0.3)
        handles, labels = ax.get_legend_handles_labels()
        uniq = dict(zip(labels, handles, strict=True))
        ax.legend(uniq.values(), uniq.keys(), loc="lower left", fontsize=8)
        ax.set_title(f"final error {rows[-1]['final_error']:.3f}")
        fig.tight_layout()
        fig.savefig(run_dir / "arm.png", dpi=110)
        plt.close(fig)
        written.append(run_dir / "arm.png")
    return written


def write_summary(run_dir: Path, extra: dict[str, Any]) -> dict[str, Any]:
    cfg = load_run_config(run_dir / "config.json")
    rows = read_metrics(run_dir)
    sim_seconds = sum(r["seconds"] for r in rows)
    steps = sum(r["steps"] for r in rows)
    summary = {
        "run_id": cfg.run_id,
        "topology": cfg.topology,
        "controller": cfg.controller,
        "epochs": len(rows),
        "steps_per_epoch": cfg.steps,
        "seed": cfg.seed,
        "placement": cfg.placement,
        "reward": cfg.reward,
        "learn": cfg.learn,
        "explore": cfg.explore,
        "goal": list(cfg.resolved_goal(cfg.topo())),
        "final_error": [r["final_error"] for r in rows],
        "mean_error": [r["mean_error"] for r in rows],
        "missed_cmds": sum(r["missed_cmds"] for r in rows),
        "steps_per_second": steps / sim_seconds if sim_seconds > 0 else 0.0,
        **extra,
    }
    (run_dir / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
    return summary
