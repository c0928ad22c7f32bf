"""Runs for the experiments: `kinswarm run`'s machinery. A run that needs no messages (the learning agents, one
robot, no process or link fault in its scenario, no trace of the step messages) runs in the `inprocess` placement:
the same step library the actors call, in a plain loop, with the same errors, metrics and checkpoints as the other
placements for the same seed (tests/test_inprocess.py), and several times faster. The others run in `single`
placement (the same Supervisor, actors and wire, in one process), with an observer of the step messages (`sim/task`,
`sim/obs/*`) for the end-effector path and the joint effort (optimality), subscribed on the run's session before any
actor exists, so nothing is missed. A spec in `process` placement (what process faults need: an agent's process
stopped or killed) runs through `kinswarm run`'s own launcher (launch.run_swarm), one OS process per actor.

Each run is a `Spec`: a run file and overrides of its fields, resolved by the one loader (actors/files/runfile.py). It
lives in its own directory with `spec.json`, and is reused when that directory already holds a finished run of the
same resolved run, or of the same run with more epochs (the first epochs of a longer run are bit-identical to a
shorter run: lockstep and seeded RNGs).
"""

from __future__ import annotations

import asyncio
import dataclasses
import functools
import hashlib
import json
import math
import os
import shutil
import socket
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from kinswarm.actors.deploy.plan import free_endpoint
from kinswarm.actors.files.config import AUTO_LISTEN, ConfigError, RunConfig, placement_problem
from kinswarm.actors.files.resolved import write_resolved
from kinswarm.actors.files.runfile import learner_settings, read_run_file, resolve, task_of
from kinswarm.actors.policies.registry import DEFAULT as DEFAULT_KIND
from kinswarm.actors.report import read_metrics, write_summary
from kinswarm.actors.runtime import open_session, tap
from kinswarm.actors.supervisor import RunResult, SinglePlacement, Supervisor
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import Obs, Task
from kinswarm.protocol.scenario import load_scenario
from kinswarm.protocol.topology import Topology

ROOT = Path(__file__).resolve().parent.parent
CHAIN4 = ROOT / "examples" / "chain4.toml"
LISTEN = "tcp/127.0.0.1:0"  # single placement: nobody connects, so any free port (no races between workers)
# No fault here is a missing actor, so a missed step deadline could only come from a loaded machine; it would
# make a joint hold and the run depend on the load. A long deadline keeps every run a function of its seed. (An
# agent stopped on purpose, `process` placement, costs the one step it is lost in, ended at this deadline.)
DEADLINE_MS = 10_000

Goal = tuple[float, float]


