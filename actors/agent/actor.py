"""The agent actor: one joint (or a compound agent with no joint) running the lockstep step
(docs/architecture.md, "The step").

Step t, as seen by agent i:
  begin   when it holds its encoder reading q_i (sim/obs) and its base frame (the parent's `down`; the root reads
          the task observation instead, and its task turns it into the goal and the reward r(t-1)): compose the
          joint frame, send each child its base frame, the goal, r(t-1) and the task's context.
  finish  when every child has answered `up` (a leaf finishes at once): it sends `up` to its parent at once (the
          subtree's tips, its own action of step t-1, its task's aggregate of the subtree), then defines
          S_i = <q_i, theta_i, d_i, g_i> plus its task's and its learner's extra variables, counts the children's
          actions of step t-1 (carried by their `up` of step t), learns from (s(t-1), a(t-1), r(t-1), s(t)), picks
          a(t) by the joint action selection mechanism (leaving out what its task says it must) and sends `cmd`.
          After the last step of an epoch it sends one more `up` (step = steps) with that step's action, so the
          parent's counts are whole before a checkpoint.
Sending `up` before learning takes the learners of all but the root off the step's critical path: they run while the
pass goes on up. The parent learns exactly what it would with the actions a step earlier: its choice at t needs only
the counts up to t-1 (Eq. 7) and the joint action of t-1 (Eq. 6). Messages for a newer step supersede an unfinished
older one (the sim has moved on past its deadline). The task is the agent's `AgentTask` (actors/tasks/base.py):
this file names none. What an agent computes of the step is the step library's (actors/step/): the passes
(`AgentPasses`), and its learner built, started, observing, learning and deciding through the driver's per-agent
pieces (actors/step/swarm.py), as in the plain loops; this file buffers the messages and speaks the wire.
"""

from __future__ import annotations

import asyncio
from dataclasses import dataclass, field
from typing import Any

from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.files.runfile import kind_of, learner_settings, task_of
from kinswarm.actors.learning.kinds import JointLearner
from kinswarm.actors.runtime import Node
from kinswarm.actors.step.passes import AgentPasses, TopDown, visible_actions
from kinswarm.actors.step.swarm import agent_learner, drop_transition, learn_and_decide, observe_children, start_epoch
from kinswarm.actors.step.trace import StepTrace
from kinswarm.actors.tasks.base import StepView
from kinswarm.protocol.keys import StepKey, agent_keys
from kinswarm.protocol.messages import Bye, Checkpoint, Cmd, Down, Fault, Obs, Readings, Stop, Task, Up
from kinswarm.protocol.topology import Topology

from .memory import Memory
from .standin import StandIn, WakeGuard

Key = tuple[int, int]  # (epoch, step)


@dataclass
class _Step:
    key: Key
    top: TopDown  # frame, link end, reading, goal, r(t-1), context (actors/step/passes.py)
    waiting: frozenset[str]  # the live agents whose `up` this step needs: children, or adopted ones' children
    tips: dict[str, tuple[float, ...]]  # end effectors of adopted leaves, computed here
    ups: dict[str, Up] = field(default_factory=dict)  # by sender


