"""Where messages wait for the event loop: a thread-safe mailbox (zenoh threads push, the loop pops, one wake-up per
burst), and the local bus of the Nodes sharing one session (the `single` placement's direct delivery)."""

from __future__ import annotations

import asyncio
import collections
from collections.abc import Callable
from typing import TYPE_CHECKING

import zenoh

if TYPE_CHECKING:
    from .node import Node

Handler = Callable[[str, bytes], None]  # a step handler: (key, payload)


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

    def push_local(self, key: str, payload: bytes) -> None:  # the loop's own thread: no self-pipe write
        was_empty = not self._items
        self._items.append((key, payload))
        if was_empty:
            self._ready.set()

    async def wait(self) -> None:
        """Until an item is in (only the loop pops, so it stays until popped)."""
        while not self._items:
            self._ready.clear()
            if self._items:  # pushed between the check and the clear
                return
            await self._ready.wait()

    def pop(self) -> tuple[str, bytes]:
        return self._items.popleft()

    async def get(self) -> tuple[str, bytes]:
        while not self._items:
            self._ready.clear()
            if self._items:  # pushed between the check and the clear
                break
            await self._ready.wait()
        return self._items.popleft()

    def __len__(self) -> int:
        return len(self._items)


class LocalBus:
    """The step subscriptions of the Nodes sharing one session, for local delivery (see the module doc)."""

    def __init__(self) -> None:
        self.nodes = 0  # open Nodes on the session; the bus goes with the last
        # (key expression, listening Node, its step handler for the key if it has one: Node.listen's `inline`)
        self._listeners: list[tuple[zenoh.KeyExpr, Node, Handler | None]] = []
        self._routes: dict[str, tuple[tuple[Node, Handler | None], ...]] = {}  # key -> one entry per matching listen

    def add(self, key_expr: str, node: Node, inline: Handler | None = None) -> None:
        self._listeners.append((zenoh.KeyExpr(key_expr), node, inline))
        self._routes.clear()

    def remove(self, node: Node) -> None:
        self._listeners = [(e, n, h) for e, n, h in self._listeners if n is not node]
        self._routes.clear()

    def __bool__(self) -> bool:
        return bool(self._listeners)

    def route(self, key: str) -> tuple[tuple[Node, Handler | None], ...]:
        nodes = self._routes.get(key)
        if nodes is None:
            k = zenoh.KeyExpr(key)
            nodes = self._routes[key] = tuple((n, h) for e, n, h in self._listeners if e.intersects(k))
        return nodes


_BUSES: dict[int, tuple[zenoh.Session, LocalBus]] = {}  # by id(session); the entry keeps the session alive


def _bus(session: zenoh.Session) -> LocalBus:
    entry = _BUSES.get(id(session))
    if entry is None or entry[0] is not session:
        entry = _BUSES[id(session)] = (session, LocalBus())
    entry[1].nodes += 1
    return entry[1]