@dataclass(frozen=True)
class Spec:
    """One swarm run: `file`, a run file, with these fields set over it. `goals`: a goal per epoch, cycled (None: the
    file's); `learner`, `task`, `scene`: (field, value) overrides of those tables; `observe`: record every step's
    tips and joint angles (trace.npz)."""

    name: str
    seed: int = 0
    epochs: int = 60
    steps: int = 500
    reward: str | None = None  # None: the file's
    learner: tuple[tuple[str, Any], ...] = ()
    task: tuple[tuple[str, Any], ...] = ()
    scene: tuple[tuple[str, Any], ...] = ()
    goals: tuple[Goal, ...] | None = None
    file: str = str(CHAIN4)
    from_dir: str | None = None
    learn: bool = True
    explore: bool = True
    successive: bool = False  # each epoch starts where the last ended (RunConfig.successive)
    scenario: str | None = None
    controller: str = "agents"
    observe: bool = False
    # Another run starts from this one's checkpoints (`--from`): only a run of exactly these epochs will do.
    # Not part of the identity: it changes nothing in the run.
    checkpoint: bool = False
    # "process": one OS process per actor (`kinswarm run --placement process`), for process faults (freeze, kill);
    # no `observe`. A run without them gives the same errors in either placement (tests/test_swarm.py). "single":
    # in this process, run in the `inprocess` placement when it needs no messages (run_spec), else in `single`.
    placement: str = "single"

    def overrides(self) -> list[tuple[tuple[str, ...], Any]]:
        """The fields this spec sets over its run file."""
        out: list[tuple[tuple[str, ...], Any]] = [
            (("run", "seed"), self.seed),
            (("run", "epochs"), self.epochs),
            (("run", "steps"), self.steps),
            (("run", "placement"), self.placement),
            (("run", "learn"), self.learn),
            (("run", "explore"), self.explore),
            (("run", "successive"), self.successive),
            (("run", "controller"), self.controller),
            (("run", "deadline_ms"), DEADLINE_MS),
            (("run", "checkpoint_every"), 0),  # the last epoch only: what --from needs
            (("run", "record"), False),  # the report draws what it needs; no animation or recording per run
        ]
        if self.from_dir is not None:
            out.append((("run", "from"), self.from_dir))
        if self.scenario is not None:
            out.append((("run", "scenario"), self.scenario))
        if self.reward is not None:
            out.append((("task", "reward"), self.reward))
        if self.goals:
            out.append((("task", "goals"), [list(g) for g in self.goals]))
        for section, pairs in (("learner", self.learner), ("task", self.task), ("scene", self.scene)):
            out += [((section, k), _listed(v)) for k, v in pairs]
        return out

    def config(self, out: Path, run_id: str | None = None, listen: str = LISTEN) -> RunConfig:
        return resolve(
            read_run_file(self.file), self.file, self.overrides(), run_id=run_id or "x", out=out, listen=listen
        )

    def identity(self, with_epochs: bool = True) -> str:
        """The run's hash: of what it runs (the resolved robot, scene, task, every agent's learner and run fields,
        `from_dir` by its run's directory name), not of where or how it is spelled, so a cache serves any checkout
        and any --out."""
        cfg = self.config(Path("."))
        d = {f: getattr(cfg, f) for f in ("robot", "scene", "task", "learner", *_RUN_FIELDS)}
        # every agent's learner as the run builds it: the overrides on the task's and the state kind's defaults, so a
        # changed default (a kind's lr, a task's scale) is another run, not a cached one
        task = task_of(cfg)
        d["learner"] = {a: dataclasses.asdict(s) for a, s in learner_settings(task, cfg.learner).items()}
        # the learner kind is not among its settings; the paper's is left out, so the runs made before there were
        # other kinds keep their identity (and their cache entries)
        if (kind := cfg.learner.get("kind", DEFAULT_KIND)) != DEFAULT_KIND:
            d["learner_kind"] = kind
        # the task's settings at their defaults are left out: a setting added later (off by default) leaves the
        # runs made before it their identity and their cache entries
        defaults = _defaults(type(task.settings))
        d["task"] = {k: v for k, v in d["task"].items() if k not in defaults or _plain(v) != defaults[k]}
        if self.from_dir is not None:
            d["from_dir"] = Path(self.from_dir).name  # itself "<name>-<identity>": portable
        if self.scenario is not None:
            d["scenario"] = _content(self.scenario)
        if self.placement != "single":  # a process fault applies only there (single: refused, the run goes on)
            d["placement"] = self.placement
        if not with_epochs:
            d.pop("epochs")
        return hashlib.sha256(json.dumps(d, sort_keys=True, default=json_default).encode()).hexdigest()[:16]


def _plain(value: Any) -> str:
    return json.dumps(value, sort_keys=True, default=json_default)


@functools.cache
def _defaults(settings: type) -> dict[str, str]:
    """A settings dataclass's default values, as `_plain` spells them."""
    out = {}
    for f in dataclasses.fields(settings):
        if f.default is not dataclasses.MISSING:
            out[f.name] = _plain(f.default)
        elif f.default_factory is not dataclasses.MISSING:
            out[f.name] = _plain(f.default_factory())
    return out


_RUN_FIELDS = ("epochs", "steps", "seed", "learn", "explore", "successive", "controller", "action_deg", "from_dir")


def json_default(o: Any) -> Any:
    """json.dumps's default for what settings hold: dataclasses (StateVariable) as tables, the rest as lists."""
    if dataclasses.is_dataclass(o) and not isinstance(o, type):
        return dataclasses.asdict(o)
    if isinstance(o, Path):
        return str(o.relative_to(ROOT)) if o.is_relative_to(ROOT) else str(o)
    return list(o)


