"""The garbage collector and a long-lived actor process.

An actor's process builds its heap once (its learner, the world, numba's and Zenoh's modules: ~100,000 objects that
live as long as it does) and then allocates little that survives a step. Python's collector still walks every
long-lived object in each full collection: measured on a 4-agent chain held in one process
(benchmarks/handler_cost.py), one full collection took ~50 ms of CPU every few hundred steps, a stall of that
length in whichever step handler it fell. `freeze_setup()` collects the setup's garbage once and moves what is left
out of the collector's view (gc.freeze): later collections walk only what the run itself keeps. Objects are freed by
reference counting as before; what the setup built in cycles stays until the process ends, which for an actor
process is what it would anyway. Only for a process that runs one actor until it leaves (actors/process/main.py): a
process that runs many swarms one after another (a test session, the `single` placement inside a notebook) would
keep each one's cycles.
"""

from __future__ import annotations

import gc


def freeze_setup() -> None:
    """Collect the garbage of the setup, then keep what survives out of every later collection (gc.freeze)."""
    gc.collect()
    gc.freeze()
