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
Tap = Callable[[str, bytes], None]  # a tap's callback: (key, payload bytes)
Route = tuple[tuple[tuple["Node", Handler | None], ...], tuple[Tap, ...]]  # a key's Nodes (and handlers), its taps


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
    """The step subscriptions of the Nodes sharing one session, and its taps, for local delivery (see the module
    doc): a step message sent in this session reaches them through the bus, not through Zenoh."""

    def __init__(self) -> None:
        self.nodes = 0  # open Nodes and taps on the session; the bus goes with the last
        # (key expression, listening Node, its step handler for the key if it has one: Node.listen's `inline`)
        self._listeners: list[tuple[zenoh.KeyExpr, Node, Handler | None]] = []
        self._taps: list[tuple[zenoh.KeyExpr, Tap]] = []
        self._routes: dict[str, Route] = {}  # key -> its listeners (one entry per matching listen) and taps

    def add(self, key_expr: str, node: Node, inline: Handler | None = None) -> None:
        self._listeners.append((zenoh.KeyExpr(key_expr), node, inline))
        self._routes.clear()

    def remove(self, node: Node) -> None:
        self._listeners = [(e, n, h) for e, n, h in self._listeners if n is not node]
        self._routes.clear()

    def add_tap(self, key_expr: str, tap: Tap) -> None:
        self._taps.append((zenoh.KeyExpr(key_expr), tap))
        self._routes.clear()

    def remove_tap(self, tap: Tap) -> None:
        self._taps = [(e, t) for e, t in self._taps if t is not tap]
        self._routes.clear()

    def __bool__(self) -> bool:
        return bool(self._listeners or self._taps)

    def route(self, key: str) -> Route:
        route = self._routes.get(key)
        if route is None:
            k = zenoh.KeyExpr(key)
            nodes = tuple((n, h) for e, n, h in self._listeners if e.intersects(k))
            route = self._routes[key] = (nodes, tuple(t for e, t in self._taps if e.intersects(k)))
        return route

    def heard(self, key: str) -> bool:
        """Someone in this session listens on a step key (a Node or a tap)."""
        nodes, taps = self.route(key)
        return bool(nodes or taps)


class Tapped:
    """A tap on a session's step keys (`tap`): undeclare() ends it."""

    def __init__(self, session: zenoh.Session, key_expr: str, callback: Tap) -> None:
        self._bus, self._tap = _bus(session), callback
        self._bus.add_tap(key_expr, callback)
        # every origin: this session's step publishers never deliver here (their destination is other sessions)
        self._sub = session.declare_subscriber(key_expr, lambda s: callback(str(s.key_expr), s.payload.to_bytes()))

    def undeclare(self) -> None:
        if self._tap is not None:
            self._sub.undeclare()
            self._bus.remove_tap(self._tap)
            _release(self._bus)
            self._tap = None


def tap(session: zenoh.Session, key_expr: str, callback: Tap) -> Tapped:
    """Hear every message on `key_expr`, step keys included, as its bytes: from other sessions through Zenoh, from
    this session's Nodes through the local bus (a plain Zenoh subscriber of the same session does not hear their
    step messages: they never enter Zenoh's local routing). `callback(key, payload)` runs on the sending thread or
    Zenoh's: it should only keep what it gets."""
    return Tapped(session, key_expr, callback)


_BUSES: dict[int, tuple[zenoh.Session, LocalBus]] = {}  # by id(session); the entry keeps the session alive


def _bus(session: zenoh.Session) -> LocalBus:
    entry = _BUSES.get(id(session))
    if entry is None or entry[0] is not session:
        entry = _BUSES[id(session)] = (session, LocalBus())
    entry[1].nodes += 1
    return entry[1]


def _release(bus: LocalBus) -> None:
    """One Node or tap of the bus's session is gone; the bus goes with the last."""
    bus.nodes -= 1
    if not bus.nodes:
        for k, (_, b) in list(_BUSES.items()):
            if b is bus:
                del _BUSES[k]
