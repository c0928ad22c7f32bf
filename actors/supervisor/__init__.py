"""The supervisor, by concern: core (the run, its mailbox, the actors' liveliness), epochs (the epoch loop and the
checkpoints), placements (where actors live, their ends as events), restarts (the policy), faults (routing), hosts
(heartbeats, partitions, Setup), stalls (a lockstep that stops making progress), recorder (events and metrics as they
happen), result (what a run returns, what ends it early). The third placement, the run as a plain loop with no
supervisor at all, is actors/run/inprocess.py; it records through the same recorder and returns the same result."""

from .core import Supervisor, actors_of
from .placements import Placement, ProcessPlacement, SinglePlacement
from .result import RunResult, SwarmError

__all__ = ["Placement", "ProcessPlacement", "RunResult", "SinglePlacement", "Supervisor", "SwarmError", "actors_of"]
