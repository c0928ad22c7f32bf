"""Several hosts: what `kinswarm up`, `down`, `router` and `certs` do beyond one host's supervisor.

`up` on the leading host resolves the run and serves it (a Setup signed with the plan's digest); `up` on
every other host fetches it, writes its own copy of the run directory (config, scenario) and
runs its share under its own supervisor. `down` asks the leader to stop (a Stop on ctl/stop); the leader
tells every host.
"""

from __future__ import annotations

import asyncio
import dataclasses
import logging
import os
import secrets
import signal
import subprocess
import time
from pathlib import Path

from kinswarm.actors.deploy.plan import Plan, PlanError, load_credentials
from kinswarm.actors.files.config import RunConfig, config_from_json
from kinswarm.actors.files.rundir import check_out
from kinswarm.actors.runtime import NetSpec, Node, open_session
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys, every_run, run_of, shape
from kinswarm.protocol.messages import Setup, Stop
from kinswarm.protocol.topology import Topology

log = logging.getLogger("kinswarm.deploy")


class DeployError(RuntimeError):
    pass


def control_net(plan: Plan, host: str, topo: Topology | None) -> NetSpec:
    """A short-lived tool on `host` (fault, status, down, a follower's first look): the host supervisor's
    identity, connecting to its endpoint (or the routers), listening on nothing."""
    if plan.mode == "client":
        spec = NetSpec(mode="client", connect=plan.routers, lease_ms=plan.lease_ms, must_connect=True)
    else:  # several hosts: a client of the host's router (its supervisor); one host: a peer
        mode = "client" if len(plan.hosts) > 1 else "peer"
        spec = NetSpec(mode=mode, connect=(plan.hosts[host].listen,), lease_ms=plan.lease_ms, must_connect=True)
    return plan.secure(spec, plan.identity("supervisor", "", host), topo)


def fetch_setup(plan: Plan, host: str, wait_s: float) -> tuple[str, Setup]:
    """Ask the leader for its run (polling until it answers or `wait_s` passes): (run id, Setup)."""
    leader = plan.hosts[plan.leader]
    if plan.mode == "peer":  # a peer retries the leader's endpoint in the background, where a client gives up
        spec = control_net(plan, host, None).with_(mode="peer", connect=(leader.listen,), must_connect=False)
    else:
        spec = control_net(plan, host, None).with_(must_connect=False)
    session = open_session(spec)
    deadline = time.monotonic() + wait_s
    told = False
    try:
        while True:
            for reply in session.get(every_run(shape("setup", plan.name)), timeout=2.0):
                if reply.ok is None or (run := run_of(str(reply.ok.key_expr))) is None:
                    continue
                try:
                    return run, codec.decode(reply.ok.payload.to_bytes(), Setup, run, plan.digest)
                except codec.DecodeError as e:
                    raise DeployError(
                        f"the leader ({plan.leader}) answered for run {run} but its plan differs from {plan.source} "
                        f"({e}): run every host with the same plan file"
                    ) from None
            if time.monotonic() > deadline:
                raise DeployError(f"no answer from the leader {plan.leader} at {leader.listen} within {wait_s:.0f} s")
            if not told:
                told = True
                print(f"kinswarm: waiting for the leader ({plan.leader}, {leader.listen}) to start the run ...")
            time.sleep(0.5)
    finally:
        session.close()


