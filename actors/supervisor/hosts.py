"""Several hosts (a deploy plan): every supervisor sends its heartbeat every quarter lease on ctl/host/<host>; a host
unheard for a lease is cut off — the run pauses (the sim, hearing the same silence, holds its steps; the leader's
epoch deadline stops) until it is heard again — and past a grace the run ends saying why. Silence is a timer per
host, re-armed by each heartbeat, not a poll. The leader also serves the resolved run (Setup) to the other hosts."""

from __future__ import annotations

import asyncio
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

from kinswarm.protocol import codec
from kinswarm.protocol.messages import Heartbeat, Setup

if TYPE_CHECKING:
    from .core import Supervisor

SILENT = "__silent__"  # mailbox key: payload b"host", its lease ran out since its last heartbeat
GRACE = "__grace__"  # mailbox key: payload b"host", a cut-off host's grace ran out
HOST_GRACE_S = 120.0  # the leader stops a run missing a host this long; another host, missing the leader


class HostError(RuntimeError):
    pass


class HostWatch:
    def __init__(self, sup: Supervisor) -> None:
        self.sup = sup
        self.lease = sup.plan.lease_ms / 1000
        self.heard: dict[str, float] = {}  # host -> when its heartbeat last came
        self.missing: set[str] = set()  # hosts not heard for a lease: the swarm is paused
        self.paused_s = 0.0  # seconds paused so far (epoch deadlines stretch by it)
        self._paused_at = 0.0
        self._seq = 0
        self._silence: dict[str, asyncio.TimerHandle] = {}
        self._beat: asyncio.TimerHandle | None = None
        self.grace_s = HOST_GRACE_S

    def start(self) -> None:
        """Send ours now and every quarter lease."""
        sup = self.sup
        assert sup.node is not None
        self._seq += 1
        sup.node.send(sup.keys.host(sup.host), Heartbeat(host=sup.host, seq=self._seq, leader=int(sup.lead)))
        self._beat = asyncio.get_running_loop().call_later(self.lease / 4, self.start)

    def stop(self) -> None:
        for t in [self._beat, *self._silence.values()]:
            if t is not None:
                t.cancel()

    def heard_from(self, host: str) -> None:
        now = time.monotonic()
        self.heard[host] = now
        old = self._silence.pop(host, None)
        if old is not None:
            old.cancel()
        self._silence[host] = self.sup.later(self.lease, SILENT, host.encode())
        if host in self.missing:
            self.missing.discard(host)
            if not self.missing:
                self.paused_s += now - self._paused_at
            self.sup.event("rejoin", host, f"host {host} heard again after {now - self._paused_at:.1f} s")

    def on_silent(self, host: str) -> None:
        now = time.monotonic()
        if host in self.missing or now - self.heard.get(host, now) < self.lease - 1e-3:
            return
        if not self.missing:
            self._paused_at = now
        self.missing.add(host)
        self.sup.event("partition", host, f"no heartbeat from host {host} for {now - self.heard[host]:.2f} s: paused")
        self.sup.later(self.grace_s, GRACE, host.encode())

    def on_grace(self, host: str) -> None:
        """A pause, not a hang: past the grace the run ends, saying why."""
        sup, now = self.sup, time.monotonic()
        if host in self.missing and now - self.heard[host] >= self.grace_s - 1e-3:
            if sup.lead or host == sup.plan.leader:
                raise HostError(f"host {host} unheard for {now - self.heard[host]:.0f} s; stopping")

    def paused_seconds(self, now: float) -> float:
        return self.paused_s + (now - self._paused_at if self.missing else 0.0)

    def serve_setup(self) -> Any:
        """The leader answers the other hosts' `kinswarm up`: the resolved run, signed with the plan's digest."""
        cfg, plan, sup = self.sup.cfg, self.sup.plan, self.sup
        scenario = Path(cfg.scenario).read_text() if cfg.scenario else ""
        msg = Setup(plan=plan.name, config=cfg.to_json(), scenario=scenario)
        key = sup.keys.setup(plan.name)
        payload = codec.encode(msg, cfg.run_id, "supervisor/main", plan.digest)

        def on_query(q: Any) -> None:  # zenoh thread
            q.reply(key, payload)

        return sup.session.declare_queryable(key, on_query)
