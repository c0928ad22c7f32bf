"""Deploy plans (`deploy/*.toml`): which actors run on which host, how the hosts reach each other, and how
they prove who they are. `kinswarm up PLAN --host NAME` runs one host's share; `kinswarm run` is the
one-host plan built in code (`local_plan`), the same machinery.

A plan names hosts, each with an address the others reach it at and the actors it runs ("sim", "agents" for
every agent no other host claims, or agent ids); one host leads (it trains, the others serve). No router
host by default (`mode = "peer"`): each host's supervisor is its host's Zenoh router (the hub), its actors are
clients of it, and the other supervisors connect to the leader's, so the one link between hosts is a configured
one that comes back after a cut. A host of N actors holds N connections, not a mesh of N^2 (docs/architecture.md:
18 processes held 490 as gossiping peers). `mode = "client"` makes every process a client of the plan's routers
(`kinswarm router`), for sites where hosts cannot reach each other directly.

`kinswarm run` (the one-host plan built in code) guards its hub with per-run user/password credentials derived
from the run's secret (`local_plan(..., secret=)`): a process without the run's files cannot even join its
network, so it can declare no liveliness token and no subscriber on the run's keys.

Security, for anything beyond one machine: `tls` turns every endpoint into `tls/...` with the plan's
certificates (`kinswarm certs PLAN --out DIR` writes throwaway ones); `mtls` makes both ends present one,
so each process is known by its certificate's common name; `credentials` adds user/password; `acl`
makes every process drop what an identity may not say: only supervisors speak on ctl/** and fault/**,
the sim only on sim/obs, sim/task and the records, an agent only on its own command and the down/up keys
of its place in the tree (keys are addressed by the receiver: a/<x>/up is what x hears from its
children, so agent y publishes on a/<parent(y)>/up and a/<descendant>/down).
"""

from __future__ import annotations

import hashlib
import hmac
import ipaddress
import os
import socket
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from kinswarm.actors.files.config import AUTO_LISTEN, LEASE_RANGE_MS
from kinswarm.actors.runtime import LEASE_MS, NetSpec
from kinswarm.protocol.keys import agent_denied, check_id, every_run, sim_denied
from kinswarm.protocol.topology import Topology

MODES = ("peer", "client")
SUPERVISOR_PORT = 7447
_RUN_KEYS = {"file", "set"}  # [run]: the run file the leader runs, and --set overrides of it


class PlanError(ValueError):
    def __init__(self, source: str | Path, where: str, problem: str) -> None:
        super().__init__(f"{source}: {where}: {problem}")


@dataclass(frozen=True)
class Host:
    name: str
    address: str  # what the other hosts reach this one at (an IP or a DNS name)
    listen: str  # this host's supervisor endpoint
    actors: tuple[str, ...]  # "sim", "agents" (every agent not claimed elsewhere) or agent ids


@dataclass(frozen=True)
class Security:
    tls: bool = False
    mtls: bool = False
    certs: str = ""  # directory: ca.pem, <identity>.pem, <identity>.key
    credentials: str = ""  # TOML: [users] <identity> = "password"
    acl: bool = False
    # `kinswarm run`: every identity's password derived from the run's secret (run_password), the hub's dictionary
    # of them written into `net_dir` (the run's net/, owner-only). A plan's own `credentials` take precedence.
    secret: bytes = field(default=b"", repr=False)
    net_dir: str = ""

    @property
    def on(self) -> bool:
        return self.tls or bool(self.credentials) or self.acl


