"""Talking to a running swarm from outside it: a short-lived member of the run (`Client`) that asks its supervisor for
a fault and reads the reply, or reads the status it publishes; the run's config, read from its directory; a fault
checked before it is sent. What `kinswarm fault` and `kinswarm status` are made of (actors/cli/control.py), and what an
experiment or a benchmark sends a fault with, as the command line does.

The client joins the run through the endpoint the supervisor listens on and signs its messages with the run's key,
read from the run directory's config.json (owner-only): whoever can read that file may inject faults; nobody else on
the network can. Light on purpose, as the commands' lean path needs: Zenoh, the codec, the keys and the run's config,
no numpy, learner, report or launcher.
"""

from __future__ import annotations

import os
import secrets
import time
from collections.abc import Callable
from pathlib import Path

from kinswarm.actors.files.config import ConfigError, RunConfig, load_run_config
from kinswarm.actors.runtime import NetSpec, Node, open_session
from kinswarm.actors.runtime.net import zenoh_reason
from kinswarm.protocol.faults import check_fault
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Fault, FaultReply, JointStatus, SwarmStatus


class ControlError(RuntimeError):
    pass


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

    async def statuses(self, timeout: float = 5.0, keep_waiting: Callable[[float], bool] | None = None):  # noqa: ANN201 -- an async iterator of (status, joints)
        """The run's statuses as they come. `timeout` seconds without one end the wait, unless `keep_waiting(waited)`
        says to go on (a run that is there but busy: starting, or on a loaded machine)."""
        k = self.node.keys
        self.node.listen(k.metrics("status"))
        self.node.listen(k.metrics("joints"))
        joints: JointStatus | None = None
        waited = 0.0
        while True:
            try:
                key, payload = await self.node.recv(timeout=timeout)
            except TimeoutError:
                waited += timeout
                if keep_waiting is not None and keep_waiting(waited):
                    continue
                raise ControlError(f"no status from run {k.run} at {self.connect} within {waited:g} s") from None
            waited = 0.0
            if key == k.metrics("joints"):
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
