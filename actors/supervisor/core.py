"""The supervisor: spawns the simulator and the agents (placements.py), waits until every one is wired and alive,
runs the epochs, gathers metrics (recorder.py), has the agents checkpoint, applies faults (faults.py) and the restart
policy (restarts.py), keeps several hosts in step (hosts.py), and stops everything it started.

One mailbox, handled in order on the loop: the run's messages, and the supervisor's own events — an actor's end, a
restart or thaw coming due, a host's silence, the status tick — posted there by callbacks and timers. Every wait is
on that mailbox (with a deadline), none polls. `run()` owns every resource it opens (an AsyncExitStack) and every
timer it arms, and leaves none behind.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh
from kinswarm.actors.deploy.plan import Plan, local_plan
from kinswarm.actors.run.config import RunConfig
from kinswarm.actors.run.resume import Resume
from kinswarm.actors.run.runfile import task_of
from kinswarm.actors.runtime import Node
from kinswarm.actors.runtime.wake import WakeGuard
from kinswarm.protocol.clock import ClockReader, clock_path
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import (
    AgentTrace,
    Bye,
    EpochDone,
    Event,
    Fault,
    Heartbeat,
    JointStatus,
    Saved,
    Stop,
    SwarmStatus,
)
from kinswarm.protocol.topology import Topology

from .epochs import EpochLoop
from .faults import THAW, FaultRouter
from .hosts import GRACE, SILENT, HostError, HostWatch
from .placements import EXIT, ActorId, Placement, parse_exit
from .recorder import Recorder
from .restarts import RestartBudgetSpent, RestartPolicy
from .result import NoMessage, RunResult, SwarmError
from .stalls import SIM_SILENT, StallError, StallWatch

log = logging.getLogger("kinswarm.supervisor")
ALIVE, RESPAWN, STATUS = "__alive__", "__respawn__", "__status__"  # the supervisor's own mailbox items


class _Down(Exception):
    """Someone asked the swarm to stop (`kinswarm down`: a Stop on ctl/stop)."""


def actors_of(cfg: RunConfig, topo: Topology) -> list[ActorId]:
    if cfg.controller != "agents":
        return [("sim", "sim"), ("controller", cfg.controller)]
    return [("sim", "sim"), *(("agent", a) for a in topo.order)]


class Supervisor:
    STATUS_EVERY = 0.5  # seconds between SwarmStatus messages
    hosts_wait_s = 600.0  # how long the leader waits for the other hosts' actors (`kinswarm up --wait`)
    # A start fails only when it stalls: for START_STALL_S no actor became ready and the processes still starting
    # used less than START_BUSY_CPU_S of CPU between them. N fresh interpreters share the machine's cores (and take
    # turns at loading the learner's compiled kernels), and an actor is ready only once its neighbours listen, so in
    # a large swarm the first become ready after minutes, then the rest in a burst. A fixed 60 s failed a 16-agent
    # chain at load 9-15; 60 s + 2 s an actor still failed a 100-agent chain at load ~130 whose agents were busy.
    # Agents queued on the kernels' lock behind another run's are idle: 60 s of that failed a start at load ~80.
    START_STALL_S = 120.0
    START_BUSY_CPU_S = 1.0

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
        self.agents = list(topo.order) if cfg.controller == "agents" else []
        self.alive: set[ActorId] = set()
        self.node: Node | None = None
        self.result = RunResult()
        self.recorder = Recorder(self.out)
        self.clock = ClockReader(clock_path(self.out))  # the sim's step, when the sim runs on this host
        self.restarts = RestartPolicy(self.agents, cfg.max_restarts, cfg.restart_window_s)
        self.faults = FaultRouter(self)
        self.hosts = HostWatch(self)
        self.epochs = EpochLoop(self)
        self.stalls = StallWatch(self)
        self.training = False  # liveliness changes are events only once the swarm is up
        self.epoch = -1
        self.joints: JointStatus | None = None
        self.byes: dict[str, Bye] = {}
        self.saved: dict[str, int] = {}  # agent -> the epoch of the newest checkpoint it said it saved
        self.why_down: dict[str, tuple[float, str]] = {}  # actor -> (since when, why): what `status` says of it
        self._timers: set[asyncio.TimerHandle] = set()
        self.hostname = {h: h for h in self.plan.hosts} if self.multi else {self.host: socket.gethostname()}
        self.resumed: Resume | None = None  # `--resume`: where the run goes on (actors/run/resume.py)
        # What a reply the run waits for is asked again with, while it waits (expect's `ask`): a pause of this process
        # or of the replier, or a cut, lapses the Zenoh links between them, and what was put meanwhile is lost.
        self.asking: Callable[[], None] | None = None
        self.resend_s = 2 * cfg.lease_ms / 1000  # how often it is asked again while no reply comes
        self.waking: WakeGuard | None = None  # this process's own stalls (run())
        self.on_start: Callable[[int, int], None] | None = None  # told (ready, of) as this host's actors come up

    def host_of(self, actor: ActorId) -> str:
        role, ident = actor
        return self.where[ident] if role == "agent" else self.where["sim"]  # the baseline runs beside the sim

    def later(self, delay: float, key: str, payload: bytes = b"") -> asyncio.TimerHandle:
        """A timer owned by this run: `key` comes through the mailbox after `delay` seconds."""
        assert self.node is not None
        push = self.node.mailbox.push_local
        handle = asyncio.get_running_loop().call_later(
            delay, lambda: (self._timers.discard(handle), push(key, payload))
        )
        self._timers.add(handle)
        return handle

    # -- the run ---------------------------------------------------------------------------------
    async def run(self) -> RunResult:
        t0 = time.perf_counter()
        loop = asyncio.get_running_loop()
        self.node = node = Node(self.session, self.keys, "supervisor", "main" if self.lead else self.host, self.cfg.key)
        self.waking = WakeGuard(node, self.cfg.lease_ms / 1000, later=lambda delay, p: self.later(delay, ALIVE, p))
        k = self.keys
        for key in (k.metrics("epoch"), k.metrics("event"), k.metrics("joints"), k.rep("agent", "*")):
            node.listen(key)
        for key in (k.rep("bye", "*"), k.rep("sim", "*"), k.ctl("stop")):
            node.listen(key)
        if self.cfg.record_agents and self.lead:
            node.listen(k.metrics("agent"))
        node.listen(k.fault("request") if self.lead else k.ctl("fault"))  # others: what the leader forwards
        if self.multi:
            node.listen(k.host("*"))

        def on_alive(sample: Any) -> None:  # zenoh thread
            parsed = self.keys.parse_alive(str(sample.key_expr))
            if parsed is not None:
                up = b"+" if sample.kind == zenoh.SampleKind.PUT else b"-"
                node.mailbox.push(ALIVE, up + f"{parsed[0]}/{parsed[1]}".encode())

        async with contextlib.AsyncExitStack() as stack:
            watch = self.session.liveliness().declare_subscriber(self.keys.alive_all, on_alive, history=True)
            stack.callback(watch.undeclare)
            if self.lead and self.multi:
                stack.callback(self.hosts.serve_setup().undeclare)
            node.declare_alive()
            self.recorder.open_events()
            if self.resumed is not None:  # before anything of the resumed run: the crash and the resume, in order
                self.recorder.event(self.resumed.epoch, 0, "resume", "swarm", self.resumed.detail)
            # a crashed run's clock still reads where its sim died: not this run's until its own sim writes one
            self.clock.path.unlink(missing_ok=True)
            self.placement.attach(node.mailbox.push_local)
            if self.multi:
                self.hosts.start()
            try:
                await self.placement.start(self.local, restore=self.resumed is not None and self.resumed.restore)
                # the status tick, and the wake guard that reads its lateness, from here: the mailbox is handled from
                # the readiness wait on. Armed before the start, a 100-agent start's forks (13 s at load 8) read as
                # the supervisor having been stopped
                self.later(self.STATUS_EVERY, STATUS)
                self.waking.expect(self.STATUS_EVERY)
                await self._wait_ready(self.local)
                if self.lead:
                    await self._wait_alive(self.expected, timeout=self.hosts_wait_s, what="the other hosts' actors")
                    await self.epochs.train()
                else:
                    await self._serve()
            except asyncio.CancelledError:
                self.result.interrupted = True
                log.warning("interrupted: stopping the swarm")
            except _Down as e:
                self.result.interrupted = True
                self.event("down", "swarm", str(e))
            except (SwarmError, RestartBudgetSpent, HostError, StallError) as e:
                self.result.error = str(e)
                log.error("%s", e)
                self.event("failed", "swarm", str(e))
            finally:
                await self._shutdown(loop)
        self.result.wall_seconds = time.perf_counter() - t0
        return self.result

    async def _shutdown(self, loop: asyncio.AbstractEventLoop) -> None:
        """Explicit, in order: Stop to every actor (the leader), their Byes (3 s), the placement stopped (frozen ones
        woken, SIGTERM, SIGKILL), every timer cancelled, the records closed."""
        assert self.node is not None
        self.training = False
        try:
            if self.lead:
                self.node.send(self.keys.ctl("stop"), Stop(reason=self._stop_reason()))
            await self._collect_byes(timeout=3.0)
        except Exception:  # the session may be closing
            pass
        await self.placement.stop()
        for t in self._timers:
            t.cancel()
        self._timers.clear()
        self.hosts.stop()
        self.stalls.stop()
        self.result.rejected_by = {"supervisor": self.node.rejected, **{a: b.rejected for a, b in self.byes.items()}}
        self.result.rejected = sum(self.result.rejected_by.values())
        self.result.restarts = self.restarts.totals
        self.node.close()
        self.recorder.close()
        self.clock.close()

    def _stop_reason(self) -> str:
        return "interrupted" if self.result.interrupted else "failed" if self.result.error else "done"

    async def _serve(self) -> None:
        """Another host's share: keep it alive (restarts, forwarded faults, heartbeats) until the leader's Stop."""
        self.training = True
        log.info("host %s: %d actors up; serving the leader's run %s", self.host, len(self.local), self.cfg.run_id)
        stop = await self.expect(Stop, lambda m: True, timeout=float("inf"))
        self.event("stop", self.host, f"the leader says: {stop.reason}")

    # -- the mailbox -----------------------------------------------------------------------------
    async def expect(
        self,
        kind: type,
        match: Callable[[Any], bool],
        timeout: float,
        stretch: bool = True,
        any_item: bool = False,
        ask: Callable[[], None] | None = None,
    ) -> Any:
        """Handle the mailbox until a message of `kind` satisfying `match` (any item at all with `any_item`); a
        partition stops the deadline's clock. `ask` sends the request the awaited message answers once more: every
        `resend_s` while none comes, when an actor's token comes back and when this process wakes from a stall (its
        answer may have been put while a link was down). Repliers answer a repeated request again, changing nothing."""
        assert self.node is not None
        deadline = time.monotonic() + timeout
        paused0 = self.hosts.paused_seconds(time.monotonic())
        asking, self.asking = self.asking, ask
        next_ask = time.monotonic() + self.resend_s
        try:
            while True:
                now = time.monotonic()
                remaining = deadline - now + (self.hosts.paused_seconds(now) - paused0 if stretch else 0.0)
                if remaining <= 0:
                    raise NoMessage(f"no {kind.__name__} within {timeout:.0f} s")
                if ask is not None:
                    if now >= next_ask:
                        ask()
                        next_ask = now + self.resend_s
                    remaining = min(remaining, next_ask - now)
                try:
                    key, payload = await self.node.recv(timeout=None if remaining == float("inf") else remaining)
                except TimeoutError:
                    continue
                m = self._route(key, payload)
                if isinstance(m, Stop) and self.lead and kind is not Stop:
                    raise _Down(f"stop requested ({m.reason})")
                if isinstance(m, kind) and match(m):
                    return m
                if any_item:
                    return None
        finally:
            self.asking = asking

    def ask_again(self, why: str) -> None:
        """Send the awaited reply's request again now (an actor's token came back, or this process woke)."""
        if self.asking is not None:
            log.info("asking again for the reply awaited: %s", why)
            self.asking()

    async def _collect_byes(self, timeout: float) -> None:
        assert self.node is not None
        want = {ident for role, ident in self.expected if (role, ident) in self.alive}
        deadline = time.monotonic() + timeout
        next_ask = time.monotonic() + self.cfg.lease_ms / 1000
        while not want <= set(self.byes) and time.monotonic() < deadline:
            now = time.monotonic()
            if self.lead and now >= next_ask:  # a Stop put while a link was down is lost: once more, a lease on
                self.node.send(self.keys.ctl("stop"), Stop(reason=self._stop_reason()))
                next_ask = now + self.cfg.lease_ms / 1000
            try:
                key, payload = await self.node.recv(timeout=max(0.0, min(deadline, next_ask) - now))
            except TimeoutError:
                continue
            with contextlib.suppress(SwarmError, RestartBudgetSpent, HostError, StallError):  # leaving anyway
                self._route(key, payload)

    async def _wait_alive(self, expected: list[ActorId], timeout: float, what: str = "") -> None:
        if what and not set(expected) <= self.alive:
            hosts = sorted({self.host_of(a) for a in set(expected) - self.alive})
            log.warning("waiting for %s (on %s): start `kinswarm up PLAN --host NAME` there", what, ", ".join(hosts))
        try:
            async with asyncio.timeout(timeout):
                while not set(expected) <= self.alive:
                    assert self.node is not None
                    self._route(*await self.node.recv())
        except TimeoutError:
            raise SwarmError(f"not alive after {timeout:.0f} s: {sorted(set(expected) - self.alive)}") from None

    async def _wait_ready(self, expected: list[ActorId]) -> None:
        """Until every actor of `expected` is alive (wired, matched, its token up), telling `on_start` as they come;
        a SwarmError once the start stalls (START_STALL_S with no actor become ready and the starting processes
        idle), never after a fixed time."""
        assert self.node is not None
        want = set(expected)
        ready = len(want & self.alive)
        if self.on_start is not None:
            self.on_start(ready, len(want))
        # several hosts: an actor here is ready only once its neighbours on the other hosts listen, and those start
        # when someone starts them there (`kinswarm up --wait`)
        stall_s = max(self.START_STALL_S, self.hosts_wait_s) if self.multi else self.START_STALL_S
        deadline, cpu = time.monotonic() + stall_s, self._starting_cpu(want)
        while ready < len(want):
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                now_cpu = self._starting_cpu(want)
                if now_cpu is not None and cpu is not None and now_cpu - cpu >= self.START_BUSY_CPU_S:
                    log.info(
                        "starting: %d/%d actors ready, the others busy (%.0f CPU-s)", ready, len(want), now_cpu - cpu
                    )
                    deadline, cpu = time.monotonic() + stall_s, now_cpu
                    continue
                late = [f"{role} {ident}" for role, ident in sorted(want - self.alive)]
                more = f" and {len(late) - 8} more" if len(late) > 8 else ""
                why = f"{ready}/{len(want)} ready; not: {', '.join(late[:8])}{more}"
                raise SwarmError(f"starting: no actor became ready for {stall_s:.0f} s, nor busy ({why})")
            try:
                self._route(*await self.node.recv(timeout=remaining))
            except TimeoutError:
                continue
            if (now := len(want & self.alive)) > ready:
                ready = now
                deadline, cpu = time.monotonic() + stall_s, self._starting_cpu(want)
                log.info("starting: %d/%d actors ready", ready, len(want))
                if self.on_start is not None:
                    self.on_start(ready, len(want))

    def _starting_cpu(self, want: set[ActorId]) -> float | None:
        """CPU seconds used so far by the processes of the actors of `want` not yet alive (Linux: /proc/PID/stat);
        None where actors share this process (the single placement) or /proc cannot tell."""
        pids = self.placement.pids
        mine = os.getpid()
        own = [pids[ident] for role, ident in want - self.alive if pids.get(ident, mine) != mine]
        if not own:
            return None
        total = 0
        for pid in own:
            try:  # utime and stime: fields 14 and 15, counted after the command's closing parenthesis
                fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
                total += int(fields[11]) + int(fields[12])
            except (OSError, IndexError, ValueError):  # gone (its end is an event of its own), or no /proc
                continue
        return total / os.sysconf("SC_CLK_TCK")

    def _route(self, key: str, payload: bytes) -> Any:
        """Handle one mailbox item: the supervisor's own events and what it consumes itself; return EpochDone,
        Saved, Bye and Stop to the caller."""
        node = self.node
        assert node is not None
        if key.startswith("__"):
            self._own(key, payload)
            return None
        kind = key[len(self.keys.root) + 1 :]
        if kind == "metrics/epoch":
            return node.decode(key, payload, EpochDone)
        if kind.startswith("rep/agent/"):
            return node.decode(key, payload, Saved)
        if kind.startswith(("rep/bye/", "rep/sim/")):
            if (bye := node.decode(key, payload, Bye)) is not None:
                self.byes[self.keys.last_chunk(key)] = bye
            return bye
        if kind == "ctl/stop":
            return node.decode(key, payload, Stop)
        if kind == "metrics/event":
            if (e := node.decode(key, payload, Event)) is not None:
                if e.event == "restored":  # when it happened; which checkpoint's epoch, in a field of its own
                    newest = self.saved.get(e.target, -1)  # a restart must restore this one (or a newer one)
                    self.event(e.event, e.target, e.detail, checkpoint_epoch=e.epoch, newest_saved=newest)
                else:
                    self.recorder.event(e.epoch, e.step, e.event, e.target, e.detail)
        elif kind == "metrics/agent":
            if (tr := node.decode(key, payload, AgentTrace)) is not None:
                self.recorder.agent(tr)
        elif kind == "metrics/joints":
            if (j := node.decode(key, payload, JointStatus)) is not None:
                self._on_joints(j)
        elif kind == "fault/request":
            if (f := node.decode(key, payload, Fault)) is not None:
                self.faults.on_request(f)
        elif kind == "ctl/fault" and not self.lead:
            if (f := node.decode(key, payload, Fault)) is not None:
                self.faults.on_forwarded(f)
        elif kind.startswith("ctl/host/"):
            hb = node.decode(key, payload, Heartbeat)
            if hb is not None and hb.host in self.plan.hosts and hb.host != self.host:
                self.hosts.heard_from(hb.host)
        return None

    def _own(self, key: str, payload: bytes) -> None:
        """The supervisor's own events, in the mailbox's order with the messages."""
        now = time.monotonic()
        if key == ALIVE:
            assert self.waking is not None  # a loss heard as this process wakes is held a lease (runtime/wake.py)
            if (change := self.waking.token(payload.decode())) is not None:
                role, ident = change[1:].split("/", 1)
                self._alive_changed((role, ident), change[0] == "+")
        elif key == EXIT:
            actor, how = parse_exit(payload)
            self._on_exit(actor, how, now)
        elif key == RESPAWN:
            agent = payload.decode()
            self.placement.spawn(("agent", agent), restore=True)
            self.event("restart", agent, f"restart {self.restarts.total(agent)} (restores its newest checkpoint)")
        elif key == THAW:
            self.faults.on_thaw_due(payload.decode())
        elif key == SILENT:
            self.hosts.on_silent(payload.decode())
        elif key == GRACE:
            self.hosts.on_grace(payload.decode())
        elif key == SIM_SILENT:
            self.stalls.on_silent()
        elif key == STATUS:
            assert self.waking is not None
            # In the single placement every actor shares this process and its session: a late tick is its loop busy
            # with their steps, and a pause stops them all alike with no link between them to lapse.
            if self.waking.ticked() and self.cfg.placement != "single":
                self._woke(now)
            self.later(self.STATUS_EVERY, STATUS)
            self.waking.expect(self.STATUS_EVERY)
            if self.lead:
                self._publish_status(now)

    def _woke(self, now: float) -> None:
        """This process did not run for a while (SIGSTOP, starved): not the swarm's stall, and the reply it waits for
        may have been put while its links were down."""
        assert self.waking is not None
        slept = self.waking.slept
        # while a swarm starts, a loaded machine starves every process for seconds: worth a line in the log, not a
        # warning on a newcomer's terminal; once training, it is on the run's record too
        log.log(
            logging.WARNING if self.training else logging.INFO,
            "the supervisor did not run for %.1f s (stopped or starved): asking again for its replies",
            slept,
        )
        if self.training:
            self.event(
                "woke", "supervisor", f"did not run for {slept:.1f} s (stopped or starved)", seconds=round(slept, 3)
            )
        self.stalls.woke(now)
        self.ask_again("the supervisor woke")

    def _on_joints(self, j: JointStatus) -> None:
        self.joints = j
        self.epochs.on_joints(j)
        if self.lead:
            self.stalls.on_joints(j)

    # -- liveliness, exits, restarts -------------------------------------------------------------
    def _alive_changed(self, actor: ActorId, up: bool) -> None:
        changed = (actor in self.alive) != up  # a token back that was never counted gone (held as this process woke)
        if up:
            self.alive.add(actor)
            self.why_down.pop(actor[1], None)
        else:
            self.alive.discard(actor)
            self.why_down.setdefault(actor[1], (time.monotonic(), "its liveliness token went away"))
        if self.training and actor[0] != "supervisor":
            if changed:
                self.event("alive" if up else "lost", actor[1], "liveliness token " + ("back" if up else "gone"))
                if not up:
                    self.result.tokens_lost[actor[1]] = self.result.tokens_lost.get(actor[1], 0) + 1
            if up:  # its links were down a while: a reply it put meanwhile is lost
                self.ask_again(f"{actor[0]} {actor[1]}'s token is back")

    def _on_exit(self, actor: ActorId, how: str, now: float) -> None:
        role, ident = actor
        if not self.training:  # starting up: nothing to restart from yet
            raise SwarmError(f"{role} {ident} {how}; its log ends:\n{self.placement.log_tail(actor)}")
        if role != "agent":
            raise SwarmError(f"{role} {ident} on {self.host} {how}; its log ends:\n{self.placement.log_tail(actor)}")
        self.event("exited", ident, how)
        self.faults.frozen.pop(ident, None)
        delay = self.restarts.on_exit(ident, now)
        self.why_down[ident] = (now, f"{how}; restart {self.restarts.total(ident)} due {delay:.1f} s after")
        self.later(delay, RESPAWN, ident.encode())

    # -- records ---------------------------------------------------------------------------------
    def now(self) -> tuple[int, int]:
        """(epoch, step) of the sim at this moment: read from its clock on this host (exact), else its latest status
        (another host's sim), else the epoch about to run at its step 0. Never -1, never another epoch's step."""
        at = self.clock.read()
        if at is None and self.joints is not None:
            at = (self.joints.epoch, self.joints.step)
        if at is None or at[0] < 0:  # the sim has run no step yet (of this run, or of this resumed run)
            first = self.resumed.epoch if self.resumed is not None else 0
            return max(self.epoch, first), 0
        return at

    def event(self, event: str, target: str, detail: str, at: tuple[int, int] | None = None, **extra: object) -> None:
        """Record an event at `at` (epoch, step), or at the sim's step now."""
        self.recorder.event(*(at or self.now()), event, target, detail, **extra)

    def _publish_status(self, now: float) -> None:
        assert self.node is not None
        ids = [ident for _, ident in self.expected]
        roles = dict((ident, role) for role, ident in self.expected)
        pids = self.placement.pids
        faults: dict[str, list[str]] = {i: [] for i in ids}
        for agent, what in self.faults.status(now).items():
            faults.setdefault(agent, []).extend(what)
        for ident, (since, why) in self.why_down.items():
            if ident in faults and (roles[ident], ident) not in self.alive:
                faults[ident].append(f"down {now - since:.1f} s: {why}")
        if self.joints is not None:
            for joint, what in self.joints.faults.items():
                faults.setdefault(joint, []).append(what)
        if stalled := self.stalls.status(now):
            faults.setdefault("sim", []).append(stalled)
        status = SwarmStatus(
            epoch=self.epoch,
            epochs=self.cfg.epochs,
            role=roles,
            alive={i: int((roles[i], i) in self.alive) for i in ids},
            pid={i: pids.get(i, 0) for i in ids},
            host={i: self.hostname.get(self.host_of((roles[i], i)), self.host_of((roles[i], i))) for i in ids},
            restarts={i: self.restarts.total(i) for i in ids},
            faults=faults,
        )
        self.node.send(self.keys.metrics("status"), status)
