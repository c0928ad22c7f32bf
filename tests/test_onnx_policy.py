"""`[learner] kind = "onnx"`: a policy from an ONNX file acts the same in parallel_env and as a swarm of processes,
and a bad policy is refused in one line before anything starts (actors/policies/onnx.py).

The policies are built here with the `onnx` helper API: a fixed linear layer over the observation (scores = s W + b),
per agent or shared with the agent's index as a second input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")
from kinswarm.actors.env import parallel_env  # noqa: E402
from kinswarm.actors.policies.onnx import OnnxPolicy, PolicyError  # noqa: E402
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
CHAIN4 = ROOT / "examples" / "chain4.toml"
EPOCHS, STEPS = 2, 60


def linear(
    path: Path, w: np.ndarray, b: np.ndarray, *, index: np.ndarray | None = None, out: float = 0.0, log: bool = False
) -> Path:
    """scores = s W + b (+ float(index) v, when `index` is v: a shared policy's second input) (+ out: NaN to spoil),
    or the log of that (`log`: NaN where it is negative)."""
    n = w.shape[0]
    nodes = [helper.make_node("MatMul", ["obs", "W"], ["sw"]), helper.make_node("Add", ["sw", "b"], ["raw"])]
    inits = [numpy_helper.from_array(w.astype(np.float32), "W"), numpy_helper.from_array(b.astype(np.float32), "b")]
    inputs = [helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, n])]
    last = "raw"
    if index is not None:
        inputs.append(helper.make_tensor_value_info("agent", TensorProto.INT64, [1, 1]))
        inits.append(numpy_helper.from_array(index.astype(np.float32).reshape(1, -1), "v"))
        nodes += [
            helper.make_node("Cast", ["agent"], ["agentf"], to=TensorProto.FLOAT),
            helper.make_node("Mul", ["agentf", "v"], ["iv"]),
            helper.make_node("Add", ["raw", "iv"], ["with_index"]),
        ]
        last = "with_index"
    inits.append(numpy_helper.from_array(np.full((1, b.size), out, dtype=np.float32), "spoil"))
    nodes.append(helper.make_node("Add", [last, "spoil"], ["spoiled"]))
    nodes.append(helper.make_node("Log" if log else "Identity", ["spoiled"], ["scores"]))
    outputs = [helper.make_tensor_value_info("scores", TensorProto.FLOAT, [1, b.size])]
    graph = helper.make_graph(nodes, "policy", inputs, outputs, inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 13)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def _weights(n: int, seed: int) -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(seed)
    return rng.normal(size=(n, 3)), rng.normal(scale=0.1, size=3)


def _obs_size() -> dict[str, int]:
    env = parallel_env(str(CHAIN4), steps=2)
    try:
        return {a: env.observation_space(a)["observation"].shape[0] for a in env.possible_agents}
    finally:
        env.close()


@pytest.fixture(scope="module")
def policies(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    """A directory of one policy per agent, and one shared file with the agent's index."""
    root = tmp_path_factory.mktemp("policies")
    sizes = _obs_size()
    per_agent = root / "per-agent"
    per_agent.mkdir()
    for i, (a, n) in enumerate(sizes.items()):
        linear(per_agent / f"{a}.onnx", *_weights(n, i))
    (n,) = set(sizes.values())  # chain4's agents see states of one size: one file can serve them all
    w, b = _weights(n, 99)
    shared = linear(root / "shared.onnx", w, b, index=np.array([0.5, -0.2, 0.3]))
    return {"dir": per_agent, "file": shared}


def _env_finals(policy: Path) -> tuple[list[float], list[list[int]]]:
    """The policy's actions on parallel_env, as any user of the env would take them: argmax over the masked scores."""
    env = parallel_env(str(CHAIN4), epochs=EPOCHS, steps=STEPS, sets=["learner.kind=onnx", f"learner.policy={policy}"])
    try:
        learners = env.stepper.learners()  # the swarm's own builder: the same OnnxPolicy objects
        assert all(isinstance(x, OnnxPolicy) for x in learners.values())
        finals, first = [], []
        for _ in range(EPOCHS):
            obs, infos = env.reset()
            taken = []
            while env.agents:
                actions = {}
                for i, a in enumerate(env.possible_agents):
                    scores = learners[a].scores(obs[a]["observation"])
                    if policy.is_file():  # the shared one: the index is part of the contract, checked here
                        assert i == learners[a].index
                    actions[a] = int(np.argmax(np.where(obs[a]["action_mask"] == 1, scores, -np.inf)))
                taken.append([actions[a] for a in env.possible_agents])
                obs, _, _, _, infos = env.step(actions)
            finals.append(next(iter(infos.values()))["error"])
            first.append(taken[:5])
        return finals, first
    finally:
        env.close()


def _kinswarm(*args: str, timeout: float = 240) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "kinswarm.actors.cli", *args], capture_output=True, text=True, timeout=timeout
    )


