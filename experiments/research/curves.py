"""Learning curves as the field draws them: the share of test set 0 reached (final error within 0.5) over env steps
and over training CPU-seconds, every method on the same budget, the same goals and the same frozen test, mean and
spread over seeds.

The protocol is the peers' (experiments/peers, learners.evaluate): examples/reach-generalise.toml, Level-3's 64
quad-tree goals twice each in the seed's order, 500-step episodes, a budget of 64,000 env steps (one env step: one
move of the whole robot, every joint acting once), and every EVERY env steps from 0 to the budget the frozen,
deterministic policy on the first 100 goals of Halton test set 0, 200 steps each from the start pose.

  swarm      the fuzzy, independent and tabular learner kinds. The test point at N env steps is the frozen test
             (`--from` its checkpoint, learn and explore off) of a training of N/500 epochs; a training of fewer
             epochs is the first epochs of a longer one to the bit (lockstep, seeded), so the points are one training
             read at 8 budgets. Each prefix is its own cached run, and its CPU-seconds are measured when it runs.
             The frozen run steps the robot as parallel_env does (tests/test_env.py: the paper's learners on the env
             give the inprocess run's final errors to the bit), so it is the peers' test, not a lookalike.
  ppo-shared PPO (SB3, library defaults) with one policy shared by the joints, on parallel_env (JointsVecEnv)
  sac        SAC (sbx when installed, else SB3; library defaults) on gym_env's Box

SAC is not run unless named: its env steps cost ~15x PPO's here. KINSWARM_CURVES_METHODS picks methods by name
(fuzzy, independent, tabular, ppo-shared, sac, sweep), each with its own number of seeds as `name:N`; `sweep` is
PPO's 2x2 of learning rate x n_steps on seed 0.
Every method's results are cached by their spec (the swarm's runs in OUT/runs, the peers' in OUT/curves/peers/),
so a second call redoes nothing and an interrupted one resumes.
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import resource
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
from kinswarm.actors.learning.kinds import DEFAULT as DEFAULT_KIND

from ..common import Context, Report, frac_within, plt_module
from ..goals import halton, quadtree, training_order
from ..swarm import ROOT, RunOutcome, Spec, find_cached, learner_overrides, run_spec

SEEDS = 3
RUN_FILE = str(ROOT / "examples" / "reach-generalise.toml")  # the peers' (learners.RUN_FILE)
LEVEL, REPS, TRAIN_STEPS, EVAL_STEPS, TESTS = 3, 2, 500, 200, 100
BUDGET = REPS * 4**LEVEL * TRAIN_STEPS  # 64,000 env steps
EVERY = 8_000
KINDS = {
    "fuzzy": "swarm, fuzzy (the paper's)",
    "independent": "swarm, independent (no JASM)",
    "tabular": "swarm, tabular (no fuzzy interpolation)",
}
PEERS = {"ppo-shared": "PPO, one policy shared by the joints", "sac": "SAC, central (Box)"}
DEFAULT_METHODS = ("fuzzy", "independent", "tabular", "ppo-shared")
# PPO's sweep: SB3's defaults are lr 3e-4, n_steps 2048 (per env; the shared policy has a row per joint)
SWEEP_LR, SWEEP_N_STEPS = (1e-4, 1e-3), (512, 2048)
BARS = (0.90, 0.95)


def _size(quick: bool) -> dict[str, int]:
    if quick:  # seconds: 4 epochs of 50 steps, a point every 2 epochs, 3 test goals of 20 steps
        return {"budget": 200, "every": 100, "train_steps": 50, "tests": 3, "eval_steps": 20}
    return {"budget": BUDGET, "every": EVERY, "train_steps": TRAIN_STEPS, "tests": TESTS, "eval_steps": EVAL_STEPS}


def _methods(seeds: int) -> dict[str, int]:
    """The methods named in KINSWARM_CURVES_METHODS and their seeds: `name` (--seeds seeds) or `name:N` (seeds
    0..N-1, e.g. `sac:1` where the CPU budget allows one)."""
    chosen: dict[str, int] = {}
    known = [*KINDS, *PEERS, "sweep"]
    for item in os.environ.get("KINSWARM_CURVES_METHODS", ",".join(DEFAULT_METHODS)).split(","):
        name, _, n = item.partition(":")
        if name not in known:
            raise ValueError(f"KINSWARM_CURVES_METHODS: unknown method {name!r} (choose from {', '.join(known)})")
        if n and not (n.isdigit() and int(n) > 0):
            raise ValueError(f"KINSWARM_CURVES_METHODS: {item!r}: seeds after ':' are a whole number > 0")
        chosen[name] = int(n) if n else seeds
    return chosen


def _cpu() -> float:
    """This process's CPU-seconds and its children's (a run's own processes, if any)."""
    ch = resource.getrusage(resource.RUSAGE_CHILDREN)
    return time.process_time() + ch.ru_utime + ch.ru_stime


# -- the swarm -------------------------------------------------------------------------------------------------------
def _overrides(kind: str) -> tuple:
    return () if kind == DEFAULT_KIND else learner_overrides(kind=kind)


def _warm_up(kind: str) -> None:
    """One tiny run of the kind, uncached, so that the first measured training does not pay numba's compile (or
    cache load) and the imports: the peers' CPU-seconds count neither."""
    spec = Spec(f"curve-warm-{kind}", epochs=1, steps=5, learner=_overrides(kind), file=RUN_FILE, checkpoint=True)
    with tempfile.TemporaryDirectory() as tmp:
        run_spec(spec, Path(tmp))


def _timed(spec: Spec, runs: Path, cpu_file: Path) -> tuple[RunOutcome, float | None]:
    """The run of `spec` (cached or fresh) and its training CPU-seconds: measured here when it runs, else as
    recorded when it ran (None: it ran elsewhere, its CPU time unknown)."""
    known: dict[str, float] = json.loads(cpu_file.read_text()) if cpu_file.is_file() else {}
    cached = find_cached(spec, runs)
    if cached is not None:
        return run_spec(spec, runs), known.get(cached.name)
    c0 = _cpu()
    out = run_spec(spec, runs)
    cpu = _cpu() - c0
    known[out.out.name] = cpu
    cpu_file.write_text(json.dumps(known, indent=1, sort_keys=True) + "\n")
    return out, cpu


def swarm_curve(ctx: Context, kind: str, seed: int, z: dict[str, int], used: list[RunOutcome]) -> dict[str, Any]:
    """One kind, one seed: the frozen test at every point, from the checkpoint of a training of that many env
    steps (0: the untrained learners, greedy on a zero Q). Every run it used is appended to `used`."""
    goals = training_order(quadtree(LEVEL), REPS, seed)
    tests = tuple(halton(0)[: z["tests"]])
    cpu_file = ctx.out / "swarm-cpu.json"  # run directory -> training CPU-seconds, measured on this machine
    curve: dict[str, Any] = {"env_steps": [], "cpu_seconds": [], "within": [], "mean": [], "runs": []}
    for n in range(0, z["budget"] + 1, z["every"]):
        epochs = n // z["train_steps"]
        trained, cpu = None, 0.0
        if epochs:
            train = Spec(
                f"curve-train-{kind}-e{epochs}",
                seed=seed,
                epochs=epochs,
                steps=z["train_steps"],
                goals=goals,
                learner=_overrides(kind),
                file=RUN_FILE,
                checkpoint=True,
            )
            trained, cpu = _timed(train, ctx.runs, cpu_file)
            used.append(trained)
        test = Spec(
            f"curve-test0-{kind}{'' if trained else '-untrained'}",
            seed=seed,
            epochs=len(tests),
            steps=z["eval_steps"],
            goals=tests,
            learner=_overrides(kind),
            file=RUN_FILE,
            from_dir=str(trained.out) if trained else None,
            learn=False,
            explore=False,
        )
        tested = run_spec(test, ctx.runs)
        used.append(tested)
        errors = tested.final_errors
        curve["env_steps"].append(n)
        curve["cpu_seconds"].append(None if cpu is None else round(cpu, 2))
        curve["within"].append(frac_within(errors))
        curve["mean"].append(float(np.mean(errors)))
        curve["runs"].append(trained.out.name if trained else None)
        print(
            f"  {kind} seed {seed}: {n:>6,} env steps, {curve['cpu_seconds'][-1]} CPU-s, "
            f"{100 * curve['within'][-1]:.0f} % within 0.5",
            flush=True,
        )
    return curve


# -- the peers -------------------------------------------------------------------------------------------------------
def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in ("torch", "stable-baselines3", "sbx-rl"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            pass
    return out


def peer_curve(ctx: Context, method: str, seed: int, z: dict[str, int], hp: dict[str, Any]) -> dict[str, Any]:
    """One peer, one seed, trained for the budget with library defaults (and `hp` over them), tested as
    learners.train tests it (learners.CurveCallback) every `every` env steps, and before training (0)."""
    from ..peers import _learners

    learners = _learners()
    spec = {
        "method": method,
        "seed": seed,
        "hp": hp,
        **z,
        "goal_order_seed": seed,
        "versions": _versions(),
    }
    key = hashlib.sha256(json.dumps(spec, sort_keys=True).encode()).hexdigest()[:10]
    hp_name = "".join(f"-{k}{v:g}" for k, v in sorted(hp.items()))
    cached = ctx.out / "peers" / f"{method}{hp_name}-s{seed}-{key}.json"
    if cached.is_file():  # this spec run earlier by this command with this --out, on this machine
        return json.loads(cached.read_text())
    import torch
    from stable_baselines3 import PPO

    torch.set_num_threads(1)  # two shared cores: one for us (as the peers experiment)
    goals = training_order(quadtree(LEVEL), REPS, seed)
    tests = halton(0)[: z["tests"]]
    small = {"n_steps": 64, "batch_size": 32} if ctx.quick else {}  # the quick version: seconds, not a rollout
    if method == "ppo-shared":
        env: Any = learners.joints_env(goals, z["train_steps"], seed)
        per_step = env.n
        model: Any = PPO("MlpPolicy", env, seed=seed, verbose=0, device="cpu", **{**small, **hp})
    else:
        env = learners.central_env(goals, z["train_steps"], True, seed)
        per_step = 1
        model = learners.sac_class()(
            "MlpPolicy", env, seed=seed, verbose=0, **({"learning_starts": 64} if ctx.quick else {}), **hp
        )

    def check(m: Any) -> list[float]:
        return learners.evaluate(m, method, tests, z["eval_steps"])

    errors = check(model)  # the untrained policy: the curve's point at 0
    cb = learners.CurveCallback(method, per_step, z["every"], check)
    model.learn(total_timesteps=z["budget"] * per_step, callback=cb)
    env.close()
    c = cb.curve
    res = {
        "spec": spec,
        "label": PEERS[method],
        "env_steps": [0, *c.env_steps],
        "cpu_seconds": [0.0, *c.cpu_seconds],
        "within": [learners.within(errors), *c.within],
        "mean": [float(np.mean(errors)), *c.mean],
        "load": os.getloadavg()[0],
        "machine": f"{os.cpu_count()} cores, {platform.machine()}",
    }
    for n, cpu, w in zip(res["env_steps"], res["cpu_seconds"], res["within"], strict=True):
        print(f"  {method}{hp_name} seed {seed}: {n:>6,} env steps, {cpu} CPU-s, {100 * w:.0f} % within 0.5")
    cached.parent.mkdir(parents=True, exist_ok=True)
    cached.write_text(json.dumps(res, indent=1) + "\n")
    return res


# -- over seeds ------------------------------------------------------------------------------------------------------
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


# -- the run ---------------------------------------------------------------------------------------------------------
def run(ctx: Context) -> dict[str, Any]:
    z = _size(ctx.quick)
    methods = _methods(ctx.seeds)
    ctx.out.mkdir(parents=True, exist_ok=True)
    curves: dict[str, list[dict[str, Any]]] = {}
    used: list[RunOutcome] = []
    for kind in (k for k in KINDS if k in methods):
        print(f"{KINDS[kind]}: {methods[kind]} seed(s)", flush=True)
        _warm_up(kind)
        curves[kind] = [swarm_curve(ctx, kind, seed, z, used) for seed in range(methods[kind])]
    for method in (m for m in ("ppo-shared", "sac") if m in methods):
        print(f"{PEERS[method]}: {methods[method]} seed(s)", flush=True)
        curves[method] = [peer_curve(ctx, method, seed, z, {}) for seed in range(methods[method])]
    sweep: dict[str, dict[str, Any]] = {}
    if "sweep" in methods:
        for lr in SWEEP_LR:
            for n_steps in SWEEP_N_STEPS:
                hp = {"learning_rate": lr, "n_steps": n_steps // 32 if ctx.quick else n_steps}
                print(f"PPO sweep {hp}: seed 0", flush=True)
                sweep[f"lr {lr:g}, n_steps {hp['n_steps']}"] = peer_curve(ctx, "ppo-shared", 0, z, hp)
    labels = {**KINDS, **PEERS}
    agg = {m: over_seeds(labels[m], cs) for m, cs in curves.items()}
    from ._curves_report import write

    z = {**z, "sweep_default_n_steps": 64 if ctx.quick else 2048}
    return write(ctx, z, agg, curves, sweep, Report, plt_module, used)
