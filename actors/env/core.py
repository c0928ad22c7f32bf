"""The step as the environments see it: a run file's robot, task and agents' passes, stepped one joint action at a
time by whoever chooses the actions (no learners here). Both faces (parallel.py, robot_env.py) stand on it.

It drives the step as the inprocess placement (actors/run/inprocess.py) does, through the same driver
(actors/step/swarm.py): the same faults due, passes and learners, so a policy that acts as the run's learners act gets
the run's numbers. The one shift: in the swarm the reward r(t-1) of a move
arrives at the start of the next step t, when the root's task measures the new pose. Here `act` moves the robot and
then runs that next step's passes at once, so the move's reward comes back with the observation it led to; the
passes after the episode's last move run too (the swarm skips them: its epoch is over), so the last move is paid.
"""

from __future__ import annotations

import math
import zlib
from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import tomli_w
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.files.runfile import load_run
from kinswarm.actors.learning.kinds import JointLearner
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.actors.policies.registry import LearnerKind
from kinswarm.actors.step.epoch import epoch_start
from kinswarm.actors.step.passes import Decision, TopDown
from kinswarm.actors.step.swarm import Swarm
from kinswarm.protocol.faults import JOINT_FAULTS, check_fault
from kinswarm.protocol.messages import Fault
from kinswarm.protocol.scenario import load_scenario
from kinswarm.protocol.topology import Topology
from kinswarm.sim.robot import Robot

from .draws import draw_goal, draw_pose, draws_goal, draws_start
from .render import frame

#: the actions of one joint: decrease, keep, increase by one action size
N_ACTIONS = 3
_DISTURB_STREAM = b"sim-disturb"  # sim/faults.py's: a seeded reset seeds the disturbances as a run's seed does

Event = tuple[int, int, str, str, str]  # (episode, step, event, target, detail)


def load_config(run_file: str | Path, overrides: Mapping[str, Any], sets: Iterable[str] = ()) -> RunConfig:
    """The run file resolved with the env's overrides, for the inprocess loop the env is. A keyword is a [run] field
    (`steps=50`) or `section__field` (`task__goal=[4, 6]`, `learner__gamma=0.9`); `sets` are `--set` texts. A bad
    one is refused in one line that names it (a ValueError)."""
    given: list[tuple[str, str]] = [(s, f"sets {s!r}") for s in sets]
    for name, value in overrides.items():
        section, _, field = name.partition("__")
        key = f"{section}.{field}" if field else f"run.{name}"
        try:
            text = tomli_w.dumps({"v": value}).partition("=")[2].strip()
        except TypeError:
            raise ValueError(f"{name}={value!r}: not a TOML value (a number, string, bool or a list of them)") from None
        given.append((f"{key}={text}", f"{name}={value!r}"))
    given.append(('run.placement="inprocess"', "the env (a plain loop in this process)"))
    if not Path(run_file).is_file():
        raise ValueError(f"{run_file}: no such run file")
    return load_run(run_file, given)


def check_success(success: float | None) -> float | None:
    """The `success` option: None (episodes only truncate), or the task's error (its `error` info) within which an
    episode terminates."""
    if success is None:
        return None
    number = isinstance(success, (int, float)) and not isinstance(success, bool)
    if not (number and math.isfinite(success) and success > 0):
        raise ValueError(f"success: expected a distance > 0 (the error within which an episode ends), got {success!r}")
    return float(success)


