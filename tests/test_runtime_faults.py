"""Link faults in the runtime (drop, delay, duplicate, corrupt, clear) over real Zenoh sessions on loopback.

Two sessions, one listening and one connecting, as two actor processes would be; node `a2` sends, node
`a1` receives. A fault on `a2` acts on what it sends, a fault on `a1` on what it receives.
"""

from __future__ import annotations

import asyncio
import math
import time

import pytest
import zenoh
from conftest import fault_message
from kinswarm.actors.runtime import Node
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Cmd, EpochStart, Fault

pytestmark = pytest.mark.timeout(60)

KEYS = Keys("faults")
KEY = b"0123456789abcdef0123456789abcdef"
STEP = KEYS.cmd("a2")  # sim/cmd/a2: a step key
CTL = KEYS.ctl("epoch")  # a control key: never faulted


def fault(kind: str, target: str = "a2", **params: float | None) -> Fault:
    return fault_message(kind, target, **params)


async def wire(sessions: tuple[zenoh.Session, zenoh.Session], sender: str = "a2") -> tuple[Node, Node]:
    tx = Node(sessions[0], KEYS, "agent", sender, KEY)
    rx = Node(sessions[1], KEYS, "agent", "a1", KEY)
    rx.listen(KEYS.cmd_all)
    rx.listen(KEYS.ctl_all)
    await tx.wait_matched([STEP, CTL], timeout=10.0)
    return tx, rx


async def collect(node: Node, quiet: float = 0.4) -> list[tuple[str, bytes, float]]:
    """Everything that arrives until nothing has for `quiet` seconds: (key, payload, arrival time)."""
    got = []
    while True:
        try:
            key, payload = await node.recv(timeout=quiet)
        except TimeoutError:
            return got
        got.append((key, payload, time.monotonic()))


def steps_of(rx: Node, got: list[tuple[str, bytes, float]]) -> list[int]:
    out = []
    for key, payload, _ in got:
        if key == STEP and (m := rx.decode(key, payload, Cmd)) is not None:
            out.append(m.step)
    return out


def send_both(tx: Node, n: int) -> None:
    for i in range(n):
        tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
        tx.send(CTL, EpochStart(epoch=i, steps=1, goal=(0.0, 0.0)))


@pytest.mark.parametrize("side", ["sender", "receiver"])
def test_drop_everything_on_step_keys_but_never_on_control_keys(sessions, side):
    async def body() -> None:
        tx, rx = await wire(sessions)
        faulted = tx if side == "sender" else rx
        try:
            desc = faulted.apply_fault(fault("drop", faulted.ident, rate=1.0))
            assert desc == f"drop {faulted.ident} rate=1"
            send_both(tx, 50)
            got = await collect(rx)
            assert steps_of(rx, got) == []
            assert sum(k == CTL for k, _, _ in got) == 50  # the swarm stays controllable
            assert faulted.link_counts == {"dropped": 50, "delayed": 0, "duplicated": 0, "corrupted": 0}
            assert rx.rejected == 0
        finally:
            tx.close()
            rx.close()

    asyncio.run(body())


@pytest.mark.parametrize("side", ["sender", "receiver"])
def test_drop_at_a_rate_loses_about_that_share(sessions, side):
    n, rate = 1000, 0.3

    async def one_run() -> set[int]:
        tx, rx = await wire(sessions)
        faulted = tx if side == "sender" else rx
        try:
            faulted.apply_fault(fault("drop", faulted.ident, rate=rate))
            for i in range(n):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
            arrived = steps_of(rx, await collect(rx))
            assert faulted.link_counts["dropped"] == n - len(arrived)
            return set(arrived)
        finally:
            tx.close()
            rx.close()

    async def body() -> None:
        first = await one_run()
        # binomial: sd = sqrt(n p (1 - p)) ~ 14.5; 5 sd fails about once in 3.5 million runs
        assert abs((n - len(first)) - n * rate) <= 5 * math.sqrt(n * rate * (1 - rate))
        # the node's RNG is seeded from its ident: the same fault on the same node drops the same messages
        assert await one_run() == first

    asyncio.run(body())


