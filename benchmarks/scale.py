"""The cost of a growing swarm: chains and wide trees of N joints, from the command to its summary.

    python benchmarks/scale.py                                   # N = 4..64, chain and tree, 3 placements, 2 hosts
    python benchmarks/scale.py --n 8,128 --topologies chain --placements process --repeats 3 --json out.json
    python benchmarks/scale.py --hosts-n ''                      # no two-host rows

Each row is one `kinswarm run FILE` as a user types it (a fresh process; learning on, the real PyBullet world, real
Zenoh sessions), FILE written by experiments/arms.py into a tmp dir: N `[[robot.agent]]` tables, the tip reaching 12
from the base at every N (a chain's links 12 / N; a tree's joints carry up to 3 children, so its depth grows as
log N). While it runs, this script reads the run's process tree from /proc (no psutil):

- start: seconds from the command to the sim's first step (its clock, `<run>/net/clock`; the `inprocess` placement
  has none: its first epoch's end less the epoch's seconds), and to `summary.json` (once it is written and every
  actor has left, the CLI is ended: what it does next is drawing plots, minutes on a loaded machine, untimed);
- steps/s: the sim's per-epoch timing (metrics.jsonl), the first epoch dropped as warm-up;
- CPU-ms a step: utime + stime (/proc/PID/stat) of every process of the run summed, between two readings of the sim's
  clock (from the epochs after the first, or from the first step when they went by too fast to be read twice, to
  the last step; inprocess: from the first epoch's row to the last one's), per step; and the run's whole CPU (wait4:
  every process it reaped);
- RSS (/proc/PID/status) and PSS (/proc/PID/smaps_rollup: memory shared between processes counted once) of each
  actor process, agents and sim apart, once the sim is in its second epoch (else once every actor is up; a run that
  never got so far: at the most actors its start reached, read every 5 s);
- Zenoh sessions (the run's processes with Zenoh's runtime threads: kinswarm opens one a process) and TCP
  connections (established sockets in /proc/PID/fd, looked up in the process's own /proc/PID/net/tcp{,6}; both ends
  of a loopback connection count, as `ss -tnp` lists them), per process and in total, at the same moment.

Placements: `process` (one OS process per actor, the subject), `single` and `inprocess` (the controls). With
--hosts-n (root: network namespaces, as benchmarks/deploy_rate.py), the same robot split over two hosts (`kinswarm up`
with one plan on each: the sim and a1 on `brain`, every other agent on `limbs`). A run that fails is a row ("failed:
<reason>"), never the end of the benchmark. Prints a table (markdown) and writes JSON (--json, default
scale.json in the current directory). Quote medians over repeats and say the load: these machines are shared.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import re
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
from kinswarm.experiments.arms import SHAPES, depth, run_file  # noqa: E402
from kinswarm.protocol.clock import ClockReader, clock_path  # noqa: E402
from netns import Hosts, NetnsUnavailable  # noqa: E402

KINSWARM = [sys.executable, "-m", "kinswarm.actors.cli"]
TICK = os.sysconf("SC_CLK_TCK")
PAGE = os.sysconf("SC_PAGE_SIZE")
PLACEMENTS = ("process", "single", "inprocess")
POLL_S = 0.05  # how often the process tree is read: a measurement's resolution, not a wait on anything
COLUMNS = ("N", "topology", "placement", "depth", "procs", "first step s", "summary s", "steps/s",
           "CPU-ms/step", "agent RSS MB", "agent PSS MB", "sim RSS MB", "sim PSS MB", "sessions", "TCP", "TCP/proc",
           "result")  # fmt: skip
ROW_KEYS = ("n", "topology", "placement", "hosts", "repeat", "depth", "result", "load", "processes", "actors",
            "first_step_s", "summary_s", "exit_s", "steps_per_s", "cpu_ms_per_step", "cpu_total_s", "agent_rss_mb",
            "agent_pss_mb", "sim_rss_mb", "sim_pss_mb", "sessions", "tcp_total", "tcp_per_process",
            "tcp_per_process_max", "per_process")  # fmt: skip


# -- /proc ---------------------------------------------------------------------------------------------------------
def _stat(pid: int) -> tuple[int, int] | None:
    """(ppid, utime + stime in ticks), or None if gone."""
    try:
        raw = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    rest = raw[raw.rindex(")") + 2 :].split()  # after "pid (comm) ": state ppid ... utime(14) stime(15)
    return int(rest[1]), int(rest[11]) + int(rest[12])


def tree(roots: Iterable[int]) -> dict[int, int]:
    """Every live process in the trees under `roots` (themselves included): pid -> CPU ticks so far."""
    table: dict[int, tuple[int, int]] = {}
    for d in os.listdir("/proc"):
        if d.isdigit() and (st := _stat(int(d))) is not None:
            table[int(d)] = st
    children: dict[int, list[int]] = {}
    for pid, (ppid, _) in table.items():
        children.setdefault(ppid, []).append(pid)
    out: dict[int, int] = {}
    todo = [r for r in roots if r in table]
    while todo:
        pid = todo.pop()
        out[pid] = table[pid][1]
        todo += children.get(pid, [])
    return out


def role_of(pid: int) -> str:
    """sim, agent, controller (an actor forked by the run's zygote is named ROLE-ID), hub (the host's Zenoh router),
    zygote, supervisor (the `kinswarm run` or `up` process) or other (e.g. a zenoh helper)."""
    try:
        argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
        comm = Path(f"/proc/{pid}/comm").read_text().strip()
    except OSError:
        return "gone"
    words = [a.decode(errors="replace") for a in argv]
    for role in ("agent", "sim", "controller"):
        if comm.startswith(role + "-"):
            return role
    if comm == "hub" or "kinswarm.actors.runtime.hub" in words:
        return "hub"
    if "--zygote" in words:
        return "zygote"
    if "kinswarm.actors.process.main" in words:
        i = words.index("kinswarm.actors.process.main")
        return words[i + 1] if i + 1 < len(words) else "actor"
    if "kinswarm.actors.cli" in words or any(w.endswith("/kinswarm") for w in words):
        return "supervisor"
    return "other"


def memory_mb(pid: int) -> tuple[float, float]:
    """(RSS, PSS) in MB; NaN where unreadable."""
    rss = pss = float("nan")
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                rss = int(line.split()[1]) / 1024
        for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
            if line.startswith("Pss:"):
                pss = int(line.split()[1]) / 1024
    except OSError:
        pass
    return rss, pss


def runs_zenoh(pid: int) -> bool:
    """Whether `pid` has a Zenoh session open: Zenoh's runtime threads (net-N, acc-N) exist once one is. Each of
    kinswarm's processes opens at most one (the single placement's actors share the supervisor's)."""
    try:
        tasks = os.listdir(f"/proc/{pid}/task")
    except OSError:
        return False
    for t in tasks:
        try:
            if Path(f"/proc/{pid}/task/{t}/comm").read_text().startswith(("net-", "acc-")):
                return True
        except OSError:
            continue
    return False


