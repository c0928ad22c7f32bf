"""Actor entry point: `python -m kinswarm.actors.run.main ROLE ID CONFIG --net NETSPEC.json [--restore]`.

This is the one spawn path of the `process` placement (the supervisor starts it with spawn semantics:
a fresh interpreter, the Zenoh session opened inside the child). `build_actor` is shared with the
`single` placement, which runs the same actors as tasks over one session.
"""

from __future__ import annotations

import ctypes
import os
import signal
import sys


def _die_with_parent(parent: int) -> None:
    """Linux: get SIGTERM when the supervisor dies, even by SIGKILL, so no actor is orphaned. Done
    before the heavy imports; a supervisor that died before this point is caught by the ppid check."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGTERM)  # PR_SET_PDEATHSIG
    except OSError:
        pass
    if os.getppid() != parent:
        os._exit(3)


if __name__ == "__main__" and "--parent" in sys.argv:
    _die_with_parent(int(sys.argv[sys.argv.index("--parent") + 1]))

import argparse  # noqa: E402
import asyncio  # noqa: E402
import logging  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Protocol  # noqa: E402

from kinswarm.actors.run.config import RunConfig, load_run_config  # noqa: E402
from kinswarm.actors.runtime import NetSpec, Node, open_session, setup_logging  # noqa: E402
from kinswarm.actors.runtime.heap import freeze_setup  # noqa: E402
from kinswarm.protocol.keys import Keys  # noqa: E402
from kinswarm.protocol.topology import Topology  # noqa: E402

ROLES = ("agent", "sim", "controller")
SUPERVISOR_GRACE_S = 3.0  # how long an actor waits for a vanished supervisor token to come back


class Actor(Protocol):
    async def run(self) -> None: ...


def build_actor(role: str, ident: str, cfg: RunConfig, topo: Topology, node: Node, restore: bool = False) -> Actor:
    """`restore`: a restart -- resume from this run's newest good checkpoint instead of the start."""
    if role == "agent":
        from kinswarm.actors.agent.actor import Agent
        from kinswarm.actors.agent.fleet import FleetAgent

        agent = FleetAgent(cfg, topo, ident, node) if cfg.fleet > 1 else Agent(cfg, topo, ident, node)
        if restore:
            agent.memory.resume(Path(cfg.out) / "agents")
        elif cfg.from_dir:
            agent.memory.restore(Path(cfg.from_dir) / "agents")
        return agent
    if role == "sim":  # imported lazily: agent processes never load PyBullet
        from kinswarm.actors.simulator.actor import SimActor
        from kinswarm.actors.simulator.fleet import FleetSim

        return FleetSim(cfg, topo, node) if cfg.fleet > 1 else SimActor(cfg, topo, node)
    if role == "controller":
        from kinswarm.actors.simulator.controller import BaselineController

        return BaselineController(cfg, topo, node)
    raise ValueError(f"unknown role {role!r}; expected one of {', '.join(ROLES)}")


async def _serve(
    role: str, ident: str, cfg: RunConfig, net: NetSpec, parent_pid: int, restore: bool, supervisor: str
) -> None:
    log = logging.getLogger(f"kinswarm.{role}.{ident}")
    topo = cfg.topo()
    session = open_session(net)
    loop = asyncio.get_running_loop()
    task = asyncio.current_task()
    assert task is not None
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, task.cancel)
    node = Node(session, Keys(cfg.run_id), role, ident, cfg.key)
    # The supervisor's liveliness token staying away (it died, or its host is gone) ends this actor. A
    # grace period lets an actor that was frozen past the lease (SIGSTOP) rejoin once its session reconnects.
    present = {"supervisor": True}
    lost = asyncio.Event()

    def on_supervisor(sample: Any) -> None:  # zenoh thread
        present["supervisor"] = sample.kind == sample.kind.PUT
        if not present["supervisor"]:
            try:
                loop.call_soon_threadsafe(lost.set)
            except RuntimeError:  # the actor's loop is already closed: it is leaving anyway
                pass

    async def supervisor_gone() -> None:
        while True:
            await lost.wait()
            lost.clear()
            await asyncio.sleep(SUPERVISOR_GRACE_S)
            if present["supervisor"]:
                continue
            if os.getppid() == parent_pid:
                # Our parent is the supervisor and it still runs: a lease missed on an overloaded machine
                # (seen at load 40 on 2 cores), not a lost supervisor. Its death would reach us by signal.
                log.warning("the supervisor's token is gone but its process %d runs; staying", parent_pid)
                continue
            return

    watch = session.liveliness().declare_subscriber(node.keys.alive("supervisor", supervisor), on_supervisor)
    try:
        actor = build_actor(role, ident, cfg, topo, node, restore)
        freeze_setup()  # this process runs this one actor: its setup's objects leave the collector's walks
        async with asyncio.TaskGroup() as tg:
            run = tg.create_task(actor.run())
            gone = tg.create_task(supervisor_gone())
            done, _ = await asyncio.wait({run, gone}, return_when=asyncio.FIRST_COMPLETED)
            if gone in done:
                log.warning("supervisor is gone; leaving")
            run.cancel()
            gone.cancel()
    except asyncio.CancelledError:
        log.info("signal received; leaving")
    finally:
        watch.undeclare()
        node.close()
        session.close()
        if os.getppid() != parent_pid:
            log.warning("parent %d is gone", parent_pid)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="kinswarm-actor", description=__doc__)
    p.add_argument("role", choices=ROLES)
    p.add_argument("ident")
    p.add_argument("config", type=Path)
    p.add_argument("--net", type=Path, required=True, help="the NetSpec (JSON) this actor's session opens with")
    p.add_argument("--parent", type=int, default=None, help="the supervisor's pid: leave when it is gone")
    p.add_argument("--supervisor", default="main", help="the id of the supervisor that spawned this actor")
    p.add_argument("--restore", action="store_true", help="a restart: resume from the run's newest checkpoint")
    p.add_argument("--log-level", default="INFO")
    a = p.parse_args(argv)
    parent = a.parent if a.parent is not None else os.getppid()
    setup_logging(a.log_level)
    sys.setswitchinterval(0.0005)  # zenoh callbacks need the GIL promptly (shared notes: p99 10 -> 3 ms)
    try:
        # its files are in the directory of the config.json it was handed (moved or copied since, perhaps)
        cfg = load_run_config(a.config).located(a.config.parent)
        net = NetSpec.from_json(a.net.read_text())
        asyncio.run(_serve(a.role, a.ident, cfg, net, parent, a.restore, a.supervisor))
    except Exception as e:  # a clear last word in the actor's log; the supervisor reports it
        logging.getLogger(f"kinswarm.{a.role}.{a.ident}").error("failed: %s", _cause(e))
        return 2
    return 0


def _cause(e: BaseException) -> str:
    """`Type: message` of the errors that ended the actor (a TaskGroup's group unwrapped to its leaves)."""
    if isinstance(e, BaseExceptionGroup):
        return "; ".join(_cause(x) for x in e.exceptions)
    return f"{type(e).__name__}: {e}"


if __name__ == "__main__":
    sys.exit(main())
