"""`kinswarm run --resume RUN-DIR`: a run whose supervisor died (SIGKILL, a power cut), was interrupted (Ctrl-C,
SIGTERM) or failed (a full disk, a read-only directory, an actor that kept dying) continues from its last complete
checkpoint, in its own directory, as config.json resolved it. Only a run that finished is not resumed. A run directory
moved or copied since resumes where it is now (`settle`): a copy as a run of its own.

The last complete checkpoint is the newest epoch every learning agent holds a good checkpoint of (`<id>.npz` or,
when the supervisor died between two agents' saves, `<id>.prev.npz`), and that metrics.jsonl holds whole rows up
to. Before the run goes on, under the run's lock: the rows of metrics.jsonl, poses.jsonl and agents.jsonl past that
epoch are dropped (the epochs train again), each agent's `<id>.npz` is made that epoch's checkpoint (a newer one is
dropped: it learned from an epoch that trains again), and events.jsonl says where the run resumed. When no epoch is
held by every agent (one was down over two of the others' saves, so its two checkpoints are older than theirs), the
run goes on after the oldest agent's newest: each agent from its newest checkpoint up to that epoch, else its
oldest. It is not the uninterrupted run's state then (no epoch's is complete), but no trained epoch is thrown away:
starting from scratch would lose them all, as a chaos soak found (525 epochs, at the 14th crash). Its agents
restore their learned state from there, their random generators included, so a deterministic run (`single`
placement, a checkpoint every epoch, same seed) ends as it would have without the crash.

What is not carried over: live faults injected before the crash (`kinswarm fault`) and a scenario's faults due before
the resumed epoch (those due from it on come as scheduled), the simulator's disturbance draws (a fresh stream), and
with `successive` the robot's pose (the resumed epoch starts from the task's start pose)."""

from __future__ import annotations

import contextlib
import dataclasses
import json
import logging
import os
import secrets
from dataclasses import dataclass
from pathlib import Path

from kinswarm.actors.files.checkpoint import CheckpointError, load_checkpoint, previous
from kinswarm.actors.files.config import ConfigError, RunConfig, load_run_config, recorded_version, writer_version
from kinswarm.actors.files.rundir import failed_start, lock_held, run_state
from kinswarm.protocol.keys import check_id

log = logging.getLogger("kinswarm.resume")

FLAG = "--resume"


@dataclass(frozen=True)
class Resume:
    epoch: int  # the first epoch the resumed run trains: the checkpoint's epoch + 1 (0: from the start)
    restore: bool  # the agents restore this run's checkpoint (else they start as the run started)
    detail: str  # for events.jsonl


def check_resume(run_dir: Path) -> RunConfig:
    """The run in `run_dir` as config.json resolved it, or one line (ConfigError) naming why it cannot be resumed.
    Reads only: nothing in the directory changes."""
    where = f"{FLAG} {run_dir}"
    if run_dir.exists() and not run_dir.is_dir():
        raise ConfigError(f"{where}: a file, not a run directory (give the directory that holds config.json)")
    if not run_dir.is_dir():
        raise ConfigError(f"{where}: no such directory")
    config = run_dir / "config.json"
    if not config.is_file():
        raise ConfigError(f"{where}: holds no run (no config.json)")
    _check_whole(config, where)
    written, mine = recorded_version(config), writer_version()
    if written != mine:
        made = f"kinswarm {written}" if written else "a kinswarm that recorded no version"
        raise ConfigError(f"{where}: a run made by {made}, not this one ({mine}): resume it with that version")
    try:
        cfg = load_run_config(config)
    except ConfigError as e:
        raise ConfigError(f"{where}: {e}") from None
    if lock_held(run_dir):
        raise ConfigError(f"{where}: run {cfg.run_id} is still running (a process holds its lock): nothing to resume")
    state = run_state(run_dir)
    if state.summary is not None and not _ended_early(state.summary):
        raise ConfigError(f"{where}: run {cfg.run_id} {state.how} at {state.when} (summary.json): nothing to resume")
    if failed_start(run_dir):
        raise ConfigError(f"{where}: run {cfg.run_id} never began (no epoch): start it again with `kinswarm run`")
    if cfg.placement == "inprocess":
        raise ConfigError(f"{where}: run {cfg.run_id} ran in the inprocess placement, which cannot be resumed")
    if len(cfg.hosts) > 1:
        raise ConfigError(f"{where}: run {cfg.run_id} ran on several hosts; resume runs on one (start it again)")
    return cfg.located(run_dir)  # moved or copied since: its files are here (settle makes it so under the lock)


