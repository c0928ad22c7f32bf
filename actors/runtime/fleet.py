"""A fleet (run.fleet = B > 1) on the wire: its step messages travel as Batches (protocol/messages.py), one per key
whatever its B. While an actor handles one batch, what its lanes send is gathered (Node.gathering, Node.send_as) and
leaves as one Batch per key; a `Lane` is one robot of the fleet as the actor's one-robot code sees its Node."""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Callable, Iterator
from typing import TYPE_CHECKING, Any, TypeVar

from kinswarm.protocol import codec
from kinswarm.protocol.messages import Batch

if TYPE_CHECKING:
    from .node import Local, Node

M = TypeVar("M")


class Gathering:
    """Node's batches (a mixin: `fleet` and `_gathered` are made in Node.__init__)."""

    fleet: int
    _gathered: dict[str, list[tuple[list[int], list[Any]]]] | None
    _later: list[Callable[[], None]]
    _step_prefixes: tuple[str, ...]

    if TYPE_CHECKING:  # Node's

        def send(self, key: str, msg: Any) -> None: ...
        def decode(self, key: str, payload: Any, expect: type[M]) -> M | None: ...
        def _rejected(self, key: str, sender: str, reason: str) -> None: ...

    @contextlib.contextmanager
    def gathering(self) -> Iterator[None]:
        """While inside, the step messages this actor's lanes send (`send_as`) are gathered; on leaving, each key's
        go out as one Batch (a second when a robot sent twice on one key: a robot's k-th message is in the k-th),
        keys in the order of their first message, and then what the lanes left for later (`after_sending`) runs, in
        the order they left it, gathered again. Nothing is sent when the body raises: the actor is failing. Within a
        gathering (one handler's, under the node's lock) another one adds to it: the outer one sends."""
        if self._gathered is not None:
            yield
            return
        self._gathered, self._later = {}, []
        try:
            yield
            gathered, later = self._gathered, self._later
        finally:
            self._gathered, self._later = None, []
        for key, groups in gathered.items():
            for robots, items in groups:
                self.send(key, Batch(of=items[0].KIND, robots=robots, items=items))
        if later:
            with self.gathering():
                for fn in later:
                    fn()

    def after_sending(self, fn: Callable[[], None]) -> None:
        """Run `fn` once what the lanes have sent so far has left (now, outside gathering()): an agent's `up` leaves
        before any robot's learner runs, as one robot's does (actors/agent/actor.py), so a fleet's learning is off
        the step's critical path too. Lanes leave theirs in robot order and they run in it: a fleet's learner sees
        its calls in the order it would have without this."""
        if self._gathered is None:
            fn()
        else:
            self._later.append(fn)

    def send_as(self, robot: int, key: str, msg: Any) -> None:
        """Robot `robot`'s message: a step message into the batch being gathered (alone in a Batch of its own outside
        gathering()), anything else sent as it is."""
        gathered = self._gathered
        if not key.startswith(self._step_prefixes):
            self.send(key, msg)
        elif gathered is None:
            self.send(key, Batch(of=msg.KIND, robots=[robot], items=[msg]))
        else:
            groups = gathered.get(key)
            if groups is None:
                gathered[key] = [([robot], [msg])]
                return
            for robots, items in groups:
                if robots[-1] < robot:
                    robots.append(robot)
                    items.append(msg)
                    return
            groups.append(([robot], [msg]))

    def decode_batch(self, key: str, payload: bytes | Local, of: type[M]) -> Batch | None:
        """A Batch of `of` messages for robots of this fleet, or None (the reason logged, as decode() logs it)."""
        m = self.decode(key, payload, Batch)
        if m is None:
            return None
        if m.of != of.KIND:  # type: ignore[attr-defined]
            reason = f"batch of {m.of!r}, expected {of.KIND!r}"  # type: ignore[attr-defined]
        elif m.robots[-1] >= self.fleet:
            reason = f"batch for robot {m.robots[-1]}: this fleet has {self.fleet}"
        else:
            return m
        self._rejected(key, codec.sender(payload) if isinstance(payload, bytes) else payload.src, reason)
        return None


class Lane:
    """One robot of a fleet as an actor's per-robot code sees its Node: the step messages it sends are robot
    `robot`'s (Node.send_as: into the batch being gathered). Only the owning lane (robot 0's, the actor's own) speaks
    for the actor otherwise: it subscribes, and sends what is not a step message (events, replies); the other lanes'
    are their duplicates (every robot loses the same neighbour at the same step), not sent, and their log says only
    errors (the owner's says the rest once)."""

    __slots__ = ("node", "robot", "owner", "log")

    def __init__(self, node: Node, robot: int) -> None:
        self.node, self.robot, self.owner = node, robot, robot == 0
        self.log = node.log
        if not self.owner:
            self.log = logging.getLogger(f"{node.log.name}.fleet")
            self.log.setLevel(logging.ERROR)

    def send(self, key: str, msg: Any) -> None:
        if self.owner or key.startswith(self.node._step_prefixes):
            self.node.send_as(self.robot, key, msg)

    def listen(self, key_expr: str, inline: Callable[[str, bytes], None] | None = None) -> None:
        if self.owner:
            self.node.listen(key_expr, inline)

    def __getattr__(self, name: str) -> Any:
        return getattr(self.node, name)
