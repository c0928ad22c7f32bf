"""The runtime shell every actor runs in: one Zenoh session factory, an asyncio mailbox, publishers
with BLOCK congestion control, readiness (every publisher matched before the liveliness token goes up),
and clean shutdown.

Zenoh callbacks run on a zenoh-owned thread. For most keys they only append `(key, bytes)` to a deque and wake
the event loop once per burst (`call_soon_threadsafe` per message caps a subscriber near 85k msg/s; one wake-up per
burst is an order of magnitude cheaper), and the loop handles them.

Step messages handled where they arrive (`Node.listen(key, inline=handler)`): an actor may give its step keys a
handler that runs on Zenoh's delivery thread itself -- decode (MAC and validation as always), the step's logic, the
next puts -- without waking the loop: the agents' obs, task, down and up, and the sim's commands (the last of which
moves the robot and publishes the next step). Every handler of an actor runs under its Node's `lock`: the loop takes
it for each mailbox item (`Node.next()`), a Zenoh thread only tries it. A step message goes to the mailbox instead,
to be handled by the loop in arrival order, when the lock is busy (the loop is handling something, maybe awaiting a
checkpoint's save, or another Zenoh thread a step), when something already waits there (nothing is overtaken), while
a link fault is active (faults are applied on the loop, as below), and before the actor serves (`serve_inline()`).
Measured on the 4-joint chain in the `process` placement: a step that woke each agent's loop two or three times and
the sim's up to four times (a command each) now wakes none; 359 -> 535 steps/s (benchmarks/floors.py,
docs/architecture.md). The loop keeps control, faults, checkpoints and timers; a handler that raises fails the actor
on its loop (`next()` raises it).

Local delivery (the `single` placement): step messages (keys under `sim/` and `a/`) that a Node sends are handed
straight to the Nodes of the same session that listen on them, instead of a round trip through Zenoh's local routing
(whose delivery threads run the subscriber callback, take the GIL from the event loop and wake it through its
self-pipe: ~2/3 of a single-placement step). They go as messages (`Local`), not bytes: the receiver checks each as it
checks a wire message's body (`codec.local`: the same generated checks of every field and of the envelope), into a
message of its own; what those checks cannot tell goes the wire's way (encoded, signed, decoded), so a message is
refused, or taken, exactly as from another process. Bytes are made only when someone needs them: another session
listening (Zenoh's matching status: step publishers reach other sessions only), a tap (`tap()`, the way to hear step
messages in the sender's own session: a plain Zenoh subscriber there does not), a link fault (faults act on bytes).
A receiver's step handler runs within the send, under its lock, on the same terms as on Zenoh's thread (serving
inline, nothing waiting, no link fault; else the mailbox): a step crosses the actors of one process as calls, down
the tree and, where a handler is busy further up, through the mailbox. Measured on chain4, single
(benchmarks/floors.py): 2183 steps/s with bytes through the mailbox, ~2770 handled within the send, ~3700 as
messages, ~4050 with the matching status kept by a listener rather than asked at every send. A Node's step
subscriptions hear only other sessions through Zenoh (`allowed_origin=REMOTE`), so nothing arrives twice.

Link faults (docs/faults.md, `Node.apply_fault`): drop, delay, duplicate and corrupt act on a node's step
links only — what it sends and receives under `sim/` and `a/` — never on ctl/, rep/, metrics/, fault/ or
liveliness, so a faulted swarm stays controllable. With none active, sending and receiving cost one
attribute check more than without the feature; with some active, received step messages are handed to
the loop one by one and faulted there, so the RNG, counters and timers are only ever touched on the loop.
"""

from .fleet import Lane
from .links import LINK_COUNTS, LinkFault
from .mailbox import LocalBus, Mailbox, Tapped, tap
from .net import HANDSHAKE_MS, LEASE_MS, NetSpec, open_session, zenoh_config
from .node import Local, Node, setup_logging

__all__ = [
    "HANDSHAKE_MS",
    "LEASE_MS",
    "LINK_COUNTS",
    "Lane",
    "LinkFault",
    "Local",
    "LocalBus",
    "Mailbox",
    "NetSpec",
    "Node",
    "Tapped",
    "open_session",
    "setup_logging",
    "tap",
    "zenoh_config",
]
