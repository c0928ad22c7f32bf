"""The deep-RL peers on kinswarm.env: Stable-Baselines3's SAC and PPO on the whole robot (gym_env), PPO with one
policy shared by every joint (parallel_env, each joint a row of a vector env), their evaluation on test goals
(frozen, from the start pose), their learning curves, and the shared policy's export to ONNX."""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium
import numpy as np
import torch
from kinswarm.env import gym_env, parallel_env
from kinswarm.env.sb3 import JointsVecEnv
from stable_baselines3 import PPO, SAC
from stable_baselines3.common.callbacks import BaseCallback

# the generalisation recipe's robot, task and reward (graded)
RUN_FILE = str(Path(__file__).resolve().parents[2] / "examples" / "reach-generalise.toml")
Goal = tuple[float, float]
Faults = list[dict[str, Any]]


def _goals_text(goals: Sequence[Goal]) -> str:
    return "task.goals=[" + ", ".join(f"[{x!r}, {y!r}]" for x, y in goals) + "]"


# -- the whole robot, one agent ------------------------------------------------------------------------------------
def central_env(goals: Sequence[Goal], steps: int, continuous: bool, seed: int) -> gymnasium.Env:
    """gym_env on the training goals, one per episode in the given order (the task's goal list cycles; draw=False:
    SB3's seeded reset does not draw others)."""
    return gym_env(
        RUN_FILE, continuous=continuous, steps=steps, seed=seed, sets=[_goals_text(goals)], render_mode=None, draw=False
    )


class GoalsEnv(gymnasium.Wrapper):
    """Each reset the next goal of a list, with the given faults from the first step (the joints freed first) of
    episode `faults_from` on (the live sequence: at a goal intact, then the fault); records each episode's final
    error. What a policy learning online meets: one episode per goal."""

    def __init__(self, env: gymnasium.Env, goals: Sequence[Goal], faults: Faults, faults_from: int = 0) -> None:
        super().__init__(env)
        self.options = GoalsOptions(goals, faults, faults_from)
        self.final_errors: list[float] = []

    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
        return self.env.reset(seed=seed, options=self.options(0))

    def step(self, action: Any) -> Any:
        obs, r, term, trunc, info = self.env.step(action)
        if term or trunc:
            self.final_errors.append(float(info["error"]))
        return obs, r, term, trunc, info


# -- every joint, one shared policy ------------------------------------------------------------------------------
# parallel_env's joints as the rows of an SB3 vector env (kinswarm.env.sb3: S_i, then a one-hot of the agent's index)
class GoalsOptions:
    """The reset options of each episode: the next goal of a list (cycling), with the given faults from its first
    step (the joints freed first) from episode `faults_from` on, none before."""

    def __init__(self, goals: Sequence[Goal], faults: Faults, faults_from: int = 0) -> None:
        self.goals, self.faults, self.faults_from, self.i = list(goals), faults, faults_from, 0

    def __call__(self, copy: int) -> dict[str, Any]:
        goal = self.goals[self.i % len(self.goals)]
        faults = self.faults if self.i >= self.faults_from else []
        self.i += 1
        return {"goal": list(goal), "faults": faults}


def joints_env(goals: Sequence[Goal], steps: int, seed: int) -> JointsVecEnv:
    """The training goals in order, one per episode (the task's goal list; draw=False: a seed does not draw them)."""
    par = parallel_env(RUN_FILE, steps=steps, seed=seed, sets=[_goals_text(goals)], render_mode=None, draw=False)
    venv = JointsVecEnv(par)
    venv.seed(seed)
    return venv


def goals_env(
    goals: Sequence[Goal], steps: int, faults: Faults, sets: Sequence[str] = (), faults_from: int = 0
) -> JointsVecEnv:
    par = parallel_env(RUN_FILE, steps=steps, sets=list(sets), render_mode=None)
    return JointsVecEnv(par, options=GoalsOptions(goals, faults, faults_from))


def central_goals_env(
    method: str, goals: Sequence[Goal], steps: int, faults: Faults, sets: Sequence[str] = (), faults_from: int = 0
) -> GoalsEnv:
    env = gym_env(RUN_FILE, continuous=method == "sac", steps=steps, sets=list(sets), render_mode=None)
    return GoalsEnv(env, goals, faults, faults_from)


# the successive protocol: each episode from where the last ended; on the chain whose joints turn freely
# (examples/chain4-free.toml's limits, as the any-pose recipe's robot)
SUCCESSIVE = ("run.successive=true",)
FREE_JOINTS = ("robot.defaults.limits_deg=[-36000.0, 36000.0]",)


