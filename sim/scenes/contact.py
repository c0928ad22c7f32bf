"""The object scene's physics (paper §5.5): a fixed rectangular object and the fingertip contact model (Fig. 25).

The object has "infinite mass": it never moves; what the fingers do to it is summed into a net force and a
net torque about its centre, the quantities the grasp must drive to zero.

Contact model, per fingertip, one step = one time unit (dt = 1; the paper's epochs last 500 time units):

- penetration depth delta >= 0 into the object, and the contact point p on the object's surface with its
  outward normal n, from PyBullet `getClosestPoints` (exact for these shapes), of what the scene's
  `[scene.object] contact` names: "link" (the default) the fingertip agent's whole capsule, so a distal link
  lying along a face presses with its side or its base; "tip" a sphere of the capsule's radius at the
  fingertip only, a point contact at the fingertip as the paper models it (examples/grasp3.toml);
- normal force (a linear spring-damper, Fig. 25): fn = max(0, kn delta + cn d(delta)/dt) -- no adhesion;
- tangential spring anchored at the first contact point p0 (set when a contact begins, dropped when it
  ends): u = (p - p0) . t, with t = (-n_y, n_x) the surface tangent; ft_trial = kt u + ct du/dt;
- Coulomb: if |ft_trial| > mu fn the contact slips: ft = sign(ft_trial) mu fn and the anchor follows the
  finger, p0 = p - (ft / kt) t, so the spring holds exactly the capped force;
- friction-cone margin = mu fn - |ft_trial|: >= 0 inside the cone (no slip), < 0 by how much it slips.

Sign conventions: f_i = -fn n + ft t is the force fingertip i applies *on the object* (pressing in is
along -n); the net force is F = sum f_i and the net torque tau = sum (p_i - c) x f_i (z component, about
the object's centre c, counter-clockwise positive), in force x length units.

The object is solid for the fingers (a choice, documented in docs/science.md): a step that would put any
link of a finger deeper than `max_depth` into the object is not executed for that finger (its joints
hold, the sim counts it as blocked). Penetration, and so every contact force, is bounded: fn <= kn
max_depth + cn max_depth. Only the fingertip (link or sphere) makes contact forces; an inner link touching
the object is blocked the same way but pushes nothing.

`solid = "pad"` (with contact = "tip"): only the fingertip pad may sink in. With "links" a finger could reach a
face through the face next to it, its distal link sunk up to max_depth across the object's corner (measured:
docs/notebook/grasp.md), a penetration no rigid finger makes. With "pad" no link may be deeper than the
fingertip sphere (by more than PAD_TOL), so a finger presses a face with its tip and cannot cut a corner; and a
finger whose move is refused is not frozen whole: its joints' moves are tried one by one (root first), each kept
if the finger stays out, so one joint pushing in does not hold the other three.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

from kinswarm.protocol.scene import ObjectSpec
from kinswarm.protocol.topology import Topology

Vec = tuple[float, float]

# Distance within which getClosestPoints reports a pair; beyond it a finger is simply out of contact.
_QUERY_DISTANCE = 0.05
# solid = "pad": how much deeper than its fingertip sphere a link may be (the distal capsule ends in that sphere)
PAD_TOL = 0.01


@dataclass(frozen=True)
class ContactReading:
    """One fingertip's contact at one step (all zero when it does not touch)."""

    contact: bool
    depth: float
    fn: float  # normal force magnitude, >= 0
    ft: float  # tangential force along t, after the Coulomb cap
    ft_trial: float  # what the spring-damper asked for
    margin: float  # mu fn - |ft_trial|: < 0 means it slips
    point: Vec  # contact point on the object's surface
    normal: Vec  # the object's outward normal there
    force: Vec  # f_i, the force on the object

    @property
    def slip(self) -> bool:
        return self.contact and self.margin < 0.0


NO_CONTACT = ContactReading(False, 0.0, 0.0, 0.0, 0.0, 0.0, (math.nan, math.nan), (0.0, 0.0), (0.0, 0.0))


