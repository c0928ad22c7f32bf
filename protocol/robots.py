"""A robot from its `[robot]` table or its file: a planar robot of agents (topology.py) or a robot from URDF
(urdf_robot.py), both as a Topology."""

from __future__ import annotations

import tomllib
from pathlib import Path
from typing import Any

from .spec import SpecError
from .topology import Topology, parse_planar_robot


def parse_robot(robot: Any, source: str = "<memory>", where: str = "robot") -> Topology:
    """Validate a `[robot]` table and build the Topology; errors name the source and the field."""
    if isinstance(robot, dict) and "urdf" in robot:
        from .urdf_robot import parse_urdf_robot  # here: it needs numpy, which reading a run's config does not

        return parse_urdf_robot(robot, source, where)
    return parse_planar_robot(robot, source, where)


def load_robot(path: str | Path) -> Topology:
    """The robot of a robot file or a run file: its [robot] table (named after the file unless it names itself)."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text())
    except OSError as e:
        raise SpecError(str(path), "file", f"cannot read: {e.strerror or e}") from None
    except tomllib.TOMLDecodeError as e:
        raise SpecError(str(path), "toml", str(e)) from None
    robot = data.get("robot")
    if not isinstance(robot, dict):
        raise SpecError(str(path), "robot", "a robot file needs a [robot] table")
    return parse_robot({"name": path.stem, **robot}, str(path))
