"""Pure-numpy learning core: fuzzy Q-learning with joint action selection (paper §4)."""

from .fuzzy import FuzzyPartition, memberships_1d
from .jasm import boltzmann, expected_values, explore_probability, probabilities, select_action, temperature
from .learner import Learner
from .qlearning import SparseFuzzyQ
from .reward import REWARD_MODES, reach_reward
from .settings import STATE_NAMES, LearnerSettings
from .state import agent_state, joint_frame, link_end, moves_to_goal

__all__ = [
    "REWARD_MODES",
    "STATE_NAMES",
    "FuzzyPartition",
    "Learner",
    "LearnerSettings",
    "SparseFuzzyQ",
    "agent_state",
    "boltzmann",
    "expected_values",
    "explore_probability",
    "joint_frame",
    "link_end",
    "memberships_1d",
    "moves_to_goal",
    "probabilities",
    "reach_reward",
    "select_action",
    "temperature",
]