class Agent:
    def __init__(self, cfg: RunConfig, topo: Topology, agent_id: str, node: Node, learner: Any = None) -> None:
        """`learner`: the learner to decide with (a fleet's lane shares its agent's: actors/agent/fleet.py); by
        default its own."""
        self.cfg, self.topo, self.node, self.id = cfg, topo, node, agent_id
        self.spec = topo.agents[agent_id]
        self.keys = node.keys
        # a step's keys and constants, made once (they are built on every step otherwise)
        self._down_key = {a: node.keys.down(a) for a in topo.agents}  # a stand-in sends to its adopted ones' children
        self._up_key = node.keys.up(topo.agents[agent_id].parent) if topo.agents[agent_id].parent else ""
        self._cmd_key = node.keys.cmd(agent_id)
        self._children = list(topo.agents[agent_id].children)
        self._waits = frozenset(self._children)
        self._own_q = [agent_id] if topo.agents[agent_id].has_dof else []
        self.is_root = self.spec.parent is None
        # the message each kind of step key it hears carries: the root hears the task, the others their parent's down
        head: dict[str, type] = {"task": Task} if self.is_root else {"down": Down}
        self._carries: dict[str, type] = {"obs": Obs, "up": Up, **head}
        self._ctl = {node.keys.ctl(verb): verb for verb in ("fault", "checkpoint", "stop")}
        task = task_of(cfg)
        self.learner: JointLearner | None = None
        obs = None  # what S_i holds (the task's)
        if self.spec.has_dof:
            settings = learner_settings(task, cfg.learner, cfg.source)[agent_id]
            obs = settings.observation
            kind = kind_of(cfg.learner, cfg.source)
            self.learner = learner or agent_learner(cfg, topo, agent_id, kind, settings)
        self.passes = AgentPasses(topo, agent_id, task, obs, cfg.action_rad)
        self.geom, self.visible = self.passes.geom, self.passes.visible
        self.trace = None  # what it saw and chose, for the recording (run.record_agents)
        if cfg.record_agents and obs is not None:
            self.trace = StepTrace(agent_id, obs.names)
        self.task = self.passes.task
        self.memory = Memory(self)
        self.standin = StandIn(self)
        self.waking = WakeGuard(node, cfg.lease_ms / 1000)
        self.epoch = -1
        self.last_begun: Key = (-1, -1)
        self.last_finished: Key = (-1, -1)
        self.current: _Step | None = None
        self.q_in: dict[str, dict[Key, float]] = {agent_id: {}}  # encoder readings: mine and adopted ones'
        self.head_in: dict[Key, Down | Task] = {}
        self.sense_in: dict[Key, Readings] = {}  # my own Obs.sense, by step
        self.ups_early: dict[Key, dict[str, Up]] = {}
        self.steps_done = 0
        self.decided: tuple[Key, int] | None = None  # my last chosen step and action (sent up a step later)
        # the step whose visible children's actions the learner still awaits, and which of them were lost then
        self.observing: tuple[Key, frozenset[str]] | None = None
        # actions at an epoch's last step from the children's closing `up`, by that step: one child's may come
        # before this agent has finished the step (another child is still on its way)
        self.closing: dict[Key, dict[str, int]] = {}

    # -- wiring ----------------------------------------------------------------------------------
    def step_keys(self) -> list[str]:
        """What this agent hears during a step (handled where it arrives)."""
        k = self.keys
        subs = [k.task if self.is_root else k.down(self.id)]
        if self.spec.has_dof:
            subs.append(k.obs(self.id))
        if self.spec.children:
            subs.append(k.up(self.id))
        return subs

    def stand_in_readings(self, lost: str) -> None:
        """Hear and keep the encoder readings of `lost`, a descendant this agent stands in for (standin.py)."""
        self.q_in.setdefault(lost, {})
        self.node.listen(self.keys.obs(lost))

    def outputs(self) -> list[str]:
        """Every key this agent publishes on during a step; all must be matched before it is alive."""
        k = self.keys
        outs = [f"{k.root}/{key}" for key in agent_keys(self.topo, self.id)[0]]
        if self.trace is not None:
            outs.append(k.metrics("agent"))
        return outs

    # -- the loop ----------------------------------------------------------------------------------
    async def run(self) -> None:
        node, k = self.node, self.keys
        node.listen(k.ctl_all)  # control waits for the loop
        for s in self.step_keys():
            node.listen(s, inline=self._on_step)
        watch = self.standin.watch()
        try:
            while True:  # a neighbour frozen or restarting is waited for, not a reason to leave (its stall is
                try:  # the supervisor's to see and judge)
                    await node.wait_matched([*self.outputs(), k.metrics("event")], timeout=30.0)
                    break
                except TimeoutError as e:
                    node.log.warning("%s; still waiting", e)
            node.declare_alive()
            if self.memory.restored is not None:
                node.send(k.metrics("event"), self.memory.restored)
            ticker = asyncio.create_task(self.waking.watch())  # run()'s own, gone with it (not a TaskGroup: the
            try:  # loop's errors reach the placement as they are, not wrapped in a group)
                await self._loop()
            finally:
                ticker.cancel()
                await asyncio.wait([ticker])  # gone before run() returns (wait, not await: our own cancel still raises)
        finally:
            if watch is not None:
                watch.undeclare()

    async def _loop(self) -> None:
        """Control on the loop; the step messages on Zenoh's thread as they arrive (Node.listen's `inline`), or here
        when they had to wait in the mailbox: either way one at a time, under the node's lock."""
        node, k = self.node, self.keys
        node.serve_inline()
        while True:
            async with node.next() as (key, payload):
                if self._on_step(key, payload):
                    continue
                verb = self._ctl.get(key)
                if key == "__alive__":
                    if (change := self.waking.token(payload.decode())) is not None:
                        self._on_token(change)
                elif verb == "fault":
                    if (f := node.decode(key, payload, Fault)) is not None:
                        node.apply_fault(f)
                elif verb == "checkpoint":
                    if (m4 := node.decode(key, payload, Checkpoint)) is not None:
                        await asyncio.to_thread(self.memory.save, m4)  # the lock held: no step meanwhile
                elif verb == "stop":
                    if node.decode(key, payload, Stop) is not None:
                        node.serve_inline(False)  # no step after the stop
                        node.send(k.rep("bye", self.id), Bye(steps=self.steps_done, rejected=node.rejected))
                        return
                # other ctl verbs are for other actors

    def _on_token(self, change: str) -> None:
        self.standin.on_token(change)

    def _on_step(self, key: str, payload: bytes) -> bool:
        """One step message (obs, task, down, up) handled; False if `key` is not one."""
        step = self._step_of(key)
        if step is None:
            return False
        if (m := self.node.decode(key, payload, self._carries[step.kind])) is not None:
            self._take(step, m)
        return True

    def _step_of(self, key: str) -> StepKey | None:
        """The step key an agent hears (obs, task, down, up), parsed; None for any other key."""
        step = self.keys.parse_step(key)
        return step if step is not None and step.kind in self._carries else None

    def _take(self, step: StepKey, m: Any) -> None:
        """A step message, decoded: an encoder reading, the head of the step (task or down), or a child's up. `step`:
        its key (an obs names its joint, an up its addressee)."""
        if type(m) is Obs:
            agent = step.agent
            if agent in self.q_in:
                self.q_in[agent][(m.epoch, m.step)] = m.q
                if m.sense and agent == self.id:
                    self.sense_in[(m.epoch, m.step)] = m.sense
                self._try_begin((m.epoch, m.step))
        elif type(m) is Up:
            self._on_up(m, step.agent)
        else:
            self.head_in[(m.epoch, m.step)] = m
            self._try_begin((m.epoch, m.step))

    # -- begin: the top-down pass --------------------------------------------------------------------
    def _try_begin(self, key: Key) -> None:
        if key <= self.last_begun:
            return  # stale: a newer step has begun
        epoch, step = key
        if not (0 <= epoch < self.cfg.epochs and 0 <= step < self.cfg.steps):
            self.node.log.warning("ignored step %s: outside this run's epochs and steps", key)
            return
        head = self.head_in.get(key)
        if head is None:
            return
        if self.standin.down:  # a descendant is lost: I stand in for the agents between me and the live ones
            adopted, waiting = self.standin.region()
            needs_q = self._own_q + [a for a in adopted if self.topo.agents[a].has_dof]
        else:  # the usual step: my children, my own reading (hoisted: this runs every step)
            adopted, waiting, needs_q = [], self._children, self._own_q
        q_in = self.q_in
        for a in needs_q:
            if key not in q_in.get(a, ()):
                return
        q = {a: q_in[a].pop(key) for a in needs_q}
        del self.head_in[key]
        own = self.sense_in.pop(key, {})
        # drop everything older: newer steps supersede unfinished older ones (mostly nothing is left to look at)
        for a, readings in q_in.items():
            if readings:
                q_in[a] = {kk: v for kk, v in readings.items() if kk > key}
        if self.head_in:
            self.head_in = {kk: v for kk, v in self.head_in.items() if kk > key}
        if self.sense_in:
            self.sense_in = {kk: v for kk, v in self.sense_in.items() if kk > key}
        self.last_begun = key
        if epoch != self.epoch:
            self.epoch = epoch
            start_epoch(self.passes, self.learner, self.memory.epochs_before + epoch, step)
        elif self.learner is not None and key != (epoch, self.last_finished[1] + 1):
            drop_transition(self.learner, step)  # a missed step: no TD update across the gap
        if adopted or self.standin.adopted:
            self.standin.announce(adopted)

        top = self.passes.begin(head, q.get(self.id, 0.0), own)
        tips: dict[str, tuple[float, ...]] = {}
        send, down, down_key = self.node.send, self.passes.down, self._down_key
        for child, child_base in self.standin.frames_below(self.id, top.end, q, tips):
            send(down_key[child], down(top, child, epoch, step, child_base))
        waits = self._waits if waiting is self._children else frozenset(waiting)
        ups_early = self.ups_early
        self.current = _Step(key, top, waits, tips, ups_early.pop(key, {}) if ups_early else {})
        if ups_early:
            self.ups_early = {kk: v for kk, v in ups_early.items() if kk > key}
        self._try_finish()

    # -- finish: the bottom-up pass ----------------------------------------------------------------
    def _on_up(self, m: Up, addressee: str) -> None:
        child = self.standin.sender_of(m, addressee)
        if child is None:
            return
        if m.step == self.cfg.steps:  # a child's closing `up`: its action at the epoch's last step
            if addressee == self.id:
                self._on_closing(child, m)
            return
        key = (m.epoch, m.step)
        if self.current is not None and self.current.key == key:
            self.current.ups[child] = m
            self._try_finish()
        elif key > self.last_begun:
            self.ups_early.setdefault(key, {})[child] = m

    def _try_finish(self) -> None:
        cur = self.current
        if cur is None or not cur.waiting.issubset(cur.ups):
            return
        self.current = None
        epoch, step = cur.key
        d = self.decided
        last = d[1] if d is not None and d[0] == (epoch, step - 1) else None
        ups = {c: cur.ups[c] for c in cur.waiting}
        tips, view = self.passes.finish(cur.top, epoch, step, ups, last, cur.tips)
        if not self.is_root:  # first: the parent's state needs only the tips (and the task's aggregate)
            self.node.send(self._up_key, self.passes.up(view, tips))
        if self.learner is None:
            self._finished(cur)
        else:  # a fleet's robots' ups leave first, all of them (Node.after_sending): then each robot learns
            self.node.after_sending(lambda: self._learn(cur, view, tips))

    def _learn(self, cur: _Step, view: StepView, tips: dict[str, tuple[float, ...]]) -> None:
        """The rest of the step once `up` has left: the state S_i, the children's actions of the step before, the TD
        update and a(t) (the driver's `learn_and_decide`, as in the plain loops), and `cmd`."""
        assert self.learner is not None
        epoch, step, cfg = view.epoch, view.step, self.cfg
        children = self._children_actions(cur)
        d = self.passes.decide_from(cur.top, view)
        action, delta = learn_and_decide(
            self.learner, self.passes, d, children, epoch, step, cfg.learn, cfg.explore, self.trace
        )
        self.decided = (cur.key, action)
        if self.trace is not None and step == cfg.steps - 1:
            self.node.send(self.keys.metrics("agent"), self.trace.take())
        if self.visible:
            # a lost child's joint holds: to this agent's fictitious play it chose "keep"
            self.observing = (cur.key, frozenset(c for c in self.visible if c not in cur.ups))
            if step == cfg.steps - 1:
                self.closing = {k: v for k, v in self.closing.items() if k >= cur.key}
                self._try_close()
        if step == cfg.steps - 1 and not self.is_root:  # the closing `up`, before the epoch can end
            self.node.send(self._up_key, Up(epoch=epoch, step=cfg.steps, tips=tips, action=action))
        self.node.send(self._cmd_key, Cmd(epoch=epoch, step=step, delta=delta))
        self._finished(cur)

    def _finished(self, cur: _Step) -> None:
        self.last_finished = cur.key
        self.steps_done += 1

    # -- what the children did: fictitious play's counts ---------------------------------------------
    def _children_actions(self, cur: _Step) -> list[int] | None:
        """The visible children's actions of the step before `cur`, which their `up` of `cur` carried (-1 for one
        missing: a child lost or restarted since, and the transition is dropped); None when none are awaited."""
        obs, self.observing = self.observing, None
        epoch, step = cur.key
        if obs is None or obs[0] != (epoch, step - 1):
            return None  # the epoch's first step, or after a gap (_try_begin dropped the transition)
        return visible_actions(self.visible, {c: m.action for c, m in cur.ups.items()}, obs[1])

    def _on_closing(self, child: str, m: Up) -> None:
        if self.learner is None or child not in self.visible or (m.epoch, m.step - 1) < self.last_finished:
            return
        self.closing.setdefault((m.epoch, m.step - 1), {})[child] = m.action
        self._try_close()

    def _try_close(self) -> None:
        """Observe an epoch's last step once every visible child's closing action is in."""
        obs = self.observing
        acts = self.closing.get(obs[0]) if obs is not None else None
        if obs is None or acts is None or not all(c in obs[1] or c in acts for c in self.visible):
            return
        self.observing = None
        del self.closing[obs[0]]
        assert self.learner is not None
        observe_children(self.learner, visible_actions(self.visible, acts, obs[1]), obs[0][1] + 1, self.cfg.learn)
