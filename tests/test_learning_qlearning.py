"""Eqs. 2, 5, 6 on a tiny sparse rule base."""

import numpy as np
import pytest
from kinswarm.actors.learning import SparseFuzzyQ


def test_eq2_eq6_hand_computed():
    q = SparseFuzzyQ(3)
    # Eq. 6: phi^i[0] += delta O^i / sum O, delta = 4, O = (1, 3) -> +1 and +3
    q.update(np.array([5, 7]), np.array([1.0, 3.0]), action=0, delta=4.0)
    np.testing.assert_allclose(q.phi[: q.rows], [[1.0, 0, 0], [3.0, 0, 0]])
    # Eq. 2: rules 5, 7, 9 with O = 1, 1, 2: Q = (1 * phi5 + 1 * phi7 + 2 * 0) / 4
    Q = q.q_values(np.array([5, 7, 9]), np.array([1.0, 1.0, 2.0]))
    np.testing.assert_allclose(Q, [1.0, 0.0, 0.0])
    assert q.rows == 2  # reading the untouched rule 9 did not create it
    assert np.all(q.q_values(np.array([11, 12]), np.array([0.5, 0.5])) == 0.0)


def test_eq5_delta():
    q = SparseFuzzyQ(3)
    # delta = lambda (r + gamma * bootstrap - Q(s, a)) = 0.5 (-2 + 0.9 * 3 - 1) = -0.15
    assert q.td_delta(q_sa=1.0, reward=-2.0, bootstrap=3.0, lr=0.5, gamma=0.9) == pytest.approx(-0.15)


def test_grow_and_export_import():
    q = SparseFuzzyQ(9, capacity=2)
    rng = np.random.default_rng(0)
    for _ in range(20):
        rules = rng.choice(1000, 8, replace=False)
        q.update(rules, rng.random(8), int(rng.integers(9)), float(rng.normal()))
    keys, phi = q.export()
    assert keys.dtype == np.int64 and phi.shape == (q.rows, 9)
    q2 = SparseFuzzyQ(9)
    q2.load(keys, phi)
    probe = np.arange(1000)
    np.testing.assert_allclose(q2.q_values(probe, np.ones(1000)), q.q_values(probe, np.ones(1000)))
    with pytest.raises(ValueError, match="phi"):
        q2.load(keys, phi[:, :3])
    with pytest.raises(ValueError, match="phi_keys"):
        q2.load(keys.astype(float), phi)
