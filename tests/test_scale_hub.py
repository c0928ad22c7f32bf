"""One host's Zenoh network as a hub: the hub (a process the supervisor starts) is the router, every actor and the
supervisor its clients. Connections grow linearly with the swarm (a 32-agent chain starts, runs and holds at most 4 TCP
connections a process on average), and only the run can speak on it: a stranger's session without the run's secret
cannot join, so liveliness tokens it declares on the run's keys change nothing."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from conftest import EXAMPLES, LIVE, LOCKSTEP_ARGS, free_port
from kinswarm.actors.cli.commands import main as cli_main
from kinswarm.actors.runtime import open_session
from kinswarm.protocol.clock import ClockReader, clock_path
from kinswarm.protocol.keys import Keys

pytestmark = pytest.mark.timeout(900)  # hang guards only: a 34-process start on a loaded 2-core machine is slow


def chain_file(n: int, path: Path) -> Path:
    """A planar chain of `n` joints whose reach is chain4's (12): links of 12/n, a gentle curl of 60 deg in all."""
    rows = [
        f'[robot]\nname = "chain{n}"\n\n[robot.defaults]\nlink_length = {12.0 / n!r}\nlimits_deg = [-180.0, 180.0]\n'
    ]
    for i in range(1, n + 1):
        parent = f'parent = "a{i - 1}"\n' if i > 1 else ""
        rows.append(f'[[robot.agent]]\nid = "a{i}"\n{parent}initial_deg = {0.0 if i == 1 else 60.0 / (n - 1)!r}\n')
    rows.append('[task]\nkind = "reach"\ngoal = [4.16, 6.18]\n')
    path.write_text("\n".join(rows))
    return path


def process_tree(pid: int) -> list[int]:
    """`pid` and its descendants, now."""
    out = [pid]
    try:
        children = Path(f"/proc/{pid}/task/{pid}/children").read_text().split()
    except OSError:
        return out
    for c in children:
        out += process_tree(int(c))
    return out


def tcp_connections(pids: list[int]) -> dict[int, int]:
    """Established TCP connections held by each of `pids` (`ss -tnp`: a loopback connection counts at both ends)."""
    text = subprocess.run(["ss", "-tnpH", "state", "established"], capture_output=True, text=True, check=True).stdout
    held = dict.fromkeys(pids, 0)
    for line in text.splitlines():
        for m in re.finditer(r"pid=(\d+)", line):
            if int(m.group(1)) in held:
                held[int(m.group(1))] += 1
    return held


