"""What one agent's step handlers cost in Python, message kind by message kind, without Zenoh's wire in the way.

    python benchmarks/handler_cost.py [--epochs 3] [--steps 500] [--sink] [--profile a4/down] [--top 25]

The four agents of examples/chain4.toml are built as the `process` placement builds them (actors/process/main.py), each
with a Node of its own on a Zenoh session of its own: every step message an agent sends is encoded, signed and put
as in `process` (nobody hears the put; with `--sink` a session of its own listens, so each put travels over TCP),
and this script hands the same bytes to the addressee's step handler (`Agent._on_step`: decode with MAC and
validation, the step's logic, the next puts), one message at a time, in the order of a `process` step: the task and
the four obs, the downs, the ups leaf first. The sim is stood in for: each obs carries the joint's last reading plus
its command, the task the goal and the tips at those readings (sim/kinematics.py). So the handlers see what they see
in a swarm; the numbers are their own CPU (thread time) per message, medians in µs with the first epoch dropped, the
wire and the other processes left out. Run it with another checkout's interpreter to compare two versions.

`--profile KEY` (e.g. `a4/down`, `a2/up`, `a1/task`) runs cProfile, on thread CPU time, around that handler only and
prints its `--top` functions by own time.
"""

from __future__ import annotations

import argparse
import asyncio
import collections
import cProfile
import gc
import os
import pstats
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import zenoh
from kinswarm.actors.agent.actor import Agent
from kinswarm.actors.files.runfile import load_run
from kinswarm.actors.runtime import NetSpec, Node, open_session
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Cmd, Obs, Task
from kinswarm.sim.kinematics import tips as tips_of

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
from step_rate import free_port  # noqa: E402


async def measure(
    epochs: int, steps: int, profile: str | None, sink: bool, freeze: bool = True, parts: dict | None = None
) -> dict[str, list[tuple[int, int]]]:
    """Per handler (`<agent>/<kind>`): (thread CPU ns, wall ns) of every call after the first epoch. `sink`: a session
    of its own listens to every key, so each put travels over TCP as in `process`. `parts`: filled with each handler's
    CPU in each of PARTS."""
    cfg = load_run(
        ROOT / "examples" / "chain4.toml", [f"run.epochs={epochs}", f"run.steps={steps}", "run.record=false"]
    )
    topo = cfg.topo()
    keys = Keys(cfg.run_id)
    sessions, agents, nodes = [], {}, {}
    outbox: collections.deque[tuple[str, bytes]] = collections.deque()

    class Put:
        """A publisher whose puts the script also hands to the addressee (the Zenoh put itself is kept)."""

        def __init__(self, pub: Any, key: str) -> None:
            self.pub, self.key = pub, key

        def put(self, payload: bytes) -> None:
            self.pub.put(payload)
            outbox.append((self.key, payload))

    def capture(node: Node) -> None:
        publisher = node.publisher

        def _publisher(key: str) -> Any:
            pub = publisher(key)
            if type(pub) is not Put:
                pub = node._pubs[key] = Put(pub, key)
            return pub

        node.publisher = _publisher  # type: ignore[method-assign]

    spec, listener = NetSpec(mode="peer"), None
    if sink:
        endpoint = f"tcp/127.0.0.1:{free_port()}"
        listener = open_session(NetSpec(mode="peer", listen=(endpoint,)))
        heard = listener.declare_subscriber(keys.everything, zenoh.handlers.RingChannel(1))  # no Python, no GIL
        spec = NetSpec(mode="peer", connect=(endpoint,))
    for a in topo.agents:
        s = open_session(spec)
        sessions.append(s)
        node = Node(s, keys, "agent", a, cfg.key)
        capture(node)
        nodes[a], agents[a] = node, Agent(cfg, topo, a, node)
    sim = Node(sessions[0], keys, "sim", "sim", cfg.key)
    if sink:
        await asyncio.sleep(1.0)  # the sessions meet the listener
    root = next(a for a in topo.agents if topo.agents[a].parent is None)
    q = {a: spec.initial for a, spec in topo.agents.items() if spec.has_dof}
    times: dict[str, list[tuple[int, int]]] = collections.defaultdict(list)
    prof = cProfile.Profile(time.thread_time) if profile else None  # CPU: preemption on a shared machine left out
    now: list[str] = [""]  # the handler running (for --parts)
    if parts is not None:
        _time_parts(parts, now)

    def deliver(key: str, payload: bytes, epoch: int) -> None:
        step = keys.parse_step(key)
        assert step is not None, key
        if step.kind == "cmd":
            m = codec.decode(payload, Cmd, keys.run, cfg.key)
            q[step.agent] += m.delta
            return
        kind = step.kind
        agent = root if kind == "task" else step.agent  # the task is the root's; obs, down, up name their addressee
        name = now[0] = f"{agent}/{kind}" if epoch > 0 else ""
        name = name or f"{agent}/{kind}"
        on = prof is not None and name == profile and epoch > 0
        c0, t0 = time.thread_time_ns(), time.perf_counter_ns()
        if on:
            prof.enable()
        agents[agent]._on_step(key, payload)
        if on:
            prof.disable()
        if epoch > 0:
            times[name].append((time.thread_time_ns() - c0, time.perf_counter_ns() - t0))

    collected: dict[int, list[int]] = collections.defaultdict(lambda: [0, 0])  # generation -> [count, CPU ns]
    started = [0]

    def on_gc(phase: str, info: dict[str, int]) -> None:  # the collections of the measured epochs, and their CPU
        if phase == "start":
            started[0] = time.thread_time_ns()
        elif measuring:
            c = collected[info["generation"]]
            c[0] += 1
            c[1] += time.thread_time_ns() - started[0]

    measuring = False
    if freeze:  # as an actor's process does once it is built (actors/runtime/heap.py; inline: older checkouts lack it)
        gc.collect()
        gc.freeze()
    gc.callbacks.append(on_gc)
    for epoch in range(epochs):
        measuring = epoch > 0
        for step in range(steps):
            # the sim's share: the task first, then each joint's obs (its order in sim/actor.py)
            sim_msgs = [(keys.task, Task(epoch=epoch, step=step, goal=tuple(cfg.task["goal"]), tips=tips_of(topo, q)))]
            sim_msgs += [(keys.obs(a), Obs(epoch=epoch, step=step, q=q[a])) for a in q]
            for key, msg in sim_msgs:
                outbox.append((key, codec.encode(msg, keys.run, "sim", cfg.key)))
            while outbox:
                deliver(*outbox.popleft(), epoch)
        # the closing ups of the epoch's last step are in the outbox's drain above
    for n in [*nodes.values(), sim]:
        n.close()
    for s in sessions:
        s.close()
    if listener is not None:
        heard.undeclare()
        listener.close()
    gc.callbacks.remove(on_gc)
    for g, (n, ns) in sorted(collected.items()):
        print(f"gc generation {g}: {n} collections, {ns / 1e6:.1f} ms of CPU in {(epochs - 1) * steps} steps")
    if prof is not None:
        pstats.Stats(prof).sort_stats("tottime").print_stats(ARGS.top)
    return times


