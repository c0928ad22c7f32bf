"""The peers' report: generalisation, time to skill (with the learning-curve figure), the wrong model, the export."""

from __future__ import annotations

from typing import Any

from ..common import Context

BARS = (0.90, 0.95)
METHOD_NAMES = {"sac": "SAC", "ppo": "PPO, central", "ppo-shared": "PPO, shared by the joints"}


def _pct(x: float | None) -> str:
    return "—" if x is None else f"{100 * x:.0f} %"


def _skill(curve: dict[str, list], bar: float) -> str:
    for s, c, w in zip(curve["env_steps"], curve["cpu_seconds"], curve["within"], strict=True):
        if w >= bar:
            return f"{s:,} steps / {c:.0f} CPU-s"
    last = curve["env_steps"][-1] if curve["env_steps"] else 0
    return f"not within {last:,} steps"


def write(
    ctx: Context,
    z: dict[str, int],
    peers: dict[str, Any],
    ref: dict[str, Any],
    swarm: dict[str, float],
    report_cls: Any,
    plt_module: Any,
    onnx_row: dict[str, Any] | None = None,
) -> dict[str, Any]:
    swarm_cpu, swarm_steps = swarm["cpu_seconds"], int(swarm["env_steps"])
    rep = report_cls(ctx, "The deep-RL peers on the same work", "§5.2 and the adapt experiment's faults")
    rep.text(
        "SAC and PPO from Stable-Baselines3 (SAC: its JAX port sbx when installed) with library defaults, on "
        "`kinswarm.env` built from examples/reach-generalise.toml (the generalisation recipe's chain4, 1° moves, "
        "reward `graded`, the start pose each episode), trained on Level-3's 64 quad-tree goals twice each in "
        f"seed 0's order, {z['train_steps']}-step episodes: "
        + ", ".join(f"{r['label']} {r['budget']:,}" for r in peers.values())
        + " env steps (the swarm's: 64,000), one seed (0). Tests frozen and deterministic, "
        f"{z['eval_steps']} steps from the start pose, on the first "
        f"{z['tests']} goals of Halton test sets 0 and 1. The swarm's rows, the rule's and the pseudo-inverse's are "
        "the committed reports' (docs/results/generalisation: 6 seeds; docs/results/adapt: 3 seeds), not rerun. "
        "'central' policies see the whole robot (every reading, the tip, the goal); the shared PPO sees what one "
        "agent of the swarm sees (its S_i and a one-hot of its index) and moves one joint."
    )
    reused = [r["label"] for r in peers.values() if r.get("reused")]
    if reused:
        rep.text(
            f"Reused from an earlier call with this --out (`OUT/peers/<method>.json`, trained and tested then, their "
            f"CPU-seconds measured then): {'; '.join(reused)}. This call's wall time is the rest: the swarm's "
            "CPU-seconds, the ONNX swarm runs and the report."
        )
    rep.text("## Generalisation: unseen goals, frozen, from the start pose")
    rows = []
    for r in peers.values():
        rows.append(
            [
                r["label"],
                f"{r['budget']:,}",
                "1",
                _pct(r["test_set_0"]["within"]),
                f"{r['test_set_0']['mean']:.3f}",
                _pct(r["test_set_1"]["within"]),
                f"{r['test_set_1']['mean']:.3f}",
            ]
        )
    for label in (
        "swarm, fuzzy (the paper's)",
        "swarm, independent",
        "swarm, tabular",
        "rule on g_perp",
        "pseudo-inverse",
    ):
        r = ref.get(label)
        if not r:
            continue
        t0, t1 = r.get("test_set_0", {}), r.get("test_set_1", {})
        is_swarm = label.startswith("swarm")
        rows.append(
            [
                label,
                "64,000" if is_swarm else "no learning",
                str(t0.get("seeds", 1)),
                _pct(t0.get("within")),
                f"{t0.get('mean', float('nan')):.3f}",
                _pct(t1.get("within")),
                f"{t1.get('mean', float('nan')):.3f}",
            ]
        )
    rep.table(
        ["method", "training env steps", "seeds", "set 0 within 0.5", "set 0 mean", "set 1 within 0.5", "set 1 mean"],
        rows,
    )

    rep.text(
        "## Time to skill",
        "Every " + ", ".join(f"{r['every']:,}" for r in peers.values()) + " env steps (in the table's order) "
        "the frozen policy is tested on test set 0; CPU-seconds are the "
        "training's alone (this process's CPU time, tests excluded; torch at one thread). The swarm's "
        "generalisation runs record no curve: its point is its budget, and its CPU-seconds are one Level-3 "
        f"training (seed 0, {swarm_steps:,} env steps, inprocess placement) measured here: {swarm_cpu:.0f} CPU-s"
        + (f" (at a load average of {swarm['load']:.1f}). " if "load" in swarm else ". ")
        + "PPO collects 2,048 steps per update: its last point can pass the budget. Curves over seeds at the "
        "same 64,000-step budget, a point every 8,000 env steps from 0, the swarm's learner kinds "
        "included: docs/results/research/curves/report.md (`python -m kinswarm.experiments.research curves`).",
    )
    rows = []
    for r in peers.values():
        rows.append([r["label"], *(_skill(r["curve"], b) for b in BARS), f"{r['train_cpu_seconds']:.0f}"])
    fz = ref.get("swarm, fuzzy (the paper's)", {}).get("test_set_0", {})
    if fz:
        at = f"64,000 steps / {swarm_cpu:.0f} CPU-s"
        rows.append(
            [
                "swarm, fuzzy (the paper's)",
                *((f"≤ {at}" if fz["within"] >= b else f"not at {at}") for b in BARS),
                f"{swarm_cpu:.0f}",
            ]
        )
    rep.table(["method", "≥ 90 % of set 0 within 0.5", "≥ 95 %", "training CPU-s (env steps as above)"], rows)
    plt = plt_module()
    fig, ax = plt.subplots(figsize=(7, 4))
    for r in peers.values():
        ax.plot(r["curve"]["env_steps"], [100 * w for w in r["curve"]["within"]], marker=".", label=r["label"])
    for label, mark in (("swarm, fuzzy (the paper's)", "*"), ("swarm, independent", "s"), ("swarm, tabular", "^")):
        t0 = ref.get(label, {}).get("test_set_0")
        if t0:
            ax.plot([64_000], [100 * t0["within"]], mark, ms=10, label=f"{label} (6 seeds, its budget)")
    for label, ls in (("rule on g_perp", ":"), ("pseudo-inverse", "--")):
        t0 = ref.get(label, {}).get("test_set_0")
        if t0:
            ax.axhline(100 * t0["within"], ls=ls, color="grey", lw=1)
            ax.annotate(label, (0, 100 * t0["within"]), fontsize=7, va="bottom")
    ax.set_xlabel("env steps of training")
    ax.set_ylabel("test set 0 within 0.5 (%)")
    ax.set_ylim(0, 102)
    ax.legend(fontsize=7, loc="lower right")
    rep.save_figure(
        fig,
        "curves.png",
        "Share of test set 0 within 0.5 over training: the peers' curves, the swarm's "
        "points at its budget, the rule and the pseudo-inverse (no learning)",
    )

    rep.text(
        "## A wrong model (unknown to every method)",
        f"Adapt's protocol: the first {z['wrong']} goals of test set 0, one {z['wrong_steps']}-step episode each "
        "from the start pose, the fault from the first step. 'learning' is the trained SAC policy learning on "
        f"(sbx/SB3 `learn`, its stochastic policy acting) on the first {z['online']} of those goals, its learning "
        "carried from goal to goal, started again from the trained policy for each fault. Swarm rows: "
        "docs/results/adapt (mean over 3 seeds).",
    )
    rows = []
    for cond in peers[next(iter(peers))]["wrong"]:
        for r in peers.values():
            for how, v in r["wrong"][cond].items():
                rows.append([cond, f"{r['label']}, {how}", _pct(v["within"]), f"{v['mean']:.3f}"])
        for who, v in ref.get("wrong", {}).get(cond, {}).items():
            rows.append(
                [
                    cond,
                    who if who in ("rule", "pseudo-inverse") else f"swarm, {who}",
                    _pct(v["within"]),
                    f"{v['mean']:.3f}",
                ]
            )
    rep.table(["fault", "method", "within 0.5", "mean final error"], rows)

    onnx = peers.get("ppo-shared", {}).get("onnx")
    if onnx:
        rep.text(
            "## The shared policy in ONNX",
            f"`{onnx['file']}` (in this report's directory): inputs `obs` float32 (1, obs_dim) — the agent's "
            "observation as parallel_env gives it — and `agent` int64 (1,) — its index in parallel_env's "
            "agents; output `scores` float32 (1, 3) over (−, 0, +): mask with action_mask, take the argmax. "
            + (
                f"onnxruntime against the torch policy in parallel_env: {onnx['same']} of {onnx['decisions']} "
                "decisions the same."
                if onnx.get("checked")
                else f"Not checked: {onnx.get('why')}."
            ),
        )
    if onnx_row is not None:
        _swarm_row(rep, onnx_row, peers["ppo-shared"], z["eval_steps"])
    missing = [METHOD_NAMES[m] for m in METHOD_NAMES if m not in peers]
    rep.text(
        "## Not done here",
        (f"Not run for this report: {', '.join(missing)} (the machine's CPU budget). " if missing else "")
        + "The successive protocol (each goal from where the last ended), the iiwa's reach3d row, more seeds of "
        "the peers and longer budgets: not run within this report's CPU budget.",
    )
    rep.results = {"size": z, "peers": peers, "committed": ref, "swarm_training_cpu_seconds": round(swarm_cpu, 1)}
    if onnx_row is not None:
        rep.results["onnx_swarm"] = onnx_row
    rep.write({"run_file": "examples/reach-generalise.toml", "size": z, "seed": 0})
    return rep.results


