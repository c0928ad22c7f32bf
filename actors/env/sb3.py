"""parallel_env's agents as the rows of a Stable-Baselines3 vector env: one policy shared by every joint (independent
learners with parameter sharing), over one or several copies of the robot, episodes ending in truncation as SB3
expects them (`TimeLimit.truncated`, the terminal observation), so PPO bootstraps the value at an episode's cut.

    from kinswarm.env import parallel_env
    from kinswarm.env.sb3 import JointsVecEnv

    venv = JointsVecEnv([parallel_env("examples/iiwa.toml", render_mode=None) for _ in range(2)])
    venv.seed(0)  # copy c resets with seed 0 + c: its own goals
    PPO("MlpPolicy", venv).learn(10_000)

A row is one agent of one copy: its observation (float32, as parallel_env gives it) padded with zeros to the largest
agent's, then (one_hot=True) a one-hot of the agent's index in `possible_agents`, so the shared policy can tell the
joints apart. The Box is each column's widest bounds over the agents: the iiwa's joints, each with its own S_i
bounds, share one space. Every agent's action space must be the same (the shared policy has one). `action_masks()`
gives each row's mask (sb3-contrib's MaskablePPO takes it). Needs Stable-Baselines3 (not a dependency of kinswarm).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces

try:
    from stable_baselines3.common.vec_env.base_vec_env import VecEnv
except ImportError as e:  # one line that says what to install
    what = f"kinswarm.env.sb3 needs Stable-Baselines3 ({e.name} is missing): docs/env.md"
    raise ImportError(what, name=e.name) from None

from .parallel import KinswarmParallelEnv

Options = Callable[[int], Mapping[str, Any] | None]


class JointsVecEnv(VecEnv):
    """`envs`: one parallel env or several copies of one (the same robot and agents). `options(c)`: the reset
    options of copy c's next episode (a goal, faults), called at each of its resets; None: none."""

    def __init__(
        self,
        envs: KinswarmParallelEnv | Sequence[KinswarmParallelEnv],
        options: Options | None = None,
        one_hot: bool = True,
    ) -> None:
        self.envs = [envs] if isinstance(envs, KinswarmParallelEnv) else list(envs)
        if not self.envs:
            raise ValueError("JointsVecEnv: no env given")
        first = self.envs[0]
        self.agents = list(first.possible_agents)
        if any(list(e.possible_agents) != self.agents for e in self.envs):
            raise ValueError("JointsVecEnv: the copies' agents differ; give copies of one env")
        self.n = len(self.agents)  # rows per copy
        acts = [first.action_space(a) for a in self.agents]
        if any(s != acts[0] for s in acts):
            raise ValueError("JointsVecEnv: the agents' action spaces differ; one shared policy needs one")
        boxes = [first.observation_space(a)["observation"] for a in self.agents]
        self.obs_dim = max(b.shape[0] for b in boxes)
        lo = np.full((self.n, self.obs_dim), np.inf)
        hi = np.full((self.n, self.obs_dim), -np.inf)
        for i, b in enumerate(boxes):
            lo[i, : b.shape[0]], hi[i, : b.shape[0]] = b.low, b.high
            lo[i, b.shape[0] :] = hi[i, b.shape[0] :] = 0.0  # the padding
        width = self.obs_dim + (self.n if one_hot else 0)
        low = np.concatenate([lo.min(0), np.zeros(width - self.obs_dim)]).astype(np.float32)
        high = np.concatenate([hi.max(0), np.ones(width - self.obs_dim)]).astype(np.float32)
        self.one_hot, self.options, self.render_mode = one_hot, options, None
        super().__init__(self.n * len(self.envs), spaces.Box(low, high, dtype=np.float32), acts[0])
        self._actions: np.ndarray = np.zeros((self.num_envs, *acts[0].shape))
        self._masks = np.ones((self.num_envs, first.observation_space(self.agents[0])["action_mask"].shape[0]), bool)
        self.final_errors: list[float] = []  # the task's error at each episode's end, copies in the order they ended

    # -- the rows ------------------------------------------------------------------------------------------------
    def _rows(self, c: int, obs: Mapping[str, Mapping[str, np.ndarray]]) -> np.ndarray:
        out = np.zeros((self.n, self.observation_space.shape[0]), dtype=np.float32)
        for i, a in enumerate(self.agents):
            s = obs[a]["observation"]
            out[i, : s.shape[0]] = s
            if self.one_hot:
                out[i, self.obs_dim + i] = 1.0
            self._masks[c * self.n + i] = obs[a]["action_mask"].astype(bool)
        return out

    def _reset_copy(self, c: int, seed: int | None) -> np.ndarray:
        options = self.options(c) if self.options is not None else None
        obs, _ = self.envs[c].reset(seed=seed, options=options)
        return self._rows(c, obs)

    def reset(self) -> np.ndarray:
        seeds = getattr(self, "_seeds", [None] * self.num_envs)  # VecEnv.seed(s): row k gets s + k; copy c s + c
        out = [self._reset_copy(c, seeds[c]) for c in range(len(self.envs))]
        self._reset_seeds()
        self._reset_options()
        return np.concatenate(out)

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions).reshape(self.num_envs, *self.action_space.shape)

    def step_wait(self) -> Any:
        all_obs, rewards, dones, infos = [], [], [], []
        for c, env in enumerate(self.envs):
            rows = self._actions[c * self.n : (c + 1) * self.n]
            chosen = {a: _action(rows[i]) for i, a in enumerate(self.agents)}
            obs, rew, term, trunc, info = env.step(chosen)
            stacked = self._rows(c, obs)
            over = not env.agents
            copy_infos: list[dict[str, Any]] = [{"error": info[a]["error"]} for a in self.agents]
            if over:
                self.final_errors.append(float(info[self.agents[0]]["error"]))
                truncated = any(trunc.values()) and not any(term.values())
                for i, d in enumerate(copy_infos):
                    d["terminal_observation"] = stacked[i]
                    d["TimeLimit.truncated"] = truncated  # a cut, not an end: SB3 bootstraps the value here
                stacked = self._reset_copy(c, None)
            all_obs.append(stacked)
            rewards.append(np.array([rew[a] for a in self.agents], dtype=np.float32))
            dones.append(np.full(self.n, over))
            infos += copy_infos
        return np.concatenate(all_obs), np.concatenate(rewards), np.concatenate(dones), infos

    def action_masks(self) -> np.ndarray:
        """Each row's mask now (rows x 3 for Discrete actions): the moves its joint's task allows."""
        return self._masks.copy()

    def close(self) -> None:
        for env in self.envs:
            env.close()

    # -- SB3's VecEnv plumbing ---------------------------------------------------------------------------------------
    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self, attr_name)] * len(self._indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self, attr_name, value)

    def env_method(self, method_name: str, *args: Any, indices: Any = None, **kwargs: Any) -> list[Any]:
        rows = self._indices(indices)
        if method_name == "action_masks":  # per row, as sb3-contrib's get_action_masks asks each env for its own
            return [self._masks[k].copy() for k in rows]
        return [getattr(self, method_name)(*args, **kwargs)] * len(rows)

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        return [False] * len(self._indices(indices))

    def _indices(self, indices: Any) -> list[int]:
        if indices is None:
            return list(range(self.num_envs))
        return [indices] if isinstance(indices, int) else list(indices)


def _action(row: np.ndarray) -> Any:
    """A row's action as parallel_env takes it: an int for Discrete, the array otherwise."""
    return int(row) if row.shape == () else row
