"""A robot from a URDF file: one agent per movable joint, nested as the URDF's tree (a run file's `[robot]` table).

```toml
[robot]
urdf = "kuka_iiwa/model.urdf"    # a path (relative to this file), else a file of pybullet_data by that name
name = "iiwa"                    # optional (default: the URDF's robot name)
base = [0.0, 0.0, 0.0]           # optional: where the URDF's root link sits (x, y, z; or x, y, z, roll, pitch, yaw deg)
joints = ["lbr_iiwa_joint_1"]    # optional: the movable joints that are agents (default: all); the others stay
                                 # at their home value and fold into the fixed transforms
home_deg = [0, 30, 0, -60, 0, 45, 0]  # optional: every agent's angle at each epoch start, in agent order
                                 # (default 0, or the nearest limit); mm for a prismatic joint
tool = [0.0, 0.0, 0.1]           # optional: the end effector on the last link (x, y, z; or with roll, pitch, yaw deg)
tool_link = "lbr_iiwa_link_7"    # optional: the link `tool` is given on (a fixed descendant of a leaf agent's link)
```

Agents are named a1, a2, ... in the URDF's order (depth first from the root link); each keeps its joint's name.
Revolute and prismatic joints are agents; a continuous joint is a revolute one with limits [-180°, 180°] (its angle
is not wrapped); fixed joints fold into their child's transform; floating and planar joints are refused, and so is
a robot with no movable joint left. What is not an agent has no say: it stays where its home puts it.
"""

from __future__ import annotations

import math
import re
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from . import frames
from .spec import SpecError, table, vector
from .topology import ID_RE, AgentSpec, Topology

URDF_KEYS = frozenset({"name", "urdf", "base", "joints", "home_deg", "tool", "tool_link"})
MOVABLE = ("revolute", "continuous", "prismatic")


@dataclass(frozen=True)
class _Joint:
    name: str
    kind: str
    parent: str
    child: str
    origin: frames.Frame
    axis: tuple[float, float, float]
    limits: tuple[float, float]


def find_urdf(name: str, source: str) -> Path:
    """The URDF file `name`: relative to the run file's folder, absolute, or one of pybullet_data's."""
    p = Path(name)
    candidates = [p] if p.is_absolute() else [Path(source).parent / p]
    if not p.is_absolute():
        try:
            import pybullet_data  # the arms PyBullet ships: kuka_iiwa/model.urdf, franka_panda/panda.urdf, ...

            candidates.append(Path(pybullet_data.getDataPath()) / p)
        except ImportError:
            pass
    for c in candidates:
        if c.is_file():
            return c.resolve()
    raise SpecError(source, "robot.urdf", f"no such file {name!r} (looked in {', '.join(str(c) for c in candidates)})")


def _floats(text: str | None, n: int, default: tuple[float, ...], where: str, src: str) -> tuple[float, ...]:
    if text is None:
        return default
    try:
        vals = tuple(float(x) for x in text.split())
    except ValueError:
        raise SpecError(src, where, f"expected {n} numbers, got {text!r}") from None
    if len(vals) != n or not all(math.isfinite(v) for v in vals):
        raise SpecError(src, where, f"expected {n} finite numbers, got {text!r}")
    return vals


def _frame(xyz: tuple[float, ...], rpy: tuple[float, ...]) -> frames.Frame:
    return (xyz[0], xyz[1], xyz[2], *frames.rpy_quat(*rpy))


