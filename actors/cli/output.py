"""What a command prints, told apart from the run's own files: a closed pipe (`kinswarm status RUN | head -1`) or a full
disk (`> /dev/full`) is one line or none, never a traceback. Shared by the whole CLI (commands.py) and the lean path of
`fault` and `status` (control.py), so it imports nothing of ours."""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from typing import Any


class OutputGone(Exception):
    """What this command prints cannot be written: a reader that stopped reading (`| head -1`), a full disk."""

    def __init__(self, error: OSError) -> None:
        super().__init__(str(error))
        self.error = error

    def exit(self) -> int:
        """One line (none for a closed pipe: its reader had what it wanted), stdout let go, the exit code."""
        where = _stdout_name()
        with contextlib.suppress(OSError):  # what is still buffered would fail again as the interpreter exits
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.__stdout__.fileno())
            os.close(devnull)
        if isinstance(self.error, BrokenPipeError):
            return 128 + signal.SIGPIPE
        print(f"kinswarm: error: cannot write the output to {where}: {self.error.strerror}", file=sys.stderr)
        return 1


def _stdout_name() -> str:
    try:
        return os.readlink("/proc/self/fd/1")
    except OSError:
        return "stdout"


class Output:
    """sys.stdout whose OSErrors are OutputGone: told apart from the OSErrors of the run's own files."""

    def __init__(self, inner: Any) -> None:
        self.inner = inner

    def write(self, text: str) -> int:
        try:
            return self.inner.write(text)
        except OSError as e:
            raise OutputGone(e) from None

    def flush(self) -> None:
        try:
            self.inner.flush()
        except OSError as e:
            raise OutputGone(e) from None

    def __getattr__(self, name: str) -> Any:
        return getattr(self.inner, name)
