"""The runtime shell every actor runs in: one Zenoh session factory, an asyncio mailbox, publishers
with BLOCK congestion control, readiness (every publisher matched before the liveliness token goes up),
and clean shutdown.

Zenoh callbacks run on a zenoh-owned thread. They only append `(key, bytes)` to a deque and wake the
event loop once per burst (`call_soon_threadsafe` per message caps a subscriber near 85k msg/s; one
wake-up per burst is an order of magnitude cheaper). Everything else happens on the loop.
"""

from __future__ import annotations

import asyncio
import collections
import json
import logging
import time
from collections.abc import Iterable
from typing import Any, TypeVar

import zenoh
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys

DEFAULT_LISTEN = "tcp/127.0.0.1:7447"
LEASE_MS = 1000
M = TypeVar("M")


def zenoh_config(
    *,
    listen: Iterable[str] = (),
    connect: Iterable[str] = (),
    mode: str = "peer",
    lease_ms: int = LEASE_MS,
    must_connect: bool = False,
) -> zenoh.Config:
    """The one place a Zenoh config is built. Multicast scouting is off: peers find each other only
    through the endpoints given (and gossip among themselves), never across the network by accident."""
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps(mode))
    c.insert_json5("listen/endpoints", json.dumps(list(listen)))
    c.insert_json5("connect/endpoints", json.dumps(list(connect)))
    c.insert_json5("scouting/multicast/enabled", "false")
    c.insert_json5("transport/link/tx/lease", str(lease_ms))
    if must_connect:  # an actor whose supervisor is unreachable fails instead of retrying forever
        c.insert_json5("connect/timeout_ms", "10000")
        c.insert_json5("connect/exit_on_failure", "true")
    return c


def open_session(
    *, listen: Iterable[str] = (), connect: Iterable[str] = (), mode: str = "peer", must_connect: bool = False
) -> zenoh.Session:
    """The one session factory. An actor process listens on a fresh loopback port so the others can
    reach it directly (gossip spreads the locator), and connects to the supervisor's endpoint."""
    return zenoh.open(zenoh_config(listen=listen, connect=connect, mode=mode, must_connect=must_connect))


class Mailbox:
    """Thread-safe inbox: zenoh threads push, the event loop pops; one wake-up per burst."""

    def __init__(self, loop: asyncio.AbstractEventLoop) -> None:
        self._loop = loop
        self._items: collections.deque[tuple[str, bytes]] = collections.deque()
        self._ready = asyncio.Event()

    def push(self, key: str, payload: bytes) -> None:  # zenoh thread
        was_empty = not self._items
        self._items.append((key, payload))
        if was_empty:
            try:
                self._loop.call_soon_threadsafe(self._ready.set)
            except RuntimeError:  # loop closed during shutdown: nobody is listening any more
                pass

    async def get(self) -> tuple[str, bytes]:
        while not self._items:
            self._ready.clear()
            if self._items:  # pushed between the check and the clear
                break
            await self._ready.wait()
        return self._items.popleft()

    def __len__(self) -> int:
        return len(self._items)


class Node:
    """One actor's handle on the wire: mailbox, publishers, subscriptions, liveliness token.

    Several nodes may share one session (the `single` placement); each owns its declarations and
    undeclares them in `close()`."""

    def __init__(self, session: zenoh.Session, keys: Keys, role: str, ident: str, key: bytes) -> None:
        self.session = session
        self.keys = keys
        self.role = role
        self.ident = ident
        self.key = key  # the run's MAC key (codec.py)
        self.log = logging.getLogger(f"kinswarm.{role}.{ident}")
        self.mailbox = Mailbox(asyncio.get_running_loop())
        self._pubs: dict[str, Any] = {}
        self._subs: list[Any] = []
        self._token: Any = None
        self.rejected = 0

    # -- sending ---------------------------------------------------------------------------------
    def publisher(self, key: str) -> Any:
        pub = self._pubs.get(key)
        if pub is None:
            # BLOCK: the default DROP silently loses messages under load; lockstep cannot afford that.
            pub = self.session.declare_publisher(
                key, congestion_control=zenoh.CongestionControl.BLOCK, express=True
            )
            self._pubs[key] = pub
        return pub

    def send(self, key: str, msg: Any) -> None:
        self.publisher(key).put(codec.encode(msg, self.keys.run, self.ident, self.key))

    # -- receiving -------------------------------------------------------------------------------
    def listen(self, key_expr: str) -> None:
        push = self.mailbox.push
        self._subs.append(
            self.session.declare_subscriber(key_expr, lambda s: push(str(s.key_expr), s.payload.to_bytes()))
        )

    async def recv(self) -> tuple[str, bytes]:
        return await self.mailbox.get()

    def decode(self, key: str, payload: bytes, expect: type[M]) -> M | None:
        """Decode or log why not and return None: a bad message never crashes an actor."""
        try:
            return codec.decode(payload, expect, self.keys.run, self.key)
        except codec.DecodeError as e:
            self.rejected += 1
            if self.rejected <= 20 or self.rejected % 1000 == 0:
                self.log.warning(
                    "rejected message on %s from %s: %s (rejected so far: %d)",
                    key,
                    codec.sender(payload),
                    e,
                    self.rejected,
                )
            return None

    # -- readiness -------------------------------------------------------------------------------
    async def wait_matched(self, keys: Iterable[str], timeout: float) -> None:
        """Wait until every given publisher has a matching subscriber: a put before that is lost."""
        pending = [k for k in keys]
        deadline = time.monotonic() + timeout
        while pending:
            pending = [k for k in pending if not self.publisher(k).matching_status.matching]
            if not pending:
                return
            if time.monotonic() > deadline:
                raise TimeoutError(f"{self.role}/{self.ident}: nobody subscribes to {pending}")
            await asyncio.sleep(0.005)

    def declare_alive(self) -> None:
        self._token = self.session.liveliness().declare_token(self.keys.alive(self.role, self.ident))

    def close(self) -> None:
        for d in [self._token, *self._subs, *self._pubs.values()]:
            if d is not None:
                try:
                    d.undeclare()
                except Exception:  # already gone with the session
                    pass
        self._pubs.clear()
        self._subs.clear()
        self._token = None


def setup_logging(level: str = "INFO") -> None:
    logging.basicConfig(
        level=getattr(logging, level.upper(), logging.INFO),
        format="%(asctime)s %(levelname)s %(name)s: %(message)s",
    )
