"""Where actors live. The wire, the messages and the lockstep are the same in both placements, so the same seed
gives the same run:
  process  one OS process per actor (fresh interpreters: spawn, never fork), each with its own Zenoh session
           connected to the supervisor's endpoint;
  single   every actor a task in this process, sharing the supervisor's session.
An actor's end is an event, not a poll: a process's pidfd becomes readable when it exits, a task calls back when it
is done; either posts an `EXIT` item into the supervisor's mailbox (`attach`), where it is handled in order.
"""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
import threading
from collections.abc import Callable
from pathlib import Path

import zenoh
from kinswarm.actors.run.config import RunConfig
from kinswarm.actors.run.main import build_actor
from kinswarm.actors.runtime import Node
from kinswarm.protocol.faults import PROCESS_FAULTS
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.topology import Topology

ActorId = tuple[str, str]  # (role, ident)
EXIT = "__exit__"  # mailbox key of an actor's end: payload b"role/ident/how"
Push = Callable[[str, bytes], None]


def exit_item(actor: ActorId, how: str) -> bytes:
    return f"{actor[0]}/{actor[1]}/{how}".encode()


def parse_exit(payload: bytes) -> tuple[ActorId, str]:
    role, ident, how = payload.decode().split("/", 2)
    return (role, ident), how


class ProcessPlacement:
    """One OS process per actor; stdout/stderr of each go to `<out>/logs/<ident>.log`."""

    supports = PROCESS_FAULTS

    def __init__(
        self, config_path: Path, nets: Callable[[str, str], Path], logs: Path, supervisor: str = "main"
    ) -> None:
        """`nets(role, ident)`: the file of the NetSpec that actor's session is opened with; `supervisor`: the
        id of the supervisor the actors watch (they leave when it is gone for good)."""
        self.config_path, self.nets, self.logs, self.supervisor = config_path, nets, logs, supervisor
        self.procs: dict[ActorId, subprocess.Popen] = {}
        self._ended: dict[int, asyncio.Future[str]] = {}  # by pid: how it ended
        self._push: Push | None = None
        self._loop: asyncio.AbstractEventLoop | None = None

    def attach(self, push: Push) -> None:
        self._push, self._loop = push, asyncio.get_running_loop()

    async def start(self, actors: list[ActorId], restore: bool = False) -> None:
        """`restore`: a resumed run's actors, from the run's checkpoints (as a restart's)."""
        self.logs.mkdir(parents=True, exist_ok=True)
        for actor in actors:
            self.spawn(actor, restore=restore and actor[0] == "agent")

    def spawn(self, actor: ActorId, restore: bool = False) -> None:
        """The one spawn path: a fresh interpreter running `kinswarm.actors.run.main` (never fork)."""
        role, ident = actor
        argv = [sys.executable, "-m", "kinswarm.actors.run.main", role, ident, str(self.config_path)]
        argv += ["--net", str(self.nets(role, ident)), "--parent", str(os.getpid()), "--supervisor", self.supervisor]
        if restore:
            argv.append("--restore")
        with open(self.logs / f"{ident}.log", "ab") as logf:
            p = subprocess.Popen(
                argv,
                stdin=subprocess.DEVNULL,
                stdout=logf,
                stderr=subprocess.STDOUT,
                start_new_session=True,  # Ctrl-C reaches the supervisor only; it stops them in order
            )
        self.procs[actor] = p
        self._watch(actor, p)

    def _watch(self, actor: ActorId, p: subprocess.Popen) -> None:
        """Be told when `p` ends: its pidfd on the loop (Linux >= 5.3), else a thread blocked in wait()."""
        loop = self._loop or asyncio.get_running_loop()
        ended: asyncio.Future[str] = loop.create_future()
        self._ended[p.pid] = ended

        def report() -> None:  # on the loop
            code = p.wait()
            how = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
            if not ended.done():
                ended.set_result(how)
                if self._push is not None:
                    self._push(EXIT, exit_item(actor, how))

        try:
            fd = os.pidfd_open(p.pid)
        except (AttributeError, OSError):
            threading.Thread(target=lambda: (p.wait(), loop.call_soon_threadsafe(report)), daemon=True).start()
            return

        def readable() -> None:
            loop.remove_reader(fd)
            os.close(fd)
            report()

        loop.add_reader(fd, readable)

    def signal(self, actor: ActorId, sig: signal.Signals) -> bool:
        p = self.procs.get(actor)
        if p is None or p.poll() is not None:
            return False
        p.send_signal(sig)
        return True

    def log_tail(self, actor: ActorId) -> str:
        return _tail(self.logs / f"{actor[1]}.log")

    async def stop(self, grace: float = 5.0) -> None:
        """SIGCONT (a frozen actor can neither leave nor die of SIGTERM), `grace` seconds to leave on their Stop,
        then SIGTERM, 2 s, SIGKILL; returns once every process has ended."""
        self._push = None  # ends from here on are the shutdown's, not faults
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGCONT)
        for sig, wait in ((signal.SIGTERM, grace), (signal.SIGKILL, 2.0), (None, 5.0)):
            pending = [self._ended[p.pid] for p in self.procs.values() if not self._ended[p.pid].done()]
            if pending:
                await asyncio.wait(pending, timeout=wait)
            if sig is None:
                break
            for p in self.procs.values():
                if not self._ended[p.pid].done() and p.poll() is None:
                    p.send_signal(sig)
        for p in self.procs.values():
            p.wait()

    @property
    def pids(self) -> dict[str, int]:
        return {ident: p.pid for (_, ident), p in self.procs.items() if p.poll() is None}


