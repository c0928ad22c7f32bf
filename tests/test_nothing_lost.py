"""Nothing lost, nothing cryptic: a run directory is written by one run, once; every bad input is one line before
anything is spawned; the readouts say what happened. (Stalls: tests/test_stalls.py; generated inputs:
tests/test_fuzz.py.)"""

from __future__ import annotations

import hashlib
import json
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import EXAMPLES, ROOT, free_port, swarm_pids
from kinswarm.actors.cli.commands import main as cli

CHAIN4 = str(EXAMPLES / "chain4.toml")
KINSWARM = [sys.executable, "-m", "kinswarm.actors.cli.entry"]
SMALL = ["--epochs", "1", "--steps", "30", "--no-progress"]


def _digests(d: Path) -> dict[str, str]:
    return {
        str(p.relative_to(d)): hashlib.sha256(p.read_bytes()).hexdigest() for p in sorted(d.rglob("*")) if p.is_file()
    }


def _one_line_error(capsys: pytest.CaptureFixture, *parts: str) -> str:
    err = capsys.readouterr().err.strip()
    assert err.startswith("kinswarm: error: ") and "\n" not in err and "Traceback" not in err, err
    for p in parts:
        assert p in err, err
    return err


@pytest.mark.timeout(120)
def test_a_run_directory_is_written_once(tmp_path, capsys):
    """Case 1: a second run into a directory that holds a run is refused, the first's files untouched (byte for byte),
    and nothing of the second is spawned (it would have dialled the first run's port)."""
    out = tmp_path / "reuse"
    assert (
        cli(["run", CHAIN4, *SMALL, "--run-id", "reuse", "--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}"])
        == 0
    )
    capsys.readouterr()
    before = _digests(out)
    code = cli(
        ["run", CHAIN4, *SMALL, "--run-id", "reuse", "--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}"]
    )
    assert code == 2
    _one_line_error(capsys, str(out), "already holds a run")
    assert _digests(out) == before


@pytest.mark.timeout(180)
def test_two_runs_with_one_id_at_once(tmp_path):
    """Case 2: started together into one directory, one runs and the other is refused before it spawns anything."""
    out = tmp_path / "twin"
    args = ["run", CHAIN4, "--epochs", "3", "--steps", "200", "--no-progress", "--run-id", "twin", "--out", str(out)]
    procs = [
        subprocess.Popen(
            [*KINSWARM, *args, "--listen", f"tcp/127.0.0.1:{free_port()}"],
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        for _ in range(2)
    ]
    results = [p.communicate(timeout=150) for p in procs]
    codes = sorted(p.returncode for p in procs)
    assert codes == [0, 2], results
    refused = next(err for (o, err), p in zip(results, procs, strict=True) if p.returncode == 2)
    assert "another run is writing it now" in refused or "already holds a run" in refused, refused
    summary = json.loads((out / "summary.json").read_text())
    assert summary["run_id"] == "twin" and len(summary["final_error"]) == 3 and not summary["error"]
    assert swarm_pids(str(out / "config.json")) == []


@pytest.mark.parametrize(
    ("args", "says"),
    [
        (["run", CHAIN4, "--out", "{file}"], "a file, not a directory"),
        (["run", CHAIN4, "--out", "{file}/sub"], "is a file, not a directory"),
        (["run", CHAIN4, "--out", "/proc/kinswarm-nope"], "--out /proc/kinswarm-nope"),
        (["experiment", "cost", "--quick", "--out", "{file}"], "a file, not a directory"),
        (["certs", str(ROOT / "deploy" / "two-hosts.toml"), "--out", "{file}"], "a file, not a directory"),
        (["run", CHAIN4, "--goal=100,100"], "task.goal: (100, 100) lies 141 from the robot's base"),
        (["run", CHAIN4, "--scenario", str(ROOT / "scenarios" / "paper-recovery.toml")], "it would never fire"),
        (["run", CHAIN4, "--seed", "-1"], "run.seed: expected an integer >= 0"),
        (["run", CHAIN4, "--listen", "garbage"], "--listen: expected an endpoint like tcp/127.0.0.1:7447"),
        (["run", CHAIN4, "--from", str(ROOT / "examples")], "no such checkpoint"),
        (["fault", "demo", "freeze", "a1", "--for", "-5s"], "--for: expected a duration > 0"),
        (["report", "{dir}"], "not a run directory"),
    ],
)
def test_bad_input_is_one_line_before_anything_starts(tmp_path, capsys, args, says):
    """Cases 4 and 5: each is refused with one line naming what is wrong; no run directory appears."""
    (tmp_path / "file").write_text("x")
    args = [a.format(file=tmp_path / "file", dir=tmp_path) for a in args]
    if "--out" not in args and args[0] == "run":
        args += ["--out", str(tmp_path / "out")]
    assert cli([*args, *(["--no-progress"] if args[0] == "run" else [])]) == 2
    _one_line_error(capsys, says)
    assert not (tmp_path / "out").exists()


@pytest.mark.timeout(120)
def test_from_a_run_of_another_robot(tmp_path, capsys):
    trained = tmp_path / "chain"
    assert cli(["run", CHAIN4, *SMALL, "--out", str(trained), "--listen", f"tcp/127.0.0.1:{free_port()}"]) == 0
    capsys.readouterr()
    assert cli(["run", str(EXAMPLES / "corridor7.toml"), "--from", str(trained), "--out", str(tmp_path / "o")]) == 2
    _one_line_error(capsys, "a run of robot 'chain4'", "not of this run's 'corridor7'")


def test_ctrl_c_while_starting_is_a_clean_exit(tmp_path):
    """Case 4: Ctrl-C in the first tenths of a second (while the imports run): no traceback, no process left."""
    for delay in (0.15, 0.2, 0.3, 0.45, 0.6):
        out = tmp_path / f"c{delay}"
        p = subprocess.Popen(
            [*KINSWARM, "run", CHAIN4, *SMALL, "--out", str(out), "--listen", f"tcp/127.0.0.1:{free_port()}"],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        )  # fmt: skip
        time.sleep(delay)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=60)
        assert "Traceback" not in err and p.returncode in (0, 130), (delay, err[-800:])
        assert swarm_pids(str(out / "config.json")) == []


