"""The agent actor: one joint (or a compound agent with no joint) running the lockstep step (actor.py),
standing in for lost children (standin.py) and keeping its learned state in checkpoints (memory.py)."""

from .actor import Agent, agent_seed

__all__ = ["Agent", "agent_seed"]
