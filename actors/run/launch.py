"""Launching one run: the supervisor's session, its placement, the progress bar, Ctrl-C handled once, and the run
directory's records (config.json, run.toml, metrics, summary, plots). `kinswarm run`, `baseline` and `up` and the
Python API all come through `run_swarm`."""

from __future__ import annotations

import asyncio
import contextlib
import dataclasses
import logging
import os
import signal
import statistics
import sys
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

from kinswarm.actors.deploy.plan import Plan, PlanError, local_plan
from kinswarm.actors.files.config import AUTO_LISTEN, ENDPOINT, ConfigError, RunConfig
from kinswarm.actors.files.resolved import write_resolved
from kinswarm.actors.files.resume import Resume, prepare_resume, settle
from kinswarm.actors.files.rundir import Claim, claim, reclaim
from kinswarm.actors.runtime import NetSpec, open_session
from kinswarm.actors.runtime.hub import Hub
from kinswarm.actors.runtime.net import zenoh_reason
from kinswarm.protocol.messages import EpochDone
from kinswarm.protocol.topology import Topology

if TYPE_CHECKING:
    import zenoh
    from kinswarm.actors.supervisor.result import RunResult

log = logging.getLogger("kinswarm.launch")


def write_net(path: Path, spec: NetSpec) -> Path:
    """Owner-only: a NetSpec may carry a password."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "w") as f:
        f.write(spec.to_json() + "\n")
    return path


class Interrupted(KeyboardInterrupt):
    """A start interrupted (Ctrl-C, SIGTERM) before its first epoch: it leaves nothing; `signum` for the exit code."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


@contextlib.contextmanager
def _signals_stop_once() -> Iterator[list[int]]:
    """Ctrl-C or SIGTERM cancels the running task once; the supervisor then stops the swarm and the
    summary is written. More signals until then only say so: a second Ctrl-C cancelling the shutdown
    would leave the actors without their Stop and the run without its summary. Yields the signals caught, in order
    (the first is the one that stopped the run: its exit code)."""
    task, loop = asyncio.current_task(), asyncio.get_running_loop()
    assert task is not None
    caught: list[int] = []

    def on_signal(sig: int) -> None:
        caught.append(sig)
        if len(caught) == 1:
            task.cancel()
        elif len(caught) == 2:
            print("kinswarm: stopping the swarm and writing its summary, please wait", file=sys.stderr)

    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, on_signal, int(sig))
    try:
        yield caught
    finally:
        for sig in (signal.SIGINT, signal.SIGTERM):
            loop.remove_signal_handler(sig)


async def _supervise(
    cfg: RunConfig,
    topo: Topology,
    progress: bool,
    plan: Plan,
    host: str,
    claimed: Claim,
    wait_s: float = 600.0,
    view: str | None = None,
    resume: Resume | None = None,
) -> dict:
    from kinswarm.actors.deploy.hosts import control_net
    from kinswarm.actors.supervisor import ProcessPlacement, SinglePlacement, Supervisor

    out = Path(cfg.out)
    session, plan, hub = _open_session(cfg, topo, plan, host)
    lead = host == plan.leader
    sup_id = "main" if lead else host
    # where the run listens, for `kinswarm fault/status` (an auto port is known only from here)
    write_net(out / "net" / "cli.json", control_net(plan, host, topo))

    def nets(role: str, ident: str) -> Path:  # this run's own, fresh (a restart rewrites the same content)
        identity = plan.identity(role, ident, host)
        return write_net(out / "net" / f"{identity}.json", plan.net(host, identity, supervisor=False, topo=topo))

    with contextlib.ExitStack() as undo:  # until the run begins, a failure leaves nothing of it (its port free again)
        if hub is not None:
            undo.callback(hub.close)
        undo.callback(session.close)
        on_epoch, close_watchers, on_start = _watchers(cfg, progress and lead, view if lead else None)
        undo.callback(close_watchers)
        placement: ProcessPlacement | SinglePlacement
        if cfg.placement == "single":
            placement = SinglePlacement(cfg, topo, session)
        else:
            placement = ProcessPlacement(out / "config.json", nets, out / "logs", supervisor=sup_id)
        sup = Supervisor(cfg, topo, session, placement, on_epoch=on_epoch, plan=plan, host=host)
        sup.hosts_wait_s = wait_s
        sup.resumed = resume
        sup.on_start = on_start
        undo.pop_all()
    claimed.begin()  # from here on the run directory is the run's, however it ends
    with _signals_stop_once() as caught:
        try:
            result = await sup.run()
        finally:
            close_watchers()
            session.close()
            if hub is not None:
                hub.close()
        if result.interrupted and caught:
            result.signal = signal.Signals(caught[0]).name
            if resume is None and not result.epochs:  # stopped while starting: nothing of it blocks a retry
                claimed.withdraw()
                raise Interrupted(caught[0])
        if not lead:
            return {
                "host": host,
                "error": result.error,
                "interrupted": result.interrupted,
                "interrupted_by": result.signal,
                "restarts": result.restarts,
            }
        return _finish(cfg, result, progress)


