"""`kinswarm fault` and `kinswarm status`: asked of a running swarm from another terminal, through the client of
actors/control/client.py.

A lean path on purpose (`main`, which the console script calls for these two commands): a fault or a status asked on
a loaded machine is mostly Python's start-up, so this module and what it imports stay off numpy, the learners, the
report and the launcher: Zenoh, the codec, the keys, the run's config and its directory's state
(benchmarks/control_latency.py measures it).
"""

from __future__ import annotations

import argparse
import asyncio
import math
import re
import signal
import sys
import time
from pathlib import Path

from kinswarm.actors.cli.output import Output, OutputGone
from kinswarm.actors.control.client import Client, ControlError, make_fault, run_config, run_config_at, tool_net
from kinswarm.actors.files.config import ConfigError, RunConfig
from kinswarm.actors.files.rundir import failed_start, lock_held, run_state
from kinswarm.actors.runtime import NetSpec, setup_logging
from kinswarm.protocol.faults import FAULTS, describe
from kinswarm.protocol.messages import JointStatus, SwarmStatus
from kinswarm.protocol.spec import SpecError

COMMANDS = ("fault", "status")

_DURATION = re.compile(r"^\s*([0-9]*\.?[0-9]+)\s*(ms|s|m|min|h)?\s*$")
_UNIT = {"ms": 0.001, "s": 1.0, None: 1.0, "m": 60.0, "min": 60.0, "h": 3600.0}


def parse_duration(text: str) -> float:
    """`5s`, `500ms`, `2m`, `1.5` (seconds) -> seconds."""
    m = _DURATION.match(text)
    if not m or float(m.group(1)) <= 0:
        raise ValueError(f"--for: expected a duration > 0 like 5s, 500ms or 2m, got {text!r}")
    return float(m.group(1)) * _UNIT[m.group(2)]


def render(status: SwarmStatus, joints: JointStatus | None, run_id: str) -> str:
    """The `kinswarm status` table (epochs counted from 0, as metrics.jsonl and events.jsonl count them)."""
    head = f"run {run_id}  epoch {status.epoch} of 0-{status.epochs - 1}"
    if joints is not None and joints.epoch == status.epoch:
        head += f"  step {joints.step}"
    cols = ("actor", "role", "alive", "pid", "host", "restarts", "joint", "action", "faults")
    rows = []
    for ident, role in status.role.items():
        q = joints.q.get(ident) if joints is not None else None
        d = joints.delta.get(ident) if joints is not None else None
        rows.append(
            (
                ident,
                role,
                "yes" if status.alive.get(ident) else "NO",
                str(status.pid.get(ident) or "-"),
                status.host.get(ident, "-"),
                str(status.restarts.get(ident, 0)),
                "-" if q is None else f"{math.degrees(q):8.2f}°",
                "-" if d is None else f"{math.degrees(d):+.2f}°",
                "; ".join(status.faults.get(ident, [])) or "-",
            )
        )
    widths = [max(len(c), *(len(r[i]) for r in rows)) for i, c in enumerate(cols)]
    line = "  ".join(c.ljust(w) for c, w in zip(cols, widths, strict=True))
    body = ["  ".join(v.ljust(w) for v, w in zip(r, widths, strict=True)) for r in rows]
    return "\n".join([head, line, *body])


async def show_status(cfg: RunConfig, connect: str | NetSpec, watch: bool, run_dir: Path) -> None:
    """Print the status (with the joints: the first one or two statuses may come before the sim's readings); with
    `watch`, redraw it until the run ends, and say how it ended."""
    if (run_dir / "summary.json").exists():
        print(ended(run_dir, cfg.run_id))
        return
    said = False

    def keep_waiting(waited: float) -> bool:
        """A run here whose process still holds its directory is there, only slow to speak (a 100-agent start forks
        for seconds before its first status): waited for, said once. Another host's run, or one gone, is not."""
        nonlocal said
        if not lock_held(run_dir) or (run_dir / "summary.json").exists():
            return False
        if not said:
            print(
                f"kinswarm: run {cfg.run_id} is running but has sent no status for {waited:g} s (starting, or its "
                "machine is loaded); still waiting (Ctrl-C to stop)",
                file=sys.stderr,
            )
            said = True
        return True

    async with Client(cfg, connect) as c:
        first = time.monotonic()
        try:
            async for status, joints in c.statuses(keep_waiting=keep_waiting):
                table = render(status, joints, cfg.run_id)
                if not watch:
                    if joints is None and time.monotonic() - first < 2.0:
                        continue  # the sim's readings come twice a second
                    print(table)
                    return
                sys.stdout.write("\x1b[H\x1b[2J" + table + "\n")  # clear and redraw, like `top`
                sys.stdout.flush()
        except ControlError:
            if (run_dir / "summary.json").exists():  # it ended while we watched
                print(ended(run_dir, cfg.run_id))
                return
            raise


def ended(run_dir: Path, run_id: str) -> str:
    """One line on a finished run, from its summary."""
    import json

    try:
        s = json.loads((run_dir / "summary.json").read_text())
    except (OSError, ValueError):
        return f"run {run_id} has ended ({run_dir / 'summary.json'})"
    how = "failed: " + s["error"] if s.get("error") else "was interrupted" if s.get("interrupted") else "finished"
    fe = s.get("final_error") or []
    last = f", final error {fe[-1]:.3f}" if fe else ""
    return f"run {run_id} {how} ({len(fe)} epochs{last}; {run_dir / 'summary.json'})"


VALUED = ("--for", "--ms", "--rate", "--steps", "--amplitude", "--factor", "--degrees", "--robot")  # fault's options