def _tcp_table(pid: int) -> dict[int, str]:
    """socket inode -> TCP state (hex: 01 established, 0A listening) in `pid`'s network namespace."""
    states: dict[int, str] = {}
    for name in ("tcp", "tcp6"):
        try:
            lines = Path(f"/proc/{pid}/net/{name}").read_text().splitlines()[1:]
        except OSError:
            continue
        for line in lines:
            f = line.split()
            states[int(f[9])] = f[3]
    return states


def sockets(pid: int, tables: dict[str, dict[int, str]]) -> tuple[int, int]:
    """(established TCP connections, listening TCP sockets) of `pid`; `tables`: per network namespace, filled here."""
    try:
        ns = os.readlink(f"/proc/{pid}/ns/net")
        fds = os.listdir(f"/proc/{pid}/fd")
    except OSError:
        return 0, 0
    if ns not in tables:
        tables[ns] = _tcp_table(pid)
    table = tables[ns]
    est = listen = 0
    for fd in fds:
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            state = table.get(int(target[8:-1]))
            est += state == "01"
            listen += state == "0A"
    return est, listen


# -- one run -------------------------------------------------------------------------------------------------------
@dataclass
class Watch:
    """What the poll loop saw of one run."""

    started: float
    first_step: float | None = None
    summary: float | None = None
    rows_seen: list[tuple[float, int]] = field(default_factory=list)  # (when, rows in metrics.jsonl) as they grew
    cpu_at: list[tuple[float, int]] = field(default_factory=list)  # (when, the tree's ticks so far)
    seen: dict[int, int] = field(default_factory=dict)  # every pid ever in the tree -> its last ticks
    steps_at: list[tuple[int, int, int]] = field(default_factory=list)  # (the sim's epoch, step, the tree's ticks)
    snapshot: dict[int, dict[str, Any]] | None = None  # per process at the first epoch's end (or first step)
    expect: int = 0  # actor processes (sim and agents) of the run
    complete: bool = False  # a snapshot with every actor is taken
    settled: bool = False  # the sim's second epoch has been seen
    probed: float = 0.0  # when the starting run's processes were last read

    def poll(self, roots: Sequence[int], leader_dir: Path, clock: ClockReader | None) -> None:
        now = time.perf_counter()
        procs = tree(roots)
        self.seen.update(procs)
        self.cpu_at.append((now, sum(self.seen.values())))  # an exited process keeps its last reading
        at = clock.read() if clock is not None else None
        if at is not None and at[0] >= 0:
            self.steps_at.append((at[0], at[1], sum(self.seen.values())))
        if self.first_step is None and at is not None and at[0] >= 0:
            self.first_step = now
        # memory and connections: once every actor is up (the sim's clock is there), and again once the sim is in its
        # second epoch (warmed up) if every actor is still there; a start that never gets so far keeps the most
        # actors it reached, read every 5 s
        up = at is not None and sum(role_of(pid) in ("agent", "sim") for pid in procs) >= self.expect
        if not self.complete and (up or now - self.probed > 5.0):
            self.probed = now
            snap = _snapshot(procs)
            if self.snapshot is None or _actors(snap) >= _actors(self.snapshot):
                self.snapshot = snap
            self.complete = up and _actors(snap) >= self.expect
        if at is not None and at[0] >= 1 and not self.settled:
            self.settled = True
            snap = _snapshot(procs)
            if _actors(snap) >= self.expect:
                self.snapshot = snap
        rows = _rows(leader_dir)
        if not self.rows_seen or rows > self.rows_seen[-1][1]:
            self.rows_seen.append((now, rows))
        if at is not None and at[0] >= 1 and not self.settled:  # the first epoch is over: warmed up
            self.settled = True
            later = _snapshot(procs)
            if self.snapshot is None or _actors(later) >= _actors(self.snapshot):
                self.snapshot = later
        if self.summary is None and (leader_dir / "summary.json").is_file():
            self.summary = now

    def cpu_near(self, t: float) -> int:
        return min(self.cpu_at, key=lambda c: abs(c[0] - t))[1]