class SinglePlacement:
    """Every actor a task in this process, on the supervisor's session. A task can be killed
    (cancelled) and restarted, but not frozen."""

    supports = ("kill", "restart")

    def __init__(self, cfg: RunConfig, topo: Topology, session: zenoh.Session) -> None:
        self.cfg, self.topo, self.session = cfg, topo, session
        self.tasks: dict[ActorId, asyncio.Task] = {}
        self.nodes: dict[ActorId, Node] = {}
        self._push: Push | None = None

    def attach(self, push: Push) -> None:
        self._push = push

    async def start(self, actors: list[ActorId], restore: bool = False) -> None:
        for actor in actors:
            self.spawn(actor, restore=restore and actor[0] == "agent")

    def spawn(self, actor: ActorId, restore: bool = False) -> None:
        role, ident = actor
        node = Node(self.session, Keys(self.cfg.run_id), role, ident, self.cfg.key)
        self.nodes[actor] = node
        built = build_actor(role, ident, self.cfg, self.topo, node, restore)
        task = asyncio.create_task(built.run(), name=f"{role}/{ident}")
        self.tasks[actor] = task

        def done(t: asyncio.Task) -> None:
            node.close()  # its liveliness token goes at once, like a dead process's
            exc = None if t.cancelled() else t.exception()
            how = "killed (task cancelled)" if t.cancelled() else f"ended: {exc!r}"
            if self._push is not None:
                self._push(EXIT, exit_item(actor, how))

        task.add_done_callback(done)

    def signal(self, actor: ActorId, sig: signal.Signals) -> bool:
        t = self.tasks.get(actor)
        if t is None or t.done():
            return False
        if sig not in (signal.SIGKILL, signal.SIGTERM):
            raise ValueError(f"{signal.Signals(sig).name} needs --placement process")
        t.cancel()
        self.nodes[actor].close()  # its liveliness token goes at once, like a dead process's
        return True

    def log_tail(self, actor: ActorId) -> str:
        return "(single placement: see this process's log)"

    async def stop(self, grace: float = 5.0) -> None:
        self._push = None
        pending = [t for t in self.tasks.values() if not t.done()]
        if pending:
            _, still = await asyncio.wait(pending, timeout=grace)
            for t in still:
                t.cancel()
            await asyncio.gather(*still, return_exceptions=True)
        for node in self.nodes.values():
            node.close()

    @property
    def pids(self) -> dict[str, int]:
        return {ident: os.getpid() for (_, ident), t in self.tasks.items() if not t.done()}


Placement = ProcessPlacement | SinglePlacement


def _tail(path: Path, n: int = 15) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"
