"""Local delivery: step messages between Nodes of one session skip Zenoh's local routing (runtime.py),
yet arrive exactly once, still reach other sessions and taps, and still get faulted."""

from __future__ import annotations

import asyncio
import math
import time

import pytest
from conftest import fault_message
from kinswarm.actors.runtime import Local, Node, open_session, tap
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Cmd, EpochStart

KEYS = Keys("lt")
KEY = b"k" * 32
STEP = KEYS.cmd("a2")
CTL = KEYS.ctl("epoch")


async def drain(node: Node, quiet: float = 0.3) -> list[tuple[str, bytes]]:
    got = []
    while True:
        try:
            got.append(await node.recv(timeout=quiet))
        except TimeoutError:
            return got


def steps(node: Node, got: list[tuple[str, bytes]]) -> list[int]:
    return [m.step for k, p in got if k == STEP and (m := node.decode(k, p, Cmd)) is not None]


@pytest.mark.timeout(60)
def test_local_nodes_hear_each_other_once_and_others_still_hear_them(endpoint):
    async def body() -> None:
        a, b = open_session(listen=[endpoint]), open_session(connect=[endpoint])
        raw: list[str] = []
        try:
            tx = Node(a, KEYS, "agent", "a2", KEY)
            rx = Node(a, KEYS, "sim", "sim", KEY)  # same session: local delivery
            far = Node(b, KEYS, "agent", "a1", KEY)  # another session: through Zenoh
            for n in (rx, far):
                n.listen(KEYS.cmd_all)
                n.listen(KEYS.ctl_all)
            tapped = tap(a, KEYS.cmd_all, lambda key, payload: raw.append(key))  # not a Node: a tap
            plain: list[str] = []  # a plain Zenoh subscriber of the same session: their step messages skip Zenoh here
            sub = a.declare_subscriber(KEYS.cmd_all, lambda s: plain.append(str(s.key_expr)))
            await tx.wait_matched([STEP, CTL], timeout=10.0)
            await asyncio.sleep(0.3)  # the remote subscriptions reach tx's session
            for i in range(50):
                tx.send(STEP, Cmd(epoch=0, step=i, delta=0.0))
                tx.send(CTL, EpochStart(epoch=i, steps=1, goal=(0.0, 0.0)))
            local, remote = await drain(rx), await drain(far)
            assert steps(rx, local) == list(range(50))  # once each, in order
            assert all(type(p) is Local for k, p in local if k == STEP)  # handed over as messages, checked on decode
            assert steps(far, remote) == list(range(50))
            assert sum(k == CTL for k, _ in local) == 50 and sum(k == CTL for k, _ in remote) == 50
            assert len(raw) == 50 and plain == []
            # a remote sender still reaches the local Node (its step subscription hears other sessions)
            far.send(STEP, Cmd(epoch=1, step=7, delta=0.0))
            assert steps(rx, await drain(rx)) == [7]
            assert steps(far, await drain(far)) == [7]  # as with Zenoh, a Node hears what it says on its keys
            # a closed Node hears nothing more; the others still do
            rx.close()
            tx.send(STEP, Cmd(epoch=1, step=8, delta=0.0))
            assert steps(far, await drain(far)) == [8]
            assert await drain(rx, quiet=0.1) == []
            sub.undeclare()
            tapped.undeclare()
        finally:
            b.close()
            a.close()

    asyncio.run(body())


@pytest.mark.timeout(60)
@pytest.mark.parametrize("side", ["sender", "receiver"])
def test_local_delivery_is_faulted(endpoint, side):
    async def body() -> None:
        a = open_session(listen=[endpoint])
        try:
            tx = Node(a, KEYS, "agent", "a2", KEY)
            rx = Node(a, KEYS, "agent", "a1", KEY)
            rx.listen(KEYS.cmd_all)
            await tx.wait_matched([STEP], timeout=10.0)
            faulted = tx if side == "sender" else rx
            assert faulted.apply_fault(fault_message("delay", faulted.ident, ms=200.0))
            assert faulted.apply_fault(fault_message("duplicate", faulted.ident, rate=1.0))
            t0 = time.monotonic()
            tx.send(STEP, Cmd(epoch=0, step=3, delta=0.0))
            first = await rx.recv(timeout=5)
            assert time.monotonic() - t0 >= 0.18
            assert steps(rx, [first, *await drain(rx)]) == [3, 3]
            assert faulted.link_counts["duplicated"] == 1
        finally:
            a.close()

    asyncio.run(body())


