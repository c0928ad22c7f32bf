"""The simulator actor: the robot, and the clock of the lockstep.

For each step it publishes the task observation to the root and each agent's encoder reading (with what the scene
lets each sense), then waits for a `cmd` from every DOF agent that is alive — or for the step deadline, after which a
missing command means that joint holds — hands the increments (clipped to the action size and the joint limits) to
the scene, which moves the robot as it allows, and records the error. At the end of an epoch it publishes
`metrics/epoch`. What surrounds the robot is the run's scene (sim/scenes/): this file names none.

It is also where joint faults live (docs/faults.md, sim/faults.py): a locked joint ignores its agent, a disturbed one
moves at random, a faulty motor or encoder moves or reads wrong; the agents are not told. Faults come live on
`ctl/fault` or from the run's scenario file; every change is published on `metrics/event`, and the joints' state on
`metrics/joints`.
"""

from __future__ import annotations

import asyncio
import logging
import time
from typing import Any

import zenoh
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.runtime import Node
from kinswarm.actors.step.swarm import faults_due
from kinswarm.protocol.clock import ClockWriter, clock_path
from kinswarm.protocol.faults import JOINT_FAULTS, describe
from kinswarm.protocol.keys import GONE, UP, parse_token_change, token_change
from kinswarm.protocol.messages import (
    Bye,
    Cmd,
    EpochDone,
    EpochStart,
    Event,
    Fault,
    Heartbeat,
    JointStatus,
    Obs,
    Stop,
)
from kinswarm.protocol.scenario import load_scenario
from kinswarm.protocol.topology import Topology
from kinswarm.sim.robot import Robot
from kinswarm.sim.world import World

from .hosts import HostSilence

# Timers and liveliness changes go through the mailbox under keys no Zenoh key can equal (those start
# with "ks/"), so every handler but the commands' runs on the loop, in arrival order. The commands are handled on
# Zenoh's thread as they arrive (Node.listen's `inline`; under the node's lock, so never beside the loop's handlers):
# the last one moves the robot and publishes the next step from there, with no wake-up of the loop.
DEADLINE, ALIVE, STATUS, PAUSE_CHECK = "__deadline__", "__alive__", "__status__", "__pause__"
STATUS_S = 0.5


