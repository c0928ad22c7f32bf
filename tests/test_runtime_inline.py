"""Step handlers on Zenoh's delivery thread (Node.listen's `inline`, the `process` placement's hot path): each step
message is handled once, in order, never beside the loop's own handlers; a bad MAC is still rejected there; link
faults still act (a faulted node's step messages go through the loop as before); a handler that raises fails the
actor on its loop; once inline handling is off no handler runs. And the simulator's deadline watchdog, which
replaced one timer per step: a step still ends at its deadline, and only then."""

from __future__ import annotations

import asyncio
import contextlib
import threading
import time
from collections.abc import AsyncIterator
from typing import Any

import pytest
import zenoh
from conftest import RecordingNode, fault_message, run_config
from kinswarm.actors.runtime import Node
from kinswarm.actors.simulator.actor import DEADLINE, SimActor
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Cmd, EpochStart, Stop

pytestmark = pytest.mark.timeout(60)

KEYS = Keys("inline")
KEY = b"0123456789abcdef0123456789abcdef"
STEP = KEYS.cmd("a2")  # sim/cmd/a2: a step key
STOP = KEYS.ctl("stop")  # a control key: always the loop's


fault = fault_message


class Receiver:
    """An actor with one step handler (decoding Cmd, as the sim does) and a loop that serves the rest."""

    def __init__(self, session: zenoh.Session) -> None:
        self.node = Node(session, KEYS, "agent", "a1", KEY)
        self.handled: list[tuple[int, str, int]] = []  # (step, "inline" or "loop", thread id)
        self.busy = threading.Lock()  # held while a handler runs: a second one at once would fail to take it
        self.overlaps = 0
        self.loop_thread = threading.get_ident()
        self.fail_at: int | None = None
        self.node.listen(KEYS.cmd_all, inline=self.on_step)
        self.node.listen(KEYS.ctl_all)

    def on_step(self, key: str, payload: bytes) -> None:
        if not self.busy.acquire(blocking=False):
            self.overlaps += 1
            return
        try:
            m = self.node.decode(key, payload, Cmd)
            if m is None:
                return
            if m.step == self.fail_at:
                raise KeyError(f"step {m.step}")
            on_loop = threading.get_ident() == self.loop_thread
            self.handled.append((m.step, "loop" if on_loop else "inline", threading.get_ident()))
        finally:
            self.busy.release()

    async def serve(self, hold: float = 0.0) -> None:
        """The loop: step messages that had to wait go to the same handler; `ctl/stop` ends it. A stop holds the
        lock `hold` seconds first (as a checkpoint's save does), and step messages arriving meanwhile must wait."""
        node = self.node
        node.serve_inline()
        while True:
            async with node.next() as (key, payload):
                if key.startswith(KEYS.cmd_all[:-1]):
                    self.on_step(key, payload)
                elif key == STOP and node.decode(key, payload, Stop) is not None:
                    if hold:
                        await asyncio.sleep(hold)
                        hold = 0.0
                        continue
                    return


async def wire(sessions: tuple[zenoh.Session, zenoh.Session]) -> tuple[Node, Receiver]:
    tx = Node(sessions[0], KEYS, "agent", "a2", KEY)
    rx = Receiver(sessions[1])
    await tx.wait_matched([STEP, STOP], timeout=10.0)
    return tx, rx


@contextlib.asynccontextmanager
async def served(tx: Node, rx: Receiver, hold: float = 0.0) -> AsyncIterator[asyncio.Task[None]]:
    """The frame of the tests below: rx's loop serving (given a moment to start), then both nodes closed."""
    serving = asyncio.create_task(rx.serve(hold))
    try:
        await asyncio.sleep(0.05)
        yield serving
    finally:
        serving.cancel()
        tx.close()
        rx.node.close()


async def until(pred: Any, timeout: float = 10.0) -> None:
    deadline = time.monotonic() + timeout
    while not pred():
        assert time.monotonic() < deadline, "timed out"
        await asyncio.sleep(0.01)


def test_step_messages_are_handled_on_zenohs_thread_once_each_in_order(sessions):
    async def body() -> None:
        tx, rx = await wire(sessions)
        async with served(tx, rx) as serving:
            for i in range(200):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
                if i % 20 == 0:
                    await asyncio.sleep(0.005)
            await until(lambda: len(rx.handled) == 200)
            tx.send(STOP, Stop(reason="test"))
            await asyncio.wait_for(serving, 10.0)
            assert [s for s, _, _ in rx.handled] == list(range(200))  # once each, in order
            assert rx.overlaps == 0
            inline = [t for _, where, t in rx.handled if where == "inline"]
            assert len(inline) >= 190, "the step messages did not wake the loop"  # a few may race the loop's lock
            assert rx.loop_thread not in inline
            assert rx.node.inline_handled == len(inline)

    asyncio.run(body())