@pytest.mark.timeout(120)
def test_the_readouts_say_what_happened(tmp_path, capsys):
    """Case 6: status after the end says how it ended; fault says what it applied; report recovers every whole row
    of a torn metrics file and says what it left out."""
    out = tmp_path / "r"
    assert cli(["run", CHAIN4, *SMALL, "--epochs", "2", "--run-id", "rd", "--out", str(out), "--listen",
                f"tcp/127.0.0.1:{free_port()}"]) == 0  # fmt: skip
    capsys.readouterr()
    assert cli(["status", "rd", "--run-dir", str(out), "--watch"]) == 0
    assert "run rd finished (2 epochs, final error" in capsys.readouterr().out
    torn = tmp_path / "torn"
    shutil.copytree(out, torn)
    text = (torn / "metrics.jsonl").read_text()
    (torn / "metrics.jsonl").write_text(text[: -len(text.splitlines()[-1]) // 2])  # a killed writer's last row
    assert cli(["report", str(torn)]) == 0
    io = capsys.readouterr()
    assert "metrics.jsonl:2: not a whole row" in io.err and "learning_curve.png" in io.out


@pytest.mark.timeout(120)
def test_status_and_fault_on_a_live_run(tmp_path):
    out = tmp_path / "live"
    args = ["run", CHAIN4, "--epochs", "40", "--steps", "300", "--no-progress", "--run-id", "lv", "--out", str(out)]
    p = subprocess.Popen([*KINSWARM, *args, "--listen", f"tcp/127.0.0.1:{free_port()}"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)  # fmt: skip
    try:
        deadline = time.monotonic() + 60
        while not (out / "metrics.jsonl").exists() or not (out / "metrics.jsonl").read_text():
            assert time.monotonic() < deadline and p.poll() is None
            time.sleep(0.2)
        run = lambda *a: subprocess.run([*KINSWARM, *a, "--run-dir", str(out)], capture_output=True, text=True)  # noqa: E731
        status = run("status", "lv")
        head, *rows = status.stdout.splitlines()
        assert "epoch " in head and " of 0-39" in head, status.stdout
        a2 = next(r for r in rows if r.startswith("a2 "))
        assert "°" in a2, status.stdout  # the joints are there, not "-"
        lock = run("fault", "lv", "lock", "a2")
        assert lock.returncode == 0 and "lock a2: applied" in lock.stdout, lock.stdout + lock.stderr
    finally:
        p.send_signal(signal.SIGINT)
        p.communicate(timeout=60)
    assert swarm_pids(str(out / "config.json")) == []
