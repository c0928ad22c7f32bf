"""Fuzzification of the agent state (paper §4.1, Eqs. 3-4) with sparse rule activation.

Each state variable has m sigmoid membership sets forming a partition of unity. They are built from
logistics of Eq. 3's form L_b(x) = 1 / (1 + rho e^(-sigma x)) with rho = e^(sigma b), i.e. a soft step up
at boundary b. With boundaries b_0 < ... < b_{m-2} midway between evenly spaced centres:

    set 0 = 1 - L_{b_0},   set j = L_{b_{j-1}} - L_{b_j},   set m-1 = L_{b_{m-2}}

which telescopes to 1. Only the top-k sets per variable are kept, so k^6 rules fire per state (64 for
k = 2) out of the full grid prod(n_sets) (1,783,600 for the paper's sets), which is never allocated.
"""

from __future__ import annotations

import itertools

import numpy as np

from .settings import LearnerSettings


def centres(m: int, lo: float, hi: float) -> np.ndarray:
    """Evenly spaced set centres over [lo, hi] (a single set sits in the middle)."""
    if m == 1:
        return np.array([(lo + hi) / 2.0])
    return np.linspace(lo, hi, m)


def memberships_1d(x: float, m: int, lo: float, hi: float, slope: float) -> np.ndarray:
    """Memberships of scalar x in the m sets over [lo, hi] (Eq. 3); sums to 1. Reference implementation."""
    if m == 1:
        return np.ones(1)
    c = centres(m, lo, hi)
    b = (c[:-1] + c[1:]) / 2.0
    sigma = slope / (c[1] - c[0])
    xc = min(max(x, lo), hi)  # outside the range: clip, memberships stay valid
    L = 1.0 / (1.0 + np.exp(-sigma * (xc - b)))  # Eq. 3 with rho = e^(sigma b)
    upper = np.concatenate(([1.0], L))
    lower = np.concatenate((L, [0.0]))
    return upper - lower


