"""The peers' report: generalisation, time to skill (with the learning-curve figure), the wrong model, the export."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import numpy as np

from ..common import Context

BARS = (0.90, 0.95)
RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"  # the committed reports (as the package's)
METHOD_NAMES = {"sac": "SAC", "ppo": "PPO, central", "ppo-shared": "PPO, shared by the joints"}
SWARM_KINDS = ("fuzzy", "independent", "tabular")
PEER_STUDY = ("ppo-shared", "sac")  # peers the curves study ran too (its seeds shown beside this command's)
PLASTIC_ADAPT = "trained + direction + sensed tip, learning"  # adapt's row: today's recipe, learning on
LIVE_RECIPE = "swarm, today's recipe, learning"
LIVE_ANY_POSE = "swarm, the any-pose recipe (+ direction + sensed tip), learning"
SETS_IIWA = ("A", "B")  # reach3d's test sets


def _pct(x: float | None) -> str:
    return "—" if x is None else f"{100 * x:.0f} %"


def _ms(xs: list[float], pct: bool = True, digits: int = 3) -> str:
    """Mean ± sample std over seeds (one seed: the value alone)."""
    a = np.asarray(xs, dtype=float)
    f = (lambda v: f"{100 * v:.0f}") if pct else (lambda v: f"{v:.{digits}f}")
    s = f(a.mean()) if len(a) == 1 else f"{f(a.mean())} ± {f(a.std(ddof=1))}"
    return s + (" %" if pct else "")


def _n(seeds: int) -> str:
    return f"{seeds} seed" + ("s" if seeds != 1 else "")


def _first_per_seed(curve: dict[str, list], bar: float) -> tuple[int, float] | None:
    for s, c, w in zip(curve["env_steps"], curve["cpu_seconds"], curve["within"], strict=True):
        if w >= bar - 1e-9:
            return s, c
    return None


def _to_bar(curves: list[dict[str, list]], bar: float) -> str:
    """Env steps and training CPU-seconds to the first test point at `bar`, per seed: mean (min–max) over the seeds
    that get there, and how many do."""
    hits = [h for h in (_first_per_seed(c, bar) for c in curves) if h is not None]
    if not hits:
        return f"no seed by {curves[0]['env_steps'][-1]:,}"
    steps, cpu = [h[0] for h in hits], [h[1] for h in hits]
    spread = "" if len(hits) == 1 else f" ({min(steps):,}–{max(steps):,}; {min(cpu):.0f}–{max(cpu):.0f})"
    return f"{np.mean(steps):,.0f} / {np.mean(cpu):.0f} CPU-s{spread}, {len(hits)} of {len(curves)} seeds"


def _cell(a: dict[str, Any], at: int) -> str:
    if at not in a["env_steps"]:
        return "—"
    i = a["env_steps"].index(at)
    m, lo, hi = a["within_mean"][i], a["within_min"][i], a["within_max"][i]
    return f"{100 * m:.0f} %" if a["seeds"] == 1 else f"{100 * m:.0f} ({100 * lo:.0f}–{100 * hi:.0f}) %"


def _curves_study() -> dict[str, Any] | None:
    """The swarm's curves: the curves study's results (docs/results/research/curves, same protocol), if present."""
    path = RESULTS / "research" / "curves" / "results.json"
    return json.loads(path.read_text()) if path.is_file() else None


def write(
    ctx: Context,
    z: dict[str, int],
    peers: dict[str, Any],
    ref: dict[str, Any],
    swarm: dict[str, float],
    report_cls: Any,
    plt_module: Any,
    onnx_row: dict[str, Any] | None = None,
    sweep: dict[str, dict[str, Any]] | None = None,
) -> dict[str, Any]:
    from ..research._curves_report import _figure, over_seeds
    from .iiwa import swarm_rows

    iiwa_ref = swarm_rows()

    swarm_cpu, swarm_steps = swarm["cpu_seconds"], int(swarm["env_steps"])
    rep = report_cls(ctx, "The deep-RL peers on the same work", "§5.2 and the adapt experiment's faults")
    n_seeds = {r["label"]: len(r["seeds"]) for r in peers.values()}
    versions = next((s.get("versions") for r in peers.values() for s in r["seeds"] if s.get("versions")), {})
    rep.text(
        "SAC and PPO from Stable-Baselines3 ("
        + ("SAC: its JAX port sbx" if "sbx-rl" in versions else "SAC: SB3's own on torch, sbx not being installed")
        + ") with library defaults"
        + (" (the shared PPO also tuned, in a small sweep below)" if sweep else " (no tuning for any method)")
        + ", on `kinswarm.env` built from "
        "examples/reach-generalise.toml (the generalisation recipe's chain4, 1° moves, reward `graded`, the start "
        "pose each episode), each seed trained on Level-3's 64 "
        f"quad-tree goals twice each in that seed's order, {z['train_steps']}-step episodes, for "
        f"{z['budget']:,} env steps (the swarm's budget; one env step: every joint moves once): "
        + "; ".join(f"{label} on {n} seed(s)" for label, n in n_seeds.items())
        + f", all trained here. Tests frozen and deterministic, {z['eval_steps']} steps from the start pose, on the "
        f"first {z['tests']} goals of Halton test sets 0 and 1. The swarm's rows, the rule's and the pseudo-inverse's "
        "are the committed reports' (docs/results/generalisation, docs/results/research/curves, "
        "docs/results/adapt; their seeds in each table), not rerun. 'central' policies see "
        "the whole robot (every reading, the tip, the goal); the shared PPO sees what one agent of the swarm sees "
        "(its S_i and a one-hot of its index) and moves one joint."
        + (" Versions: " + ", ".join(f"{k} {v}" for k, v in versions.items()) + "." if versions else ""),
    )
    earlier = [  # (what, its cached result) trained by an earlier call with this --out
        *((f"{r['label']} seed {s['seed']}", s) for r in peers.values() for s in r["seeds"]),
        *((f"{r['label']} on the iiwa, seed {s['seed']}", s) for r in peers.values() for s in r.get("iiwa", [])),
        *((f"the sweep's {name}", s) for name, s in (sweep or {}).items()),
    ]
    reused = [(what, s) for what, s in earlier if s.get("reused")]
    if reused:
        wall = sum(s.get("wall_seconds", 0.0) for _, s in reused)
        rep.text(
            "Trained by an earlier call with this --out (`OUT/peers/`: each seed's results and its model; their "
            f"CPU-seconds measured then; {wall:.0f} s of wall time summed over those trainings, their curves and the "
            f"iiwa's tests, some of them side by side): {'; '.join(what for what, _ in reused)}. This call's wall time "
            "is the rest."
        )

    study = _curves_study()
    per_seed: dict[str, list[dict[str, list]]] = {}
    labels: dict[str, str] = {}
    if study:
        for k in SWARM_KINDS:
            if k in study["per_seed"]:
                per_seed[k], labels[k] = study["per_seed"][k], study["curves"][k]["label"]
    for m, r in peers.items():
        per_seed[m], labels[m] = [s["curve"] for s in r["seeds"]], r["label"]
    for m in PEER_STUDY:  # the curves study's seeds of a peer, the same protocol: beside this command's
        if study and m in study["per_seed"] and not ctx.quick:
            key = f"{m} (curves study)"
            per_seed[key], labels[key] = study["per_seed"][m], f"{study['curves'][m]['label']} (curves study)"
    agg = {m: over_seeds(labels[m], cs) for m, cs in per_seed.items()}
    rep.text("## In short", *in_short(peers, per_seed, ref, z, iiwa_ref, sweep or {}))
    rep.text("## Generalisation: unseen goals, frozen, from the start pose")
    rows = []
    for r in peers.values():
        ss = r["seeds"]
        rows.append(
            [
                r["label"],
                f"{z['budget']:,}",
                str(len(ss)),
                *(
                    x
                    for k in (0, 1)
                    for x in (
                        _ms([s[f"test_set_{k}"]["within"] for s in ss]),
                        _ms([s[f"test_set_{k}"]["mean"] for s in ss], pct=False),
                    )
                ),
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
    rep.text("Peers: mean ± std over seeds (sample std); the swarm's rows: the mean over its seeds.")

    # -- learning curves: every method, its seeds, the same budget and test points ---------------------------------
    rep.text(
        "## Learning curves and time to skill: seeds, budget and test equal for every method",
        f"Every method on the same run file, goals (each seed's order) and {z['budget']:,}-env-step budget; the frozen "
        f"test of test set 0 every {z['every']:,} env steps from 0; mean and min–max over seeds. CPU-seconds are the "
        "training's alone (tests excluded; torch at one thread). The peers are trained by this command (rows marked "
        "'curves study': that study's seeds of the same peer, the same protocol); the swarm's kinds are the curves "
        "study's (docs/results/research/curves, "
        + (f"`{study['command']}`" if study else "not present")
        + ": its test point at N env steps is the frozen test `--from` its learners after N env steps, the same "
        "test as the peers'). Both ran on this machine; CPU-seconds grow with the machine's load (the peers' "
        "mean load average while training: "
        + ", ".join(
            f"{METHOD_NAMES[m]} {np.mean([s.get('load', float('nan')) for s in r['seeds']]):.1f}"
            for m, r in peers.items()
        )
        + "). PPO collects 2,048 steps per update (per row: the shared policy's rows are the joints).",
    )
    plt = plt_module()
    if agg:
        _figure(rep, plt, agg, z)
    marks = sorted({s for a in agg.values() for s in a["env_steps"]} & {8_000, 16_000, 32_000, z["budget"]})
    rows = []
    for m, a in agg.items():
        cpu_end = a["cpu_mean"][-1]
        rows.append(
            [
                a["label"],
                str(a["seeds"]),
                *(_cell(a, at) for at in marks),
                *(_to_bar(per_seed[m], b) for b in BARS),
                "—" if cpu_end is None else f"{cpu_end:.0f}",
            ]
        )
    rep.table(
        [
            "method",
            "seeds",
            *(f"{at:,} env steps" for at in marks),
            "first ≥ 90 %: env steps / CPU-s, mean (min–max) over the seeds that get there",
            "first ≥ 95 %",
            f"training CPU-s, {z['budget']:,} steps (mean)",
        ],
        rows,
    )
    if sweep:
        _sweep(rep, z, marks, sweep, peers.get("ppo-shared"), 64 if ctx.quick else 2048)
    rep.text(
        f"One Level-3 training of the fuzzy swarm (seed 0, {swarm_steps:,} env steps, inprocess placement) measured "
        f"by this command: {swarm_cpu:.0f} CPU-s"
        + (f" at a load average of {swarm['load']:.1f}." if "load" in swarm else ".")
    )

    _successive(rep, z, peers, ref)
    _iiwa(rep, peers, iiwa_ref)
    _wrong(rep, z, peers, ref)

    first0 = next((s for s in peers.get("ppo-shared", {}).get("seeds", []) if s["seed"] == 0), None)
    onnx = (first0 or {}).get("onnx")
    if onnx:
        rep.text(
            "## The shared policy in ONNX",
            f"`{onnx['file']}` (in this report's directory; seed 0's policy): inputs `obs` float32 (1, obs_dim) — the "
            "agent's observation as parallel_env gives it — and `agent` int64 (1,) — its index in parallel_env's "
            "agents; output `scores` float32 (1, 3) over (−, 0, +): mask with action_mask, take the argmax. "
            + (
                f"onnxruntime against the torch policy in parallel_env: {onnx['same']} of {onnx['decisions']} "
                "decisions the same."
                if onnx.get("checked")
                else f"Not checked: {onnx.get('why')}."
            ),
        )
    if onnx_row is not None and first0 is not None:
        _swarm_row(rep, onnx_row, first0, z["eval_steps"])
    missing = [METHOD_NAMES[m] for m in METHOD_NAMES if m not in peers]
    fewer = [f"{r['label']} ({len(r['seeds'])})" for r in peers.values() if len(r["seeds"]) < ctx.seeds]
    not_done = [
        *([f"Not run for this report: {', '.join(missing)} (the machine's CPU budget)."] if missing else []),
        *(
            [
                f"On fewer than {ctx.seeds} seeds (the machine's CPU budget; KINSWARM_PEERS_METHODS=NAME:N): "
                f"{', '.join(fewer)}; the rows marked 'curves study' are a peer's seeds at the same budget and test."
            ]
            if fewer
            else []
        ),
        *(
            []
            if sweep
            else ["The shared PPO's tuning sweep: not run by this call (KINSWARM_PEERS_METHODS without it)."]
        ),
    ]
    rep.text("## Not done here", " ".join(not_done) or "Nothing: every peer on every seed, the sweep too.")
    slim = {
        m: {
            **r,
            "seeds": [{k: v for k, v in s.items() if k != "errors"} for s in r["seeds"]],
            "iiwa": [{k: v for k, v in s.items() if k not in SETS_IIWA} for s in r.get("iiwa", [])],
            "iiwa_sets": {
                name: {k: [s[name][k] for s in r.get("iiwa", [])] for k in ("within", "mean", "median")}
                for name in SETS_IIWA
            },
        }
        for m, r in peers.items()
    }
    rep.results = {
        "size": z,
        "peers": slim,
        "curves": agg,
        "committed": ref,
        "swarm_training_cpu_seconds": round(swarm_cpu, 1),
        "sweep": {
            name: {k: r[k] for k in ("hp", "curve", "train_cpu_seconds", "load")} for name, r in (sweep or {}).items()
        },
    }
    if onnx_row is not None:
        rep.results["onnx_swarm"] = onnx_row
    rep.write({"run_file": "examples/reach-generalise.toml", "size": z, "seeds": ctx.seed_list})
    return rep.results


def _sweep(
    rep: Any,
    z: dict[str, int],
    marks: list[int],
    sweep: dict[str, dict[str, Any]],
    defaults: dict[str, Any] | None,
    default_n_steps: int,
) -> None:
    """The shared PPO's tuning sweep (seed 0) beside its defaults (seed 0, and the mean over its seeds)."""
    rep.text(
        "### The shared PPO tuned: learning rate x n_steps",
        "A 2x2 over SB3's defaults (learning rate 3e-4, n_steps 2,048 per joint row; the rest the defaults: batch 64, "
        f"10 epochs, a 64-64 network), seed 0, the same goals, budget ({z['budget']:,} env steps) and test points; "
        "its stated budget: these four trainings and their curves, nothing more. Beside them the defaults' seed 0 "
        "(their mean over seeds: the table above). A setting is scored by its curve on test set 0 (the sweep "
        "chooses on the test set, which flatters it: a tuned setting's number is an upper bound).",
    )
    rows: list[list[str]] = []

    def row(name: str, curve: dict[str, list], cpu: float) -> list[str]:
        at = dict(zip(curve["env_steps"], curve["within"], strict=True))
        return [
            name,
            *(_pct(at.get(m)) for m in marks),
            *(_to_bar([curve], b) for b in BARS),
            f"{100 * max(curve['within']):.0f} %",
            f"{cpu:.0f}",
        ]

    if defaults:
        first = next((s for s in defaults["seeds"] if s["seed"] == 0), None)
        if first:
            name = f"defaults: lr 0.0003, n_steps {default_n_steps} (seed 0)"
            rows.append(row(name, first["curve"], first["train_cpu_seconds"]))
    for name, r in sweep.items():
        rows.append(row(name, r["curve"], r["train_cpu_seconds"]))
    rep.table(
        ["PPO, shared, seed 0", *(f"{m:,} env steps" for m in marks), "first ≥ 90 %", "first ≥ 95 %", "best point",
         "training CPU-s"],
        rows,
    )  # fmt: skip


