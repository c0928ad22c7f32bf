"""The agent actor: one joint (or a compound agent with no joint) running DESIGN §3's lockstep step.

Step t, as seen by agent i:
  begin   when it holds its encoder reading q_i (sim/obs) and its base frame (the parent's `down`;
          the root reads the task observation instead and computes the reward r(t-1) there):
          compose the joint frame, send each child its base frame, the goal and r(t-1).
  finish  when every child has answered `up` (a leaf finishes at once): with the subtree's tips it
          defines S_i = <q_i, theta_i, d_i, g_i>, learns from (s(t-1), a(t-1), r(t-1), s(t)), picks
          a(t) by the joint action selection mechanism, sends `up` to its parent and `cmd` to the sim.
Messages for a newer step supersede an unfinished older one (the sim has moved on past its deadline).
"""

from __future__ import annotations

import asyncio
import math
import zlib
from dataclasses import dataclass, field
from pathlib import Path

from kinswarm.actors.checkpoint import load_checkpoint, save_checkpoint
from kinswarm.actors.config import RunConfig
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.reward import reach_reward
from kinswarm.actors.learning.settings import LearnerSettings
from kinswarm.actors.learning.state import agent_state, joint_frame, link_end
from kinswarm.actors.runtime import Node
from kinswarm.protocol.messages import Checkpoint, Cmd, Down, Obs, Saved, Stop, Task, Up
from kinswarm.protocol.topology import Topology

Key = tuple[int, int]  # (epoch, step)


def agent_seed(seed: int, agent: str) -> list[int]:
    """Per-agent RNG seed: the same in every placement, independent of spawn order."""
    return [seed, zlib.crc32(agent.encode())]


def learner_settings(cfg: RunConfig, topo: Topology) -> LearnerSettings:
    return LearnerSettings.for_reach(topo.reach, **cfg.learner)


@dataclass
class _Step:
    key: Key
    frame: tuple[float, float, float]
    end: tuple[float, float, float]
    q: float
    goal: tuple[float, float]
    reward: float | None
    ups: dict[str, Up] = field(default_factory=dict)


