"""Plasticity where the world changed: `[learner] plasticity = "surprise"`.

A trained swarm's Q-values are large and settled; after its body changes (a motor wired backwards, an encoder that
reads wrong) they take many updates at the trained learning rate to turn round, and nothing tells the agent that it
should learn faster now. This gate gives it that signal from its own experience only: the TD error of each update,
delta = r(t-1) + gamma max_a E(s(t), a) - E(s(t-1), a(t-1)) (E of Eq. 9: what its Q expected of the action it took),
against the usual size of its TD errors. The usual size is a slow running mean of |delta| (over ~1000 updates, kept
in the checkpoint, so a swarm started `--from` a trained run knows what is usual for it); the recent size a fast one
(~20 updates). While the recent size stays above SURPRISE times the usual, the agent is surprised: its learning rate
is multiplied by BOOST (capped at 1), and after the surprise ends the boost fades back to 1 over ~SETTLE updates.

It reads nothing but the reward and its own Q: not the fault, the scenario or any event (tests/test_plasticity.py).
Its numbers, and the ideas measured and not kept: docs/science.md, "Plasticity".
"""

from __future__ import annotations

import math

#: the recent |delta| against the usual |delta| above which the agent is surprised
SURPRISE = 2.5
#: learning-rate factor while surprised: 16x, the rate that turned a trained swarm round after a reversal
BOOST = 16.0
#: updates over which the boost fades back to 1 once the surprise ends (e-folding)
SETTLE = 100.0
#: running means of |delta|: the usual one over ~1/USUAL updates, the recent one over ~1/RECENT
USUAL, RECENT = 1.0 / 1000.0, 1.0 / 20.0
#: updates seen before the usual size counts (a fresh learner has no usual yet, and no gate)
WARMUP = 200


class SurpriseGate:
    """The gate of one learner: feed it each update's TD error (`update`), read the factor on its learning rate
    (`factor`). `usual` and `seen` are its learned state (a checkpoint's); `recent` and `boost` start afresh."""

    def __init__(self) -> None:
        self.usual = 0.0
        self.seen = 0
        self.recent = 0.0
        self.boost = 1.0
        self.surprised = False

    @property
    def factor(self) -> float:
        return self.boost

    def update(self, delta: float) -> None:
        size = abs(delta)
        if not math.isfinite(size):
            return
        if self.seen == 0:
            self.recent = size
        self.recent += RECENT * (size - self.recent)
        self.surprised = self.seen >= WARMUP and self.recent > SURPRISE * self.usual
        if self.surprised:
            self.boost = BOOST
        else:
            self.boost = 1.0 + (self.boost - 1.0) * math.exp(-1.0 / SETTLE)
            # only unsurprised experience sets what is usual: a long surprise does not teach the gate that it is
            rate = max(USUAL, 1.0 / (self.seen + 1))  # a plain mean until the running one takes over
            self.usual += rate * (size - self.usual)
            self.seen += 1

    def reset_episode(self) -> None:
        """A new epoch or a gap: the recent size starts from the usual one (no TD error spans the reset)."""
        self.recent = self.usual

    def state(self) -> tuple[float, int]:
        return self.usual, self.seen

    def load(self, usual: float, seen: int) -> None:
        self.usual, self.seen = float(usual), int(seen)
        self.recent, self.boost, self.surprised = self.usual, 1.0, False


#: how fast the agreement between the moves an agent means and the moves its encoder sees follows the latest ones
AGREE_RATE = 1.0 / 20.0
#: the agreement below which the agent concludes that its motor turns the other way
DISAGREE = -0.5


class MotorDirection:
    """`[learner] plasticity = "direction"`: which way the agent's own motor turns, as its own encoder shows it.

    A learner means its actions as moves of its joint (0 decrease, 1 keep, 2 increase): its Q-values hold what each
    move is worth. Each step it compares the move it meant at the step before with the change of its own joint
    angle it reads now (q, the first variable of the planar state): `agree` is the running mean of
    sign(change) x the meant direction over the steps it moved and the joint did (a joint held at a limit or
    locked says nothing). When `agree` falls below DISAGREE, its motor turns the other way from what it learned on:
    it sends the opposite command from then on, so that its learned values hold again, and starts agreeing anew.
    It reads its own command and its own encoder: nothing a robot's joint does not know of itself."""

    def __init__(self) -> None:
        self.sign = 1  # -1: commands are sent reversed
        self.agree = 1.0
        self._q: float | None = None
        self._meant = 0  # the direction meant by the last move: -1, 0, +1

    def command(self, meant: int) -> int:
        """The action to send for the move `meant` (an involution: also maps a sent action back to its meaning)."""
        return meant if self.sign > 0 else 2 - meant

    def sees(self, q: float) -> None:
        """The joint angle read at this step: the effect of the move meant at the step before."""
        if self._q is not None and self._meant != 0:
            dq = (q - self._q + math.pi) % (2.0 * math.pi) - math.pi
            if abs(dq) > 1e-9:
                self.agree += AGREE_RATE * ((1.0 if dq * self._meant > 0 else -1.0) - self.agree)
                if self.agree < DISAGREE:
                    self.sign, self.agree = -self.sign, -self.agree  # what disagreed agrees in the new frame
        self._q = q

    def meant(self, action: int) -> None:
        self._meant = action - 1

    def reset_episode(self) -> None:
        """The pose was reset (or steps were missed): no change of angle spans it."""
        self._q, self._meant = None, 0
