"""Tuning reach3d in a plain loop (research): the iiwa's seven learners, their rotation-plane states and the root's
graded reward, stepped one after the other in one process — no wire, no simulator process, the arm's model
(protocol/frames.py) for its pose. The same Learner, state, reward and g_rot as the swarm; only the message passing
is gone, so a training takes about a minute, not several. It chose the settings of `kinswarm experiment reach3d`;
the report's numbers are the swarm's own, not these.

    python -m kinswarm.experiments.research reach3d_loop --out runs/research          # DEFAULT's variants, ~20 min
    python -m kinswarm.experiments.research reach3d_loop --quick --out runs/research  # seconds

The task now weighs the orientation 0.3 m/rad (frames.POSE_WEIGHT, chosen here: w03); the variants keep their own
weight (W_TASK, 0.1, unless a variant says), so each still means what it measured.

Measured (seed 0 unless said; within 5 cm of 100 unseen goals from random starts, test sets A / B of the reach3d
experiment, frozen after training; 2026-11-24, a loaded 2-core machine):
- points, 300 steps: 48 goals x 4 passes 89 %; 96 x 4 92 % (seed 1: 93 % / 86 %); 128 x 3 89 %; q out of the
  state 78 %; epsilon_decay 0.03 87 %. 400 steps, 96 x 4: 97 % / 92 % (seed 1: 96 % / 93 %); g_perp in 11 sets
  96 % / 90 % (seed 1: 92 % / 86 %). The rule on g_perp: 95 % (set A, 300 steps).
- poses (within 5 cm and 15°, set A): 96 x 4, 300 steps 35 % (mean 3.9 cm, 30.6°); the rule 30 % (6.1 cm, 31°).

Poses, 2026-11-24 (96 x 4, 400 steps; within 5 cm and 15° [within 5 cm] mean cm / deg; seed 0 set A unless said;
`REACH3D_LOOP_ONLY=key REACH3D_LOOP_SEEDS=0 REACH3D_LOOP_SETS=A python -m kinswarm.experiments.research reach3d_loop
--out runs/research-poses`; results.json gathers them):
- pose (the task's until then: D = |w| + 0.1 angle, g_rot 5 sets ±45°): seeds 0/1/2 14/37/26 % [83/90/91]
  4.7/4.0/3.6 cm, 39/26/34°: the position is reached, the orientation not.
- the reward's orientation weight (D = |w| + W angle, the state as the task's): W 0.2 44 % [61]; W 0.3 (w03) 60 / 62 /
  65 % on A, 48 / 64 / 59 % on B (seeds 0/1/2; 5.9-9.2 cm, 13-20°); W 0.4 38 % [41]; W 0.5 33 % [33] 20 cm, 14°.
  W 0.3 with 192 x 4 goals 52 %; W 0.3 without g_rot 0 % [7] 113°: g_rot carries the orientation.
  D = sqrt(|w|^2 + (W angle)^2): W 0.2 57 %, W 0.25 54 % (96 x 8: 50 %), W 0.3 (l2w03) 64/63/50 % on A, 65/60/54 %
  on B.
- state, with the task's reward (W 0.1): g_rot 9 sets over ±60° 21 %; g_rot and |phi| 27 %.
- state, with W 0.3: g_rot 9 sets over ±60° 55 %; + |phi| 42 %; + -dD/dq (9 sets, ±0.3 m/rad) 24 %; g_perp replaced
  by g_perp + 0.3 phi.a 42 %; (l2, W 0.3) g_perp replaced by g_perp + 0.09 phi.a/|r_perp| 59 %, |w| replaced by D 46 %.
- limit-aware state, W 0.3 (lim = the room, rad, left toward where g_perp + 0.3 phi.a turns the joint: q_max - q if
  it is > 0, else q - q_min): g_rot and lim 3 sets over [0, 0.5] rad (w03lim3) 52 % [62] 7.7 cm, 20°; 5 sets (w03lim5)
  51 % [62]; q in 7 sets, not 5 (w03q7) 53 % [66]; q replaced by lim, 5 sets over [0, 0.5] (w03qlim) 61 / 51 % on A,
  60 / 62 % on B (seeds 0/1; 6.4-7.7 cm, 13-20°), w03's 60 / 62 and 48 / 64: the same 58.5 % mean. Knowing the
  limit is near does not get a joint out of the minimum; a variable more only thins the training (96 x 4).
- why: one joint's 1° step moves the tip |r_perp| x 1° and turns the tool at most 1°, so with D = |w| + W angle only
  joints with a lever under W can trade position for orientation alone; at 0.1 m/rad that is the flange's joint.
  Greedy per joint on the model (sim/baseline.py's law on D, set A, 400 steps): sum W 0.1 14 %, 0.2 34 %, 0.3 48 %;
  l2 W 0.1 29 % (the baseline's greedy), 0.15 64 %, 0.2 77 %, 0.25 78 % (800 steps 78 %), 0.3 70 %, 0.45 59 %, 1.0
  7 %; a joint-limit barrier added does not help (77 %, 69 %). The trained swarm's failures (l2w03, seed 0): 25 of 36
  end with a joint at its limit, 35 of 36 have stopped moving, 2 of 36 were ever within the tolerance: local minima,
  as the greedy's and the pseudo-inverse's (58 % at 400 steps, 65 % at 3000; 41 of its 42 failures at a limit).
- the turn, g_q (frames.best_turn: the move to the joint's own best angle within its limits, the others held), D =
  sqrt(|w|^2 + (0.25 angle)^2), sets A / B (test sets A and B, seed 0 unless said): with the plane state, g_rot and
  g_q 5 sets +-45 deg (gq5) 55 / 54 %; g_q, no g_rot (gq5only) 55 / 55 %; g_q 9 sets alone, the plane state
  uninformative (gq9solo) 76 / 65 %; but |w| (gq9w) 19 / 19 %; gq9solo with quarter moves under D 0.1 m (gq9f) 85 /
  82 %; and g_q over +-15 deg (gq9_15f) 93 / 90 %, seed 1 82 / 86 %, seed 2 87 / 89 %.
- the turn state itself (LearnerSettings.for_turn: g_q alone, 9 rules, no uninformative variables): at lr 0.5 (turn)
  36 / 32 %. gq9_15f's 6 uninformative variables fire 64 rules per set of g_q, each at 1/64 of its weight, which
  divides the learning rate by 64: turn_lr (0.5 / 64) 88 / 90 %; lr 0.05 35 / 27 %; 0.002 91 / 83 %. Kept: the turn
  state at lr 0.5 / 64. Seeds 0-2, A / B: 96 x 4 (turn_lr) 85.0 / 82.3 %; 96 x 8 (turn_p8) 85.7 / 82.0 %; 192 x 4
  (turn_g192) 82.7 / 73.7 %: more experience does not help; the protocol stays 96 x 4.
"""

