"""Eqs. 7-9, T(t), epsilon-decreasing and random tie-breaking."""

import math

import numpy as np
import pytest
from kinswarm.actors.learning import (
    boltzmann,
    expected_values,
    explore_probability,
    probabilities,
    select_action,
    temperature,
)
from kinswarm.actors.learning.jasm import greedy


def test_eq7_probabilities():
    np.testing.assert_allclose(
        probabilities(np.array([[1.0, 2.0, 1.0], [3.0, 0.5, 0.5]])), [[0.25, 0.5, 0.25], [0.75, 0.125, 0.125]]
    )


def test_eq9_hand_3x3():
    Q = np.arange(9.0).reshape(3, 3)  # own action on axis 0, the visible agent's on axis 1
    P = np.array([[0.2, 0.3, 0.5]])
    # row a: sum_b Q[a, b] P[b]
    np.testing.assert_allclose(expected_values(Q.ravel(), P), [1.3, 4.3, 7.3])


def test_eq9_two_visible_agents():
    rng = np.random.default_rng(1)
    Q = rng.normal(size=(3, 3, 3))
    P = probabilities(rng.random((2, 3)) + 0.1)
    np.testing.assert_allclose(expected_values(Q.ravel(), P), np.einsum("abc,b,c->a", Q, P[0], P[1]))
    assert expected_values(np.array([1.0, 2.0, 3.0]), np.zeros((0, 3))).tolist() == [1.0, 2.0, 3.0]


def test_eq8_boltzmann():
    E = np.array([0.0, math.log(2), math.log(4)])
    np.testing.assert_allclose(boltzmann(E, 1.0), [1 / 7, 2 / 7, 4 / 7])
    np.testing.assert_allclose(boltzmann(2 * E, 2.0), [1 / 7, 2 / 7, 4 / 7])
    np.testing.assert_allclose(boltzmann(np.array([1e4, 1e4, 1e4]), 1.0), [1 / 3] * 3)  # stable
    assert np.all(np.isfinite(boltzmann(np.array([-1e5, 0.0, 1e5]), 1.0)))


def test_temperature_and_explore_probability():
    assert temperature(0, 10.0, 0.01) == pytest.approx(11.0)
    assert temperature(100, 10.0, 0.01) == pytest.approx(1 + 10 / math.e)
    assert explore_probability(11.0, 10.0, 1.0) == 1.0  # T(0) = 1 + T_max
    assert explore_probability(1 + 10 / math.e, 10.0, 1.0) == pytest.approx(10 / math.e / 9)
    assert explore_probability(1 + 10 / math.e, 10.0, 0.5) == pytest.approx(5 / math.e / 9)
    assert explore_probability(1.0, 10.0, 1.0) == 0.0


def test_random_tie_break_picks_all_tied():
    rng = np.random.default_rng(0)
    picks = {greedy(np.array([0.4, 0.4, 0.2]), rng) for _ in range(200)}
    assert picks == {0, 1}
    picks = [select_action(np.full(3, 1 / 3), 0.0, rng) for _ in range(600)]
    counts = np.bincount(picks, minlength=3)
    assert np.all(counts > 150)  # all three tied actions, roughly uniformly


def test_explore_samples_from_pi():
    rng = np.random.default_rng(0)
    pi = np.array([0.1, 0.2, 0.7])
    picks = np.bincount([select_action(pi, 1.0, rng) for _ in range(4000)], minlength=3) / 4000
    np.testing.assert_allclose(picks, pi, atol=0.03)
    assert {select_action(pi, 1.0, rng, explore=False) for _ in range(50)} == {2}
