"""A process that wakes from a stall of its own (SIGSTOPped by a freeze or by hand, or starved past the lease) finds
its Zenoh links lapsed: as its session reconnects every peer's liveliness token goes and comes back, and what was put
towards it meanwhile is lost. That is not its peers leaving. `WakeGuard` tells the two apart: a ticker (a task of its
own, `watch`, or the owner's periodic timer, `expect`/`ticked`) late by half a lease means this process did not run;
a token loss heard within a lease of such a wake is held, and counts only if the token is still gone a lease later.

Used by the agents (a descendant's loss: stand in or not) and the supervisor (a loss recorded, a stall judged, a reply
asked for again). The simulator needs none: an agent's token lost while it stalled costs only that agent's joint
holding for the steps until it is back (it is waited for again from the next step)."""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from typing import TYPE_CHECKING, Any

from kinswarm.protocol.keys import GONE, HELD, UP, parse_token_change, token_change

if TYPE_CHECKING:
    from .node import Node

ALIVE = "__alive__"  # the mailbox key a held loss comes back on: its token's change, HELD (protocol/keys.py)


class WakeGuard:
    def __init__(
        self,
        node: Node,
        lease_s: float,
        clock: Callable[[], float] = time.monotonic,
        later: Callable[[float, bytes], Any] | None = None,
    ) -> None:
        """`later(delay, payload)`: how a held loss's second look is scheduled (the owner's timers: it must come
        through the mailbox under ALIVE); by default a loop timer pushing it into the node's mailbox."""
        self.node, self.lease, self.clock = node, lease_s, clock
        self.tick = lease_s / 4
        self.due = math.inf  # when the ticker should next run (none before watch() or expect())
        self.woke = -math.inf  # when the ticker last found itself late by more than half a lease
        self.slept = 0.0  # how long this process did not run, at that wake
        self.held: set[str] = set()  # the tokens (their keys) that went as this process woke, not back yet
        self._later = later

    async def watch(self) -> None:
        """Tick every quarter lease; a tick late by half a lease means this process did not run meanwhile."""
        while True:
            self.expect(self.tick)
            await asyncio.sleep(self.tick)
            self.ticked()

    def expect(self, delay: float) -> None:
        """The owner's periodic timer is armed to fire `delay` seconds from now."""
        self.due = self.clock() + delay

    def ticked(self) -> bool:
        """The ticker ran: True if it ran late by half a lease (this process just woke)."""
        now = self.clock()
        if now - self.due > self.lease / 2:
            self.woke, self.slept = now, now - self.due
            return True
        return False

    def just_woke(self) -> bool:
        now = self.clock()  # a tick overdue now: the ticker has not run since the wake
        return now - self.due > self.lease / 2 or now - self.woke < self.lease

    def token(self, change: str) -> str | None:
        """The change to act on (a token came, UP, or went, GONE: protocol/keys.py `token_change`), or None while a
        loss is held. HELD: a held loss's lease is up."""
        sign, peer = parse_token_change(change)
        if sign == UP:
            self.held.discard(peer)
            return change
        if sign == HELD:
            if peer not in self.held:
                return None  # it came back
            self.held.discard(peer)
            return token_change(GONE, peer)
        if not self.just_woke():
            return change
        if peer not in self.held:
            self.held.add(peer)
            self.node.log.info("token %s went as this process woke from a stall: a loss if still gone in %.1f s",
                               peer, self.lease)  # fmt: skip
            again = token_change(HELD, peer).encode()
            if self._later is not None:
                self._later(self.lease, again)
            else:
                asyncio.get_running_loop().call_later(self.lease, self.node.mailbox.push_local, ALIVE, again)
        return None
