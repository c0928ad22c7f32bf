"""A tabular learner: Q-learning over a table of the fuzzy grid's cells (no interpolation between them): the control
for what fuzzy generalisation (§4.1, Eqs. 2-4) buys."""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np

from .fuzzy import centres
from .learner import Learner
from .settings import LearnerSettings

#: the sets' slope the table is read with: at the centre of any set its own membership is then the largest (for the
#: end sets that needs slope > 2 ln 2); the cells do not depend on it (TabularLearner)
SLOPE = 4.0


class TabularLearner(Learner):
    """An agent's Q-table over the grid the fuzzy learner's sets span, with the paper's joint action selection.

    The cell of s: per variable, the set whose centre is nearest (centres evenly spaced over the variable's range,
    fuzzy.centres; x clipped to the range). Q(s, .) = phi[cell(s)], a row over joint actions created at its first
    update (qlearning.SparseFuzzyQ). The TD rule is Eq. 5 with that Q: phi[cell(s), alpha] += lr (r + gamma max_a E(s',
    a) - phi[cell(s), alpha]), E by Eq. 9, the action chosen by Eq. 8 as the paper's (JASM, Eqs. 7-9, unchanged).

    It is the fuzzy learner fed, instead of s, the centre of s's cell, with top_k = 1: at a set's centre that set's
    membership is its variable's largest, so exactly one rule fires, the cell's, with weight w = O / sum O = 1 (Eq. 4):
    Eq. 2 then reads Q(s, .) = phi[cell] and Eq. 6 adds the whole delta to that one entry: the table and its TD rule,
    on the fuzzy learner's compiled kernel (tests/test_learner_kinds.py holds it to a Q-table written out in numpy).
    """

    def __init__(self, settings: LearnerSettings, n_visible: int, seed: int | Sequence[int]) -> None:
        super().__init__(settings.replace(top_k=1, slope=SLOPE), n_visible, seed)
        sets, bounds = self.settings.state_sets, self.settings.state_ranges
        self._lo = np.array([lo for lo, _ in bounds])
        self._hi = np.array([hi for _, hi in bounds])
        self._last = np.array(sets, dtype=np.float64) - 1.0  # the last cell's index per variable
        self._centres = np.full((len(sets), max(sets)), np.nan)  # per variable its cells' centres, padded
        for v, (m, (lo, hi)) in enumerate(zip(sets, bounds, strict=True)):
            self._centres[v, :m] = centres(m, lo, hi)
        self._rows = np.arange(len(sets))

    def cell(self, state: np.ndarray) -> np.ndarray:
        """The cell of s: per variable the index of the nearest set centre (x clipped to the range; a half-way x goes
        to the even index, numpy's rounding)."""
        x = np.minimum(np.maximum(np.asarray(state, dtype=np.float64), self._lo), self._hi)
        span = np.where(self._last > 0, self._hi - self._lo, 1.0)
        return np.rint((x - self._lo) / span * self._last).astype(np.int64)

    def centre(self, state: np.ndarray) -> np.ndarray:
        """The centre of s's cell (a NaN variable stays NaN, as the fuzzy learner takes it)."""
        x = np.asarray(state, dtype=np.float64)
        if x.shape != self._lo.shape:
            raise ValueError(f"state must have {self._lo.size} variables, got shape {x.shape}")
        nan = np.isnan(x)
        if nan.any():
            c = self._centres[self._rows, self.cell(np.where(nan, self._lo, x))]
            return np.where(nan, x, c)
        return self._centres[self._rows, self.cell(x)]

    def decide(
        self,
        state: np.ndarray,
        reward: float | None,
        learn: bool = True,
        explore: bool = True,
        avoid: Collection[int] = (),
    ) -> int:
        return super().decide(self.centre(state), reward, learn, explore, avoid)
