"""A Node: one actor's presence on the wire. Publishers with BLOCK congestion control, subscriptions into its
mailbox, readiness (every publisher matched before the liveliness token goes up), decoding with the reasons logged,
and clean shutdown; its link faults are in links.py, a fleet's batches in fleet.py. The package's doc (__init__.py)
says how messages reach the loop."""

from __future__ import annotations

import asyncio
import contextlib
import logging
import random
import threading
import time
from collections.abc import AsyncIterator, Callable, Iterable
from dataclasses import dataclass
from typing import Any, TypeVar

import zenoh
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys

from . import timeline as _timeline
from .fleet import Gathering
from .links import LINK_COUNTS, LinkFault, LinkFaults
from .mailbox import Mailbox, _bus, _release
from .timeline import HANDLED

#: a node logs the first rejected message on each of up to this many keys, then every 1000th: a flood on one key
#: cannot hide a bad message on another, and the log stays bounded
LOGGED_KEYS = 100
# wait_matched looks again this often when other Nodes share the session (they tell no listener), else this often
# for safety's sake: Zenoh's matching listener wakes it at once
LOCAL_CHECK_S, REMOTE_CHECK_S = 0.005, 1.0
M = TypeVar("M")


_NOBODY: tuple[tuple, tuple] = ((), ())  # no Node and no tap of this session listens
FAILED = "__failed__"  # the mailbox item that wakes the loop when an inline step handler raised (no Zenoh key)
# Inline handlers nest: in the single placement a chain's step runs down and back up its joints as calls, each
# handler's send running the next one's. A 100-joint chain nested 200 deep and ended in RecursionError. Past this
# depth a step message goes into its mailbox instead (handled on the loop, in the same order): every robot of the
# examples (at most 2 x 7 levels a step) still runs as calls.
INLINE_DEPTH = 32
_inline = threading.local()  # .depth: the inline handlers running on this thread, nested


@dataclass(slots=True)
class Local:
    """A step message handed to a Node of the sender's own session as it is (local delivery): no bytes unless someone
    needs them (a link fault, a tap, the general decode path); checked as the wire's are when decoded (Node.decode)."""

    msg: Any
    run: str
    src: str
    key: bytes
    payload: bytes | None = None

    def encoded(self) -> bytes:
        if self.payload is None:
            self.payload = codec.encode(self.msg, self.run, self.src, self.key)
        return self.payload