def _rows(run_dir: Path) -> int:
    try:
        return sum(1 for line in (run_dir / "metrics.jsonl").read_text().splitlines() if line.strip())
    except OSError:
        return 0


def _actors(snap: dict[int, dict[str, Any]]) -> int:
    return sum(s["role"] in ("agent", "sim", "controller") for s in snap.values())


def _snapshot(procs: dict[int, int]) -> dict[int, dict[str, Any]]:
    tables: dict[str, dict[int, str]] = {}
    snap = {}
    for pid in procs:
        rss, pss = memory_mb(pid)
        est, listen = sockets(pid, tables)
        snap[pid] = {
            "role": role_of(pid),
            "rss_mb": rss,
            "pss_mb": pss,
            "tcp": est,
            "listen": listen,
            "zenoh": runs_zenoh(pid),
        }
    return snap


def available_mb() -> float:
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            return int(line.split()[1]) / 1024
    return float("inf")


def too_big(n: int, placement: str, rows: Sequence[dict[str, Any]]) -> str | None:
    """Why a `process` run of n agents would not fit in this machine's free memory, judged from the agents' PSS in
    the rows so far (twice it, for the start-up's peak and other users), or None."""
    if placement != "process":
        return None
    pss = [r["agent_pss_mb"] for r in rows if r["placement"] == "process" and r.get("agent_pss_mb")]
    if not pss:
        return None
    need, free = 2 * (n + 2) * max(pss), available_mb()
    return (
        None
        if need < free
        else f"skipped: needs ~{need / 1024:.1f} GB ({n + 2} x 2 x {max(pss):.0f} MB PSS), {free / 1024:.1f} GB free"
    )


def _stop(pids: Iterable[int], sig: signal.Signals) -> None:
    for pid in pids:
        try:
            os.kill(pid, sig)
        except ProcessLookupError:
            pass


def run_one(
    file: Path,
    n: int,
    placement: str,
    epochs: int,
    steps: int,
    seed: int,
    out: Path,
    guard_s: float,
    progress: Callable[[str], None],
) -> dict[str, Any]:
    """`kinswarm run FILE` on this host, watched from the command to its end."""
    expect = n + 1 if placement == "process" else 0
    argv = [*KINSWARM, "run", str(file), "--placement", placement, "--epochs", str(epochs), "--steps", str(steps),
            "--seed", str(seed), "--out", str(out), "--run-id", out.name, "--no-progress",
            "--set", "run.record=false"]  # fmt: skip  # record: motion.gif is minutes of drawing no column times
    log = out.parent / f"{out.name}.log"
    w = Watch(started=time.perf_counter(), expect=expect)
    with open(log, "wb") as f:
        p = subprocess.Popen(argv, stdout=f, stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL)
    clock = ClockReader(clock_path(out))
    status, rusage, guarded = None, None, False
    last_said = time.perf_counter()
    try:
        while status is None:
            pid, st, ru = os.wait4(p.pid, os.WNOHANG)
            if pid:
                status, rusage = st, ru
                break
            w.poll([p.pid], out, clock)
            if w.summary is not None and not any(role_of(q) in ("agent", "sim") for q in tree([p.pid])):
                # the summary is written and every actor has left: what the CLI does next is drawing the plots,
                # minutes on a loaded machine that no column times (and deaf to SIGTERM until it is done)
                _stop([p.pid], signal.SIGKILL)
                _, status, rusage = os.wait4(p.pid, 0)
                break
            time.sleep(POLL_S)
            now = time.perf_counter()
            if now - last_said > 15:
                last_said = now
                at = clock.read()
                progress(f"  ... {now - w.started:.0f} s, {len(w.seen)} processes so far, sim at {at}")
            if now - w.started > guard_s:  # a hang guard only: a run this slow is a row, not a stuck benchmark
                guarded = True
                _stop([p.pid], signal.SIGTERM)  # the supervisor stops its actors in order
                if not _waited(p.pid, 30.0):
                    _stop(tree([p.pid]), signal.SIGKILL)
                _, status, rusage = os.wait4(p.pid, 0)
    finally:
        clock.close()
        if status is None:  # interrupted: the supervisor stops its actors in order
            _stop([p.pid], signal.SIGTERM)
            os.wait4(p.pid, 0)
        p.returncode = 0 if status is None else os.waitstatus_to_exitcode(status)
        if w.summary is not None and p.returncode == -signal.SIGKILL:  # ended by us after its summary
            p.returncode = 0
    exit_s = time.perf_counter() - w.started
    # the actors run in sessions of their own: whatever outlived the supervisor is ended by its PID (checked to be
    # still this run's: a PID may have been reused)
    _stop([pid for pid in w.seen if pid != p.pid and _of_run(pid, out)], signal.SIGKILL)
    row = _measure(w, out, epochs, steps, exit_s)
    row["cpu_total_s"] = None if rusage is None else round(rusage.ru_utime + rusage.ru_stime, 2)
    row["result"] = _result(out, log, p.returncode, guarded, guard_s)
    return row