class Agent:
    def __init__(self, cfg: RunConfig, topo: Topology, agent_id: str, node: Node) -> None:
        self.cfg, self.topo, self.node, self.id = cfg, topo, node, agent_id
        self.spec = topo.agents[agent_id]
        self.keys = node.keys
        self.is_root = self.spec.parent is None
        # The paper's neighbourhood: an agent sees the agents one level below it (its DOF children).
        self.visible = [c for c in self.spec.children if topo.agents[c].has_dof]
        self.leaves = topo.subtree_leaves(agent_id)
        # which child an `up` comes from, by the set of tips it reports (computed once, not per message)
        self.child_by_tips = {frozenset(topo.subtree_leaves(c)): c for c in self.spec.children}
        self.learner: Learner | None = None
        self.epochs_before = 0  # epochs trained before this run (from --from), for the lr schedule
        if self.spec.has_dof:
            self.learner = Learner(learner_settings(cfg, topo), len(self.visible), agent_seed(cfg.seed, agent_id))
        self.epoch = -1
        self.last_begun: Key = (-1, -1)
        self.current: _Step | None = None
        self.q_in: dict[Key, float] = {}
        self.head_in: dict[Key, Down | Task] = {}
        self.ups_early: dict[Key, dict[str, Up]] = {}
        self.D_prev: float | None = None  # root only: D_goal(t-1)
        self.steps_done = 0

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

    # -- the loop ----------------------------------------------------------------------------------
    async def run(self) -> None:
        node, k = self.node, self.keys
        for s in self.subscriptions():
            node.listen(s)
        await node.wait_matched(self.outputs(), timeout=30.0)
        node.declare_alive()
        while True:
            key, payload = await node.recv()
            kind = key[len(k.root) + 1 :]
            if kind.startswith("sim/obs/"):
                if (m := node.decode(key, payload, Obs)) is not None:
                    self.q_in[(m.epoch, m.step)] = m.q
                    self._try_begin((m.epoch, m.step))
            elif kind.endswith("/down") or kind == "sim/task":
                m2 = node.decode(key, payload, Task if self.is_root else Down)
                if m2 is not None:
                    self.head_in[(m2.epoch, m2.step)] = m2
                    self._try_begin((m2.epoch, m2.step))
            elif kind.endswith("/up"):
                if (m3 := node.decode(key, payload, Up)) is not None:
                    self._on_up(m3, key)
            elif kind == "ctl/checkpoint":
                if (m4 := node.decode(key, payload, Checkpoint)) is not None:
                    await asyncio.to_thread(self._save, m4)
            elif kind == "ctl/stop":
                if node.decode(key, payload, Stop) is not None:
                    return
            # other ctl verbs are for other actors

    # -- handlers ----------------------------------------------------------------------------------
    def _try_begin(self, key: Key) -> None:
        if key <= self.last_begun:
            return  # stale: a newer step has begun
        if self.spec.has_dof and key not in self.q_in:
            return
        head = self.head_in.get(key)
        if head is None:
            return
        q = self.q_in.get(key, 0.0)
        # drop everything up to this step: newer steps supersede unfinished older ones
        self.q_in = {kk: v for kk, v in self.q_in.items() if kk > key}
        self.head_in = {kk: v for kk, v in self.head_in.items() if kk > key}
        self.last_begun = key
        epoch, step = key
        if epoch != self.epoch:
            self.epoch = epoch
            self.D_prev = None
            if self.learner is not None:
                self.learner.start_epoch(self.epochs_before + epoch)

        if isinstance(head, Task):  # the root: the world's base, the reward from the task observation
            base = self.topo.base
            goal = head.goal
            D = _distance(_centroid([head.tips[leaf] for leaf in self.leaves if leaf in head.tips]), goal)
            reward = None if self.D_prev is None else reach_reward(D, self.D_prev, self.cfg.reward)
            self.D_prev = D
        else:
            base, goal, reward = head.base, head.goal, head.reward
        frame = joint_frame(base, self.spec.offset, q)
        end = link_end(frame, self.spec.link_length)
        for c in self.spec.children:
            self.node.send(self.keys.down(c), Down(epoch=epoch, step=step, base=end, goal=goal, reward=reward))
        self.current = _Step(key, frame, end, q, goal, reward, self.ups_early.pop(key, {}))
        self.ups_early = {kk: v for kk, v in self.ups_early.items() if kk > key}
        self._try_finish()

    def _on_up(self, m: Up, key_expr: str) -> None:
        child = self._child_of(m) if m.tips else None
        if child is None:
            self.node.log.warning("rejected up on %s: tips %s are not from one of my children", key_expr, list(m.tips))
            return
        key = (m.epoch, m.step)
        if self.current is not None and self.current.key == key:
            self.current.ups[child] = m
            self._try_finish()
        elif key > self.last_begun:
            self.ups_early.setdefault(key, {})[child] = m

    def _child_of(self, m: Up) -> str | None:
        """The child whose subtree holds exactly the tips reported."""
        return self.child_by_tips.get(frozenset(m.tips))

    def _try_finish(self) -> None:
        cur = self.current
        if cur is None or len(cur.ups) < len(self.spec.children):
            return
        self.current = None
        epoch, step = cur.key
        if self.spec.is_leaf:
            tips = {self.id: cur.end}
        else:
            tips = {leaf: tip for u in cur.ups.values() for leaf, tip in u.tips.items()}
        action = -1
        if self.learner is not None:
            tip = _centroid([tips[leaf] for leaf in self.leaves])
            s = agent_state(cur.frame, cur.q, tip, cur.goal)
            visible_actions = [cur.ups[c].action for c in self.visible]
            action = self.learner.step(s, cur.reward, visible_actions, learn=self.cfg.learn, explore=self.cfg.explore)
        if not self.is_root:
            self.node.send(self.keys.up(self.spec.parent), Up(epoch=epoch, step=step, tips=tips, action=action))  # type: ignore[arg-type]
        if self.learner is not None:
            delta = (action - 1) * self.cfg.action_rad  # actions 0, 1, 2: decrease, keep, increase
            self.node.send(self.keys.cmd(self.id), Cmd(epoch=epoch, step=step, delta=delta))
        self.steps_done += 1

    def _save(self, m: Checkpoint) -> None:
        path = Path(m.directory) / f"{self.id}.npz"
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
                        "seed": self.cfg.seed,
                    },
                )
            except OSError as e:
                error = f"cannot write {path}: {e}"
                self.node.log.error(error)
        self.node.send(self.keys.rep("agent", self.id), Saved(epoch=m.epoch, path=str(path), error=error))


def _centroid(points: list) -> tuple[float, float]:
    if len(points) == 1:  # a chain: the end effector itself
        return (points[0][0], points[0][1])
    if not points:
        return (math.nan, math.nan)
    n = len(points)
    return (sum(p[0] for p in points) / n, sum(p[1] for p in points) / n)


def _distance(p: tuple[float, float], goal: tuple[float, float]) -> float:
    return math.hypot(p[0] - goal[0], p[1] - goal[1])
