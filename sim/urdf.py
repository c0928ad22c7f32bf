"""URDF generation for planar chains and trees described by a Topology.

Link frames equal the joint frames of sim.kinematics: link `link_<id>` sits at agent id's joint with local x
along its link, so a child's joint origin is (parent link_length + offset_x, offset_y) rotated by offset_h.
Each leaf gets a massless-looking `tip_<id>` link fixed at its link end so getLinkState reads tips directly.
The base pose (topology.base) is applied by loadURDF, not written here.
"""

from __future__ import annotations

import itertools
import math
import os
import re
import uuid
from pathlib import Path
from xml.sax.saxutils import quoteattr

from kinswarm.protocol.topology import Topology

_counter = itertools.count()

# Kinematic use only (no stepSimulation), but PyBullet still wants a positive mass/inertia per link.
_INERTIAL = (
    '    <inertial><origin xyz="{cx} 0 0"/><mass value="1"/>'
    '<inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial>\n'
)
_TINY_INERTIAL = (
    '    <inertial><mass value="1e-6"/><inertia ixx="1e-9" ixy="0" ixz="0" iyy="1e-9" iyz="0" izz="1e-9"/></inertial>\n'
)


def link_name(aid: str) -> str:
    return f"link_{aid}"


def tip_name(aid: str) -> str:
    return f"tip_{aid}"


def joint_name(aid: str) -> str:
    return f"joint_{aid}"


def tip_joint_name(aid: str) -> str:
    return f"tipjoint_{aid}"


def _f(x: float) -> str:
    return repr(float(x))  # shortest round-tripping repr: no precision lost through the XML


def _capsule(length: float, radius: float) -> str:
    # URDF capsules lie along local z, centred: rotate onto x and shift by half the link.
    geom = (
        f'<origin xyz="{_f(length / 2)} 0 0" rpy="0 {_f(math.pi / 2)} 0"/>'
        f'<geometry><capsule radius="{_f(radius)}" length="{_f(length)}"/></geometry>'
    )
    return f"    <visual>{geom}</visual>\n    <collision>{geom}</collision>\n"


# PyBullet reads the state of links 0-126 of a body (measured: a chain of 126 joints and its tip link runs, one of 127
# fails in getLinkState); a planar robot's body is a link a joint and a tip link an end effector
MAX_LINKS = 127


def too_many_links(topo: Topology) -> str | None:
    """Why PyBullet cannot hold this planar robot as one body, or None."""
    if topo.spatial:  # its own URDF: PyBullet says so itself when it loads it
        return None
    joints, tips = len(topo.order), len(topo.end_effectors)
    if joints + tips <= MAX_LINKS:
        return None
    return (
        f"{joints} joints and {tips} end effectors make {joints + tips} links in PyBullet (a link a joint, a tip link"
        f" an end effector); a body holds at most {MAX_LINKS}"
    )


def urdf_text(topo: Topology, *, radius: float = 0.1) -> str:
    """The URDF document for `topo` (one robot, links in the x-y plane)."""
    if radius <= 0:
        raise ValueError(f"capsule radius must be > 0, got {radius}")
    if problem := too_many_links(topo):
        raise ValueError(f"robot {topo.name}: {problem}")
    out = [f'<?xml version="1.0"?>\n<robot name={quoteattr(topo.name)}>\n']
    out.append(f'  <link name="base">\n{_TINY_INERTIAL}  </link>\n')
    for aid in topo.order:
        a = topo.agents[aid]
        body = _INERTIAL.format(cx=_f(a.link_length / 2))
        if a.link_length > 0:
            body += _capsule(a.link_length, radius)
        out.append(f'  <link name="{link_name(aid)}">\n{body}  </link>\n')
        parent_link = "base" if a.parent is None else link_name(a.parent)
        along = 0.0 if a.parent is None else topo.agents[a.parent].link_length
        ox, oy, oh = a.offset
        origin = f'<origin xyz="{_f(along + ox)} {_f(oy)} 0" rpy="0 0 {_f(oh)}"/>'
        if a.compound:
            out.append(
                f'  <joint name="{joint_name(aid)}" type="fixed"><parent link="{parent_link}"/>'
                f'<child link="{link_name(aid)}"/>{origin}</joint>\n'
            )
        else:
            lo, hi = a.limits
            out.append(
                f'  <joint name="{joint_name(aid)}" type="revolute"><parent link="{parent_link}"/>'
                f'<child link="{link_name(aid)}"/>{origin}<axis xyz="0 0 1"/>'
                f'<limit lower="{_f(lo)}" upper="{_f(hi)}" effort="100" velocity="10"/></joint>\n'
            )
    for leaf in topo.end_effectors:
        length = topo.agents[leaf].link_length
        out.append(f'  <link name="{tip_name(leaf)}">\n{_TINY_INERTIAL}  </link>\n')
        out.append(
            f'  <joint name="{tip_joint_name(leaf)}" type="fixed"><parent link="{link_name(leaf)}"/>'
            f'<child link="{tip_name(leaf)}"/><origin xyz="{_f(length)} 0 0" rpy="0 0 0"/></joint>\n'
        )
    out.append("</robot>\n")
    return "".join(out)


def write_urdf(topo: Topology, directory: Path, *, radius: float = 0.1) -> Path:
    """Write the URDF under a file name never used before: PyBullet caches loadURDF by path."""
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    stem = re.sub(r"[^A-Za-z0-9_-]", "_", topo.name)[:40]  # the name is free text; keep the path safe
    path = directory / f"{stem}-{os.getpid()}-{next(_counter)}-{uuid.uuid4().hex[:8]}.urdf"
    path.write_text(urdf_text(topo, radius=radius))
    return path