def _of_run(pid: int, out: Path) -> bool:
    try:
        return str(out).encode() in Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return False


def _waited(pid: int, timeout: float) -> bool:
    """Whether `pid` (our child) ended within `timeout` s (not reaped)."""
    end = time.monotonic() + timeout
    while time.monotonic() < end:
        try:
            r = os.waitid(os.P_PID, pid, os.WEXITED | os.WNOHANG | os.WNOWAIT)
        except ChildProcessError:
            return False
        if r is not None:
            return True
        time.sleep(0.1)
    return False


def _result(out: Path, log: Path, code: int, guarded: bool, guard_s: float) -> str:
    if guarded:
        return f"failed: no end within the hang guard ({guard_s:.0f} s)"
    try:
        summary = json.loads((out / "summary.json").read_text())
    except (OSError, ValueError):
        summary = {}
    if summary.get("error"):
        error = " ".join(str(summary["error"]).split())
        if (m := re.match(r"(not alive after [\d.]+ s): \[(.*)\]$", error)) is not None:  # say how many first
            error = f"{m.group(1)}, {m.group(2).count('(')} actors: [{m.group(2)}]"
        return "failed: " + error[:160]
    if code != 0 or not summary:
        tail = (
            [line for line in log.read_text(errors="replace").splitlines() if line.strip()][-1:] if log.exists() else []
        )
        return f"failed: exit code {code}" + (f": {tail[0][:160]}" if tail else "")
    return "ok"


def _cpu_per_step(steps_at: list[tuple[int, int, int]], steps: int) -> float | None:
    if not steps_at:
        return None
    glob = [(e * steps + k, ticks) for e, k, ticks in steps_at]
    last = max(g for g, _ in glob)
    end = next((g, t) for g, t in glob if g == last)
    later = [(g, t) for (e, _, _), (g, t) in zip(steps_at, glob, strict=True) if e >= 1 and g < last]
    start = later[0] if len(later) >= 2 and last - later[0][0] >= 20 else glob[0]
    if end[0] - start[0] < 10:
        return None
    return round(1000 * (end[1] - start[1]) / TICK / (end[0] - start[0]), 2)


