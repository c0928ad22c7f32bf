"""A run directory's life as its tools see it: claimed only once the run has begun (a failed start leaves nothing
that stops its retry; a run that began keeps its data, however it ends), and read by `report`, `animate`, `view`,
`fault` and `status` whatever state it is in: half-made, failed, running or finished — one line, or a note that
says what the output covers, never a traceback or a silent empty result."""

from __future__ import annotations

import fcntl
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import EXAMPLES, free_port, run_config, swarm_pids
from kinswarm.actors.cli.commands import main as cli
from kinswarm.actors.runtime.net import zenoh_reason

CHAIN4 = str(EXAMPLES / "chain4.toml")
KINSWARM = [sys.executable, "-m", "kinswarm.actors.cli.entry"]
SMALL = ["--epochs", "1", "--steps", "30", "--no-progress", "--placement", "single"]
START_FILES = {".lock", "config.json", "run.toml", "metrics.jsonl", "net"}


@pytest.fixture
def busy_port() -> Iterator[int]:
    """A port another program listens on for the test's length."""
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        s.listen()
        yield s.getsockname()[1]


def one_line_error(capsys: pytest.CaptureFixture, *parts: str) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("kinswarm: error: ") and "\n" not in err and "Traceback" not in err, err
    assert ".rs:" not in err and ".cargo" not in err, err  # no Rust source path
    for p in parts:
        assert p in err, err
    return err


def run_args(out: Path, port: int, run_id: str = "x") -> list[str]:
    return ["run", CHAIN4, *SMALL, "--run-id", run_id, "--out", str(out), "--listen", f"tcp/127.0.0.1:{port}"]


# -- claimed once the run has begun -------------------------------------------------------------------------------


@pytest.mark.timeout(180)
def test_a_start_on_a_taken_port_leaves_nothing_and_the_retry_runs(tmp_path, capsys, busy_port):
    out = tmp_path / "runs" / "x"
    assert cli(run_args(out, busy_port)) == 2
    one_line_error(capsys, f"tcp/127.0.0.1:{busy_port} is taken")
    assert not out.exists()  # made by the start, removed with it
    assert cli(run_args(out, free_port())) == 0  # the same --out (and --run-id), a free port
    assert (out / "summary.json").is_file() and json.loads((out / "summary.json").read_text())["epochs"] == 1
    capsys.readouterr()
    # a finished run: `fault` answers from its summary, without asking a supervisor that is gone
    assert cli(["fault", "x", "lock", "a2", "--run-dir", str(out)]) == 2
    one_line_error(capsys, "run x finished at ", "; nothing to fault")


@pytest.mark.timeout(120)
def test_a_failed_start_in_a_directory_that_was_there_leaves_it_as_it_was(tmp_path, capsys, busy_port):
    out = tmp_path / "mine"
    out.mkdir()
    (out / "notes.txt").write_text("the user's own\n")
    assert cli(run_args(out, busy_port)) == 2
    one_line_error(capsys, "is taken")
    assert sorted(os.listdir(out)) == ["notes.txt"] and (out / "notes.txt").read_text() == "the user's own\n"


@pytest.mark.timeout(120)
def test_a_run_that_began_keeps_its_data_when_it_crashes(tmp_path, monkeypatch):
    """Once the supervisor runs, the directory is the run's: a crash does not take it away."""
    from kinswarm.actors.run.launch import run_swarm
    from kinswarm.actors.supervisor import Supervisor

    async def crash(self: Supervisor) -> None:
        (Path(self.cfg.out) / "events.jsonl").write_text("")  # as the supervisor's first act does
        raise RuntimeError("the supervisor crashed")

    monkeypatch.setattr(Supervisor, "run", crash)
    out = tmp_path / "crashed"
    cfg = run_config(CHAIN4, run_id="c", out=str(out), listen=f"tcp/127.0.0.1:{free_port()}", placement="single")
    with pytest.raises(RuntimeError, match="crashed"):
        run_swarm(cfg, cfg.topo())
    assert {"config.json", "run.toml", "metrics.jsonl", "events.jsonl"} <= set(os.listdir(out))
    assert cli(run_args(out, free_port(), "c")) == 2  # it holds a run: written once