@dataclass(frozen=True)
class Plan:
    source: str
    name: str
    leader: str
    hosts: dict[str, Host]
    mode: str = "peer"
    lease_ms: int = LEASE_MS
    routers: tuple[str, ...] = ()
    security: Security = field(default_factory=Security)
    run_file: str = ""  # [run] file: the run file the leader's `kinswarm up` runs (absolute)
    run_sets: tuple[str, ...] = ()  # [run] set: overrides of it, as `--set` takes them
    digest: bytes = b""  # of the file's bytes: hosts must run the same plan

    # -- placement -------------------------------------------------------------------------------
    def placement(self, topo: Topology) -> dict[str, str]:
        """actor ident ("sim" or an agent id) -> host name; every actor placed exactly once."""
        where: dict[str, str] = {}
        catch_all = None
        for h in self.hosts.values():
            for a in h.actors:
                if a == "agents":
                    if catch_all is not None:
                        raise PlanError(self.source, f"host {h.name}.actors", f"'agents' is claimed by {catch_all} too")
                    catch_all = h.name
                    continue
                if a != "sim" and a not in topo.agents:
                    raise PlanError(
                        self.source, f"host {h.name}.actors", f"{a!r} is not an agent of {topo.source} ({topo.name})"
                    )
                if a in where:
                    raise PlanError(self.source, f"host {h.name}.actors", f"{a!r} is placed on {where[a]} too")
                where[a] = h.name
        for a in topo.order:
            if a not in where:
                if catch_all is None:
                    raise PlanError(self.source, "host.actors", f"agent {a!r} runs nowhere (name it, or use 'agents')")
                where[a] = catch_all
        if "sim" not in where:
            raise PlanError(self.source, "host.actors", "no host runs the simulator ('sim')")
        return where

    def identity(self, role: str, ident: str, host: str) -> str:
        """The name a process is known by (certificate common name, user name)."""
        if role == "supervisor":
            return f"sup-{host}"
        if role == "agent":
            return f"agent-{ident}"
        return role  # sim, controller, router

    def identities(self, topo: Topology) -> dict[str, str]:
        """Every identity of the plan -> the host it lives on (the router: every host may run it)."""
        where = self.placement(topo)
        out = {f"sup-{h}": h for h in self.hosts}
        for ident, h in where.items():
            out["sim" if ident == "sim" else f"agent-{ident}"] = h
        return out

    # -- the network ------------------------------------------------------------------------------
    def endpoint(self, address: str, port: int) -> str:
        host = f"[{address}]" if ":" in address else address
        return f"{'tls' if self.security.tls else 'tcp'}/{host}:{port}"

    def net(self, host: str, identity: str, supervisor: bool, topo: Topology) -> NetSpec:
        """The NetSpec of a process of `host`: its host's supervisor (`supervisor`) or an actor there."""
        h = self.hosts[host]
        if self.mode == "client":
            spec = NetSpec(mode="client", connect=self.routers, lease_ms=self.lease_ms, must_connect=True)
        elif supervisor:
            # Each host's supervisor is its host's Zenoh router and its actors are clients of it; the other
            # supervisors connect to the leader's. Routers forward and reconnect to a configured endpoint after a
            # cut; peers learned by gossip did not (1 cut in ~8 never healed). On one host too: gossiping peers
            # meshed (N^2 connections: 490 for 18 processes; a 16-agent chain could not start in 60 s), a hub
            # holds one connection per actor, at the cost of a relay on every hop (docs/architecture.md).
            several = len(self.hosts) > 1
            leader = (self.hosts[self.leader].listen,) if several and host != self.leader else ()
            spec = NetSpec(
                mode="router", listen=(h.listen,), connect=leader, lease_ms=self.lease_ms,
                close_blocked_ms=self.lease_ms if several else 0,
            )  # fmt: skip
        else:
            spec = NetSpec(mode="client", connect=(h.listen,), lease_ms=self.lease_ms, must_connect=True)
        return self.secure(spec, identity, topo)

    def secure(self, spec: NetSpec, identity: str, topo: Topology | None) -> NetSpec:
        """`spec` with this plan's security for `identity` (no ACL when `topo` is None: a first look only)."""
        s = self.security
        changes: dict[str, Any] = {}
        if s.tls:
            certs = Path(s.certs)
            changes.update(ca=str(certs / "ca.pem"), mtls=s.mtls)
            cert, key = certs / f"{identity}.pem", certs / f"{identity}.key"
            if cert.exists() and key.exists():
                changes.update(cert=str(cert), key=str(key))
            elif s.mtls or spec.listen:
                raise PlanError(
                    self.source, "security.certs", f"no certificate for {identity} in {certs} ({cert.name})"
                )
        if s.credentials:
            users = load_credentials(s.credentials, self.source)
            if identity not in users:
                raise PlanError(self.source, "security.credentials", f"no password for {identity} in {s.credentials}")
            changes.update(user=identity, password=users[identity], dictionary=dictionary_file(s.credentials, users))
        elif s.secret:
            changes.update(user=identity, password=run_password(s.secret, identity))
            if spec.listen and topo is not None:  # the hub: it checks everyone else
                users = {i: run_password(s.secret, i) for i in [*self.identities(topo), "controller"]}
                changes["dictionary"] = write_dictionary(Path(s.net_dir) / "hub.dictionary", users)
        if s.acl and topo is not None:
            changes["acl"] = acl(self, topo)
        return spec.with_(**changes)