# -- evaluation -----------------------------------------------------------------------------------------------------
def evaluate(
    model: Any,
    method: str,
    goals: Sequence[Goal],
    steps: int,
    faults: Faults | None = None,
    sets: Sequence[str] = (),
    faults_from: int = 0,
) -> list[float]:
    """Final errors of the frozen, deterministic policy, one `steps`-step episode per goal from the start pose (with
    SUCCESSIVE in `sets`: from where the last ended); the faults from episode `faults_from` on."""
    faults = faults or []
    if method == "ppo-shared":
        env: Any = goals_env(goals, steps, faults, sets, faults_from)
    else:
        env = central_goals_env(method, goals, steps, faults, sets, faults_from)
    return episodes(model, method, env, len(goals))


def episodes(model: Any, method: str, env: Any, n: int) -> list[float]:
    """Final errors of n episodes of the frozen, deterministic policy in an env whose resets choose each episode's
    goal and start (the shared policy: a JointsVecEnv; a central one: a Gymnasium env, its info["error"] at each
    episode's end); the env closed after."""
    if method == "ppo-shared":
        obs = env.reset()
        while len(env.final_errors) < n:
            actions, _ = model.predict(obs, deterministic=True)
            env.step_async(actions)
            obs, *_ = env.step_wait()
        env.close()
        return env.final_errors[:n]
    errors = []
    for _ in range(n):
        obs, _ = env.reset()
        over = False
        while not over:
            action, _ = model.predict(obs, deterministic=True)
            obs, _, term, trunc, info = env.step(action)
            over = term or trunc
        errors.append(float(info["error"]))
    env.close()
    return errors


def within(errors: Sequence[float], tol: float = 0.5) -> float:
    return float(np.mean(np.asarray(errors) <= tol)) if len(errors) else 0.0


@dataclass
class Curve:
    """Test-set results over training: env steps, training CPU-seconds (evaluation excluded), share within 0.5."""

    env_steps: list[int] = field(default_factory=list)
    cpu_seconds: list[float] = field(default_factory=list)
    within: list[float] = field(default_factory=list)
    mean: list[float] = field(default_factory=list)

    def first(self, bar: float) -> tuple[int, float] | None:
        for s, c, w in zip(self.env_steps, self.cpu_seconds, self.within, strict=True):
            if w >= bar:
                return s, c
        return None


class CurveCallback(BaseCallback):
    """Every `every` env steps: the frozen policy on the test goals (its CPU time not counted as training)."""

    def __init__(self, method: str, per_step: int, every: int, check: Callable[[Any], list[float]]) -> None:
        super().__init__()
        self.method, self.per_step, self.every, self.check = method, per_step, every, check
        self.curve, self.next, self.eval_cpu, self.cpu0 = Curve(), every, 0.0, time.process_time()

    def _on_step(self) -> bool:
        env_steps = self.num_timesteps // self.per_step
        if env_steps >= self.next:
            self.next += self.every
            c0 = time.process_time()
            trained_cpu = c0 - self.cpu0 - self.eval_cpu
            errors = self.check(self.model)
            self.eval_cpu += time.process_time() - c0
            self.curve.env_steps.append(env_steps)
            self.curve.cpu_seconds.append(round(trained_cpu, 1))
            self.curve.within.append(within(errors))
            self.curve.mean.append(float(np.mean(errors)))
        return True


def train(
    method: str,
    goals: Sequence[Goal],
    steps: int,
    budget: int,
    seed: int,
    every: int,
    check_goals: Sequence[Goal],
    quick: bool = False,
    hp: dict[str, Any] | None = None,
) -> tuple[Any, Curve, float]:
    """One peer trained for `budget` env steps on the training goals (`hp` over the library's defaults); its curve on
    `check_goals` (200-step episodes); the CPU-seconds of training alone."""
    if method == "ppo-shared":
        env: Any = joints_env(goals, steps, seed)
        per_step = env.n
    else:
        env = central_env(goals, steps, method == "sac", seed)
        per_step = 1
    model = new_model(method, env, seed, quick, hp)

    def check(m: Any) -> list[float]:
        return evaluate(m, method, check_goals, 20 if quick else 200)

    errors = check(model)  # the untrained policy: the curve's point at 0 (as the curves study's)
    cb = CurveCallback(method, per_step, every, check)
    c0 = time.process_time()
    model.learn(total_timesteps=budget * per_step, callback=cb)
    cpu = time.process_time() - c0 - cb.eval_cpu
    env.close()
    c = cb.curve
    curve = Curve(
        [0, *c.env_steps], [0.0, *c.cpu_seconds], [within(errors), *c.within], [float(np.mean(errors)), *c.mean]
    )
    return model, curve, cpu


