"""The epoch loop (the leader): each epoch's start (the task's goal, and each step's when it moves), its end awaited
(the deadline stretched by a partition), its row handed on, and the agents' checkpoints gathered. Another host follows
the leader's epochs until its Stop. What the loop owns, it alone changes and the supervisor reads: whether the swarm
trains, the epoch under way, and the newest checkpoint each agent said it saved."""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING

from kinswarm.actors.step.epoch import checkpoint_due, epoch_start
from kinswarm.protocol.messages import Checkpoint, EpochDone, EpochStart, JointStatus, Saved, Stop

from .result import NoMessage, SwarmError

if TYPE_CHECKING:
    from .core import Supervisor

log = logging.getLogger("kinswarm.supervisor")


class EpochLoop:
    def __init__(self, sup: Supervisor, done: Callable[[EpochDone], None]) -> None:
        """`done`: told each epoch's end, in order (the supervisor records it and tells its watchers)."""
        self.sup = sup
        self._done = done
        self._sent = 0.0
        self._start: EpochStart | None = None  # while its EpochDone is awaited
        self._training = False
        self._epoch = -1
        self._saved: dict[str, int] = {}

    @property
    def training(self) -> bool:
        """Whether the swarm trains: from the first epoch (the leader) or the actors' start (another host) to the
        run's end. Only then is an actor's end restarted, a token's loss recorded, a process fault accepted."""
        return self._training

    @property
    def epoch(self) -> int:
        """The epoch under way, or the last one run (-1 before the first)."""
        return self._epoch

    @property
    def saved(self) -> Mapping[str, int]:
        """agent -> the epoch of the newest checkpoint it said it saved."""
        return self._saved

    @property
    def running(self) -> EpochStart | None:
        """The epoch under way (its start went out, its end has not come)."""
        return self._start

    async def train(self) -> None:
        sup, cfg = self.sup, self.sup.cfg
        assert sup.node is not None
        await sup.node.wait_matched([sup.keys.ctl(v) for v in ("epoch", "checkpoint", "fault")], timeout=10.0)
        sup.recorder.open_metrics()
        self._training = True
        sup.stalls.arm()
        first = sup.resumed.epoch if sup.resumed is not None else 0  # a resumed run: after its checkpoint
        for epoch in range(first, cfg.epochs):
            self._done(await self.run_epoch(epoch))
            if sup.agents and checkpoint_due(cfg, epoch):
                await self.checkpoint(epoch)

    async def follow(self) -> None:
        """Another host's share: it trains as the leader's epochs go (restarts, forwarded faults, heartbeats) until
        the leader's Stop."""
        sup = self.sup
        self._training = True
        log.info("host %s: %d actors up; serving the leader's run %s", sup.host, len(sup.local), sup.cfg.run_id)
        stop = await sup.replies.expect(Stop, lambda m: True, timeout=math.inf)
        sup.event("stop", sup.host, f"the leader says: {stop.reason}")

    def end(self) -> None:
        """The run ends: nothing from here on is training's (an actor's end is not restarted)."""
        self._training = False

    def epoch_start(self, epoch: int) -> EpochStart:
        return epoch_start(self.sup.cfg, self.sup.task, epoch)

    async def run_epoch(self, epoch: int) -> EpochDone:
        sup, cfg = self.sup, self.sup.cfg
        assert sup.node is not None
        self._epoch = epoch
        self._start = self.epoch_start(epoch)
        hosts = sup.hosts
        # not into a partition: the other side would miss the start. Each heartbeat is a mailbox item, and the last
        # missing host's rejoins the run: the wait ends on that item.
        await sup.replies.until(lambda m: not hosts.missing, math.inf, what="the other hosts", stretch=False)
        sup.node.send(sup.keys.ctl("epoch"), self._start)
        self._sent = time.monotonic()
        sup.stalls.epoch_started(self._sent)
        # generous: every step may run into its deadline and still finish
        timeout = 30.0 + cfg.steps * cfg.deadline_ms / 1000 * 1.5
        # The start goes out again while its end does not come: the sim takes its running epoch's start as nothing,
        # and answers a finished one's with its EpochDone again (a pause or a cut may have lost either message)
        done = await sup.replies.expect(EpochDone, lambda m: m.epoch == epoch, timeout, ask=self._ask_epoch)
        self._start = None
        return done

    def _ask_epoch(self) -> None:
        sup, start = self.sup, self._start
        if start is not None and sup.node is not None and not sup.hosts.missing:
            sup.node.send(sup.keys.ctl("epoch"), start)
            self._sent = time.monotonic()

    def on_joints(self, j: JointStatus) -> None:
        """The sim's status: still at an earlier epoch a second after this one's start went out, the start was lost
        to a partition; it goes out again. Only across hosts: on one host nothing is lost on the way (BLOCK), and a
        status the supervisor reads late (its loop busy with a single placement's steps) is not news."""
        sup, start = self.sup, self._start
        if len(sup.cfg.hosts) < 2:
            return
        if start is not None and j.epoch < start.epoch and not sup.hosts.missing:
            if time.monotonic() - self._sent > 1.0:
                log.warning("the sim is still at epoch %d: sending epoch %d's start again", j.epoch, start.epoch)
                assert sup.node is not None
                sup.node.send(sup.keys.ctl("epoch"), start)
                self._sent = time.monotonic()

    async def checkpoint(self, epoch: int) -> None:
        sup = self.sup
        assert sup.node is not None
        directory = sup.out / "agents"
        directory.mkdir(parents=True, exist_ok=True)
        request = Checkpoint(epoch=epoch, directory=str(directory))

        def ask() -> None:  # an agent that saved already answers the same request with the same Saved, saving nothing
            assert sup.node is not None
            sup.node.send(sup.keys.ctl("checkpoint"), request)

        ask()
        # An agent that is down, or dies before answering, cannot answer: its previous checkpoint stays
        # its newest, and a restarted one resumes from that.
        before = dict(sup.restarts.totals)
        waiting = set(sup.topo.dof_agents)

        def answered(m: object) -> bool:
            """Whether no agent is left to wait for, after mailbox item `m` (any item may end the wait for one: an
            exit, a token gone, a freeze, a host cut off)."""
            if isinstance(m, Saved) and m.epoch == epoch:
                agent = Path(m.path).stem
                if m.error:
                    raise SwarmError(f"agent {agent} could not checkpoint: {m.error}")
                waiting.discard(agent)
                self._saved[agent] = m.epoch
            waiting.difference_update(
                [
                    a
                    for a in waiting
                    if ("agent", a) not in sup.alive
                    or a in sup.faults.frozen
                    or sup.restarts.total(a) != before[a]
                    or sup.where[a] in sup.hosts.missing
                ]
            )
            return not waiting

        try:  # its Saved may be lost on the way (a pause, a cut): the request goes out again meanwhile
            await sup.replies.until(answered, 30.0, what="checkpoint", stretch=False, ask=ask)
        except NoMessage:
            local = sorted(a for a in waiting if sup.where[a] == sup.host)
            if local:
                raise SwarmError(f"no checkpoint from {', '.join(local)} within 30 s") from None
            # across hosts a request or its answer can be lost to a cut: their previous checkpoint stays newest
            for a in sorted(waiting):
                sup.event("checkpoint_missed", a, f"no answer from {sup.where[a]} within 30 s; training goes on")
