"""The deep-RL peers on the swarm's own work: what a practitioner would pick instead, on the same goals.

SAC (sbx, SB3's JAX port, when installed; else SB3's) on gym_env's continuous Box, PPO on gym_env's MultiDiscrete (a
central policy seeing the whole robot), and PPO with one policy shared by every joint on parallel_env (independent
learners with parameter sharing), each seed trained on the generalisation protocol's Level-3 goals (64 quad-tree
centres, twice each in the seed's order, 500-step episodes) for the swarm's 64k env steps with library defaults and
the task's own reward (`graded`), then:

  curve            the test set 0 share within 0.5, frozen, every EVERY env steps from 0 (the curves study's points):
                   env steps and training CPU-seconds until >= 90 % and >= 95 %, per seed
  generalisation   frozen, deterministic, from the start pose: test sets 0 and 1 (100 Halton goals, 200 steps each)
  successive       test set 0, each goal from where the last ended, on chain4 and on the chain whose joints turn
                   freely (the any-pose recipe's robot)
  wrong model      a1 reversed, a2 and a3 reversed (unknown), adapt's 30 goals of test set 0, one 500-step episode
                   each: frozen; and learning on (SB3's learn, carried from goal to goal) on the first 10
  live             adapt's live sequence: at a goal intact, the fault from the next episode on, then 10 next goals
                   from where it stands; frozen and learning on
  iiwa             reach3d's points (iiwa.py): trained on its training set for the swarm's 153,600 env steps,
                   frozen on its test sets A and B, within 5 cm

against the swarm's kinds, the rule and the pseudo-inverse as their committed reports give them
(docs/results/generalisation, docs/results/research/curves, docs/results/adapt with today's recipe: not rerun), and
the swarm's training CPU-seconds measured here. Seed 0's shared policy is exported to ONNX (learners.export_onnx),
checked against torch with onnxruntime, and run through `kinswarm run` as `[learner] kind = "onnx"` in a process
swarm on test goals, intact and with `kinswarm fault ... lock a2` sent live, beside the same file stepped in
parallel_env (onnx_swarm.py: onnxruntime, no torch). Every method's seeds are cached in OUT as they end.
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
# the shared PPO's tuning sweep, seed 0, curve only: learning rate x n_steps (per joint row) over SB3's defaults
# (lr 3e-4, n_steps 2048); `sweep` in KINSWARM_PEERS_METHODS (in the default set)
SWEEP_LR, SWEEP_N_STEPS = (1e-4, 1e-3), (512, 2048)
LEVEL, REPS, TRAIN_STEPS, EVAL_STEPS = 3, 2, 500, 200
BUDGET = REPS * 4**LEVEL * TRAIN_STEPS  # the swarm's 64k env steps: every peer's budget too
EVERY = 8_000  # the frozen test of test set 0 every 8k env steps from 0, as the curves study tests the swarm
WRONG = {
    "a1 reversed": [{"fault": "reverse", "targets": ["a1"]}],
    "a2, a3 reversed": [{"fault": "reverse", "targets": ["a2", "a3"]}],
}
WRONG_GOALS, WRONG_STEPS = 30, 500
ONLINE_GOALS = 10  # a peer learning on: the first 10 of them (SAC's env steps cost ~15x the swarm's)
LIVE_NEXT = 10  # adapt's live sequence: at a goal intact, the fault from the next episode on, then 10 next goals
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
            "live_next": 2,
            "onnx_goals": 6,
            "onnx_steps": 100,
            "onnx_lock_after": 1,
        }
    return {
        "budget": BUDGET,
        "train_steps": TRAIN_STEPS,
        "every": EVERY,
        "tests": 100,
        "eval_steps": EVAL_STEPS,
        "wrong": WRONG_GOALS,
        "wrong_steps": WRONG_STEPS,
        "online": ONLINE_GOALS,
        "live_next": LIVE_NEXT,
        "onnx_goals": ONNX_GOALS,
        "onnx_steps": EVAL_STEPS,
        "onnx_lock_after": ONNX_LOCK_AFTER,
    }


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {}
    for name in ("torch", "stable-baselines3", "sbx-rl", "jax"):
        try:
            out[name] = version(name)
        except PackageNotFoundError:
            pass
    return out


def sweep_points(quick: bool) -> dict[str, dict[str, Any]]:
    """The sweep's settings by name (the quick version's n_steps a 32nd)."""
    return {
        f"lr {lr:g}, n_steps {n // 32 if quick else n}": {"learning_rate": lr, "n_steps": n // 32 if quick else n}
        for lr in SWEEP_LR
        for n in SWEEP_N_STEPS
    }


def train_seed(method: str, seed: int, quick: bool, out: str, hp: dict[str, Any] | None = None) -> dict[str, Any]:
    """One peer, one seed: trained with library defaults (`hp` over them: the sweep) for the budget on Level-3's goals
    in the seed's order, its frozen test of test set 0 every `every` env steps from 0 (its curve), the model saved.
    Cached in OUT by method, settings and seed: an interrupted call resumes, a second one retrains nothing."""
    z = _size(quick)
    tag = "".join(f"-{k}{v:g}" for k, v in sorted((hp or {}).items()))
    cached = Path(out) / f"{method}{tag}-s{seed}.json"
    if cached.is_file():
        return {**json.loads(cached.read_text()), "reused": True}
    learners = _learners()
    goals = list(training_order(quadtree(LEVEL), REPS, seed))
    if quick:
        goals = goals[:4]
    w0 = time.time()
    model, curve, cpu = learners.train(
        method, goals, z["train_steps"], z["budget"], seed, z["every"], halton(0)[: z["tests"]], quick, hp
    )
    model.save(str(Path(out) / f"{method}{tag}-s{seed}-model"))
    res = {
        "label": METHODS[method],
        "seed": seed,
        "budget": z["budget"],
        "every": z["every"],
        "train_cpu_seconds": round(cpu, 1),
        "wall_seconds": round(time.time() - w0, 1),  # training and its curve's tests
        "load": os.getloadavg()[0],
        "versions": _versions(),
        "curve": curve.__dict__,
        "hp": hp or {},
    }
    print(f"  {METHODS[method]}{tag}, seed {seed}: {cpu:.0f} training CPU-s, curve {curve.within}", flush=True)
    cached.write_text(json.dumps(res, default=float))
    return res


def _stats(errors: list[float]) -> dict[str, Any]:
    from .learners import within

    return {"within": within(errors), "mean": float(np.mean(errors)), "errors": [float(e) for e in errors]}


def live_order(goals: list, seed: int, n: int) -> list:
    """adapt's live sequence for a seed: a goal, then the n next ones (experiments/adapt.py)."""
    return [goals[(seed * n + i) % len(goals)] for i in range(n + 1)]


