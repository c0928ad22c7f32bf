"""The learning core: fuzzy Q-learning with joint action selection (paper §4), in numpy, its per-step arithmetic
compiled with numba (kernels.py); what an agent observes (observation.py); the learner kinds a run chooses from and
the protocol they meet (kinds.py; the registry a run chooses them from: actors/policies/registry.py).

The parts that run compiled code (FuzzyPartition, SparseFuzzyQ and the learners) are imported when first asked for,
so that a process that only reads settings or states (the supervisor, the command line) does not load numba
(~0.15 s)."""

from importlib import import_module

from .jasm import boltzmann, expected_values, explore_probability, probabilities, select_action, temperature
from .kinds import JointLearner
from .observation import Observation
from .settings import STATE_NAMES, LearnerSettings, StateVariable
from .state import agent_state, goal_along_motion, joint_frame, link_end

_COMPILED = {
    "FuzzyPartition": "fuzzy",
    "memberships_1d": "fuzzy",
    "SparseFuzzyQ": "qlearning",
    "Learner": "learner",
    "IndependentLearner": "independent",
    "TabularLearner": "tabular",
}


def __getattr__(name: str) -> object:
    if name in _COMPILED:
        return getattr(import_module(f".{_COMPILED[name]}", __name__), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


__all__ = [
    "STATE_NAMES",
    "FuzzyPartition",
    "IndependentLearner",
    "JointLearner",
    "Learner",
    "LearnerSettings",
    "Observation",
    "SparseFuzzyQ",
    "StateVariable",
    "TabularLearner",
    "agent_state",
    "boltzmann",
    "expected_values",
    "explore_probability",
    "goal_along_motion",
    "joint_frame",
    "link_end",
    "memberships_1d",
    "probabilities",
    "select_action",
    "temperature",
]
