"""Actor entry point: `python -m kinswarm.actors.process.main ROLE ID CONFIG --net NETSPEC.json [--restore]`, and the
zygote the `process` placement forks its actors from: `python -m kinswarm.actors.process.main --zygote CONFIG`.

This is the one spawn path of the `process` placement. The supervisor starts one zygote a run: a fresh interpreter
that imports what every actor needs (the runtime, the agent, numpy, numba and the run's compiled learner kernels) once,
never opens a Zenoh session, and then forks each actor on request (`serve_zygote`); the child runs `main` with the
actor's arguments and opens its own session. The pages the zygote loaded stay shared between its children
(copy-on-write), so N agents hold one copy of numba's and numpy's memory instead of N, and load the kernels zero
times instead of N at once. `build_actor` is shared with the `single` placement, which runs the same actors as tasks
over one session.
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
import gc  # noqa: E402
import json  # noqa: E402
import logging  # noqa: E402
import selectors  # noqa: E402
from pathlib import Path  # noqa: E402
from typing import Any, Protocol  # noqa: E402

from kinswarm.actors.files.config import RunConfig, load_run_config  # noqa: E402
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
        if cfg.fleet > 1:
            from kinswarm.actors.agent.fleet import FleetAgent

            agent: Any = FleetAgent(cfg, topo, ident, node)
        else:
            from kinswarm.actors.agent.actor import Agent

            agent = Agent(cfg, topo, ident, node)
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


# -- the zygote ------------------------------------------------------------------------------------------------------
#
# The supervisor's side is actors/supervisor/placements.py (`Zygote`). The conversation is JSON lines: the supervisor
# writes {"argv": [...], "log": path} on the zygote's stdin; the zygote answers on its stdout {"ready": pid} once it
# has loaded, {"pid": pid} for each fork, in order, and {"exit": pid, "code": c} when a child ends (c as a Popen's
# returncode: negative for a signal). The zygote's stdin closing (the supervisor is done, or gone) ends it; its
# children then get SIGTERM (PR_SET_DEATHSIG, as every actor did from its supervisor before), and the zygote itself
# gets SIGTERM when the supervisor dies.
#
# Forking is safe here because the zygote has no session and no thread of ours: importing zenoh starts no thread
# (its runtime starts with the first session, opened only in the child), numba compiles and loads on the calling
# thread, and the one thread numpy starts (OpenBLAS's pool) is stopped before a fork and started again in the child by
# OpenBLAS itself (pthread_atfork). A Zenoh session open before a fork hangs the child: never open one here.

ZYGOTE = "--zygote"


def preload(cfg: RunConfig) -> None:
    """Load what this run's actors will: the agent's modules, and each distinct learner of the run built once, so
    numba loads (or, with a cold cache, compiles) its kernels for the argument types the agents call them with.
    Learners of a kind from outside the learning package (an ONNX policy) are left to their agents."""
    from kinswarm.actors.agent.actor import Agent  # noqa: F401 - loaded to be shared
    from kinswarm.actors.files.runfile import kind_of, learner_settings, task_of

    if cfg.fleet > 1:
        from kinswarm.actors.agent.fleet import FleetAgent  # noqa: F401 - loaded to be shared
    topo = cfg.topo()
    kind = kind_of(cfg.learner, cfg.source)
    if kind.takes or cfg.controller != "agents":
        return
    settings = learner_settings(task_of(cfg), cfg.learner, cfg.source)
    built: set[tuple[str, int]] = set()
    for ident, spec in topo.agents.items():
        if not spec.has_dof:
            continue
        n_visible = sum(topo.agents[c].has_dof for c in spec.children)
        if (repr(settings[ident]), n_visible) not in built:
            built.add((repr(settings[ident]), n_visible))
            kind.build(settings[ident], n_visible, 0)


def serve_zygote(config: Path) -> int:
    """Load what the run's actors need, then fork one actor for each request until stdin closes."""
    zygote = os.getpid()
    try:
        preload(load_run_config(config))
    except Exception as e:  # one line for the supervisor: the actors would fail the same way
        _say({"error": _cause(e)})
        return 2
    gc.collect()
    gc.freeze()  # the loaded modules' objects: never walked by a child's collector, so their pages stay shared
    wake_r, wake_w = os.pipe()
    os.set_blocking(wake_r, False)
    os.set_blocking(wake_w, False)
    signal.signal(signal.SIGCHLD, lambda *_: None)  # a handler, so that the signal reaches the wake-up pipe
    signal.set_wakeup_fd(wake_w)
    sel = selectors.DefaultSelector()
    sel.register(0, selectors.EVENT_READ)
    sel.register(wake_r, selectors.EVENT_READ)
    _say({"ready": zygote})
    pending = b""
    while True:
        for key, _ in sel.select():
            if key.fd == wake_r:
                while _drain(wake_r):
                    pass
                _reap()
                continue
            data = os.read(0, 65536)
            if not data:  # the supervisor is done with us (or gone): our children follow us (their death signal)
                return 0
            pending += data
            while b"\n" in pending:
                line, pending = pending.split(b"\n", 1)
                request = json.loads(line)
                pid = os.fork()
                if pid == 0:  # the child: never returns into this loop
                    code = 1
                    try:
                        sel.close()
                        signal.set_wakeup_fd(-1)
                        signal.signal(signal.SIGCHLD, signal.SIG_DFL)
                        for fd in (wake_r, wake_w):
                            os.close(fd)
                        code = _child(zygote, request["argv"], request["log"])
                    finally:
                        os._exit(code)
                _say({"pid": pid})
        _reap()


