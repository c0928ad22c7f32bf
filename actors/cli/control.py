"""Talking to a running swarm from another terminal: `kinswarm fault` and `kinswarm status`.

The client joins the run through the endpoint the supervisor listens on and signs its messages with
the run's key, read from the run directory's config.json (owner-only): whoever can read that file may
inject faults; nobody else on the network can.
"""

from __future__ import annotations

import math
import os
import re
import secrets
import sys
import time
from pathlib import Path

from kinswarm.actors.run.config import ConfigError, RunConfig, load_run_config
from kinswarm.actors.runtime import NetSpec, Node, open_session
from kinswarm.actors.runtime.net import zenoh_reason
from kinswarm.protocol.faults import check_fault
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Fault, FaultReply, JointStatus, SwarmStatus

_DURATION = re.compile(r"^\s*([0-9]*\.?[0-9]+)\s*(ms|s|m|min|h)?\s*$")
_UNIT = {"ms": 0.001, "s": 1.0, None: 1.0, "m": 60.0, "min": 60.0, "h": 3600.0}


class ControlError(RuntimeError):
    pass


def parse_duration(text: str) -> float:
    """`5s`, `500ms`, `2m`, `1.5` (seconds) -> seconds."""
    m = _DURATION.match(text)
    if not m or float(m.group(1)) <= 0:
        raise ValueError(f"--for: expected a duration > 0 like 5s, 500ms or 2m, got {text!r}")
    return float(m.group(1)) * _UNIT[m.group(2)]


def tool_net(run_dir: Path, cfg: RunConfig, connect: str | None) -> NetSpec:
    """How a tool reaches the run: the NetSpec its supervisor wrote (identity, TLS) or its endpoint."""
    path = run_dir / "net" / "cli.json"
    net = NetSpec.from_json(path.read_text()) if path.exists() else NetSpec(connect=(cfg.listen,), must_connect=True)
    return net.with_(connect=(connect,)) if connect else net


def run_config_at(run_dir: Path) -> RunConfig:
    path = run_dir / "config.json"
    if not path.exists():
        raise ControlError(f"{path} not found: it holds the run's key; pass --run-dir DIR (the run's --out)")
    return load_run_config(path)


def run_config(run_id: str, run_dir: Path | None) -> RunConfig:
    path = (run_dir or Path("runs") / run_id) / "config.json"
    cfg = run_config_at(path.parent)
    if cfg.run_id != run_id:
        raise ConfigError(f"{path} belongs to run {cfg.run_id!r}, not {run_id!r}")
    return cfg


class Client:
    """A short-lived member of a run: one session, one node, closed on exit."""

    def __init__(self, cfg: RunConfig, connect: str | NetSpec) -> None:
        """`connect`: an endpoint, or the NetSpec the run wrote for its tools (`<run>/net/cli.json`)."""
        self.cfg = cfg
        self.net = connect if isinstance(connect, NetSpec) else NetSpec(connect=(connect,), must_connect=True)
        self.connect = ", ".join(self.net.connect)

    async def __aenter__(self) -> Client:
        try:
            self.session = open_session(self.net)
        except Exception as e:
            raise ControlError(f"cannot reach run {self.cfg.run_id} at {self.connect}: {zenoh_reason(e)}") from None
        self.node = Node(self.session, Keys(self.cfg.run_id), "cli", f"cli-{os.getpid()}", self.cfg.key)
        return self

    async def __aexit__(self, *exc: object) -> None:
        self.node.close()
        self.session.close()

    async def fault(self, f: Fault, timeout: float = 5.0) -> FaultReply:
        k = self.node.keys
        self.node.listen(k.rep("fault", f.id))
        try:
            await self.node.wait_matched([k.fault("request")], timeout=timeout)
        except TimeoutError:
            raise ControlError(f"no supervisor of run {k.run} answers at {self.connect}") from None
        self.node.send(k.fault("request"), f)
        deadline = time.monotonic() + timeout
        while (remaining := deadline - time.monotonic()) > 0:
            try:
                key, payload = await self.node.recv(timeout=remaining)
            except TimeoutError:
                break
            reply = self.node.decode(key, payload, FaultReply)
            if reply is not None and reply.id == f.id:
                return reply
        raise ControlError(f"the supervisor of run {k.run} did not answer within {timeout:g} s")

    async def statuses(self, timeout: float = 5.0):  # noqa: ANN201 -- an async iterator of (status, joints)
        k = self.node.keys
        self.node.listen(k.metrics("status"))
        self.node.listen(k.metrics("joints"))
        joints: JointStatus | None = None
        while True:
            try:
                key, payload = await self.node.recv(timeout=timeout)
            except TimeoutError:
                raise ControlError(f"no status from run {k.run} at {self.connect} within {timeout:g} s") from None
            if key.endswith("/metrics/joints"):
                joints = self.node.decode(key, payload, JointStatus) or joints
            elif (status := self.node.decode(key, payload, SwarmStatus)) is not None:
                yield status, joints