def _share(errors: list[float], tol: float = 0.5) -> str:
    return f"{sum(e <= tol for e in errors)} / {len(errors)}"


def _same(flag: bool | None) -> str:
    return {True: "yes, to the bit", False: "no", None: "—"}[flag]


def _swarm_row(rep: Any, r: dict[str, Any], torch_row: dict[str, Any], eval_steps: int) -> None:
    """Trained elsewhere, deployed as a swarm, broken live: onnx_swarm.row's numbers."""
    n, steps = r["goals"], r["steps"]
    lock = r.get("lock")
    rep.text(
        "## Trained elsewhere, run as a swarm, broken live",
        'The file above as `[learner] kind = "onnx"` (the run file: `OUT/peers/onnx-swarm/onnx-swarm.toml`, the '
        "recipe's robot, reward and observation, the policy shared by every agent with its index), through "
        "`kinswarm run` in "
        f"`process` placement (one OS process per actor, over Zenoh) on the first {n} goals of test set 0, one "
        f"{steps}-step epoch each from the start pose; once, intact; once with `kinswarm fault RUN lock a2` sent "
        f"while it ran, after its first {r.get('lock_after', '?')} epochs. Beside it, the same file stepped in "
        "parallel_env (onnxruntime, the argmax over the moves the action mask allows, as the agents take them), "
        "intact and with a2 locked from each episode's first step. A fault stays across epochs and the world reset "
        "puts every joint at its initial angle, so every epoch after the one the lock landed in is the env's locked "
        "episode."
        + (
            " The live run's epochs before the landing one are the intact env's, to the bit."
            if r.get("before_identical")
            else ""
        ),
    )
    rows = [
        [f"parallel_env, intact ({n} goals)", _share(r["env_intact"]), "—"],
        [f"process swarm, intact ({n} goals)", _share(r["swarm_intact"]), _same(r["intact_identical"])],
    ]
    if lock is not None and r.get("after"):
        after = r["after"]
        pick = lambda xs: [xs[i] for i in after]  # noqa: E731 -- the epochs after the landing one
        first, last = after[0] + 1, after[-1] + 1
        rows += [
            [
                f"process swarm, `lock a2` sent live (landed at epoch {lock['epoch'] + 1}, step {lock['step']}): "
                f"epochs {first}-{last}",
                _share(pick(r["swarm_live"])),
                _same(r["after_identical"]),
            ],
            [f"parallel_env, a2 locked from step 0, the same {len(after)} goals", _share(pick(r["env_locked"])), "—"],
            [f"parallel_env, intact, the same {len(after)} goals", _share(pick(r["env_intact"])), "—"],
        ]
    else:
        said = (r.get("fault") or {}).get("said", "not sent")
        rows.append(["process swarm, `lock a2` sent live", f"did not land before the run ended ({said})", "—"])
    unmasked = torch_row["test_set_0"]["errors"][:n]
    if len(unmasked) == n and eval_steps == steps:  # the generalisation table's test of the torch policy, these goals
        rows.append(
            [f"the torch policy in parallel_env, no action mask (as tested above), {n} goals", _share(unmasked), "—"]
        )
    rep.table(["the shared PPO policy", "within 0.5", "final errors the same as the env's"], rows)