def _best(peers: dict[str, Any], value: Any) -> tuple[str, list[float]]:
    """The peer with the highest mean of `value(seed result)` over its seeds: its label and its per-seed values."""
    per = {r["label"]: [value(s) for s in r["seeds"]] for r in peers.values()}
    label = max(per, key=lambda k: float(np.mean(per[k])))
    return label, per[label]


def _mean_first(curves: list[dict[str, list]], bar: float) -> tuple[float, float, int] | None:
    hits = [h for h in (_first_per_seed(c, bar) for c in curves) if h is not None]
    if not hits:
        return None
    return float(np.mean([h[0] for h in hits])), float(np.mean([h[1] for h in hits])), len(hits)


def in_short(
    peers: dict[str, Any],
    per_seed: dict[str, list],
    ref: dict[str, Any],
    z: dict[str, int],
    iiwa_ref: dict[str, dict[str, list[float]]],
    sweep: dict[str, dict[str, Any]] | None = None,
) -> list[str]:
    """Where the swarm wins and where it loses, by how much, on how many seeds: each line from the tables below."""
    if not peers:
        return ["No peer ran."]
    lines = []
    fz = ref.get("swarm, fuzzy (the paper's)", {}).get("test_set_0")
    label, vals = _best(peers, lambda s: s["test_set_0"]["within"])
    if fz:
        lines.append(
            f"- Unseen goals, frozen, from the start pose (test set 0 within 0.5): the swarm {_pct(fz['within'])} "
            f"({fz.get('seeds', '?')} seeds); the best peer, {label}, {_ms(vals)} ({_n(len(vals))}); the rule "
            f"{_pct(ref.get('rule on g_perp', {}).get('test_set_0', {}).get('within'))}."
        )
    if "fuzzy" in per_seed:
        best = max(
            (m for m in peers if m in per_seed),
            key=lambda m: float(np.mean([c["within"][-1] for c in per_seed[m]])),
        )
        sw, pe = per_seed["fuzzy"], per_seed[best]
        parts = []
        for bar in BARS:
            a, b = _mean_first(sw, bar), _mean_first(pe, bar)
            say = lambda x, n: (  # noqa: E731
                "no seed" if x is None else f"{x[0]:,.0f} env steps / {x[1]:.0f} CPU-s ({x[2]} of {n} seeds)"
            )
            parts.append(f"≥ {100 * bar:.0f} %: the swarm {say(a, len(sw))}, {peers[best]['label']} {say(b, len(pe))}")
        cpu_s = float(np.mean([c["cpu_seconds"][-1] for c in sw]))
        cpu_p = float(np.mean([c["cpu_seconds"][-1] for c in pe]))
        lines.append(
            "- Time to skill (the first test point, mean over the seeds that get there): "
            + "; ".join(parts)
            + f". Training CPU-seconds for {z['budget']:,} env steps (the swarm's: the curves study's): "
            f"the swarm {cpu_s:.0f}, "
            f"{peers[best]['label']} {cpu_p:.0f} ({cpu_p / max(cpu_s, 1e-9):.1f}x the swarm's)."
        )
    default0 = next((s for s in peers.get("ppo-shared", {}).get("seeds", []) if s["seed"] == 0), None)
    if sweep and default0:
        end = {name: r["curve"]["within"][-1] for name, r in sweep.items()}
        best = max(end, key=lambda k: end[k])
        lines.append(
            f"- Tuning the shared PPO (seed 0, {len(sweep)} settings of learning rate x n_steps): at "
            f"{z['budget']:,} env steps the best, {best}, {_pct(end[best])}; the defaults "
            f"{_pct(default0['curve']['within'][-1])}; the range {_pct(min(end.values()))}-{_pct(max(end.values()))}."
        )
    succ = ref.get("successive", {})
    label_c, vals_c = _best(peers, lambda s: s["successive"]["chain4"]["within"])
    label_f, vals_f = _best(peers, lambda s: s["successive"]["joints free"]["within"])
    if succ:
        lines.append(
            "- Successive goals (each from where the last ended, test set 0): on chain4 (±180°) the swarm "
            f"{_pct(succ.get('succ', {}).get('within'))}, the best peer ({label_c}) {_ms(vals_c)}; on the free chain "
            f"the any-pose recipe's swarm {_pct(succ.get('any pose', {}).get('within'))}, the swarm trained from the "
            f"start pose {_pct(succ.get('succ free', {}).get('within'))}, the best peer ({label_f}) {_ms(vals_f)}."
        )
    iiwa = {m: r["iiwa"] for m, r in peers.items() if r.get("iiwa")}
    swarm_iiwa = iiwa_ref.get("swarm, fuzzy (the paper's), frozen", {})
    if iiwa and swarm_iiwa:
        best = max(iiwa, key=lambda m: float(np.mean([s["A"]["within"] for s in iiwa[m]])))
        lines.append(
            "- The iiwa's points (3D, 7 joints, random starts; reach3d's test set A within 5 cm, frozen): the swarm "
            f"{_ms(swarm_iiwa['A'])} ({_n(len(swarm_iiwa['A']))}), the best peer ({peers[best]['label']}) "
            f"{_ms([s['A']['within'] for s in iiwa[best]])} ({_n(len(iiwa[best]))}); the rule "
            f"{_ms(iiwa_ref.get('rule on g_perp', {}).get('A', [float('nan')]))}."
        )
    wrong = ref.get("wrong", {})
    if wrong:
        parts = []
        for cond in wrong:
            rec = wrong[cond].get(PLASTIC_ADAPT)
            label, vals = _best(
                peers, lambda s, c=cond: max(s["wrong"][c]["frozen"]["within"], s["wrong"][c]["learning"]["within"])
            )
            if rec:
                parts.append(
                    f"{cond}: the swarm {rec['within']}, the best peer ({label}, frozen or learning) {_ms(vals)}"
                )
        lines.append(
            f"- A wrong model (adapt's goals; the swarm today's recipe learning on, over the first {z['online']} "
            "goals, 3 seeds): " + "; ".join(parts) + "."
        )
    live = ref.get("live", {})
    if live:
        parts = []
        for cond in [c for c in live if c != "intact"]:
            rows = {(r["robot"], r["label"]): r["within"] for r in live[cond]}
            label, vals = _best(
                peers, lambda s, c=cond: max(s["live"][c]["frozen"]["within"], s["live"][c]["learning"]["within"])
            )
            parts.append(
                f"{cond}: the swarm {rows.get(('chain4, ±180°', LIVE_RECIPE), '—')} on chain4, the any-pose recipe "
                f"{rows.get(('joints free', LIVE_ANY_POSE), '—')} on the free chain, the best peer ({label}) "
                f"{_ms(vals)} on chain4"
            )
        lines.append(
            f"- Live (at a goal intact, then the fault and {z['live_next']} next goals from where it stands): "
            + "; ".join(parts)
            + "."
        )
    return lines


