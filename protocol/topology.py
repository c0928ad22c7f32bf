"""The topology spec: a TOML file describing the nested hierarchy of agents.

```toml
[robot]
name = "chain4"
base = [0.0, 0.0, 0.0]          # x, y, heading (deg) of the root joint in the world

[defaults]                      # optional; applies to every [[agent]] that leaves a field out
link_length = 3.0
limits_deg = [-180.0, 180.0]

[[agent]]
id = "a1"                       # [A-Za-z0-9_-]+, unique
parent = ""                     # "" or absent: the root (exactly one)
link_length = 3.0               # the link this joint drives
limits_deg = [-170.0, 170.0]    # joint limits
initial_deg = 0.0               # joint angle at every epoch start
offset = [0.0, 0.0, 0.0]        # joint placement relative to the parent's link end (x, y, heading deg)
compound = false                # true: no DOF, only encapsulates children (the paper's grasp agent)

[task]
goal = [4.16, 6.18]             # default goal (x, y) for reaching

[[obstacle]]                    # optional static boxes (walls of a corridor): see obstacles.py
center = [4.5, 4.4]
half_extents = [1.5, 2.0]

[object]                        # optional: a fixed rectangular object to grasp (paper §5.5, "infinite mass")
center = [0.0, 0.0]             # x, y of its centre
half_extents = [1.0, 0.6]       # half width (x) and half height (y), axis-aligned
mu = 0.5                        # Coulomb friction coefficient (Fig. 24a)
kn = 20.0                       # normal spring (force / length), Fig. 25
kt = 20.0                       # tangential spring (force / length)
cn = 2.0                        # normal damper (force / (length / time unit))
ct = 2.0                        # tangential damper
max_depth = 0.3                 # the object is solid: no link may sink deeper than this
contact = "tip"                 # optional: "link" (default, the fingertip link's capsule) or "tip" (its end)
[object.grasp]                  # the grasp point (goal) of every end effector, on the object's boundary
f1_4 = [-1.0, 0.0]
```

Trees, not only chains: an agent may have several children, and every leaf is an end effector.
Agents are listed parents-first in `Topology.order`; angles are stored in radians.
"""

from __future__ import annotations

import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .obstacles import ObstacleSpec, parse_obstacles

ID_RE = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


class TopologyError(ValueError):
    """A topology file that does not fit the spec; the message names the file, the field and the fault."""

    def __init__(self, source: str, where: str, what: str) -> None:
        super().__init__(f"{source}: {where}: {what}")
        self.source, self.where, self.what = source, where, what


@dataclass(frozen=True)
class AgentSpec:
    id: str
    parent: str | None
    children: tuple[str, ...]
    link_length: float
    limits: tuple[float, float]  # radians
    initial: float  # radians
    offset: tuple[float, float, float]  # x, y, heading (radians) relative to the parent's link end
    compound: bool

    @property
    def has_dof(self) -> bool:
        return not self.compound

    @property
    def is_leaf(self) -> bool:
        return not self.children


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

    @property
    def char_length(self) -> float:
        """The object's characteristic length (its larger half-extent): torque / char_length is a force."""
        return max(self.half_extents)


