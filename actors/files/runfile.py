"""Run files: the one loader. A TOML run file holds everything a run needs; `kinswarm run FILE`, `kinswarm up` (a
plan names a run file), the experiments and the Python API all resolve it here, so every default is written once
(in the dataclass that owns it).

```toml
[run]                      # RunConfig's fields (actors/files/config.py); all optional
epochs = 60
seed = 0
placement = "process"      # or "single"

[robot]                    # inline (protocol/topology.py), or: robot = "robots/chain4.toml" (that file's [robot])
name = "chain4"
[[robot.agent]]
id = "a1"

[scene]                    # optional (protocol/scene.py): free | walls | object
kind = "free"

[task]                     # required: kind = a module of actors/tasks/ and that task's settings
kind = "reach"
goal = [4.16, 6.18]

[learner]                  # optional: kind (actors/policies/registry.py; default "fuzzy") and LearnerSettings
gamma = 0.9                # overrides (actors/learning/settings.py): the observation's fields, the learner's own
```

A recipe that is another with a few changes names it: `base = "corridor7-inner200.toml"` (top level) reads that file
first and lays this one's tables over it, field by field (a list replaces a list). `--set section.field=VALUE`
overrides one field before anything is checked (VALUE is a TOML value: 0.97, true, [1, 2], "text"; a bare word is a
string). Paths in a file are relative to the file; paths given on the command line to the working directory. Every
problem is one line naming where the bad value was written (the file, or the flag: `--set task.goal=abc`, `--epochs
0`), the field and what was expected, in TOML's words (a list, a table, a string).
`write_resolved` writes the resolved run as a run file (`<out>/run.toml`), from which the run can be made again.
"""

from __future__ import annotations

import dataclasses
import re
import secrets
import time
import tomllib
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import msgspec
from kinswarm.actors.files.config import (
    AUTO_LISTEN,
    CONTROLLERS,
    RUN_KEYS,
    ConfigError,
    RunConfig,
    check_endpoint,
    placement_problem,
)
from kinswarm.actors.files.tables import PATH_KEYS, absolute, absolute_paths, copied, merged, plain, put, spec_error
from kinswarm.actors.learning.settings import SPATIAL_STATES, LearnerSettings
from kinswarm.actors.learning.state import OWN_EXTRAS
from kinswarm.actors.policies.registry import DEFAULT, OWN_FIELDS, LearnerKind, learner_kind
from kinswarm.actors.tasks import kinds, task_class
from kinswarm.actors.tasks.base import TaskDef
from kinswarm.protocol.keys import check_id
from kinswarm.protocol.robots import parse_robot
from kinswarm.protocol.scene import SceneSpec, agent_readings, parse_scene
from kinswarm.protocol.spec import SpecError, read_toml, shown, table
from kinswarm.protocol.topology import ROBOT_KEYS, Topology
from kinswarm.protocol.urdf_robot import URDF_KEYS
from kinswarm.sim.urdf import too_many_links

SECTIONS = ("run", "robot", "scene", "task", "learner")
MAX_BASES = 8  # how deep `base` files may nest
_OLD_LAYOUT = {
    "agent": "[[agent]] tables go under [robot] as [[robot.agent]]",
    "defaults": "[defaults] goes under [robot] as [robot.defaults]",
    "obstacle": '[[obstacle]] tables go under [scene] as [[scene.obstacle]] (with [scene] kind = "walls")',
    "object": '[object] goes under [scene] as [scene.object] (with [scene] kind = "object")',
}


_MISSING = {
    "robot": 'missing: give a [robot] table or robot = "a robot file"',
    "task": f"missing: give a [task] table with kind = one of {', '.join(kinds())}",
}


