"""Host silence, as the simulator sees it: with several hosts (a deploy plan) it hears every host's heartbeat, and
while one is silent for a lease the next step is held back, not run on stale or missing data. The silence itself is
the signal: during a cut even local messages stalled for ~9 s (measured). The sim holds and publishes the steps;
this part says when to, and announces the pause and the resume."""

from __future__ import annotations

import time
from collections.abc import Callable, Iterable

RECHECK_S = 0.1  # while held, how often the silence is looked at again


class HostSilence:
    def __init__(
        self,
        hosts: Iterable[str],
        lease_s: float,
        event: Callable[[str, str, str], None],
        recheck: Callable[[float], None],
    ) -> None:
        """`event(name, target, detail)` announces a pause or a resume; `recheck(delay)` asks for `recheck()` to be
        called on the loop after `delay` seconds."""
        hosts = frozenset(hosts)
        self.hosts = hosts if len(hosts) > 1 else frozenset()  # one host has no one to be cut from
        self.lease = lease_s
        self.heard: dict[str, float] = {}  # host -> when its heartbeat last came
        self.paused = False
        self._event, self._recheck = event, recheck

    def heard_from(self, host: str) -> None:
        if host in self.hosts:
            self.heard[host] = time.monotonic()

    def silent(self) -> list[str]:
        """The hosts unheard for a lease (a host never heard counts as heard now: it is still starting)."""
        now = time.monotonic()
        return sorted(h for h in self.hosts if now - self.heard.get(h, now) > self.lease)

    def holding(self) -> bool:
        """Whether steps are held (checked when a step is due): a pause begins when a host is found silent."""
        if not self.hosts:
            return False
        silent = self.silent()
        if silent and not self.paused:
            self.paused = True
            self._event("pause", "sim", f"no heartbeat from {', '.join(silent)} for a lease; steps held")
            self._recheck(RECHECK_S)
        return self.paused

    def recheck(self) -> bool:
        """Looked at again while held: True once every host is heard again (the pause is over)."""
        if self.silent():
            self._recheck(RECHECK_S)
            return False
        self.paused = False
        self._event("resume", "sim", "every host heard again")
        return True
