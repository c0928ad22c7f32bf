"""The learner kinds a run chooses from (`[learner] kind = "..."`), as `[task] kind` chooses a module of actors/tasks/:
the registry, and what each kind takes.

Every kind is built over an agent's observation (actors/learning/observation.py) with the run's [learner] settings
(settings.LearnerSettings), the number of visible children (the paper's neighbourhood, §3.2) and the agent's seed, and
meets the JointLearner protocol (actors/learning/kinds.py). Each says which [learner] fields it does not take, so a run
file that gives one is refused by name.

Adding a kind: a class meeting JointLearner and a `LearnerKind` in KINDS naming its module by full path. The paper's
kinds live in actors/learning (numpy and numba only); a kind that needs more (a policy run by onnxruntime) lives in
this package, with the [learner] fields of its own that it `takes`: its module then has
`build(settings, n_visible, seed, *, agent, index, options)` and `check(settings, order, options)`. The registry is
here, above actors/learning, so that naming a kind of this package makes no arrow from learning back to it
(tests/test_cycles.py).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields
from importlib import import_module
from typing import Any

from kinswarm.actors.learning.kinds import JointLearner
from kinswarm.actors.learning.settings import OBSERVATION_FIELDS, LearnerSettings

#: the kind a run has when its [learner] table names none: the paper's
DEFAULT = "fuzzy"
_NO_DEFAULT = object()
_DEFAULTS = {f.name: f.default for f in fields(LearnerSettings)}


@dataclass(frozen=True)
class LearnerKind:
    """A kind of learner: where its class lives (imported when first built: the compiled kernels load numba, which
    the supervisor and the command line do without) and the [learner] fields it does not take, with why."""

    name: str
    summary: str
    module: str  # its full module path (kinswarm.actors.learning.learner, kinswarm.actors.policies.onnx)
    cls: str  # the class built; for a kind that takes fields of its own, its module's builder function
    refuses: tuple[tuple[str, str], ...] = ()  # (field, why it does not apply)
    takes: tuple[str, ...] = ()  # [learner] fields of its own, beyond LearnerSettings (given to build as options)

    def _module(self):  # noqa: ANN202 - a module
        return import_module(self.module)

    def build(
        self,
        settings: LearnerSettings,
        n_visible: int,
        seed: int | Sequence[int],
        *,
        agent: str = "",
        index: int = 0,
        options: Mapping[str, Any] | None = None,
    ) -> JointLearner:
        """`agent`, its `index` in the robot's DOF order and the run's [learner] table (`options`) reach only a kind
        that takes fields of its own: the paper's learners are the same for every agent but their seed."""
        make = getattr(self._module(), self.cls)
        if not self.takes:
            return make(settings, n_visible, seed)
        return make(settings, n_visible, seed, agent=agent, index=index, options=options or {})

    def check(self, settings: Mapping[str, LearnerSettings], order: Sequence[str], options: Mapping[str, Any]) -> None:
        """What a kind with fields of its own opens before a run starts (its files), tried now: ValueError if bad."""
        if self.takes:
            self._module().check(settings, order, options)

    def refused(self, given: Mapping[str, Any]) -> str | None:
        """`field: why` for the first field in `given` this kind does not take, else None. A field given at its
        default asks nothing of the kind (`count_freeze = 0`: never freeze), so a run file that sets it can be run
        with another kind by `--set learner.kind=K --set learner.FIELD=<default>`."""
        for field, why in self.refuses:
            if field in given and given[field] != _DEFAULTS.get(field, _NO_DEFAULT):
                return f"{field}: the {self.name} learner does not take it ({why})"
        for field in given:
            if field in OWN_FIELDS and field not in self.takes:
                return f"{field}: the {self.name} learner does not take it (kind {OWN_FIELDS[field]!r} does)"
        return None


#: the learner's own settings (LearnerSettings beyond the observation's fields): what a policy that learns nothing
#: refuses
_LEARNING_FIELDS = tuple(f.name for f in fields(LearnerSettings) if f.name not in OBSERVATION_FIELDS)

KINDS: dict[str, LearnerKind] = {
    k.name: k
    for k in (
        LearnerKind(
            "fuzzy",
            "the paper's: fuzzy Q-learning over joint actions with the children's modelled by fictitious play (JASM)",
            "kinswarm.actors.learning.learner",
            "Learner",
        ),
        LearnerKind(
            "independent",
            "the same fuzzy Q-learning over its own actions only: no model of the children (no JASM)",
            "kinswarm.actors.learning.independent",
            "IndependentLearner",
            (
                ("count_prior", "it counts no children's actions: Eq. 7 has nothing to count"),
                ("count_freeze", "it counts no children's actions: Eq. 7 has nothing to count"),
            ),
        ),
        LearnerKind(
            "tabular",
            "a plain Q-table over the same grid: the state's nearest cell, no fuzzy interpolation; JASM as the paper's",
            "kinswarm.actors.learning.tabular",
            "TabularLearner",
            (
                ("slope", "a table's cells have no sigmoid edges to shape"),
                ("top_k", "one cell holds each state: no memberships to keep"),
            ),
        ),
        LearnerKind(
            "onnx",
            "a frozen policy read from an ONNX file, run by onnxruntime: trained anywhere, acting as the agents",
            "kinswarm.actors.policies.onnx",
            "build",
            tuple((f, "an ONNX policy is frozen: it has no fuzzy grid and learns nothing") for f in _LEARNING_FIELDS),
            ("policy",),
        ),
    )
}

#: every kind's fields of its own, with the kind that takes it: other kinds refuse them by name
OWN_FIELDS: dict[str, str] = {f: k.name for k in KINDS.values() for f in k.takes}


def kinds() -> tuple[str, ...]:
    """Every learner kind, the default first."""
    return (DEFAULT, *sorted(k for k in KINDS if k != DEFAULT))


def learner_kind(name: object) -> LearnerKind:
    if not isinstance(name, str) or name not in KINDS:
        raise ValueError(f"unknown learner kind {name!r}; expected one of {', '.join(kinds())}")
    return KINDS[name]
