"""The supervisor, by concern: core (the run, the epoch loop, checkpoints, the mailbox), placements (where actors
live, their ends as events), restarts (the policy), faults (routing), hosts (heartbeats, partitions, Setup), recorder
(events and metrics as they happen)."""

from .core import RunResult, Supervisor, SwarmError, actors_of
from .placements import Placement, ProcessPlacement, SinglePlacement

__all__ = ["Placement", "ProcessPlacement", "RunResult", "SinglePlacement", "Supervisor", "SwarmError", "actors_of"]
