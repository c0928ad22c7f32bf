"""The `kinswarm` command line as argparse sees it: every command, its options and their help, the run's
shorthands (`--epochs` is `--set run.epochs=`), and the arguments joined so a negative value reaches its own check.
actors/cli/commands.py runs what it parses."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from kinswarm.actors.cli.control import add_control_commands, joined  # noqa: F401  (joined: the CLI's, kept here)
from kinswarm.actors.files.config import DEFAULT_LISTEN, PLACEMENTS
from kinswarm.actors.runtime import LEASE_MS


def _goal(text: str) -> str:
    try:
        x, y = (float(v) for v in text.split(","))
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected X,Y (two numbers), got {text!r}") from None
    return f"task.goal=[{x!r}, {y!r}]"


def _on_off(text: str) -> bool:
    if text not in ("on", "off"):
        raise argparse.ArgumentTypeError(f"expected on or off, got {text!r}")
    return text == "on"


# Shorthands for the most used fields: each is a --set of one field of the run file.
_SHORTHANDS = {
    "epochs": "run.epochs",
    "steps": "run.steps",
    "seed": "run.seed",
    "placement": "run.placement",
    "deadline_ms": "run.deadline_ms",
    "lease_ms": "run.lease_ms",
    "scenario": "run.scenario",
    "reward": "task.reward",
    "from_dir": "run.from",
    "learn": "run.learn",
    "explore": "run.explore",
    "checkpoint_every": "run.checkpoint_every",
    "max_restarts": "run.max_restarts",
}


def sets_of(a: argparse.Namespace) -> list[str | tuple[str, str]]:
    """The run file's overrides from the command line: the shorthands, then --set in order (the last one wins). A
    shorthand comes with the flag it was given as, so a problem with its value names that flag (`--epochs 0`)."""
    out: list[str | tuple[str, str]] = []
    for name, key in _SHORTHANDS.items():
        v = getattr(a, name, None)
        if v is None:
            continue
        if isinstance(v, bool):
            text, given = ("true" if v else "false"), ("on" if v else "off")
        elif isinstance(v, Path):
            text, given = json.dumps(str(v)), str(v)
        else:
            text, given = (json.dumps(v) if isinstance(v, str) else repr(v)), str(v)
        flag = "--from" if name == "from_dir" else f"--{name.replace('_', '-')}"
        out.append((f"{key}={text}", f"{flag} {given}"))
    if getattr(a, "goal", None):
        out.append((a.goal, "--goal"))
    if getattr(a, "successive", False):
        out.append(("run.successive=true", "--successive"))
    return out + list(getattr(a, "set", None) or [])


def _add_common(p: argparse.ArgumentParser, resumable: bool = False) -> None:
    more = {"nargs": "?", "default": None} if resumable else {}  # `run --resume DIR` takes the run's own
    p.add_argument("run_file", type=Path, metavar="RUN-FILE", help="a run file (e.g. examples/chain4.toml)", **more)
    p.add_argument(
        "--set",
        action="append",
        metavar="SECTION.FIELD=VALUE",
        help="override one field of the run file, repeatable (e.g. --set learner.gamma=0.97, --set task.goal=[4,6])",
    )
    p.add_argument("--epochs", type=int, default=None, help="= --set run.epochs=N")
    p.add_argument("--steps", type=int, default=None, help="steps per epoch (= --set run.steps=N)")
    p.add_argument("--seed", type=int, default=None, help="= --set run.seed=N")
    p.add_argument("--goal", type=_goal, default=None, help="X,Y (= --set task.goal=[X,Y]); write --goal=-5,7")
    p.add_argument("--placement", choices=PLACEMENTS, default=None, help="= --set run.placement=...")
    p.add_argument("--run-id", default=None)
    p.add_argument(
        "--listen",
        default=None,
        help=f"the supervisor's endpoint (default {DEFAULT_LISTEN}: a free port on 127.0.0.1, written to "
        "RUN-DIR/net/cli.json, where `kinswarm status`, `fault` find it)",
    )
    p.add_argument("--out", type=Path, default=None, help="run directory (default runs/<run-id>)")
    p.add_argument("--deadline-ms", type=int, default=None, help="per-step deadline; a missing cmd holds")
    p.add_argument(
        "--lease-ms",
        type=int,
        default=None,
        help=f"how long a silent Zenoh peer still counts as present (default {LEASE_MS}). On an overloaded or "
        "shared machine a starved actor can miss it and count as down for a moment (its joint holds); a longer "
        "lease rides that out, at the price of noticing a frozen actor that much later",
    )
    p.add_argument("--scenario", type=Path, default=None, help="a TOML timeline of faults (e.g. scenarios/*.toml)")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument(
        "--view",
        nargs="?",
        const="here",
        default=None,
        metavar="here|web|FILE.rrd",
        help="stream each epoch into the rerun viewer as it ends: spawned on this machine (the default), served from "
        "it for a browser (`web`), or written to FILE.rrd as the run goes (the optional extra kinswarm[viewer])",
    )
    p.add_argument("--log-level", default="WARNING")


def _experiment_names() -> tuple[str, ...]:
    """The experiments' names, for `kinswarm experiment`: the CLI's one (lazy) door into experiments/."""
    from kinswarm.experiments import BY_NAME, EXPERIMENTS

    return (*EXPERIMENTS, "all", *BY_NAME)


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="kinswarm", description="A swarm of per-joint learning agents over Zenoh.")
    sub = p.add_subparsers(dest="command", required=True)
    run = sub.add_parser("run", help="train (or evaluate) a swarm of agents: everything it needs is in a run file")
    _add_common(run, resumable=True)
    run.add_argument(
        "--resume",
        type=Path,
        default=None,
        metavar="RUN-DIR",
        help="continue a run whose supervisor died (killed, a power cut) from its last complete checkpoint, in its "
        "own directory, as it was resolved (no RUN-FILE, no overrides)",
    )
    run.add_argument("--reward", default=None, help="= --set task.reward=...")
    run.add_argument("--from", dest="from_dir", type=Path, default=None, help="start from a run's checkpoints")
    run.add_argument("--learn", type=_on_off, default=None, metavar="on|off")
    run.add_argument("--explore", type=_on_off, default=None, metavar="on|off")
    run.add_argument(
        "--successive", action="store_true", help="start each epoch where the last ended (default: initial angles)"
    )
    run.add_argument(
        "--checkpoint-every", type=int, default=None, help="epochs between checkpoints (0: last only; default 1)"
    )
    run.add_argument(
        "--max-restarts", type=int, default=None, help="restarts of one agent within 60 s before giving up"
    )
    base = sub.add_parser("baseline", help="drive the same simulator with a model-based controller")
    _add_common(base)
    base.add_argument(
        "--law",
        choices=("pinv", "greedy", "rule", "turn"),
        default="pinv",
        help="pinv: the Jacobian pseudo-inverse (default); greedy: each joint alone takes the 1-step move that "
        "brings the tip nearest (a reference for what per-joint greedy control can do); rule: each joint one step "
        "along sign(g_perp) (no learning, no model: the control every learning result needs); turn: each joint one "
        "step toward its own best angle, sign(g_q) (a robot from URDF: the rule on the turn state)",
    )
    rep = sub.add_parser("report", help="rebuild a run's summary plots")
    rep.add_argument("run_dir", type=Path)
    rep.add_argument("--log", action="store_true", help="the learning curve's error axis logarithmic")
    anim = sub.add_parser(
        "animate",
        help="a run's motion as a GIF: the robot in chosen epochs, its faults and events, beside its error",
        description="Draws RUN-DIR/motion.gif from the run's records: by default the first and last epochs and the "
        "latest epochs with events (faults, losses, restarts).",
    )
    view = sub.add_parser(
        "view",
        help="open a finished run in the rerun viewer (the optional extra kinswarm[viewer]), or save it as .rrd",
        description="The robot at every step, the goal, the error, faulty joints and every event, on the timelines "
        "step, epoch and step_in_epoch: scrub back and forth across the faults.",
    )
    view.add_argument("run_dir", type=Path, metavar="RUN-DIR")
    # a string: `Path` would drop the trailing "/" that says a directory was meant
    view.add_argument("--save", type=str, default=None, metavar="FILE.rrd", help="write the recording, open nothing")
    view.add_argument("--web", action="store_true", help="serve the viewer for a browser instead of spawning it")
    anim.add_argument("run_dir", type=Path, metavar="RUN-DIR")
    anim.add_argument("--epochs", default=None, help="which epochs, e.g. 0,5,9 (default: first, last, with events)")
    anim.add_argument("--out", type=Path, default=None, help="the GIF to write (default RUN-DIR/motion.gif)")
    add_control_commands(sub)  # fault, status: defined beside their lean path (control.py)
    exp = sub.add_parser(
        "experiment",
        help="reproduce one of the paper's experiments (or all): report.md, figures, results.json",
        description="Runs the paper's experiments on the same actors and wire as `kinswarm run` (single "
        "placement) and writes DIR/NAME/report.md with figures and a paper-vs-kinswarm table, and "
        "DIR/NAME/results.json.",
    )
    exp.add_argument("name", choices=_experiment_names(), metavar="NAME", help=", ".join(_experiment_names()))
    exp.add_argument("--seeds", type=int, default=3, help="seeds 0..N-1 (default 3)")
    exp.add_argument("--quick", action="store_true", help="a smoke version (seconds, not conclusions)")
    exp.add_argument("--out", type=Path, default=Path("runs/experiments"), help="default runs/experiments")
    exp.add_argument("--jobs", type=int, default=1, help="runs in parallel worker processes (default 1)")
    exp.add_argument("--test-set", type=int, default=0, help="generalisation: the K-th block of 100 Halton goals")
    exp.add_argument("--log-level", default="ERROR")
    up = sub.add_parser(
        "up",
        help="start this host's share of a deploy plan (the leading host trains)",
        description="Run the same command with the same plan on every host, each with its own --host. The leader "
        "resolves the run from the plan's [run] table and these flags; the other hosts fetch it from the leader.",
    )
    up.add_argument("plan", type=Path, help="a deploy plan (e.g. deploy/two-hosts.toml)")
    up.add_argument("--host", required=True, help="which of the plan's hosts this is")
    up.add_argument("--run-file", type=Path, default=None, help="leader: instead of the plan's [run] file")
    up.add_argument("--set", action="append", metavar="SECTION.FIELD=VALUE", help="leader: overrides of the run file")
    for flag, tp in (("--epochs", int), ("--steps", int), ("--seed", int), ("--deadline-ms", int)):
        up.add_argument(flag, type=tp, default=None, help="leader: overrides the run file's value")
    up.add_argument("--reward", default=None)
    up.add_argument("--scenario", type=Path, default=None)
    up.add_argument("--run-id", default=None, help="leader: the run id (default <plan>-<time>-<hex>)")
    up.add_argument("--out", type=Path, default=None, help="this host's run directory (default runs/<run-id>)")
    up.add_argument("--wait", type=float, default=600.0, help="seconds to wait for the leader / the other hosts")
    up.add_argument("--no-progress", action="store_true")
    up.add_argument("--log-level", default="WARNING")
    down = sub.add_parser("down", help="stop the running swarm of a deploy plan, on every host")
    down.add_argument("plan", type=Path)
    down.add_argument("--host", required=True, help="which of the plan's hosts this command runs on")
    down.add_argument("--log-level", default="ERROR")
    router = sub.add_parser("router", help="run a Zenoh router (for plans with mode = 'client')")
    router.add_argument("--listen", action="append", required=True, help="endpoint, e.g. tcp/0.0.0.0:7447")
    router.add_argument("--plan", type=Path, default=None, help="take TLS, credentials and ACL from this plan")
    router.add_argument("--log-level", default="WARNING")
    certs = sub.add_parser("certs", help="write a throwaway CA, certificates and passwords for a plan (trials, tests)")
    certs.add_argument("plan", type=Path)
    certs.add_argument("--out", type=Path, required=True, help="directory (the plan's security.certs)")
    certs.add_argument("--run-file", type=Path, default=None, help="default: the plan's [run] file")
    certs.add_argument("--log-level", default="WARNING")
    return p
