"""One agent's brain: fuzzy Q-learning (Algorithm 1) with joint action selection (Algorithm 2)."""

from __future__ import annotations

import fcntl
import hashlib
import os
import tempfile
from collections.abc import Collection, Iterator, Sequence
from contextlib import contextmanager, nullcontext
from pathlib import Path

import numpy as np

from . import jasm, kernels
from .fuzzy import FuzzyPartition
from .plasticity import MotorDirection
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
        nv, n, k = self.n_visible, self.n_actions, self.fuzzy.n_fired
        # Eqs. 7-9 in one array (each argument of a compiled call costs time): the fictitious-play counts
        # C^i(alpha_k^j) (Eq. 7, started at count_prior so P is defined), then P (Eq. 7), E (Eq. 9) and
        # z = (E - max E) / T (Eq. 8's exponent) that the last a(t) was chosen from.
        sel = self._selection = np.zeros((2 * nv + 2, n))
        self.counts, self._P, self._E, self._z = sel[:nv], sel[nv : 2 * nv], sel[2 * nv], sel[2 * nv + 1]
        self.counts[:] = settings.count_prior
        self._P[:] = jasm.probabilities(self.counts)
        # s(t) and s(t-1): the rules each fires (fired[i, 0]), their phi rows (fired[i, 1]; -1: never updated) and
        # w[i] = O / sum O. Slot _latest holds the last state decided on; decide() writes s(t) into the other.
        self._fired = np.zeros((2, 2, k), dtype=np.int64)
        self._fired[:, 1] = -1
        self._w = np.zeros((2, k))
        self._rules_and_O = [(self._fired[i, 0], self._w[i]) for i in (0, 1)]  # what activate() fills, as views
        self._latest = 0
        # The pending transition, s(t-1) and its joint action: -1 until observe() completes it, None when there
        # is none to learn from.
        self._pending: int | None = None
        self._own = 0  # a(t) of the pending transition
        self._counting = True  # fictitious play counts in this epoch (count_freeze)
        self.epoch = 0
        self.lr = float(settings.lr)
        self.epsilon = settings.epsilon  # epsilon(epoch) = epsilon (1 - epsilon_decay)^epoch
        self.t = 0
        # [learner] plasticity = "direction": which way its motor turns, from its own encoder (plasticity.py)
        self.motor = MotorDirection() if settings.plasticity == "direction" else None
        self._load_compiled()

    def _load_compiled(self) -> None:
        """numba loads the compiled step from its cache on first use, or compiles it (seconds; ~7 on a busy 2-core
        machine, when the cache is cold): here, when the learner is made, rather than within the first step's
        deadline. decide()'s kernels run once on this learner's own arrays with nothing to learn, which fills only
        what the first decide() writes again (P, E and z with the values they hold already), then the kernels of
        tied memberships and of a growing phi. The first time in a process, agents starting together take turns,
        so that one compiles and the others load what it wrote: four agents compiling at once on 2 busy cores took
        42 s each, close to the supervisor's 60 s wait for them (one at a time: 12 s, then loads, 18 s in all)."""
        fz, q, now = self.fuzzy, self.q, 1 - self._latest
        with nullcontext() if kernels.decide.signatures else _taking_turns(kernels.__file__):
            e = fz.exponentials(np.zeros(len(fz.n_sets)))
            kernels.decide(
                e, fz.grid, fz.L_pad, fz.top_k, False, self._fired, self._w, now, -1, False, 0.0, self.lr,
                float(self.settings.gamma), 1.0, q.phi, q.index.table, q.index.entries, q.index.size, self._selection,
            )  # fmt: skip
            fz.fire_tied(e, *self._rules_and_O[now])
            kernels.map_rehash(q.index.table, q.index.entries, len(q.index))

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
        self._reset_plasticity()

    def resync(self, t: int) -> None:
        """The agent missed steps (lost messages, a freeze): the schedule moves to step t, and the pending
        transition is dropped, since r(t-1) rewards a joint action this agent did not take part in."""
        self.t = int(t)
        self._pending = None
        self._reset_plasticity()

    def _reset_plasticity(self) -> None:
        """No change of angle spans a reset or a gap (plasticity.py)."""
        if self.motor is not None:
            self.motor.reset_episode()

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
        self._observe(visible_actions, learn)
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
        st, fz, q = self.settings, self.fuzzy, self.q
        motor = self.motor if learn else None  # a frozen swarm keeps the direction it had
        if motor is not None:
            motor.sees(float(state[0]))
        if self.motor is not None and avoid:  # the moves a wall refused, as sent: their meaning
            avoid = {self.motor.command(a) for a in avoid}
        now = 1 - self._latest  # the slot s(t) is written into
        e = fz.exponentials(state)  # Eq. 3's e^(-sigma (x - b)) for s(t)
        T = jasm.temperature(self.t, st.T_max, st.s)
        td = learn and self.lr > 0.0 and reward is not None and self._pending is not None and self._pending >= 0
        activated = False
        # The rules s(t) fires and their O (Eqs. 3-4), w = O / sum O and Q(s(t), .) (Eq. 2); (a) with td, the TD
        # update of s(t-1) and its joint action with s(t) as s' (Eqs. 5-6); (b) P (Eq. 7), E (Eq. 9) and z.
        while status := kernels.decide(
            e, fz.grid, fz.L_pad, fz.top_k, activated, self._fired, self._w, now,
            self._pending if td else -1, td, float(reward) if td else 0.0, self.lr, float(st.gamma), T,
            q.phi, q.index.table, q.index.entries, q.index.size, self._selection,
        ):  # fmt: skip
            if status == kernels.TIED:
                fz.fire_tied(e, *self._rules_and_O[now])
            else:
                q.reserve(status)  # phi rows for the rules of s(t-1) never updated
            activated = True

        # (b) JASM: the Boltzmann policy pi (Eq. 8; numpy's exp, kernels.py says why), epsilon-decreasing choice.
        p_explore = jasm.explore_probability(T, st.T_max, self.epsilon)
        mask = {a for a in avoid if 0 <= a < self.n_actions} if avoid else ()
        if mask and len(mask) < self.n_actions:
            # actions known to be futile now (a wall refused them): neither chosen nor sampled
            pi = [0.0 if a in mask else p for a, p in enumerate(jasm.policy(self._z))]
            if sum(pi) <= 0.0:  # the rest underflowed: choose among them evenly
                pi = [0.0 if a in mask else 1.0 for a in range(self.n_actions)]
            a = jasm.select_action(jasm.normalise(pi), p_explore, self.rng, explore)
        else:
            a = jasm.select_from_exponent(self._z, p_explore, self.rng, explore)  # pi only if the choice needs it

        # (d) remember s(t) for the next update; observe() adds the joint action.
        self._latest = now
        self._pending = -1
        self._own = a
        self.t += 1
        if self.motor is not None:  # Q and the pending transition keep the move meant; the motor gets the command
            self.motor.meant(a)
            return self.motor.command(a)
        return a

    def observe(self, visible_actions: Sequence[int], learn: bool = True) -> None:
        """(c)-(d) of step(): what the visible agents did at the step just decided. With learn=False the
        fictitious-play counts stay as trained: a frozen swarm's beliefs about its neighbours are learned state
        too (counting on during a test made each test goal's outcome depend on the goals and steps before it)."""
        self._check_visible(visible_actions)
        self._observe(visible_actions, learn)

    def _observe(self, visible_actions: Sequence[int], learn: bool) -> None:
        # (c) fictitious play: count what the visible agents did (Eq. 7 next time).
        if learn and self._counting:
            for j, b in enumerate(visible_actions):
                self.counts[j, b] += 1.0
        # (d) the joint action(t) of the pending (s(t), joint action(t)).
        if self._pending is not None:
            self._pending = self.joint_index(self._own, visible_actions)

    # -- introspection / checkpoints ------------------------------------------------------------
    @property
    def E(self) -> np.ndarray:
        """E (Eq. 9) the last a(t) was chosen from (a copy): the recording shows it (AgentTrace)."""
        return self._E.copy()

    @property
    def P(self) -> np.ndarray:
        """P (Eq. 7) the last a(t) was chosen from (a copy), (n_visible, n_actions)."""
        return self._P.copy()

    @property
    def rules_used(self) -> int:
        """Number of phi rows allocated (rules touched by an update)."""
        return self.q.rows

    @property
    def memory_bytes(self) -> int:
        return self.q.memory_bytes + int(self.counts.nbytes)

    def state_dict(self) -> dict[str, np.ndarray]:
        keys, phi = self.q.export()
        plastic = {}
        if self.motor is not None:  # the direction it found is learned too
            plastic["motor_sign"] = np.array(self.motor.sign, dtype=np.int64)
        return {
            **plastic,
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
        self.counts[:] = counts
        self.lr = float(lr)
        self.epoch = int(epoch)
        self.t = 0
        self._pending = None
        # fields of no mechanism this learner has (a checkpoint of another plasticity, or of one since removed)
        # are ignored: the Q-values and counts they sit beside are the same learner's
        if self.motor is not None and "motor_sign" in d:
            sign = int(np.asarray(d["motor_sign"]))
            if sign not in (-1, 1):
                raise ValueError(f"motor_sign must be -1 or 1, got {sign}")
            self.motor.sign = sign


@contextmanager
def _taking_turns(name: str) -> Iterator[None]:
    """Processes that enter together run the body one after the other: an exclusive flock on a file in the
    temporary directory named after `name` and the user (another user's lock file is not ours to open), released
    when the file closes. Where no lock file can be had the body runs at once: the turns save time, nothing more."""
    digest = hashlib.sha1(name.encode()).hexdigest()[:16]
    path = Path(tempfile.gettempdir()) / f"kinswarm-{os.getuid()}-{digest}.lock"
    try:
        f = open(path, "a")  # noqa: SIM115 (closed below, after the body)
    except OSError:
        yield
        return
    with f:
        fcntl.flock(f, fcntl.LOCK_EX)
        yield
