"""The curves' report: the figure (over env steps, over CPU-seconds), the table of every point, time to skill. (A
leading underscore: the research runner lists modules without one as studies.)"""

from __future__ import annotations

import os
from collections.abc import Sequence
from typing import Any

import numpy as np

from ..common import Context

BARS = (0.90, 0.95)
COLORS = {
    "fuzzy": "C0",
    "independent": "C1",
    "tabular": "C2",
    "ppo-shared": "C3",
    "sac": "C4",
    "ppo": "C5",  # the peers report draws these too
    "ppo-shared (curves study)": "C6",
    "sac (curves study)": "C7",
}


# -- over seeds (the peers report reads it too) ---------------------------------------------------------------------
def over_seeds(label: str, curves: Sequence[dict[str, Any]]) -> dict[str, Any]:
    """Mean, min and max over seeds at every point (the points every seed has; a PPO rollout may pass the budget)."""
    n = min(len(c["env_steps"]) for c in curves)
    steps = curves[0]["env_steps"][:n]
    assert all(c["env_steps"][:n] == steps for c in curves), "seeds tested at other env steps"
    w = np.array([c["within"][:n] for c in curves], dtype=float)
    cpu = [[x for x in col if x is not None] for col in zip(*(c["cpu_seconds"][:n] for c in curves), strict=True)]
    return {
        "label": label,
        "seeds": len(curves),
        "env_steps": steps,
        "within_mean": w.mean(axis=0).tolist(),
        "within_min": w.min(axis=0).tolist(),
        "within_max": w.max(axis=0).tolist(),
        "cpu_mean": [float(np.mean(x)) if x else None for x in cpu],
        "mean_error": np.array([c["mean"][:n] for c in curves]).mean(axis=0).tolist(),
        "per_seed": [c["within"][:n] for c in curves],
    }


def _pct(x: float) -> str:
    return f"{100 * x:.0f}"


def _cell(a: dict[str, Any], i: int) -> str:
    m, lo, hi = a["within_mean"][i], a["within_min"][i], a["within_max"][i]
    return _pct(m) if a["seeds"] == 1 or lo == hi else f"{_pct(m)} ({_pct(lo)}–{_pct(hi)})"


def _first(a: dict[str, Any], bar: float) -> str:
    """The first point where the seeds' mean share reaches `bar`; how many seeds had reached it there."""
    for i, (s, w) in enumerate(zip(a["env_steps"], a["within_mean"], strict=True)):
        if w >= bar - 1e-9:
            cpu = a["cpu_mean"][i]
            seeds = sum(p[i] >= bar - 1e-9 for p in a["per_seed"])
            at = f"{s:,} steps" + ("" if cpu is None else f" / {cpu:.0f} CPU-s")
            return f"{at} ({seeds} of {a['seeds']} seeds there)"
    return f"not by {a['env_steps'][-1]:,} steps"


def _figure(rep: Any, plt: Any, agg: dict[str, dict[str, Any]], z: dict[str, int]) -> None:
    from matplotlib.ticker import FixedLocator, FuncFormatter, NullFormatter

    fig, (ax_s, ax_c) = plt.subplots(1, 2, figsize=(11, 4.2), sharey=True)
    for m, a in agg.items():
        color = COLORS.get(m)
        y = [100 * w for w in a["within_mean"]]
        lo, hi = [100 * w for w in a["within_min"]], [100 * w for w in a["within_max"]]
        label = f"{a['label']} ({a['seeds']} seeds)"
        ax_s.plot(a["env_steps"], y, marker=".", color=color, label=label)
        ax_s.fill_between(a["env_steps"], lo, hi, color=color, alpha=0.18, lw=0)
        keep = [i for i, c in enumerate(a["cpu_mean"]) if c is not None and c > 0]  # log axis: the trained points
        if keep:
            xs = [a["cpu_mean"][i] for i in keep]
            ax_c.plot(xs, [y[i] for i in keep], marker=".", color=color, label=label)
            ax_c.fill_between(xs, [lo[i] for i in keep], [hi[i] for i in keep], color=color, alpha=0.18, lw=0)
    for ax in (ax_s, ax_c):
        ax.axhline(90, color="grey", lw=0.6, ls=":")
        ax.axhline(95, color="grey", lw=0.6, ls="--")
        ax.set_ylim(0, 102)
        ax.grid(alpha=0.3)
    ax_s.set_xlabel("env steps of training (a step: every joint moves once)")
    ax_s.set_ylabel(f"test set 0: share of {z['tests']} goals within 0.5 (%)")
    ax_c.set_xscale("log")
    # plain numbers at 1-2-5 steps (a log axis labels decades only, and the methods may span less than one)
    ax_c.xaxis.set_major_locator(FixedLocator([m * 10**e for e in range(-1, 5) for m in (1, 2, 5)]))
    ax_c.xaxis.set_major_formatter(FuncFormatter(lambda x, _: f"{x:g}"))
    ax_c.xaxis.set_minor_formatter(NullFormatter())
    ax_c.set_xlabel("training CPU-seconds (mean over seeds; tests excluded; log)")
    ax_s.legend(fontsize=7, loc="lower right")
    rep.save_figure(
        fig,
        "curves.png",
        f"Share of test set 0 within 0.5 ({z['tests']} goals, frozen, {z['eval_steps']} steps from the start pose) "
        "over training: mean over seeds (line) and min–max over seeds (band); left over env steps, right over "
        "training CPU-seconds",
    )