def acl(plan: Plan, topo: Topology) -> dict[str, Any]:
    """Zenoh's access_control section: allow by default, deny each identity what it may not publish."""
    plan.placement(topo)  # the topology fits the plan
    by = "cert_common_names" if plan.security.mtls else "usernames"
    rules: list[dict[str, Any]] = []
    subjects: list[dict[str, Any]] = []
    policies: list[dict[str, Any]] = []

    def deny(who: str, keys: list[str]) -> None:
        rid = f"deny-{who}"
        rules.append(
            {
                "id": rid,
                "messages": ["put", "delete"],
                "flows": ["ingress"],
                "permission": "deny",
                "key_exprs": [every_run(k) for k in keys],
            }
        )
        subjects.append({"id": who, by: [who]})
        policies.append({"id": f"policy-{who}", "rules": [rid], "subjects": [who]})

    # every key is declared once with who publishes it (protocol/keys.py): the sim and each agent are denied the rest
    # (the sim may ask for a scenario's faults on fault/request, as a user's `kinswarm fault` does; no agent may)
    deny("sim", list(sim_denied()))
    for a in topo.order:
        deny(f"agent-{a}", list(agent_denied(topo, a)))
    return {"enabled": True, "default_permission": "allow", "rules": rules, "subjects": subjects, "policies": policies}


# -- credentials -------------------------------------------------------------------------------------
def load_credentials(path: str | Path, source: str | Path = "") -> dict[str, str]:
    try:
        data = tomllib.loads(Path(path).read_text())
    except (OSError, tomllib.TOMLDecodeError) as e:
        raise PlanError(source or path, "security.credentials", f"cannot read {path}: {e}") from None
    users = data.get("users")
    if not isinstance(users, dict) or not all(isinstance(v, str) and v for v in users.values()):
        raise PlanError(path, "users", 'expected a table of identity = "password"')
    return users


def dictionary_file(credentials: str | Path, users: dict[str, str]) -> str:
    """Zenoh's usrpwd dictionary (user:password lines) beside the credentials file, written once, 0600."""
    return write_dictionary(Path(credentials).with_suffix(".dictionary"), users)


def write_dictionary(path: Path, users: dict[str, str]) -> str:
    """Zenoh's usrpwd dictionary (user:password lines) at `path`, written when it differs, owner-only."""
    text = "".join(f"{u}:{p}\n" for u, p in sorted(users.items()))
    if not path.exists() or path.read_text() != text:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        with os.fdopen(fd, "w") as f:
            f.write(text)
    return str(path)


def run_password(secret: bytes, identity: str) -> str:
    """A one-host run's password for `identity`: a MAC of it under the run's secret (config.json, owner-only), so
    whoever may read the run's files may join its network and nobody else; no password file to keep in step."""
    return hmac.new(secret, b"kinswarm-usrpwd/" + identity.encode(), hashlib.sha256).hexdigest()[:32]


