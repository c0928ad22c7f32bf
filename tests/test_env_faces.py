"""kinswarm.env as multi-agent researchers use it, each check as its library ships it: PettingZoo's render_test,
state_test, max_cycles_test, parallel_api_test and parallel_seed_test on the parallel face; Gymnasium's make_vec
with copies that differ; SB3's check_env with the render check on, and sb3-contrib's MaskablePPO learning, on the
Gymnasium face (skipped without SB3: its torch is not in the test install, see docs/env.md); the lifecycle (close,
then reset; render before reset); seeds drawing the episodes; the options that go beyond the anchors."""

from __future__ import annotations

import types
import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from kinswarm.env import ENV_ID, aec_env, gym_env, parallel_env
from pettingzoo.test import (
    max_cycles_test,
    parallel_api_test,
    parallel_seed_test,
    render_test,
    state_test,
)

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ["chain4", "tree5", "iiwa", "grasp3"]
STEPS = 20


def example(name: str) -> str:
    return str(ROOT / "examples" / f"{name}.toml")


@pytest.fixture(autouse=True)
def _quiet():
    with warnings.catch_warnings():  # PettingZoo's tests reset with an option of their own, which the env names
        warnings.filterwarnings("ignore", message="reset options: 'options'")
        yield


# -- PettingZoo -------------------------------------------------------------------------------------------------------
# chain4 in the default suite; the other robots (~12 s each) in the slow suite
@pytest.mark.parametrize("name", [n if n == "chain4" else pytest.param(n, marks=pytest.mark.slow) for n in EXAMPLES])
def test_pettingzoo_render_state_and_max_cycles(name: str) -> None:
    def aec(render_mode: str | None = "rgb_array"):
        return aec_env(example(name), steps=STEPS, render_mode=render_mode)

    render_test(aec)
    env, par = aec(), parallel_env(example(name), steps=STEPS)
    try:
        state_test(env, par)
        assert par.state_space.contains(par.state())
        assert par.state().dtype == np.float32
    finally:
        env.close()
        par.close()
    module = types.SimpleNamespace(  # PettingZoo's test takes a module of env() and parallel_env() factories
        env=lambda **kw: aec_env(example(name), **kw), parallel_env=lambda **kw: parallel_env(example(name), **kw)
    )
    max_cycles_test(module)


@pytest.mark.parametrize("name", EXAMPLES)
def test_pettingzoo_api_and_seed_with_float32_observations(name: str) -> None:
    env = parallel_env(example(name), steps=STEPS)
    try:
        parallel_api_test(env, num_cycles=60)
        obs, _ = env.reset(seed=3)
        assert all(o["observation"].dtype == np.float32 for o in obs.values())
    finally:
        env.close()
    parallel_seed_test(lambda: parallel_env(example(name), steps=STEPS))


@pytest.mark.parametrize("name", ["chain4", "iiwa"])
def test_the_global_state_is_the_gym_faces_observation_and_the_helpers_map_between_them(name: str) -> None:
    par, env = parallel_env(example(name), steps=5), gym_env(example(name), steps=5)
    try:
        _, infos = par.reset(seed=4)
        obs, _ = env.reset(seed=4)
        assert np.array_equal(par.state(), obs)
        rng = np.random.default_rng(0)
        for _ in range(5):
            actions = {a: int(rng.integers(3)) for a in par.agents}
            _, _, _, _, infos = par.step(actions)
            obs, *_ = env.step(par.joint_actions(actions))
            assert np.array_equal(par.state(), obs)  # the same moves at the same places
        slices = par.state_slices()
        readings = par.stepper.robot.readings()
        for a in par.possible_agents:
            assert par.state()[slices[a]][0] == np.float32(readings[a])
            assert par.joint_index(a) == slices[a].start
        assert np.array_equal(par.state()[slices["goal"]], obs[-len(par.stepper.robot.goal()) :])
        with pytest.raises(ValueError, match="not a joint"):
            par.joint_index("nowhere")
    finally:
        par.close()
        env.close()


# -- seeds draw the episodes ------------------------------------------------------------------------------------------
def test_make_vec_copies_differ_and_a_seed_repeats_them() -> None:
    def first(seed: int) -> np.ndarray:
        venv = gymnasium.make_vec(ENV_ID, num_envs=4, run_file=example("chain4"), steps=STEPS)
        try:
            obs, _ = venv.reset(seed=seed)
            return obs
        finally:
            venv.close()

    a, b, c = first(7), first(7), first(8)
    assert len({tuple(row) for row in a}) == 4  # four different episodes
    assert np.array_equal(a, b) and not np.array_equal(a, c)


