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
import collections
import contextlib
import dataclasses
import json
import logging
import math
import os
import signal
import socket
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
from kinswarm.actors.plan import Plan, local_plan
from kinswarm.actors.runfile import task_of
from kinswarm.actors.runtime import Node
from kinswarm.protocol import codec
from kinswarm.protocol.faults import (
    ALL,
    JOINT_FAULTS,
    LINK_FAULTS,
    PROCESS_FAULTS,
    check_fault,
    describe,
    expand_targets,
)
from kinswarm.protocol.keys import Keys, check_id
from kinswarm.protocol.messages import (
    Bye,
    Checkpoint,
    EpochDone,
    EpochStart,
    Event,
    Fault,
    FaultReply,
    Heartbeat,
    JointStatus,
    Saved,
    Setup,
    Stop,
    SwarmStatus,
)
from kinswarm.protocol.topology import Topology

log = logging.getLogger("kinswarm.supervisor")
ActorId = tuple[str, str]  # (role, ident)


class SwarmError(RuntimeError):
    pass


class _NoMessage(SwarmError):
    """The awaited message did not come in time."""


class _Down(Exception):
    """Someone asked the swarm to stop (`kinswarm down`: a Stop on ctl/stop)."""


def actors_of(cfg: RunConfig, topo: Topology) -> list[ActorId]:
    if cfg.controller != "agents":
        return [("sim", "sim"), ("controller", cfg.controller)]
    return [("sim", "sim"), *(("agent", a) for a in topo.order)]


# -- placements ----------------------------------------------------------------------------------
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
        self._reported: set[int] = set()  # pids whose exit was already handed to the supervisor

    async def start(self, actors: list[ActorId]) -> None:
        self.logs.mkdir(parents=True, exist_ok=True)
        for actor in actors:
            self.spawn(actor)

    def spawn(self, actor: ActorId, restore: bool = False) -> None:
        """The one spawn path: a fresh interpreter running `kinswarm.actors.main` (never fork)."""
        role, ident = actor
        argv = [sys.executable, "-m", "kinswarm.actors.main", role, ident, str(self.config_path)]
        argv += ["--net", str(self.nets(role, ident)), "--parent", str(os.getpid()), "--supervisor", self.supervisor]
        if restore:
            argv.append("--restore")
        with open(self.logs / f"{ident}.log", "ab") as logf:
            self.procs[actor] = subprocess.Popen(
                argv,
                stdin=subprocess.DEVNULL,
                stdout=logf,
                stderr=subprocess.STDOUT,
                start_new_session=True,  # Ctrl-C reaches the supervisor only; it stops them in order
            )

    def exited(self) -> list[tuple[ActorId, str]]:
        """Actors whose process ended since the last call, with how."""
        gone = []
        for actor, p in self.procs.items():
            if p.poll() is not None and p.pid not in self._reported:
                self._reported.add(p.pid)
                code = p.returncode
                how = f"killed by {signal.Signals(-code).name}" if code < 0 else f"exit code {code}"
                gone.append((actor, how))
        return gone

    def signal(self, actor: ActorId, sig: signal.Signals) -> bool:
        p = self.procs.get(actor)
        if p is None or p.poll() is not None:
            return False
        p.send_signal(sig)
        return True

    def log_tail(self, actor: ActorId) -> str:
        return _tail(self.logs / f"{actor[1]}.log")

    async def stop(self, grace: float = 5.0) -> None:
        for p in self.procs.values():  # a frozen actor cannot leave, nor even die of SIGTERM
            if p.poll() is None:
                p.send_signal(signal.SIGCONT)
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
        return {ident: p.pid for (_, ident), p in self.procs.items() if p.poll() is None}


