"""One agent's brain: fuzzy Q-learning (Algorithm 1) with joint action selection (Algorithm 2)."""

from __future__ import annotations

from collections.abc import Collection, Sequence

import numpy as np

from . import jasm
from .fuzzy import FuzzyPartition
from .qlearning import SparseFuzzyQ
from .settings import N_ACTIONS, LearnerSettings

STATE_DICT_VERSION = 1


class Learner:
    """Fuzzy joint-action Q-learner of one agent that sees n_visible agents (its children).

    Call order within one step of the bottom-up pass: visible agents choose first, then this agent
    calls step() with s(t), the reward r(t-1) of the previous joint action and the visible actions at t.
    step() is decide() then observe(); an agent that learns the visible actions at t only later (the
    swarm's up pass carries them a step late) calls decide() at t and observe() before decide() at t+1,
    which computes exactly what step() does.
    """

    def __init__(self, settings: LearnerSettings, n_visible: int, seed: int | Sequence[int]) -> None:
        if not (isinstance(n_visible, (int, np.integer)) and n_visible >= 0):
            raise ValueError(f"n_visible must be an int >= 0, got {n_visible!r}")
        self.settings = settings
        self.n_visible = int(n_visible)
        self.n_actions = N_ACTIONS
        self.n_joint = self.n_actions ** (1 + self.n_visible)
        self.rng = np.random.default_rng(seed)
        self.fuzzy = FuzzyPartition(settings)
        self.q = SparseFuzzyQ(self.n_joint)
        # Fictitious-play counts C^i(alpha_k^j) (Eq. 7), started at count_prior so P is defined.
        self.counts = np.full((self.n_visible, self.n_actions), settings.count_prior)
        self._no_visible = np.zeros((0, self.n_actions))  # P (Eq. 7) when no agent is visible
        self.epoch = 0
        self.lr = settings.lr
        self.epsilon = settings.epsilon  # epsilon(epoch) = epsilon (1 - epsilon_decay)^epoch
        self.t = 0
        # (rules, their phi rows or -1, w = O / sum O, joint action or -1 until observed) of s(t-1), a(t-1);
        # rules and rows as lists
        self._pending: tuple[list[int], list[int], np.ndarray, int] | None = None
        self._own = 0  # a(t) of the pending transition
        self._counting = True  # fictitious play counts in this epoch (count_freeze)
        self.E = np.zeros(self.n_actions)  # E (Eq. 9) and P (Eq. 7) the last a(t) was chosen from
        self.P = self._no_visible

    # -- epochs ---------------------------------------------------------------------------------
    def start_epoch(self, epoch: int, t: int = 0) -> None:
        """New epoch: lr = lr0 (1 - lr_decay)^epoch (times lr_anneal's ramp), the counts counting or not
        (count_freeze), pending dropped (no TD across resets), the schedule T(t) at step t (0, or the step an
        agent restarted mid-epoch rejoins at)."""
        if epoch < 0 or t < 0:
            raise ValueError(f"epoch and t must be >= 0, got {epoch}, {t}")
        self.epoch = int(epoch)
        self.lr = self.settings.lr * (1.0 - self.settings.lr_decay) ** self.epoch
        first, last = self.settings.lr_anneal
        if last > 0:  # linearly down to 0 over [first, last], then no learning
            self.lr *= min(max((last - self.epoch) / (last - first), 0.0), 1.0)
        self.epsilon = self.settings.epsilon * (1.0 - self.settings.epsilon_decay) ** self.epoch
        self._counting = not 0 < self.settings.count_freeze <= self.epoch
        self.t = int(t)
        self._pending = None

    def resync(self, t: int) -> None:
        """The agent missed steps (lost messages, a freeze): the schedule moves to step t, and the pending
        transition is dropped, since r(t-1) rewards a joint action this agent did not take part in."""
        self.t = int(t)
        self._pending = None

    # -- one step -------------------------------------------------------------------------------
    def joint_index(self, own: int, visible_actions: Sequence[int]) -> int:
        """Row-major index of the joint action (own, visible...) in Q(s, .)."""
        idx = own
        for b in visible_actions:
            idx = idx * self.n_actions + int(b)
        return idx

    def step(
        self,
        state: np.ndarray,
        reward: float | None,
        visible_actions: Sequence[int],
        learn: bool = True,
        explore: bool = True,
    ) -> int:
        """Learn from the previous transition, choose this agent's action a(t) (0 dec, 1 keep, 2 inc)."""
        self._check_visible(visible_actions)  # validate before any state changes
        a = self.decide(state, reward, learn=learn, explore=explore)
        self.observe(visible_actions, learn=learn)
        return a

    def _check_visible(self, visible_actions: Sequence[int]) -> None:
        if len(visible_actions) != self.n_visible:
            raise ValueError(f"expected {self.n_visible} visible actions, got {len(visible_actions)}")
        for j, b in enumerate(visible_actions):
            if not 0 <= b < self.n_actions:
                raise ValueError(f"visible action {b!r} of agent {j} is not in [0, {self.n_actions})")

    def decide(
        self,
        state: np.ndarray,
        reward: float | None,
        learn: bool = True,
        explore: bool = True,
        avoid: Collection[int] = (),
    ) -> int:
        """(a)-(b) of step(): the TD update of the previous transition, if observe() completed its joint
        action, then the choice of a(t). The visible actions at t are for observe()."""
        st = self.settings
        rules, O = self.fuzzy.activate(state)  # noqa: E741 -- the paper's O^i
        rules_list = rules.tolist()
        P = jasm.probabilities(self.counts) if self.n_visible else self._no_visible
        w = O / O.sum()  # O^i / sum_i O^i: the weight of rule i in Eq. 2 and its gradient in Eq. 6
        rows = self.q.row_list(rules_list)  # phi rows, -1 for rules never updated
        q_now = self.q.q_list(rows, w)  # Q(s(t), .), Eq. 2

        # (a) TD update of the previous transition with s(t) as s' (Eqs. 5-6).
        if learn and self.lr > 0.0 and reward is not None and self._pending is not None and self._pending[3] >= 0:
            p_rules, p_rows_list, p_w, p_joint = self._pending
            p_rows = self.q.touch_list(p_rules, p_rows_list)  # creates phi = 0 rows: Q(s, a) below is unchanged
            q_sa = float(p_w @ self.q.phi[p_rows, p_joint])  # Q(s(t-1), a(t-1)), Eq. 2
            # Eq. 5's max over what this agent can choose: max_a E(s', a) (Eq. 9), not over joint actions
            boot = float(jasm.expected_values(q_now, P, self.n_actions).max())
            delta = self.q.td_delta(q_sa, float(reward), boot, self.lr, st.gamma)  # Eq. 5
            self.q.update_rows(p_rows, p_w, p_joint, delta)  # Eq. 6
            if -1 in rows:  # s(t) may share rules just created for s(t-1)
                rows = self.q.row_list(rules_list)
            q_now = self.q.q_list(rows, w)

        # (b) JASM: E (Eq. 9), Boltzmann pi (Eq. 8), epsilon-decreasing choice.
        E = jasm.expected_values(q_now, P, self.n_actions)
        T = jasm.temperature(self.t, st.T_max, st.s)
        pi = jasm.boltzmann(E, T)
        mask = [a for a in set(avoid) if 0 <= a < self.n_actions] if avoid else []
        if mask and len(mask) < self.n_actions:
            pi[mask] = 0.0  # actions known to be futile now (a wall refused them): neither chosen nor sampled
            if pi.sum() <= 0.0:  # the rest underflowed: choose among them evenly
                pi = np.ones(self.n_actions)
                pi[mask] = 0.0
            pi /= pi.sum()
        a = jasm.select_action(pi, jasm.explore_probability(T, st.T_max, self.epsilon), self.rng, explore)
        self.E, self.P = E, P  # what a(t) was chosen from: the recording shows them (AgentTrace)

        # (d) remember s(t) for the next update; observe() adds the joint action.
        self._pending = (rules_list, rows, w, -1)
        self._own = a
        self.t += 1
        return a

    def observe(self, visible_actions: Sequence[int], learn: bool = True) -> None:
        """(c)-(d) of step(): what the visible agents did at the step just decided. With learn=False the
        fictitious-play counts stay as trained: a frozen swarm's beliefs about its neighbours are learned state
        too (counting on during a test made each test goal's outcome depend on the goals and steps before it)."""
        self._check_visible(visible_actions)
        # (c) fictitious play: count what the visible agents did (Eq. 7 next time).
        if learn and self._counting:
            for j, b in enumerate(visible_actions):
                self.counts[j, b] += 1.0
        # (d) the joint action(t) of the pending (s(t), joint action(t)).
        if self._pending is not None:
            p_rules, p_rows, p_w, _ = self._pending
            self._pending = (p_rules, p_rows, p_w, self.joint_index(self._own, visible_actions))

    # -- introspection / checkpoints ------------------------------------------------------------
    @property
    def rules_used(self) -> int:
        """Number of phi rows allocated (rules touched by an update)."""
        return self.q.rows

    @property
    def memory_bytes(self) -> int:
        return self.q.memory_bytes + int(self.counts.nbytes)

    def state_dict(self) -> dict[str, np.ndarray]:
        keys, phi = self.q.export()
        return {
            "version": np.array(STATE_DICT_VERSION, dtype=np.int64),
            "phi_keys": keys,
            "phi": phi,
            "counts": self.counts.copy(),
            "lr": np.array(self.lr, dtype=np.float64),
            "epoch": np.array(self.epoch, dtype=np.int64),
        }

    def load_state_dict(self, d: dict[str, np.ndarray]) -> None:
        for name in ("phi_keys", "phi", "counts", "lr", "epoch"):
            if name not in d:
                raise ValueError(f"state dict is missing field {name!r}")
        counts = np.asarray(d["counts"])
        if counts.shape != self.counts.shape or not np.issubdtype(counts.dtype, np.floating):
            raise ValueError(f"counts must be float with shape {self.counts.shape}, got {counts.dtype} {counts.shape}")
        if np.any(counts <= 0):
            raise ValueError("counts must be > 0 (Eq. 7 divides by their sum)")
        lr = np.asarray(d["lr"])
        if lr.shape != () or not np.issubdtype(lr.dtype, np.floating) or not 0.0 <= float(lr) <= 1.0:
            raise ValueError(f"lr must be a float scalar in [0, 1] (0: annealed to the end), got {lr!r}")
        epoch = np.asarray(d["epoch"])
        if epoch.shape != () or not np.issubdtype(epoch.dtype, np.integer) or int(epoch) < 0:
            raise ValueError(f"epoch must be a non-negative integer scalar, got {epoch!r}")
        keys = np.asarray(d["phi_keys"])
        if keys.size and (keys.min() < 0 or keys.max() >= self.fuzzy.n_rules):
            raise ValueError(f"phi_keys must lie in [0, {self.fuzzy.n_rules})")
        self.q.load(keys, np.asarray(d["phi"]))  # validates phi_keys / phi shapes and dtypes
        self.counts = counts.astype(np.float64, copy=True)
        self.lr = float(lr)
        self.epoch = int(epoch)
        self.t = 0
        self._pending = None
