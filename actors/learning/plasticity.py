"""Plasticity where the world changed: `[learner] plasticity = "direction"`.

A trained swarm's Q-values are large and settled; after its body changes (a motor wired backwards) they take many
updates to turn round, and nothing tells the agent that its body, not its task, changed. The mechanism here gives
it that from its own command and its own encoder only: not the fault, the scenario or any event
(tests/test_plasticity.py). Its numbers, and the ideas measured and not kept: docs/notebook/adapt.md.
"""

from __future__ import annotations

import math

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
