"""`kinswarm experiment peers --quick` end to end (slow suite; skipped without the peers extra): every peer trained,
tested and reported; the shared per-joint policy exported to ONNX, acting as the torch policy does, and run as
a process swarm as in the env."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("stable_baselines3")
pytest.importorskip("kinswarm.env")

pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


def test_quick_peers_report(tmp_path: Path) -> None:
    from kinswarm.actors.cli.commands import main as kinswarm

    assert kinswarm(["experiment", "peers", "--quick", "--seeds", "2", "--out", str(tmp_path)]) == 0
    out = tmp_path / "peers"
    report = (out / "report.md").read_text()
    for heading in (
        "## Generalisation",
        "## Learning curves and time to skill",
        "## Successive goals",
        "## A wrong model",
        "### Live",
        "## The shared policy in ONNX",
        "## The iiwa's points",
    ):
        assert heading in report
    assert "](curves.png)" in report and (out / "curves.png").stat().st_size > 1000
    res = json.loads((out / "results.json").read_text())
    assert res["experiment"] == "peers" and res["quick"] is True
    assert set(res["peers"]) == {"sac", "ppo", "ppo-shared"}
    for method, r in res["peers"].items():
        assert [s["seed"] for s in r["seeds"]] == [0, 1], method  # every peer on every seed, the same budget
        for s in r["seeds"]:
            assert s["budget"] == res["size"]["budget"]
            for k in (0, 1):
                assert len(s[f"test_set_{k}"]["errors"]) == res["size"]["tests"], method
                assert all(np.isfinite(s[f"test_set_{k}"]["errors"]))
            c = s["curve"]
            assert c["env_steps"][0] == 0 and c["env_steps"][-1] == res["size"]["budget"]
            assert all(0.0 <= w <= 1.0 for w in c["within"])
            assert set(s["successive"]) == {"chain4", "joints free"}
            assert len(s["successive"]["chain4"]["errors"]) == res["size"]["tests"]
            assert set(s["wrong"]) == {"a1 reversed", "a2, a3 reversed"}
            for row in s["wrong"].values():  # frozen on every goal, learning on the first `online`
                assert len(row["frozen"]["errors"]) == res["size"]["wrong"]
                assert len(row["learning"]["errors"]) == res["size"]["online"]
            assert set(s["live"]) == {"intact", "a1 reversed", "a2, a3 reversed"}
            for row in s["live"].values():  # the next goals after the one reached intact
                assert len(row["frozen"]["errors"]) == len(row["learning"]["errors"]) == res["size"]["live_next"]
        assert res["curves"][method]["seeds"] == 2
        # the iiwa's points: every peer on every seed, the same training set and both test sets
        assert [s["seed"] for s in r["iiwa"]] == [0, 1], method
        assert len({s["env_steps"] for s in r["iiwa"]}) == 1
        for name in ("A", "B"):
            assert len(r["iiwa_sets"][name]["within"]) == 2
            assert all(0.0 <= w <= 1.0 for w in r["iiwa_sets"][name]["within"])
    assert res["swarm_training_cpu_seconds"] > 0
    # the shared PPO's tuning sweep: 2x2, seed 0, each its curve at the same points as the defaults'
    assert len(res["sweep"]) == 4 and "### The shared PPO tuned" in report
    default_points = res["peers"]["ppo-shared"]["seeds"][0]["curve"]["env_steps"]
    assert all(r["curve"]["env_steps"] == default_points for r in res["sweep"].values())
    assert len({json.dumps(r["hp"], sort_keys=True) for r in res["sweep"].values()}) == 4
    onnx = res["peers"]["ppo-shared"]["seeds"][0]["onnx"]
    assert (out / onnx["file"]).stat().st_size > 0
    if onnx["checked"]:  # onnxruntime installed: the exported file chooses as the torch policy does
        assert onnx["decisions"] > 0 and onnx["same"] == onnx["decisions"]
    # the exported file as a process swarm: as in the env to the bit, intact and after a live lock of a2
    assert "## Trained elsewhere, run as a swarm, broken live" in report
    row = res["onnx_swarm"]
    assert len(row["swarm_intact"]) == res["size"]["onnx_goals"] and row["intact_identical"]
    assert row["lock"] is not None and row["after"] and row["after_identical"] and row["before_identical"], row
    # a second call retrains and retests nothing: every seed's training is read back
    assert kinswarm(["experiment", "peers", "--quick", "--seeds", "2", "--out", str(tmp_path)]) == 0
    again = (out / "report.md").read_text()
    assert "Trained by an earlier call with this --out" in again


def test_exported_scores_take_the_agent_index(tmp_path: Path) -> None:
    """The shared file's scores for one observation differ by the agent index it is given (the one-hot reaches the
    network), and match the torch policy's logits for that agent."""
    ort = pytest.importorskip("onnxruntime")
    import torch
    from kinswarm.experiments.goals import quadtree
    from kinswarm.experiments.peers import learners
    from stable_baselines3 import PPO

    venv = learners.joints_env(quadtree(1), 10, 0)
    model = PPO("MlpPolicy", venv, seed=0, n_steps=16, batch_size=16, device="cpu")
    path = learners.export_onnx(model, venv.n, venv.obs_dim, tmp_path / "p.onnx")
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    one = venv.reset()[:1, : venv.obs_dim]  # the first agent's observation, given as every agent's
    n = venv.n
    scores = [sess.run(None, {"obs": one, "agent": np.array([i], np.int64)})[0] for i in range(n)]
    with torch.no_grad():
        x = torch.as_tensor(np.concatenate([np.repeat(one, n, 0), np.eye(n)], 1).astype("f4"))
        dist = model.policy.get_distribution(x)
        logits = dist.distribution.logits.numpy()
    for i in range(venv.n):
        assert scores[i].shape == (1, 3)
        # SB3 normalises the logits (log-softmax); the argmax and the differences between scores are the same
        assert np.allclose(scores[i][0] - scores[i][0].max(), logits[i] - logits[i].max(), atol=1e-5)
    assert not np.allclose(scores[0], scores[1])
    venv.close()
