"""An agent that wakes from a stall of its own (a freeze's SIGSTOP, starvation past the lease) hears its
descendants' tokens go and come back as its session reconnects: that is not a loss to stand in for
(actors/agent/standin.py's WakeGuard). A thawed Panda a4 stood in for its healthy child a5 for a step before."""

from __future__ import annotations

import asyncio
import logging
from types import SimpleNamespace

from kinswarm.actors.agent.standin import WakeGuard


class Clock:
    def __init__(self) -> None:
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def _guard() -> tuple[WakeGuard, Clock, list[tuple[str, bytes]]]:
    clock = Clock()
    pushed: list[tuple[str, bytes]] = []
    node = SimpleNamespace(
        log=logging.getLogger("test"), mailbox=SimpleNamespace(push_local=lambda k, p: pushed.append((k, p)))
    )
    return WakeGuard(node, lease_s=1.0, clock=clock), clock, pushed  # type: ignore[arg-type]


def test_a_loss_heard_awake_counts_at_once():
    async def main() -> None:
        guard, clock, pushed = _guard()
        guard.due = clock.now + 0.25  # the ticker runs on time
        assert guard.token("-a5") == "-a5"
        assert guard.token("+a5") == "+a5"
        assert pushed == []

    asyncio.run(main())


def test_a_loss_heard_on_waking_is_held_and_forgotten_when_the_token_comes_back():
    async def main() -> None:
        guard, clock, pushed = _guard()
        guard.due = clock.now - 2.0  # the ticker is two seconds late: this process did not run
        assert guard.token("-a5") is None and guard.token("-a6") is None
        assert guard.token("+a5") == "+a5"
        await asyncio.sleep(1.05)  # a lease later the held losses are looked at again
        assert [p for _, p in pushed] == [b"?a5", b"?a6"]
        assert guard.token("?a5") is None  # came back: no loss
        assert guard.token("?a6") == "-a6"  # still gone: now it counts

    asyncio.run(main())


def test_the_ticker_marks_a_late_tick_as_a_wake():
    async def main() -> None:
        guard, clock, _ = _guard()
        ticker = asyncio.create_task(guard.watch())
        await asyncio.sleep(0)
        clock.now = guard.due + 0.8  # the tick comes 0.8 s late (more than half the lease)
        await asyncio.sleep(0.3)
        assert guard.woke == clock.now
        assert guard.token("-a5") is None  # within a lease of the wake
        clock.now = guard.woke + 1.5
        guard.due = clock.now + 0.25
        assert guard.token("-a7") == "-a7"  # long awake again
        ticker.cancel()

    asyncio.run(main())