def _open_session(cfg: RunConfig, topo: Topology, plan: Plan, host: str) -> tuple[zenoh.Session, Plan, Hub | None]:
    """The supervisor's session, the plan whose endpoint the host's hub listens on, and the hub. With actor processes
    the hub (the host's Zenoh router) is a process of its own, and the supervisor one of its clients
    (actors/runtime/hub.py: a paused supervisor must not pause the swarm); in the `single` placement the supervisor's
    session, which every actor shares, is the router. An auto port (no --listen) another program took between its
    pick and the bind (rare: a few ms) is picked again, a few times."""
    auto = plan.source == "(local)" and cfg.listen == AUTO_LISTEN
    tries = 5 if auto else 1
    for attempt in range(tries):
        spec = plan.net(host, plan.identity("supervisor", "", host), supervisor=True, topo=topo)
        hub = None
        try:
            if spec.mode == "router" and cfg.placement != "single":
                hub = Hub(write_net(Path(cfg.out) / "net" / "hub.json", spec))
                spec = spec.with_(
                    mode="client", listen=(), connect=spec.listen, must_connect=True, dictionary="", acl=None
                )
            return open_session(spec), plan, hub
        except Exception as e:
            if hub is not None:
                hub.close()
            if attempt + 1 < tries:
                log.info("picked port taken (%s): picking again", zenoh_reason(e))
                plan = local_plan(AUTO_LISTEN, cfg.lease_ms, plan.security.secret, plan.security.net_dir)
                continue
            where = ", ".join(spec.listen) or ", ".join(spec.connect)
            if plan.name != "local":
                hint = "check the plan's endpoints"
            elif auto:
                hint = f"{tries} free ports were taken before they could be bound"
            else:
                hint = "leave --listen out to take a free port"
            raise ConfigError(
                f"cannot open the supervisor's session on {where} ({zenoh_reason(e)}); is another run using it? {hint}"
            ) from None
    raise AssertionError("unreachable")


OnEpoch = Callable[[EpochDone], None]


def _watchers(
    cfg: RunConfig, progress: bool, view: str | None
) -> tuple[OnEpoch, Callable[[], None], Callable[[int, int], None]]:
    """What watches the run: the progress bar, the live viewer; (on_epoch, close, on_start: the bar says how many
    actors are ready while the swarm starts, which takes minutes for a hundred agents)."""
    bar = None
    if progress:
        from tqdm import tqdm

        bar = tqdm(total=cfg.epochs, unit="epoch", desc=cfg.run_id, dynamic_ncols=True)

    live = None
    if view is not None:
        from kinswarm.actors.report.recording import LiveRecording

        live = LiveRecording(cfg, view)

    def on_epoch(d: EpochDone) -> None:
        if live is not None:
            row = {"epoch": d.epoch, "final_error": d.final_error, "mean_error": d.mean_error, "errors": d.errors}
            live.epoch(row, d.angles)
        if bar is not None:
            fleet = {"median": f"{statistics.median(d.fleet):.3f}"} if d.fleet else {}  # a fleet: every robot's
            rate = d.steps * max(len(d.fleet), 1) / d.seconds  # robot-steps/s
            bar.set_postfix(final=f"{d.final_error:.3f}", mean=f"{d.mean_error:.3f}", **fleet, steps_s=f"{rate:.0f}")
            bar.update(1)

    def on_start(ready: int, of: int) -> None:
        if bar is not None:
            bar.set_postfix_str(f"starting: {ready}/{of} actors ready" if ready < of else "")

    def close() -> None:
        if bar is not None:
            bar.close()
        if live is not None:
            live.close()

    return on_epoch, close, on_start


def _finish(cfg: RunConfig, result: RunResult, progress: bool) -> dict:
    """The run's summary, plots and records, from what the leader gathered. What the disk refuses (full, read-only,
    forbidden) is one line, never a traceback: a summary that cannot be written fails the run and leaves it as a
    killed run leaves it, resumable; plots and records that cannot be written are a warning each (`kinswarm report`
    and `animate` draw them again)."""
    from kinswarm.actors.report import write_plots, write_summary
    from kinswarm.actors.supervisor.result import cannot_write

    out = Path(cfg.out)
    extra = {
        "wall_seconds": result.wall_seconds,
        "interrupted": result.interrupted,
        "interrupted_by": result.signal,
        "error": result.error,
        "rejected_messages": result.rejected,
        "rejected_by_actor": result.rejected_by,
        "restarts": result.restarts,
        "tokens_lost": result.tokens_lost,
    }
    try:
        summary = write_summary(out, extra)
    except OSError as e:
        from kinswarm.actors.report import summarize

        summary = summarize(out, extra)
        unwritten = cannot_write(out / "summary.json", e)
        summary["error"] = f"{summary['error']}; {unwritten}" if summary["error"] else unwritten
        return summary
    try:
        write_plots(out)
    except OSError as e:
        log.warning("plots not written: %s (`kinswarm report %s` draws them)", cannot_write(out, e), out)
    if cfg.record and summary["epochs"]:  # an interrupted start has no epoch to draw
        write_records(out, progress)
    return summary


