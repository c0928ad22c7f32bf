"""What the chaos soak (benchmarks/chaos.py) needs to break a swarm split over two hosts (`--hosts`): the split run
(network-namespace hosts on a bridge, `kinswarm up` with one plan on each, as benchmarks/deploy_rate.py starts it),
the run's control client (in this process, or in the leader's namespace as a process of its own), the cut between
the hosts as one more fault, and the checks only a split run needs.

    python benchmarks/chaos_hosts.py RUN-DIR    # the control client, run inside the leader's namespace: one JSON
                                                # request a line on stdin, one JSON reply a line on stdout
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import math
import select
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT / "benchmarks"))
from deploy_rate import start_split  # noqa: E402
from netns import Hosts, NetnsUnavailable  # noqa: E402

__all__ = ["NetnsUnavailable"]

#: kinds of the one-host soak a split run cannot take, and why (printed when they are left out)
LEFT_OUT = {"crash": "`kinswarm up` has no --resume, so a split run cannot go on after a power cut"}
HOSTS = {"brain": ("a1",), "limbs": ("a2", "a3", "a4")}  # deploy_rate.start_split's plan: the sim is on brain
CUT_S = (1.0, 6.0)  # limbs' link down for a drawn time in this range, then mended
CUT_GAP_S = 3.0  # after a mend, before the next cut: each partition and rejoin belongs to one cut
NOTICED_S = 2.0  # a cut this long is always noticed (a lease of 1 s, heard within ~1 s: docs/deploy.md)


class Control:
    """The run's control client in this process: one session for many faults (a new one after it failed)."""

    def __init__(self, out: Path) -> None:
        self.out = out
        self.loop = asyncio.new_event_loop()
        self.client: Any = None  # kinswarm.actors.control.client.Client, entered

    def fault(self, kind: str, target: str, params: dict[str, float]) -> tuple[bool, str]:
        """(delivered, the supervisor's error or ''); a run between its crash and its resume is not reached."""
        from kinswarm.actors.control.client import Client, ControlError, make_fault, run_config_at, tool_net

        async def one() -> tuple[bool, str]:
            if self.client is None:  # one session for many faults; a new one after a crash (a new endpoint)
                cfg = run_config_at(self.out)
                client = Client(cfg, tool_net(self.out, cfg, None))
                self.client = await client.__aenter__()
            fault = make_fault(kind, [target], **{k: (int(v) if k == "steps" else v) for k, v in params.items()})
            reply = await self.client.fault(fault, timeout=5.0)
            return True, reply.error

        try:
            return self.loop.run_until_complete(one())
        except ControlError as e:
            self.close()
            return False, str(e)

    def close(self) -> None:
        if self.client is not None:
            with contextlib.suppress(Exception):
                self.loop.run_until_complete(self.client.__aexit__(None, None, None))
            self.client = None

    def pids(self) -> dict[str, int]:
        from kinswarm.actors.control.client import Client, ControlError, run_config_at, tool_net

        async def one() -> dict[str, int]:
            try:
                cfg = run_config_at(self.out)
                async with Client(cfg, tool_net(self.out, cfg, None)) as c:
                    async for status, _ in c.statuses(timeout=3.0):
                        return dict(status.pid)
            except ControlError:
                pass
            return {}

        return asyncio.run(one())

    def shutdown(self) -> None:
        self.close()
        self.loop.close()


class RemoteControl:
    """The same client inside host `host`'s namespace (the leader's: faults go in from where its users are), a
    process of its own asked one JSON line at a time; started again if it stops answering."""

    def __init__(self, hosts: Hosts, host: str, out: Path, log: Path) -> None:
        self.hosts, self.host, self.out, self.log = hosts, host, out, log
        self.proc = self._start()

    def _start(self) -> subprocess.Popen:
        with open(self.log, "ab") as err:
            p = subprocess.Popen(
                ["ip", "netns", "exec", self.hosts.ns(self.host), sys.executable, __file__, str(self.out)],
                stdin=subprocess.PIPE,
                stdout=subprocess.PIPE,
                stderr=err,
                text=True,
                start_new_session=True,
            )
        self.hosts.procs.append(p)  # ended with the hosts, whatever happens to us
        return p

    def _ask(self, request: dict[str, Any], timeout: float = 60.0) -> Any:
        assert self.proc.stdin is not None and self.proc.stdout is not None
        try:
            self.proc.stdin.write(json.dumps(request) + "\n")
            self.proc.stdin.flush()
            if select.select([self.proc.stdout], [], [], timeout)[0]:
                line = self.proc.stdout.readline()
                if line:
                    return json.loads(line)
        except (BrokenPipeError, OSError):
            pass
        self.proc.kill()  # silent or gone: a late reply must not answer the next request
        self.proc.wait()
        self.proc = self._start()
        return None

    def fault(self, kind: str, target: str, params: dict[str, float]) -> tuple[bool, str]:
        reply = self._ask({"fault": kind, "target": target, "params": params})
        if reply is None:
            return False, f"the control client in {self.host} did not answer (its log: {self.log})"
        return bool(reply[0]), str(reply[1])

    def pids(self) -> dict[str, int]:
        reply = self._ask({"pids": True})
        return {k: int(v) for k, v in (reply or {}).items()}

    def close(self) -> None:
        """Nothing to do: the client in the namespace opens a new session itself after a failure."""

    def shutdown(self) -> None:
        assert self.proc.stdin is not None
        with contextlib.suppress(OSError):
            self.proc.stdin.close()  # its end of input: it closes its session and exits
        try:
            self.proc.wait(timeout=20)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()


