"""The supervisor: spawns the simulator and the agents, waits until every one is wired and alive,
runs the epochs, gathers metrics, has the agents checkpoint, and stops everything it started.

Placement decides only where actors live:
  process  one OS process per actor (fresh interpreters via subprocess: spawn, never fork), each with
           its own Zenoh session connected to the supervisor's endpoint;
  single   every actor a task in this process, sharing the supervisor's session.
The wire, the messages and the lockstep are the same in both, so the same seed gives the same run.
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import zenoh
from kinswarm.actors.config import RunConfig
from kinswarm.actors.main import build_actor
from kinswarm.actors.runtime import Node
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Checkpoint, EpochDone, EpochStart, Saved, Stop
from kinswarm.protocol.topology import Topology

log = logging.getLogger("kinswarm.supervisor")
ActorId = tuple[str, str]  # (role, ident)


class SwarmError(RuntimeError):
    pass


def actors_of(cfg: RunConfig, topo: Topology) -> list[ActorId]:
    if cfg.controller == "baseline":
        return [("sim", "sim"), ("controller", "baseline")]
    return [("sim", "sim"), *(("agent", a) for a in topo.order)]


# -- placements ----------------------------------------------------------------------------------
class ProcessPlacement:
    """One OS process per actor; stdout/stderr of each go to `<out>/logs/<ident>.log`."""

    def __init__(self, config_path: Path, connect: str, logs: Path) -> None:
        self.config_path, self.connect, self.logs = config_path, connect, logs
        self.procs: dict[ActorId, subprocess.Popen] = {}

    async def start(self, actors: list[ActorId]) -> None:
        self.logs.mkdir(parents=True, exist_ok=True)
        for role, ident in actors:
            with open(self.logs / f"{ident}.log", "ab") as logf:
                self.procs[(role, ident)] = subprocess.Popen(
                    [
                        sys.executable,
                        "-m",
                        "kinswarm.actors.main",
                        role,
                        ident,
                        str(self.config_path),
                        "--connect",
                        self.connect,
                    ],
                    stdin=subprocess.DEVNULL,
                    stdout=logf,
                    stderr=subprocess.STDOUT,
                    start_new_session=True,  # Ctrl-C reaches the supervisor only; it stops them in order
                )

    def check(self) -> None:
        for (role, ident), p in self.procs.items():
            if p.poll() is not None:
                tail = _tail(self.logs / f"{ident}.log")
                raise SwarmError(f"{role} {ident} exited with code {p.returncode}; its log ends:\n{tail}")

    async def stop(self, grace: float = 5.0) -> None:
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline and any(p.poll() is None for p in self.procs.values()):
            await asyncio.sleep(0.05)
        for p in self.procs.values():
            if p.poll() is None:
                p.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 2.0
        while time.monotonic() < deadline and any(p.poll() is None for p in self.procs.values()):
            await asyncio.sleep(0.05)
        for p in self.procs.values():
            if p.poll() is None:
                p.kill()
            p.wait()

    @property
    def pids(self) -> dict[str, int]:
        return {ident: p.pid for (_, ident), p in self.procs.items()}


class SinglePlacement:
    """Every actor a task in this process, on the supervisor's session."""

    def __init__(self, cfg: RunConfig, topo: Topology, session: zenoh.Session) -> None:
        self.cfg, self.topo, self.session = cfg, topo, session
        self.tasks: dict[ActorId, asyncio.Task] = {}
        self.nodes: list[Node] = []

    async def start(self, actors: list[ActorId]) -> None:
        keys = Keys(self.cfg.run_id)
        for role, ident in actors:
            node = Node(self.session, keys, role, ident, self.cfg.key)
            self.nodes.append(node)
            actor = build_actor(role, ident, self.cfg, self.topo, node)
            self.tasks[(role, ident)] = asyncio.create_task(actor.run(), name=f"{role}/{ident}")

    def check(self) -> None:
        for (role, ident), t in self.tasks.items():
            if t.done():
                exc = None if t.cancelled() else t.exception()
                raise SwarmError(f"{role} {ident} ended early: {exc!r}")

    async def stop(self, grace: float = 5.0) -> None:
        pending = [t for t in self.tasks.values() if not t.done()]
        if pending:
            _, still = await asyncio.wait(pending, timeout=grace)
            for t in still:
                t.cancel()
            await asyncio.gather(*still, return_exceptions=True)
        for node in self.nodes:
            node.close()

    @property
    def pids(self) -> dict[str, int]:
        return {ident: os.getpid() for (_, ident) in self.tasks}


# -- the supervisor ------------------------------------------------------------------------------
@dataclass
class RunResult:
    epochs: list[EpochDone] = field(default_factory=list)
    interrupted: bool = False
    wall_seconds: float = 0.0
    rejected: int = 0


