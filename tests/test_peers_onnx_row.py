"""The peers report's ONNX-in-the-swarm row (experiments/peers/onnx_swarm.py) without torch: a tiny policy made with
the `onnx` helper API, of the observation the peers were trained on, shared by every agent with its index.

The default suite checks the run file it writes and the env's side (intact and with a2 locked); the slow one runs the
whole row: a process swarm intact and with `kinswarm fault ... lock a2` sent live, against the env, to the bit."""

from __future__ import annotations

import tomllib
from pathlib import Path

import numpy as np
import pytest

onnx = pytest.importorskip("onnx")
pytest.importorskip("onnxruntime")
from kinswarm.actors.env import parallel_env  # noqa: E402
from kinswarm.experiments.goals import halton  # noqa: E402
from kinswarm.experiments.peers import onnx_swarm  # noqa: E402
from onnx import TensorProto, helper, numpy_helper  # noqa: E402

pytestmark = pytest.mark.timeout(600)


def shared_policy(path: Path, n: int, seed: int = 0) -> Path:
    """scores = obs W + float(agent) v: a linear policy over the observation, its index as the second input."""
    rng = np.random.default_rng(seed)
    inits = [
        numpy_helper.from_array(rng.normal(size=(n, 3)).astype(np.float32), "W"),
        numpy_helper.from_array(rng.normal(size=(1, 3)).astype(np.float32), "v"),
    ]
    nodes = [
        helper.make_node("MatMul", ["obs", "W"], ["sw"]),
        helper.make_node("Cast", ["agent"], ["agentf"], to=TensorProto.FLOAT),
        helper.make_node("Mul", ["agentf", "v"], ["iv"]),
        helper.make_node("Add", ["sw", "iv"], ["scores"]),
    ]
    inputs = [
        helper.make_tensor_value_info("obs", TensorProto.FLOAT, [1, n]),
        helper.make_tensor_value_info("agent", TensorProto.INT64, [1]),
    ]
    outputs = [helper.make_tensor_value_info("scores", TensorProto.FLOAT, [1, 3])]
    model = helper.make_model(
        helper.make_graph(nodes, "policy", inputs, outputs, inits), opset_imports=[helper.make_opsetid("", 13)]
    )
    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, str(path))
    return path


def _obs_size() -> int:
    env = parallel_env(str(onnx_swarm.RECIPE), steps=2, render_mode=None)
    try:
        (n,) = {env.observation_space(a)["observation"].shape[0] for a in env.possible_agents}
        return n
    finally:
        env.close()


def test_the_row_s_run_file_and_the_env_side(tmp_path: Path) -> None:
    policy = shared_policy(tmp_path / "p.onnx", _obs_size())
    goals = halton(0)[:4]
    file = onnx_swarm.write_run_file(tmp_path / "row.toml", policy, goals, steps=60)
    spec = tomllib.loads(file.read_text())
    recipe = tomllib.loads(onnx_swarm.RECIPE.read_text())
    assert spec["run"]["placement"] == "process" and spec["run"]["epochs"] == 4 and spec["run"]["steps"] == 60
    assert spec["task"]["goals"] == [list(g) for g in goals] and spec["task"]["reward"] == recipe["task"]["reward"]
    # the recipe's observation, nothing of the fuzzy learner's own (kind onnx refuses those): parallel_env built it
    assert spec["learner"]["kind"] == "onnx" and spec["learner"]["policy"] == str(policy.resolve())
    assert {k: spec["learner"][k] for k in ("ranges", "g3", "extra_state")} == {
        k: recipe["learner"][k] for k in ("ranges", "g3", "extra_state")
    }
    assert "n_sets" not in spec["learner"] and "plasticity" not in spec["learner"]
    intact = onnx_swarm.env_finals(file)
    locked = onnx_swarm.env_finals(file, onnx_swarm.LOCK)
    assert len(intact) == len(locked) == 4 and all(np.isfinite(intact + locked))
    assert onnx_swarm.env_finals(file) == intact  # frozen and deterministic
    assert len(set(intact)) > 1  # one goal per epoch, in the file's order
    assert intact != locked  # the lock reaches the robot


def test_a_policy_file_that_is_not_there_is_refused_in_one_line(tmp_path: Path) -> None:
    file = onnx_swarm.write_run_file(tmp_path / "row.toml", tmp_path / "nowhere.onnx", halton(0)[:1], steps=10)
    with pytest.raises(ValueError, match="learner.policy") as e:
        onnx_swarm.env_finals(file)
    assert "\n" not in str(e.value)


@pytest.mark.slow
def test_the_whole_row_a_process_swarm_intact_and_locked_live_as_the_env(tmp_path: Path) -> None:
    policy = shared_policy(tmp_path / "p.onnx", _obs_size())
    r = onnx_swarm.row(policy, halton(0)[:6], 100, tmp_path / "row", lock_after=1)
    assert r["intact_identical"], (r["swarm_intact"], r["env_intact"])
    assert r["fault"]["returncode"] == 0, r["fault"]
    assert r["lock"] is not None and r["lock"]["epoch"] >= 1  # sent after the first epoch, landed where the sim says
    assert r["after"], r["lock"]  # epochs came after the landing one
    assert r["before_identical"] and r["after_identical"], r
    assert [r["env_locked"][i] for i in r["after"]] != [r["env_intact"][i] for i in r["after"]]


def test_without_the_peers_extra_the_experiment_says_so_in_one_line(tmp_path: Path) -> None:
    """torch and SB3 hidden (as if not installed; torch's import alone would cost seconds): `kinswarm experiment
    peers` exits 2 with one line naming the extra."""
    import subprocess
    import sys

    code = (
        "import sys; sys.modules['torch'] = sys.modules['stable_baselines3'] = None\n"
        "from kinswarm.actors.cli.commands import main\n"
        f"sys.exit(main(['experiment', 'peers', '--quick', '--out', {str(tmp_path / 'out')!r}]))\n"
    )
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "needs the peers extra" in lines[0] and "pip install" in lines[0], r.stderr
    assert not (tmp_path / "out" / "peers").exists()  # nothing trained, nothing written
