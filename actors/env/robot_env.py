"""The whole robot as one Gymnasium agent: a central policy that sees every joint and moves them all at once.

  observation    float32: every joint's encoder reading (what the agents read: through the encoder faults), every
                 end effector's pose (a planar robot's x, y, heading; a spatial one's 7-float frame), the goal. Each
                 clipped to its bounds (core.Stepper.state_bounds). The parallel face's `state()` is the same vector
  action         MultiDiscrete([3] * joints): per joint one move down, none, one up; or, with continuous=True, a Box
                 [-1, 1] per joint: that share of one move (the run's action size, times the task's scale)
  reward         the root's task reward of the move, the r the swarm's agents get (before their local terms); a
                 compound root that pays each child its own (grasp) gives their mean
  info           "error" (the task's distance), "step", "action_mask" (joints x 3, int8: the moves each joint's task
                 leaves out; advice, not enforced). `action_masks()` gives it flat, as sb3-contrib's MaskablePPO asks

Episodes, goals, faults, seeding and lifecycle are the parallel env's (parallel.py): the run's `steps` moves ending in
truncation (with `success`, terminated once the task's error is within it), reset(seed=, options={"goal", "faults"}),
`apply_fault`, `close()` then `reset()` building the world again. Registered as "kinswarm/Robot-v0":
`gymnasium.make("kinswarm/Robot-v0", run_file="examples/chain4.toml")` once kinswarm.env is imported.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium
import numpy as np
from gymnasium import spaces
from kinswarm.protocol.messages import Fault

from .core import N_ACTIONS, Event, Stepper, check_success, load_config
from .faults import as_fault, reset_options
from .render import FPS, RENDER_MODES, Renderer

ENV_ID = "kinswarm/Robot-v0"


class RobotEnv(gymnasium.Env):
    metadata = {"render_modes": list(RENDER_MODES), "render_fps": FPS}

    def __init__(
        self,
        stepper: Stepper,
        continuous: bool = False,
        render_mode: str | None = "rgb_array",
        success: float | None = None,
    ) -> None:
        self.renderer = Renderer(stepper.frame, render_mode)
        self.stepper, self.continuous, self.render_mode = stepper, continuous, render_mode
        self.success = check_success(success)
        self._over = False  # terminated: the task's error came within `success`
        n = len(stepper.dof)
        lo, hi = stepper.state_bounds()
        self.observation_space = spaces.Box(lo, hi, dtype=np.float32)
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
        self._over = False
        self.renderer.shown()
        return self.stepper.global_state(), self._info()

    def step(self, action: Any) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        st = self.stepper
        if st.closed:
            raise RuntimeError("step: the env is closed; reset() builds its world again")
        if not st.started or st.t >= st.steps or self._over:
            raise RuntimeError("step: the episode is over (truncated or terminated) or not begun; call reset()")
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
        terminated = self.success is not None and st.error <= self.success
        self._over = terminated
        self.renderer.shown()
        return st.global_state(), reward, terminated, st.t >= st.steps, self._info()

    def action_masks(self) -> np.ndarray:
        """The moves each joint's task allows now, flat (joint 0's three, then joint 1's, ...): sb3-contrib's
        MaskablePPO calls it on a MultiDiscrete action space."""
        return self._info()["action_mask"].astype(bool).reshape(-1)

    def apply_fault(self, fault: Fault | Mapping[str, Any] | str, *targets: str, **params: Any) -> list[Event]:
        """A joint fault now, from this step's moves (as the parallel env's `apply_fault`)."""
        return self.stepper.apply(as_fault(fault, targets, params))

    def render(self) -> np.ndarray | None:
        return self.renderer.render()

    def close(self) -> None:
        """Release the PyBullet world and any window; a later `reset()` builds the world again (faults applied
        before are gone with it)."""
        self.stepper.close()
        self.renderer.close()

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
    draw: bool = True,
    success: float | None = None,
    **overrides: Any,
) -> RobotEnv:
    """The run file's robot and task as a Gymnasium env (overrides, `draw` and `success` as `parallel_env`'s)."""
    stepper = Stepper(load_config(run_file, overrides, sets), draw)
    try:
        return RobotEnv(stepper, continuous, render_mode, success)
    except BaseException:  # a bad option: its world not left connected
        stepper.close()
        raise


def register() -> None:
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(id=ENV_ID, entry_point="kinswarm.env.robot_env:gym_env")
