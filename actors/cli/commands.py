"""`kinswarm`'s subcommands: run a learning swarm, run the model-based baseline, inject faults into a running swarm,
show its status, rebuild a run's report (the arguments: parser.py)."""

from __future__ import annotations

import argparse
import asyncio
import dataclasses
import logging
import os
import secrets
import signal
import sys
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import zenoh
from kinswarm.actors.cli.output import Output, OutputGone
from kinswarm.actors.cli.parser import build_parser, joined, sets_of
from kinswarm.actors.deploy.plan import Plan, PlanError, load_plan
from kinswarm.actors.files.checkpoint import CheckpointError
from kinswarm.actors.files.config import ConfigError, RunConfig, check_endpoint
from kinswarm.actors.files.rundir import check_dir, reading_note
from kinswarm.actors.files.runfile import load_run
from kinswarm.actors.report import error_line
from kinswarm.actors.run.launch import resume_swarm, run_swarm
from kinswarm.actors.runtime import setup_logging
from kinswarm.actors.runtime.net import zenoh_reason
from kinswarm.actors.supervisor.result import RecordError
from kinswarm.protocol.spec import SpecError
from kinswarm.protocol.topology import Topology

log = logging.getLogger("kinswarm")
Ran = tuple[dict, RunConfig]  # a run's summary and config: what `run`, `baseline` and a leader's `up` report


def _plan_run(plan: Plan, given: Path | None, sets: list[str | tuple[str, str]] = (), **kw: Any) -> RunConfig:
    """The run a plan's leader runs: its [run] file (or `given`) with the plan's and the command line's overrides."""
    path = given if given is not None else (Path(plan.run_file) if plan.run_file else None)
    if path is None:
        raise PlanError(plan.source, "run.file", "no run file: give one in [run] file or pass --run-file")
    return load_run(path, [*((s, f"{plan.source}: run.set") for s in plan.run_sets), *sets], **kw)


def _up(a: argparse.Namespace) -> tuple[dict, RunConfig]:
    from kinswarm.actors.deploy.hosts import fetch_setup, follower_config

    plan = load_plan(a.plan)
    if a.host not in plan.hosts:
        raise PlanError(plan.source, "host", f"--host {a.host!r} is not one of {', '.join(plan.hosts)}")
    progress = not a.no_progress and sys.stderr.isatty()
    if a.host != plan.leader:
        run, setup = fetch_setup(plan, a.host, a.wait)
        cfg, topo = follower_config(setup, a.host, plan, a.out)
        print(f"kinswarm: host {a.host} joins run {run} of {plan.leader} -> {cfg.out}", flush=True)
        return run_swarm(cfg, topo, progress=False, plan=plan, host=a.host), cfg
    run_id = a.run_id or f"{plan.name}-{time.strftime('%Y%m%d-%H%M%S')}-{secrets.token_hex(2)}"
    sets = [*sets_of(a), 'run.placement="process"', f"run.lease_ms={plan.lease_ms}"]
    cfg = _plan_run(plan, a.run_file, sets, run_id=run_id, out=a.out, listen=plan.hosts[a.host].listen)
    topo = cfg.topo()
    if len(plan.hosts) > 1:  # the sim holds its steps while one of them is silent
        cfg = dataclasses.replace(cfg, hosts=list(plan.hosts))
    print(f"kinswarm: host {a.host} leads run {cfg.run_id} of plan {plan.name} -> {cfg.out}", flush=True)
    return run_swarm(cfg, topo, progress=progress, plan=plan, host=a.host, wait_s=a.wait), cfg


def _deploy_tool(a: argparse.Namespace) -> int:
    from kinswarm.actors.deploy.hosts import down, run_router, write_certs

    if a.command == "down":
        plan = load_plan(a.plan)
        if a.host not in plan.hosts:
            raise PlanError(plan.source, "host", f"--host {a.host!r} is not one of {', '.join(plan.hosts)}")
        print(f"kinswarm: asked run {asyncio.run(down(plan, a.host))} to stop")
        return 0
    if a.command == "router":
        plan = load_plan(a.plan) if a.plan else None
        topo = _plan_run(plan, None).topo() if plan and plan.security.acl else None
        run_router(a.listen, plan, topo)
        return 0
    plan = load_plan(a.plan)
    check_dir(a.out, "--out")
    for path in write_certs(plan, _plan_run(plan, a.run_file).topo(), a.out):
        print(path)
    return 0


