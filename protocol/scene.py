"""The scene spec: what surrounds the robot, from a run file's `[scene]` table. The simulator builds it
(sim/scenes/); agents meet it only through the readings it sends (messages.Readings).

```toml
[scene]
kind = "free"                   # free (default) | walls | object
shield = 0.0                    # walls: > 0 turns on the look-ahead reflex (below)

[[scene.obstacle]]              # walls: solid boxes in the robot's plane (obstacles.py)
center = [4.5, 4.4]
half_extents = [1.5, 2.0]

[scene.object]                  # object: a fixed rectangle to grasp (paper §5.5, "infinite mass")
center = [0.0, 0.0]             # x, y of its centre
half_extents = [1.0, 0.6]       # half width (x) and half height (y), axis-aligned
mu = 0.5                        # Coulomb friction coefficient (Fig. 24a)
kn = 20.0                       # normal spring (force / length), Fig. 25
kt = 20.0                       # tangential spring (force / length)
cn = 2.0                        # normal damper (force / (length / time unit))
ct = 2.0                        # tangential damper
max_depth = 0.3                 # the object is solid: no link may sink deeper than this
contact = "tip"                 # optional: "link" (default, the fingertip link's capsule) or "tip" (its end)
[scene.object.grasp]            # the grasp point of every end effector, on the object's boundary
f1_4 = [-1.0, 0.0]
```

The shield (walls): a reflex, not learned. With `shield` > 0 the scene looks one move ahead for every joint and
sends it the readings "shield-" and "shield+": 1 when its own move of -1 or +1 alone (from the present
configuration) would bring the links it moves nearer a wall than `shield`, else 0. A task that honours them leaves
those moves out (actors/tasks/corridor.py). Others' moves of the same step are not foreseen.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from .obstacles import ObstacleSpec, parse_obstacles
from .spec import SpecError, number, table, vector
from .topology import Topology

SCENE_KINDS = ("free", "walls", "object")
OBJECT_CONTACTS = ("link", "tip")
OBJECT_SOLIDS = ("links", "pad")
_OBJECT_KEYS = ("center", "half_extents", "mu", "kn", "kt", "cn", "ct", "max_depth", "grasp")
_OBJECT_OPTIONAL = ("contact", "solid")
_KEYS = {"free": {"kind"}, "walls": {"kind", "obstacle", "shield"}, "object": {"kind", "object"}}


@dataclass(frozen=True)
class ObjectSpec:
    """A fixed rectangular object (paper §5.5) and the contact model's constants (Fig. 25)."""

    center: tuple[float, float]
    half_extents: tuple[float, float]
    mu: float
    kn: float
    kt: float
    cn: float
    ct: float
    max_depth: float
    grasp: dict[str, tuple[float, float]]  # end effector -> grasp point (its goal)
    # what presses on the object: "link" = the fingertip agent's whole capsule; "tip" = a sphere of the
    # capsule's radius at the fingertip only (a point contact at the fingertip)
    contact: str = "link"
    # how solid the object is for the fingers: "links" = no link deeper than max_depth (a blocked finger holds all
    # its joints); "pad" (with contact = "tip") = also no link deeper than its fingertip pad, and a blocked
    # finger's joints are tried one by one, the ones whose own move keeps it out moving (sim/scenes/contact.py)
    solid: str = "links"

    @property
    def char_length(self) -> float:
        """The object's characteristic length (its larger half-extent): torque / char_length is a force."""
        return max(self.half_extents)


@dataclass(frozen=True)
class SceneSpec:
    kind: str = "free"
    obstacles: tuple[ObstacleSpec, ...] = ()  # walls
    shield: float = 0.0  # walls: the look-ahead reflex's distance (0: off)
    object: ObjectSpec | None = None  # object


def agent_readings(spec: SceneSpec, topo: Topology, agent: str) -> tuple[str, ...]:
    """The readings (messages.Readings) the scene sends agent `agent` with its encoder every step: what a learner's
    extra state variable may name besides its own geometry's. Each scene's `agent_sense` (sim/scenes/) sends these
    and no others (tests/test_runfile.py holds them to it)."""
    if spec.kind == "walls":
        clearance = ("clearance",) if topo.agents[agent].link_length > 0 else ()
        return ("collided", *clearance, *(("shield-", "shield+") if spec.shield > 0.0 else ()))
    if spec.kind == "object":  # every joint: its own move refused by the object; a fingertip: its contact too
        return ("collided", *(("contact", "fn", "ft", "margin") if agent in topo.end_effectors else ()))
    return ()