class ContactModel:
    """The spring-damper contact of Fig. 25 for a set of fingertips, with their anchors and last depths."""

    def __init__(self, spec: ObjectSpec, dt: float = 1.0) -> None:
        if not dt > 0:
            raise ValueError(f"dt must be > 0, got {dt}")
        self.spec, self.dt = spec, dt
        self._anchor: dict[str, Vec] = {}
        self._depth: dict[str, float] = {}
        self._u: dict[str, float] = {}

    def reset(self) -> None:
        self._anchor.clear()
        self._depth.clear()
        self._u.clear()

    def anchor(self, tip: str) -> Vec | None:
        return self._anchor.get(tip)

    def update(self, tip: str, depth: float, point: Vec | None, normal: Vec | None) -> ContactReading:
        """Advance fingertip `tip` by one step: `depth` > 0 with the contact `point` and outward `normal`,
        or depth <= 0 (out of contact: anchor and history dropped)."""
        sp = self.spec
        if depth <= 0.0 or point is None or normal is None:
            self._anchor.pop(tip, None)
            self._depth.pop(tip, None)
            self._u.pop(tip, None)
            return NO_CONTACT
        nx, ny = normal
        norm = math.hypot(nx, ny)
        nx, ny = nx / norm, ny / norm
        tx, ty = -ny, nx
        first = tip not in self._anchor
        if first:
            self._anchor[tip] = point
        ax, ay = self._anchor[tip]
        u = (point[0] - ax) * tx + (point[1] - ay) * ty
        ddepth = (depth - self._depth.get(tip, 0.0)) / self.dt  # first contact: from zero depth
        du = 0.0 if first else (u - self._u.get(tip, 0.0)) / self.dt
        fn = max(0.0, sp.kn * depth + sp.cn * ddepth)  # Fig. 25 normal spring-damper, no adhesion
        ft_trial = sp.kt * u + sp.ct * du  # Fig. 25 tangential spring-damper from the anchor
        cap = sp.mu * fn  # Coulomb
        margin = cap - abs(ft_trial)
        if abs(ft_trial) > cap:  # slip: the anchor follows so that the spring holds the capped force
            ft = math.copysign(cap, ft_trial)
            self._anchor[tip] = (point[0] - ft / sp.kt * tx, point[1] - ft / sp.kt * ty)
            u = ft / sp.kt
        else:
            ft = ft_trial
        self._depth[tip] = depth
        self._u[tip] = u
        force = (-fn * nx + ft * tx, -fn * ny + ft * ty)
        return ContactReading(True, depth, fn, ft, ft_trial, margin, point, (nx, ny), force)


def net_wrench(readings: dict[str, ContactReading], center: Vec) -> tuple[float, float, float]:
    """(F_x, F_y, tau): the sum of the contact forces on the object and of their moments about `center`."""
    fx = fy = tau = 0.0
    for r in readings.values():
        if not r.contact:
            continue
        fx += r.force[0]
        fy += r.force[1]
        tau += (r.point[0] - center[0]) * r.force[1] - (r.point[1] - center[1]) * r.force[0]
    return fx, fy, tau


def fingers(topo: Topology) -> dict[str, tuple[str, ...]]:
    """Every end effector and the DOF agents of its chain below the root (one finger each)."""
    out: dict[str, tuple[str, ...]] = {}
    for leaf in topo.end_effectors:
        chain, a = [], leaf
        while a is not None and a != topo.root:
            if topo.agents[a].has_dof:
                chain.append(a)
            a = topo.agents[a].parent
        out[leaf] = tuple(reversed(chain))
    return out


