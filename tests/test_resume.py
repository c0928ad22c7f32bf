"""`kinswarm run --resume RUN-DIR`: a run whose whole process tree was SIGKILLed goes on from its last complete
checkpoint, every epoch once in its records; in `single` placement with a checkpoint every epoch it ends exactly as
the run would have without the crash. What cannot be resumed is one line, and the directory is left as it was."""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from conftest import EXAMPLES, LIVE, LOCKSTEP_ARGS, swarm_pids
from kinswarm.actors.cli.commands import main as cli

CHAIN4 = str(EXAMPLES / "chain4.toml")
KINSWARM = [sys.executable, "-m", "kinswarm.actors.cli.entry"]
EPOCHS = 8


def run_args(run_id: str, out: Path, placement: str, steps: int) -> list[str]:
    return [
        "run", CHAIN4, "--epochs", str(EPOCHS), "--steps", str(steps), "--seed", "3", "--placement", placement,
        "--set", "run.checkpoint_every=1", "--run-id", run_id, "--out", str(out), "--no-progress", *LOCKSTEP_ARGS,
    ]  # fmt: skip


def rows(path: Path) -> list[dict]:
    return [json.loads(line) for line in path.read_text().splitlines()]


def killed_in_epoch(out: Path, argv: list[str], k: int, whole_tree: bool) -> None:
    """Start the run in its own process group; once `k` epochs are done, SIGKILL the group (the whole tree) or the
    supervisor alone (its actors then leave: PR_SET_PDEATHSIG)."""
    p = subprocess.Popen([*KINSWARM, *argv], stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        metrics = out / "metrics.jsonl"
        while not (metrics.exists() and metrics.read_text().count("\n") >= k):  # whole rows: a row may be mid-write
            assert p.poll() is None, p.communicate()[0].decode()
            time.sleep(0.02)
    finally:
        if whole_tree:
            os.killpg(p.pid, signal.SIGKILL)
        else:
            p.kill()
        p.wait()
    deadline = time.monotonic() + 30
    while swarm_pids(str(out / "config.json")):  # the actors of a killed supervisor leave on their own
        assert time.monotonic() < deadline, "actors of the killed supervisor still run"
        time.sleep(0.1)
    assert not (out / "summary.json").exists()
    assert (out / "metrics.jsonl").read_text().count("\n") < EPOCHS, "the run ended before it was killed"


def resumes(events: Path) -> list[dict]:
    return [r for r in rows(events) if r["event"] == "resume"]


@pytest.mark.timeout(600)
def test_a_killed_single_run_resumes_to_the_uninterrupted_result(tmp_path):
    ref, cut = tmp_path / "ref", tmp_path / "cut"
    assert cli(run_args("ref", ref, "single", 400)) == 0
    killed_in_epoch(cut, run_args("cut", cut, "single", 400), k=3, whole_tree=True)
    assert cli(["run", "--resume", str(cut), "--no-progress"]) == 0

    want, got = (json.loads((d / "summary.json").read_text()) for d in (ref, cut))
    assert got["final_error"] == want["final_error"]
    assert got["mean_error"] == want["mean_error"]
    assert [r["epoch"] for r in rows(cut / "metrics.jsonl")] == list(range(EPOCHS))
    assert [r["epoch"] for r in rows(cut / "poses.jsonl")] == list(range(EPOCHS))
    assert rows(cut / "poses.jsonl") == rows(ref / "poses.jsonl")
    (resume,) = resumes(cut / "events.jsonl")
    assert 1 <= resume["epoch"] <= 3 and f"checkpoint of epoch {resume['epoch'] - 1}" in resume["detail"]
    restored = [r for r in rows(cut / "events.jsonl") if r["event"] == "restored"]
    assert sorted(r["target"] for r in restored) == ["a1", "a2", "a3", "a4"]
    for r in restored:  # every agent from the same checkpoint, its learned state as saved
        assert r["checkpoint_epoch"] == resume["epoch"] - 1 and r["epoch"] == resume["epoch"]
        saved, loaded = (part.split("=")[1] for part in r["detail"].split(": ", 1)[1].split(" ") if "=" in part)
        assert saved == loaded


@pytest.mark.timeout(600)
def test_a_process_run_whose_supervisor_was_killed_resumes_every_epoch_once(tmp_path):
    out = tmp_path / "p"
    killed_in_epoch(out, run_args("p", out, "process", 150), k=2, whole_tree=False)
    p = subprocess.run([*KINSWARM, "run", "--resume", str(out), "--no-progress"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["epochs"] == EPOCHS and len(summary["final_error"]) == EPOCHS and not summary["error"]
    assert [r["epoch"] for r in rows(out / "metrics.jsonl")] == list(range(EPOCHS))
    assert len(resumes(out / "events.jsonl")) == 1
    assert not swarm_pids(str(out / "config.json"))
    assert cli(["run", "--resume", str(out)]) == 2  # and now it has ended: resumed once, not twice


# -- what cannot be resumed -----------------------------------------------------------------------------------------


def snapshot(d: Path) -> dict[str, tuple[int, str]]:
    """Every file under `d`: its mtime and content hash (a directory left as it was has the same snapshot)."""
    return {
        str(p.relative_to(d)): (p.stat().st_mtime_ns, hashlib.sha256(p.read_bytes()).hexdigest())
        for p in sorted(d.rglob("*"))
        if p.is_file()
    }


@pytest.fixture(scope="module")
def ended(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A run that finished (single placement, one short epoch)."""
    out = tmp_path_factory.mktemp("ended") / "e"
    argv = ["run", CHAIN4, "--epochs", "1", "--steps", "30", "--placement", "single", "--run-id", "e"]
    assert cli([*argv, "--out", str(out), "--no-progress"]) == 0
    return out


def killed_copy(ended: Path, to: Path) -> Path:
    """The finished run as a killed one leaves it: its summary gone."""
    import shutil

    shutil.copytree(ended, to)
    (to / "summary.json").unlink()
    return to


def one_line(capsys: pytest.CaptureFixture, *parts: str) -> None:
    err = capsys.readouterr().err.strip()
    assert err.startswith("kinswarm: error: --resume ") and "\n" not in err and "Traceback" not in err, err
    for part in parts:
        assert part in err, err


@pytest.mark.timeout(120)
def test_what_cannot_be_resumed_is_one_line_and_changes_nothing(tmp_path, capsys, ended):
    empty = tmp_path / "empty"
    empty.mkdir()
    (empty / "notes.txt").write_text("mine\n")
    other = killed_copy(ended, tmp_path / "other")
    config = json.loads((other / "config.json").read_text())
    (other / "config.json").write_text(json.dumps({**config, "kinswarm": "0.0.1+run0"}))
    running = killed_copy(ended, tmp_path / "running")
    cases = [
        (empty, "holds no run (no config.json)"),
        (ended, "run e finished at", "nothing to resume"),
        (other, "a run made by kinswarm 0.0.1+run0", "resume it with that version"),
        (running, "run e is still running", "nothing to resume"),
    ]
    fd = os.open(running / ".lock", os.O_RDWR)
    fcntl.flock(fd, fcntl.LOCK_EX)  # as a live run holds it
    try:
        for d, *says in cases:
            before = snapshot(d)
            assert cli(["run", "--resume", str(d), "--no-progress"]) == 2, d
            one_line(capsys, *says)
            assert snapshot(d) == before, d
    finally:
        os.close(fd)
    assert cli(["run", "--resume", str(tmp_path / "nowhere")]) == 2
    one_line(capsys, "no such directory")
    assert not (tmp_path / "nowhere").exists()


@pytest.mark.timeout(120)
def test_a_file_or_a_corrupt_config_is_named_for_what_it_is(tmp_path, capsys, ended):
    """`--resume FILE` says it is a file; a config.json torn or overwritten says it is corrupt (not that the kinswarm
    that wrote it recorded no version); the directory is left as it was."""
    file = tmp_path / "notes.txt"
    file.write_text("mine\n")
    assert cli(["run", "--resume", str(file), "--no-progress"]) == 2
    one_line(capsys, "a file, not a run directory")
    for name, text in (("torn", None), ("garbage", "\x00\xff{"), ("list", "[1, 2]")):
        d = killed_copy(ended, tmp_path / name)
        whole = (d / "config.json").read_text()
        (d / "config.json").write_text(text if text is not None else whole[: len(whole) // 2])
        before = snapshot(d)
        assert cli(["run", "--resume", str(d), "--no-progress"]) == 2
        one_line(capsys, f"{d / 'config.json'} is corrupt", "cannot be resumed")
        assert snapshot(d) == before


@pytest.mark.timeout(60)
def test_resume_takes_nothing_that_would_change_the_run(tmp_path, capsys, ended):
    before = snapshot(ended)
    assert cli(["run", CHAIN4, "--resume", str(ended)]) == 2
    one_line(capsys, "give no RUN-FILE")
    assert cli(["run", "--resume", str(ended), "--epochs", "20"]) == 2
    one_line(capsys, "--epochs cannot change it")
    assert cli(["run", "--resume", str(ended), "--set", "run.seed=4"]) == 2
    one_line(capsys, "--set cannot change it")
    assert snapshot(ended) == before


@pytest.mark.timeout(180)
def test_a_crash_between_two_agents_checkpoints_resumes_from_the_one_all_hold(tmp_path):
    """The supervisor died while the agents saved epoch 2: a1 had saved it (epoch 1 now its .prev), the others had
    not (their newest is epoch 1). The run goes on from epoch 1, a1 from its .prev, and ends as without the crash."""
    out = tmp_path / "mid"
    argv = ["run", CHAIN4, "--epochs", "3", "--steps", "60", "--seed", "5", "--placement", "single", "--run-id", "m"]
    assert cli([*argv, "--out", str(out), "--no-progress", *LOCKSTEP_ARGS]) == 0
    whole = json.loads((out / "summary.json").read_text())["final_error"]
    (out / "summary.json").unlink()  # as the crash left it: epochs 0-2 recorded, no summary ...
    agents = out / "agents"
    for a in ("a2", "a3", "a4"):  # ... and a2-a4 still at epoch 1 (their epoch-2 save never happened)
        os.replace(agents / f"{a}.prev.npz", agents / f"{a}.npz")
    assert cli(["run", "--resume", str(out), "--no-progress"]) == 0
    assert json.loads((out / "summary.json").read_text())["final_error"] == whole
    assert [r["epoch"] for r in rows(out / "metrics.jsonl")] == [0, 1, 2]
    (resume,) = resumes(out / "events.jsonl")
    assert resume["epoch"] == 2 and "checkpoint of epoch 1; metrics rows dropped past it: 1" in resume["detail"]


@pytest.mark.timeout(600)
def test_a_run_whose_agents_hold_no_common_epoch_resumes_after_the_oldest_not_from_scratch(tmp_path):
    """a2 was down over two of the others' saves: its checkpoints (epoch 1) are older than theirs (epochs 2, 3), so no
    epoch is held by all. The run goes on from epoch 2 (a2 from its epoch 1, the others from their oldest, epoch 2),
    every epoch once, instead of throwing away every trained epoch and starting again."""
    base = ["run", CHAIN4, "--steps", "40", "--seed", "5", "--placement", "single", "--run-id", "m", "--no-progress"]
    early, out = tmp_path / "early", tmp_path / "run"
    assert cli([*base, "--epochs", "2", "--out", str(early), *LOCKSTEP_ARGS]) == 0
    assert cli([*base, "--epochs", "4", "--out", str(out), *LOCKSTEP_ARGS]) == 0
    (out / "summary.json").unlink()  # the crash: no summary ...
    agents = out / "agents"
    os.replace(early / "agents" / "a2.npz", agents / "a2.npz")  # ... and a2's newest checkpoint is of epoch 1
    (agents / "a2.prev.npz").unlink()
    assert cli(["run", "--resume", str(out), "--no-progress"]) == 0
    assert [r["epoch"] for r in rows(out / "metrics.jsonl")] == [0, 1, 2, 3]
    (resume,) = resumes(out / "events.jsonl")
    assert resume["epoch"] == 2 and "no epoch every agent holds" in resume["detail"], resume
    assert "metrics rows dropped past it: 2" in resume["detail"], resume


# -- a run directory moved or copied ----------------------------------------------------------------------------------


def resumed(run_dir: Path) -> subprocess.Popen:
    return subprocess.Popen(
        [*KINSWARM, "run", "--resume", str(run_dir), "--no-progress"],
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        start_new_session=True,
    )


def finished(p: subprocess.Popen) -> None:
    out = p.communicate(timeout=400)[0].decode()
    assert p.returncode == 0, out
    assert "Traceback" not in out, out


@pytest.mark.slow  # several whole runs and resumes: minutes on 2 cores (`pytest -m slow`)
@pytest.mark.timeout(900)
def test_a_moved_or_copied_run_resumes_as_a_run_of_its_own_and_leaves_the_original_alone(tmp_path):
    """Process placement, its agents in processes of their own: they find their checkpoints in the directory they were
    handed, not at the path config.json recorded when the run began. Two copies of a killed run resumed at once each
    end as the uninterrupted run, with their own run ids and secrets, and the original's files are unchanged (byte for
    byte); the original, then moved, resumes to the same result and nothing is written where it was."""
    ref, run = tmp_path / "ref", tmp_path / "run"
    assert cli(run_args("ref", ref, "process", 100)) == 0
    want = json.loads((ref / "summary.json").read_text())["final_error"]
    killed_in_epoch(run, run_args("run", run, "process", 100), k=3, whole_tree=True)
    copies = [tmp_path / "copy1", tmp_path / "copy2"]
    for c in copies:
        subprocess.run(["cp", "-a", str(run), str(c)], check=True, timeout=60)
    original = snapshot(run)
    secret = json.loads((run / "config.json").read_text())["secret"]

    procs = [resumed(c) for c in copies]  # at once
    for p in procs:
        finished(p)
    assert snapshot(run) == original, "resuming a copy wrote into the original"
    configs = [json.loads((c / "config.json").read_text()) for c in copies]
    assert [c["run_id"] for c in configs] == ["copy1", "copy2"]  # named by their directories, as the original was
    assert len({secret, *(c["secret"] for c in configs)}) == 3
    for c, config in zip(copies, configs, strict=True):
        summary = json.loads((c / "summary.json").read_text())
        assert summary["final_error"] == want, c
        assert summary["run_id"] == config["run_id"] and config["out"] == str(c.resolve())
        assert [r["epoch"] for r in rows(c / "metrics.jsonl")] == list(range(EPOCHS))
        (resume,) = resumes(c / "events.jsonl")
        assert f"a copy of run run in {run}" in resume["detail"], resume
        assert oct((c / "config.json").stat().st_mode & 0o777) == "0o600"

    moved = tmp_path / "moved"
    run.rename(moved)
    finished(resumed(moved))
    assert not run.exists(), "the moved run wrote at its old path"
    summary = json.loads((moved / "summary.json").read_text())
    assert summary["final_error"] == want and summary["run_id"] == "moved"
    (resume,) = resumes(moved / "events.jsonl")
    assert f"run run moved from {run}, now run moved" in resume["detail"], resume
    restored = [r for r in rows(moved / "events.jsonl") if r["event"] == "restored"]
    assert sorted(r["target"] for r in restored) == ["a1", "a2", "a3", "a4"]  # from its checkpoints, not from scratch
    assert all(r["checkpoint_epoch"] == resume["epoch"] - 1 for r in restored), restored


# -- interrupted is not final ---------------------------------------------------------------------------------------


def signalled_after(argv: list[str], metrics: Path, k: int, sig: signal.Signals, env: dict | None = None) -> str:
    """Run `kinswarm ARGV` until metrics.jsonl holds `k` rows (0: until the supervisor has opened events.jsonl), then
    send `sig` to the command alone, as a terminal's Ctrl-C or a service manager's stop reaches it; its stderr."""
    p = subprocess.Popen([*KINSWARM, *argv], stderr=subprocess.PIPE, text=True, start_new_session=True, env=env)
    LIVE.append(p)
    events = metrics.with_name("events.jsonl")
    while not (events.exists() if k == 0 else metrics.exists() and metrics.read_text().count("\n") >= k):
        assert p.poll() is None, p.communicate()[1]
        time.sleep(0.02)
    p.send_signal(sig)
    err = p.communicate(timeout=300)[1]
    assert p.returncode == 128 + sig, (p.returncode, err)
    assert "Traceback" not in err, err
    return err


@pytest.mark.slow  # several whole runs and resumes: minutes on 2 cores (`pytest -m slow`)
@pytest.mark.timeout(900)
def test_a_run_stopped_by_sigterm_then_ctrl_c_during_its_resume_resumes_to_the_uninterrupted_result(tmp_path):
    """SIGTERM mid-run exits 143, Ctrl-C during the `--resume` 130; each leaves the run resumable as a killed one, and
    the last `--resume` ends with the uninterrupted run's final errors, every epoch once."""
    ref, out = tmp_path / "ref", tmp_path / "run"
    assert cli(run_args("ref", ref, "process", 100)) == 0
    want = json.loads((ref / "summary.json").read_text())["final_error"]
    metrics = out / "metrics.jsonl"
    signalled_after(run_args("run", out, "process", 100), metrics, 2, signal.SIGTERM)
    stopped = json.loads((out / "summary.json").read_text())
    assert stopped["interrupted"] and stopped["interrupted_by"] == "SIGTERM" and len(stopped["final_error"]) < EPOCHS
    signalled_after(["run", "--resume", str(out), "--no-progress"], metrics, 5, signal.SIGINT)
    assert json.loads((out / "summary.json").read_text())["interrupted_by"] == "SIGINT"
    assert not swarm_pids(str(out / "config.json"))
    p = subprocess.run([*KINSWARM, "run", "--resume", str(out), "--no-progress"], capture_output=True, text=True)
    assert p.returncode == 0, p.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["final_error"] == want and not summary["interrupted"]
    assert [r["epoch"] for r in rows(metrics)] == list(range(EPOCHS))
    details = [r["detail"] for r in resumes(out / "events.jsonl")]
    assert len(details) == 2 and all("after it was interrupted at" in d for d in details), details


@pytest.mark.timeout(300)
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["ctrl-c", "sigterm"])
def test_a_start_interrupted_before_its_first_epoch_leaves_nothing_and_the_retry_runs(tmp_path, sig):
    """Stopped once its supervisor has begun (events.jsonl open, actors spawning) and long before its first epoch ends:
    its own exit code, no line about a motion.gif it had no epoch to draw, nothing left that blocks the same
    --run-id, which then runs."""
    out = tmp_path / "runs" / "x"
    argv = [
        "run", CHAIN4, "--epochs", "1", "--steps", "100000", "--placement", "process", "--run-id", "x",
        "--out", str(out), "--no-progress",
    ]  # fmt: skip
    err = signalled_after(argv, out / "metrics.jsonl", 0, sig, env={**os.environ, "KINSWARM_RECORD": "1"})
    assert "motion.gif" not in err and "kinswarm: interrupted" in err, err
    assert not swarm_pids(str(out / "config.json"))
    assert not out.exists() or set(os.listdir(out)) <= {".lock"}, sorted(os.listdir(out))
    assert (
        cli(["run", CHAIN4, "--epochs", "1", "--steps", "30", "--run-id", "x", "--out", str(out), "--no-progress"]) == 0
    )