from __future__ import annotations

import json
import math
import os
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from kinswarm.actors.agent.geometry import Spatial
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.settings import LearnerSettings, StateVariable
from kinswarm.actors.tasks.reach import reach_reward
from kinswarm.actors.tasks.reach3d import wire_goal
from kinswarm.experiments import reach3d as r3
from kinswarm.experiments.common import Context
from kinswarm.protocol import frames
from kinswarm.protocol.robots import load_robot
from kinswarm.protocol.topology import Topology

SEEDS = 1
INC = math.radians(1)
FINE = 0.25  # a fine move's share of INC (Variant.fine)
# Research-only selections (the research runner has no flags for them): REACH3D_LOOP_ONLY=key,key (variants),
# REACH3D_LOOP_SEEDS=0,1 (seeds, instead of --seeds), REACH3D_LOOP_SETS=A (test sets).
ENV_ONLY, ENV_SEEDS, ENV_SETS = "REACH3D_LOOP_ONLY", "REACH3D_LOOP_SEEDS", "REACH3D_LOOP_SETS"
#: m/rad: the orientation's weight in D_goal these variants were measured against (frames.POSE_WEIGHT until
#: 2026-11-24); fixed here so that a variant keeps its meaning when the task's weight changes
W_TASK = 0.1
#: g_rot: how far (rad) the tool must still turn about this joint's own axis, over ±45° (5 sets): the pose variable of
#: the plane state until the turn state replaced it
G_ROT = StateVariable("g_rot", 5, (-math.pi / 4, math.pi / 4))
#: what runs without REACH3D_LOOP_ONLY (REACH3D_LOOP_ONLY=all: every variant)
DEFAULT = ("pt300", "pt400", "pt400g11", "pose", "w03")


