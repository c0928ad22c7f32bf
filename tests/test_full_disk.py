"""A run whose disk refuses it: full (a 1 MiB tmpfs), or its directory made read-only while it runs. It ends with one
line naming the file and the cause, no traceback, its checkpoints and whole rows kept; `--resume` completes once the
cause is gone. A record left with a torn last line is ended before the next row is appended."""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from pathlib import Path

import pytest
from conftest import EXAMPLES, LOCKSTEP_ARGS, swarm_pids
from kinswarm.actors.supervisor.recorder import Recorder
from kinswarm.protocol.messages import EpochDone

CHAIN4 = str(EXAMPLES / "chain4.toml")
KINSWARM = [sys.executable, "-m", "kinswarm.actors.cli.entry"]
NOBODY = 65534


def run_argv(out: Path, epochs: int, steps: int, placement: str) -> list[str]:
    return [
        *KINSWARM, "run", CHAIN4, "--epochs", str(epochs), "--steps", str(steps), "--seed", "3",
        "--placement", placement, "--run-id", out.name, "--out", str(out), "--no-progress", *LOCKSTEP_ARGS,
    ]  # fmt: skip


def rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def one_clear_end(stderr: str, *parts: str) -> None:
    """No traceback anywhere; the last line says the run failed, naming the file and the cause."""
    assert "Traceback" not in stderr, stderr
    last = stderr.strip().splitlines()[-1]
    assert last.startswith("kinswarm: the run failed: ") and "--resume" in last, stderr
    for part in parts:
        assert part in last, stderr


@contextlib.contextmanager
def tmpfs(size: str) -> Iterator[Path]:
    """A tmpfs of `size` mounted on a fresh directory (skipped where this machine will not mount one)."""
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("mounting a tmpfs needs root and mount(8)")
    where = Path(tempfile.mkdtemp(prefix="kinswarm-tmpfs-"))
    r = subprocess.run(["mount", "-t", "tmpfs", "-o", f"size={size}", "tmpfs", str(where)], capture_output=True)
    if r.returncode != 0:
        where.rmdir()
        pytest.skip(f"this machine does not mount a tmpfs here: {r.stderr.decode().strip()}")
    try:
        yield where
    finally:
        subprocess.run(["umount", "-l", str(where)], check=False)
        where.rmdir()


@pytest.mark.slow  # a reference run, a failed run and its resume: minutes on 2 cores (`pytest -m slow`)
@pytest.mark.timeout(600)
def test_a_run_on_a_full_disk_fails_in_one_line_and_resumes_once_there_is_room(tmp_path):
    """Process placement: the agents' checkpoints and the supervisor's records fill a 1 MiB tmpfs. The run fails in
    one line, is resumable as it is, and once the tmpfs is enlarged `--resume` ends as the run would have."""
    epochs, steps = 8, 300
    ref = tmp_path / "ref"
    p = subprocess.run(run_argv(ref, epochs, steps, "process"), capture_output=True, text=True, timeout=400)
    assert p.returncode == 0, p.stderr
    want = json.loads((ref / "summary.json").read_text())["final_error"]
    with tmpfs("1M") as disk:
        out = disk / "full"
        p = subprocess.run(run_argv(out, epochs, steps, "process"), capture_output=True, text=True, timeout=400)
        assert p.returncode == 1, p.stdout + p.stderr
        one_clear_end(p.stderr, str(out), "No space left on device")
        assert not swarm_pids(str(out / "config.json"))
        done = len(rows(out / "metrics.jsonl"))
        assert 0 < done < epochs, "the disk did not fill in the middle of the run"

        subprocess.run(["mount", "-o", "remount,size=16M", str(disk)], check=True)
        p = subprocess.run([*KINSWARM, "run", "--resume", str(out), "--no-progress"], capture_output=True, text=True)
        assert p.returncode == 0, p.stderr
        assert "Traceback" not in p.stderr, p.stderr
        summary = json.loads((out / "summary.json").read_text())
        assert summary["final_error"] == want and not summary["error"]
        assert [r["epoch"] for r in rows(out / "metrics.jsonl")] == list(range(epochs))
        (resume,) = [r for r in rows(out / "events.jsonl") if r["event"] == "resume"]
        assert "after it failed (" in resume["detail"] and "No space left on device" in resume["detail"], resume