def parse_scene(data: Any, topo: Topology, source: str = "<memory>", where: str = "scene") -> SceneSpec:
    """Validate a `[scene]` table (absent or empty: free space) against the robot it surrounds."""
    data = {} if data is None else data
    if not isinstance(data, dict):
        raise SpecError(source, where, f"must be a table, got {data!r:.60}")
    kind = data.get("kind", "free")
    if kind not in SCENE_KINDS:
        raise SpecError(source, f"{where}.kind", f"expected one of {', '.join(SCENE_KINDS)}, got {kind!r}")
    table(source, where, data, _KEYS[kind])
    if kind == "free":
        return SceneSpec()
    if kind == "walls":
        obstacles = parse_obstacles(data.get("obstacle"), source, f"{where}.obstacle")
        if not obstacles:
            raise SpecError(source, f"{where}.obstacle", "a walls scene needs at least one [[scene.obstacle]]")
        shield = number(source, f"{where}.shield", data.get("shield", 0.0))
        if shield < 0:
            raise SpecError(source, f"{where}.shield", f"must be a distance >= 0, got {shield}")
        return SceneSpec(kind=kind, obstacles=obstacles, shield=shield)
    if "object" not in data:
        raise SpecError(source, f"{where}.object", "an object scene needs a [scene.object] table")
    leaves = list(topo.end_effectors)
    return SceneSpec(kind=kind, object=_parse_object(source, f"{where}.object", data["object"], leaves))


def _parse_object(src: str, where: str, data: Any, leaves: list[str]) -> ObjectSpec:
    """The `[scene.object]` table: every number checked, every end effector given a grasp point on the object's
    boundary."""
    table(src, where, data, set(_OBJECT_KEYS) | set(_OBJECT_OPTIONAL))
    contact = data.get("contact", "link")
    if contact not in OBJECT_CONTACTS:
        raise SpecError(src, f"{where}.contact", f"must be one of {', '.join(OBJECT_CONTACTS)}, got {contact!r}")
    solid = data.get("solid", "links")
    if solid not in OBJECT_SOLIDS:
        raise SpecError(src, f"{where}.solid", f"must be one of {', '.join(OBJECT_SOLIDS)}, got {solid!r}")
    if solid == "pad" and contact != "tip":
        raise SpecError(src, f"{where}.solid", 'a fingertip pad needs contact = "tip"')
    missing = [k for k in _OBJECT_KEYS if k not in data]
    if missing:
        raise SpecError(src, f"{where}.{missing[0]}", "missing")
    cx, cy = vector(src, f"{where}.center", data["center"], 2)
    hx, hy = vector(src, f"{where}.half_extents", data["half_extents"], 2)
    if hx <= 0 or hy <= 0:
        raise SpecError(src, f"{where}.half_extents", f"both must be > 0, got [{hx}, {hy}]")
    consts: dict[str, float] = {}
    for k in ("mu", "kn", "kt", "cn", "ct", "max_depth"):
        v = number(src, f"{where}.{k}", data[k])
        positive = k in ("kn", "kt", "max_depth")
        if v < 0 or (positive and v == 0):
            raise SpecError(src, f"{where}.{k}", f"must be {'> 0' if positive else '>= 0'}, got {v}")
        consts[k] = v
    grasp_t = data["grasp"]
    if not isinstance(grasp_t, dict):
        raise SpecError(src, f"{where}.grasp", "must be a table of end effector = [x, y]")
    grasp: dict[str, tuple[float, float]] = {}
    for leaf, point in grasp_t.items():
        at = f"{where}.grasp.{leaf}"
        if leaf not in leaves:
            raise SpecError(src, at, f"{leaf!r} is not an end effector (leaves: {', '.join(leaves)})")
        gx, gy = vector(src, at, point, 2)
        dx, dy = abs(gx - cx), abs(gy - cy)
        tol = 1e-6 * max(1.0, hx, hy)
        on_edge = (abs(dx - hx) <= tol and dy <= hy + tol) or (abs(dy - hy) <= tol and dx <= hx + tol)
        if not on_edge:
            raise SpecError(src, at, f"[{gx}, {gy}] is not on the object's boundary")
        grasp[leaf] = (gx, gy)
    lacking = [leaf for leaf in leaves if leaf not in grasp]
    if lacking:
        raise SpecError(src, f"{where}.grasp", f"no grasp point for end effector(s) {', '.join(lacking)}")
    return ObjectSpec(center=(cx, cy), half_extents=(hx, hy), grasp=grasp, contact=contact, solid=solid, **consts)
