"""Static obstacles of a walls scene (paper §5.4): boxes in the robot's plane, declared in the run file.

```toml
[[scene.obstacle]]
id = "upper"                    # optional, [A-Za-z0-9_-]+, unique (default "obstacle<i>")
center = [4.5, 4.4]             # x, y of the box centre in the world
half_extents = [1.5, 2.0]       # half width along the box's x, half height along its y (> 0)
angle_deg = 0.0                 # optional rotation of the box about z
```

Walls are solid: the simulator refuses a joint increment that would make a link penetrate one (sim/scenes/walls.py).
Parsed by `scene.parse_scene` into `SceneSpec.obstacles`; errors name the file and the field.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Any

from .spec import SpecError, number, vector

_ID_RE = re.compile(r"^[A-Za-z0-9_-]{1,64}$")
_KEYS = {"id", "center", "half_extents", "angle_deg"}


@dataclass(frozen=True)
class ObstacleSpec:
    id: str
    center: tuple[float, float]
    half_extents: tuple[float, float]
    angle: float  # radians

    def corners(self) -> list[tuple[float, float]]:
        """The box's four corners in the world, counter-clockwise (for drawing)."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        hx, hy = self.half_extents
        out = []
        for sx, sy in ((-1, -1), (1, -1), (1, 1), (-1, 1)):
            x, y = sx * hx, sy * hy
            out.append((self.center[0] + c * x - s * y, self.center[1] + s * x + c * y))
        return out

    def signed_distance(self, x: float, y: float) -> float:
        """Signed distance of the point (x, y) to the box (negative inside): the closed form the tests check
        PyBullet's clearance against."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        dx, dy = x - self.center[0], y - self.center[1]
        lx, ly = c * dx + s * dy, -s * dx + c * dy
        qx, qy = abs(lx) - self.half_extents[0], abs(ly) - self.half_extents[1]
        outside = math.hypot(max(qx, 0.0), max(qy, 0.0))
        return outside + min(max(qx, qy), 0.0)


def parse_obstacles(rows: Any, source: str, where: str = "scene.obstacle") -> tuple[ObstacleSpec, ...]:
    """The `[[scene.obstacle]]` tables of a run file (absent: no obstacles)."""

    def num(at: str, v: Any) -> float:
        return number(source, at, v)

    def pair(at: str, v: Any) -> tuple[float, float]:
        x, y = vector(source, at, v, 2)
        return (x, y)

    if rows is None:
        return ()
    if not isinstance(rows, list):
        raise SpecError(source, where, "expected [[scene.obstacle]] tables (an array of tables)")
    out: list[ObstacleSpec] = []
    seen: set[str] = set()
    for i, row in enumerate(rows):
        at = f"{where}[{i}]"
        if not isinstance(row, dict):
            raise SpecError(source, at, "must be a table")
        bad = set(row) - _KEYS
        if bad:
            expected = ", ".join(sorted(_KEYS))
            raise SpecError(source, f"{at}.{sorted(bad)[0]}", f"unknown field (expected {expected})")
        oid = row.get("id", f"obstacle{i}")
        if not isinstance(oid, str) or not _ID_RE.match(oid):
            raise SpecError(source, f"{at}.id", f"expected letters, digits, '_' or '-', got {oid!r}")
        if oid in seen:
            raise SpecError(source, f"{at}.id", f"duplicate obstacle id {oid!r}")
        seen.add(oid)
        for key in ("center", "half_extents"):
            if key not in row:
                raise SpecError(source, f"{at}.{key}", "missing (a box needs center and half_extents)")
        center = pair(f"{at}.center", row["center"])
        half = pair(f"{at}.half_extents", row["half_extents"])
        if not (half[0] > 0 and half[1] > 0):
            raise SpecError(source, f"{at}.half_extents", f"both must be > 0, got {list(half)}")
        angle = num(f"{at}.angle_deg", row.get("angle_deg", 0.0))
        out.append(ObstacleSpec(id=oid, center=center, half_extents=half, angle=math.radians(angle)))
    return tuple(out)
