"""Hyper-parameters of one agent's fuzzy Q-learner (paper §4, §5.1)."""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from .reward import SETTLE_RADIUS

#: Names of the six state variables S_i = <q_i, theta_i, d_i, g1, g2, g3> (paper §3.3).
STATE_NAMES: tuple[str, ...] = ("q", "theta", "d", "g1", "g2", "g3")
BOOTSTRAPS: tuple[str, ...] = ("joint_max", "expected")
#: Where an agent's choices come from: its Q and counts as now, or as at the start of the epoch (`act_from`).
ACT_FROM: tuple[str, ...] = ("now", "epoch")
#: The clearance state variable of a scene with obstacles: the agent's own link's, or its subtree's smallest.
CLEARANCE_OF: tuple[str, ...] = ("link", "subtree")
#: g3 as the bearing of the goal from the end effector (signed, the default) or its size only (unsigned).
G3_MODES: tuple[str, ...] = ("signed", "unsigned")
#: State of a grasp scene's finger agents (paper §5.5), see `grasp_state` below.
GRASP_STATES: tuple[str, ...] = ("reach", "force", "contact", "goal")

#: Reach of the paper's planar 4R chain (4 links of length 3); default ranges scale with it.
DEFAULT_REACH = 12.0


def _ranges_for(reach: float) -> tuple[tuple[float, float], ...]:
    return (
        (-math.pi, math.pi),  # q: joint angle
        (-math.pi, math.pi),  # theta: bearing of the end effector in the agent frame
        (0.0, reach),  # d: distance joint -> end effector
        (-2.0 * reach, 2.0 * reach),  # g1: goal - tip, x in the agent frame
        (-2.0 * reach, 2.0 * reach),  # g2: goal - tip, y in the agent frame
        (-math.pi, math.pi),  # g3: bearing of the goal from the end effector
    )


