"""The simulator actor: the robot, and the clock of the lockstep.

For each step it publishes the task observation to the root and each agent's encoder reading, then
waits for a `cmd` from every DOF agent — or for the step deadline, after which a missing command
means that joint holds — applies the increments (clipped to the action size and the joint limits),
and records the end-effector error. At the end of an epoch it publishes `metrics/epoch`.
"""

from __future__ import annotations

import asyncio
import math
import time

from kinswarm.actors.config import RunConfig
from kinswarm.actors.runtime import Node
from kinswarm.protocol.messages import Cmd, EpochDone, EpochStart, Obs, Stop, Task
from kinswarm.protocol.topology import Topology
from kinswarm.sim.world import World


class SimActor:
    def __init__(self, cfg: RunConfig, topo: Topology, node: Node) -> None:
        self.cfg, self.topo, self.node, self.keys = cfg, topo, node, node.keys
        self.world = World(topo)
        self.dof = topo.dof_agents
        self.max_step = cfg.action_rad * (1 + 1e-9)
        self.epoch: EpochStart | None = None
        self.t = 0
        self.cmds: dict[str, float] = {}
        self.errors: list[float] = []
        self.tips: dict[str, tuple[float, float, float]] = {}
        self.missed = 0
        self.started = 0.0
        self._deadline: asyncio.TimerHandle | None = None

    def outputs(self) -> list[str]:
        return [self.keys.task, *(self.keys.obs(a) for a in self.dof)]

    async def run(self) -> None:
        node, k = self.node, self.keys
        node.listen(k.ctl_all)
        node.listen(k.cmd_all)
        try:
            await node.wait_matched(self.outputs(), timeout=30.0)
            node.declare_alive()
            while True:
                key, payload = await node.recv()
                if key.startswith(k.cmd_all[:-1]):
                    if (m := node.decode(key, payload, Cmd)) is not None:
                        self._on_cmd(k.last_chunk(key), m)
                elif key == k.ctl("epoch"):
                    if (e := node.decode(key, payload, EpochStart)) is not None:
                        self._on_epoch(e)
                elif key == k.ctl("stop"):
                    if node.decode(key, payload, Stop) is not None:
                        return
                elif key == "__deadline__":
                    self._on_deadline(payload)
        finally:
            if self._deadline is not None:
                self._deadline.cancel()
            self.world.close()

    # -- handlers ----------------------------------------------------------------------------------
    def _on_epoch(self, e: EpochStart) -> None:
        self.epoch = e
        self.world.reset()
        self.tips = self.world.tip_poses()
        self.t = 0
        self.errors = []
        self.missed = 0
        self.started = time.perf_counter()
        self._publish_step()

    def _on_cmd(self, agent: str, m: Cmd) -> None:
        e = self.epoch
        if e is None or (m.epoch, m.step) != (e.epoch, self.t):
            return  # late (after the deadline) or from another epoch: the joint already held
        if agent not in self.world.joint_index:
            self.node.log.warning("rejected cmd for %r: not a joint of %s", agent, self.topo.name)
            return
        self.cmds[agent] = max(-self.max_step, min(self.max_step, m.delta))
        if len(self.cmds) == len(self.dof):
            self._advance()

    def _on_deadline(self, token: bytes) -> None:
        e = self.epoch
        if e is not None and token == f"{e.epoch}/{self.t}".encode():
            missing = sorted(set(self.dof) - set(self.cmds))
            self.missed += len(missing)
            self.node.log.warning("step %d/%d: no cmd from %s by the deadline; they hold", e.epoch, self.t, missing)
            self._advance()

    # -- the step ----------------------------------------------------------------------------------
    def _publish_step(self) -> None:
        e = self.epoch
        assert e is not None
        k, send = self.keys, self.node.send
        send(k.task, Task(epoch=e.epoch, step=self.t, goal=e.goal, tips=self.tips))
        q = self.world.joint_positions()
        for a in self.dof:
            send(k.obs(a), Obs(epoch=e.epoch, step=self.t, q=q[a]))
        self.cmds = {}
        token = f"{e.epoch}/{self.t}".encode()
        loop = asyncio.get_running_loop()
        self._deadline = loop.call_later(self.cfg.deadline_ms / 1000, self.node.mailbox.push, "__deadline__", token)

    def _advance(self) -> None:
        e = self.epoch
        assert e is not None
        if self._deadline is not None:
            self._deadline.cancel()
            self._deadline = None
        self.world.apply_increments(self.cmds)
        self.tips = self.world.tip_poses()
        self.errors.append(self.error())
        self.t += 1
        if self.t < e.steps:
            self._publish_step()
            return
        self.node.send(
            self.keys.metrics("epoch"),
            EpochDone(
                epoch=e.epoch,
                steps=e.steps,
                final_error=self.errors[-1],
                mean_error=sum(self.errors) / len(self.errors),
                errors=self.errors,
                final_angles=self.world.joint_positions(),
                missed_cmds=self.missed,
                seconds=time.perf_counter() - self.started,
            ),
        )
        self.epoch = None

    def error(self) -> float:
        """End-effector distance to the goal (the centroid of the end effectors for a tree)."""
        assert self.epoch is not None
        tips = list(self.tips.values())
        x = sum(p[0] for p in tips) / len(tips)
        y = sum(p[1] for p in tips) / len(tips)
        return math.hypot(x - self.epoch.goal[0], y - self.epoch.goal[1])
