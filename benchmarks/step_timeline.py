"""Where a step's time goes: for each message of a 4-joint-chain step, from its put to its handler, beside the floors.

    python benchmarks/step_timeline.py [--placement process|single] [--epochs 3] [--steps 500] [--floors 1]

Runs `kinswarm run examples/chain4.toml` as a child process with KINSWARM_TIMELINE set (actors/runtime/timeline.py):
every actor's Node records, for each step message, when it was put, when it reached the receiver's process (Zenoh's
delivery thread entering Python, or the local bus), when its handler started and ended and the handler's thread CPU,
all on CLOCK_MONOTONIC, which every process of the machine shares. The nth put on a key is matched with the nth
arrival and the nth handling on it (one sender and one receiver a key, lockstep, no faults); the first epoch is
dropped as warm-up. Per key, in the order of the step, medians in µs:

  at       the put, after the step's `sim/task` put (where in the step it leaves)
  wire     put -> arrival: Zenoh, its delivery thread, the GIL (a wait this code cannot shorten but by fewer hops)
  wait     arrival -> handler start: the lock, the mailbox and the event loop (the wait this design adds)
  handler  the handler's wall time, and its CPU (what the step's logic costs; wall - CPU is preemption)
  inline   the share handled on Zenoh's thread rather than by the loop
In `single` a handler runs the handlers of the messages it sends within its own (local delivery): its times hold
theirs, and `wire` is the local bus's hand-over.

Then the step period, the CPU a step (the actors from their first step message; every process of the run with its
start-up, `getrusage` of the children), and `--floors`
pairs of the wire floors (benchmarks/wire_floor.py, async and block, alternated) as µs a hop and steps/s.
"""

from __future__ import annotations

import argparse
import bisect
import collections
import os
import resource
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from step_rate import free_port, wire_floor  # benchmarks/ is this script's directory, so first on sys.path

ROOT = Path(__file__).resolve().parent.parent
HOPS = 8  # a chain4 step's critical path: task, 3 downs, 3 ups, the root's cmd (the floor's pass: 6 hops + 2)


def record(placement: str, epochs: int, steps: int, trace: Path) -> float:
    """Run chain4 with the timeline on; the CPU seconds it took (every process)."""
    cmd = [sys.executable, "-m", "kinswarm.actors.cli", "run", str(ROOT / "examples" / "chain4.toml")]
    cmd += ["--placement", placement, "--epochs", str(epochs), "--steps", str(steps), "--set", "run.record=false"]
    cmd += ["--listen", f"tcp/127.0.0.1:{free_port()}", "--out", str(trace / "run"), "--no-progress"]
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    proc = subprocess.Popen(
        cmd,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        env=os.environ | {"KINSWARM_TIMELINE": str(trace)},
    )
    try:
        _, err = proc.communicate(timeout=900)
    finally:
        if proc.poll() is None:
            proc.terminate()
            proc.wait(timeout=30)
    if proc.returncode != 0:
        raise SystemExit(f"kinswarm run failed ({proc.returncode}):\n{err[-2000:]}")
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    return (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)


def load(trace: Path) -> tuple[dict, dict, dict]:
    """Per key: put times, arrival times, handlings (start, end, cpu, where), each in order."""
    puts: dict[str, list[int]] = collections.defaultdict(list)
    arrive: dict[str, list[int]] = collections.defaultdict(list)
    handled: dict[str, list[tuple[int, int, int, str]]] = collections.defaultdict(list)
    cpu: dict[str, tuple[int, int]] = {}  # pid -> the process's CPU ns at its first step message, at its close
    who: dict[str, list[str]] = {}  # pid -> the actors it runs
    for f in sorted(trace.glob("*.tsv")):
        for line in f.read_text().splitlines():
            what, key, t, *rest = line.split("\t")
            key = key.split("/", 2)[-1]  # below ks/<run>/
            if what == "cpu":  # one a process: the Nodes of one process (`single`) record the same CPU
                pid = f.stem.rsplit("-", 1)[1]
                who.setdefault(pid, []).append(f.stem.split("-")[1])
                start, end = min(int(t), cpu.get(pid, (int(t), 0))[0]), max(int(rest[0]), cpu.get(pid, (0, 0))[1])
                cpu[pid] = (start, end)
                continue
            if what == "put":
                puts[key].append(int(t))
            elif what == "arrive":
                arrive[key].append(int(t))
            else:
                handled[key].append((int(t), int(rest[0]), int(rest[1]), rest[2]))
    handled["cpu"] = [(start, end, 0, "+".join(sorted(who[pid]))) for pid, (start, end) in cpu.items()]
    return puts, arrive, handled


