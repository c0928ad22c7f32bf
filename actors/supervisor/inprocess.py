"""The `inprocess` placement: the whole run as one plain loop over the step library — no actors, no messages, no
Zenoh. Each step the robot (sim/robot.py) gives the encoder readings and the root's task observation, the agents'
top-down and bottom-up passes run in the topology's order (actors/step/passes.py), every agent with a joint learns
and decides, and the robot moves. It computes what the other placements compute, in the same order per agent, so a
run gives the same `final_error` lists, metrics and records as they do for the same seed; it is the fastest way to
run an experiment that needs no messages.

What has no meaning without processes and messages is refused before the run starts (actors/run/runfile.py): process
and link faults (kill, freeze, drop, ...), fleets, the model-based controllers and several hosts. Joint and model
faults from the run's scenario apply as in the simulator actor.
"""

from __future__ import annotations

import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from kinswarm.actors.files.checkpoint import save_checkpoint
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.files.runfile import kind_of, learner_settings, task_of
from kinswarm.actors.learning.kinds import JointLearner
from kinswarm.actors.step.epoch import checkpoint_due, epoch_start
from kinswarm.actors.step.learned import checkpoint_meta, learned_state, restore_learner
from kinswarm.actors.step.passes import AgentStep, robot_passes, visible_actions
from kinswarm.actors.step.seed import agent_seed
from kinswarm.actors.step.trace import StepTrace
from kinswarm.protocol.messages import EpochDone
from kinswarm.protocol.scenario import load_scenario
from kinswarm.protocol.topology import Topology
from kinswarm.sim.robot import Robot

from .recorder import Recorder
from .result import RunResult

log = logging.getLogger("kinswarm.inprocess")


class InProcessRun:
    """One run's agents and robot, stepped in a plain loop (`run`), or one epoch at a time (`epoch`)."""

    def __init__(self, cfg: RunConfig, topo: Topology, world: Any = None) -> None:
        """`world`: the robot's world (sim/world.World's interface); by default its PyBullet world."""
        self.cfg, self.topo = cfg, topo
        self.task = task_of(cfg)
        settings = learner_settings(self.task, cfg.learner, cfg.source)
        obs = {a: s.observation for a, s in settings.items()}
        self.kind = kind_of(cfg.learner, cfg.source)
        self.order = list(topo.order)  # top-down: every parent before its children
        self.agents = {a: AgentStep(topo, a, self.task, obs.get(a), cfg.action_rad) for a in self.order}
        self.learners = {
            a: self.kind.build(
                settings[a], len(self.agents[a].visible), agent_seed(cfg.seed, a), agent=a, index=i, options=cfg.learner
            )
            for i, a in enumerate(topo.dof_agents)
        }
        self.epochs_before = dict.fromkeys(self.learners, 0)
        if cfg.from_dir:
            for a, learner in self.learners.items():
                path = Path(cfg.from_dir) / "agents" / f"{a}.npz"
                self.epochs_before[a] = restore_learner(learner, path, a, self.kind.name)
        self.traces = {a: StepTrace(a, obs[a].names) for a in self.learners} if cfg.record_agents else {}
        scenario = load_scenario(cfg.scenario, topo) if cfg.scenario else None
        self.robot = Robot(topo, cfg.scene_spec, cfg.action_rad, cfg.seed, scenario, world)
        self.deciders = [a for a in reversed(self.order) if a in self.learners]  # leaves first, as the up pass

    def close(self) -> None:
        self.robot.close()

    def epoch(self, epoch: int, on_event: Callable[[int, int, str, str, str], None]) -> EpochDone:
        """Run epoch `epoch` to its end; `on_event(epoch, step, event, target, detail)` gets the robot's events."""
        cfg, robot, agents, learners = self.cfg, self.robot, self.agents, self.learners
        e = epoch_start(cfg, self.task, epoch)
        warning = robot.start(e.goal, e.path, e.start, keep_pose=cfg.successive and epoch > 0)
        if warning:  # a start pose this robot cannot take: its home instead, said once
            log.warning("epoch %d: %s", epoch, warning)
        for a in self.order:
            agents[a].task.start_epoch()
        for a, learner in learners.items():
            learner.start_epoch(self.epochs_before[a] + epoch, t=0)
        learn, explore = cfg.learn, cfg.explore
        started = time.perf_counter()
        longest = 0.0
        last: dict[str, int] = {}  # each agent's action at the step before
        for t in range(cfg.steps):
            step_started = time.perf_counter()
            joint, _ = robot.due(epoch)  # the others were refused before the run (actors/run/runfile.py)
            for f in joint:
                for event in robot.apply_fault(f)[0]:
                    on_event(epoch, t, *event)
            q, sense, head = robot.observations(epoch)
            begun, views = robot_passes(agents, self.order, head, q, sense, epoch, t, last)
            cmds, now = {}, {}
            for a in self.deciders:  # each joint's learner: the children's actions of t-1, then a(t)
                st, learner = agents[a], learners[a]
                if st.visible and t > 0:
                    self._observe(learner, visible_actions(st.visible, last), t)
                d = st.decide_from(begun[a], views[a])
                action = learner.decide(d.state, d.reward, learn=learn, explore=explore, avoid=d.avoid)
                if a in self.traces:
                    self.traces[a].add(epoch, t, d.state, action, learner)
                if not st.visible:
                    learner.observe([], learn=learn)
                cmds[a] = robot.clip(st.delta(action, d.scale))
                now[a] = action
            last = now
            for event in robot.move(cmds):
                on_event(epoch, robot.t, *event)
            longest = max(longest, time.perf_counter() - step_started)
        for a in self.deciders:  # the epoch's last step: the children's closing actions
            if agents[a].visible:
                self._observe(learners[a], visible_actions(agents[a].visible, last), cfg.steps)
        return robot.done(epoch, cfg.steps, 0, time.perf_counter() - started, longest)

    def _observe(self, learner: JointLearner, acts: list[int], step: int) -> None:
        if all(0 <= b < learner.n_actions for b in acts):
            learner.observe(acts, learn=self.cfg.learn)
        else:
            learner.resync(step)

    def checkpoint(self, epoch: int) -> None:
        """Every learner's state into the run's `agents/`, as the agents write it."""
        directory = Path(self.cfg.out) / "agents"
        for a, learner in self.learners.items():
            meta = checkpoint_meta(a, self.kind.name, self.topo.name, self.epochs_before[a], epoch, self.cfg.seed)
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
