"""The walls scene (paper §5.4): solid box walls in the PyBullet world, per-link signed clearance.

Each `ObstacleSpec` of the scene becomes a fixed box body (mass 0) in the World's PyBullet client, as tall
in z as it needs to be to meet the planar links. A link's clearance is the signed distance between its
capsule and the nearest box from `getClosestPoints` (exact for capsules against boxes: positive apart,
negative in penetration). Walls are solid: `Scene.move` applies the agents' increments, and when the new
configuration would make a link penetrate a wall it takes back, joint by joint (root first), the increments
that cause the penetration; those joints hold and are reported as collisions.

What the agents sense (WallsScene): each its own link's "clearance" and "collided" (its move of the step before was
refused), and with the scene's shield the look-ahead vetoes "shield-" / "shield+" (protocol/scene.py); the root's
task observation the smallest "clearance" and the refused moves ("collisions"); the metrics per step the same two.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass

from kinswarm.protocol.messages import Readings
from kinswarm.protocol.obstacles import ObstacleSpec
from kinswarm.protocol.scene import SceneSpec
from kinswarm.sim.world import World, pb

from .base import Scene

#: Links further than this from every obstacle report this clearance (the query's search radius).
MAX_CLEARANCE = 10.0
#: Penetration tolerance: a link is "in" a wall when its signed clearance is below -PENETRATION_TOL. Touching
#: (clearance 0) is allowed; the tolerance absorbs float32 noise of PyBullet's distance queries.
PENETRATION_TOL = 1e-6
#: Scene.ahead reports the present clearance without a query when its moves cannot come nearer a wall than this.
AHEAD_FAR = 1.0
_HALF_HEIGHT = 1.0  # z half-extent of the wall boxes: the links lie in z = 0


@dataclass(frozen=True)
class Moved:
    """What `Scene.move` did: the increment applied per DOF joint, the joints refused, the clearances after."""

    applied: dict[str, float]
    refused: tuple[str, ...]
    clearance: dict[str, float]


class SceneError(ValueError):
    """The scene cannot be used as given (e.g. the start configuration penetrates a wall)."""


class Walls:
    """Obstacles in `world`'s PyBullet client: clearances, solid moves, the look-ahead."""

    def __init__(self, world: World, obstacles: tuple[ObstacleSpec, ...]) -> None:
        self.world = world
        self.specs = obstacles
        cid = world.client
        self.bodies: list[int] = []
        for spec in self.specs:
            shape = pb.createCollisionShape(
                pb.GEOM_BOX, halfExtents=[*spec.half_extents, _HALF_HEIGHT], physicsClientId=cid
            )
            body = pb.createMultiBody(
                baseMass=0.0,
                baseCollisionShapeIndex=shape,
                basePosition=[*spec.center, 0.0],
                baseOrientation=pb.getQuaternionFromEuler((0.0, 0.0, spec.angle)),
                physicsClientId=cid,
            )
            self.bodies.append(body)
        topo = world.topo
        # links with a body: every agent with a link length > 0 (compound agents may have none)
        self.links = {a: world.joint_index[a] for a in topo.order if topo.agents[a].link_length > 0}
        # what each DOF joint moves: its own link and every link below it, and how far from the joint they reach
        self.moved_by = {a: tuple(b for b in topo.subtree(a) if b in self.links) for a in topo.dof_agents}
        self.radius = {a: topo.reach_below(a) for a in topo.dof_agents}

    def clearances(self) -> dict[str, float]:
        """Signed clearance of every agent's link to the nearest obstacle (MAX_CLEARANCE if none is near)."""
        return {agent: self._clearance(agent) for agent in self.links}

    def _clearance(self, agent: str) -> float:
        cid, robot, link = self.world.client, self.world.body, self.links[agent]
        best = MAX_CLEARANCE
        for body in self.bodies:
            pts = pb.getClosestPoints(
                bodyA=robot, bodyB=body, distance=MAX_CLEARANCE, linkIndexA=link, physicsClientId=cid
            )
            for p in pts:
                best = min(best, float(p[8]))  # contactDistance: negative in penetration
        return best

    def ahead(self, agent: str, step: float, clearance: Mapping[str, float]) -> tuple[float, float]:
        """The look-ahead of the scene's shield: the smallest clearance of the links `agent`'s joint moves
        after its move of -step and of +step alone from the present configuration (`clearance`: the present
        clearances). A joint turning by `step` moves no point below it further than radius x |step| (plus the
        links' radius x |step|, well under AHEAD_FAR's slack), so when no such move can come within AHEAD_FAR of a
        wall both are the present clearance, without a query."""
        now = min((clearance[b] for b in self.moved_by[agent]), default=MAX_CLEARANCE)
        if now - self.radius[agent] * abs(step) > AHEAD_FAR:
            return now, now
        world = self.world
        before = world.joint_positions()
        out = []
        for d in (-step, step):
            world.apply_increments({agent: d})
            out.append(min(self._clearance(b) for b in self.moved_by[agent]))
            world.reset(before)
        return out[0], out[1]

    def penetrating(self, clearance: Mapping[str, float]) -> list[str]:
        return [a for a, c in clearance.items() if c < -PENETRATION_TOL]

    def check_start(self, source: str) -> None:
        """Raise SceneError if the current (start) configuration already penetrates an obstacle."""
        bad = self.penetrating(self.clearances())
        if bad:
            raise SceneError(
                f"{source}: initial_deg: the start configuration puts link(s) {bad} inside an obstacle "
                "(walls are solid; move the obstacles or the start angles)"
            )

    def move(self, deltas: Mapping[str, float]) -> Moved:
        """Apply `deltas` like World.apply_increments, refusing the increments that would penetrate a wall.

        All at once when the result is free; otherwise from the configuration before, the joints' increments
        one at a time in the topology's order (root first), each kept only if no link then penetrates."""
        world = self.world
        before = world.joint_positions()
        applied = world.apply_increments(deltas)
        clearance = self.clearances()
        if not self.penetrating(clearance):
            return Moved(applied, (), clearance)
        world.reset(before)
        applied = dict.fromkeys(applied, 0.0)
        refused: list[str] = []
        clearance_now: dict[str, float] | None = None
        for a in world.topo.dof_agents:
            d = deltas.get(a, 0.0)
            if d == 0.0:
                continue
            keep = world.joint_positions()
            step = world.apply_increments({a: d})[a]
            if step == 0.0:  # at a joint limit: nothing to test
                continue
            c = self.clearances()
            if self.penetrating(c):
                world.reset(keep)
                refused.append(a)
            else:
                applied[a] = step
                clearance_now = c
        if clearance_now is None:
            clearance_now = self.clearances()
        return Moved(applied, tuple(refused), clearance_now)