def test_seed(method: str, seed: int, quick: bool, out: str) -> dict[str, Any]:
    """One trained peer, every protocol (cached in OUT by method and seed):
    generalisation  frozen, from the start pose, test sets 0 and 1
    successive      frozen, each goal of test set 0 from where the last ended, on chain4 (±180°) and on the chain
                    whose joints turn freely
    wrong           a1 reversed, a2 and a3 reversed, unknown, from the first step: adapt's first 30 goals of test set
                    0, one episode each from the start pose, frozen; and learning on (its learning carried from goal
                    to goal) on the first `online` of them, from the saved model again for each fault
    live            adapt's live sequence: at a goal intact, the fault from the next episode on, then the next goals
                    from where it stands; frozen, and learning on through the sequence"""
    cached = Path(out) / f"{method}-s{seed}-tests.json"
    if cached.is_file():
        return json.loads(cached.read_text())
    learners = _learners()
    z = _size(quick)
    path = Path(out) / f"{method}-s{seed}-model.zip"
    model = learners.load(method, path)
    c0 = time.process_time()
    res: dict[str, Any] = {}
    for k in (0, 1):
        res[f"test_set_{k}"] = _stats(learners.evaluate(model, method, halton(k)[: z["tests"]], z["eval_steps"]))
    succ = halton(0)[: z["tests"]]
    res["successive"] = {
        "chain4": _stats(learners.evaluate(model, method, succ, z["eval_steps"], sets=learners.SUCCESSIVE)),
        "joints free": _stats(
            learners.evaluate(model, method, succ, z["eval_steps"], sets=learners.SUCCESSIVE + learners.FREE_JOINTS)
        ),
    }
    wrong_goals = halton(0)[: z["wrong"]]
    order = live_order(wrong_goals, seed, z["live_next"])
    res["wrong"], res["live"] = {}, {}
    for name, faults in WRONG.items():
        res["wrong"][name] = {
            "frozen": _stats(learners.evaluate(model, method, wrong_goals, z["wrong_steps"], faults)),
            "learning": _stats(
                learners.online(
                    learners.load(method, path), method, wrong_goals[: z["online"]], z["wrong_steps"], faults
                )
            ),
        }
    for name, faults in {"intact": [], **WRONG}.items():
        kw = {"sets": learners.SUCCESSIVE, "faults_from": 1}
        frozen = learners.evaluate(model, method, order, z["wrong_steps"], faults, **kw)
        learning = learners.online(learners.load(method, path), method, order, z["wrong_steps"], faults, **kw)
        res["live"][name] = {"frozen": _stats(frozen[1:]), "learning": _stats(learning[1:])}  # the next goals
    res["test_cpu_seconds"] = round(time.process_time() - c0, 1)
    if method == "ppo-shared" and seed == 0:
        venv = learners.joints_env(order, z["train_steps"], seed)
        n, dim = venv.n, venv.obs_dim
        venv.close()
        onnx_path = learners.export_onnx(model, n, dim, Path(out) / "ppo-shared.onnx")
        res["onnx"] = {"file": onnx_path.name, "inputs": {"obs": [1, dim], "agent": [1]}, "output": "scores (1, 3)"}
        res["onnx"].update(learners.check_onnx(model, onnx_path, halton(0)[: 2 if quick else 5], z["eval_steps"]))
    cached.write_text(json.dumps(res, default=float))
    return res


