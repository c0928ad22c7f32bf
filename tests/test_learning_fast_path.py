"""The fast learning path must reproduce the straightforward implementation bit for bit.

ReferenceLearner.step below is Learner.step as first written (fancy-indexed activation, per-rule touch
loop, numpy lookups); the fast Learner must return the same actions and end with identical phi rows and
keys, counts and RNG state for the same inputs.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pytest
from kinswarm.actors.learning import jasm
from kinswarm.actors.learning.fuzzy import FuzzyPartition, centres
from kinswarm.actors.learning.learner import Learner
from kinswarm.actors.learning.qlearning import SparseFuzzyQ
from kinswarm.actors.learning.settings import N_ACTIONS, LearnerSettings

SETTINGS = [
    LearnerSettings.for_reach(12.0),
    LearnerSettings.for_reach(3.0, slope=9.0, n_sets=(5, 4, 3, 2, 6, 3)),
    LearnerSettings(n_sets=(4, 1, 3, 5, 2, 3), top_k=1, slope=2.0),
    LearnerSettings(n_sets=(4, 3, 3, 5, 4, 3), top_k=3),
    LearnerSettings(n_sets=(2, 2, 2, 2, 2, 2), slope=30.0),  # top_k = max(n_sets): no argpartition
]


def reference_touch(q: SparseFuzzyQ, rules: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """SparseFuzzyQ.touch as first written: one new row at a time."""
    rows = rows.copy()
    missing = np.flatnonzero(rows < 0)
    if len(missing):
        idx = q.index
        need = len(idx) + len(missing)
        if need > q.phi.shape[0]:
            grown = np.zeros((max(need, 2 * q.phi.shape[0]), q.n_joint_actions))
            grown[: len(idx)] = q.phi[: len(idx)]
            q.phi = grown
        for n in missing.tolist():
            rows[n] = idx[int(rules[n])] = len(idx)
    return rows


class ReferenceLearner(Learner):
    def step(
        self,
        state: np.ndarray,
        reward: float | None,
        visible_actions: Sequence[int],
        learn: bool = True,
        explore: bool = True,
    ) -> int:
        st = self.settings
        rules, O = self.fuzzy.activate_reference(state)  # noqa: E741
        P = jasm.probabilities(self.counts) if self.n_visible else np.zeros((0, self.n_actions))
        w = O / O.sum()
        rows = self.q.lookup(rules)
        q_now = self.q.q_rows(rows, w)
        if learn and reward is not None and self._pending is not None:
            p_rules, p_rows, p_w, p_joint = self._pending
            p_rows = reference_touch(self.q, p_rules, p_rows)
            q_sa = float(p_w @ self.q.phi[p_rows, p_joint])
            boot = float(jasm.expected_values(q_now, P, self.n_actions).max())
            delta = self.q.td_delta(q_sa, float(reward), boot, self.lr, st.gamma)
            self.q.phi[p_rows, p_joint] += delta * p_w
            if rows.min() < 0:
                rows = self.q.lookup(rules)
            q_now = self.q.q_rows(rows, w)
        E = jasm.expected_values(q_now, P, self.n_actions)
        T = jasm.temperature(self.t, st.T_max, st.s)
        pi = jasm.boltzmann(E, T)
        a = jasm.select_action(pi, jasm.explore_probability(T, st.T_max, st.epsilon), self.rng, explore)
        if learn:  # a frozen learner's fictitious-play counts stay as trained
            for j, b in enumerate(visible_actions):
                self.counts[j, b] += 1.0
        self._pending = (rules, rows, w, self.joint_index(a, visible_actions))
        self.t += 1
        return a


def special_values(settings: LearnerSettings) -> list[np.ndarray]:
    """Per variable: range ends, set centres, boundaries between sets, and values outside the range."""
    out = []
    for m, (lo, hi) in zip(settings.n_sets, settings.ranges, strict=True):
        c = centres(m, lo, hi)
        b = (c[:-1] + c[1:]) / 2.0
        out.append(np.concatenate((c, b, [lo, hi, lo - 1.0, hi + 1.0, 2 * hi - lo, np.inf, -np.inf])))
    return out


def random_states(settings: LearnerSettings, n: int, rng: np.random.Generator) -> list[np.ndarray]:
    """A mix of random walks (so rules repeat), uniform draws beyond the ranges and special values."""
    lo = np.array([r[0] for r in settings.ranges])
    hi = np.array([r[1] for r in settings.ranges])
    special = special_values(settings)
    states, s = [], rng.uniform(lo, hi)
    for _ in range(n):
        kind = rng.random()
        if kind < 0.5:
            s = s + rng.normal(0.0, 0.03, 6) * (hi - lo)  # small moves: s(t) shares rules with s(t-1)
        elif kind < 0.7:
            s = rng.uniform(lo - 0.3 * (hi - lo), hi + 0.3 * (hi - lo))
        else:
            s = np.array([rng.choice(v) for v in special])  # on centres, boundaries and range ends
            s = np.where(rng.random(6) < 0.5, s, rng.uniform(lo, hi))
        states.append(np.array(s))
    return states


@pytest.mark.parametrize("settings", SETTINGS)
def test_activate_matches_reference(settings: LearnerSettings) -> None:
    fp = FuzzyPartition(settings)
    for s in random_states(settings, 600, np.random.default_rng(7)):
        rules, O = fp.activate(s)  # noqa: E741
        ref_rules, ref_O = fp.activate_reference(s)
        assert rules.dtype == ref_rules.dtype == np.int64
        np.testing.assert_array_equal(rules, ref_rules)
        np.testing.assert_array_equal(O, ref_O)
        np.testing.assert_array_equal(fp._memberships_fast(s), fp.memberships(s))


@pytest.mark.parametrize(
    ("settings", "n_visible", "n_steps"),
    [
        (SETTINGS[0], 1, 1200),
        (SETTINGS[0], 0, 500),
        (SETTINGS[0], 2, 500),
        (SETTINGS[1], 1, 400),
        (SETTINGS[2], 2, 200),
        (SETTINGS[3], 1, 200),
        (SETTINGS[4], 1, 100),
    ],
)
def test_learner_matches_reference(settings: LearnerSettings, n_visible: int, n_steps: int) -> None:
    rng = np.random.default_rng(n_steps + n_visible)
    fast, ref = Learner(settings, n_visible, 3), ReferenceLearner(settings, n_visible, 3)
    for ln in (fast, ref):
        ln.start_epoch(2)
    for t, s in enumerate(random_states(settings, n_steps, rng)):
        if t % 150 == 149:
            epoch = int(rng.integers(0, 50))
            fast.start_epoch(epoch)
            ref.start_epoch(epoch)
        reward = None if rng.random() < 0.1 else float(rng.normal(-1.0, 2.0))
        visible = rng.integers(0, N_ACTIONS, n_visible).tolist()
        learn, explore = bool(rng.random() < 0.9), bool(rng.random() < 0.8)
        a = fast.step(s, reward, visible, learn=learn, explore=explore)
        assert a == ref.step(s, reward, visible, learn=learn, explore=explore), f"step {t}"
    d, r = fast.state_dict(), ref.state_dict()
    assert d.keys() == r.keys()
    for k in d:
        assert d[k].dtype == r[k].dtype
        np.testing.assert_array_equal(d[k], r[k], err_msg=k)
    assert fast.rules_used == ref.rules_used > 0
    assert fast.q.phi.shape == ref.q.phi.shape  # same growth too
    assert fast.rng.bit_generator.state == ref.rng.bit_generator.state
    assert fast.t == ref.t


def test_touch_matches_reference() -> None:
    rng = np.random.default_rng(1)
    q, ref = SparseFuzzyQ(9, capacity=4), SparseFuzzyQ(9, capacity=4)
    for _ in range(200):
        rules = np.unique(rng.integers(0, 500, 16))
        rng.shuffle(rules)
        assert np.array_equal(q.touch(rules), reference_touch(ref, rules, ref.lookup(rules)))
        # stale -1 rows (rules touched since) take the one-by-one path, whatever it does
        assert np.array_equal(q.touch(rules[:3], np.full(3, -1)), reference_touch(ref, rules[:3], np.full(3, -1)))
        assert np.array_equal(q.lookup(rules), ref.lookup(rules))
    assert q.index == ref.index
    assert q.phi.shape == ref.phi.shape