class SinglePlacement:
    """Every actor a task in this process, on the supervisor's session. A task can be killed
    (cancelled) and restarted, but not frozen."""

    supports = ("kill", "restart")

    def __init__(self, cfg: RunConfig, topo: Topology, session: zenoh.Session) -> None:
        self.cfg, self.topo, self.session = cfg, topo, session
        self.tasks: dict[ActorId, asyncio.Task] = {}
        self.nodes: dict[ActorId, Node] = {}
        self._reported: set[asyncio.Task] = set()

    async def start(self, actors: list[ActorId]) -> None:
        for actor in actors:
            self.spawn(actor)

    def spawn(self, actor: ActorId, restore: bool = False) -> None:
        role, ident = actor
        node = Node(self.session, Keys(self.cfg.run_id), role, ident, self.cfg.key)
        self.nodes[actor] = node
        built = build_actor(role, ident, self.cfg, self.topo, node, restore)
        self.tasks[actor] = asyncio.create_task(built.run(), name=f"{role}/{ident}")

    def exited(self) -> list[tuple[ActorId, str]]:
        gone = []
        for actor, t in self.tasks.items():
            if t.done() and t not in self._reported:
                self._reported.add(t)
                self.nodes[actor].close()
                exc = None if t.cancelled() else t.exception()
                gone.append((actor, "killed (task cancelled)" if exc is None and t.cancelled() else f"ended: {exc!r}"))
        return gone

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


# -- the supervisor ------------------------------------------------------------------------------
@dataclass
class RunResult:
    epochs: list[EpochDone] = field(default_factory=list)
    interrupted: bool = False
    error: str = ""  # why the run failed (restart budget exhausted, the sim died, ...)
    wall_seconds: float = 0.0
    rejected: int = 0  # messages every actor refused (from their Bye) plus the supervisor's own
    rejected_by: dict[str, int] = field(default_factory=dict)
    restarts: dict[str, int] = field(default_factory=dict)
    # liveliness tokens gone while training, by actor: a kill, a freeze, or a process starved past the lease
    tokens_lost: dict[str, int] = field(default_factory=dict)


@dataclass
class _Restarts:
    """Restart policy state of one agent: at most max_restarts within window seconds, with backoff."""

    times: collections.deque = field(default_factory=collections.deque)
    total: int = 0
    due: float | None = None  # when the pending restart is to happen
    requested: bool = False  # the exit was a `restart` fault: respawn at once, outside the budget


