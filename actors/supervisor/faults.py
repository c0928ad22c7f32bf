"""Fault routing (docs/faults.md): every fault request is checked once, then applied where it lives. Process faults
(kill, freeze, thaw, restart) by signals to this host's placement, forwarded to the host that owns the others;
joint faults through the sim and link faults through the targets' runtimes, by forwarding the same message on
ctl/fault. A freeze with a duration thaws by a timer (a THAW item in the mailbox), not by polling."""

from __future__ import annotations

import dataclasses
import logging
import signal
import time
from typing import TYPE_CHECKING

from kinswarm.actors.files.config import placement_problem
from kinswarm.protocol.faults import (
    ALL,
    JOINT_FAULTS,
    LINK_FAULTS,
    PROCESS_FAULTS,
    check_fault,
    describe,
    expand_targets,
)
from kinswarm.protocol.keys import check_id
from kinswarm.protocol.messages import Fault, FaultReply

if TYPE_CHECKING:
    from .core import Supervisor

log = logging.getLogger("kinswarm.supervisor")
THAW = "__thaw__"  # mailbox key: payload b"agent"


class FaultRouter:
    def __init__(self, sup: Supervisor) -> None:
        self.sup = sup
        self.frozen: dict[str, float | None] = {}  # agent -> when to thaw it (None: on `thaw`)
        self.link_faults: dict[str, list[tuple[str, float | None]]] = {}  # agent -> (description, expiry)

    def on_request(self, f: Fault) -> None:
        """A request on fault/request (the leader): check, apply, record, reply."""
        sup = self.sup
        assert sup.node is not None
        error = check_fault(f, list(sup.topo.order))
        if not error and not sup.agents and f.fault not in JOINT_FAULTS:
            error = f"{f.fault}: this run has no agents (a baseline run); only joint faults apply"
        if not error and f.robot is not None and f.robot >= sup.cfg.fleet:
            error = f"{f.fault}: robot {f.robot}: this run's fleet has {sup.cfg.fleet} (robots 0..{sup.cfg.fleet - 1})"
        if not error and f.fault in PROCESS_FAULTS and f.fault not in sup.placement.supports:
            error = placement_problem(f.fault, sup.cfg.placement) or f"{f.fault}: not in this run's placement"
        if not error and f.fault in PROCESS_FAULTS and f.fault != "thaw" and not sup.epochs.training:
            # an actor that ends while the swarm starts fails the run (nothing to restart from yet)
            error = f"{f.fault}: the swarm is not training (its actors are starting, or it is ending); try again"
        if not error and f.fault in JOINT_FAULTS:
            compound = [t for t in f.targets if t != ALL and not sup.topo.agents[t].has_dof]
            if compound:
                error = f"{f.fault}: {', '.join(compound)} has no joint (a compound agent)"
        detail = ""
        # The step the request goes out at, read before it goes: read after, a supervisor descheduled in between
        # (a busy machine) stamped it steps after the sim had already applied it.
        at = sup.now()
        if not error:
            pool = sup.agents if f.fault not in JOINT_FAULTS else list(sup.topo.dof_agents)
            try:
                detail = self.apply(f, expand_targets(f.targets, pool))
            except ValueError as e:
                error = str(e)
        if error:  # on the run's record too: a refused fault is something that did not happen, and why
            log.warning("fault refused: %s", error)
            sup.event("refused", ",".join(f.targets) or "-", f"{describe(f)}: {error}", at=at)
        else:
            sup.event("fault", ",".join(f.targets), describe(f) + (f" ({detail})" if detail else ""), at=at)
        try:
            check_id("fault id", f.id)
        except ValueError:
            return  # nowhere to reply
        sup.node.send(sup.keys.rep("fault", f.id), FaultReply(id=f.id, error=error, detail=detail))

    def on_forwarded(self, f: Fault) -> None:
        """Another host's supervisor: the process faults the leader forwards for this host's actors."""
        sup = self.sup
        if f.fault in PROCESS_FAULTS:
            mine = [t for t in expand_targets(f.targets, sup.agents) if sup.where.get(t) == sup.host]
            if mine:
                sup.event("fault", ",".join(mine), describe(f) + f" (from the leader: {self.apply(f, mine)})")

    def apply(self, f: Fault, targets: list[str]) -> str:
        sup = self.sup
        assert sup.node is not None
        if f.fault in JOINT_FAULTS or f.fault in LINK_FAULTS:
            sup.node.send(sup.keys.ctl("fault"), f)  # the sim / the targets' runtimes apply it
            if f.fault == "clear":
                for t in targets:
                    self.link_faults.pop(t, None)
            elif f.fault in LINK_FAULTS:
                expiry = None if f.seconds is None else time.monotonic() + f.seconds
                for t in targets:
                    self.link_faults.setdefault(t, []).append((describe(f), expiry))
            return ""
        done, skipped, forwarded = [], [], []
        remote = [t for t in targets if sup.where[t] != sup.host]
        if remote and sup.lead:  # their hosts' supervisors own those processes
            sup.node.send(sup.keys.ctl("fault"), dataclasses.replace(f, targets=remote))
            forwarded = [f"{t} (to {sup.where[t]})" for t in remote]
        for t in targets:
            if t in remote:
                continue
            actor = ("agent", t)
            if f.fault == "kill":
                ok = sup.placement.signal(actor, signal.SIGKILL)
            elif f.fault == "restart":
                ok = sup.placement.signal(actor, signal.SIGTERM)
                if ok:
                    sup.restarts.request(t)
            elif f.fault == "freeze":
                ok = sup.placement.signal(actor, signal.SIGSTOP)
                if ok:
                    self.frozen[t] = None if f.seconds is None else time.monotonic() + f.seconds
                    if f.seconds is not None:
                        sup.later(f.seconds, THAW, t.encode())
            else:  # thaw
                ok = t in self.frozen and self.thaw(t)
            (done if ok else skipped).append(t)
        detail = f"{f.fault}: {', '.join(done) or 'nobody'}"
        if forwarded:
            detail += f"; forwarded: {', '.join(forwarded)}"
        return detail + (f"; not running: {', '.join(skipped)}" if skipped else "")

    def exited(self, agent: str) -> None:
        """`agent` ended: frozen no more (its restart runs)."""
        self.frozen.pop(agent, None)

    def on_thaw_due(self, agent: str) -> None:
        """A freeze's time is up (unless it was thawed, or frozen again for longer, since)."""
        when = self.frozen.get(agent)
        if when is not None and when <= time.monotonic() + 1e-3:
            self.thaw(agent)

    def thaw(self, agent: str) -> bool:
        self.frozen.pop(agent, None)
        ok = self.sup.placement.signal(("agent", agent), signal.SIGCONT)
        if ok:
            self.sup.event("thaw", agent, "SIGCONT")
        return ok

    def status(self, now: float) -> dict[str, list[str]]:
        """What `kinswarm status` shows per agent: frozen (and for how long still), its live link faults."""
        out: dict[str, list[str]] = {}
        for agent, when in self.frozen.items():
            out.setdefault(agent, []).append(
                "frozen" + ("" if when is None else f" ({max(0.0, when - now):.1f} s left)")
            )
        for agent, fl in self.link_faults.items():
            fl[:] = [(d, exp) for d, exp in fl if exp is None or exp > now]  # expired ones go
            out.setdefault(agent, []).extend(
                d + ("" if exp is None else f" ({max(0.0, exp - now):.0f} s left)") for d, exp in fl
            )
        return out
