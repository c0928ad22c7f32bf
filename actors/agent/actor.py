"""The agent actor: one joint (or a compound agent with no joint) running DESIGN §3's lockstep step.

Step t, as seen by agent i:
  begin   when it holds its encoder reading q_i (sim/obs) and its base frame (the parent's `down`;
          the root reads the task observation instead and computes the reward r(t-1) there):
          compose the joint frame, send each child its base frame, the goal and r(t-1).
  finish  when every child has answered `up` (a leaf finishes at once): it sends `up` to its parent at
          once (the subtree's tips, and its own action of step t-1), then, with the tips, defines
          S_i = <q_i, theta_i, d_i, g_i>, counts the children's actions of step t-1 (carried by their
          `up` of step t), learns from (s(t-1), a(t-1), r(t-1), s(t)), picks a(t) by the joint action
          selection mechanism and sends `cmd` to the sim. After the last step of an epoch it sends one more
          `up` (step = steps) with that step's action, so the parent's counts are whole before a checkpoint.
Sending `up` before learning takes the learners of all but the root off the step's critical path: they
run while the pass goes on up. The parent learns exactly what it would with the actions a step earlier:
its choice at t needs only the counts up to t-1 (Eq. 7) and the joint action of t-1 (Eq. 6).
Messages for a newer step supersede an unfinished older one (the sim has moved on past its deadline).

Re-wiring (DESIGN §5): when a descendant's liveliness token goes away (killed, frozen, cut off), the
nearest live ancestor adopts its children: it reads the lost joint's encoder, composes the frames the
lost agent would have sent, sends them down and collects the ups addressed to it. The lost joint holds
(the sim stops waiting for it; to the adopter's learner its action is "keep"). Control is handed back
at the first step after the token returns. A lost root has no ancestor: its children wait for it (each
step then ends at the sim's deadline) until the supervisor has restarted it.
"""

from __future__ import annotations

import asyncio
import math
import zlib
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from kinswarm.actors.checkpoint import CheckpointError, digest, load_checkpoint, load_latest, save_checkpoint
from kinswarm.actors.config import RunConfig
from kinswarm.actors.learning.grasp import GraspReward, grasp_learner_settings
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.reward import (
    SETTLE_RADIUS,
    corridor_reward,
    follow_leader_distance,
    next_waypoint,
    path_distance,
    reach_reward,
)
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.actors.learning.state import agent_state, joint_frame, link_end, own_extras
from kinswarm.actors.runtime import Node
from kinswarm.protocol.messages import Bye, Checkpoint, Cmd, Down, Event, Fault, Obs, Saved, Stop, Task, Up
from kinswarm.protocol.topology import Topology

Key = tuple[int, int]  # (epoch, step)


def agent_seed(seed: int, agent: str) -> list[int]:
    """Per-agent RNG seed: the same in every placement, independent of spawn order."""
    return [seed, zlib.crc32(agent.encode())]


def learner_settings(cfg: RunConfig, topo: Topology, agent_id: str | None = None) -> LearnerSettings:
    if topo.object is not None and agent_id is not None:  # a grasp scene: the finger agents' kinds
        obj = topo.object
        finger = max(sum(topo.agents[a].link_length for a in _path(topo, leaf)) for leaf in topo.end_effectors)
        fn_max = (obj.kn + obj.cn) * obj.max_depth
        return grasp_learner_settings(finger, topo.agents[agent_id].is_leaf, fn_max, cfg.learner)
    settings = LearnerSettings.for_reach(topo.reach, **cfg.learner)
    if (settings.clearance_state or settings.collision_state or settings.shield) and not topo.obstacles:
        raise ValueError(
            f"learner settings clearance_state/collision_state/shield need a scene with obstacles; {topo.source} "
            "has no [[obstacle]]"
        )
    if settings.follow_leader > 0.0 and topo.via is None:
        raise ValueError(
            f"learner setting follow_leader needs the scene's [task] via (the corridor's axis); {topo.source} has none"
        )
    return settings


@dataclass
class _Step:
    key: Key
    frame: tuple[float, float, float]
    end: tuple[float, float, float]
    q: float
    goal: tuple[float, float]
    reward: float | None
    waiting: frozenset[str]  # the live agents whose `up` this step needs: children, or adopted ones' children
    tips: dict[str, tuple[float, float, float]]  # end effectors of adopted leaves, computed here
    ups: dict[str, Up] = field(default_factory=dict)  # by sender
    sense: tuple[float | None, int] = (None, 0)  # scenes with obstacles: my link's clearance, my move refused


