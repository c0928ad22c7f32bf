"""Scenes: what surrounds the robot, one module per kind (`[scene] kind` of the run file), each holding a `Scene`
subclass named SCENE (base.py is the interface)."""

from __future__ import annotations

import importlib

from kinswarm.protocol.scene import SCENE_KINDS, SceneSpec
from kinswarm.sim.world import World

from .base import Scene

SPATIAL_KINDS = ("free",)  # the scenes a spatial robot (from URDF) can be in


def scene_class(kind: str) -> type[Scene]:
    if kind not in SCENE_KINDS:
        raise ValueError(f"unknown scene kind {kind!r}; expected one of {', '.join(SCENE_KINDS)}")
    return importlib.import_module(f"{__name__}.{kind}").SCENE


def build_scene(world: World, spec: SceneSpec, action_rad: float) -> Scene:
    cls = scene_class(spec.kind)
    if world.topo.spatial and spec.kind not in SPATIAL_KINDS:  # walls and objects lie in the plane z = 0
        raise ValueError(f"the {spec.kind} scene is planar; a robot from URDF ({world.topo.name}) runs in free space")
    return cls(world, spec, action_rad)


__all__ = ["Scene", "build_scene", "scene_class"]
