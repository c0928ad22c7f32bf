"""The step's own message pattern as a floor: chain4's 15 messages a step between 5 processes, with bare relays.

    python benchmarks/pattern_floor.py [--passes 2000] [--work 0] [--port 17700]

wire_floor.py relays one message down a chain of 4 processes and back (6 hops, one process busy at a time) and
counts 8 hops a step. A `process` step is another shape: the simulator puts each joint's `obs` and the root's
`task` (5 messages), the `down`s go a1 -> a2 -> a3 -> a4 (3), the `up`s come back a4 -> a3 -> a2 -> a1 (3) and
every agent sends its `cmd` to the simulator (4), which waits for all four before the next step. Here the same
15 messages move between 5 processes (this one the simulator, four relays), each handler only decoding with msgpack
and encoding what it sends, as wire_floor's relays do; `--work US` adds US microseconds of busy CPU to every
agent's handler before it sends (a model of a handler's own work). Blocking FifoChannel receives, BLOCK congestion
control, peers on 127.0.0.1, multicast off. What it bounds: the step rate of any handlers on this pattern here.
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

import msgpack
import zenoh
from wire_floor import config  # benchmarks/ is this script's directory, so first on sys.path
from zenoh.handlers import FifoChannel

N = 4  # agents a1..a4; process 0 is the simulator
BASE_PORT = 17700
PAD = "y" * 60  # a message's payload, as wire_floor's


def busy(us: float) -> None:
    end = time.perf_counter_ns() + int(us * 1000)
    while time.perf_counter_ns() < end:
        pass


def agent(i: int, work: float, base: int) -> None:
    """Agent i (1 = the root, N = the leaf): its step is its obs and its head (the task or its parent's down); then
    down to its child, or, at the leaf, up and cmd; an up from its child is passed up (the root: only its cmd)."""
    s = zenoh.open(config(i, base))
    block = zenoh.CongestionControl.BLOCK
    pub = {k: s.declare_publisher(k, congestion_control=block) for k in (f"pat/down/{i + 1}", f"pat/up/{i - 1}")}
    cmd = s.declare_publisher(f"patcmd/{i}", congestion_control=block)
    sub = s.declare_subscriber(f"pat/*/{i}", FifoChannel(1024))
    print("READY", flush=True)
    obs: dict[int, dict] = {}  # by step: a matching-phase leftover never pairs with a later step's half
    head: dict[int, dict] = {}
    while True:
        smp = sub.recv()
        kind = str(smp.key_expr).split("/")[1]
        m = msgpack.unpackb(smp.payload.to_bytes())
        if m.get("stop"):
            break
        if kind == "obs":
            obs[m["tag"]] = m
        elif kind in ("task", "down"):
            head[m["tag"]] = m
        else:  # an up from the child
            busy(work)
            if i > 1:
                pub[f"pat/up/{i - 1}"].put(msgpack.packb({"tag": m["tag"], "up": i, "pad": PAD}))
            cmd.put(msgpack.packb({"tag": m["tag"], "cmd": i}))
            continue
        tag = m["tag"]
        if tag in obs and tag in head:
            obs = {t: v for t, v in obs.items() if t > tag}
            head = {t: v for t, v in head.items() if t > tag}
            busy(work)
            if i < N:
                pub[f"pat/down/{i + 1}"].put(msgpack.packb({"tag": tag, "down": i, "pad": PAD}))
            else:
                pub[f"pat/up/{i - 1}"].put(msgpack.packb({"tag": tag, "up": i, "pad": PAD}))
                cmd.put(msgpack.packb({"tag": tag, "cmd": i}))
    s.close()


def simulator(passes: int, base: int) -> list[float]:
    s = zenoh.open(config(0, base))
    block = zenoh.CongestionControl.BLOCK
    obs = {i: s.declare_publisher(f"pat/obs/{i}", congestion_control=block) for i in range(1, N + 1)}
    task = s.declare_publisher("pat/task/1", congestion_control=block)
    sub = s.declare_subscriber("patcmd/*", FifoChannel(1024))

    def step(tag: int) -> None:
        obs[1].put(msgpack.packb({"tag": tag, "q": 0.1, "pad": PAD}))
        task.put(msgpack.packb({"tag": tag, "pad": PAD}))
        for i in range(2, N + 1):
            obs[i].put(msgpack.packb({"tag": tag, "q": 0.1, "pad": PAD}))

    while True:  # until every agent is matched: a step comes back whole
        step(-1)
        time.sleep(0.2)
        got = 0
        while sub.try_recv() is not None:
            got += 1
        if got == N:
            break
    time.sleep(0.3)
    while sub.try_recv() is not None:  # the matching phase's late cmds
        pass
    times = []
    for k in range(-50, passes):
        t = time.perf_counter_ns()
        step(k)
        got = 0
        while got < N:
            m = msgpack.unpackb(sub.recv().payload.to_bytes())
            got += m["tag"] == k  # an older step's cmd (the matching phase's) is not this step's
        if k >= 0:
            times.append((time.perf_counter_ns() - t) / 1e3)
    for p in [*obs.values(), task]:
        p.put(msgpack.packb({"stop": True}))
    time.sleep(0.1)
    s.close()
    return times


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--passes", type=int, default=2000)
    ap.add_argument("--work", type=float, default=0.0, help="busy microseconds in every agent handler that sends")
    ap.add_argument("--port", type=int, default=BASE_PORT, help="the first of 5 consecutive ports")
    ap.add_argument("--agent", type=int, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.agent is not None:
        return agent(a.agent, a.work, a.port)
    procs = []
    try:
        for i in range(1, N + 1):
            cmd = [sys.executable, __file__, "--work", str(a.work), "--port", str(a.port), "--agent", str(i)]
            p = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True)
            if p.stdout.readline().strip() != "READY":
                raise SystemExit(f"agent {i} did not start")
            procs.append(p)
        t = sorted(simulator(a.passes, a.port))
        med, p99 = statistics.median(t), t[int(0.99 * len(t))]
        print(f"step pattern (15 messages, 5 processes, work {a.work:g} us): median {med:.0f} us, p99 {p99:.0f} us")
        print(f"= {1e6 / med:.0f} steps/s")
    finally:
        for p in procs:
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


if __name__ == "__main__":
    main()
