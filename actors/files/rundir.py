"""A run directory is written by one run, once. Before anything is spawned: `--out` must be a directory that holds no
run (or can be made); while the run lives it holds an exclusive lock on `<out>/.lock` (flock: the kernel lets go when
the process dies, however it dies), so a second run into the same directory is refused, and nothing of the first is
touched. A start that fails before the run begins (its port taken, its viewer missing) removes what it made, so the
same --run-id can be tried again at once; a run that began keeps everything, however it ends.

The same lock tells the readers (`report`, `animate`, `view`, `fault`, `status`) whether the run still lives."""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import shutil
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

from kinswarm.actors.files.config import ConfigError, load_run_config

#: files that say a directory holds a run
RUN_FILES = ("config.json", "metrics.jsonl", "summary.json", "run.toml", "events.jsonl", "poses.jsonl", "agents.jsonl")
#: all a start writes before the run begins (the supervisor opens events.jsonl as it begins): a directory holding
#: only these, unlocked and with no epoch, is a start that failed (or was killed) before its run began
START_FILES = frozenset({".lock", "config.json", "run.toml", "metrics.jsonl", "net"})


def check_dir(path: Path, flag: str) -> None:
    """One line naming why `path` cannot be a directory this command writes into (it may exist, or be made)."""
    if path.exists() and not path.is_dir():
        raise ConfigError(f"{flag} {path}: a file, not a directory")
    if path.is_dir():
        if not os.access(path, os.W_OK | os.X_OK):
            raise ConfigError(f"{flag} {path}: not writable")
        return
    parent = path.parent
    while not parent.exists():
        parent = parent.parent
    if not parent.is_dir():
        raise ConfigError(f"{flag} {path}: {parent} is a file, not a directory")
    if not os.access(parent, os.W_OK | os.X_OK):
        raise ConfigError(f"{flag} {path}: cannot create it ({parent} is not writable)")


def lock_held(out: Path) -> bool:
    """Whether a live process holds `out`'s run lock (a shared lock is tried and let go at once: nothing is made)."""
    try:
        fd = os.open(out / ".lock", os.O_RDONLY)
    except OSError:
        return False
    try:
        fcntl.flock(fd, fcntl.LOCK_SH | fcntl.LOCK_NB)
    except BlockingIOError:
        return True
    finally:
        os.close(fd)  # the shared lock, if taken, goes with it
    return False


def _start_files_only(out: Path) -> bool:
    try:
        names = set(os.listdir(out))
    except OSError:
        return False
    metrics = out / "metrics.jsonl"
    empty = not metrics.exists() or metrics.stat().st_size == 0
    return "config.json" in names and names <= START_FILES and empty


def failed_start(out: Path) -> bool:
    """`out` holds only what a start writes before its run begins, and no process holds it: no run's data."""
    return _start_files_only(out) and not lock_held(out)


def check_out(out: Path, flag: str = "--out", locked: bool = False) -> None:
    """One line naming what is wrong with a run directory, or nothing: it is free to be written (a failed start's
    leftovers do not count: `claim` clears them). `locked`: this process holds the directory's lock."""
    check_dir(out, flag)
    held = [f for f in RUN_FILES if (out / f).exists()]
    if held and not (_start_files_only(out) if locked else failed_start(out)):
        raise ConfigError(
            f"{flag} {out}: already holds a run ({held[0]}); a run directory is written once: choose another "
            "--out or --run-id, or delete it"
        )


class Claim:
    """A held run directory; `begin()` once the run has begun: from then on, whatever happens, its files stay."""

    def __init__(self) -> None:
        self.begun = False

    def begin(self) -> None:
        self.begun = True

    def withdraw(self) -> None:
        """The run ended before its first epoch (interrupted while starting): what it made goes as a failed start's
        does, once the exception that ends it leaves `claim`, so the same --run-id can be tried again."""
        self.begun = False


def _clear(out: Path, keep: set[str], made_dir: bool) -> None:
    """Remove what a failed start made in `out` (every entry not in `keep`; `out` too if it made it)."""
    for name in set(os.listdir(out)) - keep:
        p = out / name
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p, ignore_errors=True)
        else:
            p.unlink(missing_ok=True)
    if made_dir:
        with contextlib.suppress(OSError):  # not empty: something else wrote into it meanwhile; leave it
            out.rmdir()


