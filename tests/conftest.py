"""Shared fixtures: free loopback ports, the example topologies, a quick run config."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import os
import shutil
import signal
import socket
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import pytest
from hypothesis import settings
from hypothesis_timeout import pytest_timeout_set_timer  # noqa: F401  # the hook: a hung property ends at its timeout
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.files.runfile import load_run
from kinswarm.actors.runtime import Mailbox, NetSpec
from kinswarm.protocol.keys import Keys

# Swarms a test started as child processes (a `kinswarm run`, in a session of its own): whatever the test's outcome,
# each is stopped when the test ends, the supervisor and the actors it spawned, so a failed assertion leaves no swarm
LIVE: list[Any] = []


@pytest.fixture(autouse=True)
def _stop_live_swarms() -> Any:
    yield
    while LIVE:
        proc = LIVE.pop()
        with contextlib.suppress(ProcessLookupError):  # the session's leader may be gone, an actor of it not
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(timeout=30)


# Hypothesis draws the same way with and without CI set: CI=true alone would load its "ci" profile, which draws fixed
# examples (derandomize), so CI would never see what a user's run can draw. No example database either: nothing is
# written outside tmp dirs (a failure prints its seed and blob to reproduce it). `--hypothesis-profile` still wins.
settings.register_profile("kinswarm", derandomize=False, database=None, print_blob=True)
settings.load_profile("kinswarm")


_HYPOTHESIS_HOME = pytest.StashKey[str]()


def pytest_configure(config: pytest.Config) -> None:
    """Hypothesis's caches (constants, unicode tables) in this session's tmp dir, not `.hypothesis/` in the checkout
    (they are written while the tests are collected)."""
    from hypothesis.configuration import set_hypothesis_home_dir

    config.stash[_HYPOTHESIS_HOME] = home = tempfile.mkdtemp(prefix="hypothesis-")
    set_hypothesis_home_dir(home)


def pytest_unconfigure(config: pytest.Config) -> None:
    shutil.rmtree(config.stash.get(_HYPOTHESIS_HOME, ""), ignore_errors=True)


# Runs in tests draw no motion.gif and write no recording.rrd (RunConfig.record), unless a test asks: seconds a
# run, hundreds of runs. Subprocesses inherit it.
os.environ.setdefault("KINSWARM_RECORD", "0")

ROOT = Path(__file__).resolve().parent.parent
EXAMPLES = ROOT / "examples"
# The step deadline of runs whose test checks that no command was missed, or compares runs for equality (placements,
# hosts, spam): a command that misses its deadline makes its joint hold. On a starved CI machine the 500 ms default
# was missed (twice: equal runs parted, and a 5-process tree run at 23 steps/s missed 6 commands), for a reason that
# is not what these tests are about. Timing belongs in benchmarks/.
LOCKSTEP_DEADLINE_MS = 30_000
# ... and their Zenoh lease: a process starved past the 1 s default lease (a stall of the shared CI host) drops out
# of its peers' view for a moment. The sim then steps on without its agents (their joints hold), and the messages
# in flight when the link reset are lost. Measured here: SIGSTOP of a 15-process grasp swarm for 4 s made all 13
# agents "down" and one step wait out its deadline. The swarm survives that by design; an exact comparison cannot.
LOCKSTEP_LEASE_MS = 10_000
LOCKSTEP_ARGS = ["--deadline-ms", str(LOCKSTEP_DEADLINE_MS), "--lease-ms", str(LOCKSTEP_LEASE_MS)]


def run_config(file: Path | str, sets: Sequence[str] = (), **fields: Any) -> RunConfig:
    """The run of a run file as the one loader resolves it (with `--set`-style overrides), then RunConfig fields
    replaced (out, steps, deadline_ms, ...): how a test makes a config without a command line."""
    cfg = load_run(file, sets, run_id=fields.pop("run_id", "t"), out=fields.pop("out", None))
    return dataclasses.replace(cfg, **fields)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def endpoint() -> str:
    return f"tcp/127.0.0.1:{free_port()}"


@pytest.fixture
def chain4() -> Path:
    return EXAMPLES / "chain4.toml"


@pytest.fixture
def tree5() -> Path:
    return EXAMPLES / "tree5.toml"


def tool_net(out: Path, stop: Any = None, wait_s: float = 120.0) -> NetSpec | None:
    """The NetSpec a run wrote for its tools (`<out>/net/cli.json`: its endpoint and credentials; a one-host run's
    hub admits only its own identities), once the run has written it; None if `stop` (an Event) was set first."""
    path = out / "net" / "cli.json"
    deadline = time.monotonic() + wait_s  # a hang guard
    while stop is None or not stop.is_set():
        with contextlib.suppress(OSError, ValueError):  # not yet there, or half written
            return NetSpec.from_json(path.read_text())
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.02)
    return None


def swarm_pids(marker: str) -> list[int]:
    """PIDs of live processes whose command line mentions `marker` (a run's config path)."""
    pids = []
    for d in os.listdir("/proc"):
        if not d.isdigit() or int(d) == os.getpid():
            continue
        try:
            cmd = Path(f"/proc/{d}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
            state = Path(f"/proc/{d}/stat").read_text().split()[2]
        except OSError:
            continue
        if marker in cmd and state != "Z":
            pids.append(int(d))
    return pids


def actor_pids(run_dir: Path, role: str, ident: str) -> list[int]:
    """PIDs of a run's live actor `role ident`: forked by the run's zygote, it shares the zygote's command line (which
    names the run's config) and is told apart by its process name, ROLE-ID (/proc/PID/comm, 15 bytes)."""
    name = f"{role}-{ident}"[:15]
    pids = []
    for pid in swarm_pids(str(run_dir / "config.json")):
        try:
            if Path(f"/proc/{pid}/comm").read_text().strip() == name:
                pids.append(pid)
        except OSError:
            continue
    return pids


# The arms from URDF the tests build (protocol/urdf_robot.py), as [robot] tables: the example files' robots.
IIWA = {"urdf": "kuka_iiwa/model.urdf", "tool": [0.0, 0.05, 0.1]}
PANDA = {
    "urdf": "franka_panda/panda.urdf",
    "joints": [f"panda_joint{i}" for i in range(1, 8)],
    "tool": [0.0, 0.0, 0.1034],
    "tool_link": "panda_hand",
}
XARM6 = {"urdf": "xarm/xarm6_robot.urdf"}


def urdf_robot(table: dict):
    """The Topology of a [robot] table from URDF (paths as from a run file in /tmp)."""
    from kinswarm.protocol.robots import parse_robot

    return parse_robot(dict(table), "/tmp/x.toml")


def fault_message(kind: str, *targets: str, **params: Any) -> Any:
    """A Fault message with only the given sizes set (the rest None)."""
    from kinswarm.protocol.messages import Fault

    fields = dict.fromkeys(("seconds", "steps", "rate", "ms", "amplitude_deg")) | params
    return Fault(id="t", fault=kind, targets=list(targets), **fields)


@pytest.fixture
def sessions(endpoint: str) -> Any:
    """Two Zenoh sessions on loopback, the second connected to the first; both closed after the test."""
    from kinswarm.actors.runtime import open_session

    a = open_session(listen=[endpoint])
    b = open_session(connect=[endpoint])
    try:
        yield a, b
    finally:
        b.close()
        a.close()


class RecordingNode:
    """What SimActor needs of a Node, recording what it sends instead of putting it on the wire."""

    def __init__(self, run: str = "t") -> None:
        self.keys = Keys(run)
        self.role, self.ident = "sim", "sim"
        self.log = logging.getLogger("test.sim")
        self.mailbox = Mailbox(asyncio.get_running_loop())
        self.sent: list[tuple[str, Any]] = []
        self.rejected = 0

    def send(self, key: str, msg: Any) -> None:
        self.sent.append((key, msg))

    def of(self, kind: type) -> list[Any]:
        return [m for _, m in self.sent if isinstance(m, kind)]