def _successive(rep: Any, z: dict[str, int], peers: dict[str, Any], ref: dict[str, Any]) -> None:
    rep.text(
        "## Successive goals: each goal from where the last ended",
        f"The paper's on-line protocol: the {z['tests']} goals of test set 0 in order, {z['eval_steps']} steps each, "
        "each from where the last ended (the first from the start pose), frozen; on chain4 (joints within ±180°) and "
        "on the same chain with joints that turn freely (examples/chain4-free.toml's limits, the any-pose recipe's "
        "robot). Every method here was trained from the start pose on chain4, except the any-pose recipe's swarm "
        "(examples/reach-any-pose.toml: the same training on the free chain from a random pose each epoch). Swarm "
        "and rule rows: docs/results/generalisation (20 seeds).",
    )
    rows = []
    for r in peers.values():
        for robot, key in (("chain4, ±180°", "chain4"), ("joints free", "joints free")):
            ss = [s["successive"][key] for s in r["seeds"]]
            rows.append(
                [robot, r["label"], str(len(ss)), _ms([s["within"] for s in ss]), _ms([s["mean"] for s in ss], False)]
            )
    for robot, label, who in (
        ("chain4, ±180°", "swarm, fuzzy (the paper's)", "succ"),
        ("joints free", "swarm, fuzzy (the paper's)", "succ free"),
        ("joints free", "swarm, fuzzy, the any-pose recipe (trained from random poses on the free chain)", "any pose"),
        ("chain4, ±180°", "rule on g_perp", "rule succ"),
        ("joints free", "rule on g_perp", "rule succ free"),
    ):
        t0 = ref.get("successive", {}).get(who)
        if t0:
            rows.append([robot, label, str(t0.get("seeds", 1)), _pct(t0["within"]), f"{t0['mean']:.3f}"])
    rows.sort(key=lambda row: row[0] != "chain4, ±180°")
    rep.table(["robot", "method", "seeds", "test set 0 within 0.5", "mean final error"], rows)


