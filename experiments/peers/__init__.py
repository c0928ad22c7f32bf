"""The deep-RL peers on the swarm's own work: what a practitioner would pick instead, on the same goals.

SAC (sbx, SB3's JAX port, when installed; else SB3's) on gym_env's continuous Box, PPO on gym_env's MultiDiscrete (a
central policy seeing the whole robot), and PPO with one policy shared by every joint on parallel_env (independent
learners with parameter sharing), each trained on the generalisation protocol's Level-3 goals (64 quad-tree centres,
twice each in a seeded order, 500-step episodes: PPO for the swarm's 64k env steps, SAC for 16k) with library
defaults and the task's own reward (`graded`), then:

  generalisation   frozen, deterministic, from the start pose: test sets 0 and 1 (100 Halton goals, 200 steps each)
  time to skill    the test set 0 share within 0.5 every EVERY env steps: env steps and training CPU-seconds until
                   >= 90 % and >= 95 %
  wrong model      a1 reversed, a2 and a3 reversed (unknown), adapt's 30 goals of test set 0, one 500-step episode
                   each: frozen, and SAC learning on (its learning carried from goal to goal)

against the swarm's three kinds, the rule and the pseudo-inverse as their committed reports give them
(docs/results/generalisation, docs/results/adapt: not rerun), and the swarm's training CPU-seconds measured here.
The shared policy is exported to ONNX (learners.export_onnx), checked against torch with onnxruntime, and run through
`kinswarm run` as `[learner] kind = "onnx"` in a process swarm on test goals, intact and with `kinswarm fault ... lock
a2` sent live, beside the same file stepped in parallel_env (onnx_swarm.py: onnxruntime, no torch).
Needs the `peers` extra: pip install -e '.[peers]'.
"""

from __future__ import annotations

import json
import os
import resource
import shutil
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path
from typing import Any

import numpy as np

from ..common import Context, Report, plt_module
from ..goals import halton, quadtree, training_order


def _learners() -> Any:
    """The peers' training code (torch, SB3), imported when a peer is trained: the ONNX row (onnx_swarm) needs none of
    it. Without the extra: one line naming it, not a traceback (a ValueError: the CLI's kind of a user's error)."""
    try:
        from . import learners
    except ImportError as e:
        raise ValueError(
            f"kinswarm experiment peers needs the peers extra ({e.name} is missing): on a machine without a GPU first "
            "pip install torch --index-url https://download.pytorch.org/whl/cpu (else pip pulls torch's CUDA build, "
            "several GB), then pip install -e '.[peers]'"
        ) from None
    return learners


