"""Reward of the reaching task (paper §4.2, Eq. 10) and its variants; the corridor's (§5.4, Eq. 11)."""

from __future__ import annotations

import math

REWARD_MODES: tuple[str, ...] = ("paper", "strict", "shaped", "graded", "settle")
#: settle: within this of the goal (at t - 1 and t) the tip has arrived (default: the corridor's success tolerance;
#: LearnerSettings.settle_radius sets it per run)
SETTLE_RADIUS = 0.3


def reach_reward(
    D: float,
    D_prev: float,
    mode: str,
    D_min: float = 3.0,
    c: float = 1.0,
    k: float = 20.0,
    settle_radius: float = SETTLE_RADIUS,
) -> float:
    """R(t) from the goal distance D = D_goal(t) and D_prev = D_goal(t-1); Delta D = D - D_prev.

    paper (Eq. 10 as printed):
        D <= D_min and Delta D <= 0  ->  e^(-c D)
        D >  D_min                   ->  -2
        D <  D_min and Delta D > 0   ->  -1
      Eq. 10 leaves D == D_min with Delta D > 0 undefined; we treat it as inside and moving away: -1.
    strict: as paper, but 0 inside D_min when the arm did not move (|Delta D| < 1e-12), so "keep" is
      not rewarded like an approach.
    shaped: strict inside D_min; outside r = -2 + k (D_prev - D), a gradient towards the goal.
    graded: shaped with the gradient inside D_min too, r = strict + k (D_prev - D). Inside D_min an approach
      earns e^(-c D) (0.05-0.37 at D = 1-3) against -1 for a step away, so "keep" (0) beat moving wherever the
      policy was unsure; frozen swarms stopped 1-3 from unseen goals. Measured in docs/science.md ("graded").
    settle: shaped, but while the tip stays within settle_radius of the goal (at t - 1 and t) it earns e^(-c D)
      whatever it did. Shaped pays there e^(-c D) for a step in, 0 for "keep" and -1 for a step out, so an arrived
      chain never learns to keep still; in a corridor its jitter is pushed into the walls.
    """
    if mode not in REWARD_MODES:
        raise ValueError(f"unknown reward mode {mode!r}; allowed modes: {', '.join(REWARD_MODES)}")
    dD = D - D_prev
    if mode == "settle" and D <= settle_radius and D_prev <= settle_radius:
        return math.exp(-c * D)
    if D > D_min:
        if mode in ("shaped", "graded", "settle"):
            return -2.0 + k * (D_prev - D)
        return -2.0
    gradient = k * (D_prev - D) if mode == "graded" else 0.0
    if mode != "paper" and abs(dD) < 1e-12:
        return 0.0
    if dD <= 0.0:
        return math.exp(-c * D) + gradient
    return -1.0 + gradient


#: Eq. 11's constants for the corridor (paper §5.4: c1, c2 in (0, 1)); D_MIN as Eq. 10's default.
CORRIDOR_C1 = 0.5
CORRIDOR_C2 = 0.5
#: C_ai = 1, "agent a_i is close to collide", when its link's clearance is below this (the capsule radius)
CORRIDOR_D_SAFE = 0.1
#: strict and shaped on a corridor: a collision costs -CORRIDOR_WEIGHT e^(-c2 D_corridor), below any other case
CORRIDOR_WEIGHT = 5.0


def corridor_reward(
    D: float,
    D_prev: float,
    clearance: float,
    collisions: int,
    mode: str,
    D_min: float = 3.0,
    c1: float = CORRIDOR_C1,
    c2: float = CORRIDOR_C2,
    d_safe: float | None = None,
    weight: float = CORRIDOR_WEIGHT,
    k: float = 20.0,
    settle_radius: float = SETTLE_RADIUS,
) -> float:
    """R(t) of the corridor task (paper §5.4, Eq. 11) from D = D_goal(t), D_prev = D_goal(t-1), the smallest
    link clearance min_i D_corridor^{a_i}(t) and the number of joint increments the walls refused at t-1.

    Some agent is close to collide (exists a_i with C_ai = 1) when a move was refused or clearance < d_safe
    (by default CORRIDOR_D_SAFE, and 0 for settle: refusals only);
    the clearance of the closest agent is then min_i D_corridor (Eq. 11 takes the min over the agents that
    perceive a collision, which is the min over all of them).

    paper (Eq. 11 as printed, in its case order):
        D >  D_min                                   ->  -2
        D <= D_min and Delta D > 0                   ->  -1
        D <= D_min and Delta D <= 0 and no C_ai = 1  ->  e^(-c1 D)
        otherwise (D <= D_min, Delta D <= 0, a C_ai = 1)  ->  -e^(-c2 min_i D_corridor)
      A collision is punished only while approaching inside D_min, and never by more than 1: less than the
      -2 paid anywhere outside D_min, so touching a wall is cheap.
    strict: the collision case first, whatever D: -weight e^(-c2 min_i D_corridor), at most -weight * e^(-c2 d_safe),
      below every other case; else Eq. 10 "strict" (0 inside D_min when the tip did not move).
    shaped: Eq. 10 "shaped" (outside D_min -2 + k (D_prev - D), a gradient towards the goal; inside as strict)
      plus, when close to collide, the same -weight e^(-c2 min_i D_corridor): added, not replacing, so a move
      that touches is always worse than the same move clear of the walls and the gradient is kept.
    graded: as shaped, with Eq. 10 graded.
    settle: Eq. 10 settle, and the collision term for a refused move only, not for a link nearer a wall than d_safe:
      the success bar counts refusals, and an arrived chain has some link that near in 4-99 % of its steps (round 5
      of docs/science.md), where shaped then pays about -4 for sitting at the target.
    """
    if mode not in REWARD_MODES:
        raise ValueError(f"unknown reward mode {mode!r}; allowed modes: {', '.join(REWARD_MODES)}")
    if d_safe is None:
        d_safe = 0.0 if mode == "settle" else CORRIDOR_D_SAFE
    close = collisions > 0 or clearance < d_safe  # exists a_i with C_ai = 1
    penalty = math.exp(-c2 * max(clearance, 0.0))  # e^(-c2 min_i D_corridor)
    if mode == "paper":
        if D > D_min:
            return -2.0
        if D - D_prev > 0.0:
            return -1.0
        if not close:
            return math.exp(-c1 * D)
        return -penalty
    reach = reach_reward(D, D_prev, mode, D_min=D_min, c=c1, k=k, settle_radius=settle_radius)
    if mode == "strict":
        return -weight * penalty if close else reach
    return reach - (weight * penalty if close else 0.0)


