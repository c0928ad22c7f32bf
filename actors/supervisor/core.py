"""The supervisor: spawns the simulator and the agents (placements.py), waits until every one is wired and alive,
runs the epochs, gathers metrics (recorder.py), has the agents checkpoint, applies faults (faults.py) and the restart
policy (restarts.py), keeps several hosts in step (hosts.py), and stops everything it started.

One mailbox, handled in order on the loop: the run's messages, and the supervisor's own events — an actor's end, a
restart or thaw coming due, a host's silence, the status tick — posted there by callbacks and timers. Every wait is
on that mailbox (with a deadline), none polls (replies.py: the waits, and the replies asked for again; readiness.py:
the start). Each part owns its state: the supervisor reads it, and changes it only through the part's methods.
`run()` owns every resource it opens (an AsyncExitStack) and every timer it arms, and leaves none behind.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh
from kinswarm.actors.deploy.plan import Plan, local_plan
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.files.resume import Resume
from kinswarm.actors.files.runfile import task_of
from kinswarm.actors.runtime import Node
from kinswarm.actors.runtime.wake import WakeGuard
from kinswarm.protocol.clock import ClockReader, clock_path
from kinswarm.protocol.keys import GONE, UP, Key, Keys, parse_token_change, token_change
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
)
from kinswarm.protocol.topology import Topology

from .epochs import EpochLoop
from .faults import THAW, FaultRouter
from .hosts import GRACE, SILENT, HostError, HostWatch
from .placements import EXIT, ActorId, Placement, parse_exit
from .readiness import Readiness
from .recorder import Recorder
from .replies import Replies
from .restarts import RestartBudgetSpent, RestartPolicy
from .result import NoMessage, RunResult, SwarmError
from .stalls import SIM_SILENT, StallError, StallWatch
from .status import swarm_status

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
        self.epochs = EpochLoop(self, self._epoch_done)  # whether it trains, the epoch, the checkpoints saved
        self.stalls = StallWatch(self)
        self.starting = Readiness(self.alive, self._handle, lambda: self.placement.pids, self.host_of)
        self.joints: JointStatus | None = None
        self.byes: dict[str, Bye] = {}
        self.why_down: dict[str, tuple[float, str]] = {}  # actor -> (since when, why): what `status` says of it
        self._timers: set[asyncio.TimerHandle] = set()
        self.hostname = {h: h for h in self.plan.hosts} if self.multi else {self.host: socket.gethostname()}
        self.resumed: Resume | None = None  # `--resume`: where the run goes on (actors/files/resume.py)
        # every wait on the mailbox; a reply waited for is asked again every two leases while none comes
        self.replies = Replies(
            self._recv, self._route, self.hosts.paused_seconds, 2 * cfg.lease_ms / 1000, self._stop_requested
        )
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

    async def _recv(self, timeout: float | None) -> tuple[str, bytes]:
        assert self.node is not None
        return await self.node.recv(timeout=timeout)

    async def _handle(self, timeout: float | None) -> None:
        """Handle the next mailbox item while the swarm starts (TimeoutError after `timeout` s): a Stop then is
        `kinswarm down` before the first epoch, and stops the start."""
        if isinstance(item := self._route(*await self._recv(timeout)), Stop):
            self._stop_requested(item)

    def _stop_requested(self, stop: Stop) -> None:
        """A Stop on ctl/stop while the leader waits: someone ran `kinswarm down`."""
        if self.lead:
            raise _Down(f"stop requested ({stop.reason})")

    def _epoch_done(self, done: EpochDone) -> None:
        if self.on_epoch is not None:
            self.on_epoch(done)
        self.result.epochs.append(done)
        self.recorder.epoch(done)

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
            key = str(sample.key_expr)
            if self.keys.parse_alive(key) is not None:
                sign = UP if sample.kind == zenoh.SampleKind.PUT else GONE
                node.mailbox.push(ALIVE, token_change(sign, key).encode())

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
                # several hosts: an actor here is ready only once its neighbours on the other hosts listen, and those
                # start when someone starts them there (`kinswarm up --wait`)
                stall_s = Readiness.START_STALL_S
                if self.multi:
                    stall_s = max(stall_s, self.hosts_wait_s)
                await self.starting.ready(self.local, stall_s, self.on_start)
                if self.lead:
                    await self.starting.alive_within(self.expected, self.hosts_wait_s, "the other hosts' actors")
                    await self.epochs.train()
                else:
                    await self.epochs.follow()
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
        self.epochs.end()
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

    async def _collect_byes(self, timeout: float) -> None:
        """Every live actor's Bye, for `timeout` s at most; the leader's Stop sent again every lease meanwhile (a Stop
        put while a link was down is lost)."""
        want = {ident for role, ident in self.expected if (role, ident) in self.alive}

        def stop() -> None:
            assert self.node is not None
            self.node.send(self.keys.ctl("stop"), Stop(reason=self._stop_reason()))

        leaving = (SwarmError, RestartBudgetSpent, HostError, StallError)  # an item's error: the run leaves anyway
        ask = stop if self.lead else None
        with contextlib.suppress(NoMessage):
            await self.replies.until(
                lambda m: want <= set(self.byes),
                timeout,
                what="Bye",
                stretch=False,
                ask=ask,
                every=self.cfg.lease_ms / 1000,
                stops=False,
                quiet=leaving,
            )

    def _route(self, key: str, payload: bytes) -> Any:
        """Handle one mailbox item: the supervisor's own events and what it consumes itself; return EpochDone,
        Saved, Bye and Stop to the caller."""
        node = self.node
        assert node is not None
        if key.startswith("__"):
            self._own(key, payload)
            return None
        match self.keys.parse(key):
            case Key("metrics", ("epoch",)):
                return node.decode(key, payload, EpochDone)
            case Key("rep", ("agent", _)):
                return node.decode(key, payload, Saved)
            case Key("rep", ("bye" | "sim", ident)):
                if (bye := node.decode(key, payload, Bye)) is not None:
                    self.byes[ident] = bye
                return bye
            case Key("ctl", ("stop",)):
                return node.decode(key, payload, Stop)
            case Key("metrics", ("event",)):
                self._on_event(node.decode(key, payload, Event))
            case Key("metrics", ("agent",)):
                if (tr := node.decode(key, payload, AgentTrace)) is not None:
                    self.recorder.agent(tr)
            case Key("metrics", ("joints",)):
                if (j := node.decode(key, payload, JointStatus)) is not None:
                    self._on_joints(j)
            case Key("fault", ("request",)):
                if (f := node.decode(key, payload, Fault)) is not None:
                    self.faults.on_request(f)
            case Key("ctl", ("fault",)) if not self.lead:
                if (f := node.decode(key, payload, Fault)) is not None:
                    self.faults.on_forwarded(f)
            case Key("host", _):
                hb = node.decode(key, payload, Heartbeat)
                if hb is not None and hb.host in self.plan.hosts and hb.host != self.host:
                    self.hosts.heard_from(hb.host)
        return None

    def _on_event(self, e: Event | None) -> None:
        """An actor's event, recorded; a restart's restore with the newest checkpoint its agent said it saved."""
        if e is None:
            return
        if e.event == "restored":  # when it happened; which checkpoint's epoch, in a field of its own
            newest = self.epochs.saved.get(e.target, -1)  # a restart must restore this one (or a newer one)
            self.event(e.event, e.target, e.detail, checkpoint_epoch=e.epoch, newest_saved=newest)
        else:
            self.recorder.event(e.epoch, e.step, e.event, e.target, e.detail)

    def _own(self, key: str, payload: bytes) -> None:
        """The supervisor's own events, in the mailbox's order with the messages."""
        now = time.monotonic()
        if key == ALIVE:
            assert self.waking is not None  # a loss heard as this process wakes is held a lease (runtime/wake.py)
            if (change := self.waking.token(payload.decode())) is not None:
                sign, key = parse_token_change(change)
                if (actor := self.keys.parse_alive(key)) is not None:
                    self._alive_changed(actor, sign == UP)
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
            logging.WARNING if self.epochs.training else logging.INFO,
            "the supervisor did not run for %.1f s (stopped or starved): asking again for its replies",
            slept,
        )
        if self.epochs.training:
            self.event(
                "woke", "supervisor", f"did not run for {slept:.1f} s (stopped or starved)", seconds=round(slept, 3)
            )
        self.stalls.woke(now)
        self.replies.ask_again("the supervisor woke")

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
        if self.epochs.training and actor[0] != "supervisor":
            if changed:
                self.event("alive" if up else "lost", actor[1], "liveliness token " + ("back" if up else "gone"))
                if not up:
                    self.result.tokens_lost[actor[1]] = self.result.tokens_lost.get(actor[1], 0) + 1
            if up:  # its links were down a while: a reply it put meanwhile is lost
                self.replies.ask_again(f"{actor[0]} {actor[1]}'s token is back")

    def _on_exit(self, actor: ActorId, how: str, now: float) -> None:
        role, ident = actor
        if not self.epochs.training:  # starting up: nothing to restart from yet
            raise SwarmError(f"{role} {ident} {how}; its log ends:\n{self.placement.log_tail(actor)}")
        if role != "agent":
            raise SwarmError(f"{role} {ident} on {self.host} {how}; its log ends:\n{self.placement.log_tail(actor)}")
        self.event("exited", ident, how)
        self.faults.exited(ident)
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
            return max(self.epochs.epoch, first), 0
        return at

    def event(self, event: str, target: str, detail: str, at: tuple[int, int] | None = None, **extra: object) -> None:
        """Record an event at `at` (epoch, step), or at the sim's step now."""
        self.recorder.event(*(at or self.now()), event, target, detail, **extra)

    def _publish_status(self, now: float) -> None:
        assert self.node is not None
        status = swarm_status(
            epoch=self.epochs.epoch,
            epochs=self.cfg.epochs,
            expected=self.expected,
            alive=self.alive,
            pids=self.placement.pids,
            host=lambda actor: self.hostname.get(self.host_of(actor), self.host_of(actor)),
            restarts=self.restarts.total,
            faults_now=self.faults.status(now),
            why_down=self.why_down,
            joints=self.joints,
            stalled=self.stalls.status(now),
            now=now,
        )
        self.node.send(self.keys.metrics("status"), status)
