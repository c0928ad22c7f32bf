"""Where actors live. The wire, the messages and the lockstep are the same in both placements, so the same seed
gives the same run:
  process  one OS process per actor, each with its own Zenoh session connected to the supervisor's endpoint, forked
           from the run's zygote (actors/process/main.py: a fresh interpreter that loaded what every actor needs once
           and never opens a session), so the actors share those pages;
  single   every actor a task in this process, sharing the supervisor's session.
An actor's end is an event, not a poll: the zygote reports a child's end on its pipe, a task calls back when it is
done; either posts an `EXIT` item into the supervisor's mailbox (`attach`), where it is handled in order.
"""

from __future__ import annotations

import asyncio
import json
import os
import select
import signal
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.process.main import build_actor
from kinswarm.actors.runtime import Node
from kinswarm.protocol.faults import PROCESS_FAULTS
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.topology import Topology

from .result import SwarmError

ActorId = tuple[str, str]  # (role, ident)
EXIT = "__exit__"  # mailbox key of an actor's end: payload b"role/ident/how"
Push = Callable[[str, bytes], None]


def exit_item(actor: ActorId, how: str) -> bytes:
    return f"{actor[0]}/{actor[1]}/{how}".encode()


def parse_exit(payload: bytes) -> tuple[ActorId, str]:
    role, ident, how = payload.decode().split("/", 2)
    return (role, ident), how


ZYGOTE_ANSWER_S = 60.0  # hang guard: a fork's pid comes back in milliseconds


class ZygoteError(SwarmError):
    """The actors' zygote failed to load, or is gone: no actor can be started (the run fails with this line)."""


class Forked:
    """An actor forked by the zygote: its pid, and its returncode once the zygote reported its end (as a Popen's:
    negative for a signal)."""

    def __init__(self, pid: int) -> None:
        self.pid = pid
        self.returncode: int | None = None

    def poll(self) -> int | None:
        return self.returncode

    def send_signal(self, sig: int) -> None:
        """Only while no end was reported: until the zygote reaps it, its pid cannot name another process."""
        if self.returncode is None:
            try:
                os.kill(self.pid, sig)
            except ProcessLookupError:  # ended; its report is on the way
                pass


class Zygote:
    """The supervisor's side of the run's zygote (actors/process/main.py, `serve_zygote`: the conversation is described
    there). `fork` returns the new actor's pid at once; ends arrive on the loop, through `on_exit`."""

    def __init__(self, config_path: Path, log: Path, on_exit: Callable[[int, int | None], None]) -> None:
        self.config_path, self.log, self.on_exit = config_path, log, on_exit
        self.proc: subprocess.Popen | None = None
        self.pid = 0
        self._buf = b""
        self._answers: list[dict[str, Any]] = []  # pid and ready answers, in order
        self._children: set[int] = set()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._eof = False
        self._gone: asyncio.Future[None] | None = None
        self._ready: asyncio.Future[dict[str, Any]] | None = None

    async def start(self) -> None:
        """Start it and wait until it has loaded what the actors need (seconds; longer when numba compiles)."""
        self._loop = asyncio.get_running_loop()
        self._gone = self._loop.create_future()
        argv = [sys.executable, "-m", "kinswarm.actors.process.main", "--zygote", str(self.config_path)]
        argv += ["--parent", str(os.getpid())]
        with open(self.log, "ab") as logf:
            self.proc = subprocess.Popen(
                argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=logf, start_new_session=True
            )
        assert self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        os.set_blocking(fd, False)
        self._ready = self._loop.create_future()
        self._loop.add_reader(fd, self._readable)
        answer = await self._ready
        if "ready" not in answer:
            raise ZygoteError(f"the actors' zygote failed: {answer.get('error', answer)}; its log: {self.log}")
        self.pid = answer["ready"]

    def fork(self, argv: list[str], log: Path) -> int:
        """A new actor running `main(argv)`, its output appended to `log`: its pid."""
        if self.proc is None or self._eof:
            raise ZygoteError(f"the actors' zygote is gone; its log: {self.log}")
        assert self.proc.stdin is not None
        self.proc.stdin.write((json.dumps({"argv": argv, "log": str(log)}) + "\n").encode())
        self.proc.stdin.flush()
        answer = self._wait_answer()
        if "pid" not in answer:
            raise ZygoteError(f"the actors' zygote did not fork: {answer}; its log: {self.log}")
        self._children.add(answer["pid"])
        return answer["pid"]

    def _wait_answer(self) -> dict[str, Any]:
        """Block for the next answer (a fork is quick); ends read on the way are reported as they come."""
        assert self.proc is not None and self.proc.stdout is not None
        fd = self.proc.stdout.fileno()
        while not self._answers:
            if self._eof:
                raise ZygoteError(f"the actors' zygote is gone; its log: {self.log}")
            if not select.select([fd], [], [], ZYGOTE_ANSWER_S)[0]:
                raise ZygoteError(f"the actors' zygote did not answer in {ZYGOTE_ANSWER_S:.0f} s; its log: {self.log}")
            self._read(fd)
        return self._answers.pop(0)

    def _readable(self) -> None:  # on the loop
        assert self.proc is not None and self.proc.stdout is not None
        self._read(self.proc.stdout.fileno())
        ready = self._ready
        if ready is not None and not ready.done() and (self._answers or self._eof):
            ready.set_result(self._answers.pop(0) if self._answers else {"error": "it ended while loading"})

    def _read(self, fd: int) -> None:
        try:
            data = os.read(fd, 65536)
        except BlockingIOError:
            return
        if not data:
            self._ended()
            return
        self._buf += data
        while b"\n" in self._buf:
            line, self._buf = self._buf.split(b"\n", 1)
            msg = json.loads(line)
            if "exit" in msg:
                self._children.discard(msg["exit"])
                self.on_exit(msg["exit"], msg["code"])
            else:
                self._answers.append(msg)

    def _ended(self) -> None:
        """Its pipe closed: the zygote has ended. Its children end with it (their death signal); their codes are
        lost with it."""
        if self._eof:
            return
        self._eof = True
        assert self.proc is not None and self.proc.stdout is not None and self._loop is not None
        self._loop.remove_reader(self.proc.stdout.fileno())
        for pid in sorted(self._children):
            self.on_exit(pid, None)
        self._children.clear()
        if self._gone is not None and not self._gone.done():
            self._gone.set_result(None)

    async def stop(self) -> None:
        """Close its stdin (it leaves; any child still there gets SIGTERM), wait for its end (SIGKILL after 5 s)."""
        if self.proc is None:
            return
        if self.proc.stdin is not None and not self.proc.stdin.closed:
            try:
                self.proc.stdin.close()
            except BrokenPipeError:
                pass
        if self._gone is not None and not self._eof:
            try:
                await asyncio.wait_for(asyncio.shield(self._gone), 5.0)
            except TimeoutError:
                self.proc.kill()
                await self._gone
        self.proc.wait()
        if self.proc.stdout is not None:
            self.proc.stdout.close()