def _resolve(a: argparse.Namespace, controller: str | None) -> tuple[RunConfig, Topology]:
    """The run of `kinswarm run|baseline`: its run file with the command line's overrides, every input checked."""
    sets = sets_of(a) + ([f'run.controller="{controller}"'] if controller else [])
    if getattr(a, "view", None):  # the viewer shows what each agent saw and chose
        sets.append("run.record_agents=true")
    cfg = load_run(a.run_file, sets, run_id=a.run_id, out=a.out, listen=a.listen)
    return cfg, cfg.topo()


#: what `run --resume` takes besides RUN-DIR: how to watch it and where it listens; nothing that changes the run
_RESUME_TAKES = {"resume", "listen", "no_progress", "view", "log_level", "command"}


def _resumed(a: argparse.Namespace) -> RunConfig:
    """`kinswarm run --resume RUN-DIR`: the run as config.json resolved it, or one line naming what is wrong."""
    from kinswarm.actors.files.resume import check_resume

    if a.run_file is not None:
        raise ConfigError(f"--resume {a.resume}: continues the run as it was resolved: give no RUN-FILE ({a.run_file})")
    given = [k for k, v in vars(a).items() if k not in _RESUME_TAKES and v not in (None, False, [])]
    if given:
        flag = "--from" if given[0] == "from_dir" else "--" + given[0].replace("_", "-")
        raise ConfigError(f"--resume {a.resume}: continues the run as it was resolved: {flag} cannot change it")
    cfg = check_resume(a.resume)
    if a.listen is not None:  # where it listens is not the run: a port pinned then may be taken now
        cfg = dataclasses.replace(cfg, listen=a.listen if a.listen == "auto" else check_endpoint(a.listen, "--listen"))
    return cfg


def _control(a: argparse.Namespace) -> int:
    from kinswarm.actors.cli.control import run_command

    return run_command(a)


def _experiment(a: argparse.Namespace, argv: list[str]) -> int:
    from kinswarm.experiments import run_experiment

    check_dir(a.out, "--out")
    results = run_experiment(
        a.name, seeds=a.seeds, quick=a.quick, out=a.out, jobs=a.jobs, test_set=a.test_set, argv=list(argv)
    )
    for name in results:
        print(a.out / name / "report.md")
    return 0


def main(argv: list[str] | None = None) -> int:
    """The CLI: every problem a user can cause is one line and an exit code, Ctrl-C at any moment too."""
    try:  # the hand-over from entry.py's handler inside the try: a Ctrl-C right after it is caught here too
        signal.signal(signal.SIGINT, signal.default_int_handler)
        out = sys.stdout = Output(sys.stdout)
        try:
            code = _main(argv)
            out.flush()  # a full disk or a closed pipe shows here, not as the interpreter's last words
        finally:
            sys.stdout = out.inner
        return code
    except KeyboardInterrupt as e:
        print("kinswarm: interrupted", file=sys.stderr)
        return interrupted_code(e)
    except OutputGone as e:
        return e.exit()


def interrupted_code(e: KeyboardInterrupt | None = None, by: str = "") -> int:
    """The exit code of a run stopped by a signal: 128 + its number (130: Ctrl-C, 143: SIGTERM)."""
    signum = getattr(e, "signum", 0) or (signal.Signals[by] if by in signal.Signals.__members__ else signal.SIGINT)
    return 128 + int(signum)


