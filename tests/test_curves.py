"""experiments/research/curves.py at smoke size (research suite: pytest -m research): every point of every curve
at the env steps asked for, the swarm's points from trainings of exactly that many env steps, a second call served
from the cache alone, and the swarm's frozen test the peers' evaluation (the restored learners driven frozen on
parallel_env give the frozen run's final errors to the bit)."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import numpy as np
import pytest
from kinswarm.actors.files.checkpoint import load_checkpoint
from kinswarm.actors.step.learned import restore_learner
from kinswarm.experiments.goals import halton
from kinswarm.experiments.research import curves
from kinswarm.experiments.swarm import Spec, run_spec

pytestmark = [pytest.mark.research, pytest.mark.timeout(900)]
HAS_SB3 = importlib.util.find_spec("stable_baselines3") is not None


def test_quick_curves_cover_every_point_and_resume_from_the_cache(tmp_path: Path, monkeypatch) -> None:
    from kinswarm.experiments.research.__main__ import main as research

    methods = ["fuzzy", "tabular", *(["ppo-shared"] if HAS_SB3 else [])]
    monkeypatch.setenv("KINSWARM_CURVES_METHODS", ",".join(methods))
    argv = ["curves", "--quick", "--jobs", "1", "--out", str(tmp_path)]
    assert research(argv) == 0
    out = tmp_path / "curves"
    res = json.loads((out / "results.json").read_text())
    z = res["size"]
    points = list(range(0, z["budget"] + 1, z["every"]))
    assert set(res["curves"]) == set(methods)
    for m, a in res["curves"].items():
        assert a["env_steps"] == points, m
        assert a["seeds"] == 1 and all(0.0 <= w <= 1.0 for w in a["within_mean"]), m
    for kind in ("fuzzy", "tabular"):
        (c,) = res["per_seed"][kind]
        assert c["runs"][0] is None and c["cpu_seconds"][0] == 0.0  # the untrained point
        cpus = c["cpu_seconds"][1:]
        assert all(x > 0 for x in cpus) and cpus == sorted(cpus)  # one training's CPU time, up to each point
        for n, run in zip(c["env_steps"][1:], c["runs"][1:], strict=True):
            _, meta = load_checkpoint(tmp_path / "runs" / run / "agents" / "a1.npz", agent="a1", learner=kind)
            assert meta["epochs_trained"] * z["train_steps"] == n  # the learners after exactly n env steps
    # ... and they are what a training of that many epochs ends with, to the bit
    half = curves.train_spec("fuzzy", 0, z, z["every"] // z["train_steps"])
    prefix = run_spec(half, tmp_path / "prefix")
    kept = tmp_path / "runs" / res["per_seed"]["fuzzy"][0]["runs"][1] / "agents"
    for a in ("a1", "a2", "a3", "a4"):
        mine, _ = load_checkpoint(prefix.out / "agents" / f"{a}.npz", agent=a, learner="fuzzy")
        theirs, _ = load_checkpoint(kept / f"{a}.npz", agent=a, learner="fuzzy")
        assert mine.keys() == theirs.keys() and all(np.array_equal(mine[k], theirs[k]) for k in mine), a
    report = (out / "report.md").read_text()
    assert "](curves.png)" in report and (out / "curves.png").stat().st_size > 1000
    # resumable: a second call trains and tests nothing anew, and reports the same numbers
    runs_before = sorted(p.name for p in (tmp_path / "runs").iterdir())
    peers_before = sorted(p.name for p in (out / "peers").iterdir()) if HAS_SB3 else []
    assert research(argv) == 0
    again = json.loads((out / "results.json").read_text())
    assert sorted(p.name for p in (tmp_path / "runs").iterdir()) == runs_before
    assert (sorted(p.name for p in (out / "peers").iterdir()) if HAS_SB3 else []) == peers_before
    assert again["curves"] == res["curves"]


def _drive_frozen(env, learners: dict, epochs_before: int, episodes: int) -> list[float]:
    """The restored learners on the env as the frozen inprocess run calls them (tests/test_env.py `drive`, with
    learning and exploration off)."""
    finals = []
    for epoch in range(episodes):
        obs, infos = env.reset()
        for learner in learners.values():
            learner.start_epoch(epochs_before + epoch, t=0)
        rewards: dict = dict.fromkeys(learners, None)
        while env.agents:
            actions = {}
            for a, learner in learners.items():
                info = infos[a]
                if info["children"] and info["step"] > 0:
                    learner.observe(info["children_actions"], learn=False)
                avoid = [b for b in range(3) if not obs[a]["action_mask"][b]]
                actions[a] = learner.decide(info["state"], rewards[a], learn=False, explore=False, avoid=avoid)
                if not info["children"]:
                    learner.observe([], learn=False)
            obs, rewards, _, _, infos = env.step(actions)
        finals.append(next(iter(infos.values()))["error"])
    return finals


def test_the_swarms_frozen_test_is_the_peers_evaluation(tmp_path: Path) -> None:
    """The frozen run a swarm's curve point is read from, and the same checkpoint's learners stepped frozen on
    parallel_env (where learners.evaluate tests the peers), end every test goal at the same error to the bit."""
    pytest.importorskip("kinswarm.env")
    from kinswarm.env import parallel_env

    goals = tuple(halton(0)[:3])
    common = {"learner": (), "file": curves.RUN_FILE}
    trained = run_spec(Spec("t-train", epochs=3, steps=60, checkpoint=True, **common), tmp_path)
    frozen = run_spec(
        Spec(
            "t-test", epochs=3, steps=40, goals=goals, from_dir=str(trained.out), learn=False, explore=False, **common
        ),
        tmp_path,
    )
    text = "task.goals=[" + ", ".join(f"[{x!r}, {y!r}]" for x, y in goals) + "]"
    env = parallel_env(curves.RUN_FILE, steps=40, sets=[text], render_mode=None, draw=False)
    try:
        learners = env.stepper.learners()
        before = {a: restore_learner(lr, trained.out / "agents" / f"{a}.npz", a, "fuzzy") for a, lr in learners.items()}
        assert set(before.values()) == {3}
        got = _drive_frozen(env, learners, 3, len(goals))
    finally:
        env.close()
    assert got == frozen.final_errors  # to the bit
    assert len(set(got)) == len(goals)  # the goals ended apart: the swarm moved