@contextlib.contextmanager
def claim(out: Path) -> Iterator[Claim]:
    """Hold `out` for this run: made if need be, locked, and checked again under the lock (two runs started at once
    both pass check_out; only one gets the lock). Until `Claim.begin()`, an exception removes what was made."""
    check_out(out)
    made_dir = not out.exists()
    try:
        out.mkdir(parents=True, exist_ok=True)
        keep = set(os.listdir(out))
        fd = os.open(out / ".lock", os.O_RDWR | os.O_CREAT, 0o600)
    except OSError as e:
        raise ConfigError(f"--out {out}: cannot write it ({e.strerror or e})") from None
    c = Claim()
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ConfigError(f"--out {out}: another run is writing it now (its lock is held)") from None
        check_out(out, locked=True)
        if keep - {".lock"} and _start_files_only(out):  # an earlier start's leftovers: no run's data
            _clear(out, {".lock"}, made_dir=False)
            keep = {".lock"}
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        try:
            yield c
        except BaseException:
            if not c.begun:
                _clear(out, keep, made_dir)
            raise
    finally:
        os.close(fd)  # the lock goes with the descriptor


@contextlib.contextmanager
def reclaim(out: Path) -> Iterator[Claim]:
    """Hold a run's own directory again, to continue it (`--resume`): its lock, refused while a process holds it.
    Nothing is cleared, however this ends: the run began long ago."""
    try:
        fd = os.open(out / ".lock", os.O_RDWR | os.O_CREAT, 0o600)
    except OSError as e:
        raise ConfigError(f"--resume {out}: cannot write it ({e.strerror or e})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            why = "the run is still running (its lock is held): nothing to resume"
            raise ConfigError(f"--resume {out}: {why}") from None
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        c = Claim()
        c.begin()
        yield c
    finally:
        os.close(fd)


@dataclass(frozen=True)
class RunState:
    """What a run directory says of its run, for the tools that read it."""

    run_id: str
    path: Path
    epochs: list[int]  # the epochs metrics.jsonl holds whole rows of
    planned: int  # the epochs the run was to train
    live: bool  # a process holds its lock: the run is still going
    summary: dict | None  # summary.json: written when the run ended, however it ended
    ended_at: float | None  # when summary.json was written (epoch seconds)

    @property
    def how(self) -> str:
        """How a run with a summary ended, in a few words."""
        s = self.summary or {}
        return f"failed ({s['error']})" if s.get("error") else "was interrupted" if s.get("interrupted") else "finished"

    @property
    def when(self) -> str:
        return time.strftime("%Y-%m-%d %H:%M:%S", time.localtime(self.ended_at)) if self.ended_at else "?"

    @property
    def covered(self) -> str:
        return f"epoch {self.epochs[0]}" if len(self.epochs) == 1 else f"epochs {self.epochs[0]}-{self.epochs[-1]}"


def run_state(run_dir: Path) -> RunState:
    """The state of the run in `run_dir`; one line (ConfigError) when it is not a run directory."""
    if not (run_dir / "config.json").is_file():
        raise ConfigError(f"{run_dir}: not a run directory (no config.json)")
    cfg = load_run_config(run_dir / "config.json")
    epochs = []
    with contextlib.suppress(OSError):
        for line in (run_dir / "metrics.jsonl").read_text(errors="replace").splitlines():
            with contextlib.suppress(ValueError):  # a torn last row: `report` says so
                row = json.loads(line)
                if isinstance(row, dict) and isinstance(row.get("epoch"), int):
                    epochs.append(row["epoch"])
    summary, ended_at = None, None
    with contextlib.suppress(OSError, ValueError):
        ended_at = (run_dir / "summary.json").stat().st_mtime
        summary = json.loads((run_dir / "summary.json").read_text())
    if summary is not None and not isinstance(summary, dict):
        summary = {}
    return RunState(cfg.run_id, run_dir, sorted(epochs), cfg.epochs, lock_held(run_dir), summary, ended_at)


def reading_note(run_dir: Path, what: str) -> str | None:
    """Before `report`/`animate`/`view` read a run (`what`: report, animation, recording): one line
    (ConfigError) when it holds no epoch to read, and why; a note when what it reads is not the whole run (still
    running, or ended without its summary); None for a run that ended as runs end."""
    s = run_state(run_dir)
    if s.live and s.summary is None:  # (with its summary written, a run holds its lock only to draw its plots)
        if not s.epochs:
            raise ConfigError(f"run {s.run_id} is still running and has not finished its first epoch: no {what} yet")
        done = f"{len(s.epochs)} of {s.planned} epochs done"
        return f"run {s.run_id} is still running ({done}); the {what} covers {s.covered}"
    if s.summary is None:
        if failed_start(run_dir):
            raise ConfigError(
                f"run {s.run_id} never began ({run_dir} holds only what a start writes, no epoch): no {what} to make"
            )
        if not s.epochs:
            raise ConfigError(f"run {s.run_id} ended in its first epoch, no summary (killed?): no {what} to make")
        return (
            f"run {s.run_id} stopped without its summary (killed?) after {len(s.epochs)} of {s.planned} epochs; "
            f"the {what} covers {s.covered}"
        )
    if not s.epochs:
        raise ConfigError(f"run {s.run_id} {s.how} at {s.when} before its first epoch ended: no {what} to make")
    return None