def _view(a: argparse.Namespace) -> int:
    from kinswarm.actors.report.recording import open_stream, record_run, rerun_module, shown_epochs

    rerun_module()
    note = reading_note(a.run_dir, "recording")
    if not shown_epochs(a.run_dir):  # before a file is written or a viewer opened: never an empty recording
        raise ConfigError(f"{a.run_dir}: no epoch with both its metrics and its poses recorded: nothing to show")
    a.save = save_file(a.save) if a.save is not None else None
    _note(note)
    run_id = a.run_dir.resolve().name
    stream = open_stream(run_id, save=a.save, web=a.web)
    epochs = record_run(a.run_dir, stream)
    stream.flush()
    if a.save is not None:
        stream.disconnect()  # the file's footer
    print(f"{a.save or 'the viewer'}: {epochs} epochs of {a.run_dir}")
    if a.web and a.save is None:  # the served viewer lives as long as this process
        from kinswarm.actors.report.recording import serve_until_interrupted

        serve_until_interrupted()
    return 0


def save_file(given: str) -> Path:
    """`view --save FILE.rrd`: a file this command can create, or one line naming why not."""
    path = Path(given)
    if given.endswith(("/", os.sep)) or path.is_dir():
        raise ConfigError(f"--save {given}: a directory; give the recording's file, e.g. {path / 'recording.rrd'}")
    if not path.parent.is_dir():
        raise ConfigError(f"--save {given}: no such directory {path.parent}")
    if not os.access(path.parent, os.W_OK | os.X_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise ConfigError(f"--save {given}: not writable")
    return path


def _note(note: str | None) -> None:
    """A reader's note on a run it reads only part of (still running, or ended without its summary)."""
    if note:
        print(f"kinswarm: {note}", file=sys.stderr)


def _epoch_list(text: str | None) -> list[int] | None:
    """`--epochs 0,5,9`: whole epochs >= 0, or one line that says what is wrong."""
    if text is None:
        return None
    try:
        out = [int(x) for x in text.split(",")]
    except ValueError:
        raise ConfigError(f"--epochs: expected epochs like 0,5,9, got {text!r}") from None
    if not out or min(out) < 0:
        raise ConfigError(f"--epochs: epochs count from 0, got {text!r}")
    return out


def os_error(e: OSError) -> str:
    """An OSError as a line: the file (both, for a rename) and the cause."""
    where = f"{e.filename} -> {e.filename2}" if e.filename2 else e.filename
    return f"{where}: {e.strerror or e}" if where else str(e.strerror or e)


def _report(a: argparse.Namespace, argv: list[str]) -> int:
    from kinswarm.actors.report import torn_rows, write_plots

    _note(reading_note(a.run_dir, "report"))
    for line in torn_rows(a.run_dir):
        print(f"kinswarm: {line}", file=sys.stderr)
    for path in write_plots(a.run_dir, log=a.log):
        print(path)
    return 0


def _animate(a: argparse.Namespace, argv: list[str]) -> int:
    from kinswarm.actors.report.animate import write_animation

    _note(reading_note(a.run_dir, "animation"))
    print(write_animation(a.run_dir, _epoch_list(a.epochs), a.out))
    return 0


def _host_up(a: argparse.Namespace, argv: list[str]) -> int | Ran:
    """`kinswarm up`: the leader's run, reported as `run`'s; another host's share, one line (the leader has the
    results)."""
    summary, cfg = _up(a)
    if "host" not in summary:
        return summary, cfg
    if summary.get("error"):
        print(f"kinswarm: host {summary['host']} failed: {summary['error']}", file=sys.stderr)
        return 1
    print(f"kinswarm: host {summary['host']} done ({cfg.run_id})")
    return interrupted_code(by=summary.get("interrupted_by", "")) if summary.get("interrupted") else 0


def _train(a: argparse.Namespace, argv: list[str]) -> Ran:
    """`kinswarm run` (or `run --resume RUN-DIR`) and `kinswarm baseline`: the run, every input checked first."""
    if getattr(a, "resume", None) is not None:
        cfg = _resumed(a)
        if a.view:
            from kinswarm.actors.report.recording import check_view

            check_view(a.view)
        progress = not a.no_progress and sys.stderr.isatty()
        return resume_swarm(cfg, cfg.topo(), progress=progress, view=a.view), cfg
    if a.run_file is None:
        raise ConfigError("RUN-FILE: missing: give a run file (e.g. examples/chain4.toml), or --resume RUN-DIR")
    cfg, topo = _resolve(a, None if a.command == "run" else a.law)
    if a.view:  # the extra is there and the target makes sense, or one line before anything is spawned
        from kinswarm.actors.report.recording import check_view

        check_view(a.view)
    return run_swarm(cfg, topo, progress=not a.no_progress and sys.stderr.isatty(), view=a.view), cfg


#: each command's work: the parsed arguments and the command line in; an exit code, or a run to report, out
COMMANDS: dict[str, Callable[[argparse.Namespace, list[str]], int | Ran]] = {
    "run": _train,
    "baseline": _train,
    "report": _report,
    "animate": _animate,
    "view": lambda a, argv: _view(a),
    "fault": lambda a, argv: _control(a),
    "status": lambda a, argv: _control(a),
    "experiment": _experiment,
    "up": _host_up,
    "down": lambda a, argv: _deploy_tool(a),
    "router": lambda a, argv: _deploy_tool(a),
    "certs": lambda a, argv: _deploy_tool(a),
}


def _main(argv: list[str] | None) -> int:
    from kinswarm.actors.control.client import ControlError
    from kinswarm.actors.deploy.hosts import DeployError
    from kinswarm.protocol.scenario import ScenarioError

    argv = joined(list(sys.argv[1:] if argv is None else argv))
    a = build_parser().parse_args(argv)
    setup_logging(getattr(a, "log_level", "WARNING"))
    sys.setswitchinterval(0.0005)
    try:
        done = COMMANDS[a.command](a, argv)
    except (SpecError, ConfigError, CheckpointError, ScenarioError, ControlError, ValueError, DeployError) as e:
        print(f"kinswarm: error: {e}", file=sys.stderr)
        return 2
    except zenoh.ZError as e:  # a session a tool opens (router, down, a follower's fetch): Zenoh's words, one line
        print(f"kinswarm: error: {zenoh_reason(e)}", file=sys.stderr)
        return 2
    except RecordError as e:  # a record the run could not open (its directory full or read-only): the run is kept
        print(f"kinswarm: error: {e}", file=sys.stderr)
        return 1
    except OSError as e:  # the disk refused (full, read-only, forbidden): the path and the cause, one line
        print(f"kinswarm: error: {os_error(e)}", file=sys.stderr)
        return 1
    except KeyboardInterrupt as e:
        print("kinswarm: interrupted", file=sys.stderr)
        return interrupted_code(e)
    if isinstance(done, int):
        return done
    return _reported(*done)


def _reported(summary: dict, cfg: RunConfig) -> int:
    """A run's last words: its final error, its lost tokens, how it failed; the exit code."""
    fe = summary["final_error"]
    if fe:
        last = fe[-20:]
        line = error_line(cfg.topo())  # 0.5 on a planar robot's scale, 5 cm on an arm from URDF
        within = sum(e <= line for e in last)
        print(
            f"{cfg.run_id}: {len(fe)} epochs, final error {fe[-1]:.3f} (last {len(last)}: {within} within {line:g}), "
            f"{summary['steps_per_second']:.0f} steps/s, {summary['wall_seconds']:.1f} s -> {cfg.out}"
        )
        if (fleet := summary.get("fleet_final_error")) and fleet[-1]:
            print(
                f"  fleet of {cfg.fleet}: {sum(e <= line for e in fleet[-1])} robots within {line:g} at the last "
                f"epoch, {summary['robot_steps_per_second']:.0f} robot-steps/s"
            )
    if lost := sum(summary.get("tokens_lost", {}).values()):
        print(
            f"kinswarm: {lost} liveliness token(s) went away while training (events.jsonl): a fault, or an actor "
            f"starved past the {cfg.lease_ms} ms lease (--lease-ms); such a run can differ from an undisturbed one",
            file=sys.stderr,
        )
    if summary.get("error"):
        how = "goes on from its last checkpoint" if summary.get("epochs") else "starts it again (no epoch had ended)"
        again = f"`kinswarm run --resume {cfg.out}` {how}"
        print(f"kinswarm: the run failed: {summary['error']}; {again}", file=sys.stderr)
        return 1
    if summary.get("interrupted"):
        return interrupted_code(by=summary.get("interrupted_by", ""))
    return 0