def parse_set(text: str) -> tuple[tuple[str, ...], Any]:
    """`section.field=VALUE` -> (path, value); VALUE is read as TOML, a bare word as a string. What opens a TOML list,
    table or string (`[`, `{`, a quote) must be one: `task.goal=[1,` is an unclosed list, not the string "[1,"."""
    name, sep, raw = text.partition("=")
    path = tuple(name.strip().split("."))
    if not sep or len(path) < 2 or not all(re.fullmatch(r"[A-Za-z0-9_-]+", p) for p in path):
        raise ConfigError(f"--set {text!r}: expected SECTION.FIELD=VALUE, e.g. learner.gamma=0.97")
    if path[0] not in SECTIONS:
        raise ConfigError(f"--set {text!r}: no section {path[0]!r} (expected one of {', '.join(SECTIONS)})")
    raw = raw.strip()
    try:
        value = tomllib.loads(f"v = {raw}")["v"]
    except tomllib.TOMLDecodeError as e:
        if raw[:1] in ("[", "{", '"', "'"):
            why = re.sub(r" \(at .*\)$", "", str(e)).lower()  # its position is in "v = VALUE", not in the flag
            raise ConfigError(
                f'--set {text!r}: the value is not TOML ({why}): a list is [1, 2], a table {{a = 1}}, a string "text"'
            ) from None
        value = raw
    return path, value


Override = str | tuple[str, str]  # `SECTION.FIELD=VALUE` as --set takes it, or (that, where it was written)


def load_run(
    path: str | Path,
    sets: Iterable[Override] = (),
    *,
    run_id: str | None = None,
    out: str | Path | None = None,
    listen: str | None = None,
) -> RunConfig:
    """Resolve the run file at `path` with `--set` overrides into the run's config. A problem with an overridden
    value is the override's, and names it: `--set task.goal=abc: task.goal: expected a list, got a string 'abc'`;
    an override written elsewhere (a plan's [run] set) comes as (text, where) and is named as that place."""
    given = [(s, f"--set {s}") if isinstance(s, str) else s for s in sets]
    overrides = [parse_set(text) for text, _ in given]
    source = str(path)
    try:
        return resolve(read_run_file(path), source, overrides, run_id=run_id, out=out, listen=listen)
    except SpecError as e:
        if e.source != source:  # the robot file's own fields, say
            raise
        for (_, origin), (keys, _) in reversed(list(zip(given, overrides, strict=True))):  # the last one won
            if _overrode(keys, e):
                raise SpecError(origin, e.where, e.what) from None
        raise


def _overrode(keys: tuple[str, ...], e: SpecError) -> bool:
    """Whether the override of `keys` is what `e` is about: the field itself or a part of its value, or the table it
    lies in when the message names the field (a check of several fields: "gamma must be in [0, 1]")."""
    key = ".".join(keys)
    if e.where == key or e.where.startswith((f"{key}.", f"{key}[")):
        return True
    return key.startswith(f"{e.where}.") and re.search(rf"\b{re.escape(keys[-1])}\b", e.what) is not None


def read_run_file(path: str | Path, _seen: tuple[Path, ...] = ()) -> dict[str, Any]:
    """A run file's tables, with the paths it names made absolute and its `base` file (if any) laid under it."""
    path = Path(path).resolve()
    if path in _seen or len(_seen) >= MAX_BASES:
        raise SpecError(str(_seen[-1]), "base", f"{path} is its own base, or bases nest deeper than {MAX_BASES}")
    data = read_toml(path)
    base_file = data.pop("base", None)
    absolute_paths(data, path.parent)
    if base_file is None:
        return data
    if not isinstance(base_file, str):
        raise SpecError(str(path), "base", f"expected the path of a run file, got {base_file!r}")
    return merged(read_run_file(path.parent / base_file, (*_seen, path)), data)


