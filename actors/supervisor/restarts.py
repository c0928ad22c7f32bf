"""The restart policy (docs/faults.md): an agent that ends is restarted from its newest checkpoint after a backoff (0.1,
0.2, 0.4 ... 2 s), at most `max_restarts` times within `window_s` seconds, else the run fails saying so. A
`restart` fault respawns at once, outside the budget."""

from __future__ import annotations

import collections
from dataclasses import dataclass, field


class RestartBudgetSpent(RuntimeError):
    pass


@dataclass
class _Agent:
    times: collections.deque[float] = field(default_factory=collections.deque)  # restarts within the window
    total: int = 0
    requested: bool = False  # the exit was a `restart` fault


class RestartPolicy:
    def __init__(self, agents: list[str], max_restarts: int, window_s: float) -> None:
        self.max_restarts, self.window_s = max_restarts, window_s
        self.agents = {a: _Agent() for a in agents}

    def request(self, agent: str) -> None:
        """The coming exit of `agent` is a `restart` fault's."""
        self.agents[agent].requested = True

    def on_exit(self, agent: str, now: float) -> float:
        """`agent` ended at `now`: the delay before it is respawned, or RestartBudgetSpent."""
        r = self.agents[agent]
        r.total += 1
        if r.requested:
            r.requested = False
            return 0.0
        while r.times and r.times[0] < now - self.window_s:
            r.times.popleft()
        if len(r.times) >= self.max_restarts:
            raise RestartBudgetSpent(
                f"agent {agent} exited {len(r.times) + 1} times within {self.window_s:g} s "
                f"(restart policy: at most {self.max_restarts}); giving up"
            )
        backoff = min(2.0, 0.1 * 2 ** len(r.times))  # 0.1, 0.2, 0.4 ... 2 s
        r.times.append(now)
        return backoff

    def total(self, agent: str) -> int:
        return self.agents[agent].total if agent in self.agents else 0

    @property
    def totals(self) -> dict[str, int]:
        return {a: r.total for a, r in self.agents.items()}