class Stepper:
    """One robot and its agents' passes, stepped by joint actions. `episode` counts the episodes begun since the last
    seeded start: it is the epoch index the task's goals, starts and the scenario see.

    `draw`: a seeded start, and every start after it, draws the episode (draws.py: the goal of a reach task, the start
    of a random start pose) from a generator seeded by that seed; until a seed is given, and with draw=False always,
    episode k has the goal and start of the run's epoch k."""

    def __init__(self, cfg: RunConfig, draw: bool = True) -> None:
        self.cfg = cfg
        self.draw = draw
        self.rng: np.random.Generator | None = None  # the episodes' draws since the last seeded start
        self.topo: Topology = cfg.topo()
        self.swarm = Swarm(cfg, self.topo)  # the run's agents and their passes, as the inprocess placement's
        self.task = self.swarm.task
        self.settings: dict[str, LearnerSettings] = self.swarm.settings
        self.kind: LearnerKind = self.swarm.kind
        self.agents = self.swarm.agents
        self.dof = list(self.topo.dof_agents)  # the agents with a joint: the env's agents, in the robot's DOF order
        self.deciders = self.swarm.deciders  # leaves first, as the up pass
        self._robot: Robot | None = self.build()
        self.episode = -1
        self.seed = cfg.seed
        self.last: dict[str, int] = {}  # each agent's action at the step before
        self.decisions: dict[str, Decision] = {}
        self.top: dict[str, TopDown] = {}  # every agent's top-down pass of the step (the root's: the task's head)
        self.root_reward: float | None = None
        self.events: list[Event] = []  # the robot's events (faults applied, disturbances over) of the last call
        self.goal_length = len(self.task.goal(0, cfg.steps)[0])
        self._bounds: tuple[np.ndarray, np.ndarray] | None = None

    def build(self) -> Robot:
        """The robot in its own PyBullet world, as the run file builds it (a reset after `close` builds it anew)."""
        cfg = self.cfg
        scenario = load_scenario(cfg.scenario, self.topo) if cfg.scenario else None
        return Robot(self.topo, cfg.scene_spec, cfg.action_rad, cfg.seed, scenario)

    @property
    def robot(self) -> Robot:
        if self._robot is None:
            raise RuntimeError("the env is closed: reset() builds its world again")
        return self._robot

    @property
    def closed(self) -> bool:
        return self._robot is None

    @property
    def started(self) -> bool:
        """An episode has begun since the world was built (a closed env has none)."""
        return self._robot is not None and self.episode >= 0 and bool(self.decisions)

    @property
    def steps(self) -> int:
        return self.cfg.steps

    @property
    def t(self) -> int:
        return self.robot.t

    def frame(self) -> np.ndarray:
        """An RGB picture of the robot now: its pose, its goal, the episode and step (both faces' `render`)."""
        if not self.started:
            raise RuntimeError("render: no episode to draw; call reset() first")
        angles = self.robot.world.joint_positions()
        return frame(self.topo, angles, self.robot.goal(), f"{self.topo.name}  episode {self.episode}  step {self.t}")

    def close(self) -> None:
        """Disconnect the PyBullet world (again: nothing). The faults applied go with it; a later start builds the
        world anew, as at construction."""
        if self._robot is not None:
            self._robot.close()
            self._robot = None
            self.decisions = {}

    def learners(self) -> dict[str, JointLearner]:
        """The run's learners for each joint, built as every placement builds them (the same seeds)."""
        return self.swarm.learners()

    # -- the whole robot: the Gymnasium face's observation, the parallel face's global state ----------------------
    def state_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """The bounds of `global_state`, entry by entry: a reading within its joint's limits widened by pi (an offset
        fault reads up to 180 degrees beside the angle), a position within the base +- 2 reaches, a heading within
        +-pi, a quaternion's part within +-1."""
        topo = self.topo
        lo: list[float] = []
        hi: list[float] = []
        for a in self.dof:  # the readings
            j_lo, j_hi = topo.agents[a].limits
            lo.append(j_lo - math.pi)
            hi.append(j_hi + math.pi)
        r, base = 2.0 * topo.reach, topo.base
        position = [(base[i] - r, base[i] + r) for i in range(3 if topo.spatial else 2)]
        pose = position + ([(-1.0, 1.0)] * 4 if topo.spatial else [(-math.pi, math.pi)])
        for _ in topo.end_effectors:
            lo += [b[0] for b in pose]
            hi += [b[1] for b in pose]
        goal = position + [(-1.0, 1.0)] * (self.goal_length - len(position))
        lo += [b[0] for b in goal][: self.goal_length]
        hi += [b[1] for b in goal][: self.goal_length]
        return np.array(lo, np.float32), np.array(hi, np.float32)

    def global_state(self) -> np.ndarray:
        """float32: every joint's encoder reading (DOF order: through the encoder faults, what the agents read),
        every end effector's pose, the goal; each clipped to `state_bounds`."""
        if self._bounds is None:
            lo, hi = self.state_bounds()
            self._bounds = lo.astype(np.float64), hi.astype(np.float64)
        robot = self.robot
        q = robot.readings()
        values = [q[a] for a in self.dof]
        for leaf in self.topo.end_effectors:
            values += list(robot.tips[leaf])
        values += list(robot.goal())
        return np.clip(np.array(values, dtype=np.float64), *self._bounds).astype(np.float32)

    def state_slices(self) -> dict[str, slice]:
        """Where each part lies in `global_state`: "<joint>" its reading, "<end effector>.tip" its pose, "goal"."""
        out = {a: slice(i, i + 1) for i, a in enumerate(self.dof)}
        i, width = len(self.dof), 7 if self.topo.spatial else 3
        for leaf in self.topo.end_effectors:
            out[f"{leaf}.tip"] = slice(i, i + width)
            i += width
        out["goal"] = slice(i, i + self.goal_length)
        return out

    # -- an episode ----------------------------------------------------------------------------------
    def start(
        self,
        seed: int | None = None,
        goal: Sequence[float] | None = None,
        faults: Sequence[Fault] | None = None,
    ) -> None:
        """An episode begins: `seed` restarts the goal schedule at epoch 0, reseeds the robot's disturbances and (with
        `draw`) the episodes' draws; `goal` replaces the episode's goal; `faults` (when given: the joints freed first)
        apply from its first step, as a scenario's at step 0."""
        if goal is not None:
            goal = self.check_goal(goal)
        for f in faults or ():
            self.check(f)
        if self._robot is None:
            self._robot = self.build()
        if seed is not None:
            self.seed = seed
            self.episode = -1
            self.robot.faults.rng = np.random.default_rng([seed, zlib.crc32(_DISTURB_STREAM)])
            self.rng = np.random.default_rng(seed) if self.draw else None
        self.episode += 1
        e = epoch_start(self.cfg, self.task, self.episode)
        path, e_start = e.path, e.start
        if goal is not None:
            e_goal, path = tuple(goal), []
        elif self.rng is not None and draws_goal(self.task):
            e_goal, path = draw_goal(self.robot.world, self.topo, self.rng, self.goal_length), []
        else:
            e_goal = e.goal
        if self.rng is not None and draws_start(self.task):
            e_start = draw_pose(self.topo, self.rng)
        keep = self.cfg.successive and self.episode > 0
        self.events = []
        warning = self.robot.start(e_goal, path, e_start, keep_pose=keep)
        if warning:
            self.events.append((self.episode, 0, "start", "robot", warning))
        self.swarm.start_epoch(self.episode)
        if faults is not None:
            self.apply(Fault("env-free", "free", ["all"], None, None, None, None, None))
            for f in faults:
                self.apply(f)
        self.last = {}
        self._passes()

    def check_goal(self, goal: Sequence[float]) -> tuple[float, ...]:
        try:
            g = tuple(float(x) for x in goal)
        except (TypeError, ValueError):
            raise ValueError(f"reset options goal: expected {self.goal_length} numbers, got {goal!r}") from None
        if len(g) != self.goal_length or not all(math.isfinite(x) for x in g):
            raise ValueError(f"reset options goal: expected {self.goal_length} finite numbers, got {goal!r}")
        return g

    def check(self, f: Fault) -> None:
        """A joint fault this robot can take, or one line saying why not."""
        if not isinstance(f, Fault):
            raise ValueError(f"fault: expected a kinswarm.protocol.messages.Fault, got {f!r}")
        if f.fault not in JOINT_FAULTS:
            raise ValueError(f"fault {f.fault!r}: the env applies the robot's joint faults ({', '.join(JOINT_FAULTS)})")
        if problem := check_fault(f, list(self.topo.order)):
            raise ValueError(f"fault: {problem}")

    def apply(self, f: Fault) -> list[Event]:
        """Apply a joint fault now: it acts from the current step's moves (an encoder fault from the next reading)."""
        self.check(f)
        events, _ = self.robot.apply_fault(f)
        out = [(self.episode, self.robot.t, *e) for e in events]
        self.events.extend(out)
        return out

    def act(self, actions: Mapping[str, int | float]) -> None:
        """The step's moves: per joint an action (0, 1, 2: one move down, none, one up; a float in [-1, 1]: that share
        of a move), the robot moved, then the next step's passes (the move's reward)."""
        self.events = []
        cmds: dict[str, float] = {}
        now: dict[str, int] = {}
        for a in self.deciders:
            if a not in actions:
                continue
            d, v = self.decisions[a], actions[a]
            if isinstance(v, (int, np.integer)):
                cmds[a] = self.robot.clip(self.agents[a].delta(int(v), d.scale))
                now[a] = int(v)
            else:  # continuous: the share of one move, clipped to it as every command is
                cmds[a] = self.robot.clip(float(v) * self.cfg.action_rad * d.scale)
                now[a] = 1 + int(np.sign(v))  # what its parent counts: the direction it moved
        self.last = now
        self.events.extend((self.episode, self.robot.t, *e) for e in self.robot.move(cmds))
        self._passes()

    @property
    def error(self) -> float:
        """The task's error after the last move (the distance a run's final_error reports); at the start, before it."""
        robot = self.robot
        return robot.errors[-1] if robot.errors else robot.scene.error(robot.tips, robot.goal())

    # -- the passes ------------------------------------------------------------------------------------
    def _passes(self) -> None:
        """The step's scenario faults, then its top-down and bottom-up passes, as the inprocess placement runs them
        (the driver, actors/step/swarm.py): what every joint decides from."""
        robot, epoch, t = self.robot, self.episode, self.robot.t
        self.events.extend((epoch, t, *e) for e in self.swarm.faults(robot, epoch))
        step = self.swarm.passes(robot, epoch, self.last)
        self.decisions = step.decisions
        self.top = step.top
        root = step.top[self.topo.root]
        self.root_reward = root.reward
        if root.reward is None and root.children:  # a compound root pays each child its own (grasp): their mean
            given = [r for _, r, _ in root.children.values() if r is not None]
            self.root_reward = sum(given) / len(given) if given else None
