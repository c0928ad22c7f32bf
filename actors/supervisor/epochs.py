"""The epoch loop (the leader): each epoch's start (the task's goal, and each step's when it moves), its end awaited
(the deadline stretched by a partition), its row recorded, and the agents' checkpoints gathered."""

from __future__ import annotations

import contextlib
import logging
import time
from pathlib import Path
from typing import TYPE_CHECKING

from kinswarm.actors.step.epoch import checkpoint_due, epoch_start
from kinswarm.protocol.messages import Checkpoint, EpochDone, EpochStart, JointStatus, Saved

from .result import NoMessage, SwarmError

if TYPE_CHECKING:
    from .core import Supervisor

log = logging.getLogger("kinswarm.supervisor")


class EpochLoop:
    def __init__(self, sup: Supervisor) -> None:
        self.sup = sup
        self._sent = 0.0
        self._start: EpochStart | None = None  # while its EpochDone is awaited

    @property
    def running(self) -> EpochStart | None:
        """The epoch under way (its start went out, its end has not come)."""
        return self._start

    async def train(self) -> None:
        sup, cfg = self.sup, self.sup.cfg
        assert sup.node is not None
        await sup.node.wait_matched([sup.keys.ctl(v) for v in ("epoch", "checkpoint", "fault")], timeout=10.0)
        sup.recorder.open_metrics()
        sup.training = True
        sup.stalls.arm()
        first = sup.resumed.epoch if sup.resumed is not None else 0  # a resumed run: after its checkpoint
        for epoch in range(first, cfg.epochs):
            done = await self.run_epoch(epoch)
            sup.result.epochs.append(done)
            sup.recorder.epoch(done)
            if sup.agents and checkpoint_due(cfg, epoch):
                await self.checkpoint(epoch)

    def epoch_start(self, epoch: int) -> EpochStart:
        return epoch_start(self.sup.cfg, self.sup.task, epoch)

    async def run_epoch(self, epoch: int) -> EpochDone:
        sup, cfg = self.sup, self.sup.cfg
        assert sup.node is not None
        sup.epoch = epoch
        self._start = self.epoch_start(epoch)
        while sup.hosts.missing:  # not into a partition: the other side would miss the start
            with contextlib.suppress(NoMessage):
                await sup.expect(Saved, lambda m: False, timeout=0.2, stretch=False)
        sup.node.send(sup.keys.ctl("epoch"), self._start)
        self._sent = time.monotonic()
        sup.stalls.epoch_started(self._sent)
        # generous: every step may run into its deadline and still finish
        timeout = 30.0 + cfg.steps * cfg.deadline_ms / 1000 * 1.5
        # The start goes out again while its end does not come: the sim takes its running epoch's start as nothing,
        # and answers a finished one's with its EpochDone again (a pause or a cut may have lost either message)
        done = await sup.expect(EpochDone, lambda m: m.epoch == epoch, timeout, ask=self._ask_epoch)
        self._start = None
        if sup.on_epoch is not None:
            sup.on_epoch(done)
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
        sup.node.send(sup.keys.ctl("checkpoint"), request)

        def ask() -> None:  # an agent that saved already answers the same request with the same Saved, saving nothing
            assert sup.node is not None
            sup.node.send(sup.keys.ctl("checkpoint"), request)

        next_ask = time.monotonic() + sup.resend_s
        # An agent that is down, or dies before answering, cannot answer: its previous checkpoint stays
        # its newest, and a restarted one resumes from that.
        before = dict(sup.restarts.totals)
        waiting = set(sup.topo.dof_agents)
        deadline = time.monotonic() + 30.0
        while True:
            waiting = {
                a
                for a in waiting
                if ("agent", a) in sup.alive
                and a not in sup.faults.frozen
                and sup.restarts.total(a) == before[a]
                and sup.where[a] not in sup.hosts.missing
            }
            if not waiting:
                return
            if time.monotonic() > deadline:
                local = sorted(a for a in waiting if sup.where[a] == sup.host)
                if local:
                    raise SwarmError(f"no checkpoint from {', '.join(local)} within 30 s")
                # across hosts a request or its answer can be lost to a cut: their previous checkpoint stays newest
                for a in sorted(waiting):
                    sup.event("checkpoint_missed", a, f"no answer from {sup.where[a]} within 30 s; training goes on")
                return
            if time.monotonic() >= next_ask:  # its Saved may have been lost on the way (a pause, a cut)
                ask()
                next_ask = time.monotonic() + sup.resend_s
            try:  # any mailbox item (an exit, a token gone) may end the wait for an agent: look again after each
                m = await sup.expect(Saved, lambda s: s.epoch == epoch, timeout=0.5, any_item=True, ask=ask)
            except NoMessage:
                continue
            if isinstance(m, Saved):
                if m.error:
                    raise SwarmError(f"agent {Path(m.path).stem} could not checkpoint: {m.error}")
                waiting.discard(Path(m.path).stem)
                sup.saved[Path(m.path).stem] = m.epoch
