"""The robot as a PettingZoo `ParallelEnv`: one agent per joint, all acting at once, each seeing what its agent sees
in the swarm.

  agents         the DOF agents, in the robot's order (a compound agent with no joint is none, but its part of the
                 step runs: the grasp agent still gives each finger its goal and reward)
  observation    {"observation": S_i, "action_mask": int8[3]}: S_i = the agent's state (the state kind's variables,
                 the task's, the run's extra ones) clipped to the bounds its observation declares, as the paper's
                 learners clip it; the raw S_i is in infos["state"]. The mask is 0 for the moves the task leaves out
                 of this step (AgentTask.avoid); a masked move given anyway is carried out (the world still bounds it)
  action         Discrete(3): one move down, none, one up (the run's action size, times the task's scale)
  reward         what its task gives it: the root's reward of the move with the agent's local terms. In the swarm
                 r(t-1) arrives at the start of step t; here step(a_t) moves and returns the reward of that move
                 (core.py). 0.0 where the task gives none
  infos          "state" (S_i unclipped), "children" (its visible children, the paper's neighbourhood) and
                 "children_actions" (their actions of the step before, -1 at an episode's first step: what a
                 joint-action learner counts), "scale", "step", "error" (the task's distance after the last move)
  episodes       the run's `steps` moves, ending in truncation; never terminated

reset(seed=, options=): `seed` restarts the task's goal schedule (episode k has the goal of the run's epoch k) and
seeds the robot's disturbances; options "goal" (this episode's goal instead of the task's) and "faults" (joint faults
from its first step, the joints freed first; Fault objects or mappings {"fault", "targets", ...}). `apply_fault`
injects one at any step, as `kinswarm fault` does in a live run.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from kinswarm.protocol.messages import Fault
from pettingzoo import ParallelEnv

from .core import N_ACTIONS, Event, Stepper, load_config
from .faults import as_fault, reset_options


class KinswarmParallelEnv(ParallelEnv):
    metadata = {"name": "kinswarm_v0", "render_modes": ["rgb_array"], "is_parallelizable": True, "render_fps": 10}

    def __init__(self, stepper: Stepper, render_mode: str | None = "rgb_array") -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: {render_mode!r} is not one of None, 'rgb_array'")
        self.stepper = stepper
        self.render_mode = render_mode
        self.possible_agents: list[str] = list(stepper.dof)
        self.agents: list[str] = []
        self._obs_spaces = {}
        for a in self.possible_agents:
            lo, hi = zip(*stepper.settings[a].observation.bounds, strict=True)
            box = spaces.Box(np.array(lo), np.array(hi), dtype=np.float64)
            mask = spaces.Box(0, 1, shape=(N_ACTIONS,), dtype=np.int8)
            self._obs_spaces[a] = spaces.Dict({"observation": box, "action_mask": mask})
        self._act_spaces = {a: spaces.Discrete(N_ACTIONS) for a in self.possible_agents}
        self._lows = {a: s["observation"].low for a, s in self._obs_spaces.items()}
        self._highs = {a: s["observation"].high for a, s in self._obs_spaces.items()}

    @functools.cache  # noqa: B019 - PettingZoo asks for the same object at every call; the env lives as long
    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_spaces[agent]

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Space:
        return self._act_spaces[agent]

    @property
    def events(self) -> list[Event]:
        """The robot's events of the last reset or step: (episode, step, event, target, detail)."""
        return self.stepper.events

    def reset(
        self, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, dict[str, Any]]]:
        self.stepper.start(seed, *reset_options(options))
        self.agents = list(self.possible_agents)
        return self._observations(), self._infos()

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        if not self.agents:
            raise RuntimeError("step: the episode is over (every agent truncated); call reset()")
        chosen = {}
        for a, v in actions.items():
            if a not in self._act_spaces:
                raise ValueError(f"step: {a!r} is not an agent of this env ({', '.join(self.possible_agents)})")
            if not self._act_spaces[a].contains(v):
                raise ValueError(f"step: {a}'s action must be 0, 1 or 2, got {v!r}")
            chosen[a] = int(v)
        self.stepper.act(chosen)
        over = self.stepper.t >= self.stepper.steps
        agents = list(self.agents)
        obs, infos = self._observations(), self._infos()
        rewards = {a: _reward(self.stepper.decisions[a].reward) for a in agents}
        terminated = dict.fromkeys(agents, False)
        truncated = dict.fromkeys(agents, over)
        if over:
            self.agents = []
        return obs, rewards, terminated, truncated, infos

    def apply_fault(self, fault: Fault | Mapping[str, Any] | str, *targets: str, **params: Any) -> list[Event]:
        """A joint fault now, from this step's moves: a Fault, a mapping, or its name with the targets and sizes
        (`apply_fault("reverse", "a2")`, `apply_fault("offset", "a3", degrees=10)`). Returns its events."""
        return self.stepper.apply(as_fault(fault, targets, params))

    def render(self) -> np.ndarray:
        return self.stepper.frame()

    def close(self) -> None:
        self.stepper.close()

    def _observations(self) -> dict[str, dict[str, np.ndarray]]:
        out = {}
        for a in self.possible_agents:
            d = self.stepper.decisions[a]
            mask = np.ones(N_ACTIONS, dtype=np.int8)
            for b in d.avoid:
                if 0 <= b < N_ACTIONS:
                    mask[b] = 0
            s = np.clip(np.asarray(d.state, dtype=np.float64), self._lows[a], self._highs[a])
            out[a] = {"observation": s, "action_mask": mask}
        return out

    def _infos(self) -> dict[str, dict[str, Any]]:
        st = self.stepper
        out = {}
        for a in self.possible_agents:
            visible = st.agents[a].visible
            d = st.decisions[a]
            out[a] = {
                "state": np.asarray(d.state, dtype=np.float64),
                "children": tuple(visible),
                "children_actions": [st.last.get(c, -1) for c in visible],
                "scale": d.scale,
                "step": st.t,
                "error": st.error,
            }
        return out


def _reward(r: float | None) -> float:
    return 0.0 if r is None else float(r)


def parallel_env(
    run_file: str, *, sets: Sequence[str] = (), render_mode: str | None = "rgb_array", **overrides: Any
) -> KinswarmParallelEnv:
    """The run file's robot and task as a PettingZoo ParallelEnv. `overrides`: [run] fields by name (`steps=100`,
    `seed=3`), other sections' as `section__field` (`task__goal=[4, 6]`); `sets`: `--set` texts."""
    return KinswarmParallelEnv(Stepper(load_config(run_file, overrides, sets)), render_mode)