def make_fault(
    fault: str,
    targets: list[str],
    *,
    seconds: float | None = None,
    steps: int | None = None,
    rate: float | None = None,
    ms: float | None = None,
    amplitude_deg: float | None = None,
    factor: float | None = None,
    degrees: float | None = None,
    robot: int | None = None,
) -> Fault:
    f = Fault(
        id=f"cli-{secrets.token_hex(4)}",
        fault=fault,
        targets=targets,
        seconds=seconds,
        steps=steps,
        rate=rate,
        ms=ms,
        amplitude_deg=amplitude_deg,
        factor=factor,
        degrees=degrees,
        robot=robot,
    )
    error = check_fault(f)
    if error:
        raise ControlError(error)
    return f


def render(status: SwarmStatus, joints: JointStatus | None, run_id: str) -> str:
    """The `kinswarm status` table (epochs counted from 0, as metrics.jsonl and events.jsonl count them)."""
    head = f"run {run_id}  epoch {status.epoch} of 0-{status.epochs - 1}"
    if joints is not None and joints.epoch == status.epoch:
        head += f"  step {joints.step}"
    cols = ("actor", "role", "alive", "pid", "host", "restarts", "joint", "action", "faults")
    rows = []
    for ident, role in status.role.items():
        q = joints.q.get(ident) if joints is not None else None
        d = joints.delta.get(ident) if joints is not None else None
        rows.append(
            (
                ident,
                role,
                "yes" if status.alive.get(ident) else "NO",
                str(status.pid.get(ident) or "-"),
                status.host.get(ident, "-"),
                str(status.restarts.get(ident, 0)),
                "-" if q is None else f"{math.degrees(q):8.2f}°",
                "-" if d is None else f"{math.degrees(d):+.2f}°",
                "; ".join(status.faults.get(ident, [])) or "-",
            )
        )
    widths = [max(len(c), *(len(r[i]) for r in rows)) for i, c in enumerate(cols)]
    line = "  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True))
    body = ["  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join([head, line, *body])


async def show_status(cfg: RunConfig, connect: str | NetSpec, watch: bool, run_dir: Path) -> None:
    """Print the status (with the joints: the first one or two statuses may come before the sim's readings); with
    `watch`, redraw it until the run ends, and say how it ended."""
    if (run_dir / "summary.json").exists():
        print(ended(run_dir, cfg.run_id))
        return
    async with Client(cfg, connect) as c:
        first = time.monotonic()
        try:
            async for status, joints in c.statuses():
                table = render(status, joints, cfg.run_id)
                if not watch:
                    if joints is None and time.monotonic() - first < 2.0:
                        continue  # the sim's readings come twice a second
                    print(table)
                    return
                sys.stdout.write("\x1b[H\x1b[2J" + table + "\n")  # clear and redraw, like `top`
                sys.stdout.flush()
        except ControlError:
            if (run_dir / "summary.json").exists():  # it ended while we watched
                print(ended(run_dir, cfg.run_id))
                return
            raise


def ended(run_dir: Path, run_id: str) -> str:
    """One line on a finished run, from its summary."""
    import json

    try:
        s = json.loads((run_dir / "summary.json").read_text())
    except (OSError, ValueError):
        return f"run {run_id} has ended ({run_dir / 'summary.json'})"
    how = "failed: " + s["error"] if s.get("error") else "was interrupted" if s.get("interrupted") else "finished"
    fe = s.get("final_error") or []
    last = f", final error {fe[-1]:.3f}" if fe else ""
    return f"run {run_id} {how} ({len(fe)} epochs{last}; {run_dir / 'summary.json'})"
