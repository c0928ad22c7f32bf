"""A Node's link faults (drop, delay, duplicate, corrupt): applied to the step messages it sends and receives, on
its loop, with a seeded generator so that a faulted run is reproducible. Node's state for them (`_link_faults`,
`fault_rng`, `link_counts`, `on_fault_expired`) is made in Node.__init__."""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import random
from collections.abc import Callable
from dataclasses import dataclass

from kinswarm.protocol.faults import ALL, LINK_FAULTS, check_fault, describe
from kinswarm.protocol.messages import Fault

LINK_COUNTS = ("dropped", "delayed", "duplicated", "corrupted")


@dataclass
class LinkFault:
    """One active link fault of a node: at most one per kind; a new one of the same kind replaces it."""

    kind: str  # drop, delay, duplicate or corrupt
    rate: float  # probability per message (1.0 for delay)
    ms: float  # delay only
    description: str
    expiry: asyncio.TimerHandle | None = None


class LinkFaults:
    """Node's link faults (a mixin: the attributes below are Node's)."""

    ident: str
    role: str
    log: logging.Logger
    _loop: asyncio.AbstractEventLoop
    _link_faults: dict[str, LinkFault]
    fault_rng: random.Random
    link_counts: dict[str, int]
    on_fault_expired: Callable[[str], None] | None

    def apply_fault(self, f: Fault) -> str:
        """Apply a link fault to this node; return what was done in one line, or "" when `f` is not a
        link fault for this node (`all` targets every agent-role node). Call it on the loop."""
        if f.fault not in LINK_FAULTS:
            return ""
        if self.ident not in f.targets and not (ALL in f.targets and self.role == "agent"):
            return ""
        error = check_fault(f)
        if error:  # the supervisor checks before forwarding: this is a bug or a hand-made message
            self.log.warning("ignored link fault %s: %s", f.id, error)
            return ""
        if f.fault == "clear":
            was = sorted(self._link_faults)
            self._clear_link_faults()
            desc = f"clear {self.ident} ({', '.join(was) or 'no link fault'} active)"
        else:
            rate = 1.0 if f.rate is None else f.rate  # duplicate and corrupt default to every message
            shown = dataclasses.replace(f, targets=[self.ident], rate=None if f.fault == "delay" else rate)
            lf = LinkFault(kind=f.fault, rate=rate, ms=f.ms or 0.0, description=describe(shown))
            old = self._link_faults.get(lf.kind)
            if old is not None and old.expiry is not None:
                old.expiry.cancel()
            if f.seconds is not None:
                lf.expiry = self._loop.call_later(f.seconds, self._expire, lf)
            self._link_faults[lf.kind] = lf
            desc = lf.description
        self.log.warning("link fault: %s", desc)
        return desc

    @property
    def link_faults(self) -> list[str]:
        """The active link faults, one description each (for status reports)."""
        return [lf.description for lf in self._link_faults.values()]

    def _expire(self, lf: LinkFault) -> None:
        if self._link_faults.get(lf.kind) is lf:
            del self._link_faults[lf.kind]
            self.log.warning("link fault expired: %s", lf.description)
            if self.on_fault_expired is not None:
                self.on_fault_expired(lf.description)

    def _clear_link_faults(self) -> None:
        for lf in self._link_faults.values():
            if lf.expiry is not None:
                lf.expiry.cancel()
        self._link_faults.clear()

    def _fault(self, payload: bytes) -> list[tuple[float, bytes]]:
        """What the active faults make of one step message: (delay in s, payload) per copy; [] if dropped."""
        faults, rng, counts = self._link_faults, self.fault_rng, self.link_counts
        f = faults.get("drop")
        if f is not None and rng.random() < f.rate:
            counts["dropped"] += 1
            return []
        f = faults.get("corrupt")
        if f is not None and rng.random() < f.rate:
            payload = rng.randbytes(len(payload))  # garbage of the same length: the receiver's MAC check fails
            counts["corrupted"] += 1
        copies = [payload]
        f = faults.get("duplicate")
        if f is not None and rng.random() < f.rate:
            copies.append(payload)
            counts["duplicated"] += 1
        f = faults.get("delay")
        delay = 0.0
        if f is not None and f.ms > 0:
            delay = f.ms / 1000
            counts["delayed"] += len(copies)
        return [(delay, p) for p in copies]