@dataclass(frozen=True)
class Topology:
    name: str
    agents: dict[str, AgentSpec]
    order: tuple[str, ...]  # parents before children (breadth-first from the root)
    root: str
    base: tuple[float, float, float]  # x, y, heading (radians)
    goal: tuple[float, float] | None
    source: str = field(default="<memory>")
    obstacles: tuple[ObstacleSpec, ...] = ()  # static boxes of the scene ([[obstacle]], protocol/obstacles.py)
    object: ObjectSpec | None = None  # a grasp scene's object ([object] table)
    # [task] via, via_width: the goal distance is measured along an approach path through `via` (see
    # actors/learning/reward.py path_distance); None: straight to the goal
    via: tuple[float, float] | None = None
    via_width: float = 0.0
    # [task] waypoints, waypoint_radius: sub-goals the root hands down one after the other (reward.next_waypoint)
    waypoints: tuple[tuple[float, float], ...] = ()
    waypoint_radius: float = 0.0

    @property
    def dof_agents(self) -> tuple[str, ...]:
        return tuple(a for a in self.order if self.agents[a].has_dof)

    @property
    def end_effectors(self) -> tuple[str, ...]:
        return tuple(a for a in self.order if self.agents[a].is_leaf)

    @property
    def reach(self) -> float:
        """Longest root-to-leaf sum of link lengths and offsets: the radius of the task space."""
        r = self.agents[self.root]
        return math.hypot(r.offset[0], r.offset[1]) + self.reach_below(self.root)

    def reach_below(self, aid: str) -> float:
        """Longest sum of link lengths and offsets from `aid`'s joint to a leaf below it: how far from the joint
        a point it moves can lie."""
        a = self.agents[aid]
        below = (math.hypot(*self.agents[c].offset[:2]) + self.reach_below(c) for c in a.children)
        return a.link_length + max(below, default=0.0)

    def subtree(self, aid: str) -> tuple[str, ...]:
        """`aid` and every agent below it, parents first."""
        return (aid, *(b for c in self.agents[aid].children for b in self.subtree(c)))

    def depth(self, aid: str) -> int:
        d, a = 0, self.agents[aid]
        while a.parent is not None:
            d, a = d + 1, self.agents[a.parent]
        return d

    def subtree_leaves(self, aid: str) -> tuple[str, ...]:
        a = self.agents[aid]
        if a.is_leaf:
            return (aid,)
        return tuple(leaf for c in a.children for leaf in self.subtree_leaves(c))

    def initial_angles(self) -> dict[str, float]:
        return {a: self.agents[a].initial for a in self.dof_agents}