def _measure(w: Watch, leader_dir: Path, epochs: int, steps: int, exit_s: float) -> dict[str, Any]:
    t0 = w.started
    rows = []
    try:
        rows = [json.loads(line) for line in (leader_dir / "metrics.jsonl").read_text().splitlines() if line.strip()]
    except (OSError, ValueError):
        pass
    row: dict[str, Any] = {"exit_s": round(exit_s, 2)}
    row["summary_s"] = None if w.summary is None else round(w.summary - t0, 2)
    first = w.first_step
    if first is None and rows and w.rows_seen and len(w.rows_seen) > 1:  # no clock (inprocess): epoch 0's end less it
        first = next(t for t, n in w.rows_seen if n >= 1) - float(rows[0]["seconds"])
    row["first_step_s"] = None if first is None else round(first - t0, 2)
    later = rows[1:] or rows
    row["steps_per_s"] = round(sum(r["steps"] for r in later) / sum(r["seconds"] for r in later), 1) if later else None
    # CPU a step: between two readings of the sim's clock, from the first of the epochs after the first (or, when
    # those went by too fast to be read twice, the first step) to the first reading of the last step
    row["cpu_ms_per_step"] = _cpu_per_step(w.steps_at, steps)
    grown = [(t, n) for t, n in w.rows_seen if n >= 1]
    if row["cpu_ms_per_step"] is None and len(grown) >= 2 and grown[-1][1] > grown[0][1]:
        # no clock (inprocess): from the moment epoch 0's row appeared to the moment the last one did
        (ta, na), (tb, nb) = grown[0], grown[-1]
        ticks = w.cpu_near(tb) - w.cpu_near(ta)
        row["cpu_ms_per_step"] = round(1000 * ticks / TICK / ((nb - na) * steps), 2)
    snap = w.snapshot or {}
    actors = {pid: s for pid, s in snap.items() if s["role"] in ("agent", "sim", "controller")}
    agents = [s for s in actors.values() if s["role"] == "agent"]
    sims = [s for s in actors.values() if s["role"] == "sim"]
    row["processes"] = len(w.seen)
    row["actors"] = len(actors)
    for who, group in (("agent", agents), ("sim", sims)):
        for k in ("rss_mb", "pss_mb"):
            vals = [s[k] for s in group if s[k] == s[k]]
            row[f"{who}_{k}"] = round(statistics.median(vals), 1) if vals else None
    row["sessions"] = sum(s["zenoh"] for s in snap.values()) if snap else None
    tcp = [s["tcp"] for s in snap.values()]
    row["tcp_total"] = sum(tcp) if snap else None
    row["tcp_per_process"] = round(sum(tcp) / len(tcp), 1) if tcp else None
    row["tcp_per_process_max"] = max(tcp) if tcp else None
    row["per_process"] = [{"pid": pid, **s} for pid, s in sorted(snap.items())]
    return row


def run_split(
    file: Path, n: int, epochs: int, steps: int, seed: int, base: Path, guard_s: float, progress: Callable[[str], None]
) -> dict[str, Any]:
    """The same robot over two network-namespace hosts: `kinswarm up` on each, the sim and a1 on brain (the
    leader), the other agents on limbs."""
    plan = base / "plan.toml"
    plan.write_text(
        f'[plan]\nname = "scale"\nleader = "brain"\n[run]\nfile = "{file}"\n'
        f'set = ["run.epochs={epochs}", "run.steps={steps}", "run.seed={seed}", "run.record=false"]\n'
        '[[host]]\nname = "brain"\naddress = "{brain}"\nactors = ["sim", "a1"]\n'
        '[[host]]\nname = "limbs"\naddress = "{limbs}"\nactors = ["agents"]\n'
    )
    with Hosts(["brain", "limbs"], tag="sc") as h:
        plan.write_text(plan.read_text().replace("{brain}", h.address("brain")).replace("{limbs}", h.address("limbs")))
        w = Watch(started=time.perf_counter(), expect=n + 1)
        limbs = h.spawn("limbs", [*KINSWARM, "up", str(plan), "--host", "limbs", "--out", str(base / "limbs")],
                        base / "l.log")  # fmt: skip
        leader = h.spawn("brain", [*KINSWARM, "up", str(plan), "--host", "brain", "--out", str(base / "brain"),
                                   "--no-progress"], base / "b.log")  # fmt: skip
        clock = ClockReader(clock_path(base / "brain"))
        guarded = False
        last_said = time.perf_counter()
        try:
            while leader.poll() is None:
                w.poll([leader.pid, limbs.pid], base / "brain", clock)
                live = tree([leader.pid, limbs.pid])
                if w.summary is not None and not any(role_of(pid) in ("agent", "sim") for pid in live):
                    leader.send_signal(signal.SIGKILL)  # as run_one: the plots it would draw next are not timed
                    leader.wait()
                    break
                time.sleep(POLL_S)
                now = time.perf_counter()
                if now - last_said > 15:
                    last_said = now
                    progress(f"  ... {now - w.started:.0f} s, {len(w.seen)} processes so far, sim at {clock.read()}")
                if now - w.started > guard_s:
                    guarded = True
                    break
            exit_s = time.perf_counter() - w.started
        finally:
            clock.close()
        # limbs stops its share by itself on the leader's Stop; Hosts' exit ends whatever did not
        end = time.monotonic() + 30
        while limbs.poll() is None and time.monotonic() < end:
            time.sleep(0.1)
    row = _measure(w, base / "brain", epochs, steps, exit_s)
    row["cpu_total_s"] = round(sum(w.seen.values()) / TICK, 2)  # the last reading of every process: a lower bound
    code = 0 if w.summary is not None and leader.returncode == -signal.SIGKILL else leader.returncode or 0
    row["result"] = _result(base / "brain", base / "b.log", code, guarded, guard_s)
    return row


# -- the table -----------------------------------------------------------------------------------------------------
def _f(v: Any, digits: int = 1) -> str:
    if v is None:
        return "—"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


