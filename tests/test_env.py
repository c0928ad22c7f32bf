"""kinswarm.env: the peers' own checks (Gymnasium's check_env, PettingZoo's parallel_api_test and parallel_seed_test)
on the examples, the env agreeing with the inprocess placement to the bit, goals, faults, seeding, rendering, and
bad input refused in one line."""

from __future__ import annotations

import warnings
from pathlib import Path

import gymnasium
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from kinswarm.actors.files.runfile import load_run
from kinswarm.actors.learning.kinds import JointLearner
from kinswarm.actors.supervisor.inprocess import InProcessRun
from kinswarm.env import ENV_ID, KinswarmParallelEnv, gym_env, parallel_env
from kinswarm.protocol.messages import Fault
from pettingzoo.test import parallel_api_test, parallel_seed_test

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ["chain4", "tree5", "iiwa", "chain4-track", "corridor7", "grasp3"]
STEPS = 20  # two episodes within parallel_api_test's 200 cycles, in well under a second each


def example(name: str) -> str:
    return str(ROOT / "examples" / f"{name}.toml")


@pytest.fixture(autouse=True)
def _quiet_option_warning():
    with warnings.catch_warnings():  # PettingZoo's API test resets with an option of its own, which the env names
        warnings.filterwarnings("ignore", message="reset options: 'options'")
        yield


@pytest.mark.parametrize("name", EXAMPLES)
def test_pettingzoo_parallel_api_and_seed(name: str) -> None:
    env = parallel_env(example(name), steps=STEPS)
    try:
        parallel_api_test(env, num_cycles=200)
    finally:
        env.close()
    parallel_seed_test(lambda: parallel_env(example(name), steps=STEPS))


@pytest.mark.parametrize("name", EXAMPLES)
@pytest.mark.parametrize("continuous", [False, True])
def test_gymnasium_check_env(name: str, continuous: bool) -> None:
    env = gym_env(example(name), steps=STEPS, continuous=continuous)
    try:
        check_env(env, skip_render_check=False)
    finally:
        env.close()


@pytest.mark.parametrize("name", EXAMPLES)
def test_every_observation_lies_in_its_space(name: str) -> None:
    """parallel_api_test does not look: every agent's observation, masked random moves for a whole episode."""
    env = parallel_env(example(name), steps=STEPS)
    try:
        obs, infos = env.reset(seed=1)
        assert env.possible_agents == list(env.stepper.topo.dof_agents)
        for step in range(STEPS):
            for a in env.agents:
                assert env.observation_space(a).contains(obs[a]), (a, obs[a])
                assert len(infos[a]["children_actions"]) == len(infos[a]["children"])
            rng = np.random.default_rng(step)
            actions = {a: int(rng.choice(np.flatnonzero(obs[a]["action_mask"]))) for a in env.agents}
            obs, rewards, terminated, truncated, infos = env.step(actions)
            assert all(isinstance(r, float) and np.isfinite(r) for r in rewards.values())
            assert not any(terminated.values())
            assert all(truncated.values()) == (step == STEPS - 1)
            if step < STEPS - 1:  # the children's actions of the step before are the ones just taken
                for a in env.agents:
                    assert infos[a]["children_actions"] == [actions[c] for c in infos[a]["children"]]
        assert env.agents == []
    finally:
        env.close()


def test_a_compound_agent_is_no_env_agent_but_its_part_runs() -> None:
    """grasp3's hand has no joint: no env agent, but its head pays each finger its own reward, which every joint of
    that finger gets, and the gym face the mean of."""
    par = parallel_env(example("grasp3"), steps=5)
    env = gym_env(example("grasp3"), steps=5)
    try:
        assert "hand" not in par.possible_agents and len(par.possible_agents) == 12
        par.reset(seed=0)
        env.reset(seed=0)
        for t in range(5):
            actions = {a: (t + i) % 3 for i, a in enumerate(par.agents)}
            _, rewards, *_ = par.step(actions)
            _, r, *_ = env.step(np.array(list(actions.values())))
            paid = {c: given[1] for c, given in par.stepper.begun["hand"].children.items()}
            for a in par.possible_agents:
                assert rewards[a] == paid[f"{a[:2]}_1"]
            assert r == pytest.approx(sum(paid.values()) / 3)
        assert len(set(paid.values())) > 1  # the fingers are paid apart
    finally:
        par.close()
        env.close()


# -- the env and the swarm agree ---------------------------------------------------------------------------------------
def _observe(learner: JointLearner, acts: list[int], step: int) -> None:
    if all(0 <= b < learner.n_actions for b in acts):
        learner.observe(acts)
    else:
        learner.resync(step)


