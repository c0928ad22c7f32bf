"""Pure-numpy learning core: fuzzy Q-learning with joint action selection (paper §4)."""

from .fuzzy import FuzzyPartition, memberships_1d
from .jasm import boltzmann, expected_values, explore_probability, probabilities, select_action, temperature
from .learner import Learner
from .qlearning import SparseFuzzyQ
from .settings import STATE_NAMES, LearnerSettings, StateVariable
from .state import agent_state, goal_along_motion, joint_frame, link_end

__all__ = [
    "STATE_NAMES",
    "FuzzyPartition",
    "Learner",
    "LearnerSettings",
    "SparseFuzzyQ",
    "StateVariable",
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