def serve(out: Path) -> int:
    """The control client's loop (in the leader's namespace): a request a line, its reply a line."""
    control = Control(out)
    for line in sys.stdin:
        request = json.loads(line)
        if "pids" in request:
            reply: Any = control.pids()
        else:
            reply = list(control.fault(request["fault"], request["target"], request["params"]))
        print(json.dumps(reply), flush=True)
    control.shutdown()
    return 0


class Split:
    """Two hosts (network namespaces `brain` and `limbs` on a bridge) for one run: the sim and a1 on brain (the
    leader), a2-a4 on limbs. `tag` tells apart two splits of one process (a fault-free run beside the chaos)."""

    def __init__(self, tag: str = "") -> None:
        self.hosts = Hosts(list(HOSTS), tag=tag)

    def __enter__(self) -> Split:
        self.hosts.__enter__()
        return self

    def __exit__(self, *exc: object) -> None:
        self.hosts.__exit__(*exc)

    def start(self, base: Path, epochs: int, steps: int, seed: int, leader_args: Sequence[str]) -> subprocess.Popen:
        """The run, its leader's directory base/brain (log base/b.log), limbs' base/limbs (base/l.log)."""
        base.mkdir(parents=True, exist_ok=True)
        return start_split(self.hosts, base, epochs, steps, seed, leader_args)

    def wait_others(self, timeout: float) -> list[int]:
        """After the leader's end: the other hosts stop their share by themselves; the PIDs of what did not."""
        deadline = time.monotonic() + timeout
        while any(p.poll() is None for p in self.hosts.procs) and time.monotonic() < deadline:
            time.sleep(0.1)
        return [p.pid for p in self.hosts.procs if p.poll() is None]

    def left_inside(self) -> list[int]:
        """Whatever still runs in either host's namespace."""
        left: list[int] = []
        for name in HOSTS:
            r = subprocess.run(["ip", "netns", "pids", self.hosts.ns(name)], capture_output=True, text=True)
            left += [int(p) for p in r.stdout.split()]
        return left


@dataclass
class Cut:
    at: float  # wall clock (events.jsonl's `wall`) when limbs' link went down
    seconds: float
    mended: float = math.inf


def check_cuts(brain: list[dict[str, Any]], limbs: list[dict[str, Any]], cuts: list[Cut]) -> tuple[bool, str]:
    """After every cut the run went on: each side recorded the partition and then, once the link was back, the
    rejoin (as benchmarks/cut_recovery.py reads them), and the sim resumed the steps it held. A cut shorter than
    NOTICED_S may pass unnoticed (the link back before a lease without heartbeats); a longer one may not."""
    noticed, short_unnoticed, rejoin_s, bad = 0, 0, [], []
    for i, c in enumerate(cuts):
        until = cuts[i + 1].at if i + 1 < len(cuts) else math.inf
        where = f"cut {i + 1} ({c.seconds:g} s)"

        part = _first(brain, "partition", "limbs", c.at, until)
        if part is None:
            if c.seconds < NOTICED_S:
                short_unnoticed += 1
            else:
                bad.append(f"{where}: the leader recorded no partition")
            continue
        noticed += 1
        back = _first(brain, "rejoin", "limbs", max(c.mended, part["wall"]), until)
        other = _first(limbs, "partition", "brain", c.at, until)
        other_back = _first(limbs, "rejoin", "brain", max(c.mended, other["wall"]), until) if other else None
        pause = _first(brain, "pause", "sim", c.at, until)
        resume = _first(brain, "resume", "sim", pause["wall"], until) if pause else None
        if back is None:
            bad.append(f"{where}: the leader recorded no rejoin after the mend")
            continue
        rejoin_s.append(back["wall"] - c.mended)
        if other is not None and other_back is None:
            bad.append(f"{where}: limbs recorded the partition, never the rejoin")
        if pause is not None and resume is None:
            bad.append(f"{where}: the sim held its steps and never resumed")
    detail = f"{len(cuts)} cuts, {noticed} noticed and rejoined"
    if short_unnoticed:
        detail += f", {short_unnoticed} under {NOTICED_S:g} s unnoticed"
    if rejoin_s:
        median = sorted(rejoin_s)[len(rejoin_s) // 2]
        detail += f"; rejoin after the mend: median {median:.2f} s, max {max(rejoin_s):.2f} s"
    if bad:
        detail += f"; {len(bad)} not recovered ({bad[0]})"
    return not bad, detail


def _first(events: list[dict[str, Any]], event: str, target: str, after: float, until: float) -> dict[str, Any] | None:
    return next((e for e in events if e["event"] == event and e["target"] == target and after <= e["wall"] < until),
                None)  # fmt: skip


def own(events: list[dict[str, Any]], host: str) -> list[dict[str, Any]]:
    """A host's record of its own agents' exits, restarts and restores (the leader hears other hosts' restores only
    while the link is up, and never their restarts)."""
    return [e for e in events if e["event"] in ("exited", "restart", "restored") and e["target"] in HOSTS[host]]


def merged(brain: list[dict[str, Any]], limbs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """The leader's events and what only limbs' supervisor records (its agents' exits, losses, returns and the
    faults forwarded to it), in wall-clock order: the two supervisors' `t` clocks start apart."""
    mine = ("lost", "exited", "alive", "fault", "thaw", "restart")
    theirs = [e for e in limbs if e["event"] in mine and e["target"] in HOSTS["limbs"]]
    return sorted(brain + theirs, key=lambda e: e["wall"])


if __name__ == "__main__":
    sys.exit(serve(Path(sys.argv[1])))
