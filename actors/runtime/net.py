"""The one session factory: a NetSpec (what a process needs to join a swarm's Zenoh network) into a Zenoh config
and an open session."""

from __future__ import annotations

import dataclasses
import json
import re
from dataclasses import dataclass, field
from typing import Any

import zenoh

LEASE_MS = 1000
HANDSHAKE_MS = 2000


@dataclass(frozen=True)
class NetSpec:
    """Everything a process needs to join a swarm's Zenoh network: the one input of the session factory.
    Written by a host's supervisor for the actors it spawns (`<run>/net/<host>.json`, owner-only: it may
    hold a password), built from a deploy plan (actors/deploy/plan.py) or, for one host, from `--listen`."""

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


_RUST_AT = re.compile(r"\s*\bat\s+\S+\.rs:\d+\.?")  # where in Zenoh's Rust source an error was raised
_IN_USE = re.compile(r"bound to (\S+?):? \[.*Address already in use")
_NO_ANSWER = re.compile(r"Unable to connect to any of \[(?:Single\()?([^)\]]+)")


def zenoh_reason(e: BaseException) -> str:
    """A Zenoh error in one line in a user's words: the common ones said plainly, any other without the Rust source
    paths Zenoh appends to each of its nested causes."""
    text = " ".join(_RUST_AT.sub("", str(e)).split())
    if m := _IN_USE.search(text):
        return f"{m.group(1)} is taken: another program listens on that port"
    if m := _NO_ANSWER.search(text):
        return f"nothing answers at {m.group(1)}"
    return text or type(e).__name__