def joined(argv: list[str]) -> list[str]:
    """`--for -5s` as `--for=-5s`: argparse takes a value that starts with '-' for an option and says only
    "expected one argument"; joined, the value reaches its own check, which says what is wrong with it."""
    out: list[str] = []
    for arg in argv:
        if out and out[-1] in VALUED and arg.startswith("-"):
            out[-1] = f"{out[-1]}={arg}"
        else:
            out.append(arg)
    return out


# -- the commands ---------------------------------------------------------------------------------------------------


def add_control_commands(sub: argparse._SubParsersAction) -> None:
    """`fault` and `status`, as `kinswarm`'s parser (parser.py) and this module's lean one both offer them."""
    fault = sub.add_parser(
        "fault",
        help="inject a fault into a running swarm",
        description="lock|free|disturb a joint, or reverse|scale|deadzone|offset|lag its motor or encoder (the robot, "
        "unknown to the agents; free ends them all); kill|freeze|thaw|restart an agent (its process); "
        "drop|delay|duplicate|corrupt|clear an agent's messages. TARGET: agent ids or `all`.",
    )
    fault.add_argument("run_id", metavar="RUN-ID")
    fault.add_argument("fault", choices=FAULTS, metavar="FAULT")
    fault.add_argument("targets", nargs="+", metavar="TARGET")
    fault.add_argument("--for", dest="duration", default=None, help="freeze or message faults: how long (5s, 500ms)")
    fault.add_argument("--steps", type=int, default=None, help="disturb: for how many steps; lag: how many behind")
    fault.add_argument("--rate", type=float, default=None, help="drop/duplicate/corrupt: probability per message")
    fault.add_argument("--ms", type=float, default=None, help="delay: milliseconds")
    fault.add_argument("--amplitude", type=float, default=None, help="disturb: degrees per step (default 2)")
    fault.add_argument("--factor", type=float, default=None, help="scale: the motor moves FACTOR x the command")
    fault.add_argument("--degrees", type=float, default=None, help="deadzone: smallest move; offset: encoder error")
    fault.add_argument("--robot", type=int, default=None, help="a fleet's joint faults: on robot N only (default: all)")
    status = sub.add_parser("status", help="show a running swarm's actors (alive, pid, restarts, faults, joints)")
    status.add_argument("run_id", metavar="RUN-ID")
    status.add_argument("--watch", action="store_true", help="refresh live until Ctrl-C")
    for q in (fault, status):
        q.add_argument("--run-dir", type=Path, default=None, help="the run's directory (default runs/RUN-ID)")
        q.add_argument("--connect", default=None, help="the run's endpoint (default: the one it listens on)")
        q.add_argument("--log-level", default="ERROR")


def run_command(a: argparse.Namespace) -> int:
    """`kinswarm fault ...` or `kinswarm status ...`, parsed."""
    f = None
    if a.command == "fault":  # the fault first: what is wrong with it needs no run to say
        f = make_fault(
            a.fault,
            a.targets,
            seconds=parse_duration(a.duration) if a.duration else None,
            steps=a.steps,
            rate=a.rate,
            ms=a.ms,
            amplitude_deg=a.amplitude,
            factor=a.factor,
            degrees=a.degrees,
            robot=a.robot,
        )
    if a.run_dir is None and "/" in a.run_id:  # a run's directory, not an id (ids have no "/"): its own id
        a.run_dir = Path(a.run_id)
        a.run_id = run_config_at(a.run_dir).run_id
    cfg = run_config(a.run_id, a.run_dir)
    run_dir = a.run_dir or Path("runs") / a.run_id
    state = run_state(run_dir)
    if f is not None and state.summary is not None:  # said at once: no supervisor is there to ask
        raise ControlError(f"run {a.run_id} {state.how} at {state.when}; nothing to fault")
    if state.summary is None and not state.live and a.connect is None:  # its lock is free: no process runs it here
        why = "its start failed" if failed_start(run_dir) else "it was killed"
        raise ControlError(
            f"run {a.run_id} is not running ({why}: nothing holds {run_dir / '.lock'} and it has no summary); "
            "for a run on another host pass --connect ENDPOINT"
        )
    connect = tool_net(run_dir, cfg, a.connect)
    if f is None:
        asyncio.run(show_status(cfg, connect, a.watch, run_dir))
        return 0

    async def send() -> int:
        async with Client(cfg, connect) as c:
            reply = await c.fault(f)
        if reply.error:
            print(f"kinswarm: fault refused: {reply.error}", file=sys.stderr)
            return 2
        print(f"{a.run_id}: {describe(f)}: applied" + (f" ({reply.detail})" if reply.detail else ""))
        return 0

    return asyncio.run(send())


def main(argv: list[str]) -> int:
    """`kinswarm fault|status ...` on the lean path (the console script's entry.py sends these here): the same
    arguments, one-line errors and exit codes as through the whole CLI (commands.py), without its imports."""
    signal.signal(signal.SIGINT, signal.default_int_handler)
    p = argparse.ArgumentParser(prog="kinswarm", description="A swarm of per-joint learning agents over Zenoh.")
    sub = p.add_subparsers(dest="command", required=True)
    add_control_commands(sub)
    out = sys.stdout = Output(sys.stdout)  # a closed pipe or a full disk: one line or none, as in the whole CLI
    try:
        a = p.parse_args(joined(argv))
        setup_logging(a.log_level)
        code = run_command(a)
        out.flush()
        return code
    except (SpecError, ConfigError, ControlError, ValueError) as e:
        print(f"kinswarm: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("kinswarm: interrupted", file=sys.stderr)
        return 130
    except OutputGone as e:
        return e.exit()
    finally:
        sys.stdout = out.inner
