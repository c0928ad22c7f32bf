"""The runtime shell every actor runs in: one Zenoh session factory, an asyncio mailbox, publishers
with BLOCK congestion control, readiness (every publisher matched before the liveliness token goes up),
and clean shutdown.

Zenoh callbacks run on a zenoh-owned thread. They only append `(key, bytes)` to a deque and wake the
event loop once per burst (`call_soon_threadsafe` per message caps a subscriber near 85k msg/s; one
wake-up per burst is an order of magnitude cheaper). Everything else happens on the loop.

Local delivery (the `single` placement): step messages (keys under `sim/` and `a/`) that a Node sends
are handed straight to the Nodes of the same session that listen on them — still encoded, signed and
decoded by the receiver like any other message, and still faulted — instead of a round trip through
Zenoh's local routing, whose delivery threads run the subscriber callback, take the GIL from the event
loop and wake it through its self-pipe (measured: ~2/3 of a single-placement step). Zenoh still carries
every such message to the other sessions (other processes, observers, `kinswarm` tools) and to
non-Node subscribers of the same session; a Node's step subscriptions hear only other sessions through
Zenoh (`allowed_origin=REMOTE`), so nothing arrives twice.

Link faults (DESIGN §5, `Node.apply_fault`): drop, delay, duplicate and corrupt act on a node's step
links only — what it sends and receives under `sim/` and `a/` — never on ctl/, rep/, metrics/, fault/ or
liveliness, so a faulted swarm stays controllable. With none active, sending and receiving cost one
attribute check more than without the feature; with some active, received step messages are handed to
the loop one by one and faulted there, so the RNG, counters and timers are only ever touched on the loop.
"""

from __future__ import annotations

import asyncio
import collections
import dataclasses
import json
import logging
import random
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import zenoh
from kinswarm.protocol import codec
from kinswarm.protocol.faults import ALL, LINK_FAULTS, check_fault, describe
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Fault

LEASE_MS = 1000
HANDSHAKE_MS = 2000
#: a node logs the first rejected message on each of up to this many keys, then every 1000th: a flood on one key
#: cannot hide a bad message on another, and the log stays bounded
LOGGED_KEYS = 100
M = TypeVar("M")


@dataclass(frozen=True)
class NetSpec:
    """Everything a process needs to join a swarm's Zenoh network: the one input of the session factory.
    Written by a host's supervisor for the actors it spawns (`<run>/net/<host>.json`, owner-only: it may
    hold a password), built from a deploy plan (actors/plan.py) or, for one host, from `--listen`."""

    mode: str = "peer"  # peer | client (of a router) | router
    listen: tuple[str, ...] = ()
    connect: tuple[str, ...] = ()
    lease_ms: int = LEASE_MS
    must_connect: bool = False  # fail at once if no connect endpoint answers, instead of retrying forever
    # TLS (endpoints tls/...): paths of the CA, and of this process's certificate and key (its identity)
    ca: str = ""
    cert: str = ""
    key: str = ""
    mtls: bool = False
    # user/password authentication: this process's credentials, and the dictionary that checks others'
    user: str = ""
    password: str = field(default="", repr=False)
    dictionary: str = ""
    acl: dict[str, Any] | None = None  # Zenoh's access_control section, applied to what this process receives
    close_blocked_ms: int = 0  # several hosts: close a link a BLOCK put waited on this long (0: Zenoh's 5 s)

    def to_json(self) -> str:
        return json.dumps(dataclasses.asdict(self), indent=2)

    @classmethod
    def from_json(cls, text: str) -> NetSpec:
        data = json.loads(text)
        for k in ("listen", "connect"):
            data[k] = tuple(data.get(k, ()))
        return cls(**data)

    def with_(self, **changes: Any) -> NetSpec:
        return dataclasses.replace(self, **changes)