def resolve(
    data: Mapping[str, Any],
    source: str = "<memory>",
    overrides: Iterable[tuple[tuple[str, ...], Any]] = (),
    *,
    run_id: str | None = None,
    out: str | Path | None = None,
    listen: str | None = None,
) -> RunConfig:
    """A run file's content (paths absolute: read_run_file) and overrides -> the RunConfig."""
    data = copied(data)
    for key in data:
        if key not in SECTIONS:
            hint = _OLD_LAYOUT.get(key, f"expected the tables {', '.join(SECTIONS)}, and base")
            raise SpecError(source, key, f"unknown table ({hint})")
    for keys, value in overrides:  # given on the command line: paths are the working directory's
        put(data, keys, absolute(value, Path.cwd()) if keys in PATH_KEYS else value)

    for name in ("robot", "task"):  # the tables a run cannot go without, before what is wrong inside one of them
        if name not in data:
            raise SpecError(source, name, _MISSING[name])
    robot, topo = _robot(data.get("robot"), source)
    scene = parse_scene(data.get("scene"), topo, source)
    task = _task(data.get("task"), topo, scene, source)
    learner_keys = {"kind", *OWN_FIELDS, *(f.name for f in dataclasses.fields(LearnerSettings))}
    learner = table(source, "learner", data.get("learner", {}), learner_keys)
    settings = learner_settings(task, learner, source)  # every agent's, checked now
    try:  # and what a kind opens (a policy's files), tried now: not in an agent's process after the spawn
        kind_of(learner, source).check(settings, topo.dof_agents, learner)
    except ValueError as e:
        raise SpecError(source, "learner.policy", str(e)) from None
    run = table(source, "run", data.get("run", {}), set(RUN_KEYS))
    fields = {("from_dir" if k == "from" else k): v for k, v in run.items()}
    controller = run.get("controller", "agents")  # a model-based law's run is a baseline's: named so in runs/
    kind = f"baseline-{controller}-" if controller != "agents" and controller in CONTROLLERS else ""
    run_id = run_id or f"{kind}{topo.name}-{time.strftime('%Y%m%d-%H%M%S')}-{secrets.token_hex(2)}"
    try:
        check_id("run id", run_id)
    except ValueError as e:
        raise ConfigError(f"--run-id: {e}") from None
    out_dir = Path(out) if out is not None else Path("runs") / run_id
    # `--listen auto` (the default): a free port on 127.0.0.1, picked when the run starts (plan.local_plan)
    extra = {}
    if listen is not None:
        extra["listen"] = listen if listen == AUTO_LISTEN else check_endpoint(listen, "--listen")
    try:
        cfg = msgspec.convert(
            {
                **fields,
                **extra,
                "run_id": run_id,
                "out": str(out_dir.resolve()),
                "robot": robot,
                "scene": {"kind": scene.kind, **{k: v for k, v in (data.get("scene") or {}).items() if k != "kind"}},
                "task": task_table(task),
                "learner": learner,
                "source": source,
            },
            RunConfig,
        )
    except msgspec.ValidationError as e:
        raise spec_error(e, source, "run", fields) from None
    if cfg.scenario is not None:  # a bad scenario is refused before anything starts, one that cannot fire too
        from kinswarm.protocol.scenario import ScenarioError, load_scenario

        for i, e in enumerate(load_scenario(cfg.scenario, topo).entries):
            if e.step >= cfg.steps:
                what = f"step {e.step} is beyond the run's {cfg.steps} steps per epoch (run.steps): it would never fire"
                raise ScenarioError(cfg.scenario, f"event[{i}].step", what)
            if e.epoch is not None and e.epoch >= cfg.epochs:
                what = f"epoch {e.epoch} is beyond the run's {cfg.epochs} epochs (run.epochs): it would never fire"
                raise ScenarioError(cfg.scenario, f"event[{i}].epoch", what)
            if e.fault.robot is not None and e.fault.robot >= cfg.fleet:
                what = f"robot {e.fault.robot}: the run's fleet has {cfg.fleet} (run.fleet; robots 0..{cfg.fleet - 1})"
                raise ScenarioError(cfg.scenario, f"event[{i}].robot", what)
            if cfg.controller != "agents" and not e.is_joint:  # the supervisor would refuse it at its step
                what = f"{e.fault.fault}: a baseline run ({cfg.controller}) has no agents; only joint faults apply"
                raise ScenarioError(cfg.scenario, f"event[{i}].fault", what)
            if problem := placement_problem(e.fault.fault, cfg.placement):
                raise ScenarioError(cfg.scenario, f"event[{i}].fault", problem)
    if cfg.placement == "inprocess":
        check_inprocess(cfg)
    if cfg.controller == "turn" and not (task.topo.spatial and len(task.topo.end_effectors) == 1):
        raise ConfigError("controller: the turn rule moves the one end effector of a robot from URDF")
    if cfg.fleet > 1 and cfg.fleet_goals == "spread" and task.goal(0, cfg.steps)[1]:
        raise ConfigError('fleet_goals: "spread" gives each robot a goal of its own; this task\'s goal moves (a path)')
    if cfg.from_dir is not None:  # and checkpoints that do not fit this run's learners
        check_checkpoints(Path(cfg.from_dir), task, learner, source)
    return cfg


