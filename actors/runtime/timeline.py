"""Where a step's messages wait (benchmarks/step_timeline.py): with KINSWARM_TIMELINE set to a directory, every Node
of the process records, for each step message, when it was put (sender), when Zenoh's thread or the local bus handed
it over (receiver), when its handler started and ended, and the handler's thread CPU; Node.close() writes them to
`<dir>/<role>-<ident>-<pid>.tsv`. Unset (always, outside that benchmark) the cost is one global check per message.

Times are time.perf_counter_ns() (CLOCK_MONOTONIC: one clock for every process of the machine), CPU is
time.thread_time_ns() of the thread that ran the handler."""

from __future__ import annotations

import os
import time
from pathlib import Path

DIR = os.environ.get("KINSWARM_TIMELINE") or None
PUT, ARRIVE, HANDLED = "put", "arrive", "handled"


class Timeline:
    """One Node's records: (what, key, time ns[, end ns, cpu ns, where])."""

    def __init__(self, role: str, ident: str) -> None:
        self.name = f"{role}-{ident}-{os.getpid()}"
        self.rows: list[tuple] = []
        self.cpu0 = 0  # the process's CPU (every thread) at its first step message

    def put(self, key: str) -> None:
        if not self.rows:
            self.cpu0 = time.process_time_ns()
        self.rows.append((PUT, key, time.perf_counter_ns()))

    def arrive(self, key: str) -> None:
        if not self.rows:
            self.cpu0 = time.process_time_ns()
        self.rows.append((ARRIVE, key, time.perf_counter_ns()))

    def write(self) -> None:
        if DIR is None or not self.rows:
            return
        self.rows.append(("cpu", "-", self.cpu0, time.process_time_ns()))  # from the first step message to now
        with open(Path(DIR) / f"{self.name}.tsv", "w") as f:
            for row in self.rows:
                f.write("\t".join(map(str, row)) + "\n")
        self.rows = []


def timeline(role: str, ident: str) -> Timeline | None:
    return Timeline(role, ident) if DIR is not None else None