# -- loading -----------------------------------------------------------------------------------------
def free_endpoint(address: str = "127.0.0.1") -> str:
    """A port nobody listens on now: bound, read and let go. Another program may take it before the supervisor
    binds it (a few ms later); launch.py then picks again."""
    with socket.socket() as s:
        s.bind((address, 0))
        return f"tcp/{address}:{s.getsockname()[1]}"


def local_plan(listen: str, lease_ms: int = LEASE_MS, secret: bytes = b"", net_dir: str | Path = "") -> Plan:
    """The embedded default (deploy/local.toml): one host, every actor on it, clients of the supervisor's hub on
    loopback. `listen` "auto": a free port, picked here (the actors are told the endpoint the plan holds).
    `secret` (the run's, with its `net_dir`): the hub admits only the run's own identities (Security.secret)."""
    if listen == AUTO_LISTEN:
        listen = free_endpoint()
    host = Host(name="local", address="127.0.0.1", listen=listen, actors=("sim", "agents"))
    security = Security(secret=secret, net_dir=str(net_dir)) if secret else Security()
    return Plan(
        source="(local)", name="local", leader="local", hosts={"local": host}, lease_ms=lease_ms, security=security
    )


def load_plan(path: str | Path) -> Plan:
    path = Path(path)
    try:
        raw = path.read_bytes()
        data = tomllib.loads(raw.decode())
    except OSError as e:
        raise PlanError(path, "file", f"cannot read: {e.strerror}") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise PlanError(path, "file", f"not valid TOML: {e}") from None
    src = str(path)
    known = {"plan", "zenoh", "security", "host", "run"}
    for k in data:
        if k not in known:
            raise PlanError(src, k, f"unknown table (expected {', '.join(sorted(known))})")
    p = _table(src, data, "plan")
    _only(src, "plan", p, {"name", "leader"})
    name = _id(src, "plan.name", p.get("name"))
    z = _table(src, data, "zenoh", required=False)
    _only(src, "zenoh", z, {"mode", "lease_ms", "routers", "multicast_scouting"})
    mode = z.get("mode", "peer")
    if mode not in MODES:
        raise PlanError(src, "zenoh.mode", f"{mode!r} is not one of {', '.join(MODES)}")
    lease = z.get("lease_ms", LEASE_MS)
    lo, hi = LEASE_RANGE_MS
    if isinstance(lease, bool) or not isinstance(lease, int) or not lo <= lease <= hi:
        raise PlanError(src, "zenoh.lease_ms", f"expected an integer in [{lo}, {hi}], got {lease!r}")
    if z.get("multicast_scouting", False) is not False:
        raise PlanError(src, "zenoh.multicast_scouting", "must be false: peers meet only through the plan's endpoints")
    routers = z.get("routers", [])
    if not isinstance(routers, list) or not all(isinstance(r, str) and "/" in r for r in routers):
        raise PlanError(src, "zenoh.routers", f"expected a list of endpoints like tcp/10.0.0.3:7447, got {routers!r}")
    if mode == "client" and not routers:
        raise PlanError(src, "zenoh.routers", "mode = 'client' needs at least one router endpoint")
    sec = _security(src, path.parent, _table(src, data, "security", required=False))
    hosts_raw = data.get("host")
    if not isinstance(hosts_raw, list) or not hosts_raw:
        raise PlanError(src, "host", "expected at least one [[host]] table")
    hosts: dict[str, Host] = {}
    for i, h in enumerate(hosts_raw):
        at = f"host[{i}]"
        if not isinstance(h, dict):
            raise PlanError(src, at, "expected a table")
        _only(src, at, h, {"name", "address", "listen", "actors"})
        hname = _id(src, f"{at}.name", h.get("name"))
        if hname in hosts:
            raise PlanError(src, f"{at}.name", f"host {hname!r} is named twice")
        address = h.get("address")
        if not isinstance(address, str) or not address:
            raise PlanError(src, f"{at}.address", "expected the address other hosts reach this one at")
        _check_address(src, f"{at}.address", address)
        listen = h.get("listen", f"{'tls' if sec.tls else 'tcp'}/{address}:{SUPERVISOR_PORT}")
        if not isinstance(listen, str) or "/" not in listen:
            raise PlanError(src, f"{at}.listen", f"expected an endpoint like tcp/{address}:7447, got {listen!r}")
        if sec.tls and not listen.startswith("tls/"):
            raise PlanError(src, f"{at}.listen", f"security.tls is on: expected tls/..., got {listen!r}")
        actors = h.get("actors")
        if not isinstance(actors, list) or not all(isinstance(a, str) for a in actors):
            raise PlanError(src, f"{at}.actors", 'expected a list like ["sim", "a1"] or ["agents"]')
        hosts[hname] = Host(name=hname, address=address, listen=listen, actors=tuple(actors))
    leader = p.get("leader")
    if leader not in hosts:
        raise PlanError(src, "plan.leader", f"{leader!r} is not one of the hosts ({', '.join(hosts)})")
    run = _table(src, data, "run", required=False)
    _only(src, "run", run, _RUN_KEYS)
    run_file = run.get("file", "")
    if not isinstance(run_file, str):
        raise PlanError(src, "run.file", f"expected the path of a run file, got {run_file!r}")
    sets = run.get("set", [])
    if not isinstance(sets, list) or not all(isinstance(x, str) for x in sets):
        raise PlanError(src, "run.set", f'expected a list like ["run.epochs=5"], got {sets!r}')
    return Plan(
        source=src,
        name=name,
        leader=leader,
        hosts=hosts,
        mode=mode,
        lease_ms=lease,
        routers=tuple(routers),
        security=sec,
        run_file=str((path.parent / run_file).resolve()) if run_file else "",
        run_sets=tuple(sets),
        digest=hashlib.blake2b(raw, digest_size=32).digest(),
    )