def _short(result: str) -> str:
    """A failure in a table cell: without the list of the actors not alive, or the log's time stamps (the JSON keeps
    both)."""
    head, _, log = result.partition("; its log ends: ")
    why = re.search(r"(\w+Error: [^:\[]+)", log)
    return head.split(": [", 1)[0] + (f" ({why.group(1).strip()})" if why else "")


def table(rows: Sequence[dict[str, Any]]) -> str:
    """Markdown: one line per (N, topology, placement), medians over repeats; a configuration that failed in any
    repeat says so in `result`."""
    groups: dict[tuple[int, str, str], list[dict[str, Any]]] = {}
    for r in rows:
        groups.setdefault(
            (r["n"], r["topology"], r["placement"] + (" (2 hosts)" if r["hosts"] == 2 else "")), []
        ).append(r)
    lines = ["| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    for (n, topo, placement), rs in sorted(groups.items(), key=lambda kv: (kv[0][1], kv[0][0], kv[0][2])):
        ok = [r for r in rs if r["result"] == "ok"]

        def med(key: str, rs: list[dict[str, Any]] = ok) -> float | None:
            vals = [r[key] for r in rs if r.get(key) is not None]
            return statistics.median(vals) if vals else None

        failed = [_short(r["result"]) for r in rs if r["result"] != "ok"]
        result = "ok" if not failed else (f"{len(ok)}/{len(rs)} ok; " if ok else "") + failed[0]
        cells = [n, topo, placement, rs[0]["depth"], _f(med("processes", rs)), _f(med("first_step_s", rs)),
                 _f(med("summary_s")), _f(med("steps_per_s"), 0), _f(med("cpu_ms_per_step"), 2),
                 _f(med("agent_rss_mb", rs)), _f(med("agent_pss_mb", rs)), _f(med("sim_rss_mb", rs)),
                 _f(med("sim_pss_mb", rs)), _f(med("sessions", rs), 0), _f(med("tcp_total", rs), 0),
                 _f(med("tcp_per_process", rs)), result]  # fmt: skip
        lines.append("| " + " | ".join(str(c) for c in cells) + " |")
    return "\n".join(lines)


GROWTH = {"first_step_s": "first step s", "summary_s": "summary s", "steps_per_s": "steps/s",
          "cpu_ms_per_step": "CPU-ms/step", "agent_pss_mb": "agent PSS MB", "tcp_total": "TCP"}  # fmt: skip


def growth(rows: Sequence[dict[str, Any]]) -> dict[str, dict[str, dict[str, float]]]:
    """How each cost grows with N, per topology and placement (one host): the exponent k of a least-squares fit of
    log(cost) on log(N) over the sizes that ran (medians over repeats), and 2^k, its factor per doubling."""
    import numpy as np

    out: dict[str, dict[str, dict[str, float]]] = {}
    keys = sorted({(r["topology"], r["placement"]) for r in rows if r["hosts"] == 1})
    for topo, placement in keys:
        ok = [r for r in rows if (r["topology"], r["placement"], r["hosts"], r["result"]) == (topo, placement, 1, "ok")]
        fits: dict[str, dict[str, float]] = {}
        for key in GROWTH:
            by_n: dict[int, list[float]] = {}
            for r in ok:
                if r.get(key):
                    by_n.setdefault(r["n"], []).append(float(r[key]))
            if len(by_n) >= 2:
                ns = sorted(by_n)
                k = float(np.polyfit(np.log(ns), np.log([statistics.median(by_n[n]) for n in ns]), 1)[0])
                fits[key] = {"exponent": round(k, 2), "per_doubling": round(2**k, 2), "from_n": ns[0], "to_n": ns[-1]}
        if fits:
            out[f"{topo}/{placement}"] = fits
    return out


def growth_table(fits: dict[str, dict[str, dict[str, float]]]) -> str:
    head = ["topology/placement", *(f"{v} (x per doubling, N^k)" for v in GROWTH.values())]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]
    for name, f in fits.items():
        cells = [f"{f[k]['per_doubling']:.2f} (k {f[k]['exponent']:.2f})" if k in f else "—" for k in GROWTH]
        lines.append("| " + " | ".join([name, *cells]) + " |")
    return "\n".join(lines)