@dataclass(frozen=True)
class Geo:
    """What a joint's pose variables are made of: its world axis a, the tool's rotation error phi (world axis x
    angle still to turn, frames.orientation_error), the tool's frame, the joint -> tip lever r and w = goal - tip,
    the joint's angle q and its limits (rad)."""

    a: np.ndarray
    phi: np.ndarray
    tool: tuple[float, ...]
    r: np.ndarray
    w: np.ndarray
    q: float = 0.0
    limits: tuple[float, float] = (-math.pi, math.pi)
    goal: tuple[float, ...] = ()


def _g_rot(g: Geo) -> float:
    return float(g.phi @ g.a)  # the task's g_rot: the turn about this joint's own axis


def _rot(g: Geo) -> float:
    return float(np.linalg.norm(g.phi))  # |phi|: how far the tool must still turn, about any axis


def _rot_off(g: Geo) -> float:
    return float(np.linalg.norm(g.phi - (g.phi @ g.a) * g.a))  # the turn this joint cannot make


def _d_dir(g: Geo, weight: float) -> float:
    """-dD/dq (m/rad): how fast turning this joint up shrinks D = |w| + weight |phi| (> 0: increase q)."""
    nw, nphi = np.linalg.norm(g.w), np.linalg.norm(g.phi)
    pos = float(g.w @ np.cross(g.a, g.r)) / nw if nw > 1e-12 else 0.0
    rot = float(g.phi @ g.a) / nphi if nphi > 1e-12 else 0.0
    return pos + weight * rot


def _g_pose(g: Geo, weight: float) -> float:
    """The rule's signal (sim/baseline.py _spatial_rule): g_perp + weight x (phi . a), in m."""
    m = np.cross(g.a, g.r)
    lever = np.linalg.norm(m)
    return (float(g.w @ m) / lever if lever > 1e-12 else 0.0) + weight * float(g.phi @ g.a)


def _g_l2(g: Geo, weight: float) -> float:
    """g_perp of D = sqrt(|w|^2 + (weight angle)^2): -dD/dq x D / |r_perp| = g_perp + weight^2 (phi . a) / |r_perp|
    (m; the sign is greedy descent's on that D)."""
    m = np.cross(g.a, g.r)
    lever = float(np.linalg.norm(m))
    if lever < 1e-9:
        return float(np.sign(g.phi @ g.a))  # a joint through the tip only turns it: saturate
    return (float(g.w @ m) + weight * weight * float(g.phi @ g.a)) / lever


def _lim(g: Geo, weight: float) -> float:
    """The room (rad) this joint has left in the direction g_perp + weight (phi . a) wants it to turn."""
    lo, hi = g.limits
    return hi - g.q if _g_pose(g, weight) > 0 else g.q - lo


def _g_q(g: Geo) -> float:
    """The task's g_q (frames.best_turn): the move to this joint's own best angle within its limits."""
    lo, hi = g.limits
    joint = np.asarray(g.tool[:3]) - g.r
    return frames.best_turn(g.a, joint, g.tool, g.goal, (lo - g.q, hi - g.q))


#: name -> (its StateVariable, how a joint computes it)
POSE_VARS: dict[str, tuple[StateVariable, Callable[[Geo], float]]] = {
    "g_rot": (G_ROT, _g_rot),
    "g_rot9": (StateVariable("g_rot", 9, (-math.pi / 3, math.pi / 3)), _g_rot),
    "g_rot9_45": (StateVariable("g_rot", 9, (-math.pi / 4, math.pi / 4)), _g_rot),
    "g_rot7_30": (StateVariable("g_rot", 7, (-math.pi / 6, math.pi / 6)), _g_rot),
    "rot": (StateVariable("rot", 5, (0.0, math.pi / 2)), _rot),
    "rot_off": (StateVariable("rot_off", 5, (0.0, math.pi / 2)), _rot_off),
    "d_dir": (StateVariable("d_dir", 9, (-0.3, 0.3)), lambda g: _d_dir(g, W_TASK)),
    "d_dir3": (StateVariable("d_dir", 9, (-0.3, 0.3)), lambda g: _d_dir(g, 0.3)),
    "g_pose": (StateVariable("g_pose", 9, (-0.12, 0.12)), lambda g: _g_pose(g, W_TASK)),
    "g_l2_03": (StateVariable("g_l2", 9, (-0.12, 0.12)), lambda g: _g_l2(g, 0.3)),
    "g_pose3": (StateVariable("g_pose", 9, (-0.12, 0.12)), lambda g: _g_pose(g, 0.3)),
    "lim3": (StateVariable("lim", 3, (0.0, 0.5)), lambda g: _lim(g, 0.3)),
    "lim5": (StateVariable("lim", 5, (0.0, 0.5)), lambda g: _lim(g, 0.3)),
    "g_q5": (StateVariable("g_q", 5, (-math.pi / 4, math.pi / 4)), _g_q),
    "g_q9": (StateVariable("g_q", 9, (-math.pi / 4, math.pi / 4)), _g_q),
    "g_q9_15": (StateVariable("g_q", 9, (-math.pi / 12, math.pi / 12)), _g_q),
}


