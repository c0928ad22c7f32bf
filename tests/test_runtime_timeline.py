"""The per-message timeline benchmarks/step_timeline.py reads (actors/runtime/timeline.py): with a directory given,
the sender records each step message's put, the receiver its arrival and its handling, in order and on one clock,
and each Node writes them on close; without one, a Node keeps no record and writes nothing."""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest
from kinswarm.actors.runtime import timeline
from kinswarm.protocol.messages import Cmd, Stop
from test_runtime_inline import STEP, STOP, served, until, wire

pytestmark = pytest.mark.timeout(60)


def rows(path: Path) -> list[list[str]]:
    return [line.split("\t") for line in path.read_text().splitlines()]


def test_a_step_message_is_recorded_put_then_arrived_then_handled(sessions, tmp_path, monkeypatch):
    monkeypatch.setattr(timeline, "DIR", str(tmp_path))

    async def body() -> None:
        tx, rx = await wire(sessions)
        async with served(tx, rx) as serving:
            for i in range(50):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
            await until(lambda: len(rx.handled) == 50)
            tx.send(STOP, Stop(reason="test"))
            await asyncio.wait_for(serving, 10.0)

    asyncio.run(body())
    sent = rows(next(tmp_path.glob("agent-a2-*.tsv")))
    got = rows(next(tmp_path.glob("agent-a1-*.tsv")))
    puts = [int(r[2]) for r in sent if r[0] == "put"]
    arrived = [int(r[2]) for r in got if r[0] == "arrive" and r[1] == STEP]
    handled = [r for r in got if r[0] == "handled" and r[1] == STEP]
    assert len(puts) == len(arrived) == len(handled) == 50  # the stop is a control message: not recorded
    for put, arrival, (_, _, start, end, cpu, where) in zip(puts, arrived, handled, strict=True):
        assert put <= arrival <= int(start) <= int(end)
        assert int(cpu) >= 0 and where in ("inline", "loop")
    cpu = [r for r in got if r[0] == "cpu"]
    assert len(cpu) == 1 and int(cpu[0][3]) >= int(cpu[0][2])


def test_without_a_directory_nothing_is_kept_or_written(sessions, tmp_path, monkeypatch):
    monkeypatch.setattr(timeline, "DIR", None)

    async def body() -> None:
        tx, rx = await wire(sessions)
        assert tx._tl is None and rx.node._tl is None
        async with served(tx, rx) as serving:
            tx.send(STEP, Cmd(epoch=0, step=0, delta=0.0))
            await until(lambda: len(rx.handled) == 1)
            tx.send(STOP, Stop(reason="test"))
            await asyncio.wait_for(serving, 10.0)

    asyncio.run(body())
    assert list(tmp_path.iterdir()) == []