class Node(LinkFaults, Gathering):
    """One actor's handle on the wire: mailbox, publishers, subscriptions, liveliness token, link faults.

    Several nodes may share one session (the `single` placement); each owns its declarations and
    undeclares them in `close()`."""

    def __init__(self, session: zenoh.Session, keys: Keys, role: str, ident: str, key: bytes) -> None:
        self.session = session
        self.keys = keys
        self.role = role
        self.ident = ident
        self.key = key  # the run's MAC key (codec.py)
        self.log = logging.getLogger(f"kinswarm.{role}.{ident}")
        self._loop = asyncio.get_running_loop()
        self.mailbox = Mailbox(self._loop)
        self._pubs: dict[str, Any] = {}
        self._heard_away: dict[str, bool] = {}  # step key -> another session listens (its publisher's matching)
        self._subs: list[Any] = []
        self._token: Any = None
        self._closed = False
        self.rejected = 0
        self._rejected_keys: set[str] = set()  # keys whose first rejection was logged (at most LOGGED_KEYS)
        # link faults: empty on the fast path (the one check); touched only on the loop
        self._link_faults: dict[str, LinkFault] = {}
        self._step_prefixes = keys.step_prefixes
        self._periodic_prefixes = (keys.prefix("host"), keys.metrics("status"), keys.metrics("joints"))
        self.fault_rng = random.Random(f"link-faults/{ident}")  # seeded from the ident: faulted runs are reproducible
        self.link_counts: dict[str, int] = dict.fromkeys(LINK_COUNTS, 0)  # what the faults did, for reports
        self.on_fault_expired: Callable[[str], None] | None = None  # told the description when one expires
        self._bus = _bus(session)
        # Step handlers on Zenoh's thread (listen(..., inline=)): whoever runs this actor's handlers holds the lock --
        # the loop (next()) or a Zenoh thread; `inline` is off until the actor's loop serves (serve_inline)
        self.lock = threading.Lock()
        self.inline = False
        self._loop_holds = False  # the loop holds `lock` (in next()); only the loop reads or writes this
        self.inline_handled = 0  # step messages handled on a Zenoh thread (the rest went through the mailbox)
        self._failure: BaseException | None = None  # what an inline handler raised, for the loop to raise
        # A fleet (run.fleet = B > 1): its step messages travel as Batches, robots in [0, fleet). While the actor
        # handles one batch, what its lanes send is gathered here (key -> groups of robots and messages).
        self.fleet = 1
        self._gathered: dict[str, list[tuple[list[int], list[Any]]]] | None = None
        self._later: list[Callable[[], None]] = []  # what the lanes run once the gathered batches have left
        self._tl = _timeline.timeline(role, ident)  # None unless benchmarks/step_timeline.py asks (timeline.py)

    # -- sending ---------------------------------------------------------------------------------
    def publisher(self, key: str) -> Any:
        pub = self._pubs.get(key)
        if pub is None:
            # BLOCK: the default DROP silently loses messages under load; lockstep cannot afford that. Periodic
            # state (heartbeats, pauses, status) is resent anyway and must never wait behind a dead link: DROP.
            periodic = key.startswith(self._periodic_prefixes)
            cc = zenoh.CongestionControl.DROP if periodic else zenoh.CongestionControl.BLOCK
            # a step key's listeners in this session hear it through the local bus (its Nodes and taps): Zenoh
            # carries it to other sessions only, so its matching status says whether any other session listens
            step = key.startswith(self._step_prefixes)
            where = zenoh.Locality.REMOTE if step else zenoh.Locality.ANY
            pub = self.session.declare_publisher(key, congestion_control=cc, express=True, allowed_destination=where)
            self._pubs[key] = pub
            if step:  # whether another session listens, kept current by Zenoh (read on every step message sent)
                heard = self._heard_away
                heard[key] = False
                self._subs.append(pub.declare_matching_listener(lambda st: heard.__setitem__(key, st.matching)))
                heard[key] = pub.matching_status.matching
        return pub

    def send(self, key: str, msg: Any) -> None:
        if not key.startswith(self._step_prefixes):
            self.publisher(key).put(codec.encode(msg, self.keys.run, self.ident, self.key))
            return
        if self._tl is not None:
            self._tl.put(key)
        if self._link_faults:
            for delay, p in self._fault(codec.encode(msg, self.keys.run, self.ident, self.key)):
                if delay:  # never sleep: the loop puts it later
                    self._loop.call_later(delay, self._put_late, key, p)
                else:
                    self._emit(key, p)
            return
        nodes, taps = self._bus.route(key) if self._bus else _NOBODY
        if nodes:  # a Node of this session listens (the `single` placement): the message as it is, bytes if needed
            self._emit(key, Local(msg, self.keys.run, self.ident, self.key))
            return
        # only other sessions (the `process` placement): what _emit does then, without its hand-over object
        p = codec.encode(msg, self.keys.run, self.ident, self.key)
        (self._pubs.get(key) or self.publisher(key)).put(p)
        for tap in taps:
            tap(key, p)

    def _emit(self, key: str, payload: bytes | Local) -> None:
        """A step message: to this session's Nodes and taps listening on `key` (the local bus), and on Zenoh to the
        other sessions. Bytes only where needed: a Node of this session decodes the message itself (Local), and
        nobody encodes it when no tap and no other session listens (the `single` placement's step)."""
        pub = self.publisher(key)
        nodes, taps = self._bus.route(key) if self._bus else ((), ())
        if taps or not nodes or self._heard_away[key]:  # no Node here: put as ever (process placement)
            p = payload.encoded() if type(payload) is Local else payload
            pub.put(p)
            for tap in taps:
                tap(key, p)
        for node, inline in nodes:
            node._deliver_local(key, payload, inline)

    def _put_late(self, key: str, payload: bytes) -> None:
        if not self._closed:
            self._emit(key, payload)

    # -- receiving -------------------------------------------------------------------------------
    def listen(self, key_expr: str, inline: Callable[[str, bytes], None] | None = None) -> None:
        """Subscribe `key_expr` into the mailbox. `inline`: a handler run on Zenoh's delivery thread itself, under
        `lock`, when the actor serves inline, nothing waits in the mailbox (order is kept) and no link fault is
        active; otherwise the message waits in the mailbox and the loop hands it to the same dispatch. Step keys
        have one; a control key may (the sim's faults: applied at the step they reach it, not when the loop wakes)."""
        push = self.mailbox.push
        step = key_expr.startswith(self._step_prefixes)
        handler = inline if step else None

        if inline is not None and not step:

            def on_sample(s: Any) -> None:  # zenoh thread
                key, payload = str(s.key_expr), s.payload.to_bytes()
                if self._link_faults:
                    push(key, payload)
                else:
                    self._handle(key, payload, inline, push)

        elif handler is not None:

            def on_sample(s: Any) -> None:  # zenoh thread
                key, payload = str(s.key_expr), s.payload.to_bytes()
                if self._tl is not None:
                    self._tl.arrive(key)
                if self._link_faults:
                    self._receive_faulty(key, payload)
                else:
                    self._handle(key, payload, handler, push)

        else:

            def on_sample(s: Any) -> None:  # zenoh thread
                if self._link_faults:
                    self._receive_faulty(str(s.key_expr), s.payload.to_bytes())
                else:
                    push(str(s.key_expr), s.payload.to_bytes())

        if step:  # this session's Nodes deliver here directly (_emit)
            self._bus.add(key_expr, self, handler)
            sub = self.session.declare_subscriber(key_expr, on_sample, allowed_origin=zenoh.Locality.REMOTE)
        else:
            sub = self.session.declare_subscriber(key_expr, on_sample)
        self._subs.append(sub)

    def _handle(self, key: str, payload: bytes, handler: Callable[[str, bytes], None], push: Any) -> None:
        """Run a step handler here and now, under `lock`, when the actor serves inline, nothing waits in the mailbox
        (order is kept) and no link fault is active; else into the mailbox (`push`) for the loop. Zenoh's thread, or
        the thread of a Node of the same session that sent it (local delivery)."""
        depth = getattr(_inline, "depth", 0)
        if depth < INLINE_DEPTH and self.inline and self.lock.acquire(False):  # busy (the loop, another thread, this
            try:  # very handler) or nested too deep: the mailbox
                if self.mailbox._items or self._link_faults or not self.inline or self._closed:
                    push(key, payload)
                else:
                    self.inline_handled += 1
                    _inline.depth = depth + 1
                    if self._tl is None:
                        handler(key, payload)
                    else:
                        self._timed(key, payload, handler, "inline")
            except BaseException as e:  # next() raises it on the loop
                self._fail(e)
            finally:
                _inline.depth = depth
                self.lock.release()
        else:
            push(key, payload)

    def _timed(self, key: str, payload: Any, handler: Callable[[str, Any], Any], where: str) -> Any:
        """`handler(key, payload)`, its start, end and thread CPU recorded (benchmarks/step_timeline.py)."""
        assert self._tl is not None
        t0, c0 = time.perf_counter_ns(), time.thread_time_ns()
        try:
            return handler(key, payload)
        finally:
            self._tl.rows.append((HANDLED, key, t0, time.perf_counter_ns(), time.thread_time_ns() - c0, where))

    def _fail(self, e: BaseException) -> None:  # zenoh thread, lock held
        if self._failure is None:
            self._failure = e
            self.inline = False
        self.mailbox.push(FAILED, b"")  # wakes the loop, which raises it

    def serve_inline(self, on: bool = True) -> None:
        """From now on step handlers given to listen() may run on Zenoh's thread (`on`), or no longer (once this
        returns, none runs). Call it on the loop: on once the actor dispatches (what arrived before waits in the
        mailbox and goes first), off before what the handlers touch goes away."""
        if on or self._loop_holds:  # the loop holds the lock (a handler of its own, maybe suspended): none runs
            self.inline = on
            return
        got = self.lock.acquire(timeout=5.0)  # an inline handler in flight finishes first
        self.inline = False
        if got:
            self.lock.release()

    @contextlib.asynccontextmanager
    async def next(self) -> AsyncIterator[tuple[str, bytes]]:
        """The next mailbox item, with `lock` held while the caller handles it (the one way into an actor whose step
        handlers may run on Zenoh's thread: the two never run at once, and nothing queued is overtaken). A handler
        may await (the lock stays held); if it raises or is cancelled, the actor is leaving: inline handling ends."""
        await self.mailbox.wait()
        with self.lock:  # at most one inline handler long (a Zenoh thread only tries it)
            self._loop_holds = True
            try:
                if self._failure is not None:  # an inline handler raised: the actor fails as if its loop had
                    raise self._failure
                item = self.mailbox.pop()
                if self._tl is None or not item[0].startswith(self._step_prefixes):
                    yield item
                else:  # a step message that waited for the loop (benchmarks/step_timeline.py)
                    t0, c0 = time.perf_counter_ns(), time.thread_time_ns()
                    try:
                        yield item
                    finally:
                        cpu = time.thread_time_ns() - c0
                        self._tl.rows.append((HANDLED, item[0], t0, time.perf_counter_ns(), cpu, "loop"))
            except BaseException:
                self.inline = False
                raise
            finally:
                self._loop_holds = False

    def _deliver_local(self, key: str, payload: bytes | Local, inline: Callable[[str, bytes], None] | None) -> None:
        """A step message from a Node of the same session (the sending Node's thread): handled at once when `inline`
        may run (`_handle`: a step crosses the actors of one process as calls, no mailbox round trip on the loop),
        else into the mailbox."""
        if self._closed:
            return
        if self._tl is not None:
            self._tl.arrive(key)
        if self._link_faults and type(payload) is Local:  # faults act on bytes (corrupt: garbage of the same length)
            payload = payload.encoded()
        if asyncio._get_running_loop() is not self._loop:  # another loop or thread: as from Zenoh
            if self._link_faults:
                self._receive_faulty(key, payload)
            elif inline is not None:
                self._handle(key, payload, inline, self.mailbox.push)
            else:
                self.mailbox.push(key, payload)
        elif self._link_faults:
            self._deliver_faulty(key, payload)
        elif inline is not None:
            self._handle(key, payload, inline, self.mailbox.push_local)
        else:
            self.mailbox.push_local(key, payload)

    def _receive_faulty(self, key: str, payload: bytes) -> None:  # zenoh thread
        if not key.startswith(self._step_prefixes):
            self.mailbox.push(key, payload)
            return
        try:  # fault it on the loop: the RNG, counters and timers live there
            self._loop.call_soon_threadsafe(self._deliver_faulty, key, payload)
        except RuntimeError:  # loop closed during shutdown
            pass

    def _deliver_faulty(self, key: str, payload: bytes) -> None:  # loop
        for delay, p in self._fault(payload):
            if delay:
                self._loop.call_later(delay, self._push_late, key, p)
            else:
                self.mailbox.push(key, p)

    def _push_late(self, key: str, payload: bytes) -> None:
        if not self._closed:
            self.mailbox.push(key, payload)

    async def recv(self, timeout: float | None = None) -> tuple[str, bytes]:
        """The next message; TimeoutError after `timeout` seconds (None: wait for ever).

        Not asyncio.wait_for: on Python 3.11 it swallows a cancellation that lands while the message
        is already in hand, so a Ctrl-C between two messages was lost and the supervisor trained on.
        asyncio.timeout counts cancellations and lets the caller's through."""
        async with asyncio.timeout(timeout):
            return await self.mailbox.get()

    def decode(self, key: str, payload: bytes | Local, expect: type[M]) -> M | None:
        """Decode or log why not and return None: a bad message never crashes an actor. A Local message (from a Node
        of this session) is checked as a wire message's body is, without its bytes (codec.local); if that cannot
        tell, its bytes go the wire's way, so it is refused, or taken, exactly as from another process."""
        if type(payload) is Local:
            p = payload  # signed with this run's key, of the expected kind and checked: taken; else the wire's way
            if p.key == self.key and type(p.msg) is expect:
                if (m := codec.local(p.msg, p.run, p.src, self.keys.run)) is not None:
                    return m
            payload = p.encoded()
        try:
            return codec.decode(payload, expect, self.keys.run, self.key)
        except codec.DecodeError as e:
            self._rejected(key, codec.sender(payload), str(e))
            return None

    def _rejected(self, key: str, sender: str, reason: str) -> None:
        self.rejected += 1
        # the first rejection on each key is logged, so a flood on one key cannot hide another's; then a sample
        first_on_key = key not in self._rejected_keys and len(self._rejected_keys) < LOGGED_KEYS
        if first_on_key:
            self._rejected_keys.add(key)
        if first_on_key or self.rejected <= 20 or self.rejected % 1000 == 0:
            self.log.warning(
                "rejected message on %s from %s: %s (rejected so far: %d)", key, sender, reason, self.rejected
            )

    # -- readiness -------------------------------------------------------------------------------
    async def wait_matched(self, keys: Iterable[str], timeout: float) -> None:
        """Wait until every given publisher has a matching subscriber: a put before that is lost. Woken by Zenoh's
        matching listeners, not a poll: a hundred actors starting together polled each 5 ms, CPU the ones still
        importing needed. A Node of this session that listens (the single placement's local bus) tells no listener:
        with other Nodes on the session, the keys are looked at every LOCAL_CHECK_S."""
        pending = list(keys)
        changed = asyncio.Event()
        loop = self._loop

        def wake(_: Any) -> None:  # zenoh thread
            with contextlib.suppress(RuntimeError):  # the loop is closing: nobody waits any more
                loop.call_soon_threadsafe(changed.set)

        listeners = [self.publisher(k).declare_matching_listener(wake) for k in pending]
        deadline = time.monotonic() + timeout
        try:
            while True:
                changed.clear()
                pending = [k for k in pending if not (self._heard_here(k) or self._pubs[k].matching_status.matching)]
                if not pending:
                    return
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise TimeoutError(f"{self.role}/{self.ident}: nobody subscribes to {pending}")
                again = LOCAL_CHECK_S if self._bus.nodes > 1 else REMOTE_CHECK_S
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(min(remaining, again)):
                        await changed.wait()
        finally:
            for listener in listeners:
                with contextlib.suppress(Exception):  # gone with the session
                    listener.undeclare()

    def _heard_here(self, key: str) -> bool:
        """A Node or tap of this session listens on step key `key` (it hears it through the local bus)."""
        return key.startswith(self._step_prefixes) and self._bus.heard(key)

    def declare_alive(self) -> None:
        self._token = self.session.liveliness().declare_token(self.keys.alive(self.role, self.ident))

    def close(self) -> None:
        self.serve_inline(False)
        if self._tl is not None:
            self._tl.write()
        if not self._closed:
            self._bus.remove(self)
            _release(self._bus)
        self._closed = True  # late puts and pushes still on the loop's timers become no-ops
        self._clear_link_faults()
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
