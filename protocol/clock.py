"""The sim's step, shared on its host through a tiny memory-mapped file (`<run>/net/clock`).

The simulator is the run's clock; the supervisor records events (a fault requested, an agent lost, a restart) at
moments the sim's messages describe only a few times a second. Reading this file gives the supervisor the sim's
(epoch, step) at the very moment it records, for the cost of one 8-byte store per step on the sim's side and no
message at all. The word is one aligned 64-bit store (epoch << 32 | step); a reader takes it when two reads agree.
"""

from __future__ import annotations

import mmap
import os
import struct
from pathlib import Path

_WORD = struct.Struct("<q")
NOT_STARTED = (-1, 0)


def clock_path(run_dir: str | os.PathLike[str]) -> Path:
    return Path(run_dir) / "net" / "clock"


class ClockWriter:
    """The sim's side: created (zeroed to "no epoch yet") when the sim starts."""

    def __init__(self, path: Path) -> None:
        path.parent.mkdir(parents=True, exist_ok=True)
        # a new file renamed into place, never one truncated under a reader's map (that would be SIGBUS)
        tmp = path.with_name(f".{path.name}.{os.getpid()}")
        fd = os.open(tmp, os.O_RDWR | os.O_CREAT | os.O_TRUNC, 0o600)
        try:
            os.ftruncate(fd, _WORD.size)
            self._map = mmap.mmap(fd, _WORD.size)
        finally:
            os.close(fd)
        self.set(*NOT_STARTED)
        os.replace(tmp, path)

    def set(self, epoch: int, step: int) -> None:
        _WORD.pack_into(self._map, 0, ((epoch + 1) << 32) | (step & 0xFFFFFFFF))

    def close(self) -> None:
        self._map.close()


class ClockReader:
    """The supervisor's side: None until the sim's file exists on this host (another host's sim: no file)."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self._map: mmap.mmap | None = None
        self._ino = -1

    def read(self) -> tuple[int, int] | None:
        if not self._open():
            return None
        assert self._map is not None
        while True:
            a = _WORD.unpack_from(self._map, 0)[0]
            if a == _WORD.unpack_from(self._map, 0)[0]:
                return (a >> 32) - 1, a & 0xFFFFFFFF

    def _open(self) -> bool:
        try:  # a restarted sim (a resumed run) writes a new file: follow it
            st = os.stat(self.path)
        except OSError:  # gone (a run starting again removes its crashed sim's): no clock until a sim writes one
            self.close()
            return False
        if self._map is None or st.st_ino != self._ino:
            if st.st_size < _WORD.size:
                return self._map is not None
            with open(self.path, "rb") as f:
                new = mmap.mmap(f.fileno(), _WORD.size, access=mmap.ACCESS_READ)
            if self._map is not None:
                self._map.close()
            self._map, self._ino = new, st.st_ino
        return True

    def close(self) -> None:
        if self._map is not None:
            self._map.close()
            self._map = None
