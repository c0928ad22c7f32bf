"""The compiled kernels compute what numpy computes, bit for bit: sums in numpy's order, Eq. 9 through numpy's BLAS,
the kept sets in numpy's argpartition order, and the rule index with a dict's semantics."""

from __future__ import annotations

import numpy as np
import pytest
from kinswarm.actors.learning import jasm, kernels
from kinswarm.actors.learning.qlearning import RuleIndex


def test_total_adds_as_numpy_sums() -> None:
    """numpy's pairwise summation: one by one below 8, 8 running sums up to 128, halves above (recursing)."""
    rng = np.random.default_rng(0)
    for n in [*range(0, 300), 511, 512, 513, 1024, 4096, 6561, 10_000]:
        a = rng.random(n) ** 6  # spread magnitudes: a different order of additions shows in the last bit
        assert kernels.total(a) == a.sum(), n


@pytest.mark.parametrize("n_visible", [0, 1, 2, 3])
def test_expected_values_is_numpys_eq9(n_visible: int) -> None:
    rng = np.random.default_rng(n_visible)
    for _ in range(300):
        q = rng.normal(size=3 ** (1 + n_visible)) * 10.0 ** rng.integers(-3, 3)
        P = jasm.probabilities(rng.random((n_visible, 3)) + 0.01)
        E = np.empty(3)
        kernels.expected_values(q, P, E, np.empty(2 * q.size))
        np.testing.assert_array_equal(E, jasm.expected_values(q, P))


def test_probabilities_is_numpys_eq7() -> None:
    counts = np.random.default_rng(1).random((3, 3)) * 50 + 1
    P = np.empty((3, 3))
    kernels.probabilities(counts, P)
    np.testing.assert_array_equal(P, jasm.probabilities(counts))


def test_kept_sets_follow_numpy_or_decline_on_ties() -> None:
    rng = np.random.default_rng(2)
    for _ in range(2000):
        width = int(rng.integers(2, 12))
        k = int(rng.integers(1, width))
        n_sets = rng.integers(k, width + 1, 4)
        mu = np.full((4, width), -1.0)
        for v, m in enumerate(n_sets):
            mu[v, :m] = rng.integers(0, 6, m) / 5.0 if rng.random() < 0.5 else rng.random(m)  # ties, or none
        top = np.empty((4, k), dtype=np.int64)
        if kernels.kept_sets(mu, n_sets, top):
            np.testing.assert_array_equal(top, (-mu).argpartition(k - 1, axis=1)[:, :k])
        else:  # some variable's k + 1 largest hold a tie
            ordered = -np.sort(-mu, axis=1)[:, : k + 1]
            assert np.any(ordered[:, :-1] == ordered[:, 1:])


def test_rule_index_is_a_dict() -> None:
    rng = np.random.default_rng(3)
    index, d = RuleIndex(capacity=2), {}
    for rule in rng.integers(0, 10**9, 3000).tolist():
        if rule in d:
            assert index[rule] == d[rule]
        index[rule] = d[rule] = len(d)  # a rule seen again is given the next number, as a dict assignment
    assert len(index) == len(d) and list(index) == list(d) and index == d
    assert index.capacity >= len(d) and index.table.shape[0] >= 2 * len(d)
    assert 10**9 + 1 not in index and index.get(10**9 + 1, -1) == -1
    with pytest.raises(KeyError):
        index[10**9 + 1]


def test_the_choice_from_eq8s_exponent_is_select_actions() -> None:
    """select_from_exponent skips pi where the choice does not depend on its values: the same action from the same
    draws, also with actions tied, nearly tied (E within 1e-15 to 1e-7 of the best), and NaN (an error either way)."""

    def outcome(choose, *args):
        try:
            return choose(*args)
        except ValueError as e:
            return str(e)

    rng = np.random.default_rng(4)
    for _ in range(20_000):
        E = np.round(rng.normal(size=3), int(rng.integers(0, 3)))  # rounded: exact ties
        E += rng.choice([0.0, 1e-15, 1e-12, 1e-10, 1e-9, 1e-8, 1e-7], 3) * rng.choice([-1.0, 1.0], 3)
        if rng.random() < 0.01:
            E[int(rng.integers(3))] = np.nan
        z = (E - E.max()) / (1.0 + 10.0 * rng.random())
        p_explore, explore, seed = (
            float(rng.choice([0.0, rng.random(), 1.0])),
            bool(rng.random() < 0.8),
            rng.integers(9),
        )
        a, b = np.random.default_rng(seed), np.random.default_rng(seed)
        assert outcome(jasm.select_from_exponent, z, p_explore, a, explore) == outcome(
            jasm.select_action, jasm.policy(z), p_explore, b, explore
        )
        assert a.bit_generator.state == b.bit_generator.state