@pytest.mark.timeout(60)
def test_a_cancel_landing_while_a_message_is_in_hand_is_not_lost(endpoint):
    """Ctrl-C cancels the supervisor's task. On Python 3.11 asyncio.wait_for swallowed a cancel that came
    after the message arrived but before the waiter resumed, and the run trained on (a CI failure of
    test_ctrl_c_stops_everything). This lands the cancel exactly there, twenty times."""

    async def body() -> None:
        s = open_session(listen=[endpoint])
        node = Node(s, KEYS, "supervisor", "main", KEY)
        try:
            for _ in range(20):

                async def serve() -> None:
                    while True:
                        await node.recv(timeout=5.0)

                task = asyncio.create_task(serve())
                await asyncio.sleep(0)  # serve() waits on the mailbox
                node.mailbox.push(STEP, b"x")  # the message arrives...
                await asyncio.sleep(0)  # ...the mailbox hands it over...
                task.cancel()  # ...and the cancel lands before serve() resumes
                done, _ = await asyncio.wait([task], timeout=1.0)
                assert task in done and task.cancelled()
        finally:
            node.close()
            s.close()

    asyncio.run(body())


@pytest.mark.timeout(60)
def test_in_one_session_a_bad_message_is_refused_as_from_another(endpoint, caplog):
    """A message the wire would refuse (not finite, signed with another key) is refused in-process too,
    counted and logged with the same reason: a bug in a sender shows the same in every placement."""

    async def body() -> None:
        a = open_session(listen=[endpoint])
        try:
            tx = Node(a, KEYS, "agent", "a2", KEY)
            other_key = Node(a, KEYS, "agent", "a4", b"x" * 32)
            rx = Node(a, KEYS, "sim", "sim", KEY)
            rx.listen(KEYS.cmd_all)
            await tx.wait_matched([STEP], timeout=10.0)
            tx.send(STEP, Cmd(epoch=0, step=1, delta=math.nan))
            other_key.send(STEP, Cmd(epoch=0, step=3, delta=0.0))
            tx.send(STEP, Cmd(epoch=0, step=4, delta=0.0))
            got = await drain(rx)
            assert steps(rx, got) == [4]
            assert rx.rejected == 2
            reasons = " ".join(r.getMessage() for r in caplog.records if "rejected" in r.getMessage())
            assert "finite" in reasons and codec.BAD_MAC in reasons
        finally:
            a.close()

    asyncio.run(body())


@pytest.mark.timeout(60)
def test_a_session_that_listens_later_hears_the_next_step_messages(endpoint):
    """Step messages between Nodes of one session are put on Zenoh only while another session listens (the
    publisher's matching status, kept by a listener): one that starts listening mid-run hears what follows."""

    async def body() -> None:
        a, b = open_session(listen=[endpoint]), open_session(connect=[endpoint])
        try:
            tx, rx = Node(a, KEYS, "agent", "a2", KEY), Node(a, KEYS, "sim", "sim", KEY)
            rx.listen(KEYS.cmd_all)
            await tx.wait_matched([STEP], timeout=10.0)
            tx.send(STEP, Cmd(epoch=0, step=0, delta=0.0))
            assert not tx._heard_away[STEP]  # nobody away: no bytes, no put
            far = Node(b, KEYS, "agent", "a1", KEY)
            far.listen(KEYS.cmd_all)
            deadline = time.monotonic() + 10
            while not tx._heard_away[STEP]:
                assert time.monotonic() < deadline, "the other session's subscription never matched"
                await asyncio.sleep(0.01)
            tx.send(STEP, Cmd(epoch=0, step=1, delta=0.0))
            assert steps(far, await drain(far)) == [1]
            assert steps(rx, await drain(rx)) == [0, 1]
            far.close()
            deadline = time.monotonic() + 10
            while tx._heard_away[STEP]:  # and it goes away again
                assert time.monotonic() < deadline, "the other session's subscription never unmatched"
                await asyncio.sleep(0.01)
        finally:
            b.close()
            a.close()

    asyncio.run(body())


@pytest.mark.timeout(60)
@pytest.mark.parametrize("side", ["sender", "receiver"])
def test_in_one_session_a_corrupted_message_is_refused_by_its_mac(endpoint, side):
    """A corrupt link fault acts on bytes, so a message handed over in-process is encoded first and then garbled:
    the receiver's MAC check refuses it, as across processes."""

    async def body() -> None:
        a = open_session(listen=[endpoint])
        try:
            tx, rx = Node(a, KEYS, "agent", "a2", KEY), Node(a, KEYS, "agent", "a1", KEY)
            rx.listen(KEYS.cmd_all)
            await tx.wait_matched([STEP], timeout=10.0)
            faulted = tx if side == "sender" else rx
            assert faulted.apply_fault(fault_message("corrupt", faulted.ident, rate=1.0))
            tx.send(STEP, Cmd(epoch=0, step=5, delta=0.0))
            assert steps(rx, await drain(rx)) == []
            assert rx.rejected == 1 and faulted.link_counts["corrupted"] == 1
        finally:
            a.close()

    asyncio.run(body())
