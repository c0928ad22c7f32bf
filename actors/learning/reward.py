"""Reward of the reaching task (paper §4.2, Eq. 10) and two variants."""

from __future__ import annotations

import math

REWARD_MODES: tuple[str, ...] = ("paper", "strict", "shaped")


def reach_reward(
    D: float, D_prev: float, mode: str, D_min: float = 3.0, c: float = 1.0, k: float = 20.0
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
    """
    if mode not in REWARD_MODES:
        raise ValueError(f"unknown reward mode {mode!r}; allowed modes: {', '.join(REWARD_MODES)}")
    dD = D - D_prev
    if D > D_min:
        if mode == "shaped":
            return -2.0 + k * (D_prev - D)
        return -2.0
    if mode != "paper" and abs(dD) < 1e-12:
        return 0.0
    if dD <= 0.0:
        return math.exp(-c * D)
    return -1.0