@dataclass(frozen=True)
class Variant:
    key: str
    label: str
    overrides: dict[str, Any] = field(default_factory=dict)
    goals: int = 96
    passes: int = 4
    steps: int = 400
    pose: bool = True
    pose_state: tuple[str, ...] = ("g_rot",)  # POSE_VARS appended to the plane state for a pose goal
    pose_weight: float = W_TASK  # m/rad: the orientation's weight in the reward's D_goal only
    g_perp: str = ""  # a POSE_VARS name whose value replaces g_perp (state index 2), "" keeps g_perp
    q_var: str = ""  # a POSE_VARS name whose value, sets and range replace q's (state index 0), "" keeps q
    w_is_D: bool = False  # the plane state's |w| (index 5) replaced by the reward's D_goal (the pose's distance)
    fine: float = 0.0  # m: a move is FINE of its size while D_goal is under this (0: never)
    turn: bool = False  # the learner's state kind "turn" (LearnerSettings.for_turn: g_q alone), not the plane's
    norm: str = "sum"  # D_goal = |w| + weight angle ("sum", the task's), or sqrt(|w|^2 + (weight angle)^2) ("l2")


def _turn(key: str, label: str, overrides: dict[str, Any], goals: int = 96, passes: int = 4) -> Variant:
    """A variant of the turn state as the task has it: D_goal = sqrt(|w|^2 + (0.25 angle)^2), quarter moves under
    0.1 m."""
    return Variant(key, label, overrides, goals, passes, turn=True, pose_weight=0.25, norm="l2", fine=0.1)


