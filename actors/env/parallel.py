"""The robot as a PettingZoo `ParallelEnv`: one agent per joint (or per group of joints), all acting at once, each
seeing what its agents see in the swarm.

  agents         the DOF agents, in the robot's order (a compound agent with no joint is none, but its part of the
                 step runs: the grasp agent still gives each finger its goal and reward). With `agents=[["a1", "a2"],
                 ["a3", "a4"]]` one agent per group instead, named "a1+a2", ...: every joint in exactly one group
  observation    {"observation": S_i, "action_mask": int8[3]}, float32: S_i = the agent's state (the state kind's
                 variables, the task's, the run's extra ones) clipped to the bounds its observation declares, as the
                 paper's learners clip it; the raw S_i is in infos["state"]. The mask is 0 for the moves the task
                 leaves out of this step (AgentTask.avoid); a masked move given anyway is carried out (the world still
                 bounds it). A group's: its joints' S_i one after the other, their masks likewise (int8[3 k])
  action         Discrete(3): one move down, none, one up (the run's action size, times the task's scale); a group's
                 MultiDiscrete([3] * k). continuous=True: Box(-1, 1, (k,)), that share of one move per joint
  reward         what its task gives it: the root's reward of the move with the agent's local terms (a group's: its
                 joints' mean). In the swarm r(t-1) arrives at the start of step t; here step(a_t) moves and returns
                 the reward of that move (core.py). 0.0 where the task gives none
  infos          "state" (S_i unclipped), "children" (its visible children, the paper's neighbourhood) and
                 "children_actions" (their actions of the step before, -1 at an episode's first step: what a
                 joint-action learner counts), "scale", "step", "error" (the task's distance after the last move);
                 with reward_terms=True "reward_terms": {"task": the reward as handed down to it, "local": its own
                 terms}. A group's: "state", "step", "error" and "joints", each joint's own infos
  state()        the whole robot as the Gymnasium face sees it (float32: readings, end-effector poses, goal),
                 `state_space` its Box; `state_slices()` where each joint's reading lies in it, `joint_index(a)` a
                 joint's place in the Gymnasium face's action
  episodes       the run's `steps` moves (`max_cycles`, PettingZoo's name, is the same), ending in truncation; with
                 `success`, every agent terminated once the task's error is within it

reset(seed=, options=): `seed` restarts the task's goal schedule, seeds the robot's disturbances and draws the goal
(of a reach task) and a random start (core.Stepper, draws.py; draw=False keeps the run's goals); options "goal" (this
episode's goal) and "faults" (joint faults from its first step, the joints freed first; Fault objects or mappings
{"fault", "targets", ...}). `apply_fault` injects one at any step, as `kinswarm fault` does in a live run. `close()`
releases the PyBullet world; a later `reset()` builds it again.
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from kinswarm.protocol.messages import Fault
from pettingzoo import AECEnv, ParallelEnv
from pettingzoo.utils.conversions import parallel_to_aec

from .core import N_ACTIONS, Event, Stepper, check_success, load_config
from .faults import as_fault, reset_options
from .render import FPS, RENDER_MODES, Renderer


class KinswarmParallelEnv(ParallelEnv):
    metadata = {"name": "kinswarm_v0", "render_modes": list(RENDER_MODES), "is_parallelizable": True, "render_fps": FPS}

    def __init__(
        self,
        stepper: Stepper,
        render_mode: str | None = "rgb_array",
        *,
        groups: Sequence[Sequence[str]] | None = None,
        continuous: bool = False,
        success: float | None = None,
        reward_terms: bool = False,
    ) -> None:
        self.renderer = Renderer(stepper.frame, render_mode)
        self.stepper = stepper
        self.render_mode = render_mode
        self.continuous, self.reward_terms = continuous, reward_terms
        self.success = check_success(success)
        self.groups = agent_groups(stepper.dof, groups)  # the env's agent -> its joints
        self.possible_agents: list[str] = list(self.groups)
        self.agents: list[str] = []
        self._obs_spaces = {}
        self._act_spaces: dict[str, spaces.Space] = {}
        self._lows, self._highs = {}, {}
        for a, joints in self.groups.items():
            bounds = [b for j in joints for b in stepper.settings[j].observation.bounds]
            lo, hi = (np.array(x, dtype=np.float64) for x in zip(*bounds, strict=True))
            box = spaces.Box(lo.astype(np.float32), hi.astype(np.float32), dtype=np.float32)
            mask = spaces.Box(0, 1, shape=(N_ACTIONS * len(joints),), dtype=np.int8)
            self._obs_spaces[a] = spaces.Dict({"observation": box, "action_mask": mask})
            self._lows[a], self._highs[a] = lo, hi
            if continuous:
                self._act_spaces[a] = spaces.Box(-1.0, 1.0, shape=(len(joints),), dtype=np.float32)
            elif len(joints) == 1:
                self._act_spaces[a] = spaces.Discrete(N_ACTIONS)
            else:
                self._act_spaces[a] = spaces.MultiDiscrete([N_ACTIONS] * len(joints))
        lo, hi = stepper.state_bounds()
        self.state_space = spaces.Box(lo, hi, dtype=np.float32)
        self._over = False

    @functools.cache  # noqa: B019 - PettingZoo asks for the same object at every call; the env lives as long
    def observation_space(self, agent: str) -> spaces.Space:
        return self._obs_spaces[agent]

    @functools.cache  # noqa: B019
    def action_space(self, agent: str) -> spaces.Space:
        return self._act_spaces[agent]

    def state(self) -> np.ndarray:
        """The whole robot now, as the Gymnasium face observes it: what a centralised critic trains on."""
        if not self.stepper.started:
            raise RuntimeError("state: no episode yet; call reset() first")
        return self.stepper.global_state()

    def state_slices(self) -> dict[str, slice]:
        """Where each part of `state()` lies: "<joint>" its reading, "<end effector>.tip" its pose, "goal"."""
        return self.stepper.state_slices()

    def joint_index(self, joint: str) -> int:
        """The joint's place in the Gymnasium face's action (and its reading's in `state()`): the robot's DOF
        order."""
        if joint not in self.stepper.dof:
            raise ValueError(f"joint_index: {joint!r} is not a joint of this robot ({', '.join(self.stepper.dof)})")
        return self.stepper.dof.index(joint)

    def joint_actions(self, actions: Mapping[str, Any]) -> np.ndarray:
        """The agents' actions as the Gymnasium face's one action (each joint at its `joint_index`)."""
        out = np.zeros(len(self.stepper.dof), dtype=np.float32 if self.continuous else np.int64)
        for a, v in actions.items():
            for j, x in zip(self.groups[a], np.atleast_1d(v), strict=True):
                out[self.joint_index(j)] = x
        return out

    @property
    def events(self) -> list[Event]:
        """The robot's events of the last reset or step: (episode, step, event, target, detail)."""
        return self.stepper.events

    def reset(
        self, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[dict[str, dict[str, np.ndarray]], dict[str, dict[str, Any]]]:
        self.stepper.start(seed, *reset_options(options))
        self.agents = list(self.possible_agents)
        self._over = False
        self.renderer.shown()
        return self._observations(), self._infos()

    def step(self, actions: Mapping[str, Any]) -> tuple[dict, dict, dict, dict, dict]:
        if self.stepper.closed:
            raise RuntimeError("step: the env is closed; reset() builds its world again")
        if not self.agents:
            raise RuntimeError("step: the episode is over (every agent truncated or terminated); call reset()")
        chosen: dict[str, int | float] = {}
        for a, v in actions.items():
            if a not in self._act_spaces:
                raise ValueError(f"step: {a!r} is not an agent of this env ({', '.join(self.possible_agents)})")
            chosen.update(self._joint_moves(a, v))
        st = self.stepper
        st.act(chosen)
        over = st.t >= st.steps
        done = self.success is not None and st.error <= self.success
        agents = list(self.agents)
        obs, infos = self._observations(), self._infos()
        rewards = {a: float(np.mean([_reward(st.decisions[j].reward) for j in self.groups[a]])) for a in agents}
        terminated = dict.fromkeys(agents, done)
        truncated = dict.fromkeys(agents, over and not done)
        if over or done:
            self.agents = []
        self.renderer.shown()
        return obs, rewards, terminated, truncated, infos

    def _joint_moves(self, agent: str, v: Any) -> dict[str, int | float]:
        """An agent's action as its joints' moves; one line naming what is wrong otherwise."""
        joints, space = self.groups[agent], self._act_spaces[agent]
        if self.continuous:
            x = np.asarray(v, dtype=np.float64).reshape(-1) if _numeric(v) else None
            if x is None or x.shape != (len(joints),) or not np.all(np.isfinite(x)):
                raise ValueError(f"step: {agent}'s action must be {len(joints)} finite numbers in [-1, 1], got {v!r}")
            return {j: float(np.clip(x[i], -1.0, 1.0)) for i, j in enumerate(joints)}
        if not space.contains(v):
            what = "0, 1 or 2" if len(joints) == 1 else f"{len(joints)} actions, each 0, 1 or 2"
            raise ValueError(f"step: {agent}'s action must be {what}, got {v!r}")
        return {j: int(x) for j, x in zip(joints, np.atleast_1d(v), strict=True)}

    def apply_fault(self, fault: Fault | Mapping[str, Any] | str, *targets: str, **params: Any) -> list[Event]:
        """A joint fault now, from this step's moves: a Fault, a mapping, or its name with the targets and sizes
        (`apply_fault("reverse", "a2")`, `apply_fault("offset", "a3", degrees=10)`). Returns its events."""
        return self.stepper.apply(as_fault(fault, targets, params))

    def render(self) -> np.ndarray | None:
        return self.renderer.render()

    def close(self) -> None:
        """Release the PyBullet world and any window; a later `reset()` builds the world again (faults applied
        before are gone with it)."""
        self.stepper.close()
        self.renderer.close()
        self.agents = []

    def _observations(self) -> dict[str, dict[str, np.ndarray]]:
        out = {}
        decisions = self.stepper.decisions
        for a, joints in self.groups.items():
            mask = np.ones(N_ACTIONS * len(joints), dtype=np.int8)
            for i, j in enumerate(joints):
                for b in decisions[j].avoid:
                    if 0 <= b < N_ACTIONS:
                        mask[i * N_ACTIONS + b] = 0
            raw = np.concatenate([np.asarray(decisions[j].state, dtype=np.float64) for j in joints])
            s = np.clip(raw, self._lows[a], self._highs[a]).astype(np.float32)
            out[a] = {"observation": s, "action_mask": mask}
        return out

    def _joint_info(self, a: str) -> dict[str, Any]:
        st = self.stepper
        visible = st.agents[a].visible
        d = st.decisions[a]
        info = {
            "state": np.asarray(d.state, dtype=np.float64),
            "children": tuple(visible),
            "children_actions": [st.last.get(c, -1) for c in visible],
            "scale": d.scale,
            "step": st.t,
            "error": st.error,
        }
        if self.reward_terms:
            given = st.top[a].reward
            info["reward_terms"] = {
                "task": _reward(given),
                "local": _reward(d.reward) - _reward(given),
            }
        return info

    def _infos(self) -> dict[str, dict[str, Any]]:
        out = {}
        for a, joints in self.groups.items():
            if len(joints) == 1 and joints[0] == a:
                out[a] = self._joint_info(a)
                continue
            each = {j: self._joint_info(j) for j in joints}
            first = each[joints[0]]
            out[a] = {
                "state": np.concatenate([each[j]["state"] for j in joints]),
                "step": first["step"],
                "error": first["error"],
                "joints": each,
            }
        return out


def _reward(r: float | None) -> float:
    return 0.0 if r is None else float(r)


def _numeric(v: Any) -> bool:
    try:
        np.asarray(v, dtype=np.float64)
    except (TypeError, ValueError):
        return False
    return True


def agent_groups(joints: Sequence[str], groups: Sequence[Sequence[str]] | None) -> dict[str, list[str]]:
    """The env's agents: one per joint, or one per group of joints named by its joints ("a1+a2"). Every joint in
    exactly one group; one line naming what is wrong otherwise."""
    if groups is None:
        return {j: [j] for j in joints}
    if isinstance(groups, str) or not all(isinstance(g, (list, tuple)) and g for g in groups):
        raise ValueError(f'agents: expected groups of joints, e.g. [["a1", "a2"], ["a3"]], got {groups!r}')
    seen: list[str] = [j for g in groups for j in g]
    for j in seen:
        if j not in joints:
            raise ValueError(f"agents: {j!r} is not a joint of this robot ({', '.join(joints)})")
    twice = sorted({j for j in seen if seen.count(j) > 1})
    missing = [j for j in joints if j not in seen]
    if twice or missing:
        what = f"{', '.join(twice)} in more than one group" if twice else f"{', '.join(missing)} in none"
        raise ValueError(f"agents: every joint in exactly one group; {what}")
    return {"+".join(g): list(g) for g in groups}


def parallel_env(
    run_file: str,
    *,
    sets: Sequence[str] = (),
    render_mode: str | None = "rgb_array",
    max_cycles: int | None = None,
    draw: bool = True,
    agents: Sequence[Sequence[str]] | None = None,
    continuous: bool = False,
    success: float | None = None,
    reward_terms: bool = False,
    **overrides: Any,
) -> KinswarmParallelEnv:
    """The run file's robot and task as a PettingZoo ParallelEnv. `overrides`: [run] fields by name (`steps=100`,
    `seed=3`), other sections' as `section__field` (`task__goal=[4, 6]`); `sets`: `--set` texts; `max_cycles`:
    PettingZoo's name for `steps`. `draw=False`: every episode the run's goal and start, seed or not. `agents`:
    groups of joints as the agents; `continuous`: Box actions; `success`: terminate within this error;
    `reward_terms`: the reward's parts in infos (the module's docstring)."""
    if max_cycles is not None:
        if "steps" in overrides:
            raise ValueError("max_cycles: PettingZoo's name for steps; give one of them")
        overrides = {**overrides, "steps": max_cycles}
    stepper = Stepper(load_config(run_file, overrides, sets), draw)
    try:
        return KinswarmParallelEnv(
            stepper, render_mode, groups=agents, continuous=continuous, success=success, reward_terms=reward_terms
        )
    except BaseException:
        stepper.close()
        raise


def aec_env(run_file: str, **kwargs: Any) -> AECEnv:
    """The same env in PettingZoo's turn-based (AEC) API, which PettingZoo's render, state and max-cycles tests and
    AEC-only libraries take: `parallel_env(run_file, **kwargs)` through PettingZoo's own `parallel_to_aec`."""
    return parallel_to_aec(parallel_env(run_file, **kwargs))
