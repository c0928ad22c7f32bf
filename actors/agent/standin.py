"""Re-wiring (docs/faults.md): an agent standing in for lost descendants.

When a descendant's liveliness token goes away (killed, frozen, cut off), the nearest live ancestor adopts its
children: it reads the lost joint's encoder, composes the frames the lost agent would have sent, sends them down and
collects the ups addressed to it. The lost joint holds (the sim stops waiting for it; to the adopter's learner its
action is "keep"). Control is handed back at the first step after the token returns. A lost root has no ancestor:
its children wait for it (each step then ends at the sim's deadline) until the supervisor has restarted it.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import TYPE_CHECKING, Any

from kinswarm.actors.runtime.wake import ALIVE, WakeGuard  # noqa: F401  (the agent's, kept importable from here)
from kinswarm.protocol.keys import GONE, UP, parse_token_change, token_change
from kinswarm.protocol.messages import Event, Up

if TYPE_CHECKING:
    from .actor import Agent


class StandIn:
    def __init__(self, agent: Agent) -> None:
        self.agent = agent
        topo = agent.topo
        self.descendants = set(topo.subtree(agent.id)[1:])
        self.down: set[str] = set()  # descendants whose liveliness token went away
        self.adopted: tuple[str, ...] = ()  # the lost agents this agent stood in for at its last step
        self.listening: set[str] = set()  # lost agents whose obs/up keys this agent subscribed to
        # who sent an `up` addressed to x (me, or an agent I adopted): the child of x whose subtree holds
        # exactly the tips reported (computed once per x, not per message)
        self.child_by_tips: dict[str, dict[frozenset[str], str]] = {}

    def watch(self) -> Any:
        """Subscribe to my descendants' liveliness tokens: each change into the mailbox (`token_change`), in order."""
        if not self.descendants:
            return None
        node, k = self.agent.node, self.agent.keys
        push = node.mailbox.push

        def on_token(sample: Any) -> None:  # zenoh thread
            key = str(sample.key_expr)
            parsed = k.parse_alive(key)
            if parsed is not None and parsed[1] in self.descendants:
                sign = UP if sample.kind == sample.kind.PUT else GONE
                push(ALIVE, token_change(sign, key).encode())

        return node.session.liveliness().declare_subscriber(k.alive("agent", "*"), on_token, history=True)

    def on_token(self, change: str) -> None:
        """A descendant's token came or went (`watch`'s change, as the agent's WakeGuard let it through)."""
        a = self.agent
        sign, key = parse_token_change(change)
        parsed = a.keys.parse_alive(key)
        if parsed is None:
            return
        lost = parsed[1]
        if sign == UP:
            self.down.discard(lost)
            return
        self.down.add(lost)
        # subscribe now to what the lost agent heard, so this agent can stand in from the next step
        if lost not in self.listening:
            self.listening.add(lost)
            spec = a.topo.agents[lost]
            if spec.has_dof:
                a.stand_in_readings(lost)
            if spec.children:
                a.node.listen(a.keys.up(lost))

    def region(self) -> tuple[list[str], list[str]]:
        """(adopted, waiting): the lost agents below me down to the live ones, and those live ones."""
        children = self.agent.spec.children
        if not self.down:
            return [], list(children)
        adopted, waiting = [], []
        stack = list(children)
        while stack:
            c = stack.pop()
            if c in self.down:
                adopted.append(c)
                stack.extend(self.agent.topo.agents[c].children)
            else:
                waiting.append(c)
        return adopted, waiting

    def frames_below(
        self, agent: str, end: tuple[float, ...], q: dict[str, float], tips: dict
    ) -> Iterator[tuple[str, tuple[float, ...]]]:
        """(child, its base frame) for my children and, through lost agents, for theirs (composing the lost agents'
        frames from their encoders, as they would have); tips of lost leaves go to `tips`."""
        topo = self.agent.topo
        for c in topo.agents[agent].children:
            yield c, end
            if c in self.down:
                spec = topo.agents[c]
                geom = self.agent.geom
                c_end = geom.link_end(spec, geom.joint_frame(spec, end, q.get(c, 0.0)))
                if spec.is_leaf:
                    tips[c] = geom.tip(spec, c_end)
                yield from self.frames_below(c, c_end, q, tips)

    def announce(self, adopted: list[str]) -> None:
        now = tuple(sorted(adopted))
        if now == self.adopted:
            return
        a = self.agent
        for lost in sorted(set(now) - set(self.adopted)):
            below = ", ".join(a.topo.agents[lost].children) or "its joint only"
            self._event("adopt", lost, f"{a.id} stands in for {lost} ({below})")
        for back in sorted(set(self.adopted) - set(now)):
            self._event("handback", back, f"{a.id} hands control back to {back}")
        self.adopted = now

    def sender_of(self, m: Up, addressee: str) -> str | None:
        """The child of `addressee` (me, or an agent I stand in for) that sent `m`, known by the tips it reports;
        None when `m` is not for me or fits no child (logged)."""
        a = self.agent
        if addressee != a.id and addressee not in self.listening:
            return None
        by_tips = self.child_by_tips.get(addressee)
        if by_tips is None:
            by_tips = self.child_by_tips[addressee] = {
                frozenset(a.topo.subtree_leaves(c)): c for c in a.topo.agents[addressee].children
            }
        child = by_tips.get(frozenset(m.tips)) if m.tips else None
        if child is None:
            a.node.log.warning("rejected up to %s: tips %s are not from one of its children", addressee, list(m.tips))
        return child

    def _event(self, event: str, target: str, detail: str) -> None:
        a = self.agent
        epoch, step = a.last_begun
        a.node.log.info("%s %s: %s", event, target, detail)
        a.node.send(a.keys.metrics("event"), Event(epoch=epoch, step=step, event=event, target=target, detail=detail))