def _run_finals(tmp_path: Path, policy: Path, placement: str) -> list[float]:
    out = tmp_path / f"run-{placement}"
    sets = ["--set", "learner.kind=onnx", "--set", f"learner.policy={policy}"]
    r = _kinswarm(
        "run", str(CHAIN4), "--placement", placement, "--epochs", str(EPOCHS), "--steps", str(STEPS),
        "--out", str(out), *sets,
    )  # fmt: skip
    assert r.returncode == 0, r.stderr[-2000:]
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    return [row["final_error"] for row in rows]


@pytest.mark.parametrize("which", ["dir", "file"])
def test_a_policy_acts_the_same_in_the_env_and_as_a_swarm_of_processes(tmp_path, policies, which):
    finals, first = _env_finals(policies[which])
    assert len(set(finals)) == 1  # frozen and deterministic: every episode from the start pose is the same one
    assert any(a != 1 for step in first[0] for a in step)  # and the policy moves the robot
    assert _run_finals(tmp_path, policies[which], "process") == finals  # to the bit
    if which == "dir":
        assert _run_finals(tmp_path, policies[which], "inprocess") == finals


# -- bad input: one line, before anything starts --------------------------------------------------------------------
def _refused(tmp_path: Path, *sets: str) -> str:
    out = tmp_path / "refused"
    args = [a for s in sets for a in ("--set", s)]
    r = _kinswarm("run", str(CHAIN4), "--placement", "process", "--epochs", "1", "--out", str(out), *args, timeout=60)
    assert r.returncode == 2, (r.returncode, r.stderr)
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in r.stderr, r.stderr
    assert not out.exists()  # nothing made, nothing spawned
    return lines[0]


def test_bad_policies_are_refused_in_one_line(tmp_path, policies):
    n = next(iter(_obs_size().values()))
    bad = tmp_path / "bad"
    bad.mkdir()
    (bad / "garbage.onnx").write_bytes(b"this is no model")
    cases = {
        "missing": (str(tmp_path / "nowhere.onnx"), "no such file or directory"),
        "not onnx": (str(bad / "garbage.onnx"), "not a model onnxruntime can run"),
        "input size": (str(linear(bad / "wide.onnx", *_weights(n + 2, 0))), f"this agent's observation is (1, {n})"),
        "four scores": (str(linear(bad / "four.onnx", np.ones((n, 4)), np.zeros(4))), "gives 4 scores; expected 3"),
        "nan": (str(linear(bad / "nan.onnx", *_weights(n, 0), out=float("nan"))), "non-finite score"),
        "no agent file": (str(bad), "no a1.onnx in the directory"),
    }
    for what, (policy, says) in cases.items():
        line = _refused(tmp_path, "learner.kind=onnx", f"learner.policy={policy}")
        assert "learner.policy" in line and says in line, (what, line)
    line = _refused(tmp_path, "learner.kind=onnx")
    assert "learner.policy" in line and "needs `policy`" in line, line
    line = _refused(tmp_path, "learner.kind=onnx", f"learner.policy={policies['file']}", "learner.lr=0.3")
    assert "learner.lr" in line and "the onnx learner does not take it" in line, line
    line = _refused(tmp_path, f"learner.policy={policies['file']}")
    assert "learner.policy" in line and "the fuzzy learner does not take it" in line, line


def test_a_non_finite_score_at_run_time_keeps_the_agent_still_and_is_said_once(tmp_path, capsys):
    """A score that turns NaN on some inputs only (here the log of a negative number, for s[0] > 0.2) cannot be refused
    before the run. The agent keeps still at that step and says so once; it goes on deciding."""
    bounds = [(-1.0, 1.0), (-1.0, 1.0)]
    w = np.array([[-5.0, -5.0, -5.0], [0.0, 0.5, 0.0]])
    policy = OnnxPolicy(linear(tmp_path / "p.onnx", w, np.array([1.0, 2.0, 1.0]), log=True), bounds, index=0)
    assert policy.decide(np.array([0.0, 1.0]), None) == 1  # finite: the best score
    assert policy.decide(np.array([0.0, 1.0]), None, avoid=[1]) in (0, 2)  # the mask is applied
    for _ in range(3):
        assert policy.decide(np.array([1.0, 0.0]), None, avoid=[1]) == 1  # NaN: kept still, whatever the mask
    assert policy.decide(np.array([0.0, 1.0]), None) == 1  # and it goes on
    err = capsys.readouterr().err
    assert err.count("non-finite score") == 1 and "kept still" in err, err
    with pytest.raises(PolicyError, match="non-finite score"):  # NaN at the middle of the bounds: refused at once
        OnnxPolicy(linear(tmp_path / "q.onnx", w, np.array([-1.0, 2.0, 1.0]), log=True), bounds, index=0)