#: the parts of a handler --parts times: (what, the class and its method)
PARTS = (
    ("decode", "kinswarm.actors.runtime.node", "Node", "decode"),
    ("send (encode, sign, put)", "kinswarm.actors.runtime.node", "Node", "send"),
    ("begin (frame, task head)", "kinswarm.actors.step.passes", "AgentPasses", "begin"),
    ("finish (tips, view)", "kinswarm.actors.step.passes", "AgentPasses", "finish"),
    ("up (task aggregate)", "kinswarm.actors.step.passes", "AgentPasses", "up"),
    ("decide_from (S_i, reward)", "kinswarm.actors.step.passes", "AgentPasses", "decide_from"),
    ("learner.decide", "kinswarm.actors.learning.learner", "Learner", "decide"),
    ("learner.observe", "kinswarm.actors.learning.learner", "Learner", "observe"),
)


def _time_parts(parts: dict, now: list[str]) -> None:
    """Wrap each of PARTS to add its thread CPU to parts[handler][what] (outermost calls only: send within send)."""
    import importlib

    depth = [0]
    for what, module, cls_name, method in PARTS:
        cls = getattr(importlib.import_module(module), cls_name, None)
        if cls is None:
            continue
        inner = getattr(cls, method)

        def timed(*args: Any, _inner: Any = inner, _what: str = what, **kw: Any) -> Any:
            if depth[0] or not now[0]:
                return _inner(*args, **kw)
            depth[0] += 1
            c0 = time.thread_time_ns()
            try:
                return _inner(*args, **kw)
            finally:
                depth[0] -= 1
                parts.setdefault(now[0], collections.Counter())[_what] += time.thread_time_ns() - c0

        setattr(cls, method, timed)


def main() -> None:
    global ARGS
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--epochs", type=int, default=3)
    p.add_argument("--steps", type=int, default=500)
    p.add_argument("--profile", default=None, help="a handler to profile, e.g. a4/down")
    p.add_argument("--top", type=int, default=25)
    p.add_argument("--parts", action="store_true", help="the mean CPU of each part of each handler (PARTS)")
    p.add_argument("--no-freeze", action="store_true", help="leave the setup's objects to the collector")
    p.add_argument("--sink", action="store_true", help="puts travel over TCP to a listening session")
    ARGS = p.parse_args()
    parts: dict | None = {} if ARGS.parts else None
    times = asyncio.run(measure(ARGS.epochs, ARGS.steps, ARGS.profile, ARGS.sink, not ARGS.no_freeze, parts))
    print(f"load average {' '.join(f'{x:.1f}' for x in os.getloadavg())}; medians in µs over epochs 1..")
    print(f"{'handler':<10} {'n':>6} {'cpu':>7} {'wall':>7}")
    total = 0.0
    for name in sorted(times, key=lambda n: (n.split("/")[1], n)):
        rows = times[name]
        cpu = statistics.median(r[0] for r in rows) / 1000
        wall = statistics.median(r[1] for r in rows) / 1000
        total += cpu * len(rows) / (ARGS.epochs - 1) / ARGS.steps
        print(f"{name:<10} {len(rows):>6} {cpu:>7.1f} {wall:>7.1f}")
    print(f"the four agents' handlers a step (cpu, medians x count): {total:.0f} µs")
    if parts:
        print("\nparts, mean µs of CPU a call of the handler (the rest: dispatch, the actor's bookkeeping, the timers)")
        for name in sorted(parts, key=lambda n: (n.split("/")[1], n)):
            n = len(times[name])
            mean = statistics.mean(r[0] for r in times[name]) / 1000
            cells = ", ".join(f"{w} {ns / n / 1000:.1f}" for w, ns in parts[name].most_common())
            print(f"{name:<10} mean {mean:6.1f}: {cells}")


ARGS: argparse.Namespace
if __name__ == "__main__":
    main()
