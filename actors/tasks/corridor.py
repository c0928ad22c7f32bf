"""Corridor (paper §5.4): reach a goal among solid walls (a `walls` scene). The root's reward is Eq. 11 (or a
variant): the reach reward with a collision term from the scene's task readings ("clearance": the smallest link
clearance, "collisions": how many moves the walls refused). Each agent may add what it senses locally to its
state (its clearance, whether its own move was refused), pay a local collision penalty (and, with the blame, one for
its applied move when a move below it was refused: the walls refuse a compound move's increments root first, so the
one refused is not always the one that carried the links there), follow the leader along the corridor's axis, and
leave out moves it knows are futile (the tabu) or that the scene's shield vetoes.

```toml
[task]
kind = "corridor"
goal = [5.5, 2.0]
reward = "settle"            # as reach (reach.reward modes), with Eq. 11's collision term
via = [2.0, 2.0]             # the corridor's axis: the goal distance along it (reach.path_distance)
via_width = 0.3
settle_radius = 0.15
clearance_state = true       # + "clearance": the agent's link's clearance to the walls (5 sets over [0, 1])
clearance_of = "subtree"     #   ... "link": its own link's; "subtree": the smallest of the links its joint moves
collision_state = true       # + "collided": its own move of the step before was refused (2 sets over [0, 1])
collision_penalty = -5.0     # added to its reward when its own move was refused
collision_tabu = true        # the move the wall just refused is left out of the next choice
follow_leader = 40.0         # weight of each of the last follow_leader_links agents' own progress along the axis
follow_leader_links = 4
blame_penalty = -5.0         # added when I moved and a move of an agent below me was refused (a compound refusal)
swing_margin = 0.25          # outside D_min (the swing down to the mouth) a link this near a wall costs as a refusal
```
Measured and reasoned: docs/notebook/corridor.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from kinswarm.actors.learning.observation import Observation, StateVariable
from kinswarm.protocol.messages import Readings, Task
from kinswarm.protocol.topology import Topology

from .base import AgentTask, StepView, Vec2
from .reach import REWARD_MODES, ReachAgent, ReachSettings, ReachTask, path_distance, reach_reward
from .refusal import COLLIDED, collided, penalised, refused, tabu

CLEARANCE_OF: tuple[str, ...] = ("link", "subtree")
CLEARANCE = StateVariable("clearance", 5, (0.0, 1.0))
#: Eq. 11's constants (paper §5.4: c1, c2 in (0, 1)); D_MIN as Eq. 10's default.
CORRIDOR_C1 = 0.5
CORRIDOR_C2 = 0.5
#: C_ai = 1, "agent a_i is close to collide", when its link's clearance is below this (the capsule radius)
CORRIDOR_D_SAFE = 0.1
#: strict and shaped on a corridor: a collision costs -CORRIDOR_WEIGHT e^(-c2 D_corridor), below any other case
CORRIDOR_WEIGHT = 5.0
#: the action index that holds the joint (0: -, 1: hold, 2: +)
HOLD = 1


@dataclass(frozen=True)
class CorridorSettings(ReachSettings):
    clearance_state: bool = False  # + the agent's clearance to the walls as a state variable
    clearance_of: str = "link"  # ... of its own link, or the smallest of the links its joint moves ("subtree")
    collision_state: bool = False  # + "my move of the step before was refused" as a state variable
    collision_penalty: float = 0.0  # (<= 0) added to the reward of an agent whose own move was refused
    collision_tabu: bool = False  # leave the move the wall just refused out of the next choice
    follow_leader: float = 0.0  # weight w of each of the last agents' own progress towards its place on the axis
    follow_leader_links: int = 4  # ... how many agents, counted from the end effector
    blame_penalty: float = 0.0  # (<= 0) when I moved and a move below me was refused (its `Up` says so)
    swing_margin: float = 0.0  # (>= 0) outside D_min, a link clearance below it is close to collide (Eq. 11's C_ai)

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.clearance_of not in CLEARANCE_OF:
            raise ValueError(f"clearance_of: expected one of {', '.join(CLEARANCE_OF)}, got {self.clearance_of!r}")
        if self.clearance_of != "link" and not self.clearance_state:
            raise ValueError("clearance_of: needs clearance_state = true (it says which clearance the state holds)")
        if not (math.isfinite(self.collision_penalty) and self.collision_penalty <= 0.0):
            raise ValueError(f"collision_penalty: must be <= 0, got {self.collision_penalty}")
        if not (math.isfinite(self.follow_leader) and self.follow_leader >= 0.0):
            raise ValueError(f"follow_leader: must be >= 0, got {self.follow_leader}")
        if self.follow_leader > 0.0 and self.via is None:
            raise ValueError("follow_leader: needs via (the corridor's axis)")
        if not (math.isfinite(self.blame_penalty) and self.blame_penalty <= 0.0):
            raise ValueError(f"blame_penalty: must be <= 0, got {self.blame_penalty}")
        if not (math.isfinite(self.swing_margin) and self.swing_margin >= 0.0):
            raise ValueError(f"swing_margin: must be >= 0, got {self.swing_margin}")
        if self.follow_leader_links < 1:
            raise ValueError(f"follow_leader_links: must be >= 1, got {self.follow_leader_links}")


class CorridorTask(ReachTask):
    kind = "corridor"
    scenes = ("walls",)
    Settings = CorridorSettings
    rewards = REWARD_MODES

    def state_variables(self, agent: str) -> tuple[StateVariable, ...]:
        s = self.settings
        return (CLEARANCE,) * s.clearance_state + (COLLIDED,) * s.collision_state

    def agent(self, agent: str, observation: Observation | None) -> AgentTask:
        return CorridorAgent(self.settings, self.topo, agent)


class CorridorAgent(ReachAgent):
    def __init__(self, settings: CorridorSettings, topo: Topology, agent: str) -> None:
        super().__init__(settings, topo.subtree_leaves(agent))
        self.c = settings
        self.behind = _follow_leader_behind(topo, agent, settings)  # follow_leader: links below me, or None
        self.fl_prev: float | None = None  # follow_leader: my D_i(t-1)

    def start_epoch(self) -> None:
        super().start_epoch()
        self.fl_prev = None

    def global_reward(self, D: float, D_prev: float, obs: Task) -> float:
        clearance, collisions = obs.sense.get("clearance", math.inf), obs.sense.get("collisions", 0.0)
        c = self.c
        return corridor_reward(
            D, D_prev, clearance, collisions, c.reward, settle_radius=c.settle_radius, swing_margin=c.swing_margin
        )

    def up(self, view: StepView) -> Readings:
        """My subtree's smallest clearance (my link's and my live children's subtrees'), for my parent's state;
        with the blame, whether a move in my subtree (mine or below) was refused, for my parent's reward."""
        clearance = _subtree_clearance(view)
        out: Readings = {} if clearance is None else {"clearance": clearance}
        if self.c.blame_penalty < 0.0:
            out["refused"] = max(collided(view), _refused_below(view))
        return out

    def _clearance(self, view: StepView) -> float:
        clearance = view.sense.get("clearance", 0.0)
        if self.c.clearance_of == "subtree" and (subtree := _subtree_clearance(view)) is not None:
            clearance = subtree
        return clearance

    def state(self, view: StepView) -> list[float]:
        c = self.c
        return [self._clearance(view)] * c.clearance_state + [collided(view)] * c.collision_state

    def reward(self, view: StepView, reward: float | None) -> float | None:
        c = self.c
        reward = penalised(view, reward, c.collision_penalty)
        # a compound refusal: my move was applied, one below me (which mine carried towards the wall) was refused
        moved = view.last_action is not None and view.last_action != HOLD
        if reward is not None and c.blame_penalty < 0.0 and moved and not refused(view):
            if _refused_below(view) > 0.5:
                reward += c.blame_penalty
        if self.behind is not None:  # + w (D_i(t-1) - D_i(t)) for my link end's distance to its place on the axis
            assert self.c.via is not None
            end = (view.end[0], view.end[1])
            D_i = follow_leader_distance(end, view.goal, self.c.via, self.behind, self.c.via_width)
            if reward is not None and self.fl_prev is not None:
                reward += self.c.follow_leader * (self.fl_prev - D_i)
            self.fl_prev = D_i
        return reward

    def avoid(self, view: StepView) -> list[int]:
        """The tabu (my move the wall just refused; a refused move left the state unchanged, so choosing it again
        is futile unless others moved) and the scene's shield (moves that alone would come too near a wall)."""
        out = tabu(view, self.c.collision_tabu)
        if view.sense.get("shield-", 0.0) > 0.5:
            out.append(0)
        if view.sense.get("shield+", 0.0) > 0.5:
            out.append(2)
        return out