def swarm_training_cpu(quick: bool) -> dict[str, float]:
    """CPU-seconds of one Level-3 training of the swarm (seed 0, fresh, in a temp dir: no cache)."""
    from ..generalisation import LEARNER, Training, training_spec
    from ..swarm import run_spec

    t = Training("Level-3", LEVEL, 4 if quick else REPS * 4**LEVEL, LEARNER)
    spec = training_spec(t, 0, 100 if quick else TRAIN_STEPS)
    with tempfile.TemporaryDirectory() as tmp:
        c0, ch0 = time.process_time(), resource.getrusage(resource.RUSAGE_CHILDREN)
        run_spec(spec, Path(tmp))
        ch1 = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = time.process_time() - c0 + (ch1.ru_utime - ch0.ru_utime) + (ch1.ru_stime - ch0.ru_stime)
    # CPU-seconds grow with the machine's load (caches and cores shared): the load they were measured at goes with them
    return {"cpu_seconds": cpu, "env_steps": spec.epochs * spec.steps, "load": os.getloadavg()[0]}


def committed(online: int = ONLINE_GOALS) -> dict[str, Any]:
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
        for key, row, seeds_row in (
            ("succ", "Level-3, successive test goals", True),
            ("succ free", "Level-3, successive test goals, joints free", True),
            ("any pose", "Level-3, random starts, joints free, successive test goals", True),
            ("rule succ", "rule on g_perp, successive test goals", False),
            ("rule succ free", "rule on g_perp, successive test goals, joints free", False),
        ):
            t0 = (g["per_level"] if seeds_row else g["references"]).get(row, {}).get("test_set_0")
            if t0:
                n = len(t0["per_seed"]) if seeds_row else 1
                out.setdefault("successive", {})[key] = {
                    "within": t0["frac_within_0_5"],
                    "mean": t0["mean"],
                    "seeds": n,
                }
    if adapt.is_file():
        out.update(adapt_rows(json.loads(adapt.read_text()), online))
    return out