def check_inprocess(cfg: RunConfig) -> None:
    """What the `inprocess` placement (a plain loop: one robot, no processes, no messages) cannot run, refused in one
    line (its scenario's process and link faults are refused with every placement's, above)."""
    if cfg.fleet > 1:
        raise ConfigError("placement: inprocess runs one robot; a fleet (run.fleet) runs in the process or single one")
    if cfg.controller != "agents":
        raise ConfigError(
            f"placement: inprocess runs the learning agents; the {cfg.controller} law runs in the process placement"
        )


def check_checkpoints(run_dir: Path, task: TaskDef, learner: Mapping[str, Any], source: str = "<memory>") -> None:
    """Every DOF agent's checkpoint in `run_dir` loads into the learner this run gives it (the same state variables
    and neighbours), or the one line that says whose does not and why."""
    from kinswarm.actors.files.checkpoint import CheckpointError, load_checkpoint

    topo = task.topo
    if not run_dir.is_dir():
        raise CheckpointError(f"run.from {shown(str(run_dir))}: no such run directory")
    try:  # the run's own record says at once what it was a run of
        from kinswarm.actors.files.config import load_run_config

        theirs = load_run_config(run_dir / "config.json").topo()
    except (ConfigError, SpecError):
        theirs = None
    if theirs is not None and set(theirs.dof_agents) != set(topo.dof_agents):
        raise CheckpointError(
            f"run.from {run_dir}: a run of robot {theirs.name!r} (joints {', '.join(theirs.dof_agents)}), not of this "
            f"run's {topo.name!r} (joints {', '.join(topo.dof_agents)})"
        )
    settings = learner_settings(task, learner, source)
    kind = kind_of(learner, source)
    for i, agent in enumerate(topo.dof_agents):
        arrays, _ = load_checkpoint(run_dir / "agents" / f"{agent}.npz", agent=agent, learner=kind.name)
        visible = sum(topo.agents[c].has_dof for c in topo.agents[agent].children)
        try:
            kind.build(settings[agent], visible, 0, agent=agent, index=i, options=learner).load_state_dict(arrays)
        except ValueError as e:
            raise CheckpointError(
                f"run.from {run_dir}: {agent}'s checkpoint does not fit this run's learner ({e}); "
                "was it trained on another robot, task or [learner]?"
            ) from None


def task_of(cfg: RunConfig) -> TaskDef:
    """The run's task, from its resolved table."""
    table_ = dict(cfg.task)
    kind = table_.pop("kind")
    settings = msgspec.convert(table_, task_class(kind).Settings)
    return task_class(kind)(settings, cfg.topo(), cfg.scene_spec)


def kind_of(learner: Mapping[str, Any], source: str = "<memory>") -> LearnerKind:
    """The learner kind a [learner] table names (`kind`; the paper's fuzzy learner when it names none)."""
    try:
        return learner_kind(learner.get("kind", DEFAULT))
    except ValueError as e:
        raise SpecError(source, "learner.kind", str(e)) from None


def learner_settings(task: TaskDef, learner: Mapping[str, Any], source: str = "<memory>") -> dict[str, LearnerSettings]:
    """Every DOF agent's learner settings: the [learner] overrides on the task's scale and state variables (its
    `kind` checked: known, and given only settings it takes)."""
    kind = kind_of(learner, source)
    learner = {k: v for k, v in learner.items() if k != "kind"}
    if (refused := kind.refused(learner)) is not None:
        field, _, why = refused.partition(": ")
        raise SpecError(source, f"learner.{field}", why)
    learner = {k: v for k, v in learner.items() if k not in kind.takes}  # a kind's own: build's options
    fits = SPATIAL_STATES if task.topo.spatial else ("planar",)
    state = learner.get("state")
    if isinstance(state, str) and state not in fits:  # before the settings' own checks, which assume a kind's sets
        what = "a robot from URDF" if task.topo.spatial else "a planar robot"
        raise SpecError(source, "learner.state", f"{state!r} is not a state of {what}; it takes: {', '.join(fits)}")
    try:
        typed = msgspec.convert(dict(learner), LearnerSettings)
    except msgspec.ValidationError as e:
        raise spec_error(e, source, "learner", learner) from None
    given = {k: getattr(typed, k) for k in learner}
    out = {}
    for agent in task.topo.dof_agents:
        try:
            out[agent] = task.learner(agent, given)
        except ValueError as e:
            raise SpecError(source, "learner", str(e)) from None
        _check_extras(task, agent, out[agent], source)
    return out