def _listed(v: Any) -> Any:
    """Override values as a run file holds them: lists for tuples (nested), tables for dataclasses."""
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return {f.name: _listed(getattr(v, f.name)) for f in dataclasses.fields(v)}
    if isinstance(v, tuple | list):
        return [_listed(x) for x in v]
    return v


def resolved(file: str | Path) -> RunConfig:
    """A run file as the loader resolves it, for its robot, scene and task (nothing runs: a run it continues need
    not exist yet)."""
    return resolve(read_run_file(file), str(file), [(("run", "from"), None)], run_id="x", out=Path("."), listen=LISTEN)


def robot_and_goal(file: str | Path) -> tuple[Topology, Goal]:
    """A run file's robot and its task's goal (of the first epoch)."""
    cfg = resolved(file)
    return cfg.topo(), task_of(cfg).goal(0, cfg.steps)[0]


def _content(path: str) -> str:
    """A file by what it holds (a missing file by its path: the run will say what is wrong)."""
    try:
        st = os.stat(path)
    except OSError:
        return path
    return _content_hash(os.path.realpath(path), st.st_mtime_ns, st.st_size)


@functools.lru_cache(maxsize=256)
def _content_hash(path: str, mtime_ns: int, size: int) -> str:
    return "sha256:" + hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]


def learner_overrides(**kw: Any) -> tuple[tuple[str, Any], ...]:
    """Hashable overrides (tuples for the sequence-valued ones)."""
    return tuple(sorted((k, tuple(v) if isinstance(v, list) else v) for k, v in kw.items()))


@dataclass
class RunOutcome:
    spec: Spec
    out: Path
    summary: dict[str, Any]
    rows: list[dict[str, Any]] = field(default_factory=list)  # metrics.jsonl, the first spec.epochs rows

    @property
    def placement(self) -> str:
        """Where the run ran, as its config.json says (a run cached from before `inprocess`: `single`)."""
        try:
            return str(json.loads((self.out / "config.json").read_text())["placement"])
        except (OSError, ValueError, KeyError):
            return self.spec.placement

    @property
    def final_errors(self) -> list[float]:
        return [r["final_error"] for r in self.rows]

    @property
    def mean_errors(self) -> list[float]:
        return [r["mean_error"] for r in self.rows]

    def trace(self) -> dict[str, np.ndarray]:
        with np.load(self.out / "trace.npz") as z:
            return {k: z[k] for k in z.files}


async def _supervise(
    cfg: RunConfig, topo: Topology, observe: bool, record: Sequence[str] = ()
) -> tuple[RunResult, list[tuple[str, bytes]]]:
    """Run cfg in this process. `observe`: record the task and every Obs (for trace.npz); `record`: key
    expressions to record besides (tests and probes)."""
    session = open_session(listen=[free_endpoint() if cfg.listen == AUTO_LISTEN else cfg.listen])
    captured: list[tuple[str, bytes]] = []
    subs = []

    def keep(key: str, payload: bytes) -> None:  # the sender's thread or Zenoh's: only append; decoded after the run
        captured.append((key, payload))

    keys = Keys(cfg.run_id)
    exprs = [*((keys.task, keys.obs("*")) if observe else ()), *record]
    subs = [tap(session, key, keep) for key in exprs]  # before any actor exists: no step missed
    sup = Supervisor(cfg, topo, session, SinglePlacement(cfg, topo, session))
    try:
        result = await sup.run()
    finally:
        for s in subs:
            s.undeclare()
        session.close()
    return result, captured