# adapt's swarm rows, today's recipe first: (adapt's controller, the label here, "learning": read over the goals the
# peers learn on too)
ADAPT_WRONG = (
    ("trained, frozen", "swarm, today's recipe, frozen", False),
    ("trained + direction + sensed tip, learning", "swarm, today's recipe, learning", True),
    ("afresh trained + direction + sensed tip, learning", "swarm, today's recipe, learning, each goal afresh", True),
    ("fresh, learning", "swarm, fresh (untrained), learning", True),
    ("trained, learning", "swarm, trained without the recipe's plasticity, learning", True),
    ("rule", "rule on g_perp", False),
    ("pseudo-inverse", "pseudo-inverse", False),
)
ADAPT_LIVE = (
    ("trained + direction + sensed tip, learning", "chain4, ±180°", "swarm, today's recipe, learning"),
    ("fresh, learning", "chain4, ±180°", "swarm, fresh (untrained), learning"),
    ("rule", "chain4, ±180°", "rule on g_perp"),
    ("pseudo-inverse", "chain4, ±180°", "pseudo-inverse"),
    (
        "free joints: trained from any pose + direction + sensed tip, learning",
        "joints free",
        "swarm, the any-pose recipe (+ direction + sensed tip), learning",
    ),
    ("free joints: rule", "joints free", "rule on g_perp"),
)


def _share(values: list[float]) -> str:
    a = np.asarray(values, dtype=float)
    return f"{100 * a.mean():.0f} %" if len(a) == 1 else f"{100 * a.mean():.0f} ± {100 * a.std(ddof=1):.0f} %"


def adapt_rows(a: dict[str, Any], online: int) -> dict[str, Any]:
    """docs/results/adapt's rows for the faults here: the wrong model (per fault) and the live sequence. A learning
    row is read over the first `online` goals, the ones the peers learn on (its 30-goal share beside it)."""
    out: dict[str, Any] = {"wrong": {}, "live": {}}
    per = a["per_condition"]
    for cond in WRONG:
        rows = out["wrong"][cond] = {}
        for who, label, learning in ADAPT_WRONG:
            v = per.get(cond, {}).get(who)
            if v is None:
                continue
            errs = [np.asarray(e, dtype=float) for e in v["final_error"]]
            full = [float(np.mean(e <= 0.5)) for e in errs]
            if learning:
                first = [float(np.mean(e[:online] <= 0.5)) for e in errs]
                within = f"{_share(first)} ({_share(full)} of all {len(errs[0])})"
                mean = float(np.mean([e[:online].mean() for e in errs]))
            else:
                within, mean = _share(full), float(np.mean([e.mean() for e in errs]))
            rows[who] = {"label": label, "seeds": len(errs), "within": within, "mean": mean}
    seq = a.get("sequence", {}).get("per", {})
    for cond in ("intact", *WRONG):
        out["live"][cond] = [
            {
                "label": label,
                "robot": robot,
                "seeds": len(seq[cond][who]["within"]),
                "within": _share(seq[cond][who]["within"]),
            }
            for who, robot, label in ADAPT_LIVE
            if who in seq.get(cond, {})
        ]
    return out