@pytest.mark.slow  # a reference run, a failed run and its resume: minutes on 2 cores (`pytest -m slow`)
@pytest.mark.timeout(600)
def test_a_run_whose_directory_is_made_read_only_fails_in_one_line_and_resumes_once_writable():
    """The run directory made read-only (chmod a-w) while the run trains, the run's user without root's override: the
    epochs train (their files are open, the checkpoints in agents/), then summary.json cannot be made: one line, and
    the run as a killed one leaves it. Writable again, `--resume` writes its summary."""
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("running the run as another user needs root and setpriv(1)")
    home = Path(tempfile.mkdtemp(prefix="kinswarm-ro-"))  # a user's own directory, outside root's 0700 tmp dirs
    try:
        os.chown(home, NOBODY, NOBODY)
        out = home / "ro"
        user = ["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups", "--"]
        env = {**os.environ, "HOME": str(home), "TMPDIR": str(home)}  # its own: root's files in /tmp are not its
        p = subprocess.Popen(
            [*user, *run_argv(out, 4, 200, "single")], stderr=subprocess.PIPE, text=True, env=env, cwd=home
        )
        while not ((out / "metrics.jsonl").exists() and (out / "metrics.jsonl").read_text()):
            assert p.poll() is None, p.communicate()[1]
            time.sleep(0.02)
        out.chmod(0o555)
        err = p.communicate(timeout=300)[1]
        assert p.returncode == 1, err
        one_clear_end(err, str(out / "summary.json"), "Permission denied")
        assert not (out / "summary.json").exists()
        assert [r["epoch"] for r in rows(out / "metrics.jsonl")] == [0, 1, 2, 3]

        out.chmod(0o755)
        p = subprocess.run(
            [*user, *KINSWARM, "run", "--resume", str(out), "--no-progress"],
            capture_output=True, text=True, env=env, cwd=home, timeout=300,
        )  # fmt: skip
        assert p.returncode == 0, p.stderr
        summary = json.loads((out / "summary.json").read_text())
        assert summary["epochs"] == 4 and not summary["error"]
    finally:
        shutil.rmtree(home, ignore_errors=True)


def test_a_torn_last_line_is_ended_before_the_next_row(tmp_path):
    """A writer killed mid-row left events.jsonl and metrics.jsonl torn: the next rows are whole rows of their own."""
    whole = json.dumps({"epoch": 0, "event": "restart"})
    (tmp_path / "events.jsonl").write_text(whole + "\n" + whole[:9])
    (tmp_path / "metrics.jsonl").write_text('{"epoch": 0, "final_err')
    rec = Recorder(tmp_path)
    rec.open_events()
    rec.open_metrics()
    rec.event(1, 5, "restored", "a2", "checkpoint")
    done = EpochDone(
        epoch=1, steps=2, final_error=0.25, mean_error=0.5, errors=[0.5, 0.25], final_angles={"a1": 0.0},
        missed_cmds=0, seconds=0.1, max_step_seconds=0.05,
    )  # fmt: skip
    rec.epoch(done)
    rec.close()
    events = (tmp_path / "events.jsonl").read_text().splitlines()
    assert events[:2] == [whole, whole[:9]]
    assert json.loads(events[2])["event"] == "restored" and len(events) == 3
    metrics = (tmp_path / "metrics.jsonl").read_text().splitlines()
    assert json.loads(metrics[1])["final_error"] == 0.25 and len(metrics) == 2
    (tmp_path / "poses.jsonl").write_text("")  # an empty record stays empty: nothing to end
    Recorder(tmp_path).open_metrics()
    assert (tmp_path / "poses.jsonl").read_text() == ""