@pytest.mark.parametrize("name", ["chain4", "tree5", "iiwa"])
def test_seeds_draw_reachable_goals_and_draw_false_keeps_the_run_files(name: str) -> None:
    env = gym_env(example(name), steps=3)
    kept = gym_env(example(name), steps=3, draw=False)
    try:
        st = env.unwrapped.stepper
        goals = set()
        for seed in range(5):
            env.reset(seed=seed)
            goal = st.robot.goal()
            goals.add(goal)
            base = np.array(st.topo.base[: 3 if st.topo.spatial else 2])
            assert np.linalg.norm(np.array(goal[: len(base)]) - base) <= st.topo.reach + 1e-9
            if st.topo.spatial:
                assert goal[2] >= st.topo.base[2]  # above the floor the arm stands on
        assert len(goals) == 5
        env.reset(seed=0)
        g0 = env.unwrapped.stepper.robot.goal()
        env.reset()
        assert env.unwrapped.stepper.robot.goal() != g0  # the draws carry on without a new seed
        run_goal = kept.unwrapped.stepper.task.goal(0, 3)[0]
        for seed in (0, 1):
            kept.reset(seed=seed)
            assert kept.unwrapped.stepper.robot.goal() == run_goal
        env.reset(seed=0, options={"goal": list(run_goal)})
        assert env.unwrapped.stepper.robot.goal() == tuple(run_goal)
    finally:
        env.close()
        kept.close()


def test_a_random_start_pose_is_drawn_by_the_seed() -> None:
    def start(seed: int, draw: bool = True) -> tuple[float, ...]:
        env = gym_env(example("chain4"), steps=2, task__start_pose="random", draw=draw)
        try:
            obs, _ = env.reset(seed=seed)
            return tuple(obs[:4])
        finally:
            env.close()

    assert start(1) == start(1) != start(2)
    assert start(1, draw=False) == start(2, draw=False)  # the task's own draw, by epoch


# -- lifecycle --------------------------------------------------------------------------------------------------------
def test_reset_after_close_builds_the_world_again_and_render_before_reset_says_so() -> None:
    env = gym_env(example("chain4"), steps=3)
    with pytest.raises(RuntimeError, match="call reset"):
        env.render()
    first, _ = env.reset(seed=2)
    env.apply_fault("lock", "a2")
    env.close()
    env.close()  # twice: nothing
    with pytest.raises(RuntimeError, match="closed"):
        env.step(np.array([1, 1, 1, 1]))
    again, _ = env.reset(seed=2)
    try:
        assert np.array_equal(first, again)
        before = env.unwrapped.stepper.robot.world.joint_positions()["a2"]
        env.step(np.array([2, 2, 2, 2]))
        assert env.unwrapped.stepper.robot.world.joint_positions()["a2"] != before  # the lock went with the world
    finally:
        env.close()


def test_render_modes() -> None:
    env = gym_env(example("chain4"), steps=3, render_mode=None)
    try:
        env.reset(seed=0)
        with pytest.warns(UserWarning, match="draws nothing"):
            assert env.render() is None
    finally:
        env.close()
    par = parallel_env(example("chain4"), steps=3, render_mode="human")
    try:
        par.reset(seed=0)
        assert par.render() is None
        par.step(dict.fromkeys(par.agents, 2))
    finally:
        par.close()
    with pytest.raises(ValueError, match="render_mode"):
        gym_env(example("chain4"), render_mode="ansi")


# -- beyond the anchors ---------------------------------------------------------------------------------------------
def test_groups_of_joints_as_agents() -> None:
    par = parallel_env(example("chain4"), steps=4, agents=[["a1", "a2"], ["a3", "a4"]])
    one = parallel_env(example("chain4"), steps=4)
    try:
        assert par.possible_agents == ["a1+a2", "a3+a4"]
        assert par.action_space("a1+a2") == gymnasium.spaces.MultiDiscrete([3, 3])
        obs, infos = par.reset(seed=0)
        single, _ = one.reset(seed=0)
        assert np.array_equal(
            obs["a1+a2"]["observation"], np.concatenate([single["a1"]["observation"], single["a2"]["observation"]])
        )
        assert obs["a3+a4"]["action_mask"].shape == (6,)
        for _ in range(4):
            obs, rewards, _, truncated, infos = par.step({"a1+a2": [2, 0], "a3+a4": np.array([1, 2])})
            single, r1, *_ = one.step({"a1": 2, "a2": 0, "a3": 1, "a4": 2})
        assert rewards["a1+a2"] == pytest.approx((r1["a1"] + r1["a2"]) / 2)
        assert all(truncated.values()) and infos["a3+a4"]["joints"]["a4"]["step"] == 4
        assert par.state().tolist() == one.state().tolist()
    finally:
        par.close()
        one.close()
    for groups, message in [
        ([["a1", "a2"], ["a2", "a3", "a4"]], "a2 in more than one group"),
        ([["a1", "a2"]], "a3, a4 in none"),
        ([["a1", "a9"], ["a2", "a3", "a4"]], "'a9' is not a joint"),
    ]:
        with pytest.raises(ValueError, match=message):
            parallel_env(example("chain4"), agents=groups)