def drive(env: KinswarmParallelEnv, epochs: int) -> list[float]:
    """The paper's learners on the env, as the inprocess placement calls them: the children's actions of the step
    before, then the decision on S_i as built (infos' "state": float64, which the learner clips itself; the
    observation is its float32 copy) and the reward; after the last move, the children's last actions."""
    learners = env.stepper.learners()
    finals = []
    for epoch in range(epochs):
        obs, infos = env.reset()
        for learner in learners.values():
            learner.start_epoch(epoch, t=0)
        rewards: dict[str, float | None] = dict.fromkeys(learners, None)
        while env.agents:
            actions = {}
            for a, learner in learners.items():
                info = infos[a]
                if info["children"] and info["step"] > 0:
                    _observe(learner, info["children_actions"], info["step"])
                avoid = [b for b in range(3) if not obs[a]["action_mask"][b]]
                actions[a] = learner.decide(info["state"], rewards[a], avoid=avoid)  # S_i as built, float64
                if not info["children"]:
                    learner.observe([])
            obs, rewards, _, _, infos = env.step(actions)  # type: ignore[assignment]
        for a, learner in learners.items():
            if infos[a]["children"]:
                _observe(learner, infos[a]["children_actions"], env.stepper.steps)
        finals.append(next(iter(infos.values()))["error"])
    return finals


@pytest.mark.parametrize("name", ["chain4", "tree5", "grasp3"])
def test_the_papers_learners_on_the_env_give_the_inprocess_runs_final_errors(name: str, tmp_path: Path) -> None:
    epochs, steps = 2, 100
    cfg = load_run(
        example(name), [f"run.epochs={epochs}", f"run.steps={steps}", "run.placement=inprocess"], out=tmp_path
    )
    run = InProcessRun(cfg, cfg.topo())
    try:
        expected = [run.epoch(e, lambda *event: None).final_error for e in range(epochs)]
    finally:
        run.close()
    env = parallel_env(example(name), epochs=epochs, steps=steps)
    try:
        got = drive(env, epochs)
    finally:
        env.close()
    assert got == expected  # to the bit
    assert len(set(got)) == epochs  # the learners moved the robot: the epochs ended apart


# -- goals, faults, seeding, rendering ------------------------------------------------------------------------------
def test_goals_follow_the_task_per_episode_or_the_reset_option() -> None:
    env = gym_env(example("chain4"), steps=3, sets=["task.goals=[[4.0, 6.0], [-5.0, 5.0]]"], draw=False)
    try:
        goals = [tuple(env.reset()[0][-2:]) for _ in range(3)]
        assert goals == [(4.0, 6.0), (-5.0, 5.0), (4.0, 6.0)]  # episode k: the task's goal of epoch k
        assert tuple(env.reset(seed=5)[0][-2:]) == (4.0, 6.0)  # draw=False: a seeded reset restarts the schedule
        obs, info = env.reset(options={"goal": [1.0, 8.0]})
        assert tuple(obs[-2:]) == (1.0, 8.0)
        assert info["error"] == pytest.approx(float(np.hypot(obs[4] - 1.0, obs[5] - 8.0)), abs=1e-5)
    finally:
        env.close()


def _moved(env: gymnasium.Env, action: list[int]) -> np.ndarray:
    before = env.unwrapped.stepper.robot.world.joint_positions()
    env.step(np.array(action))
    after = env.unwrapped.stepper.robot.world.joint_positions()
    return np.array([after[a] - before[a] for a in env.unwrapped.stepper.dof])


def test_model_faults_at_reset_and_live() -> None:
    env = gym_env(example("chain4"), steps=10)
    try:
        env.reset(seed=0)
        one = env.unwrapped.stepper.cfg.action_rad
        assert _moved(env, [2, 2, 2, 2]) == pytest.approx([one] * 4)
        env.reset(
            options={"faults": [{"fault": "reverse", "targets": ["a2"]}, Fault("x", "lock", ["a4"], *[None] * 5)]}
        )
        assert _moved(env, [2, 2, 2, 2]) == pytest.approx([one, -one, one, 0.0])
        env.apply_fault("scale", "a1", factor=0.5)
        assert _moved(env, [2, 2, 2, 2]) == pytest.approx([one / 2, -one, one, 0.0])
        q_true = env.unwrapped.stepper.robot.world.joint_positions()["a3"]
        env.apply_fault("offset", "a3", degrees=10.0)
        assert env.unwrapped.stepper.robot.readings()["a3"] == pytest.approx(q_true + np.radians(10.0))
        env.reset(options={"faults": []})  # the joints freed
        assert _moved(env, [0, 0, 0, 0]) == pytest.approx([-one] * 4)
        env.reset()  # no faults option: the faults persist, as between a run's epochs
        env.apply_fault("deadzone", "all", degrees=2.0)
        assert _moved(env, [2, 2, 2, 2]) == pytest.approx([0.0] * 4)
    finally:
        env.close()


