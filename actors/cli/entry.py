"""The `kinswarm` command's entry point: light on purpose. Ctrl-C during the few tenths of a second the imports take
is a clean exit (no traceback), then the CLI's own handling takes over (actors/cli/commands.py main). The
interpreter's own start (~0.05 s, before any of ours runs) is Python's."""

from __future__ import annotations

import signal
import sys


def _interrupted_while_starting(signum: int, frame: object) -> None:
    print("kinswarm: interrupted", file=sys.stderr)
    raise SystemExit(130)


signal.signal(signal.SIGINT, _interrupted_while_starting)  # from the moment this module is imported


def main() -> int:
    from kinswarm.actors.cli.commands import main as cli

    return cli()


if __name__ == "__main__":
    sys.exit(main())