class ProcessPlacement:
    """One OS process per actor, forked by the run's zygote; stdout/stderr of each go to `<out>/logs/<ident>.log`,
    the zygote's to `<out>/logs/zygote.log`."""

    supports = PROCESS_FAULTS

    def __init__(
        self, config_path: Path, nets: Callable[[str, str], Path], logs: Path, supervisor: str = "main"
    ) -> None:
        """`nets(role, ident)`: the file of the NetSpec that actor's session is opened with; `supervisor`: the
        id of the supervisor the actors watch (they leave when it is gone for good)."""
        self.config_path, self.nets, self.logs, self.supervisor = config_path, nets, logs, supervisor
        self.procs: dict[ActorId, Forked] = {}
        self._by_pid: dict[int, tuple[ActorId, Forked]] = {}  # every actor process of the run, ended or not
        self._ended: dict[int, asyncio.Future[str]] = {}  # by pid: how it ended
        self._push: Push | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self.zygote = Zygote(config_path, logs / "zygote.log", self._exited)

    def attach(self, push: Push) -> None:
        self._push, self._loop = push, asyncio.get_running_loop()

    async def start(self, actors: list[ActorId], restore: bool = False) -> None:
        """`restore`: a resumed run's actors, from the run's checkpoints (as a restart's)."""
        self.logs.mkdir(parents=True, exist_ok=True)
        if self.zygote.proc is None:
            await self.zygote.start()
        for actor in actors:
            self.spawn(actor, restore=restore and actor[0] == "agent")
            # a fork blocks for the zygote's answer (milliseconds; a hundred of them, seconds on a loaded machine):
            # the loop's other tasks and callbacks run between two
            await asyncio.sleep(0)

    def spawn(self, actor: ActorId, restore: bool = False) -> None:
        """The one spawn path: the zygote forks a process running `kinswarm.actors.process.main`'s `main`."""
        role, ident = actor
        argv = [role, ident, str(self.config_path), "--net", str(self.nets(role, ident)), "--supervisor"]
        argv.append(self.supervisor)
        if restore:
            argv.append("--restore")
        pid = self.zygote.fork(argv, self.logs / f"{ident}.log")
        self.procs[actor] = Forked(pid)
        self._by_pid[pid] = (actor, self.procs[actor])
        self._ended[pid] = (self._loop or asyncio.get_running_loop()).create_future()

    def _exited(self, pid: int, code: int | None) -> None:
        """The zygote's report of a child's end (`code` None: the zygote itself ended, and the child with it)."""
        if pid not in self._by_pid:
            return
        actor, p = self._by_pid[pid]
        if code is None:
            how = "ended with the actors' zygote"
            p.returncode = -signal.SIGTERM
        else:
            how = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
            p.returncode = code
        ended = self._ended[pid]
        if not ended.done():
            ended.set_result(how)
            if self._push is not None:
                self._push(EXIT, exit_item(actor, how))

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
        then SIGTERM, 2 s, SIGKILL; returns once every process has ended, the zygote last."""
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
        await self.zygote.stop()

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