class Agent:
    def __init__(self, cfg: RunConfig, topo: Topology, agent_id: str, node: Node) -> None:
        self.cfg, self.topo, self.node, self.id = cfg, topo, node, agent_id
        self.spec = topo.agents[agent_id]
        self.keys = node.keys
        self.is_root = self.spec.parent is None
        # The paper's neighbourhood: an agent sees the agents one level below it (its DOF children).
        self.visible = [c for c in self.spec.children if topo.agents[c].has_dof]
        self.leaves = topo.subtree_leaves(agent_id)
        self.descendants = set(_below(topo, agent_id))
        # who sent an `up` addressed to x (me, or an agent I adopted): the child of x whose subtree holds
        # exactly the tips reported (computed once per x, not per message)
        self.child_by_tips: dict[str, dict[frozenset[str], str]] = {}
        self.learner: Learner | None = None
        self.extra_state: tuple[str, ...] = ()
        self.sense_now: dict[str, float] = {}
        self.epochs_before = 0  # epochs trained before this run (from --from), for the lr schedule
        if self.spec.has_dof:
            settings = learner_settings(cfg, topo, agent_id)
            self.learner = Learner(settings, len(self.visible), agent_seed(cfg.seed, agent_id))
            self.extra_state = settings.extra_state
        self.settle_radius = self.learner.settings.settle_radius if self.learner is not None else SETTLE_RADIUS
        # a grasp scene's root is the grasp agent: per-finger rewards and force errors (learning/grasp.py)
        self.grasp: GraspReward | None = None
        obj = topo.object
        if self.is_root and obj is not None:
            fine = learner_settings(cfg, topo, topo.dof_agents[0]).fine_action  # the fingers' fine steps
            self.grasp = GraspReward(
                cfg.reward, obj.grasp, obj.center, obj.half_extents, kn=obj.kn, kt=obj.kt, fine_action=fine
            )
            self.finger_of = {c: topo.subtree_leaves(c)[0] for c in self.spec.children}
        # my own Obs.sense by step (a fingertip's contact, the shield's look-ahead)
        self.local_in: dict[Key, dict[str, float]] = {}
        self.epoch = -1
        self.last_begun: Key = (-1, -1)
        self.last_finished: Key = (-1, -1)
        self.current: _Step | None = None
        self.q_in: dict[str, dict[Key, float]] = {agent_id: {}}  # encoder readings: mine and adopted ones'
        self.head_in: dict[Key, Down | Task] = {}
        self.sense_in: dict[Key, tuple[float | None, int]] = {}  # my obs' clearance and collided, by step
        self.ups_early: dict[Key, dict[str, Up]] = {}
        self.D_prev: float | None = None  # root only: D_goal(t-1)
        self.waypoint = 0  # root only: the current sub-goal of the scene's [task] waypoints in this epoch
        self.fl_prev: float | None = None  # follow_leader: my D_i(t-1)
        self.fl_behind = _follow_leader_behind(topo, agent_id, self.learner)  # follow_leader: links below me, or None
        self.steps_done = 0
        self.down: set[str] = set()  # descendants whose liveliness token went away
        self.adopted: tuple[str, ...] = ()  # the lost agents this agent stood in for at its last step
        self.listening: set[str] = set()  # lost agents whose obs/up keys this agent subscribed to
        self.restored: Event | None = None  # what a restart restored, announced once alive
        self.decided: tuple[Key, int] | None = None  # my last chosen step and action (sent up a step later)
        self.tabu: dict[int, tuple[float, float]] = {}  # tabu_memory: refused action -> where the tip was then
        # the step whose visible children's actions the learner still awaits, and which of them were lost then
        self.observing: tuple[Key, frozenset[str]] | None = None
        # actions at an epoch's last step from the children's closing `up`, by that step: one child's may come
        # before this agent has finished the step (another child is still on its way)
        self.closing: dict[Key, dict[str, int]] = {}

    # -- wiring ----------------------------------------------------------------------------------
    def subscriptions(self) -> list[str]:
        k = self.keys
        subs = [k.ctl_all]
        subs.append(k.task if self.is_root else k.down(self.id))
        if self.spec.has_dof:
            subs.append(k.obs(self.id))
        if self.spec.children:
            subs.append(k.up(self.id))
        return subs

    def outputs(self) -> list[str]:
        """Every key this agent publishes on during a step; all must be matched before it is alive."""
        k = self.keys
        outs = [k.down(c) for c in self.spec.children]
        if not self.is_root:
            outs.append(k.up(self.spec.parent))  # type: ignore[arg-type]
        if self.spec.has_dof:
            outs.append(k.cmd(self.id))
        return outs

    def restore(self, directory: Path) -> None:
        """Start from a previous run's checkpoint (`--from`)."""
        if self.learner is None:
            return
        arrays, meta = load_checkpoint(directory / f"{self.id}.npz", agent=self.id)
        self.learner.load_state_dict(arrays)
        self.epochs_before = int(meta.get("epochs_trained", 0))

    def resume(self, directory: Path) -> None:
        """A restart: the learned state of this run's newest good checkpoint (else the one before it);
        before the first checkpoint, the run's starting point (`--from`, or fresh)."""
        if self.learner is None:
            self.restored = Event(epoch=-1, step=-1, event="restored", target=self.id, detail="no learned state")
            return
        try:
            arrays, meta, used, refused = load_latest(directory / f"{self.id}.npz", agent=self.id)
        except CheckpointError as e:
            if self.cfg.from_dir:
                self.restore(Path(self.cfg.from_dir) / "agents")
            detail = f"no good checkpoint of this run ({e}); starting from {self.cfg.from_dir or 'scratch'}"
            self.node.log.warning(detail)
            self.restored = Event(epoch=-1, step=-1, event="restored", target=self.id, detail=detail)
            return
        for reason in refused:
            self.node.log.warning("checkpoint refused: %s", reason)
        self.learner.load_state_dict(arrays)
        self.epochs_before = int(meta.get("epochs_before", 0))
        detail = (
            f"{used.name} of epoch {meta.get('run_epoch')}: checkpoint sha256={meta['sha256']} "
            f"restored sha256={digest(self.learner.state_dict())}"
        )
        if refused:
            detail += f"; refused: {'; '.join(refused)}"
        epoch = int(meta.get("run_epoch", -1))
        self.restored = Event(epoch=epoch, step=-1, event="restored", target=self.id, detail=detail)

    # -- the loop ----------------------------------------------------------------------------------
    async def run(self) -> None:
        node, k = self.node, self.keys
        for s in self.subscriptions():
            node.listen(s)
        push = node.mailbox.push

        def on_token(sample: object) -> None:  # zenoh thread: `+a3` / `-a3` into the mailbox, in order
            parsed = k.parse_alive(str(sample.key_expr))  # type: ignore[attr-defined]
            if parsed is not None and parsed[1] in self.descendants:
                up = sample.kind == sample.kind.PUT  # type: ignore[attr-defined]
                push("__alive__", ("+" if up else "-").encode() + parsed[1].encode())

        watch = None
        if self.descendants:
            watch = node.session.liveliness().declare_subscriber(k.alive("agent", "*"), on_token, history=True)
        try:
            await node.wait_matched([*self.outputs(), k.metrics("event")], timeout=30.0)
            node.declare_alive()
            if self.restored is not None:
                node.send(k.metrics("event"), self.restored)
            await self._loop()
        finally:
            if watch is not None:
                watch.undeclare()

    async def _loop(self) -> None:
        node, k = self.node, self.keys
        while True:
            key, payload = await node.recv()
            kind = key[len(k.root) + 1 :]
            if kind.startswith("sim/obs/"):
                if (m := node.decode(key, payload, Obs)) is not None:
                    agent = kind[len("sim/obs/") :]
                    if agent in self.q_in:
                        self.q_in[agent][(m.epoch, m.step)] = m.q
                        if agent == self.id and m.clearance is not None:
                            self.sense_in[(m.epoch, m.step)] = (m.clearance, m.collided)
                        if m.sense and agent == self.id:
                            self.local_in[(m.epoch, m.step)] = m.sense
                        self._try_begin((m.epoch, m.step))
            elif kind.endswith("/down") or kind == "sim/task":
                m2 = node.decode(key, payload, Task if self.is_root else Down)
                if m2 is not None:
                    self.head_in[(m2.epoch, m2.step)] = m2
                    self._try_begin((m2.epoch, m2.step))
            elif kind.endswith("/up"):
                if (m3 := node.decode(key, payload, Up)) is not None:
                    self._on_up(m3, kind[2:-3])
            elif key == "__alive__":
                self._on_token(payload.decode())
            elif kind == "ctl/fault":
                if (f := node.decode(key, payload, Fault)) is not None:
                    node.apply_fault(f)
            elif kind == "ctl/checkpoint":
                if (m4 := node.decode(key, payload, Checkpoint)) is not None:
                    await asyncio.to_thread(self._save, m4)
            elif kind == "ctl/stop":
                if node.decode(key, payload, Stop) is not None:
                    node.send(k.rep("bye", self.id), Bye(steps=self.steps_done, rejected=node.rejected))
                    return
            # other ctl verbs are for other actors

    # -- handlers ----------------------------------------------------------------------------------
    def _on_token(self, change: str) -> None:
        agent = change[1:]
        if change[0] == "+":
            self.down.discard(agent)
            return
        self.down.add(agent)
        # subscribe now to what the lost agent heard, so this agent can stand in from the next step
        if agent not in self.listening:
            self.listening.add(agent)
            spec = self.topo.agents[agent]
            if spec.has_dof:
                self.q_in.setdefault(agent, {})
                self.node.listen(self.keys.obs(agent))
            if spec.children:
                self.node.listen(self.keys.up(agent))

    def _region(self) -> tuple[list[str], list[str]]:
        """(adopted, waiting): the lost agents below me down to the live ones, and those live ones."""
        if not self.down:
            return [], list(self.spec.children)
        adopted, waiting = [], []
        stack = list(self.spec.children)
        while stack:
            c = stack.pop()
            if c in self.down:
                adopted.append(c)
                stack.extend(self.topo.agents[c].children)
            else:
                waiting.append(c)
        return adopted, waiting

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
        adopted, waiting = self._region()
        needs_q = [self.id] if self.spec.has_dof else []
        needs_q += [a for a in adopted if self.topo.agents[a].has_dof]
        if any(key not in self.q_in.get(a, {}) for a in needs_q):
            return
        q = {a: self.q_in[a][key] for a in needs_q}
        # drop everything up to this step: newer steps supersede unfinished older ones
        for a, readings in self.q_in.items():
            self.q_in[a] = {kk: v for kk, v in readings.items() if kk > key}
        self.head_in = {kk: v for kk, v in self.head_in.items() if kk > key}
        sense = self.sense_in.pop(key, (None, 0))
        if self.sense_in:
            self.sense_in = {kk: v for kk, v in self.sense_in.items() if kk > key}
        self.last_begun = key
        if epoch != self.epoch:
            self.epoch = epoch
            self.D_prev = None
            self.waypoint = 0
            self.fl_prev = None
            self.tabu = {}
            if self.learner is not None:
                self.learner.start_epoch(self.epochs_before + epoch, t=step)
        elif self.learner is not None and key != (epoch, self.last_finished[1] + 1):
            self.learner.resync(step)  # a missed step: no TD update across the gap
        self._announce(adopted)

        per_child: dict[str, tuple[tuple[float, float], float | None, dict[str, float]]] = {}
        ctx: dict[str, float] = {}  # Down.sense: context from above (a finger's force error)
        if isinstance(head, Task) and self.grasp is not None:  # the grasp agent (paper §5.5)
            base, goal, reward = self.topo.base, head.goal, None
            per_child = self._grasp_down(head, step)
        elif isinstance(head, Task):  # the root: the world's base, the reward from the task observation
            base = self.topo.base
            goal = head.goal
            tip = _centroid([head.tips[leaf] for leaf in self.leaves if leaf in head.tips])
            via = self.topo.via  # a scene's approach path ([task] via): D_goal along it
            if self.topo.waypoints:  # sub-goals ([task] waypoints): the swarm aims at the current one
                self.waypoint, goal, D = next_waypoint(
                    tip, goal, self.topo.waypoints, self.waypoint, self.topo.waypoint_radius
                )
            elif via is not None:
                D = path_distance(tip, goal, via, self.topo.via_width)
            else:
                D = _distance(tip, goal)
            if self.D_prev is None:
                reward = None
            elif head.clearance is not None:  # a scene with obstacles: the corridor's Eq. 11
                reward = corridor_reward(
                    D, self.D_prev, head.clearance, head.collisions, self.cfg.reward, settle_radius=self.settle_radius
                )
            else:
                reward = reach_reward(D, self.D_prev, self.cfg.reward, settle_radius=self.settle_radius)
            self.D_prev = D
        else:
            base, goal, reward, ctx = head.base, head.goal, head.reward, head.sense
        self.sense_now = {**ctx, **self.local_in.pop(key, {})}
        if self.local_in:
            self.local_in = {kk: v for kk, v in self.local_in.items() if kk > key}
        frame = joint_frame(base, self.spec.offset, q.get(self.id, 0.0))
        end = link_end(frame, self.spec.link_length)
        tips: dict[str, tuple[float, float, float]] = {}
        for child, child_base in self._frames_below(self.id, end, q, tips):
            c_goal, c_reward, c_sense = per_child.get(child, (goal, reward, ctx))
            self.node.send(
                self.keys.down(child),
                Down(epoch=epoch, step=step, base=child_base, goal=c_goal, reward=c_reward, sense=c_sense),
            )
        self.current = _Step(
            key,
            frame,
            end,
            q.get(self.id, 0.0),
            goal,
            reward,
            frozenset(waiting),
            tips,
            self.ups_early.pop(key, {}),
            sense,
        )
        self.ups_early = {kk: v for kk, v in self.ups_early.items() if kk > key}
        self._try_finish()

    def _frames_below(
        self, agent: str, end: tuple[float, float, float], q: dict[str, float], tips: dict
    ) -> Iterator[tuple[str, tuple[float, float, float]]]:
        """(child, its base frame) for my children and, through lost agents, for theirs (composing the
        lost agents' frames from their encoders, as they would have); tips of lost leaves go to `tips`."""
        for c in self.topo.agents[agent].children:
            yield c, end
            if c in self.down:
                spec = self.topo.agents[c]
                c_end = link_end(joint_frame(end, spec.offset, q.get(c, 0.0)), spec.link_length)
                if spec.is_leaf:
                    tips[c] = c_end
                yield from self._frames_below(c, c_end, q, tips)

    def _announce(self, adopted: list[str]) -> None:
        now = tuple(sorted(adopted))
        if now == self.adopted:
            return
        for a in sorted(set(now) - set(self.adopted)):
            below = ", ".join(self.topo.agents[a].children) or "its joint only"
            self._event("adopt", a, f"{self.id} stands in for {a} ({below})")
        for a in sorted(set(self.adopted) - set(now)):
            self._event("handback", a, f"{self.id} hands control back to {a}")
        self.adopted = now

    def _event(self, event: str, target: str, detail: str) -> None:
        epoch, step = self.last_begun
        self.node.log.info("%s %s: %s", event, target, detail)
        self.node.send(
            self.keys.metrics("event"), Event(epoch=epoch, step=step, event=event, target=target, detail=detail)
        )

    def _on_up(self, m: Up, addressee: str) -> None:
        if addressee != self.id and addressee not in self.listening:
            return
        by_tips = self.child_by_tips.get(addressee)
        if by_tips is None:
            by_tips = self.child_by_tips[addressee] = {
                frozenset(self.topo.subtree_leaves(c)): c for c in self.topo.agents[addressee].children
            }
        child = by_tips.get(frozenset(m.tips)) if m.tips else None
        if child is None:
            self.node.log.warning(
                "rejected up to %s: tips %s are not from one of its children", addressee, list(m.tips)
            )
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
        if self.spec.is_leaf:
            tips = {self.id: cur.end}
        else:
            tips = dict(cur.tips)
            for c in cur.waiting:
                tips.update(cur.ups[c].tips)
        clearance = _subtree_clearance(cur) if self.topo.obstacles else None  # no work for plain reaching
        if not self.is_root:  # first: the parent's state needs only the tips (and the subtree's clearance)
            d = self.decided
            prev = d[1] if d is not None and d[0] == (epoch, step - 1) else -1
            up = Up(epoch=epoch, step=step, tips=tips, action=prev, clearance=clearance)
            self.node.send(self.keys.up(self.spec.parent), up)  # type: ignore[arg-type]
        if self.learner is not None:
            self._observe(cur)
            tip = _centroid([tips[leaf] for leaf in self.leaves])
            s = agent_state(cur.frame, cur.q, tip, cur.goal, self.learner.settings.g3 == "unsigned")
            reward = cur.reward
            if cur.sense[0] is not None:
                s, reward = self._scene_state(s, reward, cur.sense, clearance)
            if self.fl_behind is not None:
                reward = self._follow_leader(reward, cur)
            if self.extra_state:  # named extra variables (a grasp finger's force error, contact force)
                local = {
                    **self.sense_now,
                    **own_extras(self.extra_state, cur.frame, tip, cur.goal, self.cfg.action_rad),
                }
                s = np.concatenate([s, [local.get(n, 0.0) for n in self.extra_state]])
            avoid = self._tabu(cur, tip) if self.learner.settings.collision_tabu else []
            if self.learner.settings.shield > 0.0:
                avoid += self._shielded()
            action = self.learner.decide(s, reward, learn=self.cfg.learn, explore=self.cfg.explore, avoid=avoid)
            self.decided = (cur.key, action)
            if self.visible:
                # a lost child's joint holds: to this agent's fictitious play it chose "keep"
                self.observing = (cur.key, frozenset(c for c in self.visible if c not in cur.ups))
                if step == self.cfg.steps - 1:
                    self.closing = {k: v for k, v in self.closing.items() if k >= cur.key}
                    self._try_close()
            else:
                self.learner.observe([], learn=self.cfg.learn)
            if step == self.cfg.steps - 1 and not self.is_root:  # the closing `up`, before the epoch can end
                self.node.send(
                    self.keys.up(self.spec.parent),  # type: ignore[arg-type]
                    Up(epoch=epoch, step=self.cfg.steps, tips=tips, action=action),
                )
            delta = (action - 1) * self.cfg.action_rad  # actions 0, 1, 2: decrease, keep, increase
            if self.sense_now.get("fine", 0.0) > 0.5:  # a grasp finger near its contact goal: fine steps
                delta *= self.learner.settings.fine_action
            self.node.send(self.keys.cmd(self.id), Cmd(epoch=epoch, step=step, delta=delta))
        self.last_finished = cur.key
        self.steps_done += 1

    def _tabu(self, cur: _Step, tip: tuple[float, float]) -> list[int]:
        """The actions left out of this step's choice (collision_tabu): the one the wall just refused, and with
        tabu_memory every one refused since the tip of my chain last moved tabu_memory."""
        assert self.learner is not None
        epoch, step = cur.key
        d = self.decided
        refused = d[1] if cur.sense[1] and d is not None and d[0] == (epoch, step - 1) else None
        memory = self.learner.settings.tabu_memory
        if memory <= 0.0:
            return [] if refused is None else [refused]
        if refused is not None:
            self.tabu[refused] = tip
        self.tabu = {a: at for a, at in self.tabu.items() if math.dist(at, tip) < memory}
        return list(self.tabu)

    def _shielded(self) -> list[int]:
        """The moves the shield leaves out: those the simulator's look-ahead (my Obs.sense) finds would bring the
        links I move nearer a wall than LearnerSettings.shield. Without a reading (a lost obs) none."""
        assert self.learner is not None
        shield = self.learner.settings.shield
        ahead = (self.sense_now.get("ahead-"), None, self.sense_now.get("ahead+"))
        return [a for a, c in enumerate(ahead) if c is not None and c < shield]

    def _scene_state(
        self, s: np.ndarray, reward: float | None, sense: tuple[float | None, int], subtree: float | None
    ) -> tuple[np.ndarray, float | None]:
        """A scene with obstacles (§5.4): the optional state variables (my link's clearance or my subtree's,
        whether my move was refused) and the local collision penalty on the reward for my refused move
        (LearnerSettings)."""
        assert self.learner is not None
        st = self.learner.settings
        clearance, collided = sense
        if st.clearance_of == "subtree" and subtree is not None:
            clearance = subtree
        extra = [clearance] * st.clearance_state + [float(collided)] * st.collision_state
        if extra:
            s = np.concatenate((s, extra))
        if reward is not None and collided:
            reward += st.collision_penalty
        return s, reward

    def _follow_leader(self, reward: float | None, cur: _Step) -> float | None:
        """The body-aware local term (LearnerSettings.follow_leader): + w (D_i(t-1) - D_i(t)) for my own link
        end's distance D_i to its place on the corridor's axis (reward.follow_leader_distance)."""
        assert self.learner is not None and self.fl_behind is not None and self.topo.via is not None
        end = (cur.end[0], cur.end[1])
        D_i = follow_leader_distance(end, cur.goal, self.topo.via, self.fl_behind, self.topo.via_width)
        if reward is not None and self.fl_prev is not None:
            reward += self.learner.settings.follow_leader * (self.fl_prev - D_i)
        self.fl_prev = D_i
        return reward

    def _grasp_down(
        self, task: Task, step: int
    ) -> dict[str, tuple[tuple[float, float], float | None, dict[str, float]]]:
        """Per finger: its goal (its grasp point), its reward r(t-1) and its force error, from the task
        observation (the sim's contact readings)."""
        assert self.grasp is not None and self.topo.object is not None
        if step == 0:
            self.grasp.reset()
        rewards, context = self.grasp.step(task.tips, task.sense)
        out = {}
        for child, leaf in self.finger_of.items():
            r = None if rewards is None else rewards[leaf]
            out[child] = (self.grasp.goals[leaf], r, context[leaf])
        return out

    def _observe(self, cur: _Step) -> None:
        """Hand the learner its visible children's actions of the step before `cur`, which their `up` of
        `cur` carried; without all of them (a child lost or restarted since) that transition is dropped."""
        obs, self.observing = self.observing, None
        epoch, step = cur.key
        if obs is None or obs[0] != (epoch, step - 1):
            return  # none awaited: the epoch's first step, or after a gap (_try_begin resynced the learner)
        acts = [1 if c in obs[1] else (cur.ups[c].action if c in cur.ups else -1) for c in self.visible]
        self._observed(acts, step)

    def _observed(self, acts: list[int], step: int) -> None:
        assert self.learner is not None
        if all(0 <= a < self.learner.n_actions for a in acts):
            self.learner.observe(acts, learn=self.cfg.learn)
        else:
            self.learner.resync(step)

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
        self._observed([1 if c in obs[1] else acts[c] for c in self.visible], obs[0][1] + 1)

    def _save(self, m: Checkpoint) -> None:
        # Into this agent's own run directory, where a restart restores from: on another host than the
        # leader's, `m.directory` (the leader's) need not exist.
        path = Path(self.cfg.out) / "agents" / f"{self.id}.npz"
        error = ""
        if self.learner is not None:
            try:
                save_checkpoint(
                    path,
                    self.learner.state_dict(),
                    {
                        "agent": self.id,
                        "topology": self.topo.name,
                        "epochs_trained": self.epochs_before + m.epoch + 1,
                        "epochs_before": self.epochs_before,
                        "run_epoch": m.epoch,
                        "seed": self.cfg.seed,
                    },
                )
            except OSError as e:
                error = f"cannot write {path}: {e}"
                self.node.log.error(error)
        self.node.send(self.keys.rep("agent", self.id), Saved(epoch=m.epoch, path=str(path), error=error))