def write(
    ctx: Context,
    z: dict[str, int],
    agg: dict[str, dict[str, Any]],
    curves: dict[str, list[dict[str, Any]]],
    report_cls: Any,
    plt_module: Any,
    runs: list[Any] | None = None,
) -> dict[str, Any]:
    rep = report_cls(ctx, "Learning curves: the swarm and its peers over env steps, seeds and budgets equal", "§5.2")
    rep.text(
        "Every method trained on examples/reach-generalise.toml (chain4, 1° moves, reward `graded`, the start pose "
        f"each episode) on Level-3's 64 quad-tree goals twice each in the seed's order, {z['train_steps']}-step "
        f"episodes, for {z['budget']:,} env steps (one env step: every joint moves once). Every {z['every']:,} env "
        f"steps from 0, the frozen, deterministic policy is tested on the first {z['tests']} goals of Halton test "
        f"set 0, {z['eval_steps']} steps each from the start pose: the share whose final error is within 0.5. "
        "Swarm: the frozen run (`--from` the checkpoint of a training of that many env steps, learn and explore "
        "off), which steps the robot as parallel_env does (tests/test_env.py); peers: learners.evaluate in "
        "parallel_env / gym_env, as `kinswarm experiment peers` tests them. Library defaults for the peers "
        "(SB3's PPO: lr 3e-4, n_steps 2048 per joint row, batch 64, 10 epochs; torch at one thread). CPU-seconds: "
        "training alone, tests excluded (swarm: each training's own process CPU time, measured when it ran, "
        "numba compiled beforehand; peers: learners.CurveCallback's). All of it ran fresh by this command on this "
        f"machine ({os.cpu_count()} cores shared with other work, at a load average of {os.getloadavg()[0]:.1f} when "
        "the report was written): CPU-seconds grow with the load."
    )
    chosen = os.environ.get("KINSWARM_CURVES_METHODS")
    if chosen:  # not in the command line above: the methods and their seeds
        rep.text(f"Methods and seeds as chosen for this call: `KINSWARM_CURVES_METHODS={chosen}`.")
    methods = list(agg)
    missing = [m for m in ("fuzzy", "independent", "tabular", "ppo-shared", "sac") if m not in agg]
    if missing:
        rep.text(f"Not run by this command: {', '.join(missing)}.")
    rep.text("## The curves")
    _figure(rep, plt_module(), agg, z)
    steps = agg[methods[0]]["env_steps"] if methods else []
    rep.text(
        "Share of test set 0 within 0.5 (%), mean over seeds (min–max over seeds where they differ), at every "
        "point (env steps):"
    )
    rows = []
    for a in agg.values():
        rows.append([a["label"], str(a["seeds"]), *(_cell(a, i) for i in range(len(a["env_steps"])))])
    rep.table(["method", "seeds", *(f"{s:,}" for s in steps)], rows)
    rep.text("## Time to skill and cost")
    rows = []
    for a in agg.values():
        cpu = a["cpu_mean"][-1]
        rate = f"{a['env_steps'][-1] / cpu:,.0f}" if cpu else "—"
        rows.append(
            [
                a["label"],
                *(_first(a, b) for b in BARS),
                f"{100 * a['within_mean'][-1]:.0f} %",
                f"{a['mean_error'][-1]:.3f}",
                "—" if cpu is None else f"{cpu:.1f}" if cpu < 10 else f"{cpu:.0f}",
                rate,
            ]
        )
    rep.table(
        [
            "method",
            "first point the mean reaches ≥ 90 %",
            "≥ 95 %",
            "at the budget",
            "mean final error at the budget",
            "training CPU-s for the budget (mean)",
            "env steps per CPU-s",
        ],
        rows,
    )
    rep.results = {"size": z, "curves": agg, "per_seed": curves}
    rep.write({"run_file": "examples/reach-generalise.toml", "size": z}, runs or [])
    return rep.results
