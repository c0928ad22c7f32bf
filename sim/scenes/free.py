"""Free space: nothing around the robot (the base Scene)."""

from .base import Scene

SCENE = Scene