def _read(path: Path, src: str) -> tuple[str, str, list[_Joint]]:
    """The robot's name, root link and joints (document order) of a URDF file."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as e:
        raise SpecError(src, "robot.urdf", f"cannot read {path}: {e}") from None
    if root.tag != "robot":
        raise SpecError(src, "robot.urdf", f"{path} is not a URDF robot (its root element is <{root.tag}>)")
    links = [link.get("name", "") for link in root.findall("link")]
    joints = []
    for j in root.findall("joint"):
        name, kind = j.get("name", ""), j.get("type", "")
        where = f"robot.urdf: joint {name!r}"
        if kind in ("floating", "planar"):
            raise SpecError(src, where, f"a {kind} joint is not supported (a fixed base and 1-DOF joints only)")
        if kind not in (*MOVABLE, "fixed"):
            raise SpecError(src, where, f"unknown joint type {kind!r}")
        parent, child = j.find("parent"), j.find("child")
        if parent is None or child is None:
            raise SpecError(src, where, "needs <parent link=...> and <child link=...>")
        o = j.find("origin")
        origin = _frame(
            _floats(o.get("xyz") if o is not None else None, 3, (0.0, 0.0, 0.0), f"{where} origin xyz", src),
            _floats(o.get("rpy") if o is not None else None, 3, (0.0, 0.0, 0.0), f"{where} origin rpy", src),
        )
        a = j.find("axis")
        axis = _floats(a.get("xyz") if a is not None else None, 3, (1.0, 0.0, 0.0), f"{where} axis", src)
        norm = math.sqrt(sum(c * c for c in axis))
        if kind != "fixed" and norm == 0.0:
            raise SpecError(src, where, "its axis is zero")
        axis = tuple(c / norm for c in axis) if norm else axis
        lim = j.find("limit")
        if kind == "continuous":
            limits = (-math.pi, math.pi)
        elif kind in MOVABLE:
            if lim is None or lim.get("lower") is None or lim.get("upper") is None:
                raise SpecError(src, where, "a revolute or prismatic joint needs <limit lower=... upper=...>")
            limits = (float(lim.get("lower")), float(lim.get("upper")))  # type: ignore[arg-type]
            if not limits[0] < limits[1]:
                raise SpecError(src, where, f"its limits {limits} are empty")
        else:
            limits = (0.0, 0.0)
        joints.append(_Joint(name, kind, parent.get("link", ""), child.get("link", ""), origin, axis, limits))  # type: ignore[arg-type]
    children = {j.child for j in joints}
    roots = [link for link in links if link not in children]
    if len(roots) != 1:
        raise SpecError(src, "robot.urdf", f"expected one root link, found {roots}")
    return root.get("name", path.stem), roots[0], joints


def parse_urdf_robot(robot: dict[str, Any], source: str, where: str = "robot") -> Topology:
    """The Topology of a `[robot] urdf = ...` table; errors name the source and the field."""
    src = source
    table(src, where, robot, URDF_KEYS)
    if not isinstance(robot.get("urdf"), str) or not robot["urdf"]:
        raise SpecError(src, f"{where}.urdf", f"expected a file name, got {robot.get('urdf')!r}")
    path = find_urdf(robot["urdf"], src)
    robot_name, root_link, joints = _read(path, src)
    name = robot.get("name", re.sub(r"[^A-Za-z0-9_-]", "_", robot_name)[:64] or "robot")
    if not isinstance(name, str) or not ID_RE.match(name):
        raise SpecError(src, f"{where}.name", f"expected a short name (letters, digits, '_', '-'), got {name!r}")
    movable = [j for j in joints if j.kind in MOVABLE]
    chosen = robot.get("joints", [j.name for j in movable])
    if not isinstance(chosen, list) or not all(isinstance(n, str) for n in chosen):
        raise SpecError(src, f"{where}.joints", f"expected a list of joint names, got {chosen!r:.80}")
    known = {j.name for j in movable}
    for n in chosen:
        if n not in known:
            raise SpecError(
                src, f"{where}.joints", f"{n!r} is not a movable joint of {path.name} ({', '.join(sorted(known))})"
            )
    if not chosen:
        raise SpecError(src, f"{where}.joints", "no movable joint left for the swarm")
    agents_j = [j for j in movable if j.name in set(chosen)]  # URDF order, whatever order the list has
    ids = {j.name: f"a{i + 1}" for i, j in enumerate(agents_j)}

    home_raw = robot.get("home_deg", [0.0] * len(agents_j))
    home = vector(src, f"{where}.home_deg", home_raw, len(agents_j))
    home_q: dict[str, float] = {}
    for j, h in zip(agents_j, home, strict=True):
        v = h / 1000.0 if j.kind == "prismatic" else math.radians(h)
        if not j.limits[0] <= v <= j.limits[1]:
            if "home_deg" in robot:
                raise SpecError(src, f"{where}.home_deg", f"{h:g} for {j.name} lies outside its limits")
            v = min(max(v, j.limits[0]), j.limits[1])
        home_q[j.name] = v
    # joints that are not agents hold their middle (or 0 when that is within limits)
    for j in movable:
        if j.name not in home_q:
            home_q[j.name] = 0.0 if j.limits[0] <= 0.0 <= j.limits[1] else (j.limits[0] + j.limits[1]) / 2

    by_parent: dict[str, list[_Joint]] = {}
    for j in joints:
        by_parent.setdefault(j.parent, []).append(j)

    base_v = vector(src, f"{where}.base", robot.get("base", [0.0, 0.0, 0.0]), len(robot.get("base", [0, 0, 0])))
    if len(base_v) not in (3, 6):
        raise SpecError(src, f"{where}.base", "expected x, y, z or x, y, z, roll, pitch, yaw (deg)")
    base = _frame(base_v[:3], tuple(math.radians(a) for a in base_v[3:]) if len(base_v) == 6 else (0.0, 0.0, 0.0))

    # Walk the tree: each agent's origin is the fixed path from its parent agent's link (or the base) to its joint.
    specs: dict[str, dict[str, Any]] = {}
    link_of: dict[str, str] = {}  # agent -> its child link
    fixed_to: dict[str, tuple[str | None, frames.Frame]] = {root_link: (None, frames.IDENTITY)}  # link -> (agent, pose)

    def walk(link: str) -> None:
        owner, pose = fixed_to[link]
        for j in by_parent.get(link, []):
            step = frames.compose(pose, j.origin)
            if j.name in ids:
                aid = ids[j.name]
                specs[aid] = {"parent": owner, "origin": step, "joint": j}
                link_of[aid] = j.child
                fixed_to[j.child] = (aid, frames.IDENTITY)
            else:  # fixed, or a movable joint left out: folded at its home value
                motion = frames.IDENTITY
                if j.kind in MOVABLE:
                    q = home_q[j.name]
                    motion = (
                        (j.axis[0] * q, j.axis[1] * q, j.axis[2] * q, 0.0, 0.0, 0.0, 1.0)
                        if j.kind == "prismatic"
                        else (0.0, 0.0, 0.0, *frames.axis_angle(j.axis, q))
                    )
                fixed_to[j.child] = (owner, frames.compose(step, motion))
            walk(j.child)

    walk(root_link)
    if unreached := [n for n, a in ids.items() if a not in specs]:
        raise SpecError(src, "robot.urdf", f"joints {unreached} do not hang from the root link {root_link!r}")
    roots = [a for a, s in specs.items() if s["parent"] is None]
    if len(roots) != 1:
        raise SpecError(
            src,
            f"{where}.joints",
            f"the agents must form one tree with one root joint; roots: {[specs[a]['joint'].name for a in roots]}",
        )

    tool_v = vector(src, f"{where}.tool", robot.get("tool", [0.0, 0.0, 0.0]), len(robot.get("tool", [0, 0, 0])))
    if len(tool_v) not in (3, 6):
        raise SpecError(src, f"{where}.tool", "expected x, y, z or x, y, z, roll, pitch, yaw (deg)")
    tool = _frame(tool_v[:3], tuple(math.radians(a) for a in tool_v[3:]) if len(tool_v) == 6 else (0.0, 0.0, 0.0))
    tool_link = robot.get("tool_link")
    if tool_link is not None:
        if tool_link not in fixed_to:
            raise SpecError(src, f"{where}.tool_link", f"no link {tool_link!r} in {path.name}")
        owner, pose = fixed_to[tool_link]
        if owner is None:
            raise SpecError(src, f"{where}.tool_link", f"{tool_link!r} does not move with any agent")
        tool_owner, tool = owner, frames.compose(pose, tool)
    else:
        tool_owner = None

    children: dict[str, list[str]] = {a: [] for a in specs}
    for a, s in specs.items():
        if s["parent"] is not None:
            children[s["parent"]].append(a)
    leaves = [a for a in specs if not children[a]]
    if tool_owner is not None and tool_owner not in leaves:
        raise SpecError(
            src, f"{where}.tool_link", f"{tool_link!r} is not carried by a leaf agent ({', '.join(leaves)})"
        )
    order: list[str] = []
    frontier = roots
    while frontier:
        order.extend(frontier)
        frontier = [c for a in frontier for c in children[a]]

    agents: dict[str, AgentSpec] = {}
    for aid in order:
        s, j = specs[aid], specs[aid]["joint"]
        leaf_tool = (tool if tool_owner in (None, aid) else frames.IDENTITY) if not children[aid] else ()
        spans = [math.dist(specs[c]["origin"][:3], (0, 0, 0)) for c in children[aid]] or [
            math.dist(leaf_tool[:3], (0, 0, 0))
        ]
        agents[aid] = AgentSpec(
            id=aid,
            parent=s["parent"],
            children=tuple(children[aid]),
            link_length=max(spans),
            limits=j.limits,
            initial=home_q[j.name],
            offset=(0.0, 0.0, 0.0),
            compound=False,
            origin=s["origin"],
            axis=j.axis,
            prismatic=j.kind == "prismatic",
            tool=leaf_tool,
            joint=j.name,
        )
    return Topology(
        name=name,
        agents=agents,
        order=tuple(order),
        root=roots[0],
        base=base,
        source=src,
        urdf=str(path),
        held=tuple((j.name, home_q[j.name]) for j in movable if j.name not in ids),
    )