def test_a_bad_mac_is_rejected_on_zenohs_thread(sessions):
    async def body() -> None:
        tx, rx = await wire(sessions)
        async with served(tx, rx):
            good = codec.encode(Cmd(epoch=0, step=1, delta=0.0), KEYS.run, "a2", KEY)
            forged = codec.encode(Cmd(epoch=0, step=2, delta=0.0), KEYS.run, "a2", b"an impostor's key")
            flipped = bytearray(good)
            flipped[5] ^= 0x40
            for p in (forged, bytes(flipped), good[:-1] + bytes([good[-1] ^ 1]), good):
                tx.publisher(STEP).put(p)
            await until(lambda: len(rx.handled) == 1)
            await asyncio.sleep(0.2)
            assert [s for s, _, _ in rx.handled] == [1]
            assert rx.node.rejected == 3
            assert rx.node.inline_handled == 4  # all four were handled there, three refused

    asyncio.run(body())


@pytest.mark.parametrize("kind", ["drop", "delay", "duplicate", "corrupt"])
def test_link_faults_act_on_a_node_with_inline_handlers(sessions, kind):
    params = {"drop": {"rate": 1.0}, "delay": {"ms": 150.0}, "duplicate": {"rate": 1.0}, "corrupt": {"rate": 1.0}}

    async def body() -> None:
        tx, rx = await wire(sessions)
        async with served(tx, rx):
            assert rx.node.apply_fault(fault(kind, "a1", **params[kind]))
            t0 = time.monotonic()
            for i in range(10):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
            await asyncio.sleep(0.6)
            steps = [s for s, _, _ in rx.handled]
            assert all(where == "loop" for _, where, _ in rx.handled), "a faulted node's step messages go to the loop"
            assert rx.node.inline_handled == 0
            if kind == "drop":
                assert steps == [] and rx.node.link_counts["dropped"] == 10
            elif kind == "delay":
                assert steps == list(range(10)) and rx.node.link_counts["delayed"] == 10
                assert time.monotonic() - t0 >= 0.15
            elif kind == "duplicate":
                assert sorted(steps) == sorted(list(range(10)) * 2)
            else:
                assert steps == [] and rx.node.rejected == 10
            # cleared: handled on Zenoh's thread again
            rx.node.apply_fault(fault("clear", "a1"))
            tx.send(STEP, Cmd(epoch=0, step=99, delta=0.0))
            await until(lambda: any(s == 99 for s, _, _ in rx.handled))
            assert rx.handled[-1][1] == "inline" and rx.node.inline_handled == 1

    asyncio.run(body())


def test_while_the_loop_holds_the_lock_step_messages_wait_and_keep_their_order(sessions):
    async def body() -> None:
        tx, rx = await wire(sessions)
        async with served(tx, rx, hold=0.5) as serving:
            tx.send(STOP, Stop(reason="test"))  # the loop takes it and holds the lock for 0.5 s
            await asyncio.sleep(0.1)
            for i in range(20):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
            await asyncio.sleep(0.2)
            assert rx.handled == [], "a step handler ran while the loop held the lock"
            await until(lambda: len(rx.handled) == 20)
            assert [s for s, _, _ in rx.handled] == list(range(20))
            assert all(where == "loop" for _, where, _ in rx.handled)  # they had waited in the mailbox
            tx.send(STEP, Cmd(epoch=0, step=20, delta=0.0))  # the mailbox is empty again: back on Zenoh's thread
            await until(lambda: len(rx.handled) == 21)
            assert rx.handled[-1][1] == "inline"
            assert rx.overlaps == 0
            tx.send(STOP, Stop(reason="test"))
            await asyncio.wait_for(serving, 10.0)

    asyncio.run(body())


