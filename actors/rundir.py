"""A run directory is written by one run, once. Before anything is spawned: `--out` must be a directory that holds no
run (or can be made); while the run lives it holds an exclusive lock on `<out>/.lock` (flock: the kernel lets go when
the process dies, however it dies), so a second run into the same directory is refused, and nothing of the first is
touched."""

from __future__ import annotations

import contextlib
import fcntl
import os
from collections.abc import Iterator
from pathlib import Path

from kinswarm.actors.config import ConfigError

#: files that say a directory holds a run
RUN_FILES = ("config.json", "metrics.jsonl", "summary.json", "run.toml", "events.jsonl", "poses.jsonl", "agents.jsonl")


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


def check_out(out: Path, flag: str = "--out") -> None:
    """One line naming what is wrong with a run directory, or nothing: it is free to be written."""
    check_dir(out, flag)
    held = [f for f in RUN_FILES if (out / f).exists()]
    if held:
        raise ConfigError(
            f"{flag} {out}: already holds a run ({held[0]}); a run directory is written once: choose another "
            "--out or --run-id, or delete it"
        )


@contextlib.contextmanager
def claim(out: Path) -> Iterator[None]:
    """Hold `out` for this run: made if need be, locked, and checked again under the lock (two runs started at once
    both pass check_out; only one gets the lock)."""
    check_out(out)
    try:
        out.mkdir(parents=True, exist_ok=True)
        fd = os.open(out / ".lock", os.O_RDWR | os.O_CREAT, 0o600)
    except OSError as e:
        raise ConfigError(f"--out {out}: cannot write it ({e.strerror or e})") from None
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ConfigError(f"--out {out}: another run is writing it now (its lock is held)") from None
        check_out(out)
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        yield
    finally:
        os.close(fd)  # the lock goes with the descriptor
