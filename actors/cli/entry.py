"""The `kinswarm` command's entry point: light on purpose. Ctrl-C during the few tenths of a second the imports take
is a clean exit (no traceback), then the CLI's own handling takes over (actors/cli/commands.py main). `fault` and
`status` take a lean path of their own (actors/cli/control.py main): they are asked of a live run, often on a loaded
machine, and need neither the learners nor the report. The interpreter's own start (~0.05 s, before any of ours runs)
is Python's."""

from __future__ import annotations

import os
import signal
import sys


def _interrupted_while_starting(signum: int, frame: object) -> None:
    """Only imports run while this handler is in place (the CLI's main replaces it before it makes anything): there is
    nothing to undo, so the process ends here. An exception raised from a signal handler lands wherever the
    interpreter is, and there it can be swallowed: in importlib's module-lock callback it was printed as "Exception
    ignored ... Traceback" and the start went on."""
    sys.stderr.write("kinswarm: interrupted\n")
    sys.stderr.flush()
    os._exit(130)


signal.signal(signal.SIGINT, _interrupted_while_starting)  # from the moment this module is imported


def main() -> int:
    if sys.argv[1:2] in (["fault"], ["status"]):  # asked of a live run, often on a loaded machine: the lean path
        from kinswarm.actors.cli.control import main as control

        return control(sys.argv[1:])
    from kinswarm.actors.cli.commands import main as cli

    return cli()


if __name__ == "__main__":
    sys.exit(main())