VARIANTS: tuple[Variant, ...] = (
    Variant("pt300", "points, 96 x 4, 300 steps", steps=300, pose=False),
    Variant("pt400", "points, 96 x 4, 400 steps", pose=False),
    Variant("pt400g11", "points, 96 x 4, 400 steps, g_perp 11 sets", {"n_sets": (5, 5, 11, 5, 5, 6)}, pose=False),
    Variant("pose", "poses, 96 x 4, 400 steps (D = |w| + 0.1 angle)"),
    Variant("rot9", "poses, g_rot 9 sets over +-60 deg", pose_state=("g_rot9",)),
    Variant("w03", "poses, reward's orientation 0.3 m/rad", pose_weight=0.3),
    Variant("w02", "poses, reward's orientation 0.2 m/rad", pose_weight=0.2),
    Variant("w04", "poses, reward's orientation 0.4 m/rad", pose_weight=0.4),
    Variant(
        "w03norot",
        "poses, reward's orientation 0.3 m/rad, no g_rot (the plane state only)",
        pose_weight=0.3,
        pose_state=(),
    ),
    Variant("w03g192", "poses, reward's orientation 0.3 m/rad, 192 x 4", pose_weight=0.3, goals=192),
    Variant("w05", "poses, reward's orientation 0.5 m/rad", pose_weight=0.5),
    Variant("w03rot9", "poses, 0.3 m/rad, g_rot 9 sets over +-60 deg", pose_state=("g_rot9",), pose_weight=0.3),
    Variant(
        "w03rotoff", "poses, 0.3 m/rad, g_rot and |phi - (phi.a) a|", pose_state=("g_rot", "rot_off"), pose_weight=0.3
    ),
    Variant("w03rot", "poses, 0.3 m/rad, g_rot and |phi|", pose_state=("g_rot", "rot"), pose_weight=0.3),
    Variant(
        "w03ddir",
        "poses, 0.3 m/rad, g_rot and -dD/dq (w 0.3; 9 sets, +-0.3 m/rad)",
        pose_state=("g_rot", "d_dir3"),
        pose_weight=0.3,
    ),
    Variant(
        "w03gpose", "poses, 0.3 m/rad, g_perp -> g_perp + 0.3 phi.a, g_rot kept", g_perp="g_pose3", pose_weight=0.3
    ),
    Variant("l2w03", "poses, D = sqrt(|w|^2 + (0.3 angle)^2)", pose_weight=0.3, norm="l2"),
    Variant("l2w02", "poses, D = sqrt(|w|^2 + (0.2 angle)^2)", pose_weight=0.2, norm="l2"),
    Variant("l2w015", "poses, D = sqrt(|w|^2 + (0.15 angle)^2)", pose_weight=0.15, norm="l2"),
    Variant(
        "l2w02D",
        "poses, D = sqrt(|w|^2 + (0.2 angle)^2), |w| -> D in the state",
        pose_weight=0.2,
        norm="l2",
        w_is_D=True,
    ),
    Variant("l2w025", "poses, D = sqrt(|w|^2 + (0.25 angle)^2)", pose_weight=0.25, norm="l2"),
    Variant("l2w025p8", "poses, D = sqrt(|w|^2 + (0.25 angle)^2), 96 x 8", pose_weight=0.25, norm="l2", passes=8),
    Variant(
        "l2w025s600",
        "poses, D = sqrt(|w|^2 + (0.25 angle)^2), 600 steps (tests too)",
        pose_weight=0.25,
        norm="l2",
        steps=600,
    ),
    Variant("w03p8", "poses, reward's orientation 0.3 m/rad, 96 x 8", pose_weight=0.3, passes=8),
    Variant(
        "l2w03D",
        "poses, D = sqrt(|w|^2 + (0.3 angle)^2), |w| -> D in the state",
        pose_weight=0.3,
        norm="l2",
        w_is_D=True,
    ),
    Variant(
        "l2w03g",
        "poses, D = sqrt(|w|^2 + (0.3 angle)^2), g_perp -> g_perp + 0.09 phi.a / |r_perp|, g_rot kept",
        pose_weight=0.3,
        norm="l2",
        g_perp="g_l2_03",
    ),
    Variant("l2w05", "poses, D = sqrt(|w|^2 + (0.5 angle)^2)", pose_weight=0.5, norm="l2"),
    Variant(
        "w03lim3",
        "poses, 0.3 m/rad, g_rot and lim: room left toward g_perp + 0.3 phi.a (3 sets, [0, 0.5] rad)",
        pose_state=("g_rot", "lim3"),
        pose_weight=0.3,
    ),
    Variant(
        "w03lim5",
        "poses, 0.3 m/rad, g_rot and lim: room left toward g_perp + 0.3 phi.a (5 sets, [0, 0.5] rad)",
        pose_state=("g_rot", "lim5"),
        pose_weight=0.3,
    ),
    Variant(
        "w03qlim",
        "poses, 0.3 m/rad, q -> lim: room left toward g_perp + 0.3 phi.a (5 sets, [0, 0.5] rad)",
        q_var="lim5",
        pose_weight=0.3,
    ),
    Variant("w03q7", "poses, 0.3 m/rad, q in 7 sets", {"n_sets": (7, 5, 9, 5, 5, 6)}, pose_weight=0.3),
    Variant(
        "gq5",
        "poses, D l2 0.25, g_rot and g_q (5 sets, +-45 deg)",
        pose_state=("g_rot", "g_q5"),
        pose_weight=0.25,
        norm="l2",
    ),
    Variant(
        "gq5only",
        "poses, D l2 0.25, g_q (5 sets, +-45 deg), no g_rot",
        pose_state=("g_q5",),
        pose_weight=0.25,
        norm="l2",
    ),
    Variant(
        "gq9solo",
        "poses, D l2 0.25, the plane state blind (2 sets over +-1000), g_q 9 sets +-45 deg",
        {"n_sets": (2,) * 6, "ranges": ((-1000.0, 1000.0),) * 6},
        pose_state=("g_q9",),
        pose_weight=0.25,
        norm="l2",
    ),
    Variant(
        "gq9w",
        "poses, D l2 0.25, the plane state blind but |w|, g_q 9 sets +-45 deg",
        {"n_sets": (2, 2, 2, 2, 2, 6), "ranges": (*((-1000.0, 1000.0),) * 5, (0.0, 0.5))},
        pose_state=("g_q9",),
        pose_weight=0.25,
        norm="l2",
    ),
    Variant(
        "gq9f",
        "gq9solo, quarter moves under D 0.1 m",
        {"n_sets": (2,) * 6, "ranges": ((-1000.0, 1000.0),) * 6},
        pose_state=("g_q9",),
        pose_weight=0.25,
        norm="l2",
        fine=0.1,
    ),
    Variant(
        "gq9_15f",
        "gq9f, g_q 9 sets over +-15 deg",
        {"n_sets": (2,) * 6, "ranges": ((-1000.0, 1000.0),) * 6},
        pose_state=("g_q9_15",),
        pose_weight=0.25,
        norm="l2",
        fine=0.1,
    ),
    _turn("turn", "the turn state (g_q alone, 9 sets +-15 deg), quarter moves, lr 0.5", {"lr": 0.5}),
    _turn("turn_lr", "turn, lr 0.5 / 64 (gq9_15f's 64 uninformative rules per g_q set)", {"lr": 0.5 / 64}),
    _turn("turn_lr05", "turn, lr 0.05", {"lr": 0.05}),
    _turn("turn5", "turn, g_q 9 sets over +-5 deg", {"ranges": ((-math.pi / 36, math.pi / 36),)}),
    _turn("turn_lr002", "turn, lr 0.002", {"lr": 0.002}),
    _turn("turn_p8", "turn (lr 0.5 / 64), 96 x 8", {"lr": 0.5 / 64}, passes=8),
    _turn("turn_g192", "turn (lr 0.5 / 64), 192 x 4", {"lr": 0.5 / 64}, goals=192),
    Variant("rot", "poses, g_rot and |phi|", pose_state=("g_rot", "rot")),
    Variant("rotoff", "poses, g_rot and |phi - (phi.a) a|", pose_state=("g_rot", "rot_off")),
    Variant(
        "gpose", "poses, g_perp -> g_perp + 0.1 phi.a (9 sets, +-0.12 m), no g_rot", g_perp="g_pose", pose_state=()
    ),
    Variant("gpose_rot", "poses, g_perp -> g_perp + 0.1 phi.a, g_rot kept", g_perp="g_pose"),
    Variant("ddir", "poses, g_rot and -dD/dq (9 sets, +-0.3 m/rad)", pose_state=("g_rot", "d_dir")),
)


