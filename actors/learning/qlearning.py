"""Sparse fuzzy Q-function (paper §4.1, Eqs. 2, 5, 6).

phi^i is a vector over joint actions for rule i. Rows are created on first update, so memory grows with
the rules the agent actually visits, never with the full grid.
"""

from __future__ import annotations

from itertools import repeat

import numpy as np


class SparseFuzzyQ:
    """phi storage: dict rule index -> row of a growable float64 array (rows, n_joint_actions)."""

    def __init__(self, n_joint_actions: int, capacity: int = 1024) -> None:
        if n_joint_actions < 1:
            raise ValueError(f"n_joint_actions must be >= 1, got {n_joint_actions}")
        self.n_joint_actions = int(n_joint_actions)
        self.index: dict[int, int] = {}
        self.phi = np.zeros((max(int(capacity), 1), self.n_joint_actions))

    @property
    def rows(self) -> int:
        return len(self.index)

    @property
    def memory_bytes(self) -> int:
        # dict entries (~100 B each with the two int objects) + the allocated phi array.
        return int(self.phi.nbytes + 100 * len(self.index))

    def lookup(self, rules: np.ndarray) -> np.ndarray:
        """Rows of rules in phi, -1 for rules never touched (nothing is created)."""
        return np.array(self.row_list(rules.tolist()), dtype=np.int64)

    def row_list(self, rules: list[int]) -> list[int]:
        """lookup() with lists of Python ints in and out."""
        return list(map(self.index.get, rules, repeat(-1, len(rules))))

    def touch(self, rules: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Rows for rules, creating zero rows (phi = 0) for rules seen for the first time.

        rows: a previous lookup() of the same rules (rows are never removed, so only -1 entries can be stale).
        """
        rows = self.lookup(rules) if rows is None else rows.copy()
        missing = np.flatnonzero(rows < 0)
        if len(missing):
            idx = self.index
            need = len(idx) + len(missing)
            self._reserve(need)
            new = rules[missing].tolist()
            if len(set(new)) == len(new) and idx.keys().isdisjoint(new):
                # the usual case (distinct rules, fresh rows): new rows len(idx), len(idx) + 1, ... in order
                idx.update(zip(new, range(len(idx), need), strict=True))
                rows[missing] = np.arange(need - len(new), need)
            else:
                for n in missing.tolist():
                    rows[n] = idx[int(rules[n])] = len(idx)
        return rows

    def _reserve(self, need: int) -> None:
        """Room for need phi rows (rows in use are kept)."""
        if need > self.phi.shape[0]:
            grown = np.zeros((max(need, 2 * self.phi.shape[0]), self.n_joint_actions))
            grown[: len(self.index)] = self.phi[: len(self.index)]  # double the capacity
            self.phi = grown

    def touch_list(self, rules: list[int], rows: list[int]) -> np.ndarray:
        """touch() for rules given as a list; returns the rows as an array, new rows numbered as touch() does.

        Preconditions (the learner's pending transition meets both): the rules are distinct (distinct set
        combinations) and rows = row_list(rules) was taken after the last change of the index.
        """
        new = [rule for rule, row in zip(rules, rows, strict=True) if row < 0]
        if not new:
            return np.array(rows, dtype=np.int64)
        idx = self.index
        need = len(idx) + len(new)
        self._reserve(need)
        idx.update(zip(new, range(len(idx), need), strict=True))  # new rows in rule order, as touch() numbers them
        if len(new) == len(rules):
            return np.arange(need - len(new), need)
        return np.array(list(map(idx.__getitem__, rules)), dtype=np.int64)

    def q_rows(self, rows: np.ndarray, w: np.ndarray, complete: bool | None = None) -> np.ndarray:
        """Eq. 2 from rows already looked up (-1 = untouched rule, phi = 0) and w = O / sum O.

        complete: whether every row is >= 0, when the caller already knows.
        """
        if complete if complete is not None else rows.min() >= 0:
            return w @ self.phi.take(rows, axis=0)  # Eq. 2 (take = phi[rows], ~3x cheaper)
        known = rows >= 0
        return w[known] @ self.phi[rows[known]]  # Eq. 2

    def q_list(self, rows: list[int], w: np.ndarray) -> np.ndarray:
        """q_rows() for rows given as a list (the learner's path): skips the empty sum when no rule is known."""
        unknown = rows.count(-1)
        if unknown == len(rows):
            return np.zeros(self.n_joint_actions)  # what the empty product w[known] @ phi[rows[known]] gives
        return self.q_rows(np.array(rows, dtype=np.int64), w, complete=unknown == 0)

    def q_values(self, rules: np.ndarray, O: np.ndarray) -> np.ndarray:  # noqa: E741
        """Q(s, .) over joint actions = sum_i O^i phi^i / sum_i O^i (Eq. 2); untouched rules count as 0."""
        total = O.sum()
        if total <= 0.0:
            return np.zeros(self.n_joint_actions)
        return self.q_rows(self.lookup(rules), O / total)

    def update(self, rules: np.ndarray, O: np.ndarray, action: int, delta: float) -> None:  # noqa: E741
        """phi^i[a] += delta * O^i / sum_i O^i (Eq. 6), delta from Eq. 5."""
        total = O.sum()
        if total <= 0.0:
            return
        self.update_rows(self.touch(rules), O / total, action, delta)

    def update_rows(self, rows: np.ndarray, w: np.ndarray, action: int, delta: float) -> None:
        """Eq. 6 on rows returned by touch(), w = O / sum O = dQ(s, a) / dphi^i."""
        # Fired rules are distinct (distinct set combinations), so fancy-index += is exact.
        column = self.phi[:, action]  # a view; 1-d fancy indexing is cheaper than phi[rows, action]
        column[rows] += delta * w  # Eq. 6

    def td_delta(self, q_sa: float, reward: float, bootstrap: float, lr: float, gamma: float) -> float:
        """delta = lambda (r + gamma * bootstrap - Q(s, a)) (Eq. 5)."""
        return lr * (reward + gamma * bootstrap - q_sa)

    def export(self) -> tuple[np.ndarray, np.ndarray]:
        """(keys int64[rows], phi float64[rows, n_joint_actions]) in row order, copies."""
        keys = np.fromiter(self.index.keys(), dtype=np.int64, count=len(self.index))
        return keys, self.phi[: len(self.index)].copy()

    def load(self, keys: np.ndarray, phi: np.ndarray) -> None:
        keys = np.asarray(keys)
        phi = np.asarray(phi)
        if keys.ndim != 1 or not np.issubdtype(keys.dtype, np.integer):
            raise ValueError(f"phi_keys must be a 1-d integer array, got {keys.dtype} shape {keys.shape}")
        if phi.ndim != 2 or phi.shape != (len(keys), self.n_joint_actions):
            raise ValueError(f"phi must have shape ({len(keys)}, {self.n_joint_actions}), got {phi.shape}")
        if not np.issubdtype(phi.dtype, np.floating):
            raise ValueError(f"phi must be a float array, got {phi.dtype}")
        if len(np.unique(keys)) != len(keys):
            raise ValueError("phi_keys contains duplicates")
        self.index = {int(k): n for n, k in enumerate(keys.tolist())}
        self.phi = np.zeros((max(len(keys) * 2, 1024), self.n_joint_actions))
        self.phi[: len(keys)] = phi
