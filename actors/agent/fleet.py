"""An agent of a fleet (run.fleet = B > 1): B robots in lockstep through one swarm, this agent the same joint of
every robot.

Each robot is a lane: an `Agent` of its own (its step, its standing in for lost neighbours, its task's per-robot
memory) whose node is a `Lane` of this agent's one Node, and whose learner is a `LearnerLane` of this agent's one
learner (actors/learning/fleet.py): the joint learns from every robot's transitions. Lane 0 is this actor itself (it
subscribes, checkpoints, says goodbye). A step message arrives as one Batch (protocol/messages.py) with an item per
robot; the lanes take their items in robot order, and what they send in handling it leaves as one Batch per key
(Node.gathering). The agent code is the one robot's: nothing here knows a task.
"""

from __future__ import annotations

from typing import Any

from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.learning.fleet import LearnerLane
from kinswarm.actors.runtime import Lane, Node
from kinswarm.protocol.topology import Topology

from .actor import Agent


class FleetAgent(Agent):
    def __init__(self, cfg: RunConfig, topo: Topology, agent_id: str, node: Node) -> None:
        node.fleet = cfg.fleet
        self.fleet_node = node
        super().__init__(cfg, topo, agent_id, Lane(node, 0))  # type: ignore[arg-type]
        shared = self.learner
        if shared is not None:
            self.learner = LearnerLane(shared)  # type: ignore[assignment]
        self.lanes: list[Agent] = [self]
        for robot in range(1, cfg.fleet):
            lane = Agent(cfg, topo, agent_id, Lane(node, robot), LearnerLane(shared) if shared else None)  # type: ignore[arg-type]
            lane.trace = None  # what robot 0's lane saw is the recording's
            lane.memory = self.memory  # one learned state: one checkpoint, one count of epochs trained before
            self.lanes.append(lane)

    def _on_token(self, change: str) -> None:
        for lane in self.lanes:
            lane.standin.on_token(change)

    def _on_step(self, key: str, payload: Any) -> bool:
        step = self._step_of(key)
        if step is None:
            return False
        node = self.fleet_node
        if (batch := node.decode_batch(key, payload, self._carries[step.kind])) is not None:
            lanes = self.lanes
            with node.gathering():
                for robot, m in zip(batch.robots, batch.items, strict=True):
                    lanes[robot]._take(step, m)
        return True
