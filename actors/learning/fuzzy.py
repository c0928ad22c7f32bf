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

from . import kernels
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
    """Membership evaluation (Eq. 3) and sparse rule activation (Eq. 4) for one agent.

    activate() is the learner's path, compiled (kernels.py) around numpy's exp; memberships() and
    activate_reference() are the same arithmetic in plain numpy, the reference the tests hold it to.
    """

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
        self.n_fired = self.top_k**n_vars
        # Which of the k kept sets each of the k^n combinations takes, per variable (activate_reference).
        self._combos = np.array(list(itertools.product(range(self.top_k), repeat=n_vars)), dtype=np.int64)
        self._rows = np.arange(n_vars)
        # activate(), compiled: per variable (lo, hi, sigma) and (n_sets, strides), stacked (each argument of a
        # compiled call costs time); the real boundaries one after the other, variable v's m_v - 1 after variable
        # v - 1's; L at a padded boundary as memberships() computes it (exponent capped at 700), which the last real
        # set's membership subtracts.
        self._lo_hi_sigma = np.stack((lo, hi, sigma))
        self.grid = np.stack((self.n_sets, strides))
        self._bounds_real = np.concatenate([bounds[v, : m - 1] for v, m in enumerate(n_sets)])
        self.L_pad = float((1.0 / (1.0 + np.exp(np.full(1, 700.0))))[0])
        self._e = np.empty(len(self._bounds_real))
        self._mu = np.empty((n_vars, width))

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

    def exponentials(self, state: np.ndarray) -> np.ndarray:
        """e^(sigma (b - x)) at every real boundary (Eq. 3), into a reused buffer: the exponents compiled, the exp
        numpy's (kernels.py says why)."""
        x = np.ascontiguousarray(state, dtype=np.float64)
        if x.shape != self._lo.shape:
            raise ValueError(f"state must have {self._lo.size} variables, got shape {x.shape}")
        e = self._e
        kernels.exponents(x, self._lo_hi_sigma, self._bounds_real, self.grid, e)
        return np.exp(e, out=e)

    def _memberships_fast(self, state: np.ndarray) -> np.ndarray:
        """memberships() the way activate() computes them (into a reused buffer, valid until the next call)."""
        kernels.memberships(self.exponentials(state), self.n_sets, self.L_pad, self._mu)
        return self._mu

    def activate_into(self, state: np.ndarray, rules: np.ndarray, O: np.ndarray) -> None:  # noqa: E741
        """activate() into rules (int64[k^n]) and O (float64[k^n])."""
        e = self.exponentials(state)
        if not kernels.activate(e, self.grid, self.L_pad, self.top_k, rules, O):
            self.fire_tied(e, rules, O)

    def fire_tied(self, e: np.ndarray, rules: np.ndarray, O: np.ndarray) -> None:  # noqa: E741
        """activate() from the exponentials e when kept sets tie (kernels.kept_sets): numpy's order of them."""
        mu = self._mu
        kernels.memberships(e, self.n_sets, self.L_pad, mu)
        top = np.ascontiguousarray((-mu).argpartition(self.top_k - 1, axis=1)[:, : self.top_k])
        kernels.fire(mu, top, self.strides, rules, O)

    def activate(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Sparse rule activation: (flat rule indices int64[k^n], O float64[k^n]) for the fired rules.

        O^i is the product over variables of the kept memberships (Eq. 4); the index is row-major in
        the full grid over n_sets.
        """
        rules, O = np.empty(self.n_fired, dtype=np.int64), np.empty(self.n_fired)  # noqa: E741
        self.activate_into(state, rules, O)
        return rules, O

    def activate_reference(self, state: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """activate() in numpy, with explicit fancy indexing: the reference for tests."""
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
