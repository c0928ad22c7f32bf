"""kinswarm's robots and tasks as standard environments, for any algorithm (docs/env.md):

    from kinswarm.env import parallel_env, gym_env

    par = parallel_env("examples/chain4.toml", steps=200)   # PettingZoo ParallelEnv: one agent per joint
    env = gym_env("examples/chain4.toml", continuous=True)   # Gymnasium: the whole robot, one agent

Both step the robot as the inprocess placement does (core.py): the same task, faults and scenario, the same numbers.
Importing this package registers "kinswarm/Robot-v0" with Gymnasium. It needs the `env` extra (gymnasium,
pettingzoo): `pip install 'kinswarm[env]'`.
"""

from __future__ import annotations

try:
    import gymnasium  # noqa: F401
    import pettingzoo  # noqa: F401
except ImportError as e:  # one line that says what to install, not a traceback into the package
    raise ImportError(f"kinswarm.env needs the env extra ({e.name} is missing): pip install 'kinswarm[env]'") from None

from .faults import as_fault
from .parallel import KinswarmParallelEnv, aec_env, parallel_env
from .robot_env import ENV_ID, RobotEnv, gym_env, register

register()

__all__ = ["ENV_ID", "KinswarmParallelEnv", "RobotEnv", "aec_env", "as_fault", "gym_env", "parallel_env"]