class Supervisor:
    def __init__(
        self,
        cfg: RunConfig,
        topo: Topology,
        session: zenoh.Session,
        placement: ProcessPlacement | SinglePlacement,
        on_epoch: Callable[[EpochDone], None] | None = None,
    ) -> None:
        self.cfg, self.topo, self.session, self.placement = cfg, topo, session, placement
        self.keys = Keys(cfg.run_id)
        self.out = Path(cfg.out)
        self.on_epoch = on_epoch
        self.alive: set[ActorId] = set()
        self.node: Node | None = None
        self.result = RunResult()
        self.metrics_file: Any = None

    async def run(self) -> RunResult:
        t0 = time.perf_counter()
        loop = asyncio.get_running_loop()
        self.node = node = Node(self.session, self.keys, "supervisor", "main", self.cfg.key)
        node.listen(self.keys.metrics("epoch"))
        node.listen(self.keys.rep_all)

        def on_alive(sample: Any) -> None:  # zenoh thread
            parsed = self.keys.parse_alive(str(sample.key_expr))
            if parsed is not None:
                up = sample.kind == zenoh.SampleKind.PUT
                loop.call_soon_threadsafe(self._alive_changed, parsed, up)

        watch = self.session.liveliness().declare_subscriber(self.keys.alive_all, on_alive, history=True)
        node.declare_alive()
        expected = actors_of(self.cfg, self.topo)
        try:
            await self.placement.start(expected)
            await self._wait_alive(expected, timeout=60.0)
            await node.wait_matched([self.keys.ctl("epoch"), self.keys.ctl("checkpoint")], timeout=10.0)
            self.metrics_file = open(self.out / "metrics.jsonl", "a")  # noqa: SIM115 -- closed in finally
            for epoch in range(self.cfg.epochs):
                done = await self._run_epoch(epoch)
                self.result.epochs.append(done)
                self._record(done)
                last = epoch == self.cfg.epochs - 1
                every = self.cfg.checkpoint_every
                if (
                    self.cfg.controller == "agents"
                    and self.cfg.learn
                    and (last or (every and (epoch + 1) % every == 0))
                ):
                    await self._checkpoint(epoch)
        except asyncio.CancelledError:
            self.result.interrupted = True
            log.warning("interrupted: stopping the swarm")
        finally:
            try:
                node.send(self.keys.ctl("stop"), Stop(reason="interrupted" if self.result.interrupted else "done"))
            except Exception:  # the session may be closing
                pass
            await self.placement.stop()
            watch.undeclare()
            self.result.rejected = node.rejected
            node.close()
            if self.metrics_file is not None:
                self.metrics_file.close()
            self.result.wall_seconds = time.perf_counter() - t0
        return self.result

    def _alive_changed(self, actor: ActorId, up: bool) -> None:
        if up:
            self.alive.add(actor)
        else:
            self.alive.discard(actor)

    async def _wait_alive(self, expected: list[ActorId], timeout: float) -> None:
        deadline = time.monotonic() + timeout
        while not set(expected) <= self.alive:
            self.placement.check()
            if time.monotonic() > deadline:
                missing = sorted(set(expected) - self.alive)
                raise SwarmError(f"not alive after {timeout:.0f} s: {missing}")
            await asyncio.sleep(0.02)

    async def _expect(self, kind: type, match: Callable[[Any], bool], timeout: float) -> Any:
        """Read the supervisor's mailbox until a message of `kind` satisfying `match` arrives."""
        assert self.node is not None
        deadline = time.monotonic() + timeout
        while True:
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise SwarmError(f"no {kind.__name__} within {timeout:.0f} s")
            try:
                key, payload = await asyncio.wait_for(self.node.recv(), timeout=min(remaining, 0.5))
            except TimeoutError:
                self.placement.check()
                continue
            if key.startswith(self.keys.root + "/metrics/") and kind is EpochDone:
                m = self.node.decode(key, payload, EpochDone)
            elif key.startswith(self.keys.root + "/rep/") and kind is Saved:
                m = self.node.decode(key, payload, Saved)
            else:
                continue
            if m is not None and match(m):
                return m

    async def _run_epoch(self, epoch: int) -> EpochDone:
        assert self.node is not None
        goal = self.cfg.resolved_goal(self.topo)
        self.node.send(self.keys.ctl("epoch"), EpochStart(epoch=epoch, steps=self.cfg.steps, goal=goal))
        # generous: every step may run into its deadline and still finish
        timeout = 30.0 + self.cfg.steps * self.cfg.deadline_ms / 1000 * 1.5
        done = await self._expect(EpochDone, lambda m: m.epoch == epoch, timeout)
        if self.on_epoch is not None:
            self.on_epoch(done)
        return done

    async def _checkpoint(self, epoch: int) -> None:
        assert self.node is not None
        directory = self.out / "agents"
        directory.mkdir(parents=True, exist_ok=True)
        self.node.send(self.keys.ctl("checkpoint"), Checkpoint(epoch=epoch, directory=str(directory)))
        waiting = {a for a in self.topo.order if self.topo.agents[a].has_dof}
        while waiting:
            m = await self._expect(Saved, lambda s: s.epoch == epoch, timeout=30.0)
            agent = Path(m.path).stem
            if m.error:
                raise SwarmError(f"agent {agent} could not checkpoint: {m.error}")
            waiting.discard(agent)

    def _record(self, d: EpochDone) -> None:
        row = {
            "epoch": d.epoch,
            "final_error": d.final_error,
            "mean_error": d.mean_error,
            "steps": d.steps,
            "seconds": d.seconds,
            "missed_cmds": d.missed_cmds,
            "final_angles_deg": {a: round(math.degrees(q), 4) for a, q in d.final_angles.items()},
        }
        self.metrics_file.write(json.dumps(row) + "\n")
        self.metrics_file.flush()


def _tail(path: Path, n: int = 15) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"