class FuzzyPartition:
    """Vectorised membership evaluation (Eq. 3) and sparse rule activation (Eq. 4) for one agent."""

    def __init__(self, settings: LearnerSettings) -> None:
        n_sets, ranges = settings.state_sets, settings.state_ranges  # the six of §3.3, plus scene variables
        self.n_sets = np.asarray(n_sets, dtype=np.int64)
        self.top_k = settings.top_k
        n_vars = len(n_sets)
        width = int(self.n_sets.max())
        lo = np.array([r[0] for r in ranges])
        hi = np.array([r[1] for r in ranges])
        self._lo, self._hi = lo, hi
        # Boundaries padded to a rectangle: +inf boundaries give L = 0 so padded sets have membership 0.
        bounds = np.full((n_vars, max(width - 1, 1)), np.inf)
        sigma = np.ones(n_vars)
        for v, m in enumerate(n_sets):
            if m > 1:
                c = centres(m, lo[v], hi[v])
                bounds[v, : m - 1] = (c[:-1] + c[1:]) / 2.0
                sigma[v] = settings.slope / (c[1] - c[0])
        self._bounds = bounds
        self._sigma = sigma[:, None]
        # Padded sets get -1 so top-k never picks them even if a real membership underflows to 0.
        self._width = width
        self._pad_offset = np.where(np.arange(width)[None, :] >= self.n_sets[:, None], -1.0, 0.0)
        self._buf = np.zeros((n_vars, bounds.shape[1] + 2))
        self._buf[:, 0] = 1.0
        # Row-major strides of the full rule grid: flat index = sum_v set_v * stride_v.
        strides = np.ones(n_vars, dtype=np.int64)
        for v in range(n_vars - 2, -1, -1):
            strides[v] = strides[v + 1] * self.n_sets[v + 1]
        self.strides = strides
        self.n_rules = int(np.prod(self.n_sets))
        # Which of the k kept sets each of the k^n combinations takes, per variable.
        self._combos = np.array(list(itertools.product(range(self.top_k), repeat=n_vars)), dtype=np.int64)
        self._rows = np.arange(n_vars)
        # Buffers of activate()'s membership evaluation: the same Eq. 3 arithmetic as memberships() in fewer
        # calls. L is written only at real boundaries (_real); per variable, the columns after b_{m-2} hold the
        # constants 0, 1, 2, ... so that mu_j = L_{b_{j-1}} - L_{b_j} is L_{b_{m-2}} for the last real set and
        # -1 for padded sets, as in memberships(). (memberships() has ~1e-304 rather than 0 at b_{m-1}; that
        # cannot change L_{b_{m-2}} - L_{b_{m-1}} while L_{b_{m-2}} > 1e-280, which _exact_fast checks.)
        self._real = np.arange(bounds.shape[1])[None, :] < (self.n_sets - 1)[:, None]
        self._L = np.zeros((n_vars, width + 1))
        self._L[:, 0] = 1.0  # L_{b_{-1}} = 1
        for v, m in enumerate(n_sets):
            self._L[v, m + 1 :] = np.arange(1, width + 1 - m)  # L at b_m, b_{m+1}, ... = 1, 2, ...
        self._L_real = self._L[:, 1:-1]  # view: L at b_0 .. b_{width-2}
        self._L_lo, self._L_hi = self._L[:, :-1], self._L[:, 1:]  # views: mu_j = L_lo[j] - L_hi[j]
        self._mu = np.empty((n_vars, width))
        self._arg = np.empty(bounds.shape)
        smallest_L = 1.0 / (1.0 + np.exp(np.where(self._real, sigma[:, None] * (bounds - lo[:, None]), 0.0)))
        self._exact_fast = width >= 2 and bool(smallest_L.min() > 1e-280)
        # Index tables for activate(): entry (v, j) of a (n_vars, width) array sits at flat position
        # v * width + j, so "kept set c of variable v in fired rule i" is flat position _combo_at[v, i]
        # of the argpartition result, and set j of variable v is flat position v * width + j of mu.
        # Variables run along axis 0 so the product of Eq. 4 is 5 elementwise multiplies, left to right.
        self._row_start = (self._rows * width)[:, None]
        self._combo_at = np.ascontiguousarray((self._rows * width + self._combos).T)
        self._rule_offset = int((self._rows * width) @ strides)

    def memberships(self, state: np.ndarray) -> np.ndarray:
        """Memberships (n_vars, max(n_sets)) of each variable in its sets (Eq. 3); padded sets hold -1."""
        # outside the range: clip, memberships stay valid (ufuncs directly; np.clip's wrapper costs ~4 us)
        x = np.minimum(np.maximum(np.asarray(state, dtype=np.float64), self._lo), self._hi)[:, None]
        buf = self._buf
        # exponent capped at 700 (no overflow warning): L at padded +inf boundaries becomes ~1e-304, not 0
        arg = np.minimum(self._sigma * (self._bounds - x), 700.0)
        np.divide(1.0, 1.0 + np.exp(arg), out=buf[:, 1:-1])  # Eq. 3: 1 / (1 + rho e^(-sigma x))
        # set j = L_{b_{j-1}} - L_{b_j} with L_{b_{-1}} = 1 and L_{b_{m-1}} = 0: a partition of unity.
        return (buf[:, :-1] - buf[:, 1:])[:, : self._width] + self._pad_offset

    def _memberships_fast(self, state: np.ndarray) -> np.ndarray:
        """memberships() bit for bit in fewer numpy calls, into a reused buffer (valid until the next call)."""
        if not self._exact_fast:
            return self.memberships(state)
        x = np.minimum(np.maximum(np.asarray(state, dtype=np.float64), self._lo), self._hi)[:, None]
        arg = np.multiply(self._sigma, np.subtract(self._bounds, x, out=self._arg), out=self._arg)
        e = np.exp(arg, out=arg)
        e += 1.0
        np.divide(1.0, e, out=self._L_real, where=self._real)  # Eq. 3: 1 / (1 + rho e^(-sigma x))
        return np.subtract(self._L_lo, self._L_hi, out=self._mu)  # set j = L_{b_{j-1}} - L_{b_j}

    def activate(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sparse rule activation: (flat rule indices int64[k^n], O float64[k^n]) for the fired rules.

        O^i is the product over variables of the kept memberships (Eq. 4); the index is row-major in
        the full grid over n_sets.
        """
        mu = self._memberships_fast(state)
        if self.top_k < mu.shape[1]:
            top = (-mu).argpartition(self.top_k - 1, axis=1)  # the first top_k columns hold the kept sets
        else:
            top = np.broadcast_to(np.arange(mu.shape[1]), mu.shape)
        # flat mu position of the set each fired rule takes per variable: (n_vars, k^n)
        at = (top + self._row_start).take(self._combo_at)
        O = mu.take(at).prod(axis=0)  # noqa: E741 -- Eq. 4: prod_v mu_v, same order as prod(axis=1) per rule
        rules = self.strides @ at - self._rule_offset  # row-major index in the full grid
        return rules, O

    def activate_reference(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """activate() as first written, with explicit fancy indexing; kept as the reference for tests."""
        mu = self.memberships(state)
        k = self.top_k
        if k < mu.shape[1]:
            top = np.argpartition(-mu, k - 1, axis=1)[:, :k]
        else:
            top = np.broadcast_to(np.arange(k), (mu.shape[0], k))
        vals = mu[self._rows[:, None], top]
        sets = top[self._rows, self._combos]  # (k^n, n_vars) set index per variable
        O = vals[self._rows, self._combos].prod(axis=1)  # noqa: E741 -- Eq. 4
        rules = sets @ self.strides
        return rules.astype(np.int64, copy=False), O
