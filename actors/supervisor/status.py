"""What `kinswarm status` shows, as the supervisor publishes it twice a second (metrics/status): every actor's role,
liveliness, pid, host and restarts, and what is wrong with it now: its faults, why it is down and since when, the
sim's joint faults and a stalled step. Built from what the supervisor's parts hold; it changes none of it."""

from __future__ import annotations

from collections.abc import Callable, Collection, Mapping, Sequence

from kinswarm.protocol.messages import JointStatus, SwarmStatus

from .placements import ActorId


def swarm_status(
    *,
    epoch: int,
    epochs: int,
    expected: Sequence[ActorId],
    alive: Collection[ActorId],
    pids: Mapping[str, int],
    host: Callable[[ActorId], str],
    restarts: Callable[[str], int],
    faults_now: Mapping[str, list[str]],
    why_down: Mapping[str, tuple[float, str]],
    joints: JointStatus | None,
    stalled: str | None,
    now: float,
) -> SwarmStatus:
    """`faults_now`: the fault router's live faults by actor; `why_down`: actor -> (since when, why) for those whose
    token went or whose process exited; `stalled`: the stall watch's line on the sim, if its step is stalled."""
    ids = [ident for _, ident in expected]
    roles = {ident: role for role, ident in expected}
    faults: dict[str, list[str]] = {i: [] for i in ids}
    for agent, what in faults_now.items():
        faults.setdefault(agent, []).extend(what)
    for ident, (since, why) in why_down.items():
        if ident in faults and (roles[ident], ident) not in alive:
            faults[ident].append(f"down {now - since:.1f} s: {why}")
    if joints is not None:
        for joint, what in joints.faults.items():
            faults.setdefault(joint, []).append(what)
    if stalled:
        faults.setdefault("sim", []).append(stalled)
    return SwarmStatus(
        epoch=epoch,
        epochs=epochs,
        role=roles,
        alive={i: int((roles[i], i) in alive) for i in ids},
        pid={i: pids.get(i, 0) for i in ids},
        host={i: host((roles[i], i)) for i in ids},
        restarts={i: restarts(i) for i in ids},
        faults=faults,
    )