@pytest.mark.parametrize("side", ["sender", "receiver"])
def test_delay_delivers_late_without_blocking_the_loop_or_zenoh(sessions, side):
    d = 0.3

    async def body() -> None:
        tx, rx = await wire(sessions)
        faulted = tx if side == "sender" else rx
        ticks = 0

        async def ticker() -> None:
            nonlocal ticks
            while True:
                await asyncio.sleep(0.01)
                ticks += 1

        t = asyncio.create_task(ticker())
        try:
            assert faulted.apply_fault(fault("delay", faulted.ident, ms=d * 1000)) == f"delay {faulted.ident} ms=300"
            t0 = time.monotonic()
            tx.send(STEP, Cmd(epoch=0, step=7, delta=0.0))
            tx.send(CTL, EpochStart(epoch=0, steps=1, goal=(0.0, 0.0)))
            got = await collect(rx, quiet=d + 0.5)
            arrival = {k: at - t0 for k, _, at in got}
            # the control message, sent second, overtook the delayed one: neither the send nor the delivery of the
            # step blocked until its delay was over (no wall-clock bound: a loaded machine is late, not wrong)
            assert [k for k, _, _ in got] == [CTL, STEP]
            assert arrival[STEP] >= d * 0.95  # held for its delay (a delay is at least that long, however loaded)
            assert steps_of(rx, got) == [7]
            assert ticks >= 10  # the loop kept running all along (30 ticks if the machine were idle)
            assert faulted.link_counts["delayed"] == 1
        finally:
            t.cancel()
            tx.close()
            rx.close()

    asyncio.run(body())


@pytest.mark.parametrize("side", ["sender", "receiver"])
def test_duplicate_delivers_twice(sessions, side):
    async def body() -> None:
        tx, rx = await wire(sessions)
        faulted = tx if side == "sender" else rx
        try:
            assert faulted.apply_fault(fault("duplicate", faulted.ident)) == f"duplicate {faulted.ident} rate=1"
            send_both(tx, 20)
            got = await collect(rx)
            assert sorted(steps_of(rx, got)) == sorted(list(range(20)) * 2)
            assert sum(k == CTL for k, _, _ in got) == 20
            assert faulted.link_counts["duplicated"] == 20
        finally:
            tx.close()
            rx.close()

    asyncio.run(body())


@pytest.mark.parametrize("side", ["sender", "receiver"])
def test_corrupt_payloads_are_rejected_by_the_receiver(sessions, side):
    async def body() -> None:
        tx, rx = await wire(sessions)
        faulted = tx if side == "sender" else rx
        try:
            faulted.apply_fault(fault("corrupt", faulted.ident))
            send_both(tx, 30)
            got = await collect(rx)
            step_payloads = [p for k, p, _ in got if k == STEP]
            assert len(step_payloads) == 30
            size = len(codec.encode(Cmd(epoch=0, step=0, delta=0.0), KEYS.run, "a2", KEY))
            assert {len(p) for p in step_payloads} == {size}  # garbage of the same length
            assert steps_of(rx, got) == []  # every corrupted payload failed the MAC ...
            assert rx.rejected == 30  # ... and was counted
            assert faulted.link_counts["corrupted"] == 30
            assert sum(k == CTL for k, _, _ in got) == 30
        finally:
            tx.close()
            rx.close()

    asyncio.run(body())


def test_a_fault_expires_after_its_seconds(sessions):
    async def body() -> None:
        tx, rx = await wire(sessions)
        expired: list[str] = []
        tx.on_fault_expired = expired.append
        try:
            tx.apply_fault(fault("drop", rate=1.0, seconds=0.3))
            assert tx.link_faults == ["drop a2 seconds=0.3 rate=1"]
            tx.send(STEP, Cmd(epoch=0, step=1, delta=0.0))
            await asyncio.sleep(0.5)
            assert tx.link_faults == [] and expired == ["drop a2 seconds=0.3 rate=1"]
            tx.send(STEP, Cmd(epoch=0, step=2, delta=0.0))
            assert steps_of(rx, await collect(rx)) == [2]
        finally:
            tx.close()
            rx.close()

    asyncio.run(body())


