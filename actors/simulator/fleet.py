"""The simulator of a fleet (run.fleet = B > 1): B robots in lockstep, each in a world of its own.

Each robot is a lane: a `SimActor` of its own (its world, scene, joint faults, the step it waits on, its errors)
whose node is a `Lane` of this actor's one Node. Lane 0 is this actor itself: it subscribes, keeps the clock (the
deadline's watchdog, holding steps while a host is silent), reports the joints' status and says goodbye. The
commands of a step arrive as one Batch per agent (an item per robot) and each lane takes its own; what the lanes
publish while handling one mailbox item or one batch leaves as one Batch per key (Node.gathering). An epoch ends
when every robot's has: one EpochDone, robot 0's with every robot's final error (`fleet`). Joint faults, live or
from the scenario, apply to every robot. Nothing here knows a scene.
"""

from __future__ import annotations

import asyncio
import dataclasses
from typing import Any

from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.runtime import Lane, Node
from kinswarm.protocol.faults import JOINT_FAULTS, expand_targets
from kinswarm.protocol.messages import Cmd, EpochDone, EpochStart, Event, Fault
from kinswarm.protocol.topology import Topology
from kinswarm.sim.scenes import scene_class
from kinswarm.sim.world import World

from .actor import ALIVE, SimActor

PER_CLIENT = 8  # robots to a PyBullet client, where the scene lets them share one (World's `beside`)


class FleetSim(SimActor):
    def __init__(self, cfg: RunConfig, topo: Topology, node: Node) -> None:
        node.fleet = cfg.fleet
        self.fleet_node = node
        super().__init__(cfg, topo, Lane(node, 0))  # type: ignore[arg-type]
        self.lanes: list[SimActor] = [self]
        self._finished: dict[int, EpochDone] = {}  # robot -> its EpochDone of the running epoch
        try:
            for robot in range(1, cfg.fleet):
                self.lanes.append(_SimLane(cfg, topo, Lane(node, robot), self))  # type: ignore[arg-type]
        except BaseException:
            self._close_lanes()
            self.world.close()
            raise

    def _close_lanes(self) -> None:
        for lane in self.lanes[1:]:
            lane.world.close()

    async def run(self) -> None:
        loop = asyncio.get_running_loop()
        for lane in self.lanes[1:]:
            lane._loop = loop
        try:
            await super().run()
        finally:
            self._close_lanes()

    # -- dispatch: every robot's share, one batch out per key ------------------------------------------------------
    def handle(self, key: str, payload: bytes) -> bool:
        node, k = self.fleet_node, self.keys
        with node.gathering():
            if key.startswith(self._cmd_prefix):
                self._on_cmd_sample(key, payload)
            elif key == ALIVE:
                for lane in self.lanes:
                    lane._on_token(payload)
            elif key == k.ctl("fault"):
                if (f := node.decode(key, payload, Fault)) is not None:
                    for lane in self.lanes:
                        lane.apply_fault(f)
            elif key == k.ctl("epoch"):
                if (e := node.decode(key, payload, EpochStart)) is not None:
                    spread = len(e.goals) == len(self.lanes) and len(e.starts) in (0, len(self.lanes))
                    for robot, lane in enumerate(self.lanes):  # each robot its own goal and start, when spread
                        own = {"goal": e.goals[robot]} if spread else {}
                        if spread and e.starts:
                            own["start"] = e.starts[robot]
                        lane._on_epoch(dataclasses.replace(e, **own) if own else e)
            else:  # the watchdog, status, heartbeats, pauses, stop: the clock's and the actor's, lane 0's
                return super().handle(key, payload)
        return False

    def _on_cmd_sample(self, key: str, payload: Any) -> None:  # Zenoh's thread (inline) or the loop
        node = self.fleet_node
        if (batch := node.decode_batch(key, payload, Cmd)) is not None:
            agent, lanes = self._agent_of(key), self.lanes
            with node.gathering():
                for robot, m in zip(batch.robots, batch.items, strict=True):
                    lanes[robot]._on_cmd(agent, m)

    def _on_watchdog(self) -> None:
        """Lane 0's watchdog is the fleet's: every robot's running step is checked against its deadline."""
        for lane in self.lanes[1:]:
            lane._on_watchdog()
        super()._on_watchdog()
        if self._deadline is None and self.epoch is None and any(lane.epoch is not None for lane in self.lanes):
            self._arm(self.cfg.deadline_ms / 1000)  # robot 0 is done, another robot's step is not

    def _check_pause(self) -> None:
        super()._check_pause()
        if not self.silence.paused:  # every host heard again: the robots held go on
            for lane in self.lanes[1:]:
                if lane.held and lane.epoch is not None:
                    lane.held = False
                    lane._publish_step()

    def _done(self, m: EpochDone) -> None:
        self._finished[0] = m
        self._fleet_done()

    def _fleet_done(self) -> None:
        if len(self._finished) < len(self.lanes):
            return
        done, self._finished = self._finished, {}
        fleet = [done[robot].final_error for robot in range(len(self.lanes))]
        self._send_done(dataclasses.replace(done[0], fleet=fleet))


class _SimLane(SimActor):
    """Robot b > 0: its world and its step; the clock and the pauses are the fleet's (lane 0's). Its events are
    lane 0's too (a fault on every robot is announced once), but for the joints faulted on this robot alone."""

    def __init__(self, cfg: RunConfig, topo: Topology, node: Node, fleet: FleetSim) -> None:
        self.fleet = fleet
        super().__init__(cfg, topo, node)
        self.robot_index = node.robot  # type: ignore[attr-defined]
        self._own: set[str] = set()  # joints with a fault on this robot alone: their events are this lane's to send

    def _world(self, topo: Topology) -> World:
        """Robots in free space share PyBullet clients, PER_CLIENT to one (a client costs ~28 MB; a body added to one
        makes every joint write of the others dearer: ~20 us a robot-step at 8 to a client, ~130 at 64)."""
        robot = self.node.robot  # type: ignore[attr-defined]
        if robot % PER_CLIENT == 0 or not scene_class(self.cfg.scene_spec.kind).shares_world:
            return World(topo)
        return World(topo, beside=self.fleet.lanes[robot - robot % PER_CLIENT].world)

    def apply_fault(self, f: Fault) -> None:
        if f.robot == self.robot_index and f.fault in JOINT_FAULTS:
            targets = expand_targets(f.targets, list(self.dof))
            self._own.update(targets)
            super().apply_fault(f)
            if f.fault == "free":
                self._own.difference_update(targets)
        else:
            super().apply_fault(f)

    def _event(self, name: str, target: str, detail: str) -> None:
        if target in self._own:
            epoch, step = self.now()
            event = Event(epoch=epoch, step=step, event=name, target=target, detail=detail)
            self.fleet.node.send(self.keys.metrics("event"), event)

    @property
    def paused(self) -> bool:
        return self.fleet.silence.paused

    def _arm(self, delay: float) -> None:
        pass  # lane 0's watchdog checks this robot's step (FleetSim._on_watchdog)

    def _done(self, m: EpochDone) -> None:
        self.fleet._finished[self.node.robot] = m  # type: ignore[attr-defined]
        self.fleet._fleet_done()