def _num(src: str, where: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise TopologyError(src, where, f"expected a finite number, got {v!r}")
    return float(v)


def _vec(src: str, where: str, v: Any, n: int) -> tuple[float, ...]:
    if not isinstance(v, list) or len(v) != n:
        raise TopologyError(src, where, f"expected a list of {n} numbers, got {v!r}")
    return tuple(_num(src, f"{where}[{i}]", x) for i, x in enumerate(v))


_AGENT_KEYS = {"id", "parent", "link_length", "limits_deg", "initial_deg", "offset", "compound"}


def parse_topology(data: dict[str, Any], source: str = "<memory>") -> Topology:
    """Validate a parsed TOML document and build the Topology; errors name source and field."""
    src = source
    unknown = set(data) - {"robot", "defaults", "agent", "task", "obstacle", "object"}
    if unknown:
        raise TopologyError(
            src, sorted(unknown)[0], "unknown table (expected robot, defaults, agent, task, obstacle, object)"
        )
    robot = data.get("robot", {})
    if not isinstance(robot, dict):
        raise TopologyError(src, "robot", "must be a table")
    name = robot.get("name", Path(source).stem)
    if not isinstance(name, str) or not name:
        raise TopologyError(src, "robot.name", f"expected a non-empty string, got {name!r}")
    bx, by, bh = _vec(src, "robot.base", robot.get("base", [0.0, 0.0, 0.0]), 3)
    defaults = data.get("defaults", {})
    if not isinstance(defaults, dict):
        raise TopologyError(src, "defaults", "must be a table")
    bad = set(defaults) - (_AGENT_KEYS - {"id", "parent"})
    if bad:
        raise TopologyError(src, f"defaults.{sorted(bad)[0]}", "unknown field")

    rows = data.get("agent")
    if not isinstance(rows, list) or not rows:
        raise TopologyError(src, "agent", "expected at least one [[agent]] table")
    raw: dict[str, dict[str, Any]] = {}
    parents: dict[str, str | None] = {}
    for i, row in enumerate(rows):
        at = f"agent[{i}]"
        if not isinstance(row, dict):
            raise TopologyError(src, at, "must be a table")
        bad = set(row) - _AGENT_KEYS
        if bad:
            raise TopologyError(src, f"{at}.{sorted(bad)[0]}", "unknown field")
        aid = row.get("id")
        if not isinstance(aid, str) or not ID_RE.match(aid):
            raise TopologyError(src, f"{at}.id", f"expected letters, digits, '_' or '-', got {aid!r}")
        if aid in raw:
            raise TopologyError(src, f"{at}.id", f"duplicate agent id {aid!r}")
        parent = row.get("parent", "")
        if not isinstance(parent, str):
            raise TopologyError(src, f"{at}.parent", f"expected a string, got {parent!r}")
        raw[aid] = {**defaults, **row, "_at": at}
        parents[aid] = parent or None

    roots = [a for a, p in parents.items() if p is None]
    if len(roots) != 1:
        raise TopologyError(src, "agent.parent", f"expected exactly one root (no parent), found {roots}")
    for aid, p in parents.items():
        if p is not None and p not in raw:
            raise TopologyError(src, f"{raw[aid]['_at']}.parent", f"unknown parent {p!r}")
    children: dict[str, list[str]] = {a: [] for a in raw}
    for aid, p in parents.items():
        if p is not None:
            children[p].append(aid)

    order: list[str] = []
    frontier = [roots[0]]
    while frontier:
        order.extend(frontier)
        frontier = [c for a in frontier for c in children[a]]
    if len(order) != len(raw):
        cyc = sorted(set(raw) - set(order))
        raise TopologyError(src, "agent.parent", f"agents {cyc} are not reachable from the root (a cycle?)")

    agents: dict[str, AgentSpec] = {}
    for aid in order:
        r = raw[aid]
        at = r["_at"]
        compound = r.get("compound", False)
        if not isinstance(compound, bool):
            raise TopologyError(src, f"{at}.compound", f"expected true or false, got {compound!r}")
        if compound and not children[aid]:
            raise TopologyError(src, f"{at}.compound", "a compound agent must have children")
        length = _num(src, f"{at}.link_length", r.get("link_length", 0.0 if compound else None))
        if length < 0 or (not compound and length == 0):
            raise TopologyError(src, f"{at}.link_length", f"must be > 0 for a joint agent, got {length}")
        lo, hi = _vec(src, f"{at}.limits_deg", r.get("limits_deg", [-180.0, 180.0]), 2)
        if not lo < hi:
            raise TopologyError(src, f"{at}.limits_deg", f"lower limit {lo} must be below upper {hi}")
        initial = _num(src, f"{at}.initial_deg", r.get("initial_deg", 0.0))
        if not lo <= initial <= hi:
            raise TopologyError(src, f"{at}.initial_deg", f"{initial} lies outside limits [{lo}, {hi}]")
        ox, oy, oh = _vec(src, f"{at}.offset", r.get("offset", [0.0, 0.0, 0.0]), 3)
        agents[aid] = AgentSpec(
            id=aid,
            parent=parents[aid],
            children=tuple(children[aid]),
            link_length=length,
            limits=(math.radians(lo), math.radians(hi)),
            initial=math.radians(initial),
            offset=(ox, oy, math.radians(oh)),
            compound=compound,
        )

    task = data.get("task", {})
    if not isinstance(task, dict):
        raise TopologyError(src, "task", "must be a table")
    bad = set(task) - {"goal", "via", "via_width", "waypoints", "waypoint_radius"}
    if bad:
        raise TopologyError(src, f"task.{sorted(bad)[0]}", "unknown field")
    goal = _vec(src, "task.goal", task["goal"], 2) if "goal" in task else None
    via = _vec(src, "task.via", task["via"], 2) if "via" in task else None
    via_width = _num(src, "task.via_width", task.get("via_width", 0.0))
    if via is not None and via_width <= 0:
        raise TopologyError(src, "task.via_width", f"must be > 0 with task.via, got {via_width}")
    if via is None and "via_width" in task:
        raise TopologyError(src, "task.via_width", "only with task.via")
    raw_wp = task.get("waypoints", [])
    if not isinstance(raw_wp, list):
        raise TopologyError(src, "task.waypoints", f"expected a list of [x, y] points, got {raw_wp!r}")
    waypoints = tuple(_vec(src, f"task.waypoints[{i}]", w, 2) for i, w in enumerate(raw_wp))
    radius = _num(src, "task.waypoint_radius", task.get("waypoint_radius", 0.0))
    if waypoints and radius <= 0:
        raise TopologyError(src, "task.waypoint_radius", f"must be > 0 with task.waypoints, got {radius}")
    if not waypoints and "waypoint_radius" in task:
        raise TopologyError(src, "task.waypoint_radius", "only with task.waypoints")

    leaves = [a for a in order if not agents[a].children]
    obj = _parse_object(src, data["object"], leaves) if "object" in data else None

    return Topology(
        name=name,
        agents=agents,
        order=tuple(order),
        root=roots[0],
        base=(bx, by, math.radians(bh)),
        goal=goal,  # type: ignore[arg-type]
        source=src,
        obstacles=parse_obstacles(data.get("obstacle"), src),
        object=obj,
        via=via,  # type: ignore[arg-type]
        via_width=via_width,
        waypoints=waypoints,  # type: ignore[arg-type]
        waypoint_radius=radius,
    )


def load_topology(path: str | Path) -> Topology:
    path = Path(path)
    try:
        text = path.read_text()
    except OSError as e:
        raise TopologyError(str(path), "file", f"cannot read: {e.strerror}") from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise TopologyError(str(path), "toml", str(e)) from None
    return parse_topology(data, source=str(path))


_OBJECT_KEYS = ("center", "half_extents", "mu", "kn", "kt", "cn", "ct", "max_depth", "grasp")
_OBJECT_OPTIONAL = ("contact",)
OBJECT_CONTACTS = ("link", "tip")


def _parse_object(src: str, table: Any, leaves: list[str]) -> ObjectSpec:
    """The `[object]` table of a grasp scene: every number checked, every end effector given a grasp point
    on the object's boundary."""
    if not isinstance(table, dict):
        raise TopologyError(src, "object", "must be a table")
    bad = set(table) - set(_OBJECT_KEYS) - set(_OBJECT_OPTIONAL)
    if bad:
        known = ", ".join(_OBJECT_KEYS + _OBJECT_OPTIONAL)
        raise TopologyError(src, f"object.{sorted(bad)[0]}", f"unknown field (expected {known})")
    contact = table.get("contact", "link")
    if contact not in OBJECT_CONTACTS:
        raise TopologyError(src, "object.contact", f"must be one of {', '.join(OBJECT_CONTACTS)}, got {contact!r}")
    missing = [k for k in _OBJECT_KEYS if k not in table]
    if missing:
        raise TopologyError(src, f"object.{missing[0]}", "missing")
    cx, cy = _vec(src, "object.center", table["center"], 2)
    hx, hy = _vec(src, "object.half_extents", table["half_extents"], 2)
    if hx <= 0 or hy <= 0:
        raise TopologyError(src, "object.half_extents", f"both must be > 0, got [{hx}, {hy}]")
    consts: dict[str, float] = {}
    for k in ("mu", "kn", "kt", "cn", "ct", "max_depth"):
        v = _num(src, f"object.{k}", table[k])
        positive = k in ("kn", "kt", "max_depth")
        if v < 0 or (positive and v == 0):
            raise TopologyError(src, f"object.{k}", f"must be {'> 0' if positive else '>= 0'}, got {v}")
        consts[k] = v
    grasp_t = table["grasp"]
    if not isinstance(grasp_t, dict):
        raise TopologyError(src, "object.grasp", "must be a table of end effector = [x, y]")
    grasp: dict[str, tuple[float, float]] = {}
    for leaf, point in grasp_t.items():
        where = f"object.grasp.{leaf}"
        if leaf not in leaves:
            raise TopologyError(src, where, f"{leaf!r} is not an end effector (leaves: {', '.join(leaves)})")
        gx, gy = _vec(src, where, point, 2)
        dx, dy = abs(gx - cx), abs(gy - cy)
        tol = 1e-6 * max(1.0, hx, hy)
        on_edge = (abs(dx - hx) <= tol and dy <= hy + tol) or (abs(dy - hy) <= tol and dx <= hx + tol)
        if not on_edge:
            raise TopologyError(src, where, f"[{gx}, {gy}] is not on the object's boundary")
        grasp[leaf] = (gx, gy)
    lacking = [leaf for leaf in leaves if leaf not in grasp]
    if lacking:
        raise TopologyError(src, "object.grasp", f"no grasp point for end effector(s) {', '.join(lacking)}")
    return ObjectSpec(center=(cx, cy), half_extents=(hx, hy), grasp=grasp, contact=contact, **consts)
