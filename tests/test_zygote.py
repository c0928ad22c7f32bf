"""The `process` placement's zygote (actors/process/main.py `serve_zygote`, actors/supervisor/placements.py `Zygote`):
it loads what the actors need without a Zenoh session, forks each actor into a session of the OS of its own, reports
every end with its code, and takes its children with it when it ends; the actors it forks share its pages, so an agent
of a swarm costs a fraction of a fresh interpreter's memory."""

from __future__ import annotations

import asyncio
import os
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import EXAMPLES, free_port, run_config, swarm_pids
from kinswarm.actors.runtime import NetSpec
from kinswarm.actors.supervisor.placements import Zygote

HANG_GUARD_S = 120.0


def _sockets(pid: int) -> int:
    fds = Path(f"/proc/{pid}/fd")
    return sum(os.readlink(fds / fd).startswith("socket:") for fd in os.listdir(fds))


def _ppid(pid: int) -> int:
    return int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])


@pytest.mark.timeout(300)
def test_the_zygote_forks_reports_ends_and_takes_its_children_along(tmp_path):
    out = tmp_path / "r"
    out.mkdir()
    cfg = run_config(EXAMPLES / "chain4.toml", out=str(out))
    cfg.write(out / "config.json")
    # a session that reaches nobody (a port nobody listens on): the actor waits for a supervisor that never comes
    net = tmp_path / "net.json"
    net.write_text(NetSpec(connect=(f"tcp/127.0.0.1:{free_port()}",)).to_json())
    logs = tmp_path / "logs"
    logs.mkdir()

    async def main() -> None:
        loop = asyncio.get_running_loop()
        ends: dict[int, asyncio.Future[int | None]] = {}

        def on_exit(pid: int, code: int | None) -> None:
            ends.setdefault(pid, loop.create_future()).set_result(code)

        async def end_of(pid: int) -> int | None:
            return await asyncio.wait_for(ends.setdefault(pid, loop.create_future()), HANG_GUARD_S)

        z = Zygote(out / "config.json", logs / "zygote.log", on_exit)
        await z.start()
        assert z.proc is not None and z.pid == z.proc.pid
        assert _sockets(z.pid) == 0  # it never opened a session: forking it is safe
        argv = [str(out / "config.json"), "--net", str(net)]

        bad = z.fork(["agent", "nobody", *argv], logs / "nobody.log")
        assert await end_of(bad) == 2  # main's own failure, its code reported
        assert "failed" in (logs / "nobody.log").read_text()

        live = z.fork(["agent", "a1", *argv], logs / "a1.log")
        await _named(live, "agent-a1")  # it names itself once it is set up as an actor
        assert _ppid(live) == z.pid and os.getsid(live) == live  # its own session: Ctrl-C reaches the supervisor only
        os.kill(live, signal.SIGKILL)
        assert await end_of(live) == -signal.SIGKILL

        left = z.fork(["agent", "a2", *argv], logs / "a2.log")
        pidfd = os.pidfd_open(left)
        gone = loop.create_future()
        loop.add_reader(pidfd, lambda: gone.done() or gone.set_result(None))
        try:
            await z.stop()  # its stdin closes: it leaves, and its child gets its death signal
            assert await end_of(left) is None  # reported as ended with the zygote
            await asyncio.wait_for(gone, HANG_GUARD_S)  # and it did end
        finally:
            loop.remove_reader(pidfd)
            os.close(pidfd)
        assert z.proc.returncode == 0
        with pytest.raises(RuntimeError, match="zygote is gone"):
            z.fork(["agent", "a3", *argv], logs / "a3.log")

    asyncio.run(main())


async def _named(pid: int, name: str) -> None:
    deadline = time.monotonic() + HANG_GUARD_S
    while Path(f"/proc/{pid}/comm").read_text().strip() != name:
        assert time.monotonic() < deadline, f"{pid} never named itself {name}"
        await asyncio.sleep(0.02)


def _pss_kb(pid: int) -> int:
    for line in Path(f"/proc/{pid}/smaps_rollup").read_text().splitlines():
        if line.startswith("Pss:"):
            return int(line.split()[1])
    raise AssertionError(f"no Pss for {pid}")


@pytest.mark.timeout(300)
def test_a_swarms_agents_share_the_zygotes_pages(tmp_path):
    """A chain4 swarm at work: its agents are the zygote's children, the zygote the supervisor's, and an agent's PSS is
    below 50 MB (a fresh interpreter's agent held ~85 MB: numba, numpy and the runtime of its own)."""
    out = tmp_path / "m"
    p = subprocess.Popen(
        [sys.executable, "-m", "kinswarm.actors.cli.entry", "run", str(EXAMPLES / "chain4.toml"), "--epochs", "500"]
        + ["--steps", "200", "--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}", "--no-progress"]
        + ["--set", "run.record=false"],
        stdout=(tmp_path / "run.txt").open("w"),
        stderr=subprocess.STDOUT,
    )
    try:
        deadline = time.monotonic() + HANG_GUARD_S
        metrics = out / "metrics.jsonl"
        while not (metrics.exists() and metrics.read_text().count("\n") >= 1):
            assert p.poll() is None, (tmp_path / "run.txt").read_text()
            assert time.monotonic() < deadline, "no epoch ended"
            time.sleep(0.1)
        pids = [q for q in swarm_pids(str(out)) if q != p.pid]
        names = {q: Path(f"/proc/{q}/comm").read_text().strip() for q in pids}
        agents = [q for q, n in names.items() if n.startswith("agent-")]
        (zygote,) = [q for q, n in names.items() if not n.startswith(("agent-", "sim-", "hub"))]
        assert sorted(names[q] for q in agents) == ["agent-a1", "agent-a2", "agent-a3", "agent-a4"]
        assert _ppid(zygote) == p.pid and all(_ppid(q) == zygote for q in agents)
        pss = [_pss_kb(q) / 1024 for q in agents]
        assert statistics.median(pss) < 50.0, pss
        p.send_signal(signal.SIGINT)
        p.wait(timeout=HANG_GUARD_S)
    finally:
        if p.poll() is None:
            p.kill()
            p.wait()
    assert p.returncode == 130
    assert swarm_pids(str(out)) == []
