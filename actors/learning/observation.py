"""What an agent observes each step (paper §3.3): the variables of its state S_i, named and bounded, apart from what
any learner makes of them.

The task owns an agent's observation (actors/tasks/base.py, `TaskDef.observation`): the state kind its joint builds
(the paper's planar six, a spatial joint's rotation plane or its turn), the form of g3, the bounds of the kind's
variables on the task's scale, and the extra variables (the task's first, then those the run file adds). A learner
(actors/learning/kinds.py) is built over an observation with its own settings: the fuzzy learners lay their sets over
these bounds; a variable's `sets` is the resolution a grid learner gives it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

#: Names of the six state variables S_i = <q_i, theta_i, d_i, g1, g2, g3> (paper §3.3).
STATE_NAMES: tuple[str, ...] = ("q", "theta", "d", "g1", "g2", "g3")
#: The rotation-plane state of a spatial joint (state.plane_state): S_i = <q, d, g_perp, g_axial, g_radial, |w|>.
PLANE_STATE_NAMES: tuple[str, ...] = ("q", "d", "g_perp", "g_axial", "g_radial", "w")
#: The turn state of a spatial joint: S_i = <g_q>, the move to its own best value within its limits (frames.best_turn).
TURN_STATE_NAMES: tuple[str, ...] = ("g_q",)
#: The state kinds: the paper's planar S_i; a joint of a robot from URDF: its rotation plane, or its turn.
STATE_KINDS: dict[str, tuple[str, ...]] = {"planar": STATE_NAMES, "plane": PLANE_STATE_NAMES, "turn": TURN_STATE_NAMES}
#: The kinds a robot from URDF takes (a planar robot takes "planar")
SPATIAL_STATES: tuple[str, ...] = ("plane", "turn")
#: g3 as the bearing of the goal from the end effector (signed, the default) or its size only (unsigned).
G3_MODES: tuple[str, ...] = ("signed", "unsigned")
#: Reach of the paper's planar 4R chain (4 links of length 3); default ranges scale with it.
DEFAULT_REACH = 12.0
#: The fields of the run file's [learner] table that are the observation's (the others are the learner's own)
OBSERVATION_FIELDS: tuple[str, ...] = ("state", "g3", "ranges", "extra_state")

Bounds = tuple[tuple[float, float], ...]


def ranges_for(reach: float) -> Bounds:
    """The planar six's bounds on a robot of `reach`."""
    return (
        (-math.pi, math.pi),  # q: joint angle
        (-math.pi, math.pi),  # theta: bearing of the end effector in the agent frame
        (0.0, reach),  # d: distance joint -> end effector
        (-2.0 * reach, 2.0 * reach),  # g1: goal - tip, x in the agent frame
        (-2.0 * reach, 2.0 * reach),  # g2: goal - tip, y in the agent frame
        (-math.pi, math.pi),  # g3: bearing of the goal from the end effector
    )


def plane_ranges(reach: float, lever: float, limits: tuple[float, float]) -> Bounds:
    """A spatial joint's rotation-plane bounds (state.plane_state) on a robot of `reach` (m) whose tip can lie up to
    `lever` from this joint: q over its limits, d over [0, lever], g_perp over ±reach/10, g_axial and g_radial over
    ±reach/3, |w| over [0, reach/2.4]."""
    for name, v in (("reach", reach), ("lever", lever)):
        if not (isinstance(v, (int, float)) and math.isfinite(v) and v > 0):
            raise ValueError(f"{name} must be a positive finite number, got {v!r}")
    lo, hi = limits
    r = float(reach)
    return ((lo, hi), (0.0, float(lever)), (-r / 10, r / 10), (-r / 3, r / 3), (-r / 3, r / 3), (0.0, r / 2.4))


#: A spatial joint's turn bound: g_q (rad) over ±15°; farther moves saturate in the end sets.
TURN_RANGES: Bounds = ((-math.pi / 12, math.pi / 12),)


@dataclass(frozen=True)
class StateVariable:
    """An extra state variable appended to S_i: its name, how many membership sets, and the range they span.

    Its value comes from the agent's task (e.g. the corridor's "clearance"), from the agent's own geometry
    ("g_perp": the goal's component along the direction the agent's joint moves the tip, state.goal_along_motion),
    or else from the readings the agent holds (its Obs.sense and the Down.sense from its parent) by that name."""

    name: str
    sets: int
    range: tuple[float, float]

    def __post_init__(self) -> None:
        r = tuple(self.range) if isinstance(self.range, (list, tuple)) else ()
        if len(r) != 2 or not all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in r):
            raise ValueError(
                f"extra state variable {self.name!r}: range must be two numbers [lo, hi], got {self.range!r}"
            )
        object.__setattr__(self, "range", (float(r[0]), float(r[1])))
        lo, hi = self.range
        if not (isinstance(self.name, str) and self.name):
            raise ValueError(f"extra state variable: a name is needed, got {self.name!r}")
        if not (isinstance(self.sets, int) and not isinstance(self.sets, bool) and self.sets >= 1):
            raise ValueError(f"extra state variable {self.name!r}: sets must be an int >= 1, got {self.sets!r}")
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"extra state variable {self.name!r}: range must be finite with lo < hi, got {self.range}")


