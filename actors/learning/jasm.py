"""Joint action selection mechanism, JASM (paper §4.2, Eqs. 7-9, Algorithm 2).

Joint actions are indexed row-major over (own action, visible agent 1, visible agent 2, ...), so
Q(s, .) reshaped to (n_actions,) * (1 + n_visible) has the agent's own action on axis 0.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np


def probabilities(counts: np.ndarray) -> np.ndarray:
    """P^i(alpha_k^j) = C^i(alpha_k^j) / sum_b C^i(b^j) (Eq. 7); counts shape (n_visible, n_actions)."""
    counts = np.asarray(counts, dtype=np.float64)
    return counts / counts.sum(axis=1, keepdims=True)


def expected_values(q: np.ndarray, P: np.ndarray, n_actions: int = 3) -> np.ndarray:
    """E(alpha_i) = sum_{alpha_-i} Q(s, alpha_i u alpha_-i) prod_j P(alpha_j) (Eq. 9).

    q: Q(s, .) over joint actions, flat or shaped (n_actions,) * (1 + n_visible); P: (n_visible, n_actions).
    """
    n_visible = P.shape[0]
    E = np.asarray(q, dtype=np.float64).reshape((n_actions,) * (1 + n_visible))
    for j in range(n_visible - 1, -1, -1):
        E = E @ P[j]  # contract the last visible agent's axis with its believed policy
    return E


def temperature(t: float, T_max: float, s: float) -> float:
    """T(t) = 1 + T_max e^(-s t) (§4.2), t = step within the epoch."""
    return 1.0 + T_max * math.exp(-s * t)


def boltzmann(E: np.ndarray, T: float) -> np.ndarray:
    """pi(alpha_i) = e^(E/T) / sum e^(E/T) (Eq. 8); the max is subtracted for numerical stability."""
    z = (E - E.max()) / T
    w = np.exp(z)
    return w / w.sum()


def policy(z: np.ndarray) -> list[float]:
    """pi = e^z / sum e^z (Eq. 8) from its exponent z = (E - max E) / T, as boltzmann() computes it (numpy's exp)."""
    return normalise(np.exp(z).tolist())


def normalise(w: Sequence[float]) -> list[float]:
    """w / sum w, the sum of fewer than 8 float64s added as numpy adds them: left to right from 0.0."""
    total = 0.0
    for x in w:
        total += x
    return [x / total for x in w]


def explore_probability(T: float, T_max: float, epsilon: float) -> float:
    """epsilon-decreasing: explore with probability epsilon (T(t) - 1) / (T_max - 1), clipped to [0, 1]."""
    p = epsilon * (T - 1.0) / (T_max - 1.0)
    return 0.0 if p < 0.0 else 1.0 if p > 1.0 else p


def greedy(pi: np.ndarray | Sequence[float], rng: np.random.Generator) -> int:
    """argmax pi with random tie-breaking: Q starts at 0, so a fixed tie-break would always pick action 0."""
    p = pi.tolist() if isinstance(pi, np.ndarray) else pi
    best = max(p)
    floor = best - 1e-12 * abs(best)
    return break_tie([a for a, v in enumerate(p) if v >= floor], rng)


def break_tie(ties: list[int], rng: np.random.Generator) -> int:
    return ties[0] if len(ties) == 1 else ties[int(rng.integers(len(ties)))]


def sample(pi: np.ndarray | Sequence[float], rng: np.random.Generator) -> int:
    """An action drawn from pi: inverse CDF, cheaper than rng.choice for 3 actions."""
    u = rng.random()
    acc = 0.0
    probs = pi.tolist() if isinstance(pi, np.ndarray) else pi
    for a, p in enumerate(probs):
        acc += p
        if u < acc:
            return a
    return max(a for a, p in enumerate(probs) if p > 0.0)  # rounding left u past the sum


def select_action(
    pi: np.ndarray | Sequence[float], p_explore: float, rng: np.random.Generator, explore: bool = True
) -> int:
    """With probability p_explore sample from pi (Eq. 8), else take the best pi (ε-decreasing scheme)."""
    if explore and p_explore > 0.0 and rng.random() < p_explore:
        return sample(pi, rng)
    return greedy(pi, rng)


def select_from_exponent(z: np.ndarray, p_explore: float, rng: np.random.Generator, explore: bool = True) -> int:
    """select_action(policy(z), ...), the same choice from the same draws, with pi computed only when the choice
    depends on its values: to sample from it, and when greedy()'s tie test could be close. Otherwise the greedy
    choice is among the actions with z = 0 (pi = e^0 / sum e^z, the largest); every other z is at most -1e-9, so its
    pi is at most (1 - 1e-9) of the largest, far outside greedy()'s 1e-12 (NaN is never "otherwise")."""
    if explore and p_explore > 0.0 and rng.random() < p_explore:
        return sample(policy(z), rng)
    zs = z.tolist()
    if not all(v == 0.0 or v <= -1e-9 for v in zs):
        return greedy(policy(z), rng)
    return break_tie([a for a, v in enumerate(zs) if v == 0.0], rng)
