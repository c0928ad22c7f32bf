"""The whole robot as one Gymnasium agent: a central policy that sees every joint and moves them all at once.

  observation    float32: every joint's encoder reading (what the agents read: through the encoder faults), every
                 end effector's pose (a planar robot's x, y, heading; a spatial one's 7-float frame), the goal. Each
                 clipped to its bounds: a reading to its joint's limits widened by pi (an offset fault reads up to
                 180 degrees beside the angle), a position to the robot's base +- 2 reaches, a heading to +-pi, a
                 quaternion's part to +-1
  action         MultiDiscrete([3] * joints): per joint one move down, none, one up; or, with continuous=True, a Box
                 [-1, 1] per joint: that share of one move (the run's action size, times the task's scale)
  reward         the root's task reward of the move, the r the swarm's agents get (before their local terms); a
                 compound root that pays each child its own (grasp) gives their mean
  info           "error" (the task's distance), "step", "action_mask" (joints x 3, int8: the moves each joint's task
                 leaves out; advice, not enforced)

Episodes, goals, faults and seeding are the parallel env's (parallel.py): the run's `steps` moves ending in
truncation, reset(seed=, options={"goal", "faults"}), `apply_fault`. Registered as "kinswarm/Robot-v0":
`gymnasium.make("kinswarm/Robot-v0", run_file="examples/chain4.toml")` once kinswarm.env is imported.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from kinswarm.protocol.messages import Fault

from .core import N_ACTIONS, Event, Stepper, load_config
from .faults import as_fault, reset_options

ENV_ID = "kinswarm/Robot-v0"


class RobotEnv(gymnasium.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(self, stepper: Stepper, continuous: bool = False, render_mode: str | None = "rgb_array") -> None:
        if render_mode not in (None, "rgb_array"):
            raise ValueError(f"render_mode: {render_mode!r} is not one of None, 'rgb_array'")
        self.stepper, self.continuous, self.render_mode = stepper, continuous, render_mode
        topo, n = stepper.topo, len(stepper.dof)
        lo: list[float] = []
        hi: list[float] = []
        for a in stepper.dof:  # the readings
            j_lo, j_hi = topo.agents[a].limits
            lo.append(j_lo - math.pi)
            hi.append(j_hi + math.pi)
        r, base = 2.0 * topo.reach, topo.base
        position = [(base[i] - r, base[i] + r) for i in range(3 if topo.spatial else 2)]
        pose = position + ([(-1.0, 1.0)] * 4 if topo.spatial else [(-math.pi, math.pi)])
        for _ in topo.end_effectors:
            lo += [b[0] for b in pose]
            hi += [b[1] for b in pose]
        goal = position + [(-1.0, 1.0)] * (stepper.goal_length - len(position))
        lo += [b[0] for b in goal][: stepper.goal_length]
        hi += [b[1] for b in goal][: stepper.goal_length]
        self.observation_space = spaces.Box(np.array(lo, np.float32), np.array(hi, np.float32), dtype=np.float32)
        self._lo, self._hi = (
            self.observation_space.low.astype(np.float64),
            self.observation_space.high.astype(np.float64),
        )
        if continuous:
            self.action_space: spaces.Space = spaces.Box(-1.0, 1.0, shape=(n,), dtype=np.float32)
        else:
            self.action_space = spaces.MultiDiscrete([N_ACTIONS] * n)

    @property
    def events(self) -> list[Event]:
        """The robot's events of the last reset or step: (episode, step, event, target, detail)."""
        return self.stepper.events

    def reset(
        self, *, seed: int | None = None, options: Mapping[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.stepper.start(seed, *reset_options(options))
        return self._observation(), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        st = self.stepper
        if st.episode < 0 or st.t >= st.steps:
            raise RuntimeError("step: the episode is over (truncated) or not begun; call reset()")
        a = np.asarray(action)
        if a.shape != (len(st.dof),):
            raise ValueError(f"step: expected an action per joint ({len(st.dof)}), got shape {a.shape}")
        if self.continuous:
            if not np.all(np.isfinite(a)):
                raise ValueError(f"step: the action must be finite, got {action!r}")
            moves: dict[str, int | float] = {j: float(np.clip(v, -1.0, 1.0)) for j, v in zip(st.dof, a, strict=True)}
        else:
            if not self.action_space.contains(a.astype(np.int64)) or not np.all(a == np.round(a)):
                raise ValueError(f"step: each joint's action must be 0, 1 or 2, got {action!r}")
            moves = {j: int(v) for j, v in zip(st.dof, a, strict=True)}
        st.act(moves)
        reward = 0.0 if st.root_reward is None else float(st.root_reward)
        return self._observation(), reward, False, st.t >= st.steps, self._info()

    def apply_fault(self, fault: Fault | Mapping[str, Any] | str, *targets: str, **params: Any) -> list[Event]:
        """A joint fault now, from this step's moves (as the parallel env's `apply_fault`)."""
        return self.stepper.apply(as_fault(fault, targets, params))

    def render(self) -> np.ndarray:
        return self.stepper.frame()

    def close(self) -> None:
        self.stepper.close()

    def _observation(self) -> np.ndarray:
        st = self.stepper
        q = st.robot.readings()
        values = [q[a] for a in st.dof]
        for leaf in st.topo.end_effectors:
            values += list(st.robot.tips[leaf])
        values += list(st.robot.goal())
        return np.clip(np.array(values, dtype=np.float64), self._lo, self._hi).astype(np.float32)

    def _info(self) -> dict[str, Any]:
        st = self.stepper
        mask = np.ones((len(st.dof), N_ACTIONS), dtype=np.int8)
        for i, a in enumerate(st.dof):
            for b in st.decisions[a].avoid:
                if 0 <= b < N_ACTIONS:
                    mask[i, b] = 0
        return {"error": st.error, "step": st.t, "action_mask": mask}


def gym_env(
    run_file: str,
    *,
    continuous: bool = False,
    sets: Sequence[str] = (),
    render_mode: str | None = "rgb_array",
    **overrides: Any,
) -> RobotEnv:
    """The run file's robot and task as a Gymnasium env (overrides as `parallel_env`'s)."""
    return RobotEnv(Stepper(load_config(run_file, overrides, sets)), continuous, render_mode)


def register() -> None:
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="kinswarm.env.robot_env:gym_env")
