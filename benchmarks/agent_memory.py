"""What an actor process costs: memory of each agent and of the sim, and the time from command to first step, for
chains of N agents in the `process` placement.

    python benchmarks/agent_memory.py [--n 4,16,64] [--steps 200] [--python PYTHON ...] [--json out.json]

Each row is one `kinswarm run` of a generated chain of N joints (links of 12/N, the README's reach task), 2 epochs
of --steps steps, nothing drawn or recorded. The run's processes are found by walking the supervisor's descendants
in /proc; once the sim's clock (<run>/net/clock) shows the first step, and again after the first epoch, every one's
`smaps_rollup` is read: PSS (proportional set size: a page shared by k processes counts 1/k in each, so memory the
agents share counts once over all of them) and RSS (every page the process maps, shared or not). The table shows
the second reading (the processes at work). Times are from the command: to every agent's process existing (read
every 0.2 s), to the clock's first step (read every 10 ms), to the run's end (command to summary); CPU is the user and
system time of every process of the run (getrusage of the children: each actor was waited for by its parent). On a
shared machine the CPU column is the steadier: N fresh interpreters get N shares of a busy machine, a zygote one.

`--python` runs the rows under other interpreters too (another checkout's venv python: a change's before and after),
alternated N by N so both see the same load. Each row prints the load average (1 min) it started at.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

# benchmarks/ is this script's directory, so first on sys.path
from step_rate import free_port

ROLE_ARG = "kinswarm.actors.process.main"  # an actor's command line: python -m kinswarm.actors.process.main ROLE ID ...


def chain_file(n: int, path: Path) -> Path:
    """A planar chain of n joints, a1 (root) > ... > an, total length 12 (chain4's), reaching chain4's goal."""
    lines = ["[robot]", f'name = "chain{n}"', "base = [0.0, 0.0, 0.0]", "", "[robot.defaults]"]
    lines += [f"link_length = {12.0 / n!r}", "limits_deg = [-180.0, 180.0]", ""]
    for i in range(1, n + 1):
        lines += ["[[robot.agent]]", f'id = "a{i}"']
        if i > 1:
            lines += [f'parent = "a{i - 1}"']
        lines += [f"initial_deg = {0.0 if i == 1 else 40.0 / n!r}", ""]
    lines += ["[task]", 'kind = "reach"', "goal = [4.16, 6.18]", ""]
    path.write_text("\n".join(lines))
    return path


def memory(pid: int) -> tuple[int, int] | None:
    """(PSS, RSS) in kB, None once the process is gone."""
    try:
        text = Path(f"/proc/{pid}/smaps_rollup").read_text()
    except OSError:
        return None
    got = {}
    for line in text.splitlines():
        name, _, rest = line.partition(":")
        if name in ("Pss", "Rss"):
            got[name] = int(rest.split()[0])
    return got.get("Pss", 0), got.get("Rss", 0)


def descendants(root: int) -> list[int]:
    """Every live process under `root` (any depth), from /proc's parent links."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            stat = Path(f"/proc/{entry}/stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry))
    found, todo = [], [root]
    while todo:
        for c in children.get(todo.pop(), []):
            found.append(c)
            todo.append(c)
    return found


def role_of(pid: int) -> str:
    """'agent', 'sim', 'zygote', or 'other': from the command line of a spawned actor, from the name a forked one
    gives itself (/proc/PID/comm: "agent-a1"; its command line is the zygote's)."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
        comm = Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return "gone"
    if ROLE_ARG not in argv:
        return "other"
    if "--zygote" in argv:
        role = comm.split("-", 1)[0]
        return role if role in ("agent", "sim", "controller") else "zygote"
    i = argv.index(ROLE_ARG)
    return argv[i + 1] if i + 1 < len(argv) else "?"


def snapshot(root: int) -> dict[str, list[tuple[int, int]]]:
    """(PSS, RSS) of every process under the supervisor, by role ('supervisor' is the root itself)."""
    by_role: dict[str, list[tuple[int, int]]] = {}
    for pid in [root, *descendants(root)]:
        m = memory(pid)
        if m is not None:
            by_role.setdefault("supervisor" if pid == root else role_of(pid), []).append(m)
    return by_role


def read_clock(run_dir: Path) -> tuple[int, int] | None:
    try:
        word = int.from_bytes((run_dir / "net" / "clock").read_bytes()[:8], "little", signed=True)
    except (OSError, ValueError):
        return None
    return (word >> 32) - 1, word & 0xFFFFFFFF


def one_row(python: str, n: int, steps: int, seed: int) -> dict:
    kinswarm = str(Path(python).parent / "kinswarm")
    with tempfile.TemporaryDirectory() as d:
        out = Path(d) / "run"
        argv = [kinswarm, "run", str(chain_file(n, Path(d) / f"chain{n}.toml")), "--placement", "process"]
        argv += ["--epochs", "2", "--steps", str(steps), "--seed", str(seed), "--out", str(out)]
        argv += ["--listen", f"tcp/127.0.0.1:{free_port()}", "--no-progress", "--set", "run.record=false"]
        load = os.getloadavg()[0]
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.monotonic()
        p = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
        first = None
        at_first: dict[str, list[tuple[int, int]]] = {}
        working: dict[str, list[tuple[int, int]]] = {}
        waiting: dict[str, list[tuple[int, int]]] = {}  # before any step: the fullest reading, every ~2 s
        last_wait = last_count = 0.0
        spawned = None  # every agent's process exists (its imports may still run)
        try:
            while p.poll() is None:
                if spawned is None and time.monotonic() - last_count > 0.2:
                    last_count = time.monotonic()
                    if sum(role_of(q) == "agent" for q in descendants(p.pid)) >= n:
                        spawned = last_count - t0
                clock = read_clock(out)
                if first is None and clock is not None and clock[0] >= 0:
                    first = time.monotonic() - t0
                    at_first = snapshot(p.pid)
                if clock is not None and (clock[0] >= 1 or clock[1] >= steps // 2) and not working:
                    working = snapshot(p.pid)
                if first is None and time.monotonic() - last_wait > 2.0:
                    last_wait = time.monotonic()
                    now = snapshot(p.pid)
                    if len(now.get("agent", [])) >= len(waiting.get("agent", [])):
                        waiting = now
                time.sleep(0.01)
            text = p.stdout.read() if p.stdout else ""
        finally:
            if p.poll() is None:
                p.kill()
            p.wait()
        total = time.monotonic() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)  # every process of the run: each was waited for
        cpu = (after.ru_utime + after.ru_stime) - (before.ru_utime + before.ru_stime)
    readings = ((working, "working"), (at_first, "first step"), (waiting, "waiting"))
    # a reading taken late (a loaded machine can hold this loop back past the run's end) may miss the actors
    shown, phase = next(((got, name) for got, name in readings if len(got.get("agent", [])) == n), readings[-1])
    agents = shown.get("agent", [])
    sim = shown.get("sim", [(0, 0)])
    row = {
        "python": python,
        "n": n,
        "load": load,
        "ok": p.returncode == 0,
        "reading": phase,  # working: mid-run; first step: the run ended before mid-run; waiting: it never stepped
        "spawned_s": spawned,
        "first_step_s": first,
        "summary_s": total,
        "cpu_s": cpu,
        "agents": len(agents),
        "agent_pss_mb": statistics.median(a[0] for a in agents) / 1024 if agents else None,
        "agent_pss_max_mb": max(a[0] for a in agents) / 1024 if agents else None,
        "agent_rss_mb": statistics.median(a[1] for a in agents) / 1024 if agents else None,
        "agent_rss_max_mb": max(a[1] for a in agents) / 1024 if agents else None,
        "sim_pss_mb": sim[0][0] / 1024,
        "sim_rss_mb": sim[0][1] / 1024,
        "zygote_pss_mb": sum(m[0] for m in shown.get("zygote", [])) / 1024,
        "total_pss_mb": sum(m[0] for ms in shown.values() for m in ms) / 1024,
        "at_first_step": {k: [list(m) for m in v] for k, v in at_first.items()},
        "working": {k: [list(m) for m in v] for k, v in working.items()},
        "waiting": {k: [list(m) for m in v] for k, v in waiting.items()},
    }
    if not row["ok"]:
        row["error"] = text.strip().splitlines()[-1:] if text.strip() else ["(no output)"]
    return row


def fmt(v: float | None, spec: str = ".0f") -> str:
    return "-" if v is None else format(v, spec)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--n", default="4,16,64", help="agents in the chain, comma-separated (any N >= 1)")
    ap.add_argument("--steps", type=int, default=200, help="steps an epoch (2 epochs a run)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--python", action="append", default=[], help="also run each row under this interpreter")
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args()
    sizes = [int(x) for x in a.n.split(",") if x.strip()]
    if not sizes or min(sizes) < 1:
        sys.exit(f"--n: expected agent counts >= 1, comma-separated, got {a.n!r}")
    pythons = [sys.executable, *a.python]
    rows = []
    head = (
        f"{'N':>4} {'python':<28} {'load':>5} {'agent PSS med/max':>18} {'agent RSS med/max':>18} "
        f"{'sim PSS/RSS':>12} {'zygote PSS':>10} {'total PSS':>9} {'spawned':>8} {'first step':>10} {'summary':>8} "
        f"{'CPU':>7}"
    )
    print(head)
    for n in sizes:
        for py in pythons:
            r = one_row(py, n, a.steps, a.seed)
            rows.append(r)
            label = py if len(py) <= 28 else "..." + py[-25:]
            print(
                f"{n:>4} {label:<28} {r['load']:>5.1f} "
                f"{fmt(r['agent_pss_mb']):>8} / {fmt(r['agent_pss_max_mb']):<7} "
                f"{fmt(r['agent_rss_mb']):>8} / {fmt(r['agent_rss_max_mb']):<7} "
                f"{fmt(r['sim_pss_mb']):>5}/{fmt(r['sim_rss_mb']):<6} {fmt(r['zygote_pss_mb']):>10} "
                f"{fmt(r['total_pss_mb']):>9} {fmt(r['spawned_s'], '.1f'):>7}s "
                f"{fmt(r['first_step_s'], '.1f'):>9}s {fmt(r['summary_s'], '.1f'):>7}s {fmt(r['cpu_s'], '.1f'):>6}s"
                + ("" if r["reading"] == "working" else f"  (memory read {r['reading']})")
                + ("" if r["ok"] else f"  FAILED: {r['error'][0][:160]}"),
                flush=True,
            )
    print("memory in MB (of the processes at work, 2nd reading); times from the command: every agent's process")
    print("exists, the sim's first step, the run's summary; CPU: user + system of all the run's processes")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
