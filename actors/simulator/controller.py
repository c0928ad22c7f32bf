"""The model-based baselines as an actor: one takes the place of the agents on the same wire — reads the
same encoder readings and task observation, and sends one `cmd` per joint — so learned and
model-based runs go through the same simulator, deadlines and metrics. Its control law is the run's
`controller`: "pinv" (the pseudo-inverse), "greedy" (each joint alone, greedy in the distance), "rule" (each joint
along sign(g_perp), the hand-written control on the agents' own state) or "turn" (each joint toward its own best
angle, sign(g_q): the rule on the turn state). The goal is the task's as it travels: a planar robot's point, a spatial
robot's point or pose (sim/baseline.py); every law moves as the agents do (baseline.move_size)."""

from __future__ import annotations

from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.runtime import Node
from kinswarm.protocol.messages import Bye, Cmd, Obs, Stop, Task
from kinswarm.protocol.topology import Topology
from kinswarm.sim.baseline import greedy_increments, move_size, pinv_increments, rule_increments, turn_increments

LAWS = {"pinv": pinv_increments, "greedy": greedy_increments, "rule": rule_increments, "turn": turn_increments}


class BaselineController:
    def __init__(self, cfg: RunConfig, topo: Topology, node: Node) -> None:
        self.cfg, self.topo, self.node, self.keys = cfg, topo, node, node.keys
        self.dof = topo.dof_agents
        self.law = LAWS[cfg.controller]
        self.q: dict[tuple[int, int], dict[str, float]] = {}
        self.task: dict[tuple[int, int], Task] = {}
        self.steps = 0  # steps commanded, for its Bye

    def outputs(self) -> list[str]:
        return [self.keys.cmd(a) for a in self.dof]

    async def run(self) -> None:
        node, k = self.node, self.keys
        node.listen(k.ctl_all)
        node.listen(k.task)
        for a in self.dof:
            node.listen(k.obs(a))
        await node.wait_matched(self.outputs(), timeout=30.0)
        node.declare_alive()
        while True:
            key, payload = await node.recv()
            if key == k.task:
                if (t := node.decode(key, payload, Task)) is not None:
                    self.task[(t.epoch, t.step)] = t
                    self._try((t.epoch, t.step))
            elif key == k.ctl("stop"):
                if node.decode(key, payload, Stop) is not None:  # goodbye, as every actor says it: the supervisor
                    node.send(k.rep("bye", node.ident), Bye(steps=self.steps, rejected=node.rejected))  # waits for it
                    return
            elif (step := k.parse_step(key)) is not None and step.kind == "obs":
                if (o := node.decode(key, payload, Obs)) is not None:
                    self.q.setdefault((o.epoch, o.step), {})[step.agent] = o.q
                    self._try((o.epoch, o.step))

    def _try(self, step: tuple[int, int]) -> None:
        q, task = self.q.get(step, {}), self.task.get(step)
        if task is None or len(q) < len(self.dof):
            return
        self.q = {s: v for s, v in self.q.items() if s > step}
        self.task = {s: v for s, v in self.task.items() if s > step}
        dq = self.law(self.topo, q, task.goal, max_step=move_size(self.topo, q, task.goal, self.cfg.action_rad))
        for a in self.dof:
            self.node.send(self.keys.cmd(a), Cmd(epoch=step[0], step=step[1], delta=dq[a]))
        self.steps += 1