def path_distance(tip: tuple[float, float], goal: tuple[float, float], via: tuple[float, float], width: float) -> float:
    """D_goal measured along an approach path through `via` (a corridor's axis, declared in the scene's
    [task] table): straight to the goal once the tip is "past" via -- ahead of it towards the goal and within
    `width` of the line via -> goal -- else |tip - via| + |via - goal|. This is the task designer's knowledge
    of the scene in the reward (the agents still sense only their own clearance): it turns the corridor's
    mouth from a dead end of the Euclidean distance into a way point on a path along the corridor's axis."""
    ux, uy = goal[0] - via[0], goal[1] - via[1]
    length = math.hypot(ux, uy)
    dx, dy = tip[0] - via[0], tip[1] - via[1]
    if length > 0.0:
        along = (dx * ux + dy * uy) / length
        across = abs(dx * uy - dy * ux) / length
        if along >= 0.0 and across <= width:
            return math.hypot(tip[0] - goal[0], tip[1] - goal[1])
    return math.hypot(dx, dy) + length


def next_waypoint(
    tip: tuple[float, float],
    goal: tuple[float, float],
    waypoints: tuple[tuple[float, float], ...],
    k: int,
    radius: float,
) -> tuple[int, tuple[float, float], float]:
    """Sub-goals along a path (the scene's [task] waypoints, e.g. a corridor's axis): the root aims the swarm at
    waypoint k until the tip comes within `radius` of it, then at the next one, and at the goal after the last.
    Returns (k, the current target, D_goal = |tip - target| + the path's length from the target to the goal),
    so D_goal falls steadily along the path and barely jumps when k advances. k only grows within an epoch."""
    while k < len(waypoints) and math.hypot(tip[0] - waypoints[k][0], tip[1] - waypoints[k][1]) <= radius:
        k += 1
    points = [*waypoints[k:], goal]
    rest = sum(math.hypot(b[0] - a[0], b[1] - a[1]) for a, b in zip(points, points[1:], strict=False))
    target = points[0]
    return k, target, math.hypot(tip[0] - target[0], tip[1] - target[1]) + rest


def follow_leader_distance(
    end: tuple[float, float],
    goal: tuple[float, float],
    via: tuple[float, float],
    behind: float,
    width: float,
) -> float:
    """Body-aware corridor distance of one link ("follow the leader"): the distance of an agent's own link end
    to its place on the corridor's axis in the target configuration, `behind` (the length of the links below
    it) before the goal on the line via -> goal. The end effector (behind = 0) aims at the goal itself; the
    link above it at the point one link back, and so on: D_i = |end - g_i| measured along the approach path
    through via (path_distance) while g_i is ahead of via, straight to g_i otherwise. Each agent's own D_i is
    its "distance from the corridor that is locally perceived" (paper §5.4); summed over the links it is the
    body's distance from the straight-in configuration, which the tip's D_goal does not see."""
    ux, uy = goal[0] - via[0], goal[1] - via[1]
    length = math.hypot(ux, uy)
    if length == 0.0:
        return math.hypot(end[0] - goal[0], end[1] - goal[1])
    g = (goal[0] - behind * ux / length, goal[1] - behind * uy / length)  # g_i on the axis
    if behind < length:  # g_i ahead of via: along the approach path
        return path_distance(end, g, via, width)
    return math.hypot(end[0] - g[0], end[1] - g[1])