METHODS = {
    "sac": "SAC, central (Box)",
    "ppo": "PPO, central (MultiDiscrete)",
    "ppo-shared": "PPO, one policy shared by the joints",
}
LEVEL, REPS, TRAIN_STEPS, EVAL_STEPS = 3, 2, 500, 200
BUDGET = REPS * 4**LEVEL * TRAIN_STEPS  # the swarm's 64k env steps
# SAC's budget: a quarter of the swarm's. Measured here, SAC runs ~80 env steps per CPU-second (sbx; SB3's torch ~50)
# against PPO's ~440 and the swarm's thousands: 64k steps would be ~13 CPU-minutes of the record's budget alone
BUDGETS = {"sac": BUDGET // 4, "ppo": BUDGET, "ppo-shared": BUDGET}
EVERY = {"sac": 8_000, "ppo": 16_000, "ppo-shared": 16_000}  # a test of 100 goals is 20k env steps
SEED = 0
WRONG = {
    "a1 reversed": [{"fault": "reverse", "targets": ["a1"]}],
    "a2, a3 reversed": [{"fault": "reverse", "targets": ["a2", "a3"]}],
}
WRONG_GOALS, WRONG_STEPS = 30, 500
ONLINE_GOALS = 10  # SAC learning on: the first 10 of them (its env steps cost ~15x the swarm's)
# the shared policy's ONNX file as a process swarm: the first 30 goals of test set 0, 200 steps each, `kinswarm fault
# ... lock a2` sent once 4 epochs are done (the quick version: 6 goals of 100 steps, the lock after the first, so that
# it lands with epochs still to come)
ONNX_GOALS, ONNX_LOCK_AFTER = 30, 4
RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results"
SWARM_ROWS = {
    "swarm, fuzzy (the paper's)": "Level-3",
    "swarm, independent": "Level-3, independent (no JASM)",
    "swarm, tabular": "Level-3, tabular (no fuzzy interpolation)",
}
LAWS = {"rule on g_perp": "rule on g_perp", "pseudo-inverse": "pseudo-inverse"}


def _size(quick: bool) -> dict[str, int]:
    if quick:
        return {
            "budget": 256,
            "train_steps": 64,
            "every": 128,
            "tests": 3,
            "eval_steps": 20,
            "wrong": 2,
            "wrong_steps": 20,
            "online": 1,
            "onnx_goals": 6,
            "onnx_steps": 100,
            "onnx_lock_after": 1,
        }
    return {
        "train_steps": TRAIN_STEPS,
        "tests": 100,
        "eval_steps": EVAL_STEPS,
        "wrong": WRONG_GOALS,
        "wrong_steps": WRONG_STEPS,
        "online": ONLINE_GOALS,
        "onnx_goals": ONNX_GOALS,
        "onnx_steps": EVAL_STEPS,
        "onnx_lock_after": ONNX_LOCK_AFTER,
    }


def run_method(method: str, quick: bool, out: str) -> dict[str, Any]:
    """One peer: trained, its curve, its frozen tests, the wrong-model rows; the shared policy exported."""
    learners = _learners()
    z = _size(quick)
    goals = list(training_order(quadtree(LEVEL), REPS, SEED))
    if quick:
        goals = goals[:4]
    tests = {k: halton(k)[: z["tests"]] for k in (0, 1)}
    cached = Path(out) / f"{method}.json"
    if cached.is_file():  # this method's results of an earlier call with the same out dir (the report says so)
        return {**json.loads(cached.read_text()), "reused": True}
    every, budget = z.get("every", EVERY[method]), z.get("budget", BUDGETS[method])
    model, curve, cpu = learners.train(method, goals, z["train_steps"], budget, SEED, every, tests[0], quick)
    res: dict[str, Any] = {
        "label": METHODS[method],
        "train_cpu_seconds": round(cpu, 1),
        "curve": curve.__dict__,
        "every": every,
        "budget": budget,
    }
    for k, g in tests.items():
        errors = learners.evaluate(model, method, g, z["eval_steps"])
        res[f"test_set_{k}"] = {"within": learners.within(errors), "mean": float(np.mean(errors)), "errors": errors}
    wrong_goals = halton(0)[: z["wrong"]]
    res["wrong"] = {}
    path = Path(out) / f"{method}-model"
    model.save(str(path))
    for name, faults in WRONG.items():
        errors = learners.evaluate(model, method, wrong_goals, z["wrong_steps"], faults)
        row = {"frozen": {"within": learners.within(errors), "mean": float(np.mean(errors))}}
        if method == "sac":  # each condition from the trained policy as saved, learning on
            fresh = learners.sac_class().load(str(path))
            errors = learners.online(fresh, wrong_goals[: z["online"]], z["wrong_steps"], faults)
            row["learning"] = {"within": learners.within(errors), "mean": float(np.mean(errors))}
        res["wrong"][name] = row
    if method == "ppo-shared":
        venv = learners.joints_env(goals, z["train_steps"], SEED)
        n, dim = venv.n, venv.obs_dim
        venv.close()
        onnx_path = learners.export_onnx(model, n, dim, Path(out) / "ppo-shared.onnx")
        res["onnx"] = {"file": onnx_path.name, "inputs": {"obs": [1, dim], "agent": [1]}, "output": "scores (1, 3)"}
        res["onnx"].update(learners.check_onnx(model, onnx_path, tests[0][: 2 if quick else 5], z["eval_steps"]))
    cached.write_text(json.dumps(res, default=float))
    return res


def swarm_training_cpu(quick: bool) -> dict[str, float]:
    """CPU-seconds of one Level-3 training of the swarm (seed 0, fresh, in a temp dir: no cache)."""
    from ..generalisation import LEARNER, Training, training_spec
    from ..swarm import run_spec

    t = Training("Level-3", LEVEL, 4 if quick else REPS * 4**LEVEL, LEARNER)
    spec = training_spec(t, SEED, 100 if quick else TRAIN_STEPS)
    with tempfile.TemporaryDirectory() as tmp:
        c0, ch0 = time.process_time(), resource.getrusage(resource.RUSAGE_CHILDREN)
        run_spec(spec, Path(tmp))
        ch1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = time.process_time() - c0 + (ch1.ru_utime - ch0.ru_utime) + (ch1.ru_stime - ch0.ru_stime)
    # CPU-seconds grow with the machine's load (caches and cores shared): the load they were measured at goes with them
    return {"cpu_seconds": cpu, "env_steps": spec.epochs * spec.steps, "load": os.getloadavg()[0]}


def committed() -> dict[str, Any]:
    """The swarm's, the rule's and the pseudo-inverse's numbers from their committed reports (not rerun)."""
    out: dict[str, Any] = {}
    gen, adapt = RESULTS / "generalisation" / "results.json", RESULTS / "adapt" / "results.json"
    if gen.is_file():
        g = json.loads(gen.read_text())
        for label, row in SWARM_ROWS.items():
            per = g["per_level"].get(row, {})
            out[label] = {
                f"test_set_{k}": {
                    "within": per[f"test_set_{k}"]["frac_within_0_5"],
                    "mean": per[f"test_set_{k}"]["mean"],
                    "seeds": len(per[f"test_set_{k}"]["per_seed"]),
                }
                for k in (0, 1)
                if f"test_set_{k}" in per
            }
        for label, ref in LAWS.items():
            r = g["references"].get(ref, {})
            out[label] = {k: {"within": v["frac_within_0_5"], "mean": v["mean"]} for k, v in r.items()}
    if adapt.is_file():
        a = json.loads(adapt.read_text())["per_condition"]
        out["wrong"] = {
            cond: {
                who: {"within": float(np.mean(v["within"])), "mean": float(np.mean(v["mean_final"]))}
                for who, v in a[cond].items()
                if who in ("fresh, learning", "trained, learning", "trained, frozen", "rule", "pseudo-inverse")
            }
            for cond in WRONG
            if cond in a
        }
    return out


def run(ctx: Context) -> dict[str, Any]:
    _learners()  # the extra, said before anything runs
    z = _size(ctx.quick)
    ctx.seeds = 1  # one seed (0) of each peer: the budget allows no more
    ctx.out.mkdir(parents=True, exist_ok=True)
    # a subset by name (KINSWARM_PEERS_METHODS=ppo,ppo-shared): what the machine's budget allows, said in the report
    chosen = os.environ.get("KINSWARM_PEERS_METHODS", ",".join(METHODS)).split(",")
    unknown = [m for m in chosen if m not in METHODS]
    if unknown:
        raise ValueError(f"KINSWARM_PEERS_METHODS: unknown method {unknown[0]!r} (choose from {', '.join(METHODS)})")
    order = [m for m in ("ppo", "ppo-shared", "sac") if m in chosen]  # the cheap ones first
    args = [(m, ctx.quick, str(ctx.out)) for m in order]
    if ctx.jobs > 1:
        with ProcessPoolExecutor(min(ctx.jobs, 2)) as pool:
            done = dict(zip(order, pool.map(run_method, *zip(*args, strict=True)), strict=True))
    else:
        done = {m: run_method(*a) for m, a in zip(order, args, strict=True)}
    peers = {m: done[m] for m in METHODS if m in done}
    swarm_cpu = swarm_training_cpu(ctx.quick)
    onnx_row = None
    if "ppo-shared" in peers:
        from .onnx_swarm import row

        where = ctx.out / "onnx-swarm"
        shutil.rmtree(where, ignore_errors=True)  # made again each time: the file it runs may be a new one
        policy, goals = ctx.out / peers["ppo-shared"]["onnx"]["file"], halton(0)[: z["onnx_goals"]]
        onnx_row = row(policy, goals, z["onnx_steps"], where, z["onnx_lock_after"])
    ref = committed()
    from .report import write

    return write(ctx, z, peers, ref, swarm_cpu, Report, plt_module, onnx_row)