def _env_list(name: str) -> list[str] | None:
    v = os.environ.get(name, "").strip()
    return [x.strip() for x in v.split(",") if x.strip()] if v else None


class Loop:
    """One swarm's learners stepped in turn: each step every agent decides on its state, then observes its children."""

    def __init__(self, topo: Topology, seed: int, variant: Variant) -> None:
        self.topo, self.pose, self.geom, self.v = topo, variant.pose, Spatial(), variant
        self.vars = [POSE_VARS[n] for n in variant.pose_state] if self.pose else []
        self.replace = POSE_VARS[variant.g_perp][1] if self.pose and variant.g_perp else None
        self.q_var = POSE_VARS[variant.q_var] if self.pose and variant.q_var else None
        self.learners: dict[str, tuple[Learner, list[str]]] = {}
        for i, a in enumerate(topo.dof_agents):
            if variant.turn:
                children = list(topo.agents[a].children)
                st_turn = LearnerSettings.for_turn(**dict(variant.overrides))
                self.learners[a] = (Learner(st_turn, len(children), [seed, i]), children)
                continue
            st = LearnerSettings.for_plane(
                topo.reach, topo.reach_below(a), topo.agents[a].limits, **dict(variant.overrides)
            )
            if self.q_var is not None:
                qv = self.q_var[0]
                st = st.replace(n_sets=(qv.sets, *st.n_sets[1:]), ranges=(qv.range, *st.ranges[1:]))
            if self.pose:
                st = st.with_task_state(tuple(var for var, _ in self.vars))
            children = list(topo.agents[a].children)
            self.learners[a] = (Learner(st, len(children), [seed, i]), children)

    def distance(self, tip: tuple[float, ...], goal: tuple[float, ...]) -> float:
        D = math.dist(tip[:3], goal[:3])
        if len(goal) == 7:
            turn = self.v.pose_weight * frames.angle_between(tip[3:7], goal[3:7])
            D = math.hypot(D, turn) if self.v.norm == "l2" else D + turn
        return D

    def episode(self, goal: tuple[float, ...], start: list[float], epoch: int, steps: int, learn: bool) -> tuple:
        topo = self.topo
        q = {a: math.radians(v) for a, v in zip(topo.dof_agents, start, strict=True)}
        for learner, _ in self.learners.values():
            learner.start_epoch(epoch)
        D_prev = None
        for _ in range(steps):
            links = frames.link_frames(topo, q)
            (tip,) = frames.tips(topo, q).values()
            D = self.distance(tip, goal)
            r = None if D_prev is None else reach_reward(D, D_prev, "graded", D_min=0.3, c=10.0, k=200.0)
            D_prev = D
            phi = np.array(frames.orientation_error(tip[3:7], goal[3:7])) if self.pose else None
            acts = {}
            for a, (learner, _) in self.learners.items():
                spec = topo.agents[a]
                s = self.geom.state(spec, links[a], q[a], tip, goal, False, "turn" if self.v.turn else "plane")
                if phi is not None and not self.v.turn:
                    g = Geo(
                        np.array(frames.joint_axis(spec, links[a])),
                        phi,
                        tip,
                        np.subtract(tip[:3], links[a][:3]),
                        np.subtract(goal[:3], tip[:3]),
                        q[a],
                        spec.limits,
                        goal,
                    )
                    if self.replace is not None:
                        s[2] = self.replace(g)
                    if self.q_var is not None:
                        s[0] = self.q_var[1](g)
                    if self.v.w_is_D:
                        s[5] = D
                    s = np.append(s, [fn(g) for _, fn in self.vars])
                acts[a] = learner.decide(s, r, learn=learn, explore=learn)
            for learner, children in self.learners.values():
                learner.observe([acts[c] for c in children], learn=learn)
            inc = INC * (FINE if D < self.v.fine else 1.0)
            for a, act in acts.items():
                lo, hi = topo.agents[a].limits
                q[a] = min(max(q[a] + (act - 1) * inc, lo), hi)
        (tip,) = frames.tips(topo, q).values()
        angle = math.degrees(frames.angle_between(tip[3:7], goal[3:7])) if self.pose else 0.0
        return math.dist(tip[:3], goal[:3]), angle


