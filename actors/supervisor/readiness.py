"""A run's start: until every actor of this host is alive (wired, matched, its liveliness token up), and, on the
leader, until the other hosts' actors are too. Each wait handles the supervisor's mailbox in order, an actor's token
coming up being one of its items; none polls. A start fails only when it stalls, never after a fixed time."""

from __future__ import annotations

import asyncio
import logging
import os
import time
from collections.abc import Awaitable, Callable, Set
from pathlib import Path

from .placements import ActorId
from .result import SwarmError

log = logging.getLogger("kinswarm.supervisor")


class Readiness:
    # A start fails only when it stalls: for START_STALL_S no actor became ready and the processes still starting
    # used less than START_BUSY_CPU_S of CPU between them. N fresh interpreters share the machine's cores (and take
    # turns at loading the learner's compiled kernels), and an actor is ready only once its neighbours listen, so in
    # a large swarm the first become ready after minutes, then the rest in a burst. A fixed 60 s failed a 16-agent
    # chain at load 9-15; 60 s + 2 s an actor still failed a 100-agent chain at load ~130 whose agents were busy.
    # Agents queued on the kernels' lock behind another run's are idle: 60 s of that failed a start at load ~80.
    START_STALL_S = 120.0
    START_BUSY_CPU_S = 1.0

    def __init__(
        self,
        alive: Set[ActorId],
        handle: Callable[[float | None], Awaitable[None]],
        pids: Callable[[], dict[str, int]],
        host_of: Callable[[ActorId], str],
    ) -> None:
        """`alive`: the actors whose token is up (the supervisor's, read here); `handle(timeout)`: handle the next
        mailbox item (TimeoutError after `timeout` s); `pids()`: the actors' processes; `host_of`: an actor's host."""
        self.alive, self.handle, self.pids, self.host_of = alive, handle, pids, host_of

    async def ready(
        self, expected: list[ActorId], stall_s: float, on_start: Callable[[int, int], None] | None = None
    ) -> None:
        """Until every actor of `expected` is alive, telling `on_start` (ready, of) as they come; a SwarmError once
        the start stalls (`stall_s` with no actor become ready and the starting processes idle)."""
        want = set(expected)
        ready = len(want & self.alive)
        if on_start is not None:
            on_start(ready, len(want))
        deadline, cpu = time.monotonic() + stall_s, self._starting_cpu(want)
        while ready < len(want):
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                now_cpu = self._starting_cpu(want)
                if now_cpu is not None and cpu is not None and now_cpu - cpu >= self.START_BUSY_CPU_S:
                    log.info(
                        "starting: %d/%d actors ready, the others busy (%.0f CPU-s)", ready, len(want), now_cpu - cpu
                    )
                    deadline, cpu = time.monotonic() + stall_s, now_cpu
                    continue
                late = [f"{role} {ident}" for role, ident in sorted(want - self.alive)]
                more = f" and {len(late) - 8} more" if len(late) > 8 else ""
                why = f"{ready}/{len(want)} ready; not: {', '.join(late[:8])}{more}"
                raise SwarmError(f"starting: no actor became ready for {stall_s:.0f} s, nor busy ({why})")
            try:
                await self.handle(remaining)
            except TimeoutError:
                continue
            if (now := len(want & self.alive)) > ready:
                ready = now
                deadline, cpu = time.monotonic() + stall_s, self._starting_cpu(want)
                log.info("starting: %d/%d actors ready", ready, len(want))
                if on_start is not None:
                    on_start(ready, len(want))

    async def alive_within(self, expected: list[ActorId], timeout: float, what: str = "") -> None:
        """Until every actor of `expected` is alive (the leader: the other hosts' too), else a SwarmError after
        `timeout` s."""
        if what and not set(expected) <= self.alive:
            hosts = sorted({self.host_of(a) for a in set(expected) - self.alive})
            log.warning("waiting for %s (on %s): start `kinswarm up PLAN --host NAME` there", what, ", ".join(hosts))
        try:
            async with asyncio.timeout(timeout):
                while not set(expected) <= self.alive:
                    await self.handle(None)
        except TimeoutError:
            raise SwarmError(f"not alive after {timeout:.0f} s: {sorted(set(expected) - self.alive)}") from None

    def _starting_cpu(self, want: set[ActorId]) -> float | None:
        """CPU seconds used so far by the processes of the actors of `want` not yet alive (Linux: /proc/PID/stat);
        None where actors share this process (the single placement) or /proc cannot tell."""
        pids = self.pids()
        mine = os.getpid()
        own = [pids[ident] for role, ident in want - self.alive if pids.get(ident, mine) != mine]
        if not own:
            return None
        total = 0
        for pid in own:
            try:  # utime and stime: fields 14 and 15, counted after the command's closing parenthesis
                fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                total += int(fields[11]) + int(fields[12])
            except (OSError, IndexError, ValueError):  # gone (its end is an event of its own), or no /proc
                continue
        return total / os.sysconf("SC_CLK_TCK")