@dataclass(frozen=True)
class Observation:
    """An agent's S_i: the state kind's variables (STATE_KINDS) over `ranges`, then `extra_state`."""

    state: str = "planar"  # what S_i holds (STATE_KINDS): the paper's six, a spatial joint's "plane" or its "turn"
    g3: str = "signed"  # "unsigned": |g3|, so a goal straight behind the tip is one case, not both ends of g3
    ranges: Bounds = ranges_for(DEFAULT_REACH)  # (lo, hi) per variable of the kind; outside clips
    extra_state: tuple[StateVariable, ...] = ()  # variables appended to S_i (a task's come first)

    @property
    def names(self) -> tuple[str, ...]:
        return STATE_KINDS[self.state] + tuple(v.name for v in self.extra_state)

    @property
    def bounds(self) -> Bounds:
        return self.ranges + tuple(v.range for v in self.extra_state)

    @classmethod
    def for_reach(cls, reach: float, **fields: object) -> Observation:
        """The planar six on a robot of `reach`: d in [0, reach], g1, g2 in [-2 reach, 2 reach]."""
        if not (isinstance(reach, (int, float)) and math.isfinite(reach) and reach > 0):
            raise ValueError(f"reach must be a positive finite number, got {reach!r}")
        return cls(**{"ranges": ranges_for(float(reach)), **fields})  # type: ignore[arg-type]

    def with_task_state(self, variables: tuple[StateVariable, ...]) -> Observation:
        """This observation with a task's state variables before the extra ones it has."""
        return replace(self, extra_state=(*variables, *self.extra_state)) if variables else self

    def __post_init__(self) -> None:
        check_observation(self)


def check_observation(o: Any) -> None:
    """Validate and normalise (tuples of floats, StateVariables) the observation fields of `o` (an Observation, or
    the fuzzy learner's settings, which carry the same fields for the run file's flat [learner] table)."""
    state = o.state
    if state not in STATE_KINDS:
        raise ValueError(f"state must be one of {', '.join(STATE_KINDS)}, got {state!r}")
    base_names = STATE_KINDS[state]
    ranges = tuple((float(lo), float(hi)) for lo, hi in o.ranges)
    extra = tuple(_variable(v) for v in o.extra_state)
    object.__setattr__(o, "ranges", ranges)
    object.__setattr__(o, "extra_state", extra)
    if len(ranges) != len(base_names):
        raise ValueError(f"ranges needs {len(base_names)} (lo, hi) pairs {base_names}, got {len(ranges)}")
    for name, (lo, hi) in zip(base_names, ranges, strict=True):
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"ranges[{name}] must be finite with lo < hi, got ({lo}, {hi})")
    names = base_names + tuple(v.name for v in extra)
    if len(set(names)) != len(names):
        raise ValueError(f"state variable names must differ, got {list(names)}")
    g3 = o.g3
    if g3 not in G3_MODES:
        raise ValueError(f"g3 must be one of {G3_MODES}, got {g3!r}")
    if g3 == "unsigned" and state == "planar" and ranges[5][0] < 0.0:
        raise ValueError(
            f"g3 'unsigned' lies in [0, pi], but ranges[g3] starts at {ranges[5][0]:g}: "
            "the sets below 0 would never fire (use e.g. (0, pi))"
        )


def _variable(v: object) -> StateVariable:
    """A StateVariable, or one from a mapping {name, sets, range} or a (name, sets, range) triple."""
    if isinstance(v, StateVariable):
        return v
    if isinstance(v, dict):
        unknown, missing = set(v) - {"name", "sets", "range"}, {"name", "sets", "range"} - set(v)
        if unknown or missing:
            what = f"unknown field {sorted(unknown)[0]!r}" if unknown else f"missing {sorted(missing)[0]!r}"
            raise ValueError(f"extra state variable: {what} (it takes name, sets, range)")
        return StateVariable(v["name"], v["sets"], v["range"])
    if isinstance(v, (list, tuple)) and len(v) == 3:
        return StateVariable(v[0], v[1], tuple(v[2]))  # type: ignore[arg-type]
    raise ValueError(f"extra state variable: expected {{name, sets, range}}, got {v!r}")
