"""Learner kinds: what a per-agent learner does for its agent (the JointLearner protocol), and the registry that
`[learner] kind = "..."` chooses from, as `[task] kind` chooses a module of actors/tasks/.

Every kind is built over an agent's observation (observation.py) with the run's [learner] settings
(settings.LearnerSettings), the number of visible children (the paper's neighbourhood, §3.2) and the agent's seed.
Each says which [learner] fields it does not take, so a run file that gives one is refused by name.

Adding a kind: a class in a module of this package that meets JointLearner, and a `LearnerKind` in KINDS naming it
(docs/architecture.md, "Learners").
"""

from __future__ import annotations

from collections.abc import Collection, Sequence
from dataclasses import dataclass
from importlib import import_module
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

if TYPE_CHECKING:
    from .settings import LearnerSettings

#: the kind a run has when its [learner] table names none: the paper's
DEFAULT = "fuzzy"


@runtime_checkable
class JointLearner(Protocol):
    """One agent's learner, as the agent calls it in a step (actors/agent/actor.py).

    decide() gets s(t), the reward r(t-1) of the previous joint action and the moves to leave out; it learns from the
    previous transition (when learn) and returns a(t) in range(n_actions) (0 decrease, 1 keep, 2 increase). observe()
    gets the visible children's actions at the step just decided, which arrive a step late on the swarm's up pass; a
    learner with no model of its children ignores them. start_epoch() and resync() drop the pending transition (no
    TD update across a reset or a gap). state_dict() / load_state_dict(): the learned state as named numpy arrays,
    what a checkpoint holds. Diagnostics are optional: a learner that has `E` (expected values, Eq. 9) and `P` (the
    beliefs about its children, Eq. 7) has them recorded (actors/agent/trace.py)."""

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


@dataclass(frozen=True)
class LearnerKind:
    """A kind of learner: where its class lives (imported when first built: the compiled kernels load numba, which
    the supervisor and the command line do without) and the [learner] fields it does not take, with why."""

    name: str
    summary: str
    module: str  # of this package
    cls: str
    refuses: tuple[tuple[str, str], ...] = ()  # (field, why it does not apply)

    def build(self, settings: LearnerSettings, n_visible: int, seed: int | Sequence[int]) -> JointLearner:
        cls = getattr(import_module(f".{self.module}", __package__), self.cls)
        return cls(settings, n_visible, seed)

    def refused(self, given: Collection[str]) -> str | None:
        """`field: why` for the first field in `given` this kind does not take, else None."""
        for field, why in self.refuses:
            if field in given:
                return f"{field}: the {self.name} learner does not take it ({why})"
        return None


KINDS: dict[str, LearnerKind] = {
    k.name: k
    for k in (
        LearnerKind(
            "fuzzy",
            "the paper's: fuzzy Q-learning over joint actions with the children's modelled by fictitious play (JASM)",
            "learner",
            "Learner",
        ),
        LearnerKind(
            "independent",
            "the same fuzzy Q-learning over its own actions only: no model of the children (no JASM)",
            "independent",
            "IndependentLearner",
            (
                ("count_prior", "it counts no children's actions: Eq. 7 has nothing to count"),
                ("count_freeze", "it counts no children's actions: Eq. 7 has nothing to count"),
            ),
        ),
        LearnerKind(
            "tabular",
            "a plain Q-table over the same grid: the state's nearest cell, no fuzzy interpolation; JASM as the paper's",
            "tabular",
            "TabularLearner",
            (
                ("slope", "a table's cells have no sigmoid edges to shape"),
                ("top_k", "one cell holds each state: no memberships to keep"),
            ),
        ),
    )
}


def kinds() -> tuple[str, ...]:
    """Every learner kind, the default first."""
    return (DEFAULT, *sorted(k for k in KINDS if k != DEFAULT))


def learner_kind(name: object) -> LearnerKind:
    if not isinstance(name, str) or name not in KINDS:
        raise ValueError(f"unknown learner kind {name!r}; expected one of {', '.join(kinds())}")
    return KINDS[name]