def run(ctx: Context) -> dict[str, Any]:
    topo = load_robot(r3.ROBOT)
    only = _env_list(ENV_ONLY) or list(DEFAULT)
    if only == ["all"]:
        only = None
    seeds = [int(x) for x in _env_list(ENV_SEEDS) or ctx.seed_list]
    sets = _env_list(ENV_SETS) or list(r3.SETS)
    ctx.out.mkdir(parents=True, exist_ok=True)
    path = ctx.out / "results.json"
    results: dict[str, Any] = json.loads(path.read_text()) if path.exists() else {}
    for v in VARIANTS:
        if only is not None and v.key not in only:
            continue
        n_goals, passes, steps = (3, 1, 30) if ctx.quick else (v.goals, v.passes, v.steps)
        goals, starts = r3.training_set(topo, v.pose, n_goals, passes)
        for seed in seeds:
            loop = Loop(topo, seed, v)
            for e, (g, s) in enumerate(zip(goals, starts, strict=True)):
                loop.episode(wire_goal(tuple(g)), s, e, steps, learn=True)
            row = {}
            for name in sets:
                test_goals, test_starts = r3.sample(
                    topo, r3.SETS[name] + (7 if v.pose else 0), 3 if ctx.quick else 100, v.pose
                )
                ends = [
                    loop.episode(wire_goal(tuple(g)), s, 0, steps, False)
                    for g, s in zip(test_goals, test_starts, strict=True)
                ]
                ok = [d <= r3.TOL and a <= r3.TOL_DEG for d, a in ends]
                row[name] = {
                    "within_pct": 100.0 * float(np.mean(ok)),
                    "pos_within_pct": 100.0 * float(np.mean([d <= r3.TOL for d, _ in ends])),
                    "mean_m": float(np.mean([d for d, _ in ends])),
                    "mean_deg": float(np.mean([a for _, a in ends])),
                }
            results[f"{v.key}: {v.label} | seed {seed}" + (" (quick)" if ctx.quick else "")] = row
            print(v.key, v.label, seed, row, flush=True)
            path.write_text(json.dumps(results, indent=1) + "\n")
    return results
