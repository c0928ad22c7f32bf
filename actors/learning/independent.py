"""Independent learners: the paper's fuzzy Q-learning (§4.1) without the joint action selection mechanism (§4.2's
model of the neighbours): the control for what fictitious play buys."""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np

from .learner import Learner
from .settings import LearnerSettings


class IndependentLearner(Learner):
    """An agent's fuzzy Q-learner over its own actions only, whatever children it has.

    The same arithmetic as `Learner` with no visible agent, i.e. as the paper's learner of a leaf: Q(s, .) over the
    agent's 3 actions (Eq. 2 over the fired rules, Eqs. 3-4), Eq. 9 with no neighbour to average over is E = Q(s, .),
    so the Boltzmann policy (Eq. 8) and the TD target's max (Eq. 5) are over Q itself; Eq. 6 updates the action taken.
    Eq. 7 has nothing to count: observe() ignores the children's actions, and the transition decide() opens is
    complete at once (its joint action is a(t)).
    """

    def __init__(self, settings: LearnerSettings, n_visible: int, seed: int | Sequence[int]) -> None:
        if not (isinstance(n_visible, (int, np.integer)) and n_visible >= 0):
            raise ValueError(f"n_visible must be an int >= 0, got {n_visible!r}")
        super().__init__(settings, 0, seed)
        self.n_children = int(n_visible)  # there, but not modelled

    def decide(
        self,
        state: np.ndarray,
        reward: float | None,
        learn: bool = True,
        explore: bool = True,
        avoid: Collection[int] = (),
    ) -> int:
        a = super().decide(state, reward, learn, explore, avoid)
        self._pending = a  # (d): (s(t), a(t)) is the whole transition; Eq. 5 completes it at t+1
        return a

    def step(
        self,
        state: np.ndarray,
        reward: float | None,
        visible_actions: Sequence[int],
        learn: bool = True,
        explore: bool = True,
    ) -> int:
        return self.decide(state, reward, learn=learn, explore=explore)

    def observe(self, visible_actions: Sequence[int], learn: bool = True) -> None:
        """Nothing: the children's actions are no part of this learner's Q."""