def test_continuous_actions_are_shares_of_one_move() -> None:
    env = gym_env(example("chain4"), steps=5, continuous=True)
    try:
        env.reset(seed=0)
        one = env.unwrapped.stepper.cfg.action_rad
        assert _moved(env, [1.0, -0.5, 0.0, 0.25]) == pytest.approx([one, -one / 2, 0.0, one / 4])
    finally:
        env.close()


def test_the_gym_reward_is_the_roots_and_the_episode_truncates() -> None:
    env = gym_env(example("chain4"), steps=3)
    par = parallel_env(example("chain4"), steps=3)
    try:
        env.reset(seed=0)
        par.reset(seed=0)
        for t in range(3):
            _, r, terminated, truncated, _ = env.step(np.array([2, 2, 2, 2]))
            _, rewards, *_ = par.step(dict.fromkeys(par.agents, 2))
            assert r == rewards["a1"] and not terminated and truncated == (t == 2)  # reach: no local terms
        with pytest.raises(RuntimeError, match="call reset"):
            env.step(np.array([1, 1, 1, 1]))
    finally:
        env.close()
        par.close()


def test_seeded_disturbances_replay() -> None:
    def run(seed: int) -> list[float]:
        env = gym_env(example("chain4"), steps=5)
        try:
            env.reset(seed=seed, options={"faults": [{"fault": "disturb", "targets": ["a1"], "steps": 5}]})
            return [float(env.step(np.array([1, 1, 1, 1]))[0][0]) for _ in range(5)]
        finally:
            env.close()

    assert run(3) == run(3) != run(4)


def test_gymnasium_make_and_render() -> None:
    env = gymnasium.make(ENV_ID, run_file=example("chain4"), steps=4)
    try:
        env.reset(seed=0)
        frame = env.render()
        assert frame.dtype == np.uint8 and frame.ndim == 3 and frame.shape[2] == 3
        assert len(np.unique(frame.reshape(-1, 3), axis=0)) > 2  # the arm and the goal drawn on white
    finally:
        env.close()
    par = parallel_env(example("iiwa"), steps=4)
    try:
        par.reset(seed=0)
        assert par.render().shape[2] == 3
    finally:
        par.close()


# -- bad input, one line -----------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: parallel_env("no/such.toml"), "no/such.toml: no such run file"),
        (lambda: gym_env(example("chain4"), steps="many"), "steps='many'"),
        (lambda: gym_env(example("chain4"), stepz=3), "stepz"),
        (lambda: parallel_env(example("chain4"), learner__gamma=7.0), "learner__gamma=7.0"),
        (lambda: gym_env(example("chain4"), task__goal=[90.0, 0.0]), "beyond its reach"),
        (lambda: gym_env(example("chain4"), fleet=2), "fleet"),
    ],
)
def test_bad_construction_is_one_line(call, message: str) -> None:
    with pytest.raises(ValueError) as e:
        call()
    assert message in str(e.value) and "\n" not in str(e.value)


def test_bad_reset_options_and_faults_are_one_line() -> None:
    env = parallel_env(example("chain4"), steps=3)
    try:
        for options, message in [
            ({"goal": [1.0]}, "goal: expected 2 finite numbers"),
            ({"faults": [{"fault": "kill", "targets": ["a1"]}]}, "the env applies the robot's joint faults"),
            ({"faults": [{"fault": "lock", "targets": ["a9"]}]}, "'a9' is not an agent"),
            ({"faults": [{"fault": "scale", "targets": ["a1"]}]}, "scale: needs factor"),
            ({"faults": "reverse"}, "reverse: no target given"),
        ]:
            with pytest.raises(ValueError) as e:
                env.reset(options=options)
            assert message in str(e.value) and "\n" not in str(e.value), str(e.value)
        env.reset()
        with pytest.raises(ValueError, match="must be 0, 1 or 2"):
            env.step({"a1": 3})
        with pytest.raises(ValueError, match="not an agent"):
            env.step({"hand": 1})
    finally:
        env.close()