def start_leftovers(out: Path, run_id: str = "x") -> None:
    """What a start killed before its run began leaves (or an older kinswarm's failed start)."""
    out.mkdir(parents=True)
    run_config(CHAIN4, run_id=run_id, out=str(out)).write(out / "config.json")
    (out / "run.toml").write_text("[run]\n")
    (out / "metrics.jsonl").write_text("")
    (out / ".lock").write_text("12345\n")
    (out / "net").mkdir()
    (out / "net" / "cli.json").write_text("{}\n")


@pytest.mark.timeout(180)
def test_a_failed_starts_leftovers_do_not_block_the_retry_but_a_runs_data_and_a_live_lock_do(tmp_path, capsys):
    began = tmp_path / "began"
    start_leftovers(began)
    (began / "events.jsonl").write_text("")  # the supervisor had begun: a run, not leftovers
    assert cli(run_args(began, free_port())) == 2
    one_line_error(capsys, "already holds a run")
    live = tmp_path / "live"
    start_leftovers(live)
    with open(live / ".lock") as f:  # a start under way holds the lock
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        assert cli(run_args(live, free_port())) == 2
        one_line_error(capsys, "already holds a run")
    assert set(os.listdir(live)) == START_FILES  # untouched
    left = tmp_path / "left"
    start_leftovers(left)
    assert cli(run_args(left, free_port())) == 0
    assert json.loads((left / "summary.json").read_text())["epochs"] == 1


@pytest.mark.timeout(60)
def test_port_0_is_refused_before_anything_is_made(tmp_path, capsys):
    out = tmp_path / "zero"
    assert cli(run_args(out, 0)) == 2
    one_line_error(capsys, "--listen tcp/127.0.0.1:0: port 0")
    assert not out.exists()


def plan(tmp_path: Path, listen: str, actors: str) -> Path:
    path = tmp_path / "plan.toml"
    path.write_text(
        f'[plan]\nname = "p"\nleader = "h"\n[run]\nfile = "{CHAIN4}"\n'
        f'[[host]]\nname = "h"\naddress = "127.0.0.1"\nlisten = "{listen}"\nactors = {actors}\n'
    )
    return path


@pytest.mark.timeout(120)
@pytest.mark.parametrize(
    ("actors", "port", "says"),
    [
        ('["sim", "a1", "a2"]', None, "agent 'a3' runs nowhere"),
        ('["sim", "agents"]', 0, "host h.listen: tcp/127.0.0.1:0: port 0"),
        ('["sim", "agents"]', "busy", "is taken"),
    ],
)
def test_up_leaves_no_directory_when_its_start_fails(tmp_path, capsys, busy_port, actors, port, says):
    port = busy_port if port == "busy" else free_port() if port is None else port
    out = tmp_path / "up"
    argv = ["up", str(plan(tmp_path, f"tcp/127.0.0.1:{port}", actors)), "--host", "h", "--out", str(out)]
    assert cli([*argv, "--run-id", "u", "--epochs", "1", "--steps", "30", "--no-progress"]) == 2
    one_line_error(capsys, says)
    assert not out.exists()


# -- read in any state ----------------------------------------------------------------------------------------------


