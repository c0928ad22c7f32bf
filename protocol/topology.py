"""The robot spec: the nested hierarchy of agents, from a run file's `[robot]` table (or a robot file's).

```toml
[robot]
name = "chain4"
base = [0.0, 0.0, 0.0]          # x, y, heading (deg) of the root joint in the world

[robot.defaults]                # optional; applies to every [[robot.agent]] that leaves a field out
link_length = 3.0
limits_deg = [-180.0, 180.0]

[[robot.agent]]
id = "a1"                       # [A-Za-z0-9_-]+, unique
parent = ""                     # "" or absent: the root (exactly one)
link_length = 3.0               # the link this joint drives
limits_deg = [-170.0, 170.0]    # joint limits
initial_deg = 0.0               # joint angle at every epoch start
offset = [0.0, 0.0, 0.0]        # joint placement relative to the parent's link end (x, y, heading deg)
compound = false                # true: no DOF, only encapsulates children (the paper's grasp agent)
```

Trees, not only chains: an agent may have several children, and every leaf is an end effector.
Agents are listed parents-first in `Topology.order`; angles are stored in radians. What the robot is asked to do
(`[task]`) and what surrounds it (`[scene]`) are other tables of the run file (actors/files/runfile.py, scene.py).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from typing import Any

from .spec import SpecError, number, table, vector

ID_RE = re.compile(r"^[A-Za-z0-9_-]{1,64}$")


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
    # A spatial robot's joint (protocol/frames.py; planar agents leave these as they are): the joint frame on the
    # parent's link frame (7 floats, fixed joints folded in), the axis in it, a prismatic joint's travel instead of
    # a rotation, a leaf's tool frame on its link frame, and the URDF's name of the joint.
    origin: tuple[float, ...] = ()
    axis: tuple[float, float, float] = (0.0, 0.0, 1.0)
    prismatic: bool = False
    tool: tuple[float, ...] = ()
    joint: str = ""

    @property
    def has_dof(self) -> bool:
        return not self.compound

    @property
    def is_leaf(self) -> bool:
        return not self.children


@dataclass(frozen=True)
class Topology:
    name: str
    agents: dict[str, AgentSpec]
    order: tuple[str, ...]  # parents before children (breadth-first from the root)
    root: str
    # the root's base frame: x, y, heading (radians) for a planar robot, a 7-float frame for a spatial one
    base: tuple[float, ...]
    source: str = field(default="<memory>")
    urdf: str = ""  # a spatial robot: the URDF file it was read from (protocol/urdf_robot.py)
    held: tuple[tuple[str, float], ...] = ()  # its movable joints that are not agents, and the value they hold

    @property
    def spatial(self) -> bool:
        """A robot from URDF, moving in 3D: its frames are 7 floats (protocol/frames.py), not (x, y, heading)."""
        return bool(self.urdf)

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
        if self.spatial:  # from the base: the root joint's own offset, then the longest path below it
            return math.dist(r.origin[:3], (0.0, 0.0, 0.0)) + self.reach_below(self.root)
        return math.hypot(r.offset[0], r.offset[1]) + self.reach_below(self.root)

    def reach_below(self, aid: str) -> float:
        """Longest sum of link lengths and offsets from `aid`'s joint to a leaf below it: how far from the joint
        a point it moves can lie."""
        a = self.agents[aid]
        if self.spatial:  # a spatial joint's link_length is the distance from its joint to the next (or its tool)
            return a.link_length + max((self.reach_below(c) for c in a.children), default=0.0)
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


_AGENT_KEYS = {"id", "parent", "link_length", "limits_deg", "initial_deg", "offset", "compound"}
ROBOT_KEYS = frozenset({"name", "base", "defaults", "agent"})


def parse_planar_robot(robot: Any, source: str = "<memory>", where: str = "robot") -> Topology:
    """Validate a planar robot's `[robot]` table and build the Topology; errors name the source and the field."""
    src = source
    robot = table(src, where, robot, ROBOT_KEYS)
    name = robot.get("name", "robot")
    if not isinstance(name, str) or not name:
        raise SpecError(src, f"{where}.name", f"expected a non-empty string, got {name!r}")
    bx, by, bh = vector(src, f"{where}.base", robot.get("base", [0.0, 0.0, 0.0]), 3)
    defaults = table(src, f"{where}.defaults", robot.get("defaults", {}), _AGENT_KEYS - {"id", "parent"})

    rows = robot.get("agent")
    if not isinstance(rows, list) or not rows:
        raise SpecError(src, f"{where}.agent", "expected at least one [[robot.agent]] table")
    raw: dict[str, dict[str, Any]] = {}
    parents: dict[str, str | None] = {}
    for i, row in enumerate(rows):
        at = f"{where}.agent[{i}]"
        table(src, at, row, _AGENT_KEYS)
        aid = row.get("id")
        if not isinstance(aid, str) or not ID_RE.match(aid):
            raise SpecError(src, f"{at}.id", f"expected letters, digits, '_' or '-', got {aid!r}")
        if aid in raw:
            raise SpecError(src, f"{at}.id", f"duplicate agent id {aid!r}")
        parent = row.get("parent", "")
        if not isinstance(parent, str):
            raise SpecError(src, f"{at}.parent", f"expected a string, got {parent!r}")
        raw[aid] = {**defaults, **row, "_at": at}
        parents[aid] = parent or None

    roots = [a for a, p in parents.items() if p is None]
    if len(roots) != 1:
        raise SpecError(src, f"{where}.agent.parent", f"expected exactly one root (no parent), found {roots}")
    for aid, p in parents.items():
        if p is not None and p not in raw:
            raise SpecError(src, f"{raw[aid]['_at']}.parent", f"unknown parent {p!r}")
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
        raise SpecError(src, f"{where}.agent.parent", f"agents {cyc} are not reachable from the root (a cycle?)")

    agents: dict[str, AgentSpec] = {}
    for aid in order:
        r = raw[aid]
        at = r["_at"]
        compound = r.get("compound", False)
        if not isinstance(compound, bool):
            raise SpecError(src, f"{at}.compound", f"expected true or false, got {compound!r}")
        if compound and not children[aid]:
            raise SpecError(src, f"{at}.compound", "a compound agent must have children")
        if "link_length" not in r and not compound:  # said as the user would fix it, not as the None it reads
            what = f"missing: {aid}'s link needs a length, here or in [{where}.defaults]"
            raise SpecError(src, f"{at}.link_length", what)
        length = number(src, f"{at}.link_length", r.get("link_length", 0.0))
        if length < 0 or (not compound and length == 0):
            raise SpecError(src, f"{at}.link_length", f"must be > 0 for a joint agent, got {length}")
        lo, hi = vector(src, f"{at}.limits_deg", r.get("limits_deg", [-180.0, 180.0]), 2)
        if not lo < hi:
            raise SpecError(src, f"{at}.limits_deg", f"lower limit {lo} must be below upper {hi}")
        initial = number(src, f"{at}.initial_deg", r.get("initial_deg", 0.0))
        if not lo <= initial <= hi:
            raise SpecError(src, f"{at}.initial_deg", f"{initial} lies outside limits [{lo}, {hi}]")
        ox, oy, oh = vector(src, f"{at}.offset", r.get("offset", [0.0, 0.0, 0.0]), 3)
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
    return Topology(
        name=name,
        agents=agents,
        order=tuple(order),
        root=roots[0],
        base=(bx, by, math.radians(bh)),
        source=src,
    )