def _iiwa(rep: Any, peers: dict[str, Any], ref: dict[str, dict[str, list[float]]]) -> None:
    """reach3d's points: every peer trained and tested here (iiwa.py), the swarm's and the references' rows from
    docs/results/reach3d."""
    ran = {m: r["iiwa"] for m, r in peers.items() if r.get("iiwa")}
    if not ran:
        return
    steps = next(iter(ran.values()))[0]["env_steps"]
    rep.text(
        "## The iiwa's points: 3D, seven joints, random start poses",
        "reach3d's protocol (docs/results/reach3d): examples/iiwa.toml (PyBullet's KUKA iiwa, 7 joints, 1° moves, "
        f"the task's own reward), trained on its 96 goals x 4 passes, each from its random start pose ({steps:,} env "
        "steps, the swarm's budget there), with library defaults; then frozen and deterministic on its test sets A "
        "and B (100 unseen goals, each from an unseen start pose, 400 steps): the share within 5 cm. The swarm's, "
        "the rule's and the pseudo-inverse's rows are that report's, not rerun.",
    )
    rows = []
    for m, ss in ran.items():
        rows.append(
            [
                peers[m]["label"],
                f"{steps:,}",
                str(len(ss)),
                *(_ms([s[k]["within"] for s in ss]) for k in SETS_IIWA),
                _ms([s["A"]["mean"] for s in ss], pct=False),
                f"{np.mean([s['train_cpu_seconds'] for s in ss]):.0f}",
            ]
        )
    from ..reach3d import PASSES, STEPS, TRAIN_GOALS

    for label, r in ref.items():
        seeds = len(r.get("A", []))
        trained = {"swarm, untrained, frozen": "0"}.get(label, f"{TRAIN_GOALS * PASSES * STEPS:,}")
        rows.append(
            [
                label,
                trained if label.startswith("swarm") else "no learning",
                str(seeds),
                *(_ms(r[k]) if k in r else "—" for k in SETS_IIWA),
                _ms(r["A mean"], pct=False) if "A mean" in r else "—",
                "—",
            ]
        )
    rep.table(
        ["method", "training env steps", "seeds", "set A within 5 cm", "set B within 5 cm", "set A mean (m)",
         "training CPU-s"],
        rows,
    )  # fmt: skip


