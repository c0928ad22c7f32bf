"""Sparse fuzzy Q-function (paper §4.1, Eqs. 2, 5, 6).

phi^i is a vector over joint actions for rule i. Rows are created on first update, so memory grows with
the rules the agent actually visits, never with the full grid.
"""

from __future__ import annotations

from collections.abc import Iterator, MutableMapping

import numpy as np

from . import kernels


class RuleIndex(MutableMapping[int, int]):
    """rule index -> phi row with a dict's semantics (insertion order too), in arrays that the compiled learner reads
    and extends (kernels.map_get, map_set). Entries are never removed."""

    def __init__(self, capacity: int = 1024) -> None:
        capacity = max(int(capacity), 1)
        self.table = np.full((_slots_for(capacity), 2), -1, dtype=np.int64)  # hash slots: (rule, row) or (-1, -1)
        self.entries = np.empty((2, capacity), dtype=np.int64)  # (rules, rows) in insertion order
        self.size = np.zeros(1, dtype=np.int64)  # entries in use (an array: compiled code counts them)

    @property
    def capacity(self) -> int:
        return self.entries.shape[1]

    @property
    def nbytes(self) -> int:
        return int(self.table.nbytes + self.entries.nbytes)

    def reserve(self, need: int) -> None:
        """Room for need entries (the capacity at least doubles when it grows)."""
        if need <= self.capacity:
            return
        n, capacity = len(self), max(need, 2 * self.capacity)
        entries = np.empty((2, capacity), dtype=np.int64)
        entries[:, :n] = self.entries[:, :n]
        self.entries = entries
        self.table = np.empty((_slots_for(capacity), 2), dtype=np.int64)
        kernels.map_rehash(self.table, self.entries, n)

    def __len__(self) -> int:
        return int(self.size[0])

    def __getitem__(self, rule: int) -> int:
        row = kernels.map_get(self.table, int(rule))
        if row < 0:
            raise KeyError(rule)
        return int(row)

    def __setitem__(self, rule: int, row: int) -> None:
        if rule < 0 or row < 0:
            raise ValueError(f"rules and phi rows are >= 0, got {rule} -> {row}")
        self.reserve(len(self) + 1)
        kernels.map_set(self.table, self.entries, self.size, int(rule), int(row))

    def __delitem__(self, rule: int) -> None:
        raise TypeError("phi rows are never removed")

    def __iter__(self) -> Iterator[int]:
        return iter(self.entries[0, : len(self)].tolist())

    def __contains__(self, rule: object) -> bool:
        return isinstance(rule, (int, np.integer)) and kernels.map_get(self.table, int(rule)) >= 0


def _slots_for(capacity: int) -> int:
    """Hash slots for capacity entries: a power of two, at most half of them in use."""
    return 1 << int(2 * capacity - 1).bit_length()


class SparseFuzzyQ:
    """phi storage: rule index -> row of a growable float64 array (rows, n_joint_actions)."""

    def __init__(self, n_joint_actions: int, capacity: int = 1024) -> None:
        if n_joint_actions < 1:
            raise ValueError(f"n_joint_actions must be >= 1, got {n_joint_actions}")
        self.n_joint_actions = int(n_joint_actions)
        self.index = RuleIndex(capacity)
        self.phi = np.zeros((max(int(capacity), 1), self.n_joint_actions))

    @property
    def rows(self) -> int:
        return len(self.index)

    @property
    def memory_bytes(self) -> int:
        return int(self.phi.nbytes + self.index.nbytes)

    def lookup(self, rules: np.ndarray) -> np.ndarray:
        """Rows of rules in phi, -1 for rules never touched (nothing is created)."""
        rules = np.ascontiguousarray(rules, dtype=np.int64)
        rows = np.empty(len(rules), dtype=np.int64)
        kernels.lookup(self.index.table, rules, rows)
        return rows

    def touch(self, rules: np.ndarray, rows: np.ndarray | None = None) -> np.ndarray:
        """Rows for rules, creating zero rows (phi = 0) for rules seen for the first time, in rule order.

        rows: a previous lookup() of the same rules (rows are never removed, so only -1 entries can be stale; a
        stale entry's rule is given the next row number, as a dict assignment would).
        """
        rows = self.lookup(rules) if rows is None else np.array(rows, dtype=np.int64)
        missing = np.flatnonzero(rows < 0).tolist()
        if missing:
            self.reserve(len(self.index) + len(missing))
            for n in missing:
                rows[n] = self.index[int(rules[n])] = len(self.index)
        return rows

    def reserve(self, need: int) -> None:
        """Room for need phi rows (rows in use are kept; the capacity at least doubles when it grows)."""
        if need > self.phi.shape[0]:
            grown = np.zeros((max(need, 2 * self.phi.shape[0]), self.n_joint_actions))
            grown[: len(self.index)] = self.phi[: len(self.index)]
            self.phi = grown
        self.index.reserve(need)

    def q_rows(self, rows: np.ndarray, w: np.ndarray) -> np.ndarray:
        """Eq. 2 from rows already looked up (-1 = untouched rule, phi = 0) and w = O / sum O."""
        rows = np.ascontiguousarray(rows, dtype=np.int64)
        out, gathered = np.empty(self.n_joint_actions), np.empty((len(rows), self.n_joint_actions))
        kernels.q_values(self.phi, rows, np.ascontiguousarray(w), out, gathered, np.empty(len(rows)))
        return out

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
        """Eq. 6 on rows returned by touch(), w = O / sum O = dQ(s, a) / dphi^i (the fired rules are distinct)."""
        kernels.update(self.phi, np.ascontiguousarray(rows, dtype=np.int64), np.ascontiguousarray(w), action, delta)

    def td_delta(self, q_sa: float, reward: float, bootstrap: float, lr: float, gamma: float) -> float:
        """delta = lambda (r + gamma * bootstrap - Q(s, a)) (Eq. 5)."""
        return lr * (reward + gamma * bootstrap - q_sa)

    def export(self) -> tuple[np.ndarray, np.ndarray]:
        """(keys int64[rows], phi float64[rows, n_joint_actions]) in row order, copies."""
        n = len(self.index)
        return self.index.entries[0, :n].copy(), self.phi[:n].copy()

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
        n, capacity = len(keys), max(len(keys) * 2, 1024)
        index = RuleIndex(capacity)
        index.entries[0, :n], index.entries[1, :n], index.size[0] = keys, np.arange(n), n
        kernels.map_rehash(index.table, index.entries, n)
        self.index = index
        self.phi = np.zeros((capacity, self.n_joint_actions))
        self.phi[:n] = phi
