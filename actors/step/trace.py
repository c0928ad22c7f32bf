"""What an agent saw and chose at each step of an epoch, for the recording (`run.record_agents`): collected as
the steps go (a few list appends), sent once at the epoch's end as one AgentTrace, never on the step's path.
The learner's diagnostics are optional (actors/learning/kinds.py): E and P when it has them, else empty lists."""

from __future__ import annotations

from typing import Any

import numpy as np
from kinswarm.protocol.messages import AgentTrace


class StepTrace:
    def __init__(self, agent: str, names: tuple[str, ...]) -> None:
        self.agent, self.names = agent, list(names)
        self.epoch = -1
        self._clear()

    def _clear(self) -> None:
        self.steps: list[int] = []
        self.states: list[list[float]] = []
        self.actions: list[int] = []
        self.expected: list[list[float]] = []
        self.beliefs: list[list[float]] = []

    def add(self, epoch: int, step: int, state: np.ndarray, action: int, learner: Any) -> None:
        """What the agent saw and chose at a step, and what `learner` chose from: its E (Eq. 9) and P (Eq. 7), if it
        has them."""
        if epoch != self.epoch:  # an epoch left unfinished (a restart) is dropped, not mixed into the next
            self.epoch = epoch
            self._clear()
        self.steps.append(step)
        self.states.append([round(float(x), 5) for x in state])
        self.actions.append(int(action))
        E, P = getattr(learner, "E", None), getattr(learner, "P", None)
        self.expected.append([] if E is None else [round(float(x), 5) for x in E])
        self.beliefs.append([] if P is None else [round(float(x), 4) for x in P.ravel()])

    def take(self) -> AgentTrace:
        """The epoch's trace, and start afresh."""
        m = AgentTrace(
            epoch=self.epoch,
            agent=self.agent,
            names=self.names,
            steps=self.steps,
            states=self.states,
            actions=self.actions,
            expected=self.expected,
            beliefs=self.beliefs,
        )
        self._clear()
        return m
