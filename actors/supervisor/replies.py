"""Waiting on the supervisor's mailbox for what a run awaits (an epoch's end, the agents' checkpoints, the actors'
goodbyes), and asking again for a reply while it does not come.

A reply put while a Zenoh link was down is lost: a pause of this process or of the replier, or a cut, lapses the
links between them. So a wait for a reply holds the request that reply answers (`ask`) and sends it again every
`resend_s` while none comes, when an actor's token comes back and when this process wakes from a stall
(`ask_again`); repliers answer a repeated request again, changing nothing. Every wait handles the mailbox in order
(each item routed by the supervisor) until what it waits for holds, with a deadline that a partition stretches: no
wait polls."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Awaitable, Callable
from typing import Any

from kinswarm.protocol.messages import Stop

from .result import NoMessage

log = logging.getLogger("kinswarm.supervisor")

Recv = Callable[[float | None], Awaitable[tuple[str, bytes]]]


class Replies:
    def __init__(
        self,
        recv: Recv,
        route: Callable[[str, bytes], Any],
        paused_seconds: Callable[[float], float],
        resend_s: float,
        on_stop: Callable[[Stop], None],
    ) -> None:
        """`recv(timeout)`: the next mailbox item (TimeoutError after `timeout` s); `route`: the supervisor's handling
        of an item, returning the message a wait may be for; `paused_seconds(now)`: the time the run has been paused
        by a partition so far (a deadline stretches by it); `on_stop`: a Stop that ends a wait (the leader's: someone
        ran `kinswarm down`) is handed there."""
        self.recv, self.route, self.paused_seconds = recv, route, paused_seconds
        self.resend_s, self.on_stop = resend_s, on_stop
        self.asking: Callable[[], None] | None = None  # the request of the reply awaited now, if one is

    async def until(
        self,
        done: Callable[[Any], bool],
        timeout: float,
        *,
        what: str = "reply",
        stretch: bool = True,
        ask: Callable[[], None] | None = None,
        every: float | None = None,
        stops: bool = True,
        quiet: tuple[type[BaseException], ...] = (),
    ) -> Any:
        """Handle the mailbox until `done(m)` holds for a routed item `m` (None: an item the supervisor consumed, or
        before the first) and return that `m`; NoMessage (naming `what`) after `timeout` s, a partition stopping the
        clock unless `stretch` is False. `ask` is sent again every `every` s (`resend_s` by default) and on
        `ask_again`. With `stops`, a Stop message goes to `on_stop` first; the errors in `quiet` that handling an item
        raises are let pass (a run leaving anyway)."""
        now = time.monotonic()
        deadline, paused0 = now + timeout, self.paused_seconds(now)
        every = self.resend_s if every is None else every
        asking, self.asking = self.asking, ask
        next_ask = now + every
        try:
            if done(None):
                return None
            while True:
                now = time.monotonic()
                remaining = deadline - now + (self.paused_seconds(now) - paused0 if stretch else 0.0)
                if remaining <= 0:
                    raise NoMessage(f"no {what} within {timeout:.0f} s")
                if ask is not None:
                    if now >= next_ask:
                        ask()
                        next_ask = now + every
                    remaining = min(remaining, next_ask - now)
                try:
                    key, payload = await self.recv(None if remaining == math.inf else remaining)
                except TimeoutError:
                    continue
                try:
                    m = self.route(key, payload)
                except quiet:
                    continue
                if stops and isinstance(m, Stop):
                    self.on_stop(m)
                if done(m):
                    return m
        finally:
            self.asking = asking

    async def expect(
        self,
        kind: type,
        match: Callable[[Any], bool],
        timeout: float,
        stretch: bool = True,
        ask: Callable[[], None] | None = None,
    ) -> Any:
        """The first message of `kind` satisfying `match` (`until`'s other terms); a Stop ends the wait unless a Stop
        is what it waits for."""
        return await self.until(
            lambda m: isinstance(m, kind) and match(m),
            timeout,
            what=kind.__name__,
            stretch=stretch,
            ask=ask,
            stops=kind is not Stop,
        )

    def ask_again(self, why: str) -> None:
        """Send the awaited reply's request again now (an actor's token came back, or this process woke)."""
        if self.asking is not None:
            log.info("asking again for the reply awaited: %s", why)
            self.asking()
