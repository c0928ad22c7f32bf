"""The peers on the iiwa's points: reach3d's protocol (experiments/reach3d.py) for every peer.

Each peer trains on reach3d's training set (its 96 goals and random start poses, 4 passes in the set's seeded order,
400-step episodes: the swarm's 153,600 env steps) on `kinswarm.env` built from examples/iiwa.toml (7 joints, the
task's own reward), with library defaults, then is tested frozen and deterministic on reach3d's test sets A and B
(100 unseen goals each, each from its unseen start pose, 400 steps): the share within 5 cm, beside the swarm's rows
from docs/results/reach3d (not rerun)."""

from __future__ import annotations

import json
import os
import time
from pathlib import Path
from typing import Any

import numpy as np

from ..reach3d import QUICK_TRAINING, ROBOT, SETS, STEPS, TEST, TOL, sample, training_set

RESULTS = Path(__file__).resolve().parents[2] / "docs" / "results" / "reach3d" / "results.json"
# reach3d's rows shown beside the peers: (its key, the label here)
SWARM_ROWS = (
    ("trained, frozen", "swarm, fuzzy (the paper's), frozen"),
    ("untrained, frozen", "swarm, untrained, frozen"),
    ("blind (q only), frozen", "swarm, blind (q only), frozen"),
    ("rule", "rule on g_perp"),
    ("pseudo-inverse", "pseudo-inverse"),
)


def _sets(goals: list[list[float]], starts: list[list[float]]) -> list[str]:
    """The run's goal and start of each epoch, in order (the env's episode k is the run's epoch k: draw=False)."""
    return [f"task.goals={json.dumps(goals)}", f"task.starts={json.dumps(starts)}"]


def _env(method: str, goals: list[list[float]], starts: list[list[float]], steps: int, seed: int) -> tuple[Any, int]:
    """The env a peer trains or is tested in, and the rows per env step."""
    from kinswarm.env import gym_env, parallel_env
    from kinswarm.env.sb3 import JointsVecEnv

    sets = _sets(goals, starts)
    if method == "ppo-shared":
        par = parallel_env(str(ROBOT), steps=steps, seed=seed, sets=sets, render_mode=None, draw=False)
        venv = JointsVecEnv(par)
        venv.seed(seed)
        return venv, venv.n
    env = gym_env(
        str(ROBOT), continuous=method == "sac", steps=steps, seed=seed, sets=sets, render_mode=None, draw=False
    )
    return env, 1


def seed_row(method: str, seed: int, quick: bool, out: str) -> dict[str, Any]:
    """One peer, one seed on the iiwa: trained on reach3d's training set for its env steps, tested frozen on sets A
    and B. Cached in OUT by method and seed, as the chain's seeds are."""
    cached = Path(out) / f"iiwa-{method}-s{seed}.json"
    if cached.is_file():
        return {**json.loads(cached.read_text()), "reused": True}
    from kinswarm.protocol.robots import load_robot

    from . import learners  # torch and SB3: run() has said, in one line, if the peers extra is missing

    topo = load_robot(ROBOT)
    steps, n_test = (60, 5) if quick else (STEPS, TEST)
    goals, starts = training_set(topo, False, *(QUICK_TRAINING if quick else ()))
    env, per_step = _env(method, goals, starts, steps, seed)
    model = learners.new_model(method, env, seed, quick)
    w0, c0 = time.time(), time.process_time()
    model.learn(total_timesteps=len(goals) * steps * per_step)
    cpu = time.process_time() - c0
    env.close()
    res: dict[str, Any] = {
        "seed": seed,
        "env_steps": len(goals) * steps,
        "train_cpu_seconds": round(cpu, 1),
        "load": os.getloadavg()[0],
    }
    for name, sampling_seed in SETS.items():
        t_goals, t_starts = sample(topo, sampling_seed, n_test, False)
        test_env, _ = _env(method, t_goals, t_starts, steps, 0)
        errors = learners.episodes(model, method, test_env, len(t_goals))
        res[name] = {
            "within": float(np.mean(np.asarray(errors) <= TOL)),
            "mean": float(np.mean(errors)),
            "median": float(np.median(errors)),
            "errors": [round(e, 5) for e in errors],
        }
    res["wall_seconds"] = round(time.time() - w0, 1)
    print(f"  iiwa, {method}, seed {seed}: {cpu:.0f} training CPU-s, set A within 5 cm {res['A']['within']:.2f}")
    cached.write_text(json.dumps(res))
    return res


def swarm_rows() -> dict[str, dict[str, list[float]]]:
    """reach3d's committed rows (per seed) for the swarm and the references, by label and test set."""
    if not RESULTS.is_file():
        return {}
    points = json.loads(RESULTS.read_text())["points"]
    out: dict[str, dict[str, list[float]]] = {}
    for key, label in SWARM_ROWS:
        for name in SETS:
            row = points.get(f"{key} | {name}")
            if row:
                out.setdefault(label, {})[name] = [w / 100 for w in row["within_pct"]]
                out[label][f"{name} mean"] = row["mean"]
    return out