def test_a_chain_of_32_agents_starts_runs_and_holds_few_connections(tmp_path: Path) -> None:
    n = 32
    out = tmp_path / "run"
    cmd = [str(Path(sys.executable).parent / "kinswarm"), "run", str(chain_file(n, tmp_path / "chain32.toml"))]
    cmd += ["--placement", "process", "--epochs", "1"]
    cmd += ["--steps", "30", "--out", str(out), "--no-progress", *LOCKSTEP_ARGS]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    LIVE.append(proc)
    clock = ClockReader(clock_path(out))
    sample: dict[int, int] | None = None
    while proc.poll() is None and sample is None:  # the first step: every actor is up (the supervisor counted them)
        at = clock.read()
        if at is not None and at[0] >= 0:
            pids = process_tree(proc.pid)
            if len(pids) == n + 4:  # the supervisor, its hub and zygote, the sim and the agents
                sample = tcp_connections(pids)
        time.sleep(0.2)
    clock.close()
    output = proc.communicate(timeout=600)[0].decode(errors="replace")
    assert proc.returncode == 0, output[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert not summary["error"] and len(summary["final_error"]) == 1
    assert sample is not None, "never saw every actor process at a step"
    # a hub: each actor and the supervisor hold one connection (to the hub), the hub one each; a mesh held N^2
    assert sum(sample.values()) / len(sample) <= 4, sample
    assert sorted(sample.values())[-2] <= 2, sample  # nobody but the hub holds more than a couple
    left = [p for p in process_tree(proc.pid) if p != proc.pid and os.path.exists(f"/proc/{p}")]
    assert not left


def _forge(endpoint: str, keys: Keys, actors: list[tuple[str, str]], stop: threading.Event, out: list) -> None:
    """A plain Zenoh session (no secret, no credentials) at the run's endpoint, as early as it can be, declaring the
    run's liveliness tokens and holding them until told to stop; `out` gets what it was connected to."""
    session = open_session(connect=[endpoint])  # a peer: it dials again and again until the hub listens
    try:
        tokens = [session.liveliness().declare_token(keys.alive(role, ident)) for role, ident in actors]
        seen: set[str] = set()
        while not stop.wait(0.1):
            seen |= {str(z) for z in [*session.info.routers_zid(), *session.info.peers_zid()]}
        out.append(seen)
        for t in tokens:
            t.undeclare()
    finally:
        session.close()


def test_forged_liveliness_tokens_during_start_up_change_nothing(tmp_path: Path) -> None:
    common = ["run", str(EXAMPLES / "chain4.toml"), "--placement", "process", "--epochs", "2", "--steps", "40"]
    common += ["--seed", "3", "--no-progress", *LOCKSTEP_ARGS]

    def run(name: str, port: int) -> dict:
        out = tmp_path / name
        args = [*common, "--out", str(out), "--run-id", name, "--listen", f"tcp/127.0.0.1:{port}"]
        assert cli_main(args) == 0
        return json.loads((out / "summary.json").read_text())

    clean = run("clean", free_port())
    port = free_port()
    actors = [("supervisor", "main"), ("sim", "sim"), *(("agent", f"a{i}") for i in range(1, 5))]
    stop, joined = threading.Event(), []
    forger = threading.Thread(target=_forge, args=(f"tcp/127.0.0.1:{port}", Keys("forged"), actors, stop, joined))
    forger.start()  # before the run: its tokens are declared while the swarm starts
    try:
        forged = run("forged", port)
    finally:
        stop.set()
        forger.join(30)
    assert joined == [set()], "the stranger joined the run's network"
    assert not forged["error"] and forged["missed_cmds"] == clean["missed_cmds"] == 0
    assert forged["final_error"] == clean["final_error"]
    assert forged["mean_error"] == clean["mean_error"]


def test_a_100_joint_chain_runs_in_one_process(tmp_path):
    """The single placement runs a step down and back up a chain as nested calls (runtime/node.py's inline
    handlers): a 100-joint chain nested 200 deep and its root ended in RecursionError six times, then the run gave up.
    Past INLINE_DEPTH the step goes through the mailbox; the run ends with every agent as it started."""
    robot = chain_file(100, tmp_path / "chain100.toml")
    out = tmp_path / "run"
    args = ["run", str(robot), "--placement", "single", "--epochs", "1", "--steps", "3", "--out", str(out)]
    assert cli_main([*args, "--run-id", "c100", "--no-progress"]) == 0
    events = [json.loads(line) for line in (out / "events.jsonl").read_text().splitlines()]
    assert not [e for e in events if e["event"] in ("exited", "restart")], events
    rows = [json.loads(line) for line in (out / "metrics.jsonl").read_text().splitlines()]
    assert len(rows) == 1


def test_a_robot_past_pybullets_link_limit_is_refused_in_one_line_before_anything_starts(tmp_path, capsys):
    """PyBullet reads links 0-126 of a body: a chain of 126 joints (and its tip link) loads, one of 127 is refused
    when the run file is read, in one line, instead of failing in the sim's first getLinkState."""
    from kinswarm.actors.files.runfile import load_run

    assert load_run(chain_file(126, tmp_path / "chain126.toml")).topo().name == "chain126"
    out = tmp_path / "run"
    assert cli_main(["run", str(chain_file(127, tmp_path / "chain127.toml")), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "128 links" in err and "at most 127" in err, err
    assert not out.exists()
