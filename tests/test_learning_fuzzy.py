"""Eqs. 3-4: sigmoid memberships, partition of unity, sparse rule activation."""

import itertools
import math

import numpy as np
import pytest
from kinswarm.actors.learning import FuzzyPartition, LearnerSettings, memberships_1d

# x at a centre, slope 4: the boundary half a spacing away gives logistic(4 * 0.5) = logistic(2)
L_HI = 1.0 / (1.0 + math.exp(-2.0))


def test_memberships_hand_computed():
    # 3 sets over [0, 2]: centres 0, 1, 2; boundaries 0.5, 1.5; sigma = slope / spacing = 4.
    mu = memberships_1d(1.0, 3, 0.0, 2.0, 4.0)
    np.testing.assert_allclose(mu, [1 - L_HI, L_HI - (1 - L_HI), 1 - L_HI], rtol=1e-12)
    np.testing.assert_allclose(mu, [0.11920292, 0.76159416, 0.11920292], atol=1e-8)


def test_partition_of_unity_and_clipping():
    for x in np.linspace(-10, 10, 41):
        mu = memberships_1d(float(x), 7, -3.0, 3.0, 4.0)
        assert mu.sum() == pytest.approx(1.0)
        assert np.all(mu >= 0)
    # outside the range clips to the edge
    edge = memberships_1d(3.0, 7, -3.0, 3.0, 4.0)
    np.testing.assert_allclose(memberships_1d(50.0, 7, -3.0, 3.0, 4.0), edge)
    assert np.argmax(memberships_1d(-50.0, 7, -3.0, 3.0, 4.0)) == 0


def test_vectorised_matches_reference():
    st = LearnerSettings()
    fp = FuzzyPartition(st)
    state = np.array([0.3, -2.0, 5.5, 30.0, -7.0, 0.1])  # g1 outside its range
    mu = fp.memberships(state)
    for v, (m, (lo, hi)) in enumerate(zip(st.n_sets, st.ranges, strict=True)):
        np.testing.assert_allclose(mu[v, :m], memberships_1d(state[v], m, lo, hi, st.slope), atol=1e-12)
        assert np.all(mu[v, m:] == -1.0)  # padding never wins top-k


def test_eq4_all_rules_when_two_sets():
    # With 2 sets per variable and top-2 every rule fires: sum O = prod (sum mu) = 1.
    st = LearnerSettings(n_sets=(2,) * 6, ranges=((0.0, 1.0),) * 6)
    fp = FuzzyPartition(st)
    state = np.array([0.1, 0.2, 0.3, 0.4, 0.5, 0.9])
    rules, O = fp.activate(state)  # noqa: E741
    assert sorted(rules.tolist()) == list(range(64))
    assert O.sum() == pytest.approx(1.0)
    mus = [memberships_1d(x, 2, 0.0, 1.0, st.slope) for x in state]
    # rule 0 = every variable in set 0; rule 63 = every variable in set 1 (row-major flat index)
    assert O[rules.tolist().index(0)] == pytest.approx(np.prod([m[0] for m in mus]))
    assert O[rules.tolist().index(63)] == pytest.approx(np.prod([m[1] for m in mus]))
    # rule 0b100000 = 32: first variable in set 1, rest in set 0
    assert O[rules.tolist().index(32)] == pytest.approx(mus[0][1] * np.prod([m[0] for m in mus[1:]]))


def test_eq4_sparse_top2_and_flat_index():
    st = LearnerSettings()
    fp = FuzzyPartition(st)
    assert fp.n_rules == 20 * 20 * 13 * 7 * 7 * 7 == 1_783_600
    state = np.array([0.3, -2.0, 5.5, 3.0, -7.0, 0.1])
    rules, O = fp.activate(state)  # noqa: E741
    assert rules.dtype == np.int64 and O.dtype == np.float64
    assert rules.shape == O.shape == (64,)
    assert len(set(rules.tolist())) == 64
    # brute force: top-2 sets per variable, every combination, np.ravel_multi_index
    tops = []
    for v, (m, (lo, hi)) in enumerate(zip(st.n_sets, st.ranges, strict=True)):
        mu = memberships_1d(state[v], m, lo, hi, st.slope)
        tops.append([(int(j), mu[j]) for j in np.argsort(-mu)[:2]])
    expect = {}
    for combo in itertools.product(*tops):
        idx = int(np.ravel_multi_index([j for j, _ in combo], st.n_sets))
        expect[idx] = float(np.prod([p for _, p in combo]))
    got = dict(zip(rules.tolist(), O.tolist(), strict=True))
    assert got.keys() == expect.keys()
    for k in expect:
        assert got[k] == pytest.approx(expect[k], rel=1e-12)
