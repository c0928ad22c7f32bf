"""The sensed tip (a reach task's `tip = "sensed"`), shared by the planar reach and reach3d.

Every agent builds its state from the tip it computes by forward kinematics from the encoders; the reward comes from
the tip as sensed (Task.tips). An encoder that reads wrong makes the two disagree, and a swarm that brings its
computed tip to the goal leaves the real one off by the error. With `tip = "sensed"` the root sends the sensed tips
down with its context (`context`); an agent whose computed tip differs from the sensed one (its subtree's) by more
than TIP_PRECISION aims at the goal moved by that difference (`moved_goal`), so that its computed tip at the aim is
its sensed tip at the goal. Within TIP_PRECISION, as on a sound robot, it aims at the goal itself: the same state,
the same decisions, bit for bit. It reads no fault: only the two tips it has.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence

#: tip: the tip the agents aim by ("computed" from their encoders; "sensed": the task's observation where they disagree)
TIPS: tuple[str, ...] = ("computed", "sensed")
#: a disagreement below this is the sensor's precision, not the robot's (the robot's unit: m in 3D). On a sound robot
#: in PyBullet the two differ by its single precision: < 5.1e-7 on chain4, < 1.6e-7 m on the iiwa (notebook: adapt)
TIP_PRECISION = 1e-3


def check_tip(tip: str) -> None:
    """The `tip` setting's one-line error."""
    if tip not in TIPS:
        raise ValueError(f"tip: {tip!r} is not one of {', '.join(TIPS)}")


def sensed_key(leaf: str, axis: str) -> str:
    """The context's reading of a leaf's sensed tip."""
    return f"tip.{leaf}.{axis}"


def context(tips: Mapping[str, Sequence[float]], axes: str) -> dict[str, float]:
    """The root's context: every leaf's sensed position along `axes` ("xy" planar, "xyz" spatial; a frame's heading
    or orientation stays out)."""
    return {sensed_key(leaf, a): float(p[i]) for leaf, p in tips.items() for i, a in enumerate(axes)}


def keys(leaves: Sequence[str], axes: str) -> list[tuple[str, ...]]:
    """The context keys of each leaf's sensed position, in `axes` order."""
    return [tuple(sensed_key(leaf, a) for a in axes) for leaf in leaves]


def moved_goal(
    goal: Sequence[float], tip: Sequence[float], sense: Mapping[str, float], leaf_keys: Sequence[tuple[str, ...]]
) -> tuple[float, ...] | None:
    """The goal's position (its first len(axes) coordinates) moved by (computed tip - sensed tip), the rest of the
    goal (a pose's orientation) as it is; None where there is nothing to move: a leaf's tip not sensed this step, or
    the two tips within TIP_PRECISION."""
    points = [[sense[k] for k in ks] for ks in leaf_keys if all(k in sense for k in ks)]
    if not points or len(points) != len(leaf_keys):
        return None
    n, m = len(leaf_keys[0]), len(points)
    d = [tip[i] - sum(p[i] for p in points) / m if m > 1 else tip[i] - points[0][i] for i in range(n)]
    if math.hypot(*d) <= TIP_PRECISION:
        return None
    return (*(goal[i] + d[i] for i in range(n)), *goal[n:])