def _ended_early(summary: dict) -> bool:
    """A summary of a run that failed or was interrupted: the run goes on from its checkpoints, as a killed one."""
    return bool(summary.get("error") or summary.get("interrupted"))


def _check_whole(config: Path, where: str) -> None:
    """config.json is a JSON object, or one line saying it is corrupt (not that a version is missing: a torn or
    overwritten file records nothing, whoever wrote it)."""
    try:
        data = json.loads(config.read_bytes())
    except OSError as e:
        raise ConfigError(f"{where}: cannot read {config} ({e.strerror or e})") from None
    except ValueError as e:  # UnicodeDecodeError included
        raise ConfigError(f"{where}: {config} is corrupt (not JSON: {e}); the run cannot be resumed") from None
    if not isinstance(data, dict):
        raise ConfigError(f"{where}: {config} is corrupt (not a JSON object); the run cannot be resumed")


def settle(out: Path, cfg: RunConfig) -> tuple[RunConfig, str]:
    """Under the run's lock, before anything is spawned: a run directory moved or copied since config.json was written
    becomes the run at its place, and config.json says so. It takes a secret of its own: a copy is a run of its own,
    and two copies (of a run since moved, even) can never take each other's messages. Its run id follows the
    directory's name when the run was named by its directory (`runs/<run-id>`); a copy whose original is still where
    it was never keeps the original's id. `cfg`: check_resume's (`--listen` may differ from the recorded); returns it
    settled, and a note for events.jsonl ("" when the run is where it was)."""
    config = out / "config.json"
    recorded = load_run_config(config)
    here, old = out.resolve(), Path(recorded.out)
    if _same_dir(here, old):
        return cfg, ""
    copy = _holds(old, recorded)
    run_id = recorded.run_id
    if recorded.run_id == old.name and _valid_id(here.name):
        run_id = here.name
    if copy and run_id == recorded.run_id:
        run_id = f"{recorded.run_id[:59]}-{secrets.token_hex(2)}"
    mine = {"out": str(here), "run_id": run_id, "secret": secrets.token_hex(16)}
    what = f"a copy of run {recorded.run_id} in {old}" if copy else f"run {recorded.run_id} moved from {old}"
    named = f", now run {run_id}" if run_id != recorded.run_id else ""
    dataclasses.replace(recorded, **mine).write(config)
    return dataclasses.replace(cfg, **mine), f"{what}{named}, with a secret of its own"


def _same_dir(a: Path, b: Path) -> bool:
    try:
        return a == b or os.path.samefile(a, b)
    except OSError:
        return False


def _holds(old: Path, run: RunConfig) -> bool:
    """Whether `old` still holds `run` (its config.json, with the run's secret)."""
    try:
        return load_run_config(old / "config.json").secret == run.secret
    except (ConfigError, OSError):
        return False


def _valid_id(name: str) -> bool:
    try:
        check_id("run id", name)
    except ValueError:
        return False
    return True


def _whole_epochs(path: Path) -> list[int]:
    """The epochs 0, 1, ... whose rows metrics.jsonl holds whole and in order (up to the first torn or missing)."""
    epochs: list[int] = []
    with contextlib.suppress(OSError):
        for line in path.read_text(errors="replace").splitlines():
            try:
                row = json.loads(line)
            except ValueError:
                break
            if not isinstance(row, dict) or row.get("epoch") != len(epochs):
                break
            epochs.append(len(epochs))
    return epochs


