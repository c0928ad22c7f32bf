"""The wire floor: how fast can a message go down a chain of N processes and back up, over Zenoh,
with nothing else happening? A swarm step on a chain of N agents needs the same 2(N-1) hops plus
two to and from the simulator, so this bounds any implementation's step rate on this machine.

    python wire_floor.py [--n 4] [--passes 2000] [--mode async|block] [--port 17600]

Each process relays with the asyncio bridge (callback -> call_soon_threadsafe -> asyncio.Queue) or
a blocking FifoChannel; each msgpack-decodes, appends its id and re-encodes. Peers on 127.0.0.1,
multicast off, BLOCK congestion control. Prints medians and p99; quote ratios, not single times.

A copy of the team's shared tool (tools/wire_floor.py beside this repository), kept here so that
benchmarks/floors.py runs from a checkout alone. Changed: --port (the chain's first port; two runs at
once need different ones). The relays are the tool's, line for line: keep them so, or the floors stop
being comparable with the numbers quoted elsewhere.
"""

import argparse
import asyncio
import json
import statistics
import subprocess
import sys
import time

import msgpack
import zenoh
from zenoh.handlers import FifoChannel

BASE_PORT = 17600


def config(i, base=BASE_PORT):
    c = zenoh.Config()
    c.insert_json5("mode", json.dumps("peer"))
    c.insert_json5("listen/endpoints", json.dumps([f"tcp/127.0.0.1:{base + i}"]))
    c.insert_json5("connect/endpoints", json.dumps([f"tcp/127.0.0.1:{base + j}" for j in range(i)]))
    c.insert_json5("scouting/multicast/enabled", "false")
    return c


def next_key(i, n, direction):
    if direction == "down":
        return f"chain/down/{i + 1}" if i < n - 1 else f"chain/up/{i - 1}"
    return f"chain/up/{i - 1}" if i > 0 else None


def relay(i, n, mode, base=BASE_PORT):
    s = zenoh.open(config(i, base))
    pubs = {
        k: s.declare_publisher(k, congestion_control=zenoh.CongestionControl.BLOCK)
        for k in (f"chain/down/{i + 1}", f"chain/up/{i - 1}")
    }

    def forward(key, data):
        m = msgpack.unpackb(data)
        if m.get("stop"):
            if i < n - 1:
                pubs[f"chain/down/{i + 1}"].put(data)
            return False
        m["trace"].append(i)
        pubs[next_key(i, n, key.split("/")[1])].put(msgpack.packb(m))
        return True

    if mode == "async":

        async def main():
            loop = asyncio.get_running_loop()
            q = asyncio.Queue()
            s.declare_subscriber(
                f"chain/*/{i}",
                lambda smp: loop.call_soon_threadsafe(q.put_nowait, (str(smp.key_expr), smp.payload.to_bytes())),
            )
            print("READY", flush=True)
            while forward(*(await q.get())):
                pass

        asyncio.run(main())
    else:
        sub = s.declare_subscriber(f"chain/*/{i}", FifoChannel(1024))
        print("READY", flush=True)
        while forward(str((smp := sub.recv()).key_expr), smp.payload.to_bytes()):
            pass
    s.close()


def drive(n, passes, mode, base=BASE_PORT):
    s = zenoh.open(config(0, base))
    p0 = s.declare_publisher("chain/down/1", congestion_control=zenoh.CongestionControl.BLOCK)
    sub = s.declare_subscriber("chain/*/0", FifoChannel(1024))
    while True:  # until the whole chain is matched
        p0.put(msgpack.packb({"tag": -1, "trace": [0]}))
        time.sleep(0.2)
        if sub.try_recv() is not None:
            break
    time.sleep(0.3)
    while sub.try_recv() is not None:
        pass
    times = []
    for k in range(-50, passes):
        t = time.perf_counter_ns()
        p0.put(msgpack.packb({"tag": k, "trace": [0], "obs": "y" * 60}))
        m = msgpack.unpackb(sub.recv().payload.to_bytes())
        assert m["tag"] == k and len(m["trace"]) == 2 * n - 2
        if k >= 0:
            times.append((time.perf_counter_ns() - t) / 1e3)
    p0.put(msgpack.packb({"stop": True}))
    time.sleep(0.1)
    s.close()
    return times


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--n", type=int, default=4)
    ap.add_argument("--passes", type=int, default=2000)
    ap.add_argument("--mode", choices=("async", "block"), default="async")
    ap.add_argument("--port", type=int, default=BASE_PORT, help="the first of n consecutive ports")
    ap.add_argument("--relay", type=int, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.relay is not None:
        return relay(a.relay, a.n, a.mode, a.port)
    procs = []
    try:
        for i in range(1, a.n):
            p = subprocess.Popen(
                [sys.executable, __file__, "--n", str(a.n), "--mode", a.mode, "--port", str(a.port), "--relay", str(i)],
                stdout=subprocess.PIPE,
                text=True,
            )
            assert p.stdout.readline().strip() == "READY"
            procs.append(p)
        t = sorted(drive(a.n, a.passes, a.mode, a.port))
        hops = 2 * (a.n - 1)
        med, p99 = statistics.median(t), t[int(0.99 * len(t))]
        per_hop = med / hops
        print(
            f"n={a.n} mode={a.mode} passes={a.passes}: down+up pass median {med:.0f} us, p99 {p99:.0f} us, "
            f"{per_hop:.0f} us per hop"
        )
        print(
            f"floor for a swarm step on this chain ({hops} + 2 hops): ~{per_hop * (hops + 2):.0f} us "
            f"= ~{1e6 / (per_hop * (hops + 2)):.0f} steps/s"
        )
    finally:
        for p in procs:
            try:
                p.wait(timeout=5)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()


if __name__ == "__main__":
    main()