def table(trace: Path, epochs: int) -> tuple[list[tuple], float, int, float, dict[str, float]]:
    """Per key (at, wire, wait, handler, cpu, inline), the step period (µs), the steps kept, and the actors' CPU a
    step (µs: every thread of every actor process, from its first step message to its Node's close)."""
    puts, arrive, handled = load(trace)
    tasks = sorted(puts["sim/task"])
    per = {who: (end - start) / len(tasks) / 1e3 for start, end, _, who in handled.pop("cpu", [])}
    actors_cpu = sum(per.values())
    late = tasks[len(tasks) // epochs :]
    period = statistics.median(b - a for a, b in zip(late, late[1:], strict=False))
    rows = []
    for key, p in puts.items():
        n = min(len(p), len(arrive[key]), len(handled[key]))
        if n < epochs:
            continue
        p, a, h = sorted(p)[:n], sorted(arrive[key])[:n], sorted(handled[key])[:n]
        keep = range(n // epochs, n)
        at = []
        for i in keep:  # after the latest task put before it
            j = _latest(tasks, p[i])
            if j is not None:
                at.append(p[i] - j)
        med = statistics.median
        rows.append(
            (
                key,
                med(at) / 1e3 if at else 0.0,
                med(a[i] - p[i] for i in keep) / 1e3,
                med(h[i][0] - a[i] for i in keep) / 1e3,
                med(h[i][1] - h[i][0] for i in keep) / 1e3,
                med(h[i][2] for i in keep) / 1e3,
                sum(h[i][3] == "inline" for i in keep) / len(keep),
            )
        )
    rows.sort(key=lambda r: r[1])
    return rows, period / 1e3, len(tasks) - len(tasks) // epochs, actors_cpu, per


def _latest(sorted_times: list[int], t: int) -> int | None:
    i = bisect.bisect_right(sorted_times, t)
    return sorted_times[i - 1] if i else None


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--placement", choices=("process", "single"), default="process")
    ap.add_argument("--epochs", type=int, default=3)
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--floors", type=int, default=1, help="pairs of wire floor runs (async, block) in this sitting")
    ap.add_argument("--passes", type=int, default=2000)
    a = ap.parse_args()
    if a.epochs < 2:
        ap.error("--epochs must be at least 2 (the first is dropped as warm-up)")
    load1 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as d:
        cpu = record(a.placement, a.epochs, a.steps, Path(d))
        rows, period, kept, actors_cpu, per = table(Path(d), a.epochs)
    floors: dict[str, list[float]] = {"async": [], "block": []}
    for _ in range(a.floors):
        for mode in floors:
            if (v := wire_floor(mode, a.passes)) is not None:
                floors[mode].append(v)
    print(f"{a.placement} placement, 4-joint chain: {kept} steps after the first epoch (load avg {load1:.1f} before)")
    print(f"{'message':14}{'at':>8}{'wire':>8}{'wait':>8}{'handler':>9}{'cpu':>7}{'inline':>8}   (µs, medians)")
    for key, at, wire, wait, wall, cpu_us, inline in rows:
        print(f"{key:14}{at:8.0f}{wire:8.0f}{wait:8.0f}{wall:9.0f}{cpu_us:7.0f}{inline:8.0%}")
    steps = a.epochs * a.steps
    print(f"step period median {period:.0f} µs = {1e6 / period:.0f} steps/s (timeline on); ", end="")
    print(
        f"CPU a step: {actors_cpu:.0f} µs the actors (steady), of which handlers {sum(r[5] for r in rows):.0f}; ",
        end="",
    )
    print(f"{1e6 * cpu / steps:.0f} µs every process of the whole run (start-up included)")
    print("  by process (µs a step): " + ", ".join(f"{k} {v:.0f}" for k, v in sorted(per.items())))
    for mode, v in floors.items():
        if v:
            r = statistics.median(v)
            print(f"wire floor ({mode}): {r:.0f} steps/s, {1e6 / r / HOPS:.0f} µs a hop ({len(v)} runs)")
    print(f"load avg {os.getloadavg()[0]:.1f} after")


if __name__ == "__main__":
    main()