def _subtree_clearance(view: StepView) -> float | None:
    """The smallest clearance of my link (my Obs) and of the links below me (my live children's `Up`); links of
    lost agents this one stands in for are not counted (their readings are not gathered)."""
    own = view.sense.get("clearance")
    known = [c for c in (own, *(up.sense.get("clearance") for up in view.ups.values())) if c is not None]
    return min(known) if known else None


def _refused_below(view: StepView) -> float:
    """1 when a move of an agent below me was refused at the step before (my live children's `Up`), else 0."""
    return max((up.sense.get("refused", 0.0) for up in view.ups.values()), default=0.0)


def _follow_leader_behind(topo: Topology, agent: str, s: CorridorSettings) -> float | None:
    """follow_leader: the length of the links below `agent` on its path to the end effector, for one of the last
    follow_leader_links DOF agents of a single-leaf subtree; None when the term is off for this agent."""
    if s.follow_leader <= 0.0 or s.via is None or not topo.agents[agent].has_dof:
        return None
    leaves = topo.subtree_leaves(agent)
    if len(leaves) != 1:
        return None
    path, a = [], leaves[0]
    while a != agent:
        path.append(a)
        a = topo.agents[a].parent  # type: ignore[assignment]
    path.reverse()  # top-down, the order the lengths are summed in
    if sum(topo.agents[b].has_dof for b in path) >= s.follow_leader_links:
        return None
    return sum(topo.agents[b].link_length for b in path)