def _methods(seeds: int) -> dict[str, int]:
    """The peers named in KINSWARM_PEERS_METHODS (default: all) and their seeds: `name` (--seeds) or `name:N` (seeds
    0..N-1, where the machine's CPU budget allows fewer); what ran is said in the report."""
    chosen: dict[str, int] = {}
    known = [*METHODS, "sweep"]
    for item in os.environ.get("KINSWARM_PEERS_METHODS", ",".join(known)).split(","):
        name, _, n = item.strip().partition(":")
        if name not in known:
            raise ValueError(f"KINSWARM_PEERS_METHODS: unknown method {name!r} (choose from {', '.join(known)})")
        if n and not (n.isdigit() and int(n) > 0):
            raise ValueError(f"KINSWARM_PEERS_METHODS: {item!r}: the seeds after ':' must be a whole number >= 1")
        chosen[name] = int(n) if n else seeds
    return chosen


def run(ctx: Context) -> dict[str, Any]:
    _learners()  # the extra, said before anything runs
    z = _size(ctx.quick)
    ctx.out.mkdir(parents=True, exist_ok=True)
    methods = _methods(ctx.seeds)
    order = [m for m in ("ppo-shared", "ppo", "sac") if m in methods]  # the best peer first, SAC (the dearest) last
    jobs = [(m, seed, ctx.quick, str(ctx.out)) for m in order for seed in range(methods[m])]
    # a method's trainings (each seed cached as it ends), then its tests: an interrupted call keeps what it finished
    trained, tested = [], []
    for m in order:
        mine = [a for a in jobs if a[0] == m]
        if ctx.jobs > 1:
            with ProcessPoolExecutor(min(ctx.jobs, 2)) as pool:
                trained += list(pool.map(train_seed, *zip(*mine, strict=True)))
                tested += list(pool.map(test_seed, *zip(*mine, strict=True)))
        else:
            trained += [train_seed(*a) for a in mine]
            tested += [test_seed(*a) for a in mine]
    peers: dict[str, Any] = {m: {"label": METHODS[m], "seeds": []} for m in METHODS if m in order}
    for (m, seed, *_), t, r in zip(jobs, trained, tested, strict=True):
        peers[m]["seeds"].append({**t, **r, "seed": seed})
    from .iiwa import seed_row

    if ctx.jobs > 1 and jobs:  # the iiwa's points (reach3d's protocol), each seed cached as it ends
        with ProcessPoolExecutor(min(ctx.jobs, 2)) as pool:
            on_iiwa = list(pool.map(seed_row, *zip(*jobs, strict=True)))
    else:
        on_iiwa = [seed_row(*a) for a in jobs]
    for (m, *_), r in zip(jobs, on_iiwa, strict=True):
        peers[m].setdefault("iiwa", []).append(r)
    sweep = {}
    if "sweep" in methods:  # the shared PPO's tuning sweep: seed 0, its curve (the tests of every protocol: defaults)
        points = sweep_points(ctx.quick)
        args = [("ppo-shared", 0, ctx.quick, str(ctx.out), hp) for hp in points.values()]
        if ctx.jobs > 1:
            with ProcessPoolExecutor(min(ctx.jobs, 2)) as pool:
                sweep = dict(zip(points, pool.map(train_seed, *zip(*args, strict=True)), strict=True))
        else:
            sweep = {name: train_seed(*a) for name, a in zip(points, args, strict=True)}
    swarm_cpu = swarm_training_cpu(ctx.quick)
    onnx_row = None
    if "ppo-shared" in peers and 0 in ctx.seed_list:
        from .onnx_swarm import row

        where = ctx.out / "onnx-swarm"
        shutil.rmtree(where, ignore_errors=True)  # made again each time: the file it runs may be a new one
        first = next(s for s in peers["ppo-shared"]["seeds"] if s["seed"] == 0)
        policy, goals = ctx.out / first["onnx"]["file"], halton(0)[: z["onnx_goals"]]
        onnx_row = row(policy, goals, z["onnx_steps"], where, z["onnx_lock_after"])
    ref = committed(z["online"])
    from .report import write

    return write(ctx, z, peers, ref, swarm_cpu, Report, plt_module, onnx_row, sweep)