def _security(src: str, base: Path, s: dict[str, Any]) -> Security:
    _only(src, "security", s, {"tls", "mtls", "certs", "credentials", "acl"})
    for k in ("tls", "mtls", "acl"):
        if not isinstance(s.get(k, False), bool):
            raise PlanError(src, f"security.{k}", f"expected true or false, got {s[k]!r}")
    tls, mtls, use_acl = s.get("tls", False), s.get("mtls", False), s.get("acl", False)
    certs = s.get("certs", "")
    credentials = s.get("credentials", "")
    for k, v in (("certs", certs), ("credentials", credentials)):
        if not isinstance(v, str):
            raise PlanError(src, f"security.{k}", f"expected a path, got {v!r}")
    if mtls and not tls:
        raise PlanError(src, "security.mtls", "needs tls = true")
    if tls and not certs:
        raise PlanError(
            src, "security.certs", "tls = true needs a certificate directory (kinswarm certs PLAN --out DIR)"
        )
    if use_acl and not (mtls or credentials):
        raise PlanError(src, "security.acl", "needs identities: mtls = true or credentials")
    return Security(
        tls=tls,
        mtls=mtls,
        certs=str((base / certs).resolve()) if certs else "",
        credentials=str((base / credentials).resolve()) if credentials else "",
        acl=use_acl,
    )


def _table(src: str, data: dict[str, Any], name: str, required: bool = True) -> dict[str, Any]:
    t = data.get(name)
    if t is None and not required:
        return {}
    if not isinstance(t, dict):
        raise PlanError(src, name, f"expected a [{name}] table")
    return t


def _only(src: str, at: str, t: dict[str, Any], allowed: set[str]) -> None:
    for k in t:
        if k not in allowed:
            raise PlanError(src, f"{at}.{k}", f"unknown field (expected one of {', '.join(sorted(allowed))})")


def _id(src: str, at: str, value: Any) -> str:
    try:
        return check_id(at, value)
    except ValueError as e:
        raise PlanError(src, at, str(e)) from None


def _check_address(src: str, at: str, address: str) -> None:
    try:
        ipaddress.ip_address(address)
    except ValueError:
        if not all(part and part.replace("-", "").isalnum() for part in address.split(".")):
            raise PlanError(src, at, f"{address!r} is neither an IP address nor a host name") from None