def corridor_reward(
    D: float,
    D_prev: float,
    clearance: float,
    collisions: float,
    mode: str,
    D_min: float = 3.0,
    c1: float = CORRIDOR_C1,
    c2: float = CORRIDOR_C2,
    d_safe: float | None = None,
    weight: float = CORRIDOR_WEIGHT,
    k: float = 20.0,
    settle_radius: float = 0.3,
    swing_margin: float = 0.0,
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
      the success bar counts refusals, and an arrived chain has some link that near in 4-99 % of its steps (study 5
      of docs/notebook/corridor.md), where shaped then pays about -4 for sitting at the target.
    swing_margin (any mode but paper, whose case order pays -2 outside D_min whatever happens): outside D_min a link
      nearer a wall than swing_margin is close to collide as well. There the chain swings down to the mouth and has
      room to keep clear; inside, the corridor's band puts links that near by construction (study 15).
    """
    if mode not in REWARD_MODES:
        raise ValueError(f"unknown reward mode {mode!r}; allowed modes: {', '.join(REWARD_MODES)}")
    if d_safe is None:
        d_safe = 0.0 if mode == "settle" else CORRIDOR_D_SAFE
    close = collisions > 0 or clearance < d_safe or (D > D_min and clearance < swing_margin)  # exists a_i, C_ai = 1
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


def follow_leader_distance(end: Vec2, goal: Vec2, via: Vec2, behind: float, width: float) -> float:
    """Body-aware corridor distance of one link ("follow the leader"): the distance of an agent's own link end to its
    place on the corridor's axis in the target configuration, `behind` (the length of the links below it) before
    the goal on the line via -> goal. The end effector (behind = 0) aims at the goal itself; the link above it at the
    point one link back, and so on: D_i = |end - g_i| measured along the approach path through via (path_distance)
    while g_i is ahead of via, straight to g_i otherwise. Each agent's own D_i is its "distance from the corridor that
    is locally perceived" (paper §5.4); summed over the links it is the body's distance from the straight-in
    configuration, which the tip's D_goal does not see."""
    ux, uy = goal[0] - via[0], goal[1] - via[1]
    length = math.hypot(ux, uy)
    if length == 0.0:
        return math.hypot(end[0] - goal[0], end[1] - goal[1])
    g = (goal[0] - behind * ux / length, goal[1] - behind * uy / length)  # g_i on the axis
    if behind < length:  # g_i ahead of via: along the approach path
        return path_distance(end, g, via, width)
    return math.hypot(end[0] - g[0], end[1] - g[1])


TASK = CorridorTask