def test_clear_removes_every_link_fault_and_their_timers(sessions):
    async def body() -> None:
        tx, rx = await wire(sessions)
        try:
            tx.apply_fault(fault("drop", rate=1.0, seconds=0.3))
            tx.apply_fault(fault("delay", ms=500.0))
            assert tx.apply_fault(fault("clear")) == "clear a2 (delay, drop active)"
            assert tx.link_faults == []
            tx.send(STEP, Cmd(epoch=0, step=1, delta=0.0))
            got = await collect(rx)
            assert steps_of(rx, got) == [1]  # not dropped
            assert tx.link_counts["delayed"] == 0 and tx.link_counts["dropped"] == 0  # neither fault touched it
            # the cleared drop's timer must not remove a fault applied after the clear
            tx.apply_fault(fault("drop", rate=1.0))
            await asyncio.sleep(0.4)
            assert tx.link_faults == ["drop a2 rate=1"]
            assert tx.apply_fault(fault("clear")) == "clear a2 (drop active)"
            assert tx.apply_fault(fault("clear")) == "clear a2 (no link fault active)"
        finally:
            tx.close()
            rx.close()

    asyncio.run(body())


def test_a_newer_fault_of_a_kind_replaces_the_older(sessions):
    async def body() -> None:
        tx, rx = await wire(sessions)
        try:
            tx.apply_fault(fault("drop", rate=1.0, seconds=0.2))
            tx.apply_fault(fault("drop", rate=1.0))  # until cleared: the first one's expiry must not end it
            await asyncio.sleep(0.35)
            assert tx.link_faults == ["drop a2 rate=1"]
        finally:
            tx.close()
            rx.close()

    asyncio.run(body())


def test_targeting(sessions):
    async def body() -> None:
        agent = Node(sessions[0], KEYS, "agent", "a2", KEY)
        sim = Node(sessions[0], KEYS, "sim", "sim", KEY)
        sup = Node(sessions[0], KEYS, "supervisor", "main", KEY)
        try:
            assert agent.apply_fault(fault("drop", "a3", rate=0.5)) == ""  # someone else's
            assert agent.apply_fault(fault("lock", "a2")) == ""  # a joint fault: the sim's business
            assert agent.apply_fault(fault("kill", "a2")) == ""  # a process fault: the supervisor's
            assert agent.apply_fault(fault("drop", "a2", rate=2.0)) == ""  # invalid: ignored, logged
            assert agent.link_faults == []
            # `all` means every agent, not the sim or the supervisor
            assert agent.apply_fault(fault("delay", "all", ms=5.0)) == "delay a2 ms=5"
            assert sim.apply_fault(fault("delay", "all", ms=5.0)) == ""
            assert sup.apply_fault(fault("delay", "all", ms=5.0)) == ""
            assert agent.apply_fault(fault("corrupt", "a2", rate=0.25, seconds=3.0)) == "corrupt a2 seconds=3 rate=0.25"
            assert sorted(agent.link_faults) == ["corrupt a2 seconds=3 rate=0.25", "delay a2 ms=5"]
        finally:
            for n in (agent, sim, sup):
                n.close()

    asyncio.run(body())


def test_a_flood_on_one_key_does_not_hide_a_bad_message_on_another(sessions, caplog):
    """The rejection log samples a flood (the first 20, then every 1000th) but always shows each key's first."""

    async def body() -> None:
        rx = Node(sessions[1], KEYS, "agent", "a1", KEY)
        try:
            with caplog.at_level("WARNING", logger="kinswarm.agent.a1"):
                for _ in range(50):
                    assert rx.decode(STEP, b"\x00\xff garbage", Cmd) is None
                assert rx.decode(CTL, b"\x00\xff garbage", EpochStart) is None
            assert rx.rejected == 51
            logged = [r.getMessage() for r in caplog.records]
            assert sum(f"on {STEP} " in m for m in logged) == 20  # the flood, sampled
            assert sum(f"on {CTL} " in m for m in logged) == 1  # past the sample, still shown
        finally:
            rx.close()

    asyncio.run(body())