def _path(topo: Topology, leaf: str) -> list[str]:
    """The agents from the root down to `leaf`."""
    out, a = [], leaf
    while a is not None:
        out.append(a)
        a = topo.agents[a].parent
    return out[::-1]


def _follow_leader_behind(topo: Topology, agent: str, learner: Learner | None) -> float | None:
    """follow_leader: the length of the links below `agent` on its path to the end effector, for one of the
    last follow_leader_links DOF agents of a single-leaf subtree; None when the term is off for this agent."""
    if learner is None or learner.settings.follow_leader <= 0.0 or topo.via is None:
        return None
    leaves = topo.subtree_leaves(agent)
    if len(leaves) != 1:
        return None
    path = _path(topo, leaves[0])
    below = path[path.index(agent) + 1 :]
    if sum(topo.agents[a].has_dof for a in below) >= learner.settings.follow_leader_links:
        return None
    return sum(topo.agents[a].link_length for a in below)


def _below(topo: Topology, agent: str) -> Iterator[str]:
    for c in topo.agents[agent].children:
        yield c
        yield from _below(topo, c)


def _subtree_clearance(cur: _Step) -> float | None:
    """The smallest clearance of my link (my Obs) and of the links below me (my live children's `Up`); links
    of lost agents this one stands in for are not counted (their readings are not gathered)."""
    known = [c for c in (cur.sense[0], *(cur.ups[child].clearance for child in cur.waiting)) if c is not None]
    return min(known) if known else None


def _centroid(points: list) -> tuple[float, float]:
    if len(points) == 1:  # a chain: the end effector itself
        return (points[0][0], points[0][1])
    if not points:
        return (math.nan, math.nan)
    n = len(points)
    return (sum(p[0] for p in points) / n, sum(p[1] for p in points) / n)


def _distance(p: tuple[float, float], goal: tuple[float, float]) -> float:
    return math.hypot(p[0] - goal[0], p[1] - goal[1])
