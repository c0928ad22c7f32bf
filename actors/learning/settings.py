"""Settings of one agent's fuzzy learner (paper §4, §5.1): one dataclass, a help line per field.

Two kinds of field, kept in one flat table because that is what the run file's [learner] table is:
- the observation's (OBSERVATION_FIELDS: state, g3, ranges, extra_state): what S_i holds, the task's to give
  (observation.py; `settings.observation` is that part alone);
- the learner's own: the fuzzy grid over the observation (n_sets, slope, top_k) and the learning (gamma, lr*,
  T_max, s, epsilon*, count_*). Which of them a learner kind takes: actors/policies/registry.py.

What a task adds (the corridor's clearance and collision variables, a grasp finger's fine steps, reward constants,
reflexes such as the shield or the tabu) lives with the task (actors/tasks/); the task hands its state variables to
the learner as extra state variables. Options that were measured and not kept are gone from the code; their numbers
are in docs/notebook/.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from .observation import (
    DEFAULT_REACH,
    G3_MODES,
    OBSERVATION_FIELDS,
    PLANE_STATE_NAMES,
    SPATIAL_STATES,
    STATE_KINDS,
    STATE_NAMES,
    TURN_RANGES,
    TURN_STATE_NAMES,
    Observation,
    StateVariable,
    check_observation,
    plane_ranges,
    ranges_for,
)

#: [learner] plasticity: "off" (the paper's learner) or "direction" (plasticity.py)
PLASTICITY: tuple[str, ...] = ("off", "direction")
#: Own actions: 0 decrease, 1 keep, 2 increase the joint angle by the run's action size.
N_ACTIONS = 3
#: The sets of a spatial joint's rotation-plane variables (LearnerSettings.for_plane)
PLANE_SETS: tuple[int, ...] = (5, 5, 9, 5, 5, 6)
#: The grid and learning rate of a spatial joint's turn state (LearnerSettings.for_turn)
TURN_LEARNER: dict[str, object] = {"n_sets": (9,), "lr": 0.5 / 64}

__all__ = [
    "DEFAULT_REACH",
    "G3_MODES",
    "N_ACTIONS",
    "OBSERVATION_FIELDS",
    "PLANE_SETS",
    "PLANE_STATE_NAMES",
    "PLASTICITY",
    "SPATIAL_STATES",
    "STATE_KINDS",
    "STATE_NAMES",
    "TURN_LEARNER",
    "TURN_STATE_NAMES",
    "LearnerSettings",
    "Observation",
    "StateVariable",
]


@dataclass(frozen=True)
class LearnerSettings:
    """One agent's fuzzy Q-learner with joint action selection (Algorithms 1 and 2).

    Defaults were chosen by measurement on the planar 4R chain (links 3, goal (4.16, 6.18), 60 epochs x 500 steps,
    3 seeds): with the shaped reward every variant tried met the target (>= 80 % of the last 20 epochs within 0.5,
    median <= 0.15); s = 0.05 gave the lowest medians (~0.04) and also passes with the strict reward, where lr
    0.1/0.3/0.7 and s 0.02 did not; the paper's lr 0.1, s 0.35, T_max 100 fails with any reward but shaped.
    """

    n_sets: tuple[int, ...] = (20, 20, 13, 7, 7, 7)  # membership sets per variable of S_i (§5.1)
    ranges: tuple[tuple[float, float], ...] = ranges_for(DEFAULT_REACH)  # (lo, hi) per variable; outside clips
    slope: float = 4.0  # steepness of the sigmoid sets (Eq. 3), as sigma x set spacing
    top_k: int = 2  # memberships kept per variable: top_k ** n rules fire per state (Eq. 4, sparse)
    gamma: float = 0.9  # discount of Eq. 5
    lr: float = 0.5  # learning rate lambda of Eq. 5 in epoch 0
    lr_decay: float = 1.0 / 1050.0  # lr(epoch) = lr (1 - lr_decay) ** epoch (the paper's 1/1050)
    # (first, last): lr also scaled linearly to 0 over these epochs and 0 after, so training's last epochs run the
    # greedy policy a frozen swarm runs (docs/notebook/corridor.md, study 9); (0, 0): off
    lr_anneal: tuple[int, int] = (0, 0)
    T_max: float = 10.0  # T(t) = 1 + T_max e^(-s t) (§4.2); must exceed 1
    s: float = 0.05  # decay of T(t), t = step within the epoch: exploration tapers within the epoch
    epsilon: float = 1.0  # epsilon-decreasing: explore with probability epsilon (T(t) - 1) / (T_max - 1)
    epsilon_decay: float = 0.0  # epsilon(epoch) = epsilon (1 - epsilon_decay) ** epoch: exploration fades
    count_prior: float = 1.0  # initial fictitious-play count of every action, so Eq. 7 is defined at the start
    # from this epoch on the fictitious-play counts (Eq. 7) stay as they are, as in a frozen swarm (with lr_anneal,
    # the anneal's lr-0 epochs are then the frozen epoch step for step; corridor study 10); 0: they always count
    count_freeze: int = 0
    g3: str = "signed"  # "unsigned": |g3|, so a goal straight behind the tip is one case, not both ends of g3
    extra_state: tuple[StateVariable, ...] = ()  # variables appended to S_i (a task's come first)
    state: str = "planar"  # what S_i holds (STATE_KINDS): the paper's six, a spatial joint's "plane" or its "turn"
    # "direction": the agent finds which way its motor turns from its own encoder and acts through it (plasticity.py);
    # "off": the paper's learner
    plasticity: str = "off"

    @property
    def observation(self) -> Observation:
        """The observation these settings lay the fuzzy grid over (what S_i holds)."""
        return Observation(self.state, self.g3, self.ranges, self.extra_state)

    @property
    def state_names(self) -> tuple[str, ...]:
        return STATE_KINDS[self.state] + tuple(v.name for v in self.extra_state)

    @property
    def state_sets(self) -> tuple[int, ...]:
        return self.n_sets + tuple(v.sets for v in self.extra_state)

    @property
    def state_ranges(self) -> tuple[tuple[float, float], ...]:
        return self.ranges + tuple(v.range for v in self.extra_state)

    @classmethod
    def on(cls, observation: Observation, **learner: object) -> LearnerSettings:
        """The learner's own settings (no observation field) over `observation`."""
        mixed = sorted(set(learner) & set(OBSERVATION_FIELDS))
        if mixed:
            raise ValueError(f"{mixed[0]} is the observation's, not the learner's")
        o = observation
        return cls(state=o.state, g3=o.g3, ranges=o.ranges, extra_state=o.extra_state, **learner)  # type: ignore[arg-type]

    @classmethod
    def for_reach(cls, reach: float, **overrides: object) -> LearnerSettings:
        """Settings with d in [0, reach] and g1, g2 in [-2 reach, 2 reach]; overrides replace any field."""
        if not (isinstance(reach, (int, float)) and math.isfinite(reach) and reach > 0):
            raise ValueError(f"reach must be a positive finite number, got {reach!r}")
        kwargs: dict[str, object] = {"ranges": ranges_for(float(reach))}
        kwargs.update(overrides)
        return cls(**kwargs)  # type: ignore[arg-type]

    @classmethod
    def for_plane(cls, reach: float, lever: float, limits: tuple[float, float], **overrides: object) -> LearnerSettings:
        """Settings of a spatial joint's rotation-plane state (state.plane_state) on a robot of `reach` (m) whose
        tip can lie up to `lever` from this joint (observation.plane_ranges): q over its limits (5 sets), d over
        [0, lever] (5), g_perp over ±reach/10 (9: the fine sets decide the direction near the goal), g_axial and
        g_radial over ±reach/3 (5), |w| over [0, reach/2.4] (6). On the iiwa (reach 1.2 m): ±0.12, ±0.4, ±0.4 and
        [0, 0.5] m, the ranges an independent prototype measured frozen skills with (docs/results/reach3d)."""
        ranges = plane_ranges(reach, lever, limits)
        kwargs: dict[str, object] = {"state": "plane", "n_sets": PLANE_SETS, "ranges": ranges}
        kwargs.update(overrides)
        return cls(**kwargs)  # type: ignore[arg-type]

    @classmethod
    def for_turn(cls, **overrides: object) -> LearnerSettings:
        """Settings of a spatial joint's turn state: g_q (rad) in 9 sets over ±15°, learning at lr 0.5 / 64. Farther
        moves saturate in the end sets (only their direction matters); the fine sets near 0 decide when to stop. Nine
        rules see every step's noisy reward: at lr 0.5 the iiwa's learners reached 36 / 32 % of unseen poses (sets
        A / B), at 0.05 35 / 27 %, at 0.5 / 64 88 / 90 %, at 0.002 91 / 83 % (docs/notebook/reach3d.md,
        turn*; g_q's sets over ±45° instead: 85 / 82 %)."""
        kwargs: dict[str, object] = {"state": "turn", "ranges": TURN_RANGES, **TURN_LEARNER}
        kwargs.update(overrides)
        return cls(**kwargs)  # type: ignore[arg-type]

    def replace(self, **changes: object) -> LearnerSettings:
        return replace(self, **changes)  # type: ignore[arg-type]

    def with_task_state(self, variables: tuple[StateVariable, ...]) -> LearnerSettings:
        """These settings with a task's state variables before the extra ones given here."""
        return self.replace(extra_state=(*variables, *self.extra_state)) if variables else self

    def __post_init__(self) -> None:
        check_observation(self)  # state, g3, ranges, extra_state: observation.py
        base_names = STATE_KINDS[self.state]
        n = len(base_names)
        object.__setattr__(self, "n_sets", tuple(int(m) for m in self.n_sets))
        if len(self.n_sets) != n:
            raise ValueError(f"n_sets needs {n} entries {base_names}, got {len(self.n_sets)}")
        for name, m in zip(base_names, self.n_sets, strict=True):
            if m < 1:
                raise ValueError(f"n_sets[{name}] must be >= 1, got {m}")
        if not (isinstance(self.top_k, int) and 1 <= self.top_k <= min(self.state_sets)):
            raise ValueError(f"top_k must be an int in [1, the fewest sets {min(self.state_sets)}], got {self.top_k}")
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
        if not 0.0 <= self.epsilon_decay < 1.0:
            raise ValueError(f"epsilon_decay must be in [0, 1), got {self.epsilon_decay}")
        if not (math.isfinite(self.count_prior) and self.count_prior > 0):
            raise ValueError(f"count_prior must be > 0 so Eq. 7 is defined, got {self.count_prior}")
        if self.plasticity not in PLASTICITY:
            raise ValueError(f"plasticity must be one of {', '.join(PLASTICITY)}, got {self.plasticity!r}")
        if self.plasticity == "direction" and STATE_KINDS[self.state][0] != "q":
            raise ValueError(f'plasticity "direction" reads the joint angle q, which the {self.state} state has not')
        freeze = self.count_freeze
        if not (isinstance(freeze, int) and not isinstance(freeze, bool) and freeze >= 0):
            raise ValueError(f"count_freeze must be an epoch (int >= 0; 0 for never), got {self.count_freeze!r}")