def _write_trace(path: Path, cfg: RunConfig, topo: Topology, captured: list[tuple[str, bytes]]) -> None:
    """trace.npz: per (epoch, step) the end-effector tip (before the step's actions) and every joint angle."""
    dof = list(topo.dof_agents)
    tips: dict[tuple[int, int], tuple[float, float]] = {}
    qs: dict[tuple[int, int], dict[str, float]] = {}
    obs_prefix = Keys(cfg.run_id).obs("")
    for key, payload in captured:
        if key.startswith(obs_prefix):
            m = codec.decode(payload, Obs, cfg.run_id, cfg.key)
            qs.setdefault((m.epoch, m.step), {})[key[len(obs_prefix) :]] = m.q
        else:
            t = codec.decode(payload, Task, cfg.run_id, cfg.key)
            pts = list(t.tips.values())
            tips[(t.epoch, t.step)] = (sum(p[0] for p in pts) / len(pts), sum(p[1] for p in pts) / len(pts))
    steps = sorted(k for k in tips if k in qs and len(qs[k]) == len(dof))
    np.savez_compressed(
        path,
        epoch=np.array([k[0] for k in steps], dtype=np.int64),
        step=np.array([k[1] for k in steps], dtype=np.int64),
        tip=np.array([tips[k] for k in steps], dtype=np.float64).reshape(-1, 2),
        q=np.array([[qs[k][a] for a in dof] for k in steps], dtype=np.float64).reshape(-1, len(dof)),
        agents=np.array(dof),
    )


def _finished(run_dir: Path) -> dict[str, Any] | None:
    try:
        spec = json.loads((run_dir / "spec.json").read_text())
        summary = json.loads((run_dir / "summary.json").read_text())
    except (OSError, json.JSONDecodeError):
        return None
    if summary.get("error") or summary.get("interrupted"):
        return None
    return {"spec": spec, "summary": summary}


def find_cached(spec: Spec, runs: Path) -> Path | None:
    """A finished run of this spec, or of the same spec with at least as many epochs (its prefix is this run)."""
    if not runs.is_dir():
        return None
    want = spec.identity(with_epochs=False)
    best: tuple[int, Path] | None = None
    for name, (identity, epochs) in _index(runs).items():
        if identity != want or (spec.observe and not (runs / name / "trace.npz").is_file()):
            continue  # another run, or the same one not traced (observe is not part of a run's identity)
        if epochs == spec.epochs or (epochs > spec.epochs and not spec.observe and not spec.checkpoint):
            if best is None or epochs < best[0]:
                best = (epochs, runs / name)
    # absolute, like a fresh run's: a path that goes into another spec (`from_dir`) must not depend on how
    # --out was spelled, or that spec's identity would change between a fresh and a cached run
    return None if best is None else best[1].resolve()


# runs directory -> {finished run's directory name: (identity without epochs, epochs)}; a finished run never changes
_INDEX: dict[Path, dict[str, tuple[str, int]]] = {}


def _index(runs: Path) -> dict[str, tuple[str, int]]:
    known = _INDEX.setdefault(runs.resolve(), {})
    for d in runs.iterdir():
        if d.name not in known and d.is_dir() and (done := _finished(d)) is not None:
            known[d.name] = (_identity_of(done["spec"]), int(done["spec"]["epochs"]))
    return known


def _identity_of(recorded: dict[str, Any]) -> str:
    """A finished run's identity without epochs, as its spec.json records it."""
    return str(recorded.get("identity_wo_epochs", ""))


def run_spec(spec: Spec, runs: Path) -> RunOutcome:
    """Run one spec under `runs/` (or reuse a finished run of it) and return its outcome."""
    cached = find_cached(spec, runs)
    if cached is None:
        out = (runs / f"{spec.name}-{spec.identity()[:8]}").resolve()
        if out.exists():  # an unfinished earlier attempt
            shutil.rmtree(out)
        if spec.placement != "single":
            return _run_in_processes(spec, out)
        out.mkdir(parents=True)
        cfg = spec.config(out, run_id=f"x{spec.identity()}")
        inprocess = needs_no_messages(spec, cfg)
        if inprocess:
            cfg = dataclasses.replace(cfg, placement="inprocess")
        topo = cfg.topo()
        cfg.write(out / "config.json")
        write_resolved(cfg, out / "run.toml")
        (out / "metrics.jsonl").write_text("")
        if inprocess:
            result, captured = _run_inprocess(cfg, topo), []
        else:
            result, captured = asyncio.run(_supervise(cfg, topo, spec.observe))
        summary = write_summary(
            out,
            {"wall_seconds": result.wall_seconds, "interrupted": result.interrupted, "error": result.error},
        )
        if result.error or result.interrupted:
            raise RuntimeError(f"run {spec.name} (seed {spec.seed}) failed: {result.error or 'interrupted'}")
        if spec.observe:
            _write_trace(out / "trace.npz", cfg, topo, captured)
        record = {**dataclasses.asdict(spec), "identity_wo_epochs": spec.identity(with_epochs=False)}
        (out / "spec.json").write_text(json.dumps(record, indent=1, default=json_default) + "\n")  # last: marks it done
        cached = out
    summary = json.loads((cached / "summary.json").read_text())
    rows = read_metrics(cached)[: spec.epochs]
    return RunOutcome(spec, cached, summary, rows)


