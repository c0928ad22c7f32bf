"""What a run returns, and what ends it early: plain data, for every placement (the supervisor's and the inprocess
loop's)."""

from __future__ import annotations

from dataclasses import dataclass, field

from kinswarm.protocol.messages import EpochDone


class SwarmError(RuntimeError):
    pass


class NoMessage(SwarmError):
    """The awaited message did not come in time."""


class RecordError(SwarmError):
    """A record of the run could not be written (a full disk, a read-only or forbidden directory): the run stops, its
    checkpoints and whole rows kept, to be resumed once the cause is gone."""


def cannot_write(path: object, e: OSError) -> str:
    """One line naming the file and the cause: `cannot write runs/x/metrics.jsonl: No space left on device`."""
    return f"cannot write {e.filename or path}: {e.strerror or e}"


@dataclass
class RunResult:
    epochs: list[EpochDone] = field(default_factory=list)
    interrupted: bool = False
    signal: str = ""  # the signal that interrupted it (SIGINT: Ctrl-C; SIGTERM), when one did
    error: str = ""  # why the run failed (restart budget exhausted, the sim died, ...)
    wall_seconds: float = 0.0
    rejected: int = 0  # messages every actor refused (from their Bye) plus the supervisor's own
    rejected_by: dict[str, int] = field(default_factory=dict)
    restarts: dict[str, int] = field(default_factory=dict)
    # liveliness tokens gone while training, by actor: a kill, a freeze, or a process starved past the lease
    tokens_lost: dict[str, int] = field(default_factory=dict)