def figure(rows: Sequence[dict[str, Any]], path: Path, title: str) -> None:
    """The cost curve: start-up, steps/s, CPU-ms a step, the agents' memory and the TCP connections against N (log-log;
    medians over repeats), a line per topology and placement; failed sizes left out (the table names them)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    panels = (("first_step_s", "command to first step (s)"), ("steps_per_s", "steps/s"),
              ("cpu_ms_per_step", "CPU-ms a step, all processes"), ("agent_pss_mb", "agent PSS, median (MB)"),
              ("tcp_total", "TCP connections, all processes"))  # fmt: skip
    fig, axes = plt.subplots(1, len(panels), figsize=(4.0 * len(panels), 3.6))
    style = {"process": "o-", "single": "s--", "inprocess": "^:"}
    colour = {"chain": "C0", "tree": "C1"}
    groups = sorted({(r["topology"], r["placement"], r["hosts"]) for r in rows})
    all_n = sorted({r["n"] for r in rows})
    for ax, (key, label) in zip(axes, panels, strict=True):
        for topo, placement, hosts in groups:
            by_n: dict[int, list[float]] = {}
            for r in rows:
                if (r["topology"], r["placement"], r["hosts"]) == (topo, placement, hosts) and r["result"] == "ok":
                    if r.get(key):
                        by_n.setdefault(r["n"], []).append(float(r[key]))
            if not by_n:
                continue
            ns = sorted(by_n)
            name = f"{topo}, {placement}" + (", 2 hosts" if hosts == 2 else "")
            fmt = "D" if hosts == 2 else style.get(placement, "o-")
            ax.plot(ns, [statistics.median(by_n[n]) for n in ns], fmt, color=colour.get(topo), label=name, ms=4)
        if key == "tcp_total":  # a failed start's last reading: open markers
            for topo in sorted({r["topology"] for r in rows}):
                bad = [r for r in rows if r["topology"] == topo and r["result"] != "ok" and r.get("tcp_total")]
                if bad:
                    ax.plot([r["n"] for r in bad], [r["tcp_total"] for r in bad], "o", mfc="none",
                            color=colour.get(topo), label=f"{topo}: a failed start's last reading")  # fmt: skip
        if key == "tcp_total" and all_n:  # the shapes to tell apart: a full mesh of N + 2 peers, and a star
            ax.plot(all_n, [(n + 2) * (n + 1) for n in all_n], color="grey", lw=0.8, label="(N+2)(N+1): full mesh")
            ax.plot(all_n, [2 * (n + 1) for n in all_n], color="grey", lw=0.8, ls="--", label="2(N+1): a star")
        ax.set_xscale("log", base=2)
        ax.set_yscale("log")
        ax.set_xticks(all_n, [str(n) for n in all_n])
        ax.set_xlabel("joints N")
        ax.set_title(label, fontsize=9)
    axes[0].legend(fontsize=6)
    axes[-1].legend(fontsize=6)
    fig.suptitle(title, fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _csv(kind: Callable[[str], Any], what: str) -> Callable[[str], list[Any]]:
    def parse(s: str) -> list[Any]:
        try:
            return [kind(x) for x in s.split(",") if x.strip()]
        except ValueError:
            raise argparse.ArgumentTypeError(f"expected a comma-separated list of {what}, got {s!r}") from None

    return parse


def save(a: argparse.Namespace, argv: list[str] | None, rows: list[dict[str, Any]], skipped: str) -> None:
    """The JSON, rewritten after every row: a benchmark stopped half-way keeps what it measured."""
    doc = {
        "command": "python benchmarks/scale.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "columns": list(COLUMNS),
        "machine": {"cores": os.cpu_count(), "python": platform.python_version(), "kernel": platform.release()},
        "epochs": a.epochs,
        "steps": a.steps,
        "repeats": a.repeats,
        "load_end": list(os.getloadavg()),
        "skipped": skipped,
        "growth": growth(rows),
        "rows": [{k: r.get(k) for k in ROW_KEYS} for r in rows],
    }
    a.json.write_text(json.dumps(doc, indent=1) + "\n")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--n", type=_csv(int, "joint counts"), default=[4, 8, 16, 32, 64], help="default 4,8,16,32,64")
    p.add_argument("--topologies", type=_csv(str, "topologies"), default=list(SHAPES), help="chain,tree")
    p.add_argument("--placements", type=_csv(str, "placements"), default=list(PLACEMENTS), help=",".join(PLACEMENTS))
    p.add_argument("--hosts-n", type=_csv(int, "joint counts"), default=[8],
                   help="N of the two-host rows (process placement); '' for none (default 8)")  # fmt: skip
    p.add_argument("--repeats", type=int, default=1)
    p.add_argument("--epochs", type=int, default=3, help="epochs a run (the first is dropped as warm-up; default 3)")
    p.add_argument("--steps", type=int, default=200, help="steps an epoch (default 200)")
    p.add_argument("--guard", type=float, default=900.0, help="hang guard: seconds before a run is ended (900)")
    p.add_argument("--json", type=Path, default=Path("scale.json"))
    p.add_argument("--figure", type=Path, default=None, help="also draw the cost curve to this PNG")
    p.add_argument("--resume", action="store_true", help="keep the rows already in --json, run the others")
    p.add_argument("--replot", type=Path, default=None, metavar="JSON",
                   help="run nothing: print the table and growth of a JSON this wrote, and draw --figure")  # fmt: skip
    a = p.parse_args(argv)
    if a.replot is not None:
        try:
            old = json.loads(a.replot.read_text())
            rows = old["rows"]
        except (OSError, ValueError, KeyError) as e:
            p.error(f"--replot {a.replot}: not a JSON this benchmark wrote ({e})")
        print(table(rows))
        print(growth_table(growth(rows)))
        if a.figure is not None:
            figure(rows, a.figure, old.get("command", ""))
        return 0
    bad = [t for t in a.topologies if t not in SHAPES] + [x for x in a.placements if x not in PLACEMENTS]
    if bad:
        p.error(f"unknown topology or placement {bad[0]!r}: topologies {', '.join(SHAPES)}; placements "
                f"{', '.join(PLACEMENTS)}")  # fmt: skip
    if any(n < 1 for n in [*a.n, *a.hosts_n]) or a.repeats < 1 or a.epochs < 2 or a.steps < 1:
        p.error("--n, --hosts-n >= 1, --repeats >= 1, --epochs >= 2 (the first is a warm-up), --steps >= 1")

    def say(msg: str) -> None:
        print(msg, file=sys.stderr, flush=True)

    # the subject first (process placement on one host, then over two), the controls after: a benchmark stopped
    # half-way on a busy machine has measured what matters most
    first = [pl for pl in PLACEMENTS if pl in a.placements]
    plan = [(n, t, "process", 1) for n in a.n for t in a.topologies] if "process" in first else []
    plan += [(n, t, "process", 2) for n in a.hosts_n for t in a.topologies]
    plan += [(n, t, pl, 1) for pl in first if pl != "process" for n in a.n for t in a.topologies]
    rows: list[dict[str, Any]] = []
    if a.resume and a.json.is_file():  # the rows a stopped benchmark measured stay; their configurations are skipped
        rows = json.loads(a.json.read_text())["rows"]
    done = {(r["n"], r["topology"], r["placement"], r["hosts"], r["repeat"]) for r in rows}
    skipped = ""
    t_start = time.perf_counter()
    with tempfile.TemporaryDirectory(prefix="kinswarm-scale-") as d:
        tmp = Path(d)
        for rep in range(a.repeats):  # repeats outermost: drift on a shared machine hits every row alike
            for i, (n, topo, placement, hosts) in enumerate(plan):
                if (hosts == 2 and skipped) or (n, topo, placement, hosts, rep) in done:
                    continue
                file = run_file(topo, n, tmp / "files" / f"{topo}{n}.toml")
                out = tmp / f"{topo}{n}-{placement}-h{hosts}-r{rep}"
                load = os.getloadavg()
                say(f"[{rep * len(plan) + i + 1}/{a.repeats * len(plan)}] {topo} N={n} {placement}"
                    f"{' over 2 hosts' if hosts == 2 else ''}, repeat {rep + 1} (load {load[0]:.1f}; "
                    f"{time.perf_counter() - t_start:.0f} s in)")  # fmt: skip
                head = {"n": n, "topology": topo, "placement": placement, "hosts": hosts, "repeat": rep,
                        "depth": depth(topo, n), "load": [round(x, 2) for x in load]}  # fmt: skip
                if (why := too_big(n, placement, rows)) is not None:
                    say(f"  -> {why}")
                    rows.append({**head, "result": why})
                    save(a, argv, rows, skipped)
                    continue
                if hosts == 2:
                    try:
                        out.mkdir(parents=True)
                        row = run_split(file, n, a.epochs, a.steps, rep, out, a.guard, say)
                    except NetnsUnavailable as e:
                        skipped = f"two-host rows skipped: no network namespaces here ({e})"
                        say(skipped)
                        continue
                else:
                    out.parent.mkdir(parents=True, exist_ok=True)
                    row = run_one(file, n, placement, a.epochs, a.steps, rep, out, a.guard, say)
                row = {**head, **row}
                rows.append(row)
                save(a, argv, rows, skipped)
                say(f"  -> {row['result']}: first step {_f(row['first_step_s'])} s, summary {_f(row['summary_s'])} s, "
                    f"{_f(row['steps_per_s'], 0)} steps/s, {_f(row['cpu_ms_per_step'], 2)} CPU-ms/step, "
                    f"{row['processes']} processes, TCP {row['tcp_total']}")  # fmt: skip
    load_end = os.getloadavg()
    print(f"kinswarm scale: {a.epochs} epochs x {a.steps} steps a run, {a.repeats} repeat(s) (medians); "
          f"{os.cpu_count()} cores; load {', '.join(f'{x:.1f}' for x in load_end)} at the end")  # fmt: skip
    print(table(rows))
    print(growth_table(growth(rows)))
    if skipped:
        print(skipped)
    save(a, argv, rows, skipped)
    if a.figure is not None:
        figure(rows, a.figure, "python benchmarks/scale.py " + " ".join(argv if argv is not None else sys.argv[1:]))
    print(f"JSON: {a.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
