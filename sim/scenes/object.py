"""The object scene (paper §5.5): the fingers press on a fixed object (contact.py: the object, the contact model).

The object is solid: after the step's moves, a finger with a link deeper than max_depth goes back (its joints hold,
counted as blocked); then the contact model advances one time unit. Each fingertip agent senses its own contact
("contact", "fn", "ft", "margin"); the root's task observation carries the net wrench and every contact
(GraspScene.task_sense); the error is the fingertips' mean distance to their grasp points; the metrics keep the
forces per step. Every joint agent senses "collided": its own move of the step was refused by the object (asked
for, not executed), what the corridor's walls report the same way (walls.py).
"""

from __future__ import annotations

from collections.abc import Mapping

from kinswarm.protocol.messages import Readings
from kinswarm.protocol.scene import SceneSpec
from kinswarm.sim.world import World

from .base import Pose, Scene
from .contact import GraspScene


class ObjectScene(Scene):
    shares_world = False  # the object is pushed by the simulated contacts: one per robot, in a world of its own

    def __init__(self, world: World, spec: SceneSpec, action_rad: float) -> None:
        super().__init__(world, spec, action_rad)
        assert spec.object is not None
        self.contacts = GraspScene(world, spec.object)
        self.rows: dict[str, list[float]] = {}
        self.refused: frozenset[str] = frozenset()  # the agents whose own move of the last step was refused

    def reset(self) -> None:
        self.contacts.reset()
        self.rows = {}
        self.refused = frozenset()

    def move(self, deltas: Mapping[str, float]) -> dict[str, float]:
        g, world = self.contacts, self.world
        q_before = world.joint_positions()
        applied = world.apply_increments(deltas)
        deep = g.too_deep()
        if deep:
            q = world.joint_positions()
            for leaf in deep:
                for a in g.fingers[leaf]:
                    q[a] = q_before[a]
                    applied[a] = 0.0
            world.reset(q)
            g.blocked += len(deep)
            if g.spec.solid == "pad":  # the joints whose own move keeps the finger out still move
                self._one_by_one(deep, deltas, applied)
        # refused by the object (not by a joint limit): a finger's joint whose asked move was undone
        self.refused = frozenset(a for leaf in deep for a in g.fingers[leaf] if deltas.get(a) and not applied.get(a))
        g.sense_contacts()
        fx, fy, tau = g.wrench
        row = {"net_fx": fx, "net_fy": fy, "net_torque": tau}
        for leaf, r in g.readings.items():
            row[f"fn/{leaf}"] = r.fn
            row[f"ft/{leaf}"] = r.ft
            row[f"margin/{leaf}"] = r.margin
            row[f"contact/{leaf}"] = 1.0 if r.contact else 0.0
        for name, v in row.items():
            self.rows.setdefault(name, []).append(round(v, 5))
        return applied

    def _one_by_one(self, deep: list[str], deltas: Mapping[str, float], applied: dict[str, float]) -> None:
        """Each refused finger's joints, root first: a joint's move is kept if the finger then stays out."""
        g, world = self.contacts, self.world
        for leaf in deep:
            for a in g.fingers[leaf]:
                if not deltas.get(a):
                    continue
                q = world.joint_positions()
                step = world.apply_increments({a: deltas[a]})
                if leaf in g.too_deep():
                    world.reset(q)
                else:
                    applied[a] = step.get(a, 0.0)

    def agent_sense(self, agent: str) -> Readings:
        out: Readings = {"collided": 1.0 if agent in self.refused else 0.0}
        if agent in self.contacts.readings:
            out.update(self.contacts.tip_sense(agent))
        return out

    def task_sense(self) -> Readings:
        return self.contacts.task_sense()

    def error(self, tips: Mapping[str, Pose], goal: tuple[float, float]) -> float:
        return self.contacts.goal_error(dict(tips))

    def traces(self) -> dict[str, list[float]]:
        return self.rows


SCENE = ObjectScene
