"""The `inprocess` placement: the whole run as one plain loop over the step's driver (actors/step/swarm.py) — no
actors, no messages, no Zenoh. Each step the scenario's joint faults due apply, the robot (sim/robot.py) gives the
encoder readings and the root's task observation, the agents' passes run, every joint learns and decides, and the
robot moves. The driver is the one the agent and simulator actors take their pieces of, in the same order per
agent, so a run gives the same `final_error` lists, metrics and records as the other placements for the same seed;
it is the fastest way to run an experiment that needs no messages.

What has no meaning without processes and messages is refused before the run starts (actors/files/runfile.py): process
and link faults (kill, freeze, drop, ...), fleets, the model-based controllers and several hosts.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from kinswarm.actors.files.checkpoint import save_checkpoint
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.step.epoch import checkpoint_due, epoch_start
from kinswarm.actors.step.learned import checkpoint_meta, learned_state, restore_learner
from kinswarm.actors.step.swarm import Swarm, actions, commands
from kinswarm.actors.step.trace import StepTrace
from kinswarm.actors.supervisor.recorder import Recorder
from kinswarm.actors.supervisor.result import RunResult
from kinswarm.protocol.messages import EpochDone
from kinswarm.protocol.scenario import load_scenario
from kinswarm.protocol.topology import Topology
from kinswarm.sim.robot import Robot

log = logging.getLogger("kinswarm.inprocess")


class InProcessRun:
    """One run's agents and robot, stepped in a plain loop (`run`), or one epoch at a time (`epoch`)."""

    def __init__(self, cfg: RunConfig, topo: Topology, world: Any = None) -> None:
        """`world`: the robot's world (sim/world.World's interface); by default its PyBullet world."""
        self.cfg, self.topo = cfg, topo
        self.swarm = Swarm(cfg, topo)
        self.learners = self.swarm.learners()
        self.epochs_before = dict.fromkeys(self.learners, 0)  # the epochs each was trained before the run (--from)
        if cfg.from_dir:
            for a, learner in self.learners.items():
                path = Path(cfg.from_dir) / "agents" / f"{a}.npz"
                self.epochs_before[a] = restore_learner(learner, path, a, self.swarm.kind.name)
        self.traces: dict[str, StepTrace] = {}  # what each joint saw and chose, for the recording
        if cfg.record_agents:
            self.traces = {a: StepTrace(a, self.swarm.settings[a].observation.names) for a in self.learners}
        scenario = load_scenario(cfg.scenario, topo) if cfg.scenario else None
        self.robot = Robot(topo, cfg.scene_spec, cfg.action_rad, cfg.seed, scenario, world)

    def close(self) -> None:
        self.robot.close()

    def epoch(self, epoch: int, on_event: Callable[[int, int, str, str, str], None]) -> EpochDone:
        """Run epoch `epoch` to its end; `on_event(epoch, step, event, target, detail)` gets the robot's events."""
        cfg, robot, swarm, learners = self.cfg, self.robot, self.swarm, self.learners
        e = epoch_start(cfg, swarm.task, epoch)
        warning = robot.start(e.goal, e.path, e.start, keep_pose=cfg.successive and epoch > 0)
        if warning:  # a start pose this robot cannot take: its home instead, said once
            log.warning("epoch %d: %s", epoch, warning)
        swarm.start_epoch(epoch, learners, self.epochs_before)
        started = time.perf_counter()
        longest = 0.0
        last: dict[str, int] = {}  # each agent's action at the step before
        for t in range(cfg.steps):
            step_started = time.perf_counter()
            for event in swarm.faults(robot, epoch):
                on_event(epoch, t, *event)
            step = swarm.passes(robot, epoch, last)
            acted = swarm.learn_and_decide(step, learners, last, self.traces)
            last = actions(acted)
            for event in robot.move(commands(robot, acted)):
                on_event(epoch, robot.t, *event)
            longest = max(longest, time.perf_counter() - step_started)
        swarm.close_epoch(learners, last)
        return robot.done(epoch, cfg.steps, 0, time.perf_counter() - started, longest)

    def checkpoint(self, epoch: int) -> None:
        """Every learner's state into the run's `agents/`, as the agents write it."""
        directory = Path(self.cfg.out) / "agents"
        for a, learner in self.learners.items():
            meta = checkpoint_meta(a, self.swarm.kind.name, self.topo.name, self.epochs_before[a], epoch, self.cfg.seed)
            save_checkpoint(directory / f"{a}.npz", learned_state(learner), meta)

    def run(self, recorder: Recorder, on_epoch: Callable[[EpochDone], None] | None = None) -> RunResult:
        """Every epoch of the run, recorded as the supervisor records a swarm's; Ctrl-C ends it after the rows
        written so far."""
        t0 = time.perf_counter()
        result = RunResult(restarts=dict.fromkeys(self.learners, 0))
        recorder.open_events()
        recorder.open_metrics()
        try:
            for epoch in range(self.cfg.epochs):
                done = self.epoch(epoch, recorder.event)
                result.epochs.append(done)
                recorder.epoch(done)
                for trace in self.traces.values():
                    recorder.agent(trace.take())
                if on_epoch is not None:
                    on_epoch(done)
                if self.learners and checkpoint_due(self.cfg, epoch):
                    self.checkpoint(epoch)
        except KeyboardInterrupt:
            result.interrupted = True
            log.warning("interrupted: the run stops after %d epochs", len(result.epochs))
        finally:
            recorder.close()
            self.close()
        result.wall_seconds = time.perf_counter() - t0
        return result
