"""`up` goes to the parent before the child learns (agent.py): the parent gets a child's action a step
late, with its next `up`, or after an epoch's last step with a closing `up`. It must learn exactly what
it would with the action at once."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from conftest import LOCKSTEP_ARGS, free_port
from kinswarm.actors.cli.commands import main as cli_main
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.settings import LearnerSettings


@pytest.mark.parametrize("n_visible", [0, 1, 2])
def test_decide_then_a_late_observe_is_step(n_visible):
    settings = LearnerSettings.for_reach(12.0)
    rng = np.random.default_rng(n_visible)
    now, late = Learner(settings, n_visible, 5), Learner(settings, n_visible, 5)
    for ln in (now, late):
        ln.start_epoch(1)
    s = rng.uniform(-1.0, 1.0, 6) * [3.0, 3.0, 6.0, 12.0, 12.0, 3.0] + [0.0, 0.0, 6.0, 0.0, 0.0, 0.0]
    pending: list[int] | None = None
    for t in range(400):
        s = s + rng.normal(0.0, 0.05, 6)
        reward = None if t % 97 == 0 else float(rng.normal(-1.0, 2.0))
        visible = rng.integers(0, 3, n_visible).tolist()
        if t == 250:  # a new epoch: the last step's actions are observed before it starts
            late.observe(pending)  # type: ignore[arg-type]
            pending = None
            for ln in (now, late):
                ln.start_epoch(2)
        elif pending is not None:
            late.observe(pending)
        a = now.step(s, reward, visible)
        assert late.decide(s, reward) == a, t
        pending = visible
    late.observe(pending)  # type: ignore[arg-type]
    d, r = now.state_dict(), late.state_dict()
    for k in d:
        np.testing.assert_array_equal(d[k], r[k], err_msg=k)
    assert now.rng.bit_generator.state == late.rng.bit_generator.state


def _run(topo: Path, placement: str, out: Path, epochs: int, steps: int) -> dict:
    args = [
        "run",
        str(topo),
        "--placement",
        placement,
        "--epochs",
        str(epochs),
        "--steps",
        str(steps),
        "--seed",
        "11",
        "--out",
        str(out),
        "--listen",
        f"tcp/127.0.0.1:{free_port()}",
        *LOCKSTEP_ARGS,
        "--no-progress",
    ]
    assert cli_main(args) == 0
    return json.loads((out / "summary.json").read_text())


@pytest.mark.timeout(180)
def test_a_tree_counts_every_action_in_both_placements(tmp_path, tree5):
    """tree5's base sees two children whose last `up` of an epoch come apart: every child's action of every
    step is counted before the checkpoint (Eq. 7's counts: prior x 3 actions + one per step), and the two
    placements learn the same."""
    epochs, steps = 3, 80
    runs = {p: _run(tree5, p, tmp_path / p, epochs, steps) for p in ("single", "process")}
    assert runs["process"]["missed_cmds"] == 0
    assert runs["single"]["final_error"] == runs["process"]["final_error"]
    for agent in ("base", "l1", "r1", "l2", "r2"):
        a, b = (np.load(tmp_path / p / "agents" / f"{agent}.npz") for p in ("single", "process"))
        for k in ("phi_keys", "phi", "counts"):
            np.testing.assert_array_equal(a[k], b[k], err_msg=f"{agent} {k}")
        counts = a["counts"]
        if counts.size:  # one row per visible child
            assert counts.sum(axis=1).tolist() == [3.0 + epochs * steps] * counts.shape[0], agent