def _child(zygote: int, argv: list[str], log: str) -> int:
    """A forked actor: its own session of the OS (Ctrl-C reaches the supervisor only), stdin from /dev/null, stdout
    and stderr into its log, death with the zygote, then the actor's `main`."""
    os.setsid()
    fd = os.open(log, os.O_WRONLY | os.O_APPEND | os.O_CREAT, 0o644)
    os.dup2(fd, 1)
    os.dup2(fd, 2)
    os.close(fd)
    null = os.open(os.devnull, os.O_RDONLY)
    os.dup2(null, 0)
    os.close(null)
    _die_with_parent(zygote)  # a fork does not keep the death signal: ask again, of the zygote
    _name(f"{argv[0]}-{argv[1]}" if len(argv) > 1 else "actor")
    sys.argv = [sys.argv[0], *argv]
    try:
        code = main([*argv, "--parent", str(zygote)])
    except SystemExit as e:  # argparse's refusals
        code = e.code if isinstance(e.code, int) else 2
    logging.shutdown()
    sys.stdout.flush()
    sys.stderr.flush()
    return code


def _name(name: str) -> None:
    """The process's name in ps and /proc/PID/comm (15 bytes): every forked actor shares the zygote's command line."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(15, name.encode()[:15], 0, 0, 0)  # PR_SET_NAME
    except OSError:
        pass


def _reap() -> None:
    """Report every child that has ended."""
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        _say({"exit": pid, "code": os.waitstatus_to_exitcode(status)})


def _drain(fd: int) -> bool:
    try:
        return bool(os.read(fd, 4096))
    except BlockingIOError:
        return False


def _say(message: dict[str, Any]) -> None:
    data = (json.dumps(message) + "\n").encode()
    while data:
        data = data[os.write(1, data) :]


if __name__ == "__main__":
    if sys.argv[1:2] == [ZYGOTE]:
        z = argparse.ArgumentParser(prog="kinswarm-zygote")
        z.add_argument(ZYGOTE, dest="config", type=Path, required=True)
        z.add_argument("--parent", type=int, required=True)
        sys.exit(serve_zygote(z.parse_args().config))
    sys.exit(main())