def _run_inprocess(cfg: RunConfig, topo: Topology, progress: bool, view: str | None) -> dict:
    """The `inprocess` placement: the run as one plain loop (actors/run/inprocess.py)."""
    from kinswarm.actors.run.inprocess import InProcessRun
    from kinswarm.actors.supervisor.recorder import Recorder

    on_epoch, close_watchers, _ = _watchers(cfg, progress, view)
    try:
        result = InProcessRun(cfg, topo).run(Recorder(Path(cfg.out)), on_epoch)
    finally:
        close_watchers()
    return _finish(cfg, result, progress)


def write_records(out: Path, progress: bool) -> None:
    """What a person watches: motion.gif always, recording.rrd when the viewer's extra is installed. Never fails
    the run: what cannot be written is one warning."""
    from kinswarm.actors.report.animate import write_animation

    if progress:
        print(f"kinswarm: drawing {out / 'motion.gif'} ...", file=sys.stderr)
    try:
        write_animation(out)
    except Exception as e:  # a record of a finished run: the run itself stands
        log.warning("motion.gif not written: %s", e)
    from kinswarm.actors.report.recording import open_stream, record_run  # rerun itself only if the extra is there

    try:
        stream = open_stream(Path(out).name, save=out / "recording.rrd")
        record_run(out, stream)
        stream.flush()
        stream.disconnect()
    except ConfigError as e:  # the extra is not installed
        log.info("recording.rrd not written: %s", e)
    except Exception as e:
        log.warning("recording.rrd not written: %s", e)


def run_swarm(
    cfg: RunConfig,
    topo: Topology,
    progress: bool = False,
    plan: Plan | None = None,
    host: str | None = None,
    wait_s: float = 600.0,
    view: str | None = None,
) -> dict:
    """Run one swarm (or, with a deploy plan, one host's share of it) to the end and return its summary
    (used by the CLI, experiments and tests). Without a plan: the one-host plan (`kinswarm run`)."""
    plan = plan if plan is not None else local_plan(cfg.listen, cfg.lease_ms, cfg.key, Path(cfg.out) / "net")
    host = host if host is not None else plan.leader
    out = Path(cfg.out)
    check_start(plan, topo)
    with claim(out) as claimed:  # one run, once: refused before anything is written or spawned
        cfg.write(out / "config.json")
        if host == plan.leader:
            write_resolved(cfg, out / "run.toml")
            (out / "metrics.jsonl").write_text("")
        if cfg.placement == "inprocess":
            claimed.begin()  # nothing to open: the run begins here
            return _run_inprocess(cfg, topo, progress, view)
        return asyncio.run(_supervise(cfg, topo, progress, plan, host, claimed, wait_s, view))


def resume_swarm(cfg: RunConfig, topo: Topology, progress: bool = False, view: str | None = None) -> dict:
    """Continue the run in `cfg.out` (checked by resume.check_resume) from its last complete checkpoint, in its own
    directory, under its own lock: its rows past that checkpoint dropped, its agents restored from it."""
    plan = local_plan(cfg.listen, cfg.lease_ms, cfg.key, Path(cfg.out) / "net")
    check_start(plan, topo)
    out = Path(cfg.out)
    with reclaim(out) as claimed:
        cfg, moved = settle(out, cfg)
        resume = prepare_resume(out, cfg)
        if moved:
            resume = dataclasses.replace(resume, detail=f"{moved}; {resume.detail}")
        return asyncio.run(_supervise(cfg, topo, progress, plan, plan.leader, claimed, view=view, resume=resume))


def check_start(plan: Plan, topo: Topology) -> None:
    """What would fail a start, said before the run directory is touched: every actor placed once, and no
    supervisor on port 0 (the system would pick a port nobody else knows: the actors and the other hosts are
    told the endpoint as written)."""
    plan.placement(topo)
    for name, h in plan.hosts.items():
        m = ENDPOINT.fullmatch(h.listen)
        if m is None or int(m.group(3)) != 0:
            continue
        why = "port 0 lets the system pick a port the actors cannot know: give a free port"
        if plan.name == "local" and plan.source == "(local)":
            raise ConfigError(f"--listen {h.listen}: {why}, or leave --listen out: the run then picks one it can tell")
        raise PlanError(plan.source, f"host {name}.listen", f"{h.listen}: {why}")
