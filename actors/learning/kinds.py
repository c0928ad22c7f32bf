"""What a learner kind does for its agent: the JointLearner protocol, which every kind a run may choose meets (the
registry of kinds, with what each takes: actors/policies/registry.py). The paper's kinds are of this package
(learner.py: fuzzy, independent.py, tabular.py); a kind that needs more than numpy lives outside it (actors/policies/).
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from typing import Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class JointLearner(Protocol):
    """One agent's learner, as the agent calls it in a step (actors/agent/actor.py).

    decide() gets s(t), the reward r(t-1) of the previous joint action and the moves to leave out; it learns from the
    previous transition (when learn) and returns a(t) in range(n_actions) (0 decrease, 1 keep, 2 increase). observe()
    gets the visible children's actions at the step just decided, which arrive a step late on the swarm's up pass; a
    learner with no model of its children ignores them. start_epoch() and resync() drop the pending transition (no
    TD update across a reset or a gap). state_dict() / load_state_dict(): the learned state as named numpy arrays,
    what a checkpoint holds. Diagnostics are optional: a learner that has `E` (expected values, Eq. 9) and `P` (the
    beliefs about its children, Eq. 7) has them recorded (actors/step/trace.py)."""

    n_actions: int

    def decide(
        self,
        state: np.ndarray,
        reward: float | None,
        learn: bool = True,
        explore: bool = True,
        avoid: Collection[int] = (),
    ) -> int: ...

    def observe(self, visible_actions: Sequence[int], learn: bool = True) -> None: ...

    def start_epoch(self, epoch: int, t: int = 0) -> None: ...

    def resync(self, t: int) -> None: ...

    def state_dict(self) -> dict[str, np.ndarray]: ...

    def load_state_dict(self, d: dict[str, np.ndarray]) -> None: ...
