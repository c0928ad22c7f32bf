"""What the grasp agent senses of a step (the sim's contact readings, parsed: `Contacts`) and the object's faces as
the grasp rewards read them: which face a point is on, whether a contact is on its grasp point's face, whether a tip is
in front of a face. Numpy-free, pure functions (tests/test_grasp.py)."""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

Vec = tuple[float, float]


@dataclass(frozen=True)
class Contacts:
    """What the task observation tells the grasp agent about one step (Task.sense, parsed)."""

    contact: dict[str, bool]
    fn: dict[str, float]
    ft: dict[str, float]
    margin: dict[str, float]
    point: dict[str, Vec]  # contact points (only for fingertips in contact)
    normal: dict[str, Vec]
    net: tuple[float, float, float]  # F_x, F_y, tau
    depth: dict[str, float] | None = None  # penetration (only for fingertips in contact)
    anchor: dict[str, Vec] | None = None  # the tangential spring's anchor (only for fingertips in contact)

    @classmethod
    def from_sense(cls, sense: Mapping[str, float], tips: Sequence[str]) -> Contacts:
        c = {t: sense.get(f"contact/{t}", 0.0) > 0.5 for t in tips}
        return cls(
            contact=c,
            fn={t: sense.get(f"fn/{t}", 0.0) for t in tips},
            ft={t: sense.get(f"ft/{t}", 0.0) for t in tips},
            margin={t: sense.get(f"margin/{t}", 0.0) for t in tips},
            point={t: (sense[f"px/{t}"], sense[f"py/{t}"]) for t in tips if c[t] and f"px/{t}" in sense},
            normal={t: (sense[f"nx/{t}"], sense[f"ny/{t}"]) for t in tips if c[t] and f"nx/{t}" in sense},
            net=(sense.get("net_fx", 0.0), sense.get("net_fy", 0.0), sense.get("net_torque", 0.0)),
            depth={t: sense[f"depth/{t}"] for t in tips if c[t] and f"depth/{t}" in sense},
            anchor={t: (sense[f"ax/{t}"], sense[f"ay/{t}"]) for t in tips if c[t] and f"ax/{t}" in sense},
        )

    @property
    def all_touch(self) -> bool:
        return all(self.contact.values())

    def cone_violation(self) -> float:
        """FC(t): the summed amount by which contacts leave their friction cones (0 inside)."""
        return sum(max(0.0, -self.margin[t]) for t in self.contact if self.contact[t])


def face_normal(point: Vec, center: Vec, half_extents: Vec) -> Vec:
    """Outward normal of the rectangle's face that `point` (on its boundary) lies on."""
    dx, dy = point[0] - center[0], point[1] - center[1]
    if abs(abs(dx) - half_extents[0]) <= abs(abs(dy) - half_extents[1]):
        return (math.copysign(1.0, dx), 0.0)
    return (0.0, math.copysign(1.0, dy))


def contact_on_face(obs: Contacts, normals: Mapping[str, Vec]) -> dict[str, bool]:
    """Per fingertip: in contact on its grasp point's face (the contact normal within ~25 degrees of the
    face's), with the depth and anchor the goals need."""
    return {
        t: obs.contact[t]
        and t in obs.point
        and t in (obs.depth or {})
        and t in (obs.anchor or {})
        and obs.normal[t][0] * n[0] + obs.normal[t][1] * n[1] > 0.9
        for t, n in normals.items()
    }


def towards(tip: Vec, goal: Sequence[float], most: float) -> Vec:
    """`goal`, or the point `most` from `tip` towards it if it is farther (a goal always within fine reach)."""
    dx, dy = goal[0] - tip[0], goal[1] - tip[1]
    d = math.hypot(dx, dy)
    if d <= most:
        return (float(goal[0]), float(goal[1]))
    return (tip[0] + dx * most / d, tip[1] + dy * most / d)


def in_front(tip: Sequence[float], point: Vec, normal: Vec, center: Vec, half_extents: Vec) -> bool:
    """Whether `tip` lies outside the face through `point` (outward `normal`) and within its extent."""
    nx, ny = normal
    outside = (tip[0] - point[0]) * nx + (tip[1] - point[1]) * ny >= 0.0
    along = abs((tip[0] - center[0]) * -ny + (tip[1] - center[1]) * nx)
    return outside and along < (half_extents[1] if abs(nx) > abs(ny) else half_extents[0])