class GraspScene:
    """The object in a World's PyBullet client, the contact model, and what the sim publishes of them."""

    def __init__(self, world: object, spec: ObjectSpec) -> None:
        from kinswarm.sim.world import pb  # the world imported it with its banner silenced

        self.pb, self.world, self.spec = pb, world, spec
        self.client: int = world.client  # type: ignore[attr-defined]
        self.body: int = world.body  # type: ignore[attr-defined]
        topo: Topology = world.topo  # type: ignore[attr-defined]
        self.topo = topo
        self.fingers = fingers(topo)
        self.tips = tuple(self.fingers)
        index: dict[str, int] = world.joint_index  # type: ignore[attr-defined]
        self._tip_link = {leaf: index[leaf] for leaf in self.tips}
        self._links = {leaf: [index[a] for a in chain] for leaf, chain in self.fingers.items()}
        hx, hy = spec.half_extents
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=(hx, hy, 1.0), physicsClientId=self.client)
        self.object = pb.createMultiBody(
            baseMass=0.0,
            baseCollisionShapeIndex=shape,
            basePosition=(spec.center[0], spec.center[1], 0.0),
            physicsClientId=self.client,
        )
        self.tip_contact = spec.contact == "tip"
        self._tip_shape = pb.createCollisionShape(
            pb.GEOM_SPHERE, radius=float(getattr(world, "radius", 0.1)), physicsClientId=self.client
        )
        self.model = ContactModel(spec)
        self.readings: dict[str, ContactReading] = dict.fromkeys(self.tips, NO_CONTACT)
        self.wrench = (0.0, 0.0, 0.0)
        self.blocked = 0  # finger moves not executed this epoch (they would sink a link too deep)

    # -- geometry --------------------------------------------------------------------------------
    def _closest(self, link: int) -> tuple[float, Vec | None, Vec | None]:
        """(signed distance, contact point on the object, its outward normal) of one link's capsule."""
        pts = self.pb.getClosestPoints(
            self.body, self.object, _QUERY_DISTANCE, linkIndexA=link, physicsClientId=self.client
        )
        if not pts:
            return math.inf, None, None
        best = min(pts, key=lambda p: p[8])
        pos_b, normal_b = best[6], best[7]
        return float(best[8]), (pos_b[0], pos_b[1]), (normal_b[0], normal_b[1])

    def _closest_tip(self, tip: Sequence[float]) -> tuple[float, Vec | None, Vec | None]:
        """(signed distance, contact point, outward normal) of the fingertip sphere (radius = the capsule's,
        centred on the fingertip `tip`) against the object: a point contact at the fingertip."""
        x, y = tip[0], tip[1]
        pts = self.pb.getClosestPoints(
            bodyA=-1,
            bodyB=self.object,
            distance=_QUERY_DISTANCE,
            collisionShapeA=self._tip_shape,
            collisionShapePositionA=(x, y, 0.0),
            physicsClientId=self.client,
        )
        if not pts:
            return math.inf, None, None
        best = min(pts, key=lambda p: p[8])
        pos_b, normal_b = best[6], best[7]
        return float(best[8]), (pos_b[0], pos_b[1]), (normal_b[0], normal_b[1])

    def too_deep(self) -> list[str]:
        """The fingers with a link deeper than max_depth in the current configuration (solid = "pad": or deeper
        than its fingertip sphere)."""
        self.pb.performCollisionDetection(physicsClientId=self.client)
        limit, pad = self.spec.max_depth, self.spec.solid == "pad"
        poses = self.world.tip_poses() if pad else {}  # type: ignore[attr-defined]
        out = []
        for leaf, links in self._links.items():
            depths = [-self._closest(k)[0] for k in links]
            if pad:
                tip = max(0.0, -self._closest_tip(poses[leaf])[0])
                if any(d > 0.0 and d > tip + PAD_TOL for d in depths):
                    out.append(leaf)
                    continue
            if any(d > limit for d in depths):
                out.append(leaf)
        return out

    # -- the step --------------------------------------------------------------------------------
    def reset(self) -> None:
        self.model.reset()
        self.blocked = 0
        self.sense_contacts()

    def sense_contacts(self) -> None:
        """Read every fingertip's contact and advance the contact model by one step."""
        self.pb.performCollisionDetection(physicsClientId=self.client)
        poses = self.world.tip_poses() if self.tip_contact else {}  # type: ignore[attr-defined]
        for leaf in self.tips:
            if self.tip_contact:
                dist, point, normal = self._closest_tip(poses[leaf])
            else:
                dist, point, normal = self._closest(self._tip_link[leaf])
            self.readings[leaf] = self.model.update(leaf, -dist, point, normal)
        self.wrench = net_wrench(self.readings, self.spec.center)

    def task_sense(self) -> dict[str, float]:
        """The root's task observation: the net wrench and every contact (Task.sense)."""
        fx, fy, tau = self.wrench
        out = {"net_fx": fx, "net_fy": fy, "net_torque": tau, "blocked": float(self.blocked)}
        for leaf, r in self.readings.items():
            out[f"contact/{leaf}"] = 1.0 if r.contact else 0.0
            out[f"fn/{leaf}"] = r.fn
            out[f"ft/{leaf}"] = r.ft
            out[f"margin/{leaf}"] = r.margin
            if r.contact:
                out[f"px/{leaf}"], out[f"py/{leaf}"] = r.point
                out[f"nx/{leaf}"], out[f"ny/{leaf}"] = r.normal
                out[f"depth/{leaf}"] = r.depth
                anchor = self.model.anchor(leaf)
                if anchor is not None:
                    out[f"ax/{leaf}"], out[f"ay/{leaf}"] = anchor
        return out

    def tip_sense(self, leaf: str) -> dict[str, float]:
        """A fingertip agent's own contact reading (Obs.sense)."""
        r = self.readings[leaf]
        return {"contact": 1.0 if r.contact else 0.0, "fn": r.fn, "ft": r.ft, "margin": r.margin}

    def goal_error(self, tips: dict[str, tuple[float, float, float]]) -> float:
        """Mean distance of the fingertips to their grasp points."""
        g = self.spec.grasp
        return sum(math.hypot(tips[leaf][0] - g[leaf][0], tips[leaf][1] - g[leaf][1]) for leaf in self.tips) / len(
            self.tips
        )