def follower_config(setup: Setup, host: str, plan: Plan, out: Path | None) -> tuple[RunConfig, Topology]:
    """This host's copy of the leader's run: same settings and key, local paths."""
    leader_cfg = config_from_json(setup.config, f"the leader's run of plan {plan.name}")
    run_dir = (out or Path("runs") / leader_cfg.run_id).resolve()
    check_out(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    scenario = None
    if setup.scenario:
        scenario = run_dir / "scenario.toml"
        scenario.write_text(setup.scenario)
    cfg = dataclasses.replace(
        leader_cfg,
        out=str(run_dir),
        scenario=str(scenario) if scenario else None,
        from_dir=None,
        listen=plan.hosts[host].listen,
        placement="process",
    )
    return cfg, cfg.topo()


async def down(plan: Plan, host: str, wait_s: float = 10.0) -> str:
    """Ask the running swarm of `plan` to stop, until its leader has left; returns its run id."""
    run, setup = await asyncio.to_thread(fetch_setup, plan, host, wait_s)
    leader_cfg = config_from_json(setup.config, f"the leader's run of plan {plan.name}")
    key, topo = leader_cfg.key, leader_cfg.topo()
    spec = control_net(plan, host, topo)
    if plan.mode == "peer":  # straight to the leader, who tells everyone: a Stop only our own host heard
        spec = spec.with_(connect=tuple(dict.fromkeys((plan.hosts[plan.leader].listen, *spec.connect))))
    session = open_session(spec)
    node = Node(session, Keys(run), "cli", f"down-{os.getpid()}", key)
    leader = node.keys.alive("supervisor", "main")
    try:
        stop = node.keys.ctl("stop")
        await node.wait_matched([stop], timeout=5.0)
        deadline = time.monotonic() + wait_s
        while time.monotonic() < deadline:
            node.send(stop, Stop(reason=f"kinswarm down from {host}"))
            await asyncio.sleep(1.0)
            if not list(session.liveliness().get(leader, timeout=1.0)):
                return run
        raise DeployError(f"run {run}: the leader ({plan.leader}) is still there {wait_s:.0f} s after the stop")
    finally:
        node.close()
        session.close()


def run_router(listen: list[str], plan: Plan | None, topo: Topology | None) -> None:
    """A Zenoh router in this process until SIGINT/SIGTERM (no zenohd is installable here)."""
    spec = NetSpec(mode="router", listen=tuple(listen), lease_ms=plan.lease_ms if plan else 1000)
    if plan is not None:
        spec = plan.secure(spec, "router", topo)
    session = open_session(spec)
    print(f"kinswarm router: listening on {', '.join(listen)} (Ctrl-C to stop)", flush=True)
    stop = False

    def on_signal(*_: object) -> None:
        nonlocal stop
        stop = True

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        while not stop:
            time.sleep(0.2)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        session.close()


# -- certificates for trials and tests ----------------------------------------------------------------
def write_certs(plan: Plan, topo: Topology, out: Path, days: int = 30) -> list[Path]:
    """A throwaway CA and a certificate per identity of the plan (CN = identity, SANs = its host's address),
    plus credentials.toml (a random password per identity). Private keys are owner-only."""
    out.mkdir(parents=True, exist_ok=True)
    ca_key, ca = out / "ca.key", out / "ca.pem"
    _openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", str(ca_key))
    _openssl(
        "req", "-x509", "-new", "-key", str(ca_key), "-sha256", "-days", str(days), "-subj",
        f"/CN=kinswarm-ca-{plan.name}", "-addext", "basicConstraints=critical,CA:TRUE",
        "-addext", "keyUsage=critical,keyCertSign,cRLSign", "-out", str(ca),
    )  # fmt: skip
    written = [ca]
    idents = plan.identities(topo)
    idents["router"] = ""
    for ident, host in idents.items():
        names = {"DNS:localhost", "IP:127.0.0.1"}
        if host:
            names.add(_san(plan.hosts[host].address))
        else:  # the router: wherever the plan's routers are
            names |= {_san(r.split("/", 1)[1].rsplit(":", 1)[0].strip("[]")) for r in plan.routers}
        key, csr, pem = out / f"{ident}.key", out / f"{ident}.csr", out / f"{ident}.pem"
        ext = out / f"{ident}.ext"
        ext.write_text(
            f"subjectAltName={','.join(sorted(names))}\nbasicConstraints=CA:FALSE\n"
            "keyUsage=critical,digitalSignature\nextendedKeyUsage=serverAuth,clientAuth\n"
        )
        _openssl("genpkey", "-algorithm", "EC", "-pkeyopt", "ec_paramgen_curve:P-256", "-out", str(key))
        _openssl("req", "-new", "-key", str(key), "-subj", f"/CN={ident}", "-out", str(csr))
        _openssl(
            "x509", "-req", "-in", str(csr), "-CA", str(ca), "-CAkey", str(ca_key), "-CAcreateserial",
            "-days", str(days), "-sha256", "-extfile", str(ext), "-out", str(pem),
        )  # fmt: skip
        csr.unlink()
        ext.unlink()
        written.append(pem)
    creds = out / "credentials.toml"
    lines = ["# kinswarm certs: one password per identity (user/password authentication). Keep it secret.", "[users]"]
    lines += [f'"{ident}" = "{secrets.token_urlsafe(18)}"' for ident in idents]
    fd = os.open(creds, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write("\n".join(lines) + "\n")
    load_credentials(creds)
    for p in out.glob("*.key"):
        p.chmod(0o600)
    written.append(creds)
    return written


def _san(address: str) -> str:
    import ipaddress

    try:
        ipaddress.ip_address(address)
        return f"IP:{address}"
    except ValueError:
        return f"DNS:{address}"


def _openssl(*args: str) -> None:
    try:
        r = subprocess.run(["openssl", *args], capture_output=True, text=True, timeout=60)
    except FileNotFoundError:
        raise DeployError("openssl not found: install it, or bring your own certificates (docs/deploy.md)") from None
    if r.returncode != 0:
        raise DeployError(f"openssl {args[0]} failed: {r.stderr.strip()[-400:]}")


__all__ = [
    "DeployError",
    "PlanError",
    "control_net",
    "down",
    "fetch_setup",
    "follower_config",
    "run_router",
    "write_certs",
]