def zenoh_config(spec: NetSpec) -> zenoh.Config:
    """The one place a Zenoh config is built. Multicast scouting is off: peers find each other only
    through the endpoints given (and gossip among themselves), never across the network by accident."""
    c = zenoh.Config()

    def put(key: str, value: Any) -> None:
        c.insert_json5(key, json.dumps(value))

    put("mode", spec.mode)
    put("listen/endpoints", list(spec.listen))
    put("connect/endpoints", list(spec.connect))
    put("scouting/multicast/enabled", False)
    put("transport/link/tx/lease", spec.lease_ms)
    # Re-dial a lost configured endpoint at least once a lease (Zenoh's default backs off to 4 s): a host
    # back from a cut rejoined 2.1-2.5 s after its link returned with the default, 0.9-1.1 s with this.
    retry = {"period_init_ms": max(spec.lease_ms // 4, 50), "period_max_ms": spec.lease_ms, "period_increase_factor": 2}
    put("connect/retry", retry)
    if spec.close_blocked_ms:
        # Several hosts: a BLOCK put towards a cut-off host waits this long (Zenoh's default: 5 s) before the
        # link is closed and its sender freed. On one host a receiver stalled by load must not lose its link.
        put("transport/link/tx/queue/congestion_control/block/wait_before_close", spec.close_blocked_ms * 1000)
    # A handshake with a frozen (SIGSTOPped) peer never completes; the 10 s default then also held up
    # every new session's close (`kinswarm status` took 10 s during a freeze, 0.5 s with 2 s here).
    put("transport/unicast/open_timeout", HANDSHAKE_MS)
    put("transport/unicast/accept_timeout", HANDSHAKE_MS)
    if spec.must_connect:  # an actor whose supervisor is unreachable fails instead of retrying forever
        put("connect/timeout_ms", 10000)
        put("connect/exit_on_failure", True)
    if spec.ca:
        put("transport/link/tls/root_ca_certificate", spec.ca)
        if spec.cert:
            put("transport/link/tls/listen_certificate", spec.cert)
            put("transport/link/tls/listen_private_key", spec.key)
        if spec.mtls:
            put("transport/link/tls/enable_mtls", True)
            put("transport/link/tls/connect_certificate", spec.cert)
            put("transport/link/tls/connect_private_key", spec.key)
    if spec.user:
        put("transport/auth/usrpwd/user", spec.user)
        put("transport/auth/usrpwd/password", spec.password)
    if spec.dictionary:
        put("transport/auth/usrpwd/dictionary_file", spec.dictionary)
    if spec.acl is not None:
        put("access_control", spec.acl)
    return c


def open_session(spec: NetSpec | None = None, **kw: Any) -> zenoh.Session:
    """The one session factory: `open_session(spec)`, or `open_session(listen=[...], connect=[...])` for the
    fields of a NetSpec (tests and one-host tools)."""
    if spec is None:
        kw = {k: tuple(v) if k in ("listen", "connect") else v for k, v in kw.items()}
        spec = NetSpec(**kw)
    return zenoh.open(zenoh_config(spec))


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
        self._listeners: list[tuple[zenoh.KeyExpr, Node]] = []
        self._routes: dict[str, tuple[Node, ...]] = {}  # key -> its listeners, one entry per matching listen

    def add(self, key_expr: str, node: Node) -> None:
        self._listeners.append((zenoh.KeyExpr(key_expr), node))
        self._routes.clear()

    def remove(self, node: Node) -> None:
        self._listeners = [(e, n) for e, n in self._listeners if n is not node]
        self._routes.clear()

    def __bool__(self) -> bool:
        return bool(self._listeners)

    def route(self, key: str) -> tuple[Node, ...]:
        nodes = self._routes.get(key)
        if nodes is None:
            k = zenoh.KeyExpr(key)
            nodes = self._routes[key] = tuple(n for e, n in self._listeners if e.intersects(k))
        return nodes


_BUSES: dict[int, tuple[zenoh.Session, LocalBus]] = {}  # by id(session); the entry keeps the session alive


def _bus(session: zenoh.Session) -> LocalBus:
    entry = _BUSES.get(id(session))
    if entry is None or entry[0] is not session:
        entry = _BUSES[id(session)] = (session, LocalBus())
    entry[1].nodes += 1
    return entry[1]


LINK_COUNTS = ("dropped", "delayed", "duplicated", "corrupted")


@dataclass
class LinkFault:
    """One active link fault of a node: at most one per kind; a new one of the same kind replaces it."""

    kind: str  # drop, delay, duplicate or corrupt
    rate: float  # probability per message (1.0 for delay)
    ms: float  # delay only
    description: str
    expiry: asyncio.TimerHandle | None = None


class Node:
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
        self._subs: list[Any] = []
        self._token: Any = None
        self._closed = False
        self.rejected = 0
        self._rejected_keys: set[str] = set()  # keys whose first rejection was logged (at most LOGGED_KEYS)
        # link faults: empty on the fast path (the one check); touched only on the loop
        self._link_faults: dict[str, LinkFault] = {}
        self._step_prefixes = (f"{keys.root}/sim/", f"{keys.root}/a/")
        self._periodic_prefixes = tuple(f"{keys.root}/{k}" for k in ("ctl/host/", "metrics/status", "metrics/joints"))
        self.fault_rng = random.Random(f"link-faults/{ident}")  # seeded from the ident: faulted runs are reproducible
        self.link_counts: dict[str, int] = dict.fromkeys(LINK_COUNTS, 0)  # what the faults did, for reports
        self.on_fault_expired: Callable[[str], None] | None = None  # told the description when one expires
        self._bus = _bus(session)

    # -- sending ---------------------------------------------------------------------------------
    def publisher(self, key: str) -> Any:
        pub = self._pubs.get(key)
        if pub is None:
            # BLOCK: the default DROP silently loses messages under load; lockstep cannot afford that. Periodic
            # state (heartbeats, pauses, status) is resent anyway and must never wait behind a dead link: DROP.
            periodic = key.startswith(self._periodic_prefixes)
            cc = zenoh.CongestionControl.DROP if periodic else zenoh.CongestionControl.BLOCK
            pub = self.session.declare_publisher(key, congestion_control=cc, express=True)
            self._pubs[key] = pub
        return pub

    def send(self, key: str, msg: Any) -> None:
        payload = codec.encode(msg, self.keys.run, self.ident, self.key)
        if self._link_faults and key.startswith(self._step_prefixes):
            for delay, p in self._fault(payload):
                if delay:  # never sleep: the loop puts it later
                    self._loop.call_later(delay, self._put_late, key, p)
                else:
                    self._emit(key, p)
            return
        self._emit(key, payload)

    def _emit(self, key: str, payload: bytes) -> None:
        """Put on Zenoh (other sessions, observers); hand a step message to this session's listening Nodes."""
        self.publisher(key).put(payload)
        if self._bus:
            for node in self._bus.route(key) if key.startswith(self._step_prefixes) else ():
                node._deliver_local(key, payload)

    def _put_late(self, key: str, payload: bytes) -> None:
        if not self._closed:
            self._emit(key, payload)

    # -- receiving -------------------------------------------------------------------------------
    def listen(self, key_expr: str) -> None:
        push = self.mailbox.push

        def on_sample(s: Any) -> None:  # zenoh thread
            if self._link_faults:
                self._receive_faulty(str(s.key_expr), s.payload.to_bytes())
            else:
                push(str(s.key_expr), s.payload.to_bytes())

        if key_expr.startswith(self._step_prefixes):  # this session's Nodes deliver here directly (_emit)
            self._bus.add(key_expr, self)
            sub = self.session.declare_subscriber(key_expr, on_sample, allowed_origin=zenoh.Locality.REMOTE)
        else:
            sub = self.session.declare_subscriber(key_expr, on_sample)
        self._subs.append(sub)

    def _deliver_local(self, key: str, payload: bytes) -> None:  # the sending Node's thread
        if self._closed:
            return
        if asyncio._get_running_loop() is not self._loop:  # another loop or thread: as from Zenoh
            if self._link_faults:
                self._receive_faulty(key, payload)
            else:
                self.mailbox.push(key, payload)
        elif self._link_faults:
            self._deliver_faulty(key, payload)
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

    def decode(self, key: str, payload: bytes, expect: type[M]) -> M | None:
        """Decode or log why not and return None: a bad message never crashes an actor."""
        try:
            return codec.decode(payload, expect, self.keys.run, self.key)
        except codec.DecodeError as e:
            self.rejected += 1
            # the first rejection on each key is logged, so a flood on one key cannot hide another's; then a sample
            first_on_key = key not in self._rejected_keys and len(self._rejected_keys) < LOGGED_KEYS
            if first_on_key:
                self._rejected_keys.add(key)
            if first_on_key or self.rejected <= 20 or self.rejected % 1000 == 0:
                self.log.warning(
                    "rejected message on %s from %s: %s (rejected so far: %d)",
                    key,
                    codec.sender(payload),
                    e,
                    self.rejected,
                )
            return None

    # -- link faults -----------------------------------------------------------------------------
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
        if not self._closed:
            self._bus.remove(self)
            self._bus.nodes -= 1
            if not self._bus.nodes and _BUSES.get(id(self.session), (None,))[0] is self.session:
                del _BUSES[id(self.session)]
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