def new_model(method: str, env: Any, seed: int, quick: bool = False, hp: dict[str, Any] | None = None) -> Any:
    """A peer with library defaults, `hp` over them (the tuning sweep); the quick version: a 64-step rollout, seconds
    rather than a 2,048-step one."""
    torch.set_num_threads(1)  # two shared cores: one for us
    if method == "sac":  # sbx (SB3's JAX port) when installed: measured ~1.7x SB3's env steps per CPU-second here
        small = {"learning_starts": 64} if quick else {}
        return sac_class()("MlpPolicy", env, seed=seed, verbose=0, **{**small, **(hp or {})})
    small = {"n_steps": 64, "batch_size": 32} if quick else {}
    return PPO("MlpPolicy", env, seed=seed, verbose=0, device="cpu", **{**small, **(hp or {})})


def sac_class() -> Any:
    try:
        from sbx import SAC as SBX_SAC

        return SBX_SAC
    except ImportError:
        return SAC


def load(method: str, path: Path) -> Any:
    """A trained peer as saved (SB3's zip): a fresh copy for each condition that learns on."""
    torch.set_num_threads(1)
    cls = sac_class() if method == "sac" else PPO
    return cls.load(str(path), device="cpu") if cls is PPO else cls.load(str(path))


def online(
    model: Any,
    method: str,
    goals: Sequence[Goal],
    steps: int,
    faults: Faults,
    sets: Sequence[str] = (),
    faults_from: int = 0,
) -> list[float]:
    """The trained policy learning on (SB3's `learn`, its stochastic policy acting): one `steps`-step episode per
    goal, the faults unknown to it, its learning carried from goal to goal (as adapt's 'trained, learning'). Final
    errors per goal. PPO learns once a rollout is full (2,048 steps per row): it runs on past the last goal to its
    rollout's end, the goals cycling; the errors are the goals' first pass."""
    if method == "ppo-shared":
        venv: Any = goals_env(goals, steps, faults, sets, faults_from)
        per_step = venv.n
    else:
        venv = central_goals_env(method, goals, steps, faults, sets, faults_from)
        per_step = 1
    model.set_env(venv)
    model.learn(total_timesteps=len(goals) * steps * per_step, reset_num_timesteps=False)
    venv.close()
    return venv.final_errors[: len(goals)]


# -- export ---------------------------------------------------------------------------------------------------------
class SharedScores(torch.nn.Module):
    """The shared per-joint policy as one ONNX graph: inputs `obs` (float32, (1, obs_dim): the agent's observation as
    parallel_env gives it) and `agent` (int64, (1,): its index in parallel_env's agents); output `scores` (float32,
    (1, 3): the action logits over −, 0, +; the caller masks with action_mask and takes the argmax)."""

    def __init__(self, policy: Any, n_agents: int) -> None:
        super().__init__()
        self.policy = policy
        self.register_buffer("eye", torch.eye(n_agents, dtype=torch.float32))

    def forward(self, obs: torch.Tensor, agent: torch.Tensor) -> torch.Tensor:
        x = torch.cat([obs, self.eye[agent]], dim=1)
        latent, _ = self.policy.mlp_extractor(self.policy.extract_features(x, self.policy.pi_features_extractor))
        return self.policy.action_net(latent)


def export_onnx(model: Any, n_agents: int, obs_dim: int, path: Path) -> Path:
    module = SharedScores(model.policy, n_agents).eval()
    path.parent.mkdir(parents=True, exist_ok=True)
    with torch.no_grad():
        torch.onnx.export(
            module,
            (torch.zeros(1, obs_dim), torch.zeros(1, dtype=torch.int64)),
            str(path),
            input_names=["obs", "agent"],
            output_names=["scores"],
            dynamo=False,
        )
    return path


def check_onnx(model: Any, path: Path, goals: Sequence[Goal], steps: int) -> dict[str, Any]:
    """The exported file against the torch policy in parallel_env: every joint's action at every step of one
    episode per goal, the torch policy acting. onnxruntime if installed, else not checked."""
    try:
        import onnxruntime as ort
    except ImportError:
        return {"checked": False, "why": "onnxruntime is not installed"}
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    venv = goals_env(goals, steps, [])
    obs, same, total = venv.reset(), 0, 0
    while len(venv.final_errors) < len(goals):
        actions, _ = model.predict(obs, deterministic=True)
        for i in range(venv.n):
            (scores,) = sess.run(None, {"obs": obs[i : i + 1, : venv.obs_dim], "agent": np.array([i], np.int64)})
            same += int(np.argmax(scores[0]) == actions[i])
            total += 1
        venv.step_async(actions)
        obs, *_ = venv.step_wait()
    venv.close()
    return {"checked": True, "decisions": total, "same": same}