def _checkpoints(directory: Path, agent: str) -> dict[int, Path]:
    """An agent's good checkpoints of this run, by epoch (its newest and the one before)."""
    found: dict[int, Path] = {}
    for path in (directory / f"{agent}.npz", previous(directory / f"{agent}.npz")):
        with contextlib.suppress(CheckpointError):
            _, meta = load_checkpoint(path, agent=agent)
            if isinstance(meta.get("run_epoch"), int):
                found.setdefault(meta["run_epoch"], path)
    return found


def _keep_rows(path: Path, last: int) -> int:
    """Rewrite a jsonl file with its rows of epochs <= `last` only (atomically); the rows dropped."""
    if not path.exists():
        return 0
    kept, dropped = [], 0
    for line in path.read_text(errors="replace").splitlines():
        try:
            epoch = json.loads(line).get("epoch")
        except (ValueError, AttributeError):
            epoch = None
        if isinstance(epoch, int) and epoch <= last:
            kept.append(line + "\n")
        else:
            dropped += 1
    if dropped:
        tmp = path.with_name(f".{path.name}.resume")
        tmp.write_text("".join(kept))
        os.replace(tmp, path)
    return dropped


def prepare_resume(out: Path, cfg: RunConfig) -> Resume:
    """Make `out` the run as it was at its last complete checkpoint (the caller holds its lock). The summary of a run
    that failed or was interrupted goes (what it said is in the resume's detail): the resumed run writes its own."""
    ended = run_state(out)
    before = f"after it {ended.how} at {ended.when}; " if ended.summary is not None else ""
    (out / "summary.json").unlink(missing_ok=True)
    agents = cfg.topo().dof_agents if cfg.controller == "agents" and cfg.learn else []
    whole = _whole_epochs(out / "metrics.jsonl")
    last_row = whole[-1] if whole else -1
    directory = out / "agents"
    mixed = False
    if agents:
        held = [{e: p for e, p in _checkpoints(directory, a).items() if e <= last_row} for a in agents]
        common = set.intersection(*(set(h) for h in held)) if held else set()
        last = max(common, default=-1)
        if last < 0 and all(held):  # every agent holds one, of no one epoch: an agent down over two saves lags
            last, mixed = min(max(h) for h in held), True  # each its newest up to the oldest of theirs, else its oldest
    else:  # nothing learns: every whole epoch stands
        held, last = [], last_row
    dropped = {name: _keep_rows(out / name, last) for name in ("metrics.jsonl", "poses.jsonl", "agents.jsonl")}
    for agent, found in zip(agents, held, strict=True):
        newest = directory / f"{agent}.npz"
        for tmp in directory.glob(f".{agent}.npz.*.tmp"):  # a save the kill cut short
            tmp.unlink(missing_ok=True)
        if last < 0:  # no checkpoint every agent has: from the start, as the run began
            newest.unlink(missing_ok=True)
            previous(newest).unlink(missing_ok=True)
        else:  # saved after the last complete checkpoint: that epoch trains again
            use = max((e for e in found if e <= last), default=min(found))
            if found[use] != newest:
                os.replace(found[use], newest)
    if mixed:
        source = f"epoch {last}, each agent its newest checkpoint up to it or its oldest (no epoch every agent holds)"
    elif last >= 0 and agents:
        source = f"the checkpoint of epoch {last}"
    elif agents:
        source = "the start (no checkpoint every agent holds)"
    else:
        source = f"epoch {last + 1} (nothing learns: no checkpoint needed)"
    detail = f"{before}resumed from {source}; metrics rows dropped past it: {dropped['metrics.jsonl']}"
    if before:
        log.warning("run %s %s at %s: going on from %s", cfg.run_id, ended.how, ended.when, source)
    return Resume(epoch=last + 1, restore=last >= 0 and bool(agents), detail=detail)