class WallsScene(Scene):
    shares_world = False  # its obstacles are bodies in the client: another robot's would be among them

    def __init__(self, world: World, spec: SceneSpec, action_rad: float) -> None:
        super().__init__(world, spec, action_rad)
        self.walls = Walls(world, spec.obstacles)
        self.walls.check_start(world.topo.source)
        self.clearance: dict[str, float] = {}  # per link, after the last step's joint actions
        self.refused: tuple[str, ...] = ()  # joints whose increment of the last step was refused
        self.collisions: list[float] = []  # per step of the epoch: how many increments were refused
        self.min_clearance: list[float] = []  # per step of the epoch: the smallest link clearance

    def reset(self) -> None:
        self.clearance, self.refused = self.walls.clearances(), ()
        self.collisions, self.min_clearance = [], []

    def move(self, deltas: Mapping[str, float]) -> dict[str, float]:
        moved = self.walls.move(deltas)
        self.clearance, self.refused = moved.clearance, moved.refused
        self.collisions.append(float(len(moved.refused)))
        self.min_clearance.append(min(moved.clearance.values()) if moved.clearance else 0.0)
        return moved.applied

    def agent_sense(self, agent: str) -> Readings:
        out: Readings = {"collided": 1.0 if agent in self.refused else 0.0}
        if agent in self.clearance:
            out["clearance"] = self.clearance[agent]
        if self.spec.shield > 0.0:
            ahead = self.walls.ahead(agent, self.action_rad, self.clearance)
            out["shield-"], out["shield+"] = (1.0 if c < self.spec.shield else 0.0 for c in ahead)
        return out

    def task_sense(self) -> Readings:
        out: Readings = {"collisions": float(len(self.refused))}
        if self.clearance:
            out["clearance"] = min(self.clearance.values())
        return out

    def traces(self) -> dict[str, list[float]]:
        return {"collisions": list(self.collisions), "clearance": [round(v, 5) for v in self.min_clearance]}


SCENE = WallsScene
