"""The robot in its world, one lockstep step after another, as plain calls: no messages, no clock, no Zenoh.

The simulator actor (actor.py) drives it from its messages and its deadline; the in-process placement
(actors/run/inprocess.py) and the environments drive it in a plain loop. Per epoch:

  start(goal, path, start)   the world at the start pose (or where the last epoch ended), the faults healed, the scene
                             reset, the tips read
  due(epoch)                 the scenario's entries due at this step: the joint faults (for apply_fault) and the
                             others (kill, freeze, drop, ...: for whoever applies them)
  readings()                 what the encoders read (the true angles through the joint faults)
  observations(epoch)        the encoder readings, what each agent senses, the root's task observation
  move(cmds)                 the step's increments, clipped to the action size, through the joint faults into the
                             scene (which moves the world as it allows); the tips, the error and the pose recorded
  done(...)                  the epoch's metrics

Events (a fault applied, a disturbance over) are returned as (event, target, detail) for the caller to publish.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping

from kinswarm.protocol.faults import JOINT_FAULTS, check_fault, describe, expand_targets
from kinswarm.protocol.messages import EpochDone, Fault, Readings, Task
from kinswarm.protocol.scenario import Scenario, ScenarioEntry
from kinswarm.protocol.scene import SceneSpec
from kinswarm.protocol.topology import Topology
from kinswarm.sim.faults import JointFaults
from kinswarm.sim.scenes import build_scene
from kinswarm.sim.world import World

Event = tuple[str, str, str]  # (event, target, detail)


class Robot:
    def __init__(
        self,
        topo: Topology,
        scene: SceneSpec,
        action_rad: float,
        seed: int,
        scenario: Scenario | None = None,
        world: World | None = None,
    ) -> None:
        """`world`: the PyBullet world to use (a fleet's robots may share a client); by default its own. It is closed
        with the robot."""
        self.topo = topo
        self.world = world if world is not None else World(topo)
        try:
            self.scene = build_scene(self.world, scene, action_rad)
        except BaseException:
            self.world.close()
            raise
        self.dof = topo.dof_agents
        self.dof_set = frozenset(self.dof)
        self._root_first = [a for a in self.dof if a == topo.root]
        self._others = [a for a in self.dof if a != topo.root]
        self.max_step = action_rad * (1 + 1e-9)
        self.faults = JointFaults(list(self.dof), seed)
        self.applied: dict[str, float] = dict.fromkeys(self.dof, 0.0)  # last increment per joint
        self.tips: dict[str, tuple[float, ...]] = {}
        self.errors: list[float] = []
        self.angles: list[list[float]] = []  # the true pose after each step of the epoch
        self.t = 0
        self._goal: tuple[float, ...] = ()
        self._path: list = []
        self._due: dict[int, list[tuple[int, ScenarioEntry]]] = {}  # scenario entries by step
        if scenario is not None:
            for i, entry in enumerate(scenario.entries):
                self._due.setdefault(entry.step, []).append((i, entry))

    def close(self) -> None:
        self.world.close()

    @property
    def due_steps(self) -> list[int]:
        """The steps the scenario has entries at."""
        return sorted(self._due)

    # -- an epoch ----------------------------------------------------------------------------------
    def start(
        self, goal: tuple[float, ...], path: list, start: Mapping[str, float] | None, keep_pose: bool = False
    ) -> str | None:
        """An epoch begins. `keep_pose`: from where the last epoch ended, with its faults (successive epochs).
        Returns why the start pose was not taken (the robot's home instead), or None."""
        warning = None
        self._goal, self._path = goal, path
        if not keep_pose:
            try:  # faults persist, angles do not: a locked joint is locked at the epoch's start angle
                self.world.reset(start or None)
            except ValueError as err:  # a start pose this robot cannot take: its home instead
                warning = f"{err}; starting from the robot's home"
                self.world.reset()
            self.faults.reset()
        self.tips = self.world.tip_poses()
        self.scene.reset()
        self.t = 0
        self.errors = []
        self.angles = []
        return warning

    def goal(self) -> tuple[float, ...]:
        """The goal of the running step: it moves along the epoch's path, if it has one (after the path's last step,
        its last point: the environments measure the epoch's last move there)."""
        return self._path[min(self.t, len(self._path) - 1)] if self._path else self._goal

    def due(self, epoch: int) -> tuple[list[Fault], list[Fault]]:
        """The scenario's entries due at this step of `epoch`: (joint faults, the others), each with its id. The caller
        applies them: the joint faults through `apply_fault` (a fleet's robot takes only its own)."""
        joint: list[Fault] = []
        others: list[Fault] = []
        for i, entry in self._due.get(self.t, ()):
            if entry.epoch is not None and entry.epoch != epoch:
                continue
            f = dataclasses.replace(entry.fault, id=f"scenario-{epoch}-{self.t}-{i}")
            (joint if entry.is_joint else others).append(f)
        return joint, others

    def apply_fault(self, f: Fault) -> tuple[list[Event], list[str]]:
        """Apply a joint fault now (it takes effect at the current step's increments): (its events, a refused target's
        among them, and the warnings to log). Other faults are not the robot's: nothing happens."""
        if f.fault not in JOINT_FAULTS:
            return [], []
        detail = describe(f)
        problem = check_fault(f, list(self.topo.order))
        if problem:  # the supervisor checks live faults first: this is a scenario's, or a message not its
            return [("refused", ",".join(f.targets) or "-", f"{detail}: {problem}")], [
                f"ignored fault {f.id}: {problem}"
            ]
        events: list[Event] = []
        refused: list[str] = []
        for a in expand_targets(f.targets, list(self.dof)):
            if a not in self.dof_set:
                refused.append(f"ignored fault {f.id} on {a}: a compound agent has no joint")
                events.append(("refused", a, f"{detail}: {a} has no joint (a compound agent)"))
                continue
            self.faults.apply(f, a)
            events.append((f.fault, a, detail))
        return events, refused

    # -- a step ------------------------------------------------------------------------------------
    def readings(self) -> dict[str, float]:
        """What the encoders read."""
        return self.faults.readings(self.world.joint_positions())

    def observations(self, epoch: int) -> tuple[dict[str, float], dict[str, Readings], Task]:
        """What the step shows the agents: the encoders' readings, what the scene lets each joint's agent sense, and
        the root's task observation, sensed in that order for the root first (its reading goes out with the task)."""
        q = self.readings()
        scene = self.scene
        sense = {a: scene.agent_sense(a) for a in self._root_first}
        task = self.task(epoch)
        sense.update((a, scene.agent_sense(a)) for a in self._others)
        return q, sense, task

    def task(self, epoch: int) -> Task:
        """The root's task observation: the goal, every end effector's pose and what the scene lets the task sense."""
        return Task(epoch=epoch, step=self.t, goal=self.goal(), tips=self.tips, sense=self.scene.task_sense())

    def clip(self, delta: float) -> float:
        """A command's increment within the action size."""
        return max(-self.max_step, min(self.max_step, delta))

    def move(self, cmds: Mapping[str, float]) -> list[Event]:
        """The step's clipped increments (a joint without one holds) into the world; the events of disturbances
        that ended."""
        faults = self.faults
        self.applied = self.scene.move(faults.increments(cmds) if faults.moves_changed else cmds)
        self.tips = self.world.tip_poses()
        self.errors.append(self.scene.error(self.tips, self.goal()))
        q = self.world.joint_positions()
        self.angles.append([q[a] for a in self.dof])
        self.t += 1
        if faults.disturbed:
            return [("disturb_end", a, detail) for a, detail in faults.count_step()]
        return []

    def done(self, epoch: int, steps: int, missed: int, seconds: float, longest: float) -> EpochDone:
        """The epoch's metrics."""
        return EpochDone(
            epoch=epoch,
            steps=steps,
            final_error=self.errors[-1],
            mean_error=sum(self.errors) / len(self.errors),
            errors=self.errors,
            final_angles=self.world.joint_positions(),
            missed_cmds=missed,
            seconds=seconds,
            max_step_seconds=longest,
            traces=self.scene.traces(),
            angles=self.angles,
        )