def _wrong(rep: Any, z: dict[str, int], peers: dict[str, Any], ref: dict[str, Any]) -> None:
    wrong = ref.get("wrong", {})
    rep.text(
        "## A wrong model (unknown to every method)",
        f"Adapt's protocol: the first {z['wrong']} goals of test set 0, one {z['wrong_steps']}-step episode each from "
        "the start pose, the fault from the first step. 'frozen': the trained policy as it is. 'learning': the "
        f"trained policy learning on (SB3's `learn`, its stochastic policy acting; PPO updates once its 2,048-step "
        f"rollout is full) through the first {z['online']} of those goals, its learning carried from goal to goal, "
        "from the trained policy again for each fault. The swarm is today's recipe (examples/reach-generalise.toml: "
        '`[learner] plasticity = "direction"`, `[task] tip = "sensed"`), trained as the generalisation '
        "experiment trains it, from docs/results/adapt (3 seeds): 'learning' its row 'trained + direction + sensed "
        f"tip, learning' over the same first {z['online']} goals (its learning carried over all 30: "
        "the 30-goal share in brackets); 'frozen' its row 'trained, frozen', which is the recipe frozen: a frozen "
        "learner keeps the motor direction it had (actors/learning/learner.py: no plasticity without learning), "
        "and with a reversed motor the encoders read the true angles, so the sensed tip is the computed one.",
    )
    rows = []
    for cond in (c for c in ("a1 reversed", "a2, a3 reversed")):
        for r in peers.values():
            ss = [s["wrong"][cond] for s in r["seeds"] if cond in s["wrong"]]
            for how in ("frozen", "learning"):
                rows.append(
                    [
                        cond,
                        f"{r['label']}, {how}",
                        str(len(ss)),
                        _ms([s[how]["within"] for s in ss]),
                        _ms([s[how]["mean"] for s in ss], False),
                    ]
                )
        for v in wrong.get(cond, {}).values():
            rows.append([cond, v["label"], str(v["seeds"]), v["within"], f"{v['mean']:.3f}"])
    rep.table(["fault", "method", "seeds", "within 0.5", "mean final error"], rows)

    live = ref.get("live", {})
    rep.text(
        "### Live: at a goal intact, then the fault and the next goals",
        f"Adapt's live sequence: one goal intact, then the fault from the next episode on and {z['live_next']} next "
        f"goals, each {z['wrong_steps']} steps from where the last ended (seed s: goals 10s to 10s+10 of those 30, "
        "cycling), on chain4 (±180°); 'intact' is the same sequence with nothing broken, what each method reaches of "
        "goals from where the last ended. The share of the next goals within 0.5, mean ± std over seeds. Peers "
        "frozen, and learning on through the sequence; the swarm rows are docs/results/adapt's live sequence (3 "
        "seeds): today's recipe trained from the start pose on chain4, and the any-pose recipe on the free chain.",
    )
    rows = []
    for cond in ("intact", "a1 reversed", "a2, a3 reversed"):
        for r in peers.values():
            ss = [s["live"][cond] for s in r["seeds"] if cond in s["live"]]
            for how in ("frozen", "learning"):
                rows.append(
                    [cond, "chain4, ±180°", f"{r['label']}, {how}", str(len(ss)), _ms([s[how]["within"] for s in ss])]
                )
        for v in live.get(cond, []):
            rows.append([cond, v["robot"], v["label"], str(v["seeds"]), v["within"]])
    rep.table(["fault", "robot", "method", "seeds", "next goals within 0.5"], rows)


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