class SimActor:
    def __init__(self, cfg: RunConfig, topo: Topology, node: Node) -> None:
        self.cfg, self.topo, self.node, self.keys = cfg, topo, node, node.keys
        # Read before the world exists: a bad file fails the actor without leaking a PyBullet client.
        self.scenario = load_scenario(cfg.scenario, topo) if cfg.scenario else None
        self.robot = Robot(topo, cfg.scene_spec, cfg.action_rad, cfg.seed, self.scenario, self._world(topo))
        self.world, self.scene, self.faults = self.robot.world, self.robot.scene, self.robot.faults
        # which robot of a fleet this is (actors/simulator/fleet.py): a joint fault for another is not its
        self.robot_index = 0
        self.dof = topo.dof_agents
        self.dof_set = frozenset(self.dof)
        self._obs_first = [a for a in self.dof if a == topo.root]  # the root's reading goes out with the task
        self._obs_after = [a for a in self.dof if a != topo.root]
        self.epoch: EpochStart | None = None
        self.last_epoch = -1  # the last accepted EpochStart
        self._sent_done: EpochDone | None = None  # the last epoch's end, sent again when its start comes again
        # a joint fault applied before the first epoch acts from that epoch's step 0: its events wait to be stamped so
        # (a resumed run's first epoch is not known until its EpochStart)
        self._early: list[tuple[str, str, str]] = []
        self.cmds: dict[str, float] = {}
        self.waiting: set[str] = set()  # agents whose cmd the current step still waits for
        self.down: set[str] = set()  # agents whose liveliness token went away (and has not come back)
        self.missed = 0
        self.late: dict[str, int] = {}  # agent -> steps in a row that ended at the deadline without its cmd
        self.total_steps = 0
        self.started = 0.0
        self.step_started = 0.0
        self.longest_step = 0.0
        # The step deadline's watchdog: armed on the loop while an epoch runs, it fires when the running step is due
        # (a step published on Zenoh's thread needs no timer of its own; see _on_watchdog)
        self._deadline: asyncio.TimerHandle | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        # Several hosts (a deploy plan): steps are held while one is silent for a lease (hosts.py)
        self.silence = HostSilence(
            cfg.hosts,
            cfg.lease_ms / 1000,
            self._event,
            lambda delay: self._later(delay, self.node.mailbox.push, PAUSE_CHECK, b""),
        )
        self.held = False
        self._host_prefix = self.keys.prefix("host")
        self._status: asyncio.TimerHandle | None = None
        self._cmd_prefix = self.keys.prefix("cmd")
        # (epoch, step) for the supervisor's events on this host (protocol/clock.py); the actor that runs has one
        self.clock: ClockWriter | None = None
        if self.scenario is not None:
            late = [s for s in self.robot.due_steps if s >= cfg.steps]
            if late:
                node.log.warning(
                    "scenario %s: steps %s are beyond --steps %d, never reached", cfg.scenario, late, cfg.steps
                )

    def _world(self, topo: Topology) -> World:
        return World(topo)

    def outputs(self) -> list[str]:
        out = [self.keys.task, *(self.keys.obs(a) for a in self.dof)]
        if self.scenario is not None and not all(e.is_joint for e in self.scenario.entries):
            out.append(self.keys.fault("request"))  # someone must be there to apply kill/freeze/drop
        return out

    async def run(self) -> None:
        node, k = self.node, self.keys
        node.listen(k.ctl_all, inline=self._on_ctl_sample)
        if self.silence.hosts:
            node.listen(k.host("*"))
        node.listen(k.cmd_all, inline=self._on_cmd_sample)
        push = node.mailbox.push
        self._loop = asyncio.get_running_loop()
        self.clock = ClockWriter(clock_path(self.cfg.out))

        def on_alive(sample: Any) -> None:  # zenoh thread
            key = str(sample.key_expr)
            if k.parse_alive(key) is not None:
                push(ALIVE, token_change(UP if sample.kind == zenoh.SampleKind.PUT else GONE, key).encode())

        watch = node.session.liveliness().declare_subscriber(k.alive("agent", "*"), on_alive, history=True)
        for key in (k.metrics("event"), k.metrics("joints"), k.rep(node.role, node.ident)):
            node.publisher(key)  # declared now, so the first put does not wait on the declaration
        self._status = asyncio.get_running_loop().call_later(STATUS_S, push, STATUS, b"")
        try:
            while True:  # agents still starting (a saturated machine, their first compile) are waited for: whether
                try:  # the swarm came up in time is the supervisor's to judge (it gives up, and stops this, itself)
                    await node.wait_matched(self.outputs(), timeout=30.0)
                    break
                except TimeoutError as e:
                    node.log.warning("%s; still waiting", e)
            node.declare_alive()
            node.serve_inline()
            while True:
                async with node.next() as (key, payload):
                    if self.handle(key, payload):
                        return
        finally:
            node.serve_inline(False)  # no command moves the robot from here on
            for timer in (self._deadline, self._status):
                if timer is not None:
                    timer.cancel()
            watch.undeclare()
            self.robot.close()
            self.clock.close()

    def handle(self, key: str, payload: bytes) -> bool:
        """Dispatch one mailbox item; True means stop."""
        node, k = self.node, self.keys
        if key.startswith(self._cmd_prefix):  # the hot path first (when it had to wait in the mailbox)
            self._on_cmd_sample(key, payload)
        elif key == DEADLINE:
            self._on_watchdog()
        elif key == ALIVE:
            self._on_token(payload)
        elif key == STATUS:
            self._on_status()
        elif key == k.ctl("fault"):
            if (f := node.decode(key, payload, Fault)) is not None:
                self.apply_fault(f)
        elif key == k.ctl("epoch"):
            if (e := node.decode(key, payload, EpochStart)) is not None:
                self._on_epoch(e)
        elif key.startswith(self._host_prefix):
            if (hb := node.decode(key, payload, Heartbeat)) is not None:
                self.silence.heard_from(hb.host)
        elif key == PAUSE_CHECK:
            self._check_pause()
        elif key == k.ctl("stop"):
            if node.decode(key, payload, Stop) is not None:
                node.send(k.rep(node.role, node.ident), Bye(steps=self.total_steps, rejected=node.rejected))
                return True
        return False

    @property
    def paused(self) -> bool:
        """A host is silent: the next step is held (hosts.py)."""
        return self.silence.holding()

    def _check_pause(self) -> None:
        if self.silence.recheck() and self.held and self.epoch is not None:
            self.held = False
            self._publish_step()

    # -- handlers ----------------------------------------------------------------------------------
    def _on_epoch(self, e: EpochStart) -> None:
        # A forged or replayed EpochStart must not reset the world mid-run or rewind the epoch count.
        if self.epoch is not None:
            if e.epoch != self.epoch.epoch:  # the running epoch's own start asked again: its end will come
                self.node.log.warning("ignored EpochStart %d: epoch %d is running", e.epoch, self.epoch.epoch)
            return
        if e.epoch == self.last_epoch:  # the supervisor asks again: the end it waits for was lost (a pause, a cut)
            done = self._sent_done
            if done is not None and done.epoch == e.epoch:
                self.node.log.info("epoch %d's start came again: its EpochDone goes out again", e.epoch)
                self.node.send(self.keys.metrics("epoch"), done)
            return
        # The first start may be any epoch: a resumed run goes on after its checkpoint (actors/files/resume.py)
        if e.epoch != self.last_epoch + 1 and not (self.last_epoch < 0 <= e.epoch < self.cfg.epochs):
            self.node.log.warning("ignored EpochStart %d: the next epoch is %d", e.epoch, self.last_epoch + 1)
            return
        if e.steps < 1:
            self.node.log.warning("ignored EpochStart %d: %d steps", e.epoch, e.steps)
            return
        first = self.last_epoch < 0  # (a resumed run's first epoch has no pose of the last one to keep)
        self.epoch = e
        self.last_epoch = e.epoch
        warning = self.robot.start(e.goal, e.path, e.start, keep_pose=self.cfg.successive and not first)
        if warning:  # a start pose this robot cannot take: its home instead, said once
            self.node.log.warning("epoch %d: %s", e.epoch, warning)
        self.missed = 0
        self.started = time.perf_counter()
        self.longest_step = 0.0
        for name, target, detail in self._early:
            self._event(name, target, detail)
        self._early.clear()
        if self.paused:
            self.held = True
            return
        self._publish_step()

    def _on_ctl_sample(self, key: str, payload: bytes) -> None:  # Zenoh's thread (inline)
        """A joint fault takes effect at the step it reaches the sim (a busy machine's loop woke steps later); every
        other control message waits for the loop."""
        if key == self.keys.ctl("fault"):
            if (f := self.node.decode(key, payload, Fault)) is not None:
                self.apply_fault(f)
        else:
            self.node.mailbox.push(key, payload)

    def _on_cmd_sample(self, key: str, payload: bytes) -> None:  # Zenoh's thread (inline) or the loop
        if (m := self.node.decode(key, payload, Cmd)) is not None:
            self._on_cmd(self._agent_of(key), m)

    def _agent_of(self, key: str) -> str:
        """The agent a cmd key names (parsed: protocol/keys.py)."""
        step = self.keys.parse_step(key)
        assert step is not None  # a key of this run's sim/cmd/*: Zenoh delivers only what it subscribed to
        return step.agent

    def _on_token(self, payload: bytes) -> None:
        """An agent's liveliness token came or went."""
        sign, key = parse_token_change(payload.decode())
        if (actor := self.keys.parse_alive(key)) is not None:
            self._on_alive(actor[1], sign == UP)

    def _on_cmd(self, agent: str, m: Cmd) -> None:
        e = self.epoch
        if e is None or (m.epoch, m.step) != (e.epoch, self.t):
            return  # late (after the deadline) or from another epoch: the joint already held
        if agent not in self.dof_set:
            self.node.log.warning("rejected cmd for %r: not a joint of %s", agent, self.topo.name)
            return
        # Counted even for a locked joint (the step must not wait); _advance decides what moves.
        self.cmds[agent] = self.robot.clip(m.delta)
        self.late.pop(agent, None)
        self.waiting.discard(agent)
        if not self.waiting:
            self._advance()

    def _on_deadline(self) -> None:
        """The running step is past its deadline: the commands still missing count as missed, those joints hold."""
        e = self.epoch
        if e is None:
            return
        if self.waiting:
            missing = sorted(self.waiting)
            self.missed += len(missing)
            for a in missing:
                self.late[a] = self.late.get(a, 0) + 1
            self.node.log.warning("step %d/%d: no cmd from %s by the deadline; they hold", e.epoch, self.t, missing)
        self._advance()

    def _on_watchdog(self) -> None:
        """The deadline's watchdog fired (on the loop): the running step is past its deadline, or it re-arms for when
        the running step will be. One timer an epoch instead of one a step, and none set off the loop."""
        self._deadline = None
        e = self.epoch
        if e is None:
            return  # between epochs: the next one arms it
        due = self.cfg.deadline_ms / 1000
        if not self.held and time.perf_counter() - self.step_started >= due:
            self._on_deadline()  # the step ends: a new one, or the epoch's end
        if self._deadline is None and self.epoch is not None:
            left = due if self.held else self.step_started + due - time.perf_counter()
            self._arm(max(left, 0.0))

    def _arm(self, delay: float) -> None:
        self._deadline = self._later(delay, self.node.mailbox.push, DEADLINE, b"")

    def _later(self, delay: float, fn: Any, *args: Any) -> asyncio.TimerHandle | None:
        """loop.call_later from the loop, or from Zenoh's thread through the loop (None: the handle is not known)."""
        try:
            return asyncio.get_running_loop().call_later(delay, fn, *args)
        except RuntimeError:  # not on the loop: a command handled on Zenoh's thread
            if self._loop is not None:
                self._loop.call_soon_threadsafe(self._loop.call_later, delay, fn, *args)
            return None

    def _on_alive(self, agent: str, up: bool) -> None:
        """Agents never seen stay expected (the baseline's joints have no agent tokens); one that comes
        back is waited for from the next published step, since it may have missed this step's obs."""
        if agent not in self.dof_set:
            return
        if up:
            if agent in self.down:
                self.down.discard(agent)
                self.node.log.info("agent %s is back; waited for from the next step", agent)
            return
        if agent not in self.down:
            self.down.add(agent)
            # between epochs (a run ending, agents stopping first) it costs nothing: no warning
            level = logging.WARNING if self.epoch is not None else logging.INFO
            self.node.log.log(level, "agent %s is down; its joint holds and steps go on without it", agent)
        if self.epoch is not None and agent in self.waiting:
            self.waiting.discard(agent)
            if not self.waiting:
                self._advance()

    def _on_status(self) -> None:
        epoch, step = self.now()
        self.node.send(
            self.keys.metrics("joints"),
            JointStatus(
                epoch=epoch,
                step=step,
                q=self.world.joint_positions(),
                delta=dict(self.robot.applied),
                faults=self.faults.summary(),
                late={a: n for a, n in self.late.items() if a not in self.down},
            ),
        )
        self._status = asyncio.get_running_loop().call_later(STATUS_S, self.node.mailbox.push, STATUS, b"")

    # -- faults ------------------------------------------------------------------------------------
    def apply_fault(self, f: Fault) -> None:
        """Apply a joint fault now (it takes effect at the current step's increments); others are ignored,
        they are for the supervisor and the runtimes."""
        if f.fault not in JOINT_FAULTS or f.robot not in (None, self.robot_index):
            return
        events, refused = self.robot.apply_fault(f)
        for problem in refused:
            self.node.log.warning(problem)
        if self.epoch is None and self.last_epoch < 0:
            self._early.extend(events)
            return
        for name, target, detail in events:
            self._event(name, target, detail)

    def now(self) -> tuple[int, int]:
        """(epoch, step) for events: the running step, or where the last epoch ended (-1 before any)."""
        return (self.epoch.epoch if self.epoch is not None else self.last_epoch), self.t

    def _event(self, name: str, target: str, detail: str) -> None:
        epoch, step = self.now()
        self.node.log.info("event %s %s at %d/%d: %s", name, target, epoch, step, detail)
        event = Event(epoch=epoch, step=step, event=name, target=target, detail=detail)
        self.node.send(self.keys.metrics("event"), event)

    def _apply_due(self, epoch: int) -> None:
        """The scenario's entries due at this step: joint faults applied here (as every placement applies them: the
        driver's `faults_due`), the others requested from the supervisor."""
        for f in faults_due(self.robot, epoch, self.apply_fault):
            self.node.log.info("scenario: requesting %s (%s)", describe(f), f.id)
            self.node.send(self.keys.fault("request"), f)
            # on the timeline at its exact step: the supervisor that applies it knows the step only roughly
            self._event("scenario", ",".join(f.targets), f"{describe(f)} requested")

    # -- the step ----------------------------------------------------------------------------------
    def _publish_step(self) -> None:
        e = self.epoch
        assert e is not None
        robot, k, send = self.robot, self.keys, self.node.send
        if self.scenario is not None:
            self._apply_due(e.epoch)
        q, sense, task = robot.observations(e.epoch)  # what the encoders read and the agents sense
        # The root begins once it holds both the task and its own reading: put them back to back, so they
        # reach it in one burst (one wake-up); the others' readings are needed only a hop later.
        t = robot.t
        if self.clock is not None:
            self.clock.set(e.epoch, t)
        for a in self._obs_first:
            send(k.obs(a), Obs(epoch=e.epoch, step=t, q=q[a], sense=sense[a]))
        send(k.task, task)
        for a in self._obs_after:
            send(k.obs(a), Obs(epoch=e.epoch, step=t, q=q[a], sense=sense[a]))
        self.cmds = {}
        self.step_started = time.perf_counter()
        # Nobody expected (every agent down): the deadline runs the step rather than the joints racing.
        self.waiting = set(self.dof_set - self.down)
        if self._deadline is None:  # the watchdog runs through the epoch (_on_watchdog): armed from the loop
            self._arm(self.cfg.deadline_ms / 1000)

    def _advance(self) -> None:
        e = self.epoch
        assert e is not None
        for name, target, detail in self.robot.move(self.cmds):
            self._event(name, target, detail)
        self.longest_step = max(self.longest_step, time.perf_counter() - self.step_started)
        self.total_steps += 1
        if self.robot.t < e.steps:
            if self.paused:
                self.held = True
                return
            self._publish_step()
            return
        seconds = time.perf_counter() - self.started
        if self.clock is not None:
            self.clock.set(e.epoch, self.robot.t)
        self._done(self.robot.done(e.epoch, e.steps, self.missed, seconds, self.longest_step))
        self.epoch = None

    def _done(self, m: EpochDone) -> None:
        """The epoch is over: its metrics to the observers (a fleet's sim sends every robot's in one)."""
        self._send_done(m)

    def _send_done(self, m: EpochDone) -> None:
        """An epoch's end out, kept until the next: the supervisor asks for it again with the epoch's start."""
        self._sent_done = m
        self.node.send(self.keys.metrics("epoch"), m)

    @property
    def applied(self) -> dict[str, float]:
        """The increments the last step applied, by joint."""
        return self.robot.applied

    @property
    def t(self) -> int:
        """The running step of the epoch."""
        return self.robot.t

    def goal(self) -> tuple[float, ...]:
        """The goal of the running step."""
        return self.robot.goal()