@dataclass(frozen=True)
class LearnerSettings:
    """Settings of one agent's learner; defaults were chosen by measurement on the planar 4R chain.

    Attributes:
        n_sets: membership functions per state variable (q, theta, d, g1, g2, g3); paper §5.1.
        ranges: (lo, hi) per state variable; set centres are spread evenly over it, values outside clip.
        slope: steepness of the sigmoid memberships (Eq. 3), as sigma * centre spacing. Larger = crisper
            sets; at 4 a value at a centre gives ~0.12 to each neighbour.
        top_k: memberships kept per variable (sparse activation: top_k**6 rules fire per state).
        gamma: discount factor of Eq. 5.
        lr: learning rate lambda of Eq. 5 in epoch 0.
        lr_decay: per-epoch decay, lr(epoch) = lr * (1 - lr_decay) ** epoch (paper: 1/1050).
        lr_anneal: (first, last) epochs over which lr(epoch) is also scaled linearly down to 0, and 0 from `last`
            on: learning stops, so the last epochs of training run the greedy policy a frozen swarm runs
            (`--learn off`). (0, 0): off (default). A swarm trained with online updates leans on them within the
            epoch (a move that did badly is worth less at the next step, whose state shares most rules); measured
            on the corridor (docs/science.md, round 9).
        T_max: initial temperature of T(t) = 1 + T_max * exp(-s t) (Eq. 8); must exceed 1.
        s: decay of T(t), t = step within the epoch.
        epsilon: epsilon-decreasing factor; exploration probability epsilon * (T(t) - 1) / (T_max - 1).
        bootstrap: "joint_max" = max over joint actions of Q(s', .) as printed in Eq. 5;
            "expected" = max over own actions of E(s', .) (Eq. 9), i.e. what the agent can choose.
        count_prior: initial fictitious-play count of every action, so Eq. 7 is defined at the start.
        count_freeze: from this epoch on the fictitious-play counts (Eq. 7) stay as they are, as in a frozen swarm;
            0 (default): they count in every training epoch. With lr_anneal's `first`, the epochs of the anneal
            run one deterministic greedy trajectory that only the TD updates change, and the epochs at lr 0 are
            the frozen epoch step for step (counting on at lr 0, each epoch was another draw; round 10).
        act_from: which Q and counts the agent's choices come from. "now" (default, Algorithm 1): as updated at
            every step, so within an epoch the swarm adapts to its own TD updates. "epoch": as they were at the
            start of the epoch; the epoch's TD updates (made at every step, as always) act from the next epoch on.
            Each training epoch then runs the policy a frozen swarm of the previous epoch's end would run (plus
            exploration), so training is measured on, and learns from, that policy's own trajectories
            (docs/science.md, round 11).
        n_actions: own actions (0 decrease, 1 keep, 2 increase).
        extra_state, extra_sets, extra_ranges: named state variables appended to S_i (after the scene
            variables below), read from the agent's `sense` (its own Obs.sense and the Down.sense from its
            parent), with their membership sets and ranges; "g_perp" is computed by the agent itself (the goal's
            component along the direction its own joint moves the tip), and so is "g_moves" (the same counted in
            the tip's shift by one own move, log-compressed: state.moves_to_goal), and "g_dist" (the distance from
            the agent's tip to the goal; with sets over a short range it tells apart places near the goal that
            g1, g2's coarse sets do not). Empty by default; set per agent from
            `grasp_state` in a grasp scene (actors/learning/grasp.py, grasp_learner_settings); the generalisation
            experiment's learner adds g_perp for reaching (experiments/generalisation.py).
        grasp_state: the finger agents' state in a grasp scene (paper §5.5): "reach" = the paper's S_i
            (6 variables, goal = the finger's grasp point); "force" (round 1's default) = S_i + force_error, the
            grasp agent's (fn_i - fn_i*) / f_grip for the finger, sent down the finger; "contact" = "force"
            plus, for fingertip agents only, their own normal force fn from the contact reading; "goal"
            (default, for the `shaped` grasp reward's contact goals) = S_i + g_perp, the component of
            goal - tip along the direction the agent's own joint moves the tip (fine sets over +-0.05).
            Every agent's action is the same: -1, 0, +1 times the run's action size (`action_deg`).
        fine_action: the action scale while the parent's context says "fine" (a grasp finger within D_fine
            of its contact goal): -1, 0, +1 times fine_action x action_deg. 1 (off) by default; the grasp
            fingers' default is 0.1 (actors/learning/grasp.py).

    Scenes with obstacles (paper §5.4; the corridor): the agent's obs carries its own link's signed clearance
    and whether its own increment was refused by a wall. Both are off by default (the paper's six variables):
        clearance_state: append the own link's clearance ("the distance from the corridor that is locally
            perceived by agent a_i") as a 7th state variable, clearance_sets sets over clearance_range (clipped).
        clearance_of: what that clearance is of. "link" (default): the agent's own link's. "subtree": the smallest of
            its own link's and of every link below it (the links its joint moves), from its Obs and its children's
            `Up` (the bottom-up pass carries each subtree's smallest clearance): a proximal agent whose own link is
            far from the walls then sees that the chain it moves is against one. Measured on the corridor
            (docs/science.md, round 6).
        collision_state: append a 0/1 flag "my increment of the previous step was refused" (2 sets over [0, 1]).
            It breaks the greedy deadlock against a wall: a refused move leaves q and the tips unchanged, so
            without it the state, and hence the greedy choice, would repeat forever.
        collision_tabu: right after the wall refused the agent's own increment, that action is left out of
            the next choice (greedy and exploring): a refused move left the state unchanged, so choosing it again
            is futile unless others moved; this breaks the greedy deadlock even with learning off.
        tabu_memory: with collision_tabu, how long a refused action stays left out. 0 (default): one step (a
            refused "increase" may be followed by a refused "decrease", then "increase" again: the proximal agents
            of a jammed chain alternate). > 0: every action refused since the tip of the agent's chain last moved
            tabu_memory (in the scene's length units) stays left out, so a jammed agent tries each way once and
            then keeps; the memory is the agent's decision state, not learned, and starts empty every epoch.
            Measured on the corridor (docs/science.md, round 5): not better than one step, in training or frozen.
        shield: a reflex against the walls, not learned (0, off, by default). > 0: the simulator looks one move
            ahead for the agent (Obs.sense "ahead-", "ahead+": the smallest clearance of the links its joint moves
            after its own move of -1 or +1 alone, from the present configuration), and a move that would bring
            them nearer a wall than `shield` is left out of the choice, greedy and exploring ("keep" never is).
            A proximity sensor on the links an agent moves, like a whisker; others' moves of the same step are
            not foreseen, so the walls can still refuse a joint action. Measured on the corridor
            (docs/science.md, round 7).
        epsilon_decay: per-epoch decay of epsilon, epsilon(epoch) = epsilon * (1 - epsilon_decay) ** epoch (default 0:
            the same exploration every epoch). With a slow T(t) decay (small s) exploration then lasts through
            the epoch early in training and fades over the epochs.
        collision_penalty: added (it is <= 0) to the reward of an agent whose own increment was refused, on
            top of the root's global reward: a local signal for the agent that pushed into the wall.
        g3: "signed" (default): g3 = the bearing of the goal from the end effector relative to the joint -> end
            effector direction, in (-pi, pi]; "unsigned": its size |g3| in [0, pi] (0: the goal lies straight on,
            pi: straight back towards the joint), so a goal behind the tip no longer falls on both ends of the range
            (+pi and -pi share no set). The side is left to g1, g2 and g_perp. Its range must then start at >= 0.
        follow_leader: weight w of a body-aware local term ("follow the leader", needs the scene's [task] via):
            each of the last follow_leader_links agents (counted from the end effector) adds
            w (D_i(t-1) - D_i(t)) to its reward, D_i its own link end's distance to its place on the corridor's
            axis in the straight-in configuration (reward.follow_leader_distance). 0 (off) by default.
        settle_radius: with `--reward settle`, the tip has arrived while it stays within this of the goal and then
            earns e^(-c D) whatever it did (reward.reach_reward). By default SETTLE_RADIUS (0.3), the corridor's
            success tolerance; round 8 of docs/science.md: 0.15, inside the tolerance, because a chain comes to
            rest just inside the radius the reward gives it.

    Tuning (planar 4R chain, links 3, goal (4.16, 6.18), 60 epochs x 500 steps, 3 seeds): with the shaped
    reward every variant tried met the target (>= 80% of the last 20 epochs within 0.5, median <= 0.15)
    except bootstrap="joint_max" (one seed median 0.43). s = 0.05 gave the lowest medians (~0.04) and also
    passes with the strict reward, where lr 0.1/0.3/0.7 and s 0.02 did not; the paper's lr 0.1,
    s 0.35, T_max 100 fails with any reward but shaped.
    """

    n_sets: tuple[int, ...] = (20, 20, 13, 7, 7, 7)
    ranges: tuple[tuple[float, float], ...] = _ranges_for(DEFAULT_REACH)
    slope: float = 4.0
    top_k: int = 2
    gamma: float = 0.9
    lr: float = 0.5
    lr_decay: float = 1.0 / 1050.0
    lr_anneal: tuple[int, int] = (0, 0)
    T_max: float = 10.0
    s: float = 0.05  # T(t) - 1 falls to ~8% by t = 50 of 500 steps: exploration tapers within the epoch
    epsilon: float = 1.0
    bootstrap: str = "expected"
    count_prior: float = 1.0
    count_freeze: int = 0
    act_from: str = "now"
    n_actions: int = 3
    clearance_state: bool = False
    clearance_sets: int = 5
    clearance_range: tuple[float, float] = (0.0, 1.0)
    clearance_of: str = "link"
    collision_state: bool = False
    collision_penalty: float = 0.0
    extra_state: tuple[str, ...] = ()
    extra_sets: tuple[int, ...] = ()
    extra_ranges: tuple[tuple[float, float], ...] = ()
    grasp_state: str = "goal"
    epsilon_decay: float = 0.0
    fine_action: float = 1.0
    collision_tabu: bool = False
    tabu_memory: float = 0.0
    shield: float = 0.0
    follow_leader: float = 0.0
    follow_leader_links: int = 4
    settle_radius: float = SETTLE_RADIUS
    g3: str = "signed"

    @property
    def state_names(self) -> tuple[str, ...]:
        """Names of the state variables: STATE_NAMES, then "clearance" and "collided" when enabled."""
        base = STATE_NAMES + ("clearance",) * self.clearance_state + ("collided",) * self.collision_state
        return base + self.extra_state

    @property
    def state_sets(self) -> tuple[int, ...]:
        """Membership sets per state variable (n_sets, then those of the optional scene variables)."""
        return (
            self.n_sets + (self.clearance_sets,) * self.clearance_state + (2,) * self.collision_state + self.extra_sets
        )

    @property
    def state_ranges(self) -> tuple[tuple[float, float], ...]:
        base = self.ranges + (self.clearance_range,) * self.clearance_state + ((0.0, 1.0),) * self.collision_state
        return base + self.extra_ranges

    @classmethod
    def for_reach(cls, reach: float, **overrides: object) -> LearnerSettings:
        """Settings with d in [0, reach] and g1, g2 in [-2 reach, 2 reach]; overrides replace any field."""
        if not (isinstance(reach, (int, float)) and math.isfinite(reach) and reach > 0):
            raise ValueError(f"reach must be a positive finite number, got {reach!r}")
        kwargs: dict[str, object] = {"ranges": _ranges_for(float(reach))}
        kwargs.update(overrides)
        return cls(**kwargs)  # type: ignore[arg-type]

    def replace(self, **changes: object) -> LearnerSettings:
        return replace(self, **changes)  # type: ignore[arg-type]

    def __post_init__(self) -> None:
        n = len(STATE_NAMES)
        object.__setattr__(self, "n_sets", tuple(int(m) for m in self.n_sets))
        object.__setattr__(self, "ranges", tuple((float(lo), float(hi)) for lo, hi in self.ranges))
        if len(self.n_sets) != n:
            raise ValueError(f"n_sets needs {n} entries {STATE_NAMES}, got {len(self.n_sets)}")
        if len(self.ranges) != n:
            raise ValueError(f"ranges needs {n} (lo, hi) pairs {STATE_NAMES}, got {len(self.ranges)}")
        for name, m, (lo, hi) in zip(STATE_NAMES, self.n_sets, self.ranges, strict=True):
            if m < 1:
                raise ValueError(f"n_sets[{name}] must be >= 1, got {m}")
            if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(f"ranges[{name}] must be finite with lo < hi, got ({lo}, {hi})")
        if not (isinstance(self.top_k, int) and 1 <= self.top_k <= min(self.n_sets)):
            raise ValueError(f"top_k must be an int in [1, min(n_sets)={min(self.n_sets)}], got {self.top_k}")
        if not (math.isfinite(self.slope) and self.slope > 0):
            raise ValueError(f"slope must be > 0, got {self.slope}")
        if not 0.0 <= self.gamma <= 1.0:
            raise ValueError(f"gamma must be in [0, 1], got {self.gamma}")
        if not 0.0 < self.lr <= 1.0:
            raise ValueError(f"lr must be in (0, 1], got {self.lr}")
        if not 0.0 <= self.lr_decay < 1.0:
            raise ValueError(f"lr_decay must be in [0, 1), got {self.lr_decay}")
        anneal = tuple(self.lr_anneal)
        if not (
            len(anneal) == 2
            and all(isinstance(e, int) and not isinstance(e, bool) for e in anneal)
            and (0 <= anneal[0] < anneal[1] or anneal == (0, 0))
        ):
            raise ValueError(
                f"lr_anneal must be two epochs 0 <= first < last, or (0, 0) for off, got {self.lr_anneal!r}"
            )
        object.__setattr__(self, "lr_anneal", anneal)
        if not (math.isfinite(self.T_max) and self.T_max > 1.0):
            raise ValueError(f"T_max must be > 1 (epsilon-decreasing divides by T_max - 1), got {self.T_max}")
        if not (math.isfinite(self.s) and self.s >= 0.0):
            raise ValueError(f"s must be >= 0, got {self.s}")
        if not 0.0 <= self.epsilon <= 1.0:
            raise ValueError(f"epsilon must be in [0, 1], got {self.epsilon}")
        if self.bootstrap not in BOOTSTRAPS:
            raise ValueError(f"bootstrap must be one of {BOOTSTRAPS}, got {self.bootstrap!r}")
        if not (math.isfinite(self.count_prior) and self.count_prior > 0):
            raise ValueError(f"count_prior must be > 0 so Eq. 7 is defined, got {self.count_prior}")
        freeze = self.count_freeze
        if not (isinstance(freeze, int) and not isinstance(freeze, bool) and freeze >= 0):
            raise ValueError(f"count_freeze must be an epoch (int >= 0; 0 for never), got {self.count_freeze!r}")
        if self.act_from not in ACT_FROM:
            raise ValueError(f"act_from must be one of {ACT_FROM}, got {self.act_from!r}")
        if not (isinstance(self.n_actions, int) and self.n_actions >= 1):
            raise ValueError(f"n_actions must be an int >= 1, got {self.n_actions}")
        object.__setattr__(self, "clearance_range", tuple(float(v) for v in self.clearance_range))
        for name in ("clearance_state", "collision_state", "collision_tabu"):
            if not isinstance(getattr(self, name), bool):
                raise ValueError(f"{name} must be true or false, got {getattr(self, name)!r}")
        if not (isinstance(self.clearance_sets, int) and self.clearance_sets >= 1):
            raise ValueError(f"clearance_sets must be an int >= 1, got {self.clearance_sets!r}")
        lo, hi = self.clearance_range
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise ValueError(f"clearance_range must be finite with lo < hi, got ({lo}, {hi})")
        if self.clearance_of not in CLEARANCE_OF:
            raise ValueError(f"clearance_of must be one of {CLEARANCE_OF}, got {self.clearance_of!r}")
        if self.clearance_of != "link" and not self.clearance_state:
            raise ValueError("clearance_of needs clearance_state = true (it says which clearance the state holds)")
        if not (math.isfinite(self.tabu_memory) and self.tabu_memory >= 0.0):
            raise ValueError(f"tabu_memory must be >= 0, got {self.tabu_memory}")
        if self.tabu_memory > 0.0 and not self.collision_tabu:
            raise ValueError("tabu_memory needs collision_tabu = true (it says how long the tabu lasts)")
        if not (isinstance(self.shield, (int, float)) and math.isfinite(self.shield) and self.shield >= 0.0):
            raise ValueError(f"shield must be a distance >= 0, got {self.shield!r}")
        if not 0.0 <= self.epsilon_decay < 1.0:
            raise ValueError(f"epsilon_decay must be in [0, 1), got {self.epsilon_decay}")
        r = self.settle_radius
        if not (isinstance(r, (int, float)) and math.isfinite(r) and r > 0.0):
            raise ValueError(f"settle_radius must be a distance > 0, got {self.settle_radius!r}")
        if not (math.isfinite(self.follow_leader) and self.follow_leader >= 0.0):
            raise ValueError(f"follow_leader must be >= 0, got {self.follow_leader}")
        if not (isinstance(self.follow_leader_links, int) and self.follow_leader_links >= 1):
            raise ValueError(f"follow_leader_links must be an int >= 1, got {self.follow_leader_links!r}")
        if not (math.isfinite(self.collision_penalty) and self.collision_penalty <= 0.0):
            raise ValueError(f"collision_penalty must be <= 0, got {self.collision_penalty}")
        object.__setattr__(self, "extra_state", tuple(str(n) for n in self.extra_state))
        object.__setattr__(self, "extra_sets", tuple(int(m) for m in self.extra_sets))
        object.__setattr__(self, "extra_ranges", tuple((float(lo), float(hi)) for lo, hi in self.extra_ranges))
        if not len(self.extra_state) == len(self.extra_sets) == len(self.extra_ranges):
            raise ValueError("extra_state, extra_sets and extra_ranges need one entry per extra variable")
        for name, m, (lo, hi) in zip(self.extra_state, self.extra_sets, self.extra_ranges, strict=True):
            if m < 1 or not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
                raise ValueError(
                    f"extra variable {name!r}: needs >= 1 sets and a finite lo < hi, got {m}, ({lo}, {hi})"
                )
        if self.g3 not in G3_MODES:
            raise ValueError(f"g3 must be one of {G3_MODES}, got {self.g3!r}")
        if self.g3 == "unsigned" and self.ranges[5][0] < 0.0:
            raise ValueError(
                f"g3 'unsigned' lies in [0, pi], but ranges[g3] starts at {self.ranges[5][0]:g}: "
                "the sets below 0 would never fire (use e.g. (0, pi))"
            )
        if self.grasp_state not in GRASP_STATES:
            raise ValueError(f"grasp_state must be one of {GRASP_STATES}, got {self.grasp_state!r}")
        if not (isinstance(self.fine_action, (int, float)) and 0.0 < self.fine_action <= 1.0):
            raise ValueError(f"fine_action must be in (0, 1], got {self.fine_action!r}")
        if self.top_k > min(self.state_sets):
            raise ValueError(f"top_k must be <= the fewest sets of any state variable ({min(self.state_sets)})")