class Supervisor:
    STATUS_EVERY = 0.5  # seconds between SwarmStatus messages
    TICK = 0.05  # seconds between checks of exits, restarts and thaws while waiting

    hosts_wait_s = 600.0  # how long the leader waits for the other hosts' actors (`kinswarm up --wait`)
    HOST_GRACE_S = 120.0  # the leader stops a run missing a host this long; another host, missing the leader

    def __init__(
        self,
        cfg: RunConfig,
        topo: Topology,
        session: zenoh.Session,
        placement: Placement,
        on_epoch: Callable[[EpochDone], None] | None = None,
        plan: Plan | None = None,
        host: str | None = None,
    ) -> None:
        self.cfg, self.topo, self.session, self.placement = cfg, topo, session, placement
        self.keys = Keys(cfg.run_id)
        self.out = Path(cfg.out)
        self.on_epoch = on_epoch
        self.expected = actors_of(cfg, topo)
        self.task = task_of(cfg)  # the goal of each epoch
        # Several hosts: this supervisor spawns and restarts its host's share; the leader also trains.
        self.plan = plan if plan is not None else local_plan(cfg.listen, cfg.lease_ms)
        self.host = host if host is not None else self.plan.leader
        self.lead = self.host == self.plan.leader
        self.multi = len(self.plan.hosts) > 1
        self.where = self.plan.placement(topo)  # actor ident -> host
        self.local = [a for a in self.expected if self.host_of(a) == self.host]
        self.heard: dict[str, float] = {}  # host -> when its heartbeat last came
        self.missing: set[str] = set()  # hosts not heard for a lease: the swarm is paused
        self.paused_s = 0.0  # seconds paused so far (epoch deadlines stretch by it)
        self._paused_at = 0.0
        self._hb_seq = 0
        self._next_hb = 0.0
        self._epoch_sent = 0.0
        self._epoch_start: EpochStart | None = None  # while its EpochDone is awaited
        self.agents = list(topo.order) if cfg.controller == "agents" else []
        self.alive: set[ActorId] = set()
        self.node: Node | None = None
        self.result = RunResult()
        self.metrics_file: Any = None
        self.events_file: Any = None
        self.t0 = time.monotonic()
        self.training = False  # liveliness changes are events only once the swarm is up
        self.epoch = -1
        self.joints: JointStatus | None = None
        self.restarts: dict[str, _Restarts] = {a: _Restarts() for a in self.agents}
        self.frozen: dict[str, float | None] = {}  # agent -> when to thaw it (None: on `thaw`)
        self.link_faults: dict[str, list[tuple[str, float | None]]] = {}  # agent -> (description, expiry)
        self.byes: dict[str, Bye] = {}
        self._next_status = 0.0
        self.hostname = {h: h for h in self.plan.hosts} if self.multi else {self.host: socket.gethostname()}

    def host_of(self, actor: ActorId) -> str:
        role, ident = actor
        return self.where[ident] if role == "agent" else self.where["sim"]  # the baseline runs beside the sim

    async def run(self) -> RunResult:
        t0 = time.perf_counter()
        loop = asyncio.get_running_loop()
        ident = "main" if self.lead else self.host
        self.node = node = Node(self.session, self.keys, "supervisor", ident, self.cfg.key)
        k = self.keys
        for key in (k.metrics("epoch"), k.metrics("event"), k.metrics("joints"), k.rep("agent", "*")):
            node.listen(key)
        node.listen(k.rep("bye", "*"))
        node.listen(k.rep("sim", "*"))
        node.listen(k.ctl("stop"))
        if self.lead:
            node.listen(k.fault("request"))
        else:
            node.listen(k.ctl("fault"))  # process faults the leader forwards to this host's actors
        if self.multi:
            node.listen(k.host("*"))

        def on_alive(sample: Any) -> None:  # zenoh thread
            parsed = self.keys.parse_alive(str(sample.key_expr))
            if parsed is not None:
                up = sample.kind == zenoh.SampleKind.PUT
                try:
                    loop.call_soon_threadsafe(self._alive_changed, parsed, up)
                except RuntimeError:  # tokens going away while the run's loop closes: nobody to tell
                    pass

        watch = self.session.liveliness().declare_subscriber(self.keys.alive_all, on_alive, history=True)
        setup = self._serve_setup() if self.lead and self.multi else None
        node.declare_alive()
        self.events_file = open(self.out / "events.jsonl", "a")  # noqa: SIM115 -- closed in finally
        try:
            await self.placement.start(self.local)
            await self._wait_alive(self.local, timeout=60.0)
            if self.lead:
                await self._wait_alive(self.expected, timeout=self.hosts_wait_s, what="the other hosts' actors")
                await self._train()
            else:
                await self._serve()
        except asyncio.CancelledError:
            self.result.interrupted = True
            log.warning("interrupted: stopping the swarm")
        except _Down as e:
            self.result.interrupted = True
            self._event("down", "swarm", str(e))
        except SwarmError as e:
            self.result.error = str(e)
            log.error("%s", e)
            self._event("failed", "swarm", str(e))
        finally:
            self.training = False
            try:
                if self.lead:
                    reason = "interrupted" if self.result.interrupted else "failed" if self.result.error else "done"
                    node.send(self.keys.ctl("stop"), Stop(reason=reason))
                await self._collect_byes(timeout=3.0)
            except Exception:  # the session may be closing
                pass
            await self.placement.stop()
            watch.undeclare()
            if setup is not None:
                setup.undeclare()
            self.result.rejected_by = {"supervisor": node.rejected, **{a: b.rejected for a, b in self.byes.items()}}
            self.result.rejected = sum(self.result.rejected_by.values())
            self.result.restarts = {a: r.total for a, r in self.restarts.items()}
            node.close()
            for f in (self.metrics_file, self.events_file):
                if f is not None:
                    f.close()
            self.result.wall_seconds = time.perf_counter() - t0
        return self.result

    async def _train(self) -> None:
        assert self.node is not None
        k = self.keys
        outputs = [k.ctl(v) for v in ("epoch", "checkpoint", "fault")]
        await self.node.wait_matched(outputs, timeout=10.0)
        self.metrics_file = open(self.out / "metrics.jsonl", "a")  # noqa: SIM115 -- closed in run()
        self.training = True
        for epoch in range(self.cfg.epochs):
            done = await self._run_epoch(epoch)
            self.result.epochs.append(done)
            self._record(done)
            last = epoch == self.cfg.epochs - 1
            every = self.cfg.checkpoint_every
            if self.agents and self.cfg.learn and (last or (every and (epoch + 1) % every == 0)):
                await self._checkpoint(epoch)

    async def _serve(self) -> None:
        """Another host's share: keep it alive (restarts, forwarded faults, heartbeats) until the leader's Stop."""
        self.training = True
        log.info("host %s: %d actors up; serving the leader's run %s", self.host, len(self.local), self.cfg.run_id)
        stop = await self._expect(Stop, lambda m: True, timeout=math.inf)
        self._event("stop", self.host, f"the leader says: {stop.reason}")

    def _serve_setup(self) -> Any:
        """The leader answers the other hosts' `kinswarm up`: the resolved run, signed with the plan's digest."""
        cfg, plan = self.cfg, self.plan
        scenario = Path(cfg.scenario).read_text() if cfg.scenario else ""
        msg = Setup(plan=plan.name, config=cfg.to_json(), scenario=scenario)
        key = self.keys.setup(plan.name)
        payload = codec.encode(msg, cfg.run_id, "supervisor/main", plan.digest)

        def on_query(q: Any) -> None:  # zenoh thread
            q.reply(key, payload)

        return self.session.declare_queryable(key, on_query)

    # -- liveliness, exits, restarts -------------------------------------------------------------
    def _alive_changed(self, actor: ActorId, up: bool) -> None:
        if up:
            self.alive.add(actor)
        else:
            self.alive.discard(actor)
        if self.training and actor[0] != "supervisor":
            self._event("alive" if up else "lost", actor[1], "liveliness token " + ("back" if up else "gone"))
            if not up:
                self.result.tokens_lost[actor[1]] = self.result.tokens_lost.get(actor[1], 0) + 1

    async def _wait_alive(self, expected: list[ActorId], timeout: float, what: str = "") -> None:
        deadline = time.monotonic() + timeout
        told = False
        while not set(expected) <= self.alive:
            for actor, how in self.placement.exited():
                raise SwarmError(f"{actor[0]} {actor[1]} {how}; its log ends:\n{self.placement.log_tail(actor)}")
            missing = sorted(set(expected) - self.alive)
            if time.monotonic() > deadline:
                raise SwarmError(f"not alive after {timeout:.0f} s: {missing}")
            if what and not told:
                told = True
                hosts = sorted({self.host_of(a) for a in missing})
                log.warning(
                    "waiting for %s (on %s): start `kinswarm up PLAN --host NAME` there", what, ", ".join(hosts)
                )
            if self.multi:
                self._heartbeat(time.monotonic())
                while self.node is not None and len(self.node.mailbox):
                    self._route(*await self.node.recv())
            await asyncio.sleep(0.02)

    def _tick(self) -> None:
        """Exits -> restart policy; due restarts; due thaws; expired link faults; the status message."""
        now = time.monotonic()
        for actor, how in self.placement.exited():
            self._on_exit(actor, how, now)
        for agent, r in self.restarts.items():
            if r.due is not None and r.due <= now:
                r.due = None
                self.placement.spawn(("agent", agent), restore=True)
                self._event("restart", agent, f"restart {r.total} (restores its newest checkpoint)")
        for agent, when in list(self.frozen.items()):
            if when is not None and when <= now:
                self._thaw(agent)
        for faults in self.link_faults.values():
            faults[:] = [(d, exp) for d, exp in faults if exp is None or exp > now]
        if self.multi:
            self._heartbeat(now)
        if now >= self._next_status:
            self._next_status = now + self.STATUS_EVERY
            if self.lead:
                self._publish_status(now)

    # -- several hosts: heartbeats, partitions -----------------------------------------------------
    def _heartbeat(self, now: float) -> None:
        """Send ours every quarter lease; a host not heard for a lease is cut off (the sim, hearing the same
        silence, holds its steps; the leader's epoch deadline stops) until it is heard again."""
        assert self.node is not None
        lease = self.plan.lease_ms / 1000
        if now >= self._next_hb:
            self._next_hb = now + lease / 4
            self._hb_seq += 1
            self.node.send(
                self.keys.host(self.host), Heartbeat(host=self.host, seq=self._hb_seq, leader=int(self.lead))
            )
        missing = {h for h, t in self.heard.items() if now - t > lease}
        if missing == self.missing:
            for h in sorted(missing):  # a pause, not a hang: past the grace the run ends, saying why
                if (self.lead or h == self.plan.leader) and now - self.heard[h] > self.HOST_GRACE_S:
                    raise SwarmError(f"host {h} unheard for {now - self.heard[h]:.0f} s; stopping")
            return
        for h in sorted(missing - self.missing):
            self._event("partition", h, f"no heartbeat from host {h} for {now - self.heard[h]:.2f} s: paused")
        if missing and not self.missing:
            self._paused_at = now
        if self.missing and not missing:
            self.paused_s += now - self._paused_at
        for h in sorted(self.missing - missing):
            self._event("rejoin", h, f"host {h} heard again after {now - self._paused_at:.1f} s")
        self.missing = missing

    def _paused_seconds(self, now: float) -> float:
        return self.paused_s + (now - self._paused_at if self.missing else 0.0)

    def _on_exit(self, actor: ActorId, how: str, now: float) -> None:
        role, ident = actor
        if role != "agent":
            raise SwarmError(f"{role} {ident} on {self.host} {how}; its log ends:\n{self.placement.log_tail(actor)}")
        self._event("exited", ident, how)
        self.frozen.pop(ident, None)
        r = self.restarts[ident]
        r.total += 1
        if r.requested:
            r.requested, r.due = False, now
            return
        while r.times and r.times[0] < now - self.cfg.restart_window_s:
            r.times.popleft()
        if len(r.times) >= self.cfg.max_restarts:
            raise SwarmError(
                f"agent {ident} exited {len(r.times) + 1} times within {self.cfg.restart_window_s:g} s "
                f"(restart policy: at most {self.cfg.max_restarts}); giving up"
            )
        backoff = min(2.0, 0.1 * 2 ** len(r.times))  # 0.1, 0.2, 0.4 ... 2 s
        r.times.append(now)
        r.due = now + backoff

    # -- faults ----------------------------------------------------------------------------------
    def _on_fault(self, f: Fault) -> None:
        assert self.node is not None
        error = check_fault(f, list(self.topo.order))
        if not error and not self.agents and f.fault not in JOINT_FAULTS:
            error = f"{f.fault}: this run has no agents (a baseline run); only joint faults apply"
        if not error and f.fault in PROCESS_FAULTS and f.fault not in self.placement.supports:
            error = f"{f.fault}: needs --placement process (this run is {self.cfg.placement})"
        if not error and f.fault in JOINT_FAULTS:
            compound = [t for t in f.targets if t != ALL and not self.topo.agents[t].has_dof]
            if compound:
                error = f"{f.fault}: {', '.join(compound)} has no joint (a compound agent)"
        detail = ""
        if not error:
            targets = expand_targets(
                f.targets, self.agents if f.fault not in JOINT_FAULTS else list(self.topo.dof_agents)
            )
            try:
                detail = self._apply(f, targets)
            except ValueError as e:
                error = str(e)
        if error:
            log.warning("fault refused: %s", error)
        else:
            self._event("fault", ",".join(f.targets), describe(f) + (f" ({detail})" if detail else ""))
        try:
            check_id("fault id", f.id)
        except ValueError:
            return  # nowhere to reply
        self.node.send(self.keys.rep("fault", f.id), FaultReply(id=f.id, error=error, detail=detail))

    def _apply(self, f: Fault, targets: list[str]) -> str:
        assert self.node is not None
        if f.fault in JOINT_FAULTS or f.fault in LINK_FAULTS:
            self.node.send(self.keys.ctl("fault"), f)  # the sim / the targets' runtimes apply it
            if f.fault == "clear":
                for t in targets:
                    self.link_faults.pop(t, None)
            elif f.fault in LINK_FAULTS:
                expiry = None if f.seconds is None else time.monotonic() + f.seconds
                for t in targets:
                    self.link_faults.setdefault(t, []).append((describe(f), expiry))
            return ""
        done, skipped, forwarded = [], [], []
        remote = [t for t in targets if self.where[t] != self.host]
        if remote and self.lead:  # their hosts' supervisors own those processes
            self.node.send(self.keys.ctl("fault"), dataclasses.replace(f, targets=remote))
            forwarded = [f"{t} (to {self.where[t]})" for t in remote]
        for t in targets:
            if t in remote:
                continue
            actor = ("agent", t)
            if f.fault == "kill":
                ok = self.placement.signal(actor, signal.SIGKILL)
            elif f.fault == "restart":
                ok = self.placement.signal(actor, signal.SIGTERM)
                self.restarts[t].requested = ok
            elif f.fault == "freeze":
                ok = self.placement.signal(actor, signal.SIGSTOP)
                if ok:
                    self.frozen[t] = None if f.seconds is None else time.monotonic() + f.seconds
            else:  # thaw
                ok = t in self.frozen and self._thaw(t)
            (done if ok else skipped).append(t)
        detail = f"{f.fault}: {', '.join(done) or 'nobody'}"
        if forwarded:
            detail += f"; forwarded: {', '.join(forwarded)}"
        return detail + (f"; not running: {', '.join(skipped)}" if skipped else "")

    def _thaw(self, agent: str) -> bool:
        self.frozen.pop(agent, None)
        ok = self.placement.signal(("agent", agent), signal.SIGCONT)
        if ok:
            self._event("thaw", agent, "SIGCONT")
        return ok

    # -- records ---------------------------------------------------------------------------------
    def _event(self, event: str, target: str, detail: str, epoch: int | None = None, step: int | None = None) -> None:
        if epoch is None:
            epoch = self.epoch
            j = self.joints
            step = j.step if j is not None and j.epoch == epoch else -1
        row = {
            "t": round(time.monotonic() - self.t0, 4),
            "wall": round(time.time(), 4),
            "epoch": epoch,
            "step": step,
            "event": event,
            "target": target,
            "detail": detail,
        }
        log.info("event %s", row)
        if self.events_file is not None and not self.events_file.closed:
            self.events_file.write(json.dumps(row) + "\n")
            self.events_file.flush()

    def _publish_status(self, now: float) -> None:
        assert self.node is not None
        ids = [ident for _, ident in self.expected]
        roles = dict((ident, role) for role, ident in self.expected)
        pids = self.placement.pids
        faults: dict[str, list[str]] = {i: [] for i in ids}
        for agent, when in self.frozen.items():
            faults[agent].append("frozen" + ("" if when is None else f" ({max(0.0, when - now):.1f} s left)"))
        for agent, fl in self.link_faults.items():
            faults[agent] += [d + ("" if exp is None else f" ({max(0.0, exp - now):.0f} s left)") for d, exp in fl]
        if self.joints is not None:
            for joint, what in self.joints.faults.items():
                faults.setdefault(joint, []).append(what)
        status = SwarmStatus(
            epoch=self.epoch,
            epochs=self.cfg.epochs,
            role=roles,
            alive={i: int((roles[i], i) in self.alive) for i in ids},
            pid={i: pids.get(i, 0) for i in ids},
            host={i: self.hostname.get(self.host_of((roles[i], i)), self.host_of((roles[i], i))) for i in ids},
            restarts={i: self.restarts[i].total if i in self.restarts else 0 for i in ids},
            faults=faults,
        )
        self.node.send(self.keys.metrics("status"), status)

    # -- the mailbox -----------------------------------------------------------------------------
    def _route(self, key: str, payload: bytes) -> Any:
        """Handle what the supervisor consumes itself; return EpochDone, Saved and Bye to the caller."""
        assert self.node is not None
        kind = key[len(self.keys.root) + 1 :]
        if kind == "metrics/epoch":
            return self.node.decode(key, payload, EpochDone)
        if kind.startswith("rep/agent/"):
            return self.node.decode(key, payload, Saved)
        if kind.startswith(("rep/bye/", "rep/sim/")):
            if (bye := self.node.decode(key, payload, Bye)) is not None:
                self.byes[self.keys.last_chunk(key)] = bye
            return bye
        if kind == "metrics/event":
            if (e := self.node.decode(key, payload, Event)) is not None:
                self._event(e.event, e.target, e.detail, e.epoch, e.step)
        elif kind == "metrics/joints":
            if (j := self.node.decode(key, payload, JointStatus)) is not None:
                self.joints = j
                start = self._epoch_start
                if start is not None and j.epoch < start.epoch and not self.missing:
                    if time.monotonic() - self._epoch_sent > 1.0:  # lost in a partition: the sim never began it
                        log.warning(
                            "the sim is still at epoch %d: sending epoch %d's start again", j.epoch, start.epoch
                        )
                        self.node.send(self.keys.ctl("epoch"), start)
                        self._epoch_sent = time.monotonic()
        elif kind == "fault/request":
            if (f := self.node.decode(key, payload, Fault)) is not None:
                self._on_fault(f)
        elif kind.startswith("ctl/host/"):
            if (hb := self.node.decode(key, payload, Heartbeat)) is not None and hb.host in self.plan.hosts:
                if hb.host != self.host:
                    self.heard[hb.host] = time.monotonic()
        elif kind == "ctl/stop":
            return self.node.decode(key, payload, Stop)
        elif kind == "ctl/fault" and not self.lead:
            f = self.node.decode(key, payload, Fault)
            if f is not None and f.fault in PROCESS_FAULTS:
                mine = [t for t in expand_targets(f.targets, self.agents) if self.where.get(t) == self.host]
                if mine:
                    self._event("fault", ",".join(mine), describe(f) + f" (from the leader: {self._apply(f, mine)})")
        return None

    async def _expect(self, kind: type, match: Callable[[Any], bool], timeout: float, stretch: bool = True) -> Any:
        """Serve the mailbox (faults, events, restarts) until a message of `kind` satisfying `match`."""
        assert self.node is not None
        deadline = time.monotonic() + timeout
        paused0 = self._paused_seconds(time.monotonic())
        while True:
            self._tick()
            now = time.monotonic()
            remaining = deadline - now
            if stretch:  # a partition stops the clock
                remaining += self._paused_seconds(now) - paused0
            if remaining <= 0:
                raise _NoMessage(f"no {kind.__name__} within {timeout:.0f} s")
            try:
                key, payload = await self.node.recv(timeout=min(remaining, self.TICK))
            except TimeoutError:
                continue
            m = self._route(key, payload)
            if isinstance(m, Stop) and self.lead and kind is not Stop:
                raise _Down(f"stop requested ({m.reason})")
            if isinstance(m, kind) and match(m):
                return m

    async def _collect_byes(self, timeout: float) -> None:
        assert self.node is not None
        want = {ident for role, ident in self.expected if (role, ident) in self.alive}
        deadline = time.monotonic() + timeout
        while not want <= set(self.byes) and time.monotonic() < deadline:
            try:
                key, payload = await self.node.recv(timeout=deadline - time.monotonic())
            except TimeoutError:
                break
            self._route(key, payload)

    async def _run_epoch(self, epoch: int) -> EpochDone:
        assert self.node is not None
        self.epoch = epoch
        goal, path = self.task.goal(epoch, self.cfg.steps)
        self._epoch_start = EpochStart(epoch=epoch, steps=self.cfg.steps, goal=goal, path=path)
        while self.missing:  # not into a partition: the other side would miss the start
            with contextlib.suppress(_NoMessage):
                await self._expect(Saved, lambda m: False, timeout=0.2, stretch=False)
        self.node.send(self.keys.ctl("epoch"), self._epoch_start)
        self._epoch_sent = time.monotonic()
        # generous: every step may run into its deadline and still finish
        timeout = 30.0 + self.cfg.steps * self.cfg.deadline_ms / 1000 * 1.5
        done = await self._expect(EpochDone, lambda m: m.epoch == epoch, timeout)
        self._epoch_start = None
        if self.on_epoch is not None:
            self.on_epoch(done)
        return done

    async def _checkpoint(self, epoch: int) -> None:
        assert self.node is not None
        directory = self.out / "agents"
        directory.mkdir(parents=True, exist_ok=True)
        self.node.send(self.keys.ctl("checkpoint"), Checkpoint(epoch=epoch, directory=str(directory)))
        # An agent that is down, or dies before answering, cannot answer: its previous checkpoint stays
        # its newest, and a restarted one resumes from that.
        before = {a: r.total for a, r in self.restarts.items()}
        waiting = set(self.topo.dof_agents)
        deadline = time.monotonic() + 30.0
        while waiting:
            waiting = {
                a
                for a in waiting
                if ("agent", a) in self.alive
                and a not in self.frozen
                and self.restarts[a].total == before[a]
                and self.where[a] not in self.missing
            }
            if not waiting:
                break
            if time.monotonic() > deadline:
                local = sorted(a for a in waiting if self.where[a] == self.host)
                if local:
                    raise SwarmError(f"no checkpoint from {', '.join(local)} within 30 s")
                # across hosts a request or its answer can be lost to a cut: their previous checkpoint stays newest
                for a in sorted(waiting):
                    self._event("checkpoint_missed", a, f"no answer from {self.where[a]} within 30 s; training goes on")
                return
            try:
                m = await self._expect(Saved, lambda s: s.epoch == epoch, timeout=0.5)
            except _NoMessage:
                continue
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
            "max_step_seconds": d.max_step_seconds,
            "final_angles_deg": {a: round(math.degrees(q), 4) for a, q in d.final_angles.items()},
            "errors": [round(e, 5) for e in d.errors],
        }
        if d.traces:  # the scene's per-step series (refused moves and clearance among walls, a grasp's forces)
            row["traces"] = d.traces
        self.metrics_file.write(json.dumps(row) + "\n")
        self.metrics_file.flush()


def _tail(path: Path, n: int = 15) -> str:
    try:
        return "\n".join(path.read_text(errors="replace").splitlines()[-n:])
    except OSError:
        return "(no log)"