def test_in_one_session_a_step_message_is_handled_within_the_send_unless_it_must_wait(sessions):
    """The `single` placement: a Node of the same session hands a step message straight to the receiver's handler,
    which has run when send() returns (no round trip through the loop); while the receiver's loop holds its lock
    they wait in the mailbox, in order, and once it is empty again the next is handled within the send."""

    async def body() -> None:
        tx = Node(sessions[0], KEYS, "agent", "a2", KEY)
        rx = Receiver(sessions[0])  # the same session: local delivery
        await tx.wait_matched([STEP, STOP], timeout=10.0)
        async with served(tx, rx, hold=0.5) as serving:
            for i in range(50):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
                assert [s for s, _, _ in rx.handled] == list(range(i + 1)), "not handled within the send"
            assert rx.node.inline_handled == 50
            tx.send(STOP, Stop(reason="test"))  # the loop takes it and holds the lock for 0.5 s
            await until(lambda: rx.node._loop_holds)
            for i in range(50, 60):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
            assert len(rx.handled) == 50, "a step handler ran while the loop held the lock"
            await until(lambda: len(rx.handled) == 60)
            assert [s for s, _, _ in rx.handled] == list(range(60))
            tx.send(STEP, Cmd(epoch=0, step=60, delta=0.0))
            assert [s for s, _, _ in rx.handled] == list(range(61))
            assert rx.node.inline_handled == 51 and rx.overlaps == 0
            tx.send(STOP, Stop(reason="test"))
            await asyncio.wait_for(serving, 10.0)

    asyncio.run(body())


def test_a_failing_inline_handler_fails_the_actor_on_its_loop_and_nothing_runs_after(sessions):
    async def body() -> None:
        tx, rx = await wire(sessions)
        rx.fail_at = 3
        async with served(tx, rx) as serving:
            for i in range(6):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
            with pytest.raises(KeyError, match="step 3"):
                await asyncio.wait_for(serving, 10.0)
            assert not rx.node.inline
            seen = len(rx.handled)
            tx.send(STEP, Cmd(epoch=0, step=7, delta=0.0))
            await asyncio.sleep(0.3)
            assert len(rx.handled) == seen and all(s < 3 for s, _, _ in rx.handled)

    asyncio.run(body())


def test_no_inline_handler_runs_once_serving_is_off(sessions):
    async def body() -> None:
        tx, rx = await wire(sessions)
        async with served(tx, rx) as serving:
            tx.send(STEP, Cmd(epoch=0, step=0, delta=0.0))
            await until(lambda: len(rx.handled) == 1)
            rx.node.serve_inline(False)
            for i in range(1, 6):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
            await until(lambda: len(rx.handled) == 6)
            assert [where for _, where, _ in rx.handled] == ["inline"] + ["loop"] * 5
            serving.cancel()
            await asyncio.sleep(0.05)
            rx.node.close()
            tx.send(STEP, Cmd(epoch=0, step=9, delta=0.0))
            await asyncio.sleep(0.3)
            assert len(rx.handled) == 6

    asyncio.run(body())


# -- the simulator's deadline watchdog ---------------------------------------------------------------


def test_the_watchdog_ends_a_step_at_its_deadline_and_only_then(tmp_path, chain4):
    deadline_ms = 200

    async def body() -> None:
        cfg = run_config(chain4, out=str(tmp_path), deadline_ms=deadline_ms)
        sim = SimActor(cfg, cfg.topo(), RecordingNode())  # type: ignore[arg-type]
        try:
            sim._on_epoch(EpochStart(epoch=0, steps=6, goal=(4.16, 6.18)))
            started, ends = time.perf_counter(), []

            async def serve_until(t: int) -> None:
                while sim.t < t and sim.epoch is not None:
                    await sim.node.mailbox.wait()
                    key, payload = sim.node.mailbox.pop()
                    assert key == DEADLINE
                    sim.handle(key, payload)
                    ends.append(time.perf_counter())

            await serve_until(2)  # nobody answers: each step ends at its deadline
            assert sim.t == 2 and sim.missed == 8
            first, second = ends[0] - started, ends[1] - ends[0]
            assert first >= 0.19 and second >= 0.19, (first, second)  # not before its deadline
            assert len(ends) == 2  # and at it: each step ended by the first firing due for it, none went by idle
            # the next two steps end by their commands, at once; the watchdog fires but ends none
            await asyncio.sleep(deadline_ms / 1000 / 2)
            for _ in range(2):
                t = sim.t
                for a in sim.dof:
                    sim._on_cmd(a, Cmd(epoch=0, step=t, delta=0.0))
                assert sim.t == t + 1
            step4 = time.perf_counter()
            await serve_until(5)  # step 4 waits its own full deadline, not what was left of step 2's
            assert sim.t == 5 and sim.missed == 12
            assert ends[-1] - step4 >= 0.19, ends[-1] - step4
            await serve_until(6)
            assert sim.epoch is None  # the epoch is over: the watchdog stops
            await asyncio.sleep(deadline_ms / 1000 * 1.5)
            while len(sim.node.mailbox):
                sim.handle(*sim.node.mailbox.pop())
            assert sim._deadline is None
        finally:
            sim.world.close()

    asyncio.run(body())
