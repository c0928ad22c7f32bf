"""A host's hub: the Zenoh router that the host's actors and its supervisor are clients of, in a process of its own.

Why a process of its own: the hub relays every message of the step. Held by the supervisor's session, a supervisor
paused for longer than a lease (SIGSTOP, or a busy machine's scheduler) stalled the whole swarm with it: its clients'
links lapsed, the step under way lost its commands, and a run paused 3 s ended with other final errors than an
undisturbed one (tests/test_pause.py). A process that does nothing but route (on Zenoh's own threads) is not held up
by what the supervisor does, so a paused supervisor pauses only the supervisor.

`python -m kinswarm.actors.runtime.hub NETSPEC.json`: opens the router session of the NetSpec, writes `ready` (or
`error: <reason>`) as its first line on stdout, and holds the session until its stdin closes -- which happens when its
supervisor stops it, and also when its supervisor dies in any way, so a hub is never left behind.
"""

from __future__ import annotations

import contextlib
import ctypes
import subprocess
import sys
import threading
from pathlib import Path

READY = "ready"


class HubError(RuntimeError):
    """The hub could not open its session (its reason, in one line), or ended before it said so."""


class Hub:
    """The supervisor's handle on its host's hub process."""

    def __init__(self, net: Path, start_s: float = 300.0) -> None:
        """Starts the hub on the NetSpec in `net` and waits for its first line. `start_s` is a hang guard only: a hub
        that neither opens nor fails within it is taken for failed (a loaded machine starts Python in seconds)."""
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "kinswarm.actors.runtime.hub", str(net)],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
            start_new_session=True,  # Ctrl-C reaches the supervisor only: the hub routes its orderly stop
        )
        first: list[str] = []
        reader = threading.Thread(target=lambda: first.append(self.proc.stdout.readline() if self.proc.stdout else ""))
        reader.start()
        reader.join(start_s)
        line = first[0].strip() if first else ""
        if line != READY:
            self.close()
            raise HubError(line.removeprefix("error: ") or f"the hub did not start within {start_s:.0f} s")

    @property
    def pid(self) -> int:
        return self.proc.pid

    def close(self, wait_s: float = 10.0) -> None:
        """Stop the hub: its stdin closes, it closes its session and exits; killed if it has not within `wait_s`."""
        with contextlib.suppress(OSError):
            if self.proc.stdin:
                self.proc.stdin.close()
        try:
            self.proc.wait(wait_s)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait()
        if self.proc.stdout:
            self.proc.stdout.close()


def main(argv: list[str]) -> int:
    from kinswarm.actors.runtime.net import NetSpec, open_session, zenoh_reason

    with contextlib.suppress(OSError):  # its name in ps and /proc/PID/comm, beside the actors' ROLE-ID
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(15, b"hub", 0, 0, 0)  # PR_SET_NAME

    try:
        session = open_session(NetSpec.from_json(Path(argv[0]).read_text()))
    except Exception as e:  # noqa: BLE001 -- any failure to open is the one line the supervisor reports
        print(f"error: {zenoh_reason(e)}", flush=True)
        return 1
    print(READY, flush=True)
    with contextlib.suppress(KeyboardInterrupt):
        sys.stdin.read()  # until the supervisor closes it, or dies
    session.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