def _check_extras(task: TaskDef, agent: str, settings: LearnerSettings, source: str) -> None:
    """The learner's own extra variables (after the task's) are each one the agent can read: from its own geometry
    or a reading its scene sends it. An unknown name would otherwise be a variable stuck at 0."""
    own = () if task.topo.spatial else OWN_EXTRAS
    readable = (*own, *agent_readings(task.scene, task.topo, agent))
    for v in settings.extra_state[len(task.state_variables(agent)) :]:
        if v.name not in readable:
            takes = ", ".join(readable) if readable else "none (its geometry and its scene give no extra variables)"
            raise SpecError(source, "learner.extra_state", f"{agent} cannot read {v.name!r}; here it takes: {takes}")


def task_table(task: TaskDef) -> dict[str, Any]:
    """The resolved [task] table: the kind, then every setting (defaults included); None (unset) left out."""
    values = {f.name: getattr(task.settings, f.name) for f in dataclasses.fields(task.settings)}
    return {"kind": task.kind, **{k: plain(v) for k, v in values.items() if v is not None}}


# -- the parts ----------------------------------------------------------------------------------------------------
def _robot(data: Any, source: str) -> tuple[dict[str, Any], Topology]:
    if data is None:
        raise SpecError(source, "robot", _MISSING["robot"])
    if isinstance(data, str):  # a robot file (absolute by now): its [robot] table
        file = Path(data)
        if not data.strip() or not file.is_file():
            what = "no such file" if data.strip() and not file.exists() else "not a file"
            expected = 'expected a [robot] table or robot = "a robot file"'
            raise SpecError(source, "robot", f"{expected}, got {data!r} ({what})")
        doc = read_toml(file)
        if "robot" not in doc or not isinstance(doc["robot"], dict):
            raise SpecError(str(file), "robot", "a robot file needs a [robot] table")
        data, source = {"name": file.stem, **doc["robot"]}, str(file)
    table(source, "robot", data, URDF_KEYS if isinstance(data, dict) and "urdf" in data else ROBOT_KEYS)
    if "name" not in data and source.endswith(".toml"):
        data = {"name": Path(source).stem, **data}
    topo = parse_robot(data, source)
    if problem := too_many_links(topo):  # refused here, before a process starts, not by the sim's first step
        raise SpecError(source, "robot", problem)
    return data, topo


def _task(data: Any, topo: Topology, scene: SceneSpec, source: str) -> TaskDef:
    if data is None:
        raise SpecError(source, "task", _MISSING["task"])
    if not isinstance(data, dict):
        raise SpecError(source, "task", f"must be a table, got {data!r:.60}")
    kind = data.get("kind")
    if kind not in kinds():
        raise SpecError(source, "task.kind", f"expected one of {', '.join(kinds())}, got {kind!r}")
    cls = task_class(kind)
    if scene.kind not in cls.scenes:
        raise SpecError(
            source, "scene.kind", f"the {kind} task runs in a {' or '.join(cls.scenes)} scene, not {scene.kind!r}"
        )
    fields = {f.name for f in dataclasses.fields(cls.Settings)}
    settings_table = table(source, "task", {k: v for k, v in data.items() if k != "kind"}, fields)
    try:
        settings = msgspec.convert(settings_table, cls.Settings)
    except msgspec.ValidationError as e:
        raise spec_error(e, source, "task", settings_table) from None
    if topo.spatial != cls.spatial:
        kinds_for = ", ".join(k for k in kinds() if task_class(k).spatial == topo.spatial)
        what = "a robot from URDF" if topo.spatial else "a planar robot"
        raise SpecError(source, "task.kind", f"the {kind} task does not move {what}; it takes: {kinds_for}")
    task = cls(settings, topo, scene)
    if (problem := task.check()) is not None:
        field, sep, what = problem.partition(": ")
        if sep and re.fullmatch(r"[a-z_]+", field):
            raise SpecError(source, f"task.{field}", what)
        raise SpecError(source, "task", problem)
    return task