def epochs_dir(out: Path, epochs: int, run_id: str = "r", planned: int = 10) -> Path:
    """A run directory with `epochs` whole epochs of metrics and poses (and no summary)."""
    start_leftovers(out, run_id)
    cfg = run_config(CHAIN4, run_id=run_id, out=str(out), steps=20, epochs=planned)
    cfg.write(out / "config.json")
    (out / "events.jsonl").write_text("")
    rows, poses = [], []
    for e in range(epochs):
        errs = [2.0 - 0.05 * s for s in range(20)]
        angles = {a: 10.0 for a in ("a1", "a2", "a3", "a4")}
        row = {"epoch": e, "final_error": errs[-1], "mean_error": sum(errs) / 20, "steps": 20, "seconds": 0.1}
        rows.append({**row, "missed_cmds": 0, "errors": errs, "final_angles_deg": angles})
        poses.append({"epoch": e, "angles_deg": [[10.0 + s, 10.0, 10.0, 10.0] for s in range(20)]})
    (out / "metrics.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    (out / "poses.jsonl").write_text("".join(json.dumps(p) + "\n" for p in poses))
    return out


READERS = [["report"], ["animate"], ["view", "--save", "{tmp}/v.rrd"]]


def read(reader: list[str], out: Path, tmp: Path) -> int:
    if reader[0] == "view":
        pytest.importorskip("rerun")
    return cli([reader[0], str(out), *(a.format(tmp=tmp) for a in reader[1:])])


@pytest.mark.timeout(120)
@pytest.mark.parametrize("reader", READERS, ids=lambda r: r[0])
def test_a_directory_with_only_its_config_is_one_line(tmp_path, capsys, reader):
    out = tmp_path / "half"
    out.mkdir()
    run_config(CHAIN4, run_id="half", out=str(out)).write(out / "config.json")
    assert read(reader, out, tmp_path) == 2
    one_line_error(capsys, "run half never began", "no epoch")
    assert not (tmp_path / "v.rrd").exists()  # `view --save` wrote no empty recording


@pytest.mark.timeout(120)
@pytest.mark.parametrize("reader", READERS, ids=lambda r: r[0])
def test_a_failed_starts_directory_is_one_line(tmp_path, capsys, reader):
    start_leftovers(tmp_path / "failed", "failed")
    assert read(reader, tmp_path / "failed", tmp_path) == 2
    one_line_error(capsys, "run failed never began")
    assert not (tmp_path / "v.rrd").exists()


@pytest.mark.timeout(120)
@pytest.mark.parametrize("reader", READERS, ids=lambda r: r[0])
def test_a_run_that_ended_before_its_first_epoch_is_one_line(tmp_path, capsys, reader):
    out = epochs_dir(tmp_path / "zero", 0)
    (out / "summary.json").write_text(json.dumps({"run_id": "r", "epochs": 0, "interrupted": True, "error": None}))
    assert read(reader, out, tmp_path) == 2
    one_line_error(capsys, "run r was interrupted at ", "before its first epoch ended")
    assert not (tmp_path / "v.rrd").exists()


@pytest.mark.timeout(120)
@pytest.mark.parametrize("reader", READERS, ids=lambda r: r[0])
def test_a_running_run_is_read_with_a_note_of_what_is_covered(tmp_path, capsys, reader):
    out = epochs_dir(tmp_path / "running", 3)
    with open(out / ".lock") as f:  # the run's process holds its lock while it lives
        fcntl.flock(f, fcntl.LOCK_EX | fcntl.LOCK_NB)
        assert read(reader, out, tmp_path) == 0
        err = capsys.readouterr().err
        assert "run r is still running (3 of 10 epochs done)" in err and "covers epochs 0-2" in err, err
        (out / "metrics.jsonl").write_text("")
        (out / "poses.jsonl").write_text("")
        assert read(reader, out, tmp_path / "nothing") == 2  # no epoch done yet: nothing to read, said so
        one_line_error(capsys, "run r is still running and has not finished its first epoch")


@pytest.mark.timeout(120)
def test_a_killed_run_is_read_with_a_note_and_fault_and_status_say_it_is_not_running(tmp_path, capsys):
    out = epochs_dir(tmp_path / "killed", 2)
    assert cli(["report", str(out)]) == 0
    assert "run r stopped without its summary (killed?) after 2 of 10 epochs" in capsys.readouterr().err
    for argv in (["fault", "r", "lock", "a2"], ["status", "r"]):
        assert cli([*argv, "--run-dir", str(out)]) == 2
        one_line_error(capsys, "run r is not running (it was killed", "--connect ENDPOINT")
    start_leftovers(tmp_path / "failed", "f")
    assert cli(["status", "f", "--run-dir", str(tmp_path / "failed")]) == 2
    one_line_error(capsys, "run f is not running (its start failed")


@pytest.mark.timeout(120)
def test_a_supervisor_that_does_not_answer_is_one_line_without_rust_paths(tmp_path, capsys):
    out = epochs_dir(tmp_path / "r", 1)
    shutil.rmtree(out / "net")  # no endpoint the run wrote for its tools: the one given is tried once
    port = free_port()
    assert cli(["fault", "r", "lock", "a2", "--run-dir", str(out), "--connect", f"tcp/127.0.0.1:{port}"]) == 2
    one_line_error(capsys, f"cannot reach run r at tcp/127.0.0.1:{port}: nothing answers at tcp/127.0.0.1:{port}")


@pytest.mark.timeout(60)
def test_a_router_on_a_taken_port_is_one_line(capsys, busy_port):
    assert cli(["router", "--listen", f"tcp/127.0.0.1:{busy_port}"]) == 2
    one_line_error(capsys, f"tcp/127.0.0.1:{busy_port} is taken")


def test_zenoh_errors_in_a_users_words():
    at = " at /root/.cargo/git/checkouts/zenoh-9c599d5ef3e0480e/cc83980/io/zenoh-links/src/unicast.rs:338."
    bound = f"Can not create a new TCP listener bound to tcp/127.0.0.1:9: [127.0.0.1:9: Address already in use{at}]"
    assert zenoh_reason(RuntimeError(bound + at)) == "tcp/127.0.0.1:9 is taken: another program listens on that port"
    other = RuntimeError(f"Something new\n[inner{at}]{at}")
    assert zenoh_reason(other) == "Something new [inner]"


@pytest.mark.timeout(180)
def test_report_on_a_live_run_says_it_is_in_progress_and_fault_after_its_end_answers_at_once(tmp_path):
    """A real run, read while it trains, then stopped."""
    out = tmp_path / "live"
    args = ["run", CHAIN4, "--epochs", "500", "--steps", "30", "--no-progress", "--placement", "single"]
    args += ["--run-id", "lv", "--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}"]
    p = subprocess.Popen([*KINSWARM, *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        while not (out / "metrics.jsonl").exists() or not (out / "metrics.jsonl").read_text():
            assert p.poll() is None, p.communicate()
            time.sleep(0.2)  # ended by the test's timeout if training never starts
        r = subprocess.run([*KINSWARM, "report", str(out)], capture_output=True, text=True, timeout=120)
        assert r.returncode == 0 and "learning_curve.png" in r.stdout, r.stderr
        assert "kinswarm: run lv is still running (" in r.stderr, r.stderr
        assert "of 500 epochs done); the report covers epochs 0-" in r.stderr, r.stderr
    finally:
        p.send_signal(signal.SIGINT)
        try:
            p.communicate(timeout=60)
        finally:
            if p.poll() is None:
                p.kill()
                p.communicate()
    assert p.returncode == 130
    r = subprocess.run([*KINSWARM, "fault", "lv", "lock", "a2", "--run-dir", str(out)], capture_output=True, text=True,
                       timeout=60)  # fmt: skip
    assert r.returncode == 2 and "run lv was interrupted at " in r.stderr and "nothing to fault" in r.stderr, r.stderr
    assert swarm_pids(str(out / "config.json")) == []


# -- output that cannot be written ------------------------------------------------------------------------------------


def shell(command: str) -> subprocess.CompletedProcess[str]:
    """`command` in bash, with `kinswarm` this test's; PIPESTATUS says how kinswarm itself exited."""
    kinswarm = " ".join(KINSWARM)
    script = f'kinswarm() {{ {kinswarm} "$@"; }}; {command}; echo "exit=${{PIPESTATUS[0]}}" >&2'
    return subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=300)


def exit_of(r: subprocess.CompletedProcess[str]) -> int:
    return int(r.stderr.strip().splitlines()[-1].removeprefix("exit="))


def answered(command: str) -> subprocess.CompletedProcess[str]:
    """`shell(command)`, asked again while the run's supervisor is too busy to answer (a loaded machine): what this
    file tests is the output, not how fast a status comes."""
    for _ in range(10):
        r = shell(command)
        if "no status from run" not in r.stderr:
            return r
    return r


@pytest.mark.timeout(600)
def test_output_to_a_closed_pipe_or_a_full_disk_is_one_line(tmp_path, capsys):
    """A reader gone before the output (`| true`), or after the lines it wanted (`| head -1`, `status --watch |
    head -3` of a live run): a quiet end with SIGPIPE's code, no traceback. `status RUN > /dev/full`: one line naming
    /dev/full and the cause."""
    ended = tmp_path / "ended"
    assert cli(["run", CHAIN4, *SMALL, "--run-id", "ended", "--out", str(ended)]) == 0
    capsys.readouterr()
    for command in (f"kinswarm status {ended} | true", f"kinswarm report {ended} | true"):
        gone = shell(command)
        assert gone.stderr == f"exit={128 + signal.SIGPIPE}\n", (command, gone.stderr)
    full = shell(f"kinswarm status {ended} > /dev/full")
    assert full.stderr.splitlines() == [
        "kinswarm: error: cannot write the output to /dev/full: No space left on device",
        "exit=1",
    ], full.stderr

    out = tmp_path / "live"
    args = ["run", CHAIN4, "--epochs", "200", "--steps", "300", "--no-progress", "--placement", "single"]
    p = subprocess.Popen([*KINSWARM, *args, "--run-id", "pipe", "--out", str(out)], stderr=subprocess.PIPE, text=True)
    try:
        while not ((out / "metrics.jsonl").exists() and (out / "metrics.jsonl").read_text()):
            assert p.poll() is None, p.communicate()[1]
            time.sleep(0.05)
        once = answered(f"kinswarm status {out} | head -1")
        assert once.stdout.startswith("run pipe  epoch ") and once.stdout.count("\n") == 1, once
        assert "Traceback" not in once.stderr and exit_of(once) in (0, 128 + signal.SIGPIPE), once
        watched = answered(f"kinswarm status --watch {out} | head -3")
        assert watched.stdout.count("\n") == 3 and "Traceback" not in watched.stderr, watched
        assert exit_of(watched) == 128 + signal.SIGPIPE, watched
    finally:
        p.send_signal(signal.SIGINT)
        p.communicate(timeout=120)
    assert swarm_pids(str(out / "config.json")) == []


@pytest.mark.timeout(300)
def test_view_saved_into_a_directory_is_one_line(tmp_path, capsys):
    out = tmp_path / "v"
    assert cli(["run", CHAIN4, *SMALL, "--run-id", "v", "--out", str(out)]) == 0
    capsys.readouterr()
    for given, says in ((f"{tmp_path}/", "a directory; give the recording's file"), (f"{tmp_path}/nowhere/", "a dire")):
        assert cli(["view", str(out), "--save", given]) == 2
        err = capsys.readouterr().err.strip()
        if "kinswarm[viewer]" in err:  # the viewer's extra is not installed: that is the one line then
            pytest.skip(err)
        assert err.startswith("kinswarm: error: --save ") and says in err and "\n" not in err, err
        assert "Traceback" not in err
    assert not (tmp_path / "nowhere").exists()


@pytest.mark.timeout(120)
def test_status_waits_for_a_run_that_is_there_but_silent_and_gives_up_once_it_is_gone(tmp_path, capsys):
    """A run whose process holds its directory but sends no status yet (a 100-agent start forks for seconds first)
    is waited for, said once; once nothing holds the directory, status gives up in one line."""
    import threading

    from kinswarm.actors.runtime.net import open_session

    out = epochs_dir(tmp_path / "starting", 0)
    port = free_port()
    endpoint = f"tcp/127.0.0.1:{port}"
    session = open_session(listen=[endpoint])  # where the run's hub would be: reachable, but nothing speaks
    lock = open(out / ".lock")  # noqa: SIM115 (closed by the thread below)
    fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
    release = threading.Timer(8.0, lock.close)  # the run's process goes away while status waits
    release.start()
    try:
        t0 = time.monotonic()
        assert cli(["status", "r", "--run-dir", str(out), "--connect", endpoint]) == 2
        waited = time.monotonic() - t0
    finally:
        release.cancel()
        lock.close()
        session.close()
    err = capsys.readouterr().err
    assert "run r is running but has sent no status for 5 s" in err and "still waiting" in err, err
    assert err.count("still waiting") == 1, err
    assert "kinswarm: error: no status from run r" in err, err
    assert waited >= 8.0, waited  # it did not give up while the run's process was there