def needs_no_messages(spec: Spec, cfg: RunConfig) -> bool:
    """Whether a `single` spec can run in the `inprocess` placement: the learning agents of one robot, no trace of
    the step messages (`observe` taps them) and no fault in its scenario that only processes or links can suffer
    (those `single` applies, and `inprocess` refuses)."""
    if spec.observe or cfg.controller != "agents" or cfg.fleet > 1:
        return False
    if cfg.scenario is None:
        return True
    entries = load_scenario(cfg.scenario, cfg.topo()).entries
    return not any(placement_problem(e.fault.fault, "inprocess") for e in entries)


def _run_inprocess(cfg: RunConfig, topo: Topology) -> RunResult:
    """Run cfg in the `inprocess` placement (actors/run/inprocess.py): its metrics, events and checkpoints in
    cfg.out, as a swarm's."""
    from kinswarm.actors.run.inprocess import InProcessRun
    from kinswarm.actors.supervisor.recorder import Recorder

    return InProcessRun(cfg, topo).run(Recorder(Path(cfg.out)))


def _run_in_processes(spec: Spec, out: Path) -> RunOutcome:
    """Run `spec` as `kinswarm run --placement process` does (launch.run_swarm: its records, summary and plots), on
    a free loopback port (the actors connect to it; another run may take the port first: then another)."""
    from kinswarm.actors.run.launch import run_swarm

    if spec.observe:
        raise ValueError(f"run {spec.name}: `observe` needs the single placement")
    for attempt in range(3):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        cfg = spec.config(out, run_id=f"x{spec.identity()}", listen=f"tcp/127.0.0.1:{port}")
        try:
            summary = run_swarm(cfg, cfg.topo())
            break
        except ConfigError as e:
            if "cannot open the supervisor's session" not in str(e) or attempt == 2:
                raise
            shutil.rmtree(out, ignore_errors=True)
    if summary.get("error") or summary.get("interrupted"):
        raise RuntimeError(f"run {spec.name} (seed {spec.seed}) failed: {summary.get('error') or 'interrupted'}")
    record = {**dataclasses.asdict(spec), "identity_wo_epochs": spec.identity(with_epochs=False)}
    (out / "spec.json").write_text(json.dumps(record, indent=1, default=json_default) + "\n")  # last: marks it done
    return RunOutcome(spec, out, summary, read_metrics(out)[: spec.epochs])


def chain_topology(n: int, path: Path, link: float | None = None) -> Path:
    """A run file of a planar n-joint chain like examples/chain4.toml (reach 12, start angles 0, 10, 20, ... deg)."""
    length = 12.0 / n if link is None else link
    lines = [
        f"# A planar {n}-joint chain for the cost experiment (reach {n * length:g}).",
        "[robot]",
        f'name = "chain{n}"',
        "base = [0.0, 0.0, 0.0]",
        "",
        "[robot.defaults]",
        f"link_length = {length!r}",
        "limits_deg = [-180.0, 180.0]",
    ]
    for i in range(1, n + 1):
        lines += ["", "[[robot.agent]]", f'id = "a{i}"', f"initial_deg = {10.0 * (i - 1) % 90!r}"]
        if i > 1:
            lines.append(f'parent = "a{i - 1}"')
    x = y = h = 0.0
    for i in range(n):
        h += math.radians(10.0 * i % 90)
        x += length * math.cos(h)
        y += length * math.sin(h)
    lines += ["", "[task]", 'kind = "reach"', f"goal = [{round(0.5 * x, 3)}, {round(0.5 * y + 2.0, 3)}]"]
    path.write_text("\n".join(lines) + "\n")
    return path
