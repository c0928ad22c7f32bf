"""The chaos soak: a process-placement swarm learning for a given time while a seeded schedule breaks it in every way
at once, then the invariants a user counts on, checked from what the run left behind.

    python benchmarks/chaos.py --minutes 60                 # the hour (a line a minute says it is alive)
    python benchmarks/chaos.py --quick                      # about a minute: every kind at least once
    python benchmarks/chaos.py --minutes 10 --every 3 --kinds kill,freeze --seed 1
    python benchmarks/chaos.py --hosts --minutes 15         # split over two hosts, the cut between them a fault too

Both runs (fault-free, then chaos, same seed and settings) are `kinswarm run` child processes. Faults go in as a user
sends them: the first of each kind through `kinswarm fault RUN ...` itself, the others through the same client
(kinswarm.actors.control.client.Client: one request, one reply, as `kinswarm fault` does). At random times (exponential,
mean --every seconds) and overlapping, on random agents and joints:

- process: kill, freeze (0.3-3 s), restart;
- the robot's model: lock, reverse, scale, deadzone, offset, lag, disturb (each freed again after 1-8 s);
- messages: drop, delay, duplicate, corrupt on an agent's links (or all), for 1-6 s;
- crash: the whole run dies at once (SIGKILL to the supervisor, the simulator and every agent: a power cut), and
  goes on with `kinswarm run --resume`. (A simulator killed alone ends its run by design, docs/faults.md.)

With --hosts the swarm is split over two hosts (network namespaces on a bridge, root needed: the sim and a1 on
`brain`, the leader; a2-a4 on `limbs`; `kinswarm up` with one plan on each), faults go in from the leader's host
(`kinswarm fault` and the client run inside its namespace), and one more kind joins the schedule: cut, limbs' link
down for 1-6 s, then mended. Kinds a split run cannot take are left out, the reason printed (benchmarks/chaos_hosts.py).


The last --settle + --tail epochs get no new fault (everything is freed and cleared as they start); the last --tail
of them measure the swarm's recovery. The settle epochs let an agent killed in the last faulty epoch come back first:
it restores its newest checkpoint, and its parent stands in meanwhile (quick mode: 2; its tail is only 4 epochs).
Exit code 1 when an invariant fails; the table says which.
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import json
import math
import os
import random
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "benchmarks"))
import chaos_hosts  # noqa: E402
import chaos_picture  # noqa: E402
from chaos_hosts import Control, Cut  # noqa: E402

CLI = [sys.executable, "-m", "kinswarm.actors.cli"]
AGENTS = ("a1", "a2", "a3", "a4")
PROCESS = ("kill", "freeze", "restart")
MODEL = ("lock", "reverse", "scale", "deadzone", "offset", "lag", "disturb")
LINK = ("drop", "delay", "duplicate", "corrupt")
KINDS = (*PROCESS, *MODEL, *LINK, "crash")
# quick mode: a fault-free epoch of 150 steps on a quiet 2-core machine; a slower machine (its fault-free run's
# median epoch) stretches the schedule's seconds by as much, so that it gets as many faults a step as a quiet one
QUICK_EPOCH_S = 0.5
SPLIT = ("cut",)  # only with --hosts
START_S = 60.0  # an actor not alive this long after its start is given up on (actors/supervisor/core.py)
EPOCH_S_PER_STEP = 0.008  # process placement, chain4, 2-core machine, under chaos (0.009 --beside): sizes --minutes
SPLIT_S_PER_STEP = 0.011  # the same split over two hosts: through the hosts' routers, ~0.74 the rate (docs/deploy.md)
# events the supervisor records itself (at the sim's clock): in file order they never go back, but at a resume
SUPERVISOR = {"fault", "refused", "exited", "restart", "lost", "alive", "thaw", "restored", "stall", "stall_end"}


@dataclass
class Injected:
    kind: str
    target: str
    params: dict[str, float]
    describe: str
    t: float  # seconds since the chaos run started
    via_cli: bool


@dataclass
class Chaos:
    a: argparse.Namespace
    out: Path
    rng: random.Random
    log: Path
    proc: subprocess.Popen | None = None
    injected: list[Injected] = field(default_factory=list)
    refused: list[str] = field(default_factory=list)
    undelivered: Counter = field(default_factory=Counter)
    # pid -> its start time: over an hour the system gives a dead actor's PID to another process (pid_max 32768)
    pids: dict[int, int] = field(default_factory=dict)
    crashes: int = 0
    resumes: int = 0
    exit_codes: list[int] = field(default_factory=list)
    order: list[str] = field(default_factory=list)
    last_crash: float = -math.inf
    control: Any = None  # chaos_hosts.Control, or with --hosts its RemoteControl in the leader's namespace
    split: chaos_hosts.Split | None = None  # --hosts: the run's two hosts
    cuts: list[Cut] = field(default_factory=list)
    cut_open: Cut | None = None
    last_mend: float = -math.inf
    ended: float = math.inf  # wall clock: when the chaos run's (last) process ended
    pace: float = 1.0  # the schedule's seconds stretched by this (quick mode on a slow machine)
    wall: float = 0.0  # seconds the chaos ran
    free: subprocess.Popen | None = None  # the fault-free run

    def __post_init__(self) -> None:
        if self.control is None:
            self.control = Control(self.out)

    # -- the run -------------------------------------------------------------------------------------------
    def argv(self, run_id: str, out: Path) -> list[str]:
        a = self.a
        argv = [*CLI, "run", str(ROOT / "examples" / "chain4.toml"), "--epochs", str(a.epochs), "--steps", str(a.steps)]
        argv += ["--seed", str(a.seed), "--placement", "process", "--run-id", run_id, "--out", str(out)]
        return argv + ["--deadline-ms", str(a.deadline_ms), "--no-progress"]

    def start(self, argv: list[str]) -> None:
        with open(self.log, "a") as f:
            self.proc = subprocess.Popen(argv, stdout=f, stderr=subprocess.STDOUT, start_new_session=True)
        self.note({self.proc.pid})

    def launch(self) -> None:
        """The chaos run: one `kinswarm run`, or with --hosts `kinswarm up` on both hosts."""
        a = self.a
        if self.split is None:
            self.start(self.argv(a.run_id, self.out))
            return
        leader = ["--run-id", a.run_id, "--deadline-ms", str(a.deadline_ms)]
        self.proc = self.split.start(self.out.parent, a.epochs, a.steps, a.seed, leader)
        self.note({p.pid for p in self.split.hosts.procs})

    def epochs_done(self) -> int:
        path = self.out / "metrics.jsonl"
        return len(path.read_text().splitlines()) if path.exists() else 0

    # -- faults ------------------------------------------------------------------------------------------
    def next_kind(self) -> str:
        if not self.order:  # every kind once, in a shuffled order, then again: none is left out for long
            self.order = list(self.a.kinds)
            self.rng.shuffle(self.order)
        return self.order.pop()

    def draw(self, kind: str) -> tuple[str, dict[str, float], float]:
        """(target, parameters, seconds until it is undone by us: 0 for none)."""
        r, x = self.rng, self.pace
        target = r.choice(AGENTS)
        if kind == "freeze":
            return target, {"seconds": round(x * r.uniform(0.3, 3.0), 2)}, 0.0
        if kind in PROCESS:
            return target, {}, 0.0
        if kind in MODEL:
            params = {
                "scale": {"factor": round(r.uniform(0.3, 3.0), 2)},
                "deadzone": {"degrees": round(r.uniform(0.1, 1.0), 2)},
                "offset": {"degrees": round(r.uniform(-8.0, 8.0), 2)},
                "lag": {"steps": float(r.randint(1, 8))},
                "disturb": {"steps": float(r.randint(20, 300))},
            }.get(kind, {})
            return target, params, (0.0 if kind == "disturb" else round(x * r.uniform(1.0, 8.0), 2))
        if r.random() < 0.2:
            target = "all"
        seconds = round(x * r.uniform(1.0, 6.0), 2)
        if kind == "delay":
            return target, {"ms": float(r.randint(5, 60)), "seconds": seconds}, 0.0
        return target, {"rate": round(r.uniform(0.02, 0.2), 3), "seconds": seconds}, 0.0

    def send(self, kind: str, target: str, params: dict[str, float], via_cli: bool) -> tuple[bool, str]:
        """(delivered, the supervisor's error or ''); a run between its crash and its resume is not reached."""
        if via_cli:
            where = ["ip", "netns", "exec", self.split.hosts.ns("brain")] if self.split else []
            args = [*where, *CLI, "fault", self.a.run_id, kind, target, "--run-dir", str(self.out)]
            for name, value in params.items():
                flag = {"seconds": "--for"}.get(name, "--" + name)
                args += [flag, f"{value:g}s" if name == "seconds" else f"{value:g}"]
            r = subprocess.run(args, capture_output=True, text=True, timeout=60)
            if r.returncode == 0:
                return True, ""
            said = (r.stdout + r.stderr).strip().splitlines()
            line = said[-1] if said else f"exit {r.returncode}"
            return ("cannot reach" not in line and "did not answer" not in line and "no supervisor" not in line), line
        return self.control.fault(kind, target, params)

    def close_client(self) -> None:
        self.control.close()

    def note(self, pids: set[int]) -> None:
        """Remember processes of the run, each with its start time (one gone already cannot be left running)."""
        for pid in pids:
            if pid not in self.pids and (st := _stat(pid)) is not None:
                self.pids[pid] = st[1]

    def status_pids(self) -> dict[str, int]:
        return self.control.pids()

    def crash(self) -> bool:
        """A power cut: the supervisor, the simulator and every agent SIGKILLed at once; then `--resume`."""
        assert self.proc is not None
        pids = {p for p in self.status_pids().values() if p > 0}
        if not pids:
            return False
        self.note(pids)
        with contextlib.suppress(ProcessLookupError):  # its process group: the run and what it spawned
            os.killpg(self.proc.pid, signal.SIGKILL)
        for pid in pids:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        self.close_client()
        self.exit_codes.append(self.proc.wait())
        for pid in pids:  # gone before the resume takes the run's lock
            while _alive(pid):
                time.sleep(0.01)
        self.crashes += 1
        self.start([*CLI, "run", "--resume", str(self.out), "--no-progress"])
        self.resumes += 1
        return True

    def ready(self, kind: str, now: float) -> bool:
        if kind == "crash":  # a crash sets the run back to its last checkpoint and costs a restart of everything:
            return now - self.last_crash >= self.a.crash_gap  # spaced, or the run would spend its time starting again
        if kind == "cut":  # one at a time, apart: each partition and rejoin in events.jsonl belongs to one cut
            return self.cut_open is None and now - self.last_mend >= chaos_hosts.CUT_GAP_S
        return True

    def cut(self, now: float, undo: list[tuple[float, str, str]]) -> None:
        """limbs' link down (its cable pulled), mended after a drawn time."""
        assert self.split is not None
        seconds = round(self.rng.uniform(*chaos_hosts.CUT_S), 2)
        self.split.hosts.cut("limbs")
        self.cut_open = Cut(time.time(), seconds)
        self.injected.append(Injected("cut", "limbs", {"seconds": seconds}, f"cut limbs {seconds:g}s", now, False))
        undo.append((now + seconds, "mend", "limbs"))

    def mend(self, now: float) -> None:
        if self.cut_open is not None and self.split is not None:
            self.split.hosts.mend("limbs")
            self.cut_open.mended = time.time()
            self.cuts.append(self.cut_open)
            self.cut_open, self.last_mend = None, now

    def inject(self, now: float, undo: list[tuple[float, str, str]]) -> None:
        kind = self.next_kind()
        if not self.ready(kind, now):
            if len(set(self.a.kinds)) == 1 and kind == "cut":
                self.order.append(kind)  # nothing else to send meanwhile
                return
            if len(set(self.a.kinds)) > 1:
                held = kind
                self.order.insert(0, kind)
                while kind == held:
                    kind = self.next_kind()
        if kind in PROCESS and self.epochs_done() >= self.a.process_until:
            return  # restarted agents must be back before the measured tail begins: this tick goes without a fault
        if kind == "cut":
            self.cut(now, undo)
            return
        if kind == "crash":
            if not self.crash():
                self.order.append(kind)  # not up yet: later
                self.undelivered[kind] += 1
            else:
                self.last_crash = now
                self.injected.append(Injected(kind, "swarm", {}, "crash", now, False))
            return
        target, params, undo_after = self.draw(kind)
        first = len(self.injected) % 20 == 0  # the first, and one in twenty, as typed: `kinswarm fault ...`
        ok, error = self.send(kind, target, params, via_cli=first)
        if not ok or "not training" in error:  # not reached, or not up yet (a resume under way): it comes again
            self.order.append(kind)
            self.undelivered[kind] += 1
            return
        if error:
            self.refused.append(f"{kind} {target}: {error}")
            return
        from kinswarm.actors.control.client import make_fault
        from kinswarm.protocol.faults import describe

        f = make_fault(kind, [target], **{k: (int(v) if k == "steps" else v) for k, v in params.items()})
        self.injected.append(Injected(kind, target, params, describe(f), now, first))
        if undo_after:
            undo.append((now + undo_after, "free", target))

    def soak(self) -> float:
        """The chaos run, faults injected until its tail; returns its wall seconds."""
        a = self.a
        t0 = time.monotonic()
        self.launch()
        undo: list[tuple[float, str, str]] = []
        next_at, next_line, quiet = t0 + a.warmup, t0 + 60.0, False
        while True:
            assert self.proc is not None
            if self.proc.poll() is not None:
                self.ended = time.time()
                self.exit_codes.append(self.proc.returncode)
                self.mend(time.monotonic() - t0)
                self.control.shutdown()
                break
            now = time.monotonic()
            if now >= next_line:
                done = Counter(i.kind for i in self.injected)
                print(
                    f"chaos: {(now - t0) / 60:.0f} min, epoch {self.epochs_done()}/{a.epochs}, "
                    f"{len(self.injected)} faults ({', '.join(f'{k} {n}' for k, n in sorted(done.items()))}), "
                    f"{self.crashes} crashes",
                    flush=True,
                )
                next_line += 60.0
            for due, what, target in [u for u in undo if u[0] <= now - t0]:  # inject() dates them from t0
                undo.remove((due, what, target))
                if what == "mend":
                    self.mend(now - t0)
                else:
                    self.send(what, target, {}, via_cli=False)
            if not quiet and self.epochs_done() >= a.epochs - a.tail - a.settle:
                quiet = True  # the tail: the swarm left to recover
                self.mend(now - t0)
                for what in ("free", "clear"):
                    self.send(what, "all", {}, via_cli=False)
                undo.clear()
            if not quiet and now >= next_at and self.epochs_done() >= 1:
                if len(self.injected) % 5 == 0:  # the actors' PIDs, for "nothing left running"
                    self.note({p for p in self.status_pids().values() if p > 0})
                self.inject(now - t0, undo)
                next_at = max(next_at + self.rng.expovariate(1.0 / a.every), time.monotonic() - a.every)
            time.sleep(0.05)
        return time.monotonic() - t0


def _stat(pid: int) -> tuple[str, int] | None:
    """(state, start time in clock ticks since boot) of a process, None when there is none."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except OSError:
        return None
    return fields[0], int(fields[19])


def _alive(pid: int, start: int | None = None) -> bool:
    """Running (not a zombie), and the same process as the one seen at `start` when given."""
    st = _stat(pid)
    return st is not None and st[0] != "Z" and (start is None or st[1] == start)


def _rows(path: Path) -> list[dict[str, Any]]:
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()] if path.exists() else []


def share(metrics: list[dict[str, Any]], tail: int) -> float:
    last = [r["final_error"] for r in metrics[-tail:]]
    return sum(e <= 0.5 for e in last) / len(last) if last else 0.0


# -- the invariants ---------------------------------------------------------------------------------------------
def segments(events: list[dict[str, Any]]) -> list[list[dict[str, Any]]]:
    """The events of each supervisor's life (a resume starts a new one; its clock `t` starts again)."""
    out: list[list[dict[str, Any]]] = [[]]
    for e in events:
        if e["event"] == "resume" and e["target"] == "swarm":  # not the sim's own resume after a host's cut
            out.append([])
        out[-1].append(e)
    return out


NEAR = 25  # steps: a request and its effect further apart are drawn as two commands (actors/report/timeline.py)


def effects(events: list[dict[str, Any]], injected: list[Injected], steps: int) -> tuple[list[str], list[tuple]]:
    """Each fault sent matched with its `fault` event (the request, at the step it went out): the names of those
    never recorded, and for each joint fault (what, request's step, its effect's step or None), the effect being the
    sim's own event (exact) nearest the request within NEAR steps. Steps count across epochs: an epoch's last step
    (`steps`) is where the next one starts (its step 0), so a fault sent as an epoch ends acts at the next one's."""
    faults = [e for e in events if e["event"] == "fault"]
    missing, pairs = [], []
    for i in injected:
        if i.kind in ("crash", "cut"):  # the whole run's, not a supervisor's
            continue
        match = next((e for e in faults if e["detail"].startswith(i.describe)), None)
        if match is None:
            missing.append(i.describe)
            continue
        faults.remove(match)
        if i.kind in MODEL:
            targets = AGENTS if i.target == "all" else (i.target,)
            asked = match["epoch"] * steps + match["step"]
            near = [
                at
                for e in events
                if e["event"] == i.kind and e["target"] in targets
                and abs((at := e["epoch"] * steps + e["step"]) - asked) <= NEAR
            ]  # fmt: skip
            done = min(near, key=lambda at: abs(at - asked)) if near else None
            pairs.append((f"{i.describe} at {match['epoch']}/{match['step']}", asked, done))
    return missing, pairs


def check_faults_at_steps(events: list[dict[str, Any]], injected: list[Injected], steps: int) -> tuple[bool, str]:
    """Every fault sent is a `fault` event at a real (epoch, step), stamped where it went out: never after its effect
    (the sim's own event, exact), which is no further than a plot draws as one command; the supervisor's own events
    never go back in (epoch, step) but at a resume."""
    from kinswarm.actors.report.timeline import one_per_command

    unplaced = [e for e in events if not (e["epoch"] >= 0 and 0 <= e["step"] <= steps)]
    missing, pairs = effects(events, injected, steps)
    lost = [what for what, _, done in pairs if done is None]
    early = [what for what, asked, done in pairs if done is not None and done < asked]
    backwards = []
    for seg in segments(events):
        last = (-1, -1)
        for e in seg:
            if e["event"] in SUPERVISOR:
                at = (e["epoch"], e["step"])
                if at < last:
                    backwards.append(f"{e['event']} {e['target']} at {at} after {last}")
                last = max(last, at)
    lines = len(one_per_command(events))
    ok = not (unplaced or missing or lost or early or backwards)
    sent = sum(i.kind not in ("crash", "cut") for i in injected)
    detail = f"{sent} faults, {len(events)} events ({lines} plotted)"
    for name, bad in (("unplaced", unplaced), ("missing", missing), (f"no effect within {NEAR} steps", lost),
                      ("stamped after its effect", early), ("going back", backwards)):  # fmt: skip
        if bad:
            detail += f"; {name}: {len(bad)} ({bad[0]})"
    return ok, detail


def fault_lags(events: list[dict[str, Any]], injected: list[Injected], steps: int) -> str:
    """How soon each joint fault acted: steps from its request (the supervisor's put) to its effect (the sim applies
    it on Zenoh's thread as it arrives). A measurement, not an invariant: on a saturated machine a delivery can wait
    for a core (a restarting agent's start-up beside two swarms on two cores took 3 steps)."""
    _, pairs = effects(events, injected, steps)
    lags = Counter(done - asked for _, asked, done in pairs if done is not None)
    slowest = max(pairs, key=lambda p: -1 if p[2] is None else p[2] - p[1], default=None)
    text = ", ".join(f"{n} after {lag}" for lag, n in sorted(lags.items())) or "no joint fault"
    if slowest is not None and slowest[2] is not None and slowest[2] > slowest[1]:
        text += f" (the slowest: {slowest[0]})"
    return text


def unanswered(events: list[dict[str, Any]], ended: float = math.inf) -> tuple[int, int]:
    """(restarts after which their agent neither said what it restored nor exited again (killed or restarted while
    it was starting: that process restored nothing), of those the ones still starting when the run ended at wall
    clock `ended`: less than START_S before it). A resume starts every agent anew."""
    pending: dict[str, list[float]] = {}
    for e in events:
        if e["event"] == "resume" and e["target"] == "swarm":
            pending.clear()
        elif e["event"] == "restart":
            pending.setdefault(e["target"], []).append(e.get("wall", -math.inf))
        elif e["event"] in ("restored", "exited") and pending.get(e["target"]):
            pending[e["target"]].pop(0)
    left = [w for ws in pending.values() for w in ws]
    starting = sum(w > ended - START_S for w in left)
    return len(left) - starting, starting


def check_restores(events: list[dict[str, Any]], ended: float = math.inf) -> tuple[bool, str]:
    """Every restart restored from a checkpoint at least as new as the newest its agent said it saved, the weights
    hashing as the checkpoint did; but a restart the run's end (at wall clock `ended`) cut short."""
    restored = [e for e in events if e["event"] == "restored"]
    restarts = [e for e in events if e["event"] == "restart"]
    bad = []
    for e in restored:
        m = re.search(r"checkpoint sha256=(\w+) restored sha256=(\w+)", e["detail"])
        if e.get("checkpoint_epoch", -1) < 0 and e.get("newest_saved", -1) < 0:
            continue  # before the first checkpoint: nothing to restore
        if not (m and m.group(1) == m.group(2)) or e.get("checkpoint_epoch", -1) < e.get("newest_saved", -1):
            bad.append(f"{e['target']} at {e['epoch']}/{e['step']}: {e['detail'][:80]}")
    short, starting = unanswered(events, ended)
    detail = f"{len(restarts)} restarts, {len(restored)} restored"
    if starting:
        detail += f"; {starting} still starting when the run ended"
    if short:
        detail += f"; {short} restarts never said what they restored"
    if bad:
        detail += f"; wrong: {len(bad)} ({bad[0]})"
    return not (bad or short), detail


def check_standins(events: list[dict[str, Any]], clock: str = "t") -> tuple[bool, str]:
    """An `adopt X` only while X was down: from its loss (or the fault that caused it, or its exit) to its token's
    return, give or take a second for the two observers hearing it at different moments. `clock`: "wall" for the
    records of two supervisors (each one's `t` starts at its own start)."""
    wrong, adopts = [], 0
    for seg in segments(events):
        for e in (e for e in seg if e["event"] == "adopt"):
            adopts += 1
            x, t = e["target"], e[clock]
            starts = [
                d[clock]
                for d in seg
                if d["target"] == x
                and d["event"] in ("lost", "exited")
                or d["event"] == "fault"
                and x in d["target"].split(",")
                and d["detail"].split(" ")[0] in PROCESS
            ]
            ok = False
            for s in starts:
                back = [b[clock] for b in seg if b["event"] == "alive" and b["target"] == x and b[clock] >= s]
                if s - 1.0 <= t <= (min(back) if back else math.inf) + 0.25:
                    ok = True
                    break
            if not ok:
                wrong.append(f"{e['detail']} at {e['epoch']}/{e['step']}")
    detail = f"{adopts} stand-ins"
    return not wrong, detail + (f"; for a live child: {len(wrong)} ({wrong[0]})" if wrong else "")


def check_epochs(metrics: list[dict[str, Any]], epochs: int) -> tuple[bool, str]:
    got = [r["epoch"] for r in metrics]
    c = Counter(got)
    doubled = sorted(e for e, n in c.items() if n > 1)
    missing = sorted(set(range(epochs)) - set(got))
    ok = got == list(range(epochs))
    return ok, f"{len(got)} rows" + (f"; missing {missing[:5]}" if missing else "") + (
        f"; doubled {doubled[:5]}" if doubled else ""
    )


def check_finished(out: Path, codes: list[int], crashes: int) -> tuple[bool, str]:
    s = json.loads((out / "summary.json").read_text()) if (out / "summary.json").exists() else {"error": "no summary"}
    final = codes[-1] if codes else None
    ok = final == 0 and not s.get("error") and len(codes) == crashes + 1
    return ok, f"exit codes {codes} ({crashes} crashes, each SIGKILLed)" + (f"; {s['error']}" if s.get("error") else "")


def naming(marker: Path) -> list[int]:
    """Live processes (not this one) whose command line names `marker`: a run's actors name its directory."""
    found = []
    for d in os.listdir("/proc"):
        if d.isdigit() and int(d) != os.getpid() and _alive(int(d)):
            try:
                if str(marker).encode() in Path(f"/proc/{d}/cmdline").read_bytes():
                    found.append(int(d))
            except OSError:
                pass
    return found


def stop_everything(base: Path, procs: list[subprocess.Popen | None], pids: dict[int, int]) -> int:
    """Interrupted (Ctrl-C, SIGTERM): both runs stopped, with their actors. They run in sessions of their own (a
    crash must not take this process with it), so the signal that stopped this one never reached them."""
    doomed = {p.pid for p in procs if p is not None and p.poll() is None}
    for pid in doomed:
        with contextlib.suppress(ProcessLookupError):
            os.killpg(pid, signal.SIGKILL)
    doomed |= {pid for pid, start in pids.items() if _alive(pid, start)} | set(naming(base))
    for pid in doomed:
        with contextlib.suppress(ProcessLookupError):
            os.kill(pid, signal.SIGKILL)
    for p in procs:
        if p is not None:
            with contextlib.suppress(subprocess.TimeoutExpired):
                p.wait(timeout=10.0)
    # until each is gone: a killed process lives on while the kernel frees it (seconds for PyBullet's on a loaded
    # machine), and a zygote can fork one more actor between the scan above and its own kill
    deadline = time.monotonic() + 10.0
    while (left := {pid for pid in doomed if _alive(pid)} | set(naming(base))) and time.monotonic() < deadline:
        for pid in left - doomed:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        doomed |= left
        time.sleep(0.05)
    return len(doomed)


def check_nothing_left(pids: dict[int, int], out: Path) -> tuple[bool, str]:
    deadline = time.monotonic() + 10.0
    while (left := sorted(p for p, start in pids.items() if _alive(p, start))) and time.monotonic() < deadline:
        time.sleep(0.1)
    left += naming(out)  # anything else that still names the run's directory
    return not left, f"{len(pids)} processes seen" + (f"; still running: {sorted(set(left))}" if left else "")


def parse(argv: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--minutes", type=float, default=60.0, help="how long the chaos run learns (sizes --epochs)")
    p.add_argument("--quick", action="store_true", help="about a minute, a fault every 1-2 s, each kind at least once")
    p.add_argument("--every", type=float, default=None, help="mean seconds between faults (default 4; quick 1)")
    p.add_argument("--epochs", type=int, default=None, help="default: what --minutes holds")
    p.add_argument("--steps", type=int, default=None, help="steps per epoch (default 500; quick 150)")
    p.add_argument("--tail", type=int, default=None, help="last epochs with no new fault, measured (default 20)")
    p.add_argument("--settle", type=int, default=None, help="quiet epochs before the tail (default 0; quick 2)")
    p.add_argument("--kinds", default=None, help=f"comma-separated, of: {','.join(KINDS)} (and with --hosts: cut)")
    p.add_argument("--crash-gap", type=float, default=150.0, help="seconds at least between two crashes (quick: one)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--deadline-ms", type=int, default=100)
    p.add_argument("--beside", action="store_true", help="the fault-free run beside the chaos run, not before it")
    p.add_argument("--hosts", action="store_true", help="both runs split over two network-namespace hosts (root)")
    p.add_argument("--out", type=Path, default=None, help="keep both runs here (default: a temporary directory)")
    a = p.parse_args(argv)
    known = (*KINDS, *SPLIT) if a.hosts else KINDS
    a.kinds = [k.strip() for k in (a.kinds or ",".join(known)).split(",") if k.strip()]
    if bad := [k for k in a.kinds if k not in (*KINDS, *SPLIT)]:
        p.error(f"--kinds: unknown {', '.join(bad)}; expected some of {', '.join((*KINDS, *SPLIT))}")
    if not a.hosts and (split := [k for k in a.kinds if k in SPLIT]):
        p.error(f"--kinds {','.join(split)}: a cut between hosts needs two hosts: add --hosts")
    if a.hosts:
        for kind, why in chaos_hosts.LEFT_OUT.items():
            if kind in a.kinds:
                a.kinds = [k for k in a.kinds if k != kind]
                print(f"chaos --hosts: {kind} left out: {why}", flush=True)
        if not a.kinds:
            p.error("--kinds: none left that a split run can take")
    if a.quick:  # about 40 s of chaos on the 2-core machine, after a fault-free run of about 30 s
        a.minutes = min(a.minutes, 1.0)
        a.epochs = a.epochs or 40
        a.crash_gap = math.inf
    a.every = a.every if a.every is not None else (1.0 if a.quick else 4.0)
    a.steps = a.steps if a.steps is not None else (150 if a.quick else 500)
    a.tail = a.tail if a.tail is not None else (4 if a.quick else 20)
    a.settle = a.settle if a.settle is not None else (2 if a.quick else 0)
    if a.epochs is None:
        s_per_step = SPLIT_S_PER_STEP if a.hosts else EPOCH_S_PER_STEP
        a.epochs = max(a.tail + a.settle + 4, round(a.minutes * 60 / (a.steps * s_per_step)))
    if a.every <= 0 or a.epochs <= a.tail + a.settle or a.steps < 1 or a.settle < 0:
        p.error("--every must be > 0, --epochs more than --tail + --settle, --settle at least 0, --steps at least 1")
    # a split run's agents restart slowly here (10-17 s at load 15) while epochs of 150 steps with them down pass in
    # about a second each: in the quick mode the last process faults come 8 epochs before its 4-epoch tail
    a.process_until = a.epochs - a.tail - 8 if (a.quick and a.hosts) else a.epochs
    a.warmup = 1.0
    a.run_id = "chaos"
    base = Path(a.out) if a.out else None
    for d in (base / "fault-free", base / "chaos") if base else ():
        if d.exists():
            p.error(f"--out {base}: {d} exists already (a run of its own): give an empty directory")
    return a


def main(argv: list[str] | None = None) -> int:
    a = parse(argv)
    with tempfile.TemporaryDirectory() as tmp, contextlib.ExitStack() as stack:
        base = Path(a.out or tmp)
        base.mkdir(parents=True, exist_ok=True)
        split = free_split = None
        if a.hosts:
            try:  # two hosts for each run: a cut of the chaos run's limbs must not cut the fault-free run beside it
                split = stack.enter_context(chaos_hosts.Split())
                free_split = stack.enter_context(chaos_hosts.Split("f"))
            except chaos_hosts.NetnsUnavailable as e:
                print(f"chaos: --hosts: no network namespaces here: {e}", file=sys.stderr)
                return 2
        # a split run's directories: the leader's (what is checked) under <run>/brain, the other host's <run>/limbs
        free_out, out = (base / "fault-free", base / "chaos") if split is None else (
            base / "fault-free" / "brain", base / "chaos" / "brain")  # fmt: skip
        control = None if split is None else chaos_hosts.RemoteControl(split.hosts, "brain", out, base / "control.log")
        c = Chaos(a, out, random.Random(a.seed), base / "runs.log", control=control, split=split)
        try:
            signal.signal(signal.SIGTERM, _interrupt)
            free = _both(a, c, base, free_out, free_split)
        except KeyboardInterrupt:
            n = stop_everything(base, [c.proc, c.free], c.pids)
            stack.close()  # with --hosts: the namespaces
            kept = f"their files are in {base}" if a.out is not None else "rerun with --out to keep their files"
            print(f"chaos: interrupted: both runs stopped ({n} processes killed); {kept}", file=sys.stderr)
            if a.out is None:
                shutil.rmtree(tmp, ignore_errors=True)
            sys.stdout.flush()
            sys.stderr.flush()
            # not a return: the control client's Zenoh session, cut mid-request with its peers killed, can hang the
            # interpreter's exit (seen: 60 s and more after this line was printed)
            os._exit(130)
        return report(a, c, base, free_out, free.returncode, c.wall, [s for s in (split, free_split) if s is not None])


def _interrupt(signum: int, frame: Any) -> None:
    raise KeyboardInterrupt


def _both(
    a: argparse.Namespace, c: Chaos, base: Path, free_out: Path, free_split: chaos_hosts.Split | None
) -> subprocess.Popen:
    """The fault-free run (first, or beside) and the chaos run; returns the fault-free run, ended."""
    t0 = time.monotonic()
    if free_split is None:
        c.start(c.argv("chaos-free", free_out))
        assert c.proc is not None
        free = c.proc
    else:
        free = free_split.start(free_out.parent, a.epochs, a.steps, a.seed,
                                ["--run-id", "chaos-free", "--deadline-ms", str(a.deadline_ms)])  # fmt: skip
    c.free = free
    if not a.beside:
        while free.poll() is None:  # a line a minute: alive
            with contextlib.suppress(subprocess.TimeoutExpired):
                free.wait(timeout=60.0)
            if free.poll() is None:
                done = len(_rows(free_out / "metrics.jsonl"))
                print(f"chaos: the fault-free run first: {(time.monotonic() - t0) / 60:.0f} min, "
                      f"epoch {done}/{a.epochs}", flush=True)  # fmt: skip
        print(f"chaos: the fault-free run took {time.monotonic() - t0:.0f} s (exit {free.returncode}); now the chaos")
        epoch_s = [r["seconds"] for r in _rows(free_out / "metrics.jsonl")]
        if a.quick and epoch_s and (pace := statistics.median(epoch_s) / QUICK_EPOCH_S) > 1.0:
            c.pace, a.every = pace, a.every * pace
            print(f"chaos: a fault-free epoch took {statistics.median(epoch_s):.2f} s (quiet: {QUICK_EPOCH_S}): "
                  f"the schedule's seconds stretched x{pace:.1f}, a fault every {a.every:.1f} s")  # fmt: skip
    c.wall = c.soak()
    free.wait()
    return free


def report(
    a: argparse.Namespace,
    c: Chaos,
    base: Path,
    free_out: Path,
    free_code: int,
    wall: float,
    splits: list[chaos_hosts.Split],
) -> int:
    """The invariants, checked from what the runs left behind, printed as a table; 1 if one does not hold."""
    out = c.out
    with open(base / "faults.jsonl", "w") as f:  # the schedule as sent: the invariants can be checked again from files
        f.writelines(json.dumps(dataclasses.asdict(i)) + "\n" for i in c.injected)
    summary = free_out / "summary.json"
    free_s = json.loads(summary.read_text()).get("wall_seconds", 0.0) if summary.exists() else 0.0
    events, metrics = _rows(out / "events.jsonl"), _rows(out / "metrics.jsonl")
    free_metrics = _rows(free_out / "metrics.jsonl")
    s_free, s_chaos = share(free_metrics, a.tail), share(metrics, a.tail)
    kinds = Counter(i.kind for i in c.injected)
    if c.split is None:
        restores, standins = check_restores(events, c.ended), check_standins(events)
        left = check_nothing_left(c.pids, out)
    else:  # each host records its own agents' restarts; the leader hears the rest, but not through a cut
        limbs = _rows(out.parent / "limbs" / "events.jsonl")
        restores = check_restores(chaos_hosts.own(events, "brain") + chaos_hosts.own(limbs, "limbs"), c.ended)
        standins = check_standins(chaos_hosts.merged(events, limbs), clock="wall")
        lingering = [pid for s in splits for pid in s.wait_others(60.0)]  # the other hosts stop by themselves
        c.note({p.pid for s in splits for p in s.hosts.procs})
        ok, detail = check_nothing_left(c.pids, out.parent)
        inside = sorted({pid for s in splits for pid in s.left_inside()})
        if lingering or inside:
            detail += f"; still up: {lingering} (a host's `kinswarm up`), in the namespaces: {inside}"
        left = (ok and not (lingering or inside), detail)
    rows = [
        ("every fault in events.jsonl at its exact step", *check_faults_at_steps(events, c.injected, a.steps)),
        ("every restart restored the newest checkpoint", *restores),
        ("no agent stood in for a live child", *standins),
        ("every epoch once in metrics.jsonl", *check_epochs(metrics, a.epochs)),
        ("the run finished", *check_finished(out, c.exit_codes, c.crashes)),
        ("nothing left running" + (" (in either host)" if c.split else ""), *left),
        (
            f"still learns: last {a.tail} within 0.5 >= fault-free - 10 points",
            s_chaos >= s_free - 0.10 and free_code == 0,  # a fault-free run that failed measures nothing
            f"{s_chaos:.0%} vs fault-free {s_free:.0%} (exit {free_code})",
        ),
        ("every kind injected", all(kinds[k] >= 1 for k in a.kinds), ", ".join(f"{k} {kinds[k]}" for k in a.kinds)),
    ]
    if c.split is not None:
        limbs = _rows(out.parent / "limbs" / "events.jsonl")
        rows.insert(5, ("after every cut the run went on", *chaos_hosts.check_cuts(events, limbs, c.cuts)))
    n = len(c.injected)
    where = "split over two hosts (brain: sim, a1; limbs: a2-a4)" if c.split else "process placement"
    print(
        f"\nchaos soak: {a.epochs} epochs x {a.steps} steps, seed {a.seed}, {where}, deadline "
        f"{a.deadline_ms} ms; {n} faults in {wall:.0f} s (one every {wall / max(n, 1):.1f} s), "
        f"{c.crashes} crashes resumed, {len(c.refused)} refused, {sum(c.undelivered.values())} retried "
        f"(the run was between a crash and its resume); fault-free run {free_s:.0f} s"
        + (" (beside)" if a.beside else "")
    )
    print("| invariant | holds | what was seen |")
    print("|---|---|---|")
    for name, ok, detail in rows:
        print(f"| {name} | {'yes' if ok else 'NO'} | {detail} |")
    print(f"steps from a joint fault's request to its effect: {fault_lags(events, c.injected, a.steps)}")
    for r in c.refused[:5]:
        print(f"refused: {r}")
    if a.out is not None:  # a temporary directory's picture would go with it
        title = f"chaos soak: {a.epochs} epochs x {a.steps} steps, seed {a.seed}, {where}, {n} faults in {wall:.0f} s"
        print(f"picture: {chaos_picture.write(base / 'chaos.png', free_metrics, metrics, events, a.kinds, title)}")
    failed = [name for name, ok, _ in rows if not ok]
    if failed and a.out is None:
        logs = "runs.log" if c.split is None else "{chaos,fault-free}/{b,l}.log (the leader's, limbs'), control.log"
        print(f"(the runs' logs: {base}/{logs}, kept only with --out)")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