def test_continuous_per_agent_actions_success_and_reward_terms() -> None:
    par = parallel_env(example("chain4"), steps=50, continuous=True, reward_terms=True, success=2.0, draw=False)
    try:
        obs, _ = par.reset()
        assert par.action_space("a1") == gymnasium.spaces.Box(-1.0, 1.0, (1,), np.float32)
        one = par.stepper.cfg.action_rad
        before = par.stepper.robot.world.joint_positions()
        _, _, _, _, infos = par.step({"a1": [0.5], "a2": [-1.0], "a3": [0.0], "a4": [0.25]})
        after = par.stepper.robot.world.joint_positions()
        assert [after[a] - before[a] for a in par.possible_agents] == pytest.approx([one / 2, -one, 0.0, one / 4])
        terms = infos["a1"]["reward_terms"]
        assert terms["local"] == 0.0  # reach pays no local terms
        with pytest.raises(ValueError, match="finite numbers"):
            par.step({"a1": "up"})
        # the greedy move per joint: toward the goal until the error is within 2.0, then terminated
        ended = None
        for t in range(49):
            errs = {}
            for a in par.agents:
                errs[a] = [_error_after(par, a, s) for s in (-1.0, 1.0)]
            actions = {a: [-1.0 if e[0] < e[1] else 1.0] for a, e in errs.items()}
            _, _, terminated, truncated, infos = par.step(actions)
            if any(terminated.values()):
                ended = t
                break
        assert ended is not None and infos["a1"]["error"] <= 2.0 and not any(truncated.values())
        assert par.agents == []
    finally:
        par.close()
    with pytest.raises(ValueError, match="success"):
        gym_env(example("chain4"), success=-1.0)


def _error_after(par, joint: str, share: float) -> float:
    """The error if only this joint moved by `share` of a move now (the planar kinematics, no step taken)."""
    from kinswarm.sim.kinematics import tips

    st = par.stepper
    q = dict(st.robot.world.joint_positions())
    q[joint] += share * st.cfg.action_rad
    tip = tips(st.topo, q)[st.topo.end_effectors[0]]
    goal = st.robot.goal()
    return float(np.hypot(tip[0] - goal[0], tip[1] - goal[1]))


# -- Stable-Baselines3 and sb3-contrib ------------------------------------------------------------------------------
@pytest.mark.parametrize("name", EXAMPLES)
def test_sb3_check_env_with_render_and_maskable_ppo(name: str) -> None:
    pytest.importorskip("sb3_contrib", reason="sb3-contrib (and torch) are not in the test install: docs/env.md")
    import torch
    from sb3_contrib import MaskablePPO
    from stable_baselines3.common.env_checker import check_env

    torch.set_num_threads(1)
    env = gym_env(example(name), steps=STEPS)
    check_env(env, skip_render_check=False)  # closes the env, then steps it again
    env.close()
    env = gym_env(example(name), steps=STEPS)
    try:
        model = MaskablePPO("MlpPolicy", env, n_steps=64, batch_size=32, n_epochs=1, seed=0)
        model.learn(128)
        assert model.num_timesteps >= 128
    finally:
        env.close()


@pytest.mark.parametrize("name", ["chain4", "iiwa"])
def test_the_shared_policy_vector_env_keeps_truncation_and_its_copies_differ(name: str) -> None:
    pytest.importorskip("sb3_contrib", reason="sb3-contrib (and torch) are not in the test install: docs/env.md")
    import torch
    from kinswarm.env.sb3 import JointsVecEnv
    from sb3_contrib import MaskablePPO

    torch.set_num_threads(1)
    venv = JointsVecEnv([parallel_env(example(name), steps=5, render_mode=None) for _ in range(2)])
    try:
        n = len(venv.agents)
        venv.seed(3)
        obs = venv.reset()
        assert obs.shape == (2 * n, venv.obs_dim + n) and obs.dtype == np.float32
        assert not np.array_equal(obs[:n, : venv.obs_dim], obs[n:, : venv.obs_dim])  # two copies, two goals
        assert np.array_equal(obs[:n, venv.obs_dim :], np.eye(n))  # the agent's index
        for t in range(5):
            obs, rewards, dones, infos = venv.step(np.full(2 * n, 2))
            assert all(venv.observation_space.contains(row) for row in obs)
            assert dones.all() if t == 4 else not dones.any()
        assert all(i["TimeLimit.truncated"] for i in infos)  # a cut: SB3 bootstraps there
        assert all(i["terminal_observation"].shape == obs[0].shape for i in infos)
        assert venv.action_masks().shape == (2 * n, 3)
        model = MaskablePPO("MlpPolicy", venv, n_steps=16, batch_size=32, n_epochs=1, seed=0)
        model.learn(64)
        assert len(venv.final_errors) >= 2 * 4
    finally:
        venv.close()
