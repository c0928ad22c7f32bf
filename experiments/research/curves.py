"""Learning curves as the field draws them: the share of test set 0 reached (final error within 0.5) over env steps
and over training CPU-seconds, every method on the same budget, the same goals and the same frozen test, mean and
spread over seeds.

The protocol is the peers' (experiments/peers, learners.evaluate): examples/reach-generalise.toml, Level-3's 64
quad-tree goals twice each in the seed's order, 500-step episodes, a budget of 64,000 env steps (one env step: one
move of the whole robot, every joint acting once), and every EVERY env steps from 0 to the budget the frozen,
deterministic policy on the first 100 goals of Halton test set 0, 200 steps each from the start pose.

  swarm      the fuzzy, independent and tabular learner kinds. One training to the budget per seed, its learners
             kept every EVERY env steps (train_with_snapshots); the test point at N env steps is the frozen test
             (`--from` the learners after N/500 epochs, learn and explore off). Those learners are what a training
             of N/500 epochs ends with, to the bit (lockstep, seeded: tests/test_curves.py). Its CPU-seconds up to
             each point are measured as it runs.
             The frozen run steps the robot as parallel_env does (tests/test_env.py: the paper's learners on the env
             give the inprocess run's final errors to the bit), so it is the peers' test, not a lookalike.
  ppo-shared PPO (SB3, library defaults) with one policy shared by the joints, on parallel_env (JointsVecEnv)
  sac        SAC (sbx when installed, else SB3; library defaults) on gym_env's Box

SAC is not run unless named: its env steps cost ~15x PPO's here. KINSWARM_CURVES_METHODS picks methods by name
(fuzzy, independent, tabular, ppo-shared, sac), each with its own number of seeds as `name:N`. The shared PPO's
tuning sweep is the peers experiment's (`kinswarm experiment peers`).
Every method's results are cached by their spec (the swarm's runs in OUT/runs, the peers' in OUT/curves/peers/),
so a second call redoes nothing and an interrupted one resumes.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import platform
import resource
import shutil
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.files.resolved import write_resolved
from kinswarm.actors.policies.registry import DEFAULT as DEFAULT_KIND
from kinswarm.actors.report import write_summary
from kinswarm.actors.run.inprocess import InProcessRun
from kinswarm.actors.supervisor.recorder import Recorder

from ..common import Context, Report, frac_within, plt_module
from ..goals import halton, quadtree, training_order
from ..swarm import ROOT, RunOutcome, Spec, json_default, learner_overrides, needs_no_messages, run_spec
from ._curves_report import over_seeds

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
BARS = (0.90, 0.95)


def _size(quick: bool) -> dict[str, int]:
    if quick:  # seconds: 4 epochs of 50 steps, a point every 2 epochs, 3 test goals of 20 steps
        return {"budget": 200, "every": 100, "train_steps": 50, "tests": 3, "eval_steps": 20}
    return {"budget": BUDGET, "every": EVERY, "train_steps": TRAIN_STEPS, "tests": TESTS, "eval_steps": EVAL_STEPS}


def _methods(seeds: int) -> dict[str, int]:
    """The methods named in KINSWARM_CURVES_METHODS and their seeds: `name` (--seeds seeds) or `name:N` (seeds
    0..N-1, e.g. `sac:1` where the CPU budget allows one)."""
    chosen: dict[str, int] = {}
    known = [*KINDS, *PEERS]
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


class _SnapshotRun(InProcessRun):
    """The inprocess run, its checkpoints (every `every` epochs) also copied, with its config.json, into a run
    directory of their own (`at(epochs)`): what `--from` needs. The learners' state after N epochs, which a run of N
    epochs would end with."""

    def __init__(self, cfg: RunConfig, every: int, at: Callable[[int], Path]) -> None:
        super().__init__(cfg, cfg.topo())
        self.every, self.at = every, at

    def checkpoint(self, epoch: int) -> None:
        super().checkpoint(epoch)
        if (epoch + 1) % self.every == 0:
            dest = self.at(epoch + 1)
            shutil.copytree(Path(self.cfg.out) / "agents", dest / "agents", dirs_exist_ok=True)
            shutil.copy2(Path(self.cfg.out) / "config.json", dest / "config.json")


def _snapshot_dir(out: Path, epochs: int) -> Path:
    # a sibling of the run, named for it: a frozen test's identity names its `--from` directory by its name alone
    return out.parent / f"{out.name}-at-e{epochs}"


def train_with_snapshots(spec: Spec, runs: Path, every: int) -> tuple[Path, dict[int, float]]:
    """`spec` trained once in the inprocess placement (as run_spec runs it), its learners kept every `every` epochs
    (_snapshot_dir) and the training CPU-seconds up to each (this process's, checkpoints excluded), or all of it from
    an earlier call. run_spec's records (config.json, run.toml, metrics.jsonl, summary.json, spec.json last: done)."""
    out = (runs / f"{spec.name}-{spec.identity()[:8]}").resolve()
    points = range(every, spec.epochs + 1, every)
    record = out / "curve-cpu.json"  # epochs -> CPU-seconds, written before spec.json
    if (out / "spec.json").is_file() and record.is_file() and all(_snapshot_dir(out, n).is_dir() for n in points):
        return out, {int(k): v for k, v in json.loads(record.read_text()).items()}
    for d in (out, *(_snapshot_dir(out, n) for n in points)):  # an unfinished earlier attempt
        shutil.rmtree(d, ignore_errors=True)
    out.mkdir(parents=True)
    cfg = spec.config(out, run_id=f"x{spec.identity()}")
    if not needs_no_messages(spec, cfg):
        raise ValueError(f"{spec.name}: a curve's training runs in the inprocess placement")
    cfg = dataclasses.replace(cfg, placement="inprocess", checkpoint_every=every)
    cfg.write(out / "config.json")
    write_resolved(cfg, out / "run.toml")
    (out / "metrics.jsonl").write_text("")
    cpu: dict[int, float] = {}
    c0 = _cpu()

    def on_epoch(done: Any) -> None:  # before the epoch's checkpoint: the training's CPU time alone
        if (done.epoch + 1) % every == 0:
            cpu[done.epoch + 1] = round(_cpu() - c0, 2)

    result = _SnapshotRun(cfg, every, lambda n: _snapshot_dir(out, n)).run(Recorder(out), on_epoch)
    write_summary(out, {"wall_seconds": result.wall_seconds, "interrupted": result.interrupted, "error": result.error})
    if result.error or result.interrupted:
        raise RuntimeError(f"run {spec.name} (seed {spec.seed}) failed: {result.error or 'interrupted'}")
    record.write_text(json.dumps(cpu, indent=1) + "\n")
    done = {**dataclasses.asdict(spec), "identity_wo_epochs": spec.identity(with_epochs=False)}
    (out / "spec.json").write_text(json.dumps(done, indent=1, default=json_default) + "\n")  # last: marks it done
    return out, cpu


def train_spec(kind: str, seed: int, z: dict[str, int], epochs: int) -> Spec:
    """A swarm's training on the peers' goals: Level-3's, twice each in the seed's order (a goal per epoch)."""
    return Spec(
        f"curve-train-{kind}",
        seed=seed,
        epochs=epochs,
        steps=z["train_steps"],
        goals=training_order(quadtree(LEVEL), REPS, seed),
        learner=_overrides(kind),
        file=RUN_FILE,
        checkpoint=True,
    )


def swarm_curve(ctx: Context, kind: str, seed: int, z: dict[str, int], used: list[RunOutcome]) -> dict[str, Any]:
    """One kind, one seed: one training to the budget, and the frozen test at every point from its learners after
    that many env steps (0: the untrained learners, greedy on a zero Q). The frozen tests are appended to `used`."""
    tests = tuple(halton(0)[: z["tests"]])
    every = z["every"] // z["train_steps"]
    out, cpu = train_with_snapshots(train_spec(kind, seed, z, z["budget"] // z["train_steps"]), ctx.runs, every)
    curve: dict[str, Any] = {"env_steps": [], "cpu_seconds": [], "within": [], "mean": [], "runs": []}
    for n in range(0, z["budget"] + 1, z["every"]):
        epochs = n // z["train_steps"]
        start = _snapshot_dir(out, epochs) if epochs else None
        test = Spec(
            f"curve-test0-{kind}{'' if start else '-untrained'}",
            seed=seed,
            epochs=len(tests),
            steps=z["eval_steps"],
            goals=tests,
            learner=_overrides(kind),
            file=RUN_FILE,
            from_dir=str(start) if start else None,
            learn=False,
            explore=False,
        )
        tested = run_spec(test, ctx.runs)
        used.append(tested)
        errors = tested.final_errors
        curve["env_steps"].append(n)
        curve["cpu_seconds"].append(cpu[epochs] if epochs else 0.0)
        curve["within"].append(frac_within(errors))
        curve["mean"].append(float(np.mean(errors)))
        curve["runs"].append(start.name if start else None)
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
    labels = {**KINDS, **PEERS}
    agg = {m: over_seeds(labels[m], cs) for m, cs in curves.items()}
    from ._curves_report import write

    return write(ctx, z, agg, curves, Report, plt_module, used)
