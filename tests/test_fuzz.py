"""Property tests: thousands of generated inputs against every door bad input comes through — the codec, the run-file,
robot, scene, scenario and plan loaders, and the CLI's argument checks. Each must answer with its own one-line error
(or accept), never an uncaught exception. Nothing is started here: every subcommand's work (a swarm, an experiment,
a session with a running swarm, a router, ...) is replaced by a stub that only records that the command got that
far."""

from __future__ import annotations

import argparse
import fcntl
import importlib
import json
import multiprocessing.process
import os
import subprocess
from pathlib import Path
from typing import Any

import msgpack
import pytest
import tomli_w
import zenoh
from conftest import EXAMPLES, ROOT, run_config
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from kinswarm.actors.cli import commands as cli
from kinswarm.actors.deploy.plan import PlanError, load_plan
from kinswarm.actors.files.config import ConfigError
from kinswarm.actors.files.runfile import read_run_file, resolve
from kinswarm.protocol import codec
from kinswarm.protocol.messages import MESSAGE_TYPES, SCHEMA_VERSION
from kinswarm.protocol.robots import load_robot
from kinswarm.protocol.scenario import ScenarioError, load_scenario
from kinswarm.protocol.spec import SpecError

KEY = b"k" * 32
# Example counts that keep this file near a minute of the default suite on a 2-core machine shared with other work (at
# 1500/300/600 it took 165 s at a load of 6, 1500 nested message bodies over 120 s at a load of 13). The draws are fresh
# on every run (tests/conftest.py's profile), so the examples add up over the suite's runs.
FAST = settings(max_examples=500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SOME = settings(max_examples=100, deadline=None, suppress_health_check=[HealthCheck.too_slow])

scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(2**63), max_value=2**64 - 1),
    st.floats(allow_nan=True, allow_infinity=True),
    st.text(max_size=20),
    st.binary(max_size=20),
)
values = st.recursive(
    scalars,
    lambda inner: st.one_of(st.lists(inner, max_size=5), st.dictionaries(st.text(max_size=8), inner, max_size=5)),
    max_leaves=20,
)
# TOML-able values (no None, no bytes, finite or not floats, nested tables and arrays)
toml_scalars = st.one_of(
    st.booleans(), st.integers(min_value=-(2**63), max_value=2**63 - 1), st.floats(), st.text(max_size=12)
)
toml_values = st.recursive(
    toml_scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4), st.dictionaries(st.text(min_size=1, max_size=8), inner, max_size=4)
    ),
    max_leaves=16,
)


def _field_names(cls: type) -> list[str]:
    return [f for f in cls.__dataclass_fields__ if f != "KIND"]


@st.composite
def bodies(draw: Any) -> tuple[type, dict]:
    """A message body near a real one: the envelope right (mostly), fields of the kind's names with any values."""
    cls = draw(st.sampled_from(list(MESSAGE_TYPES.values())))
    body: dict[str, Any] = {
        "v": draw(st.sampled_from([SCHEMA_VERSION, SCHEMA_VERSION, 0])),
        "kind": draw(st.sampled_from([cls.KIND, cls.KIND, "nope"])),
        "run": draw(st.sampled_from(["r", "r", "other"])),
        "src": draw(st.sampled_from(["a1", 5])),
    }
    for name in _field_names(cls):
        if draw(st.integers(0, 9)):
            body[name] = draw(values)
    return cls, body


@SOME
@given(bodies())
def test_the_codec_refuses_garbage_with_a_reason(case):
    cls, body = case
    try:
        payload = codec.sign(msgpack.packb(body, use_bin_type=True), KEY)
    except (OverflowError, ValueError, TypeError):
        return  # not encodable: nothing of it could be on the wire
    try:
        codec.decode(payload, cls, "r", KEY)
    except codec.DecodeError as e:
        assert str(e) and "\n" not in str(e)


@FAST
@given(st.binary(max_size=300), st.sampled_from(list(MESSAGE_TYPES.values())))
def test_the_codec_refuses_random_bytes(data, cls):
    for payload in (data, codec.sign(data, KEY)):
        try:
            codec.decode(payload, cls, "r", KEY)
        except codec.DecodeError:
            pass


DEPLOY = ROOT / "deploy"
BASE = read_run_file(EXAMPLES / "chain4.toml")
SECTIONS = ("run", "robot", "scene", "task", "learner")
LOADER_ERRORS = (SpecError, ConfigError, ScenarioError, ValueError)


@st.composite
def run_files(draw: Any) -> dict:
    """A run file near examples/chain4.toml: some tables replaced, some fields set to anything."""
    doc = {k: (dict(v) if isinstance(v, dict) else v) for k, v in BASE.items()}
    for _ in range(draw(st.integers(1, 4))):
        section = draw(st.sampled_from([*SECTIONS, "agent", "obstacle"]))
        if draw(st.booleans()):
            doc[section] = draw(toml_values)
        else:
            table = doc.setdefault(section, {})
            if isinstance(table, dict):
                key = draw(
                    st.sampled_from(
                        [
                            "kind", "goal", "goals", "reward", "via", "via_width", "epochs", "steps", "seed",
                            "placement", "gamma", "n_sets", "ranges", "extra_state", "agent", "defaults", "shield",
                            "obstacle", "object", "speed", "circle", "from", "scenario", "lr_anneal", "top_k", "zz",
                        ]
                    )
                )  # fmt: skip
                table[key] = draw(toml_values)
    return doc


@SOME
@given(run_files())
def test_run_files_are_accepted_or_refused_in_one_line(doc):
    try:
        cfg = resolve(doc, "fuzz.toml", run_id="fz", out=Path("/nonexistent/fz"))
    except LOADER_ERRORS as e:
        assert "\n" not in str(e), e
        return
    assert cfg.topo() is not None and cfg.scene_spec is not None


@SOME
@given(st.text(max_size=300))
def test_robot_and_plan_files_of_any_text(tmp_path_factory, text):
    p = tmp_path_factory.mktemp("fz") / "f.toml"
    p.write_text(text)
    for load, errors in ((load_robot, (SpecError,)), (load_plan, (PlanError,))):
        try:
            load(p)
        except errors as e:
            assert "\n" not in str(e).strip(), e


@SOME
@given(st.dictionaries(st.sampled_from(["name", "description", "event", "zz"]), toml_values, max_size=4))
def test_scenario_files(tmp_path_factory, doc):
    p = tmp_path_factory.mktemp("fz") / "s.toml"
    try:
        p.write_text(tomli_w.dumps(doc))
    except (TypeError, ValueError):
        return
    topo = load_robot(EXAMPLES / "chain4.toml")
    try:
        load_scenario(p, topo)
    except ScenarioError:
        pass


# Where each subcommand starts its work, after every check of its input: replaced by Reached, so a fuzzed command
# line exercises the checks and nothing else (a drawn `experiment all` once ran every experiment at full size, in
# process, for hours). Each is replaced in its module and in the CLI's, whichever the CLI calls it through.
WORK = {
    "run": [("kinswarm.actors.run.launch", "run_swarm")],
    "baseline": [("kinswarm.actors.run.launch", "run_swarm")],
    "up": [("kinswarm.actors.run.launch", "run_swarm"), ("kinswarm.actors.deploy.hosts", "fetch_setup")],
    "report": [("kinswarm.actors.report", "write_plots")],
    "animate": [("kinswarm.actors.report.animate", "write_animation")],
    "view": [("kinswarm.actors.report.recording", "open_stream"), ("kinswarm.actors.report.recording", "record_run")],
    "fault": [("kinswarm.actors.cli.control", "Client")],
    "status": [("kinswarm.actors.cli.control", "show_status")],
    "experiment": [("kinswarm.experiments", "run_experiment")],
    "down": [("kinswarm.actors.deploy.hosts", "down")],
    "router": [("kinswarm.actors.deploy.hosts", "run_router")],
    "certs": [("kinswarm.actors.deploy.hosts", "write_certs")],
}
REAL_RUN_SWARM = cli.run_swarm
RUN_DIR = "runs/demo"  # a run directory the fixture makes (a live run, one epoch in): report, fault ... reach it


class Reached(BaseException):  # noqa: N818  # no Exception: no `except` of the CLI can swallow it
    """A command got past its checks to where its work starts."""


class Forbidden(BaseException):  # noqa: N818
    """Something a fuzzed command line must never do: spawn a process or open a Zenoh session."""


def subcommands() -> set[str]:
    (action,) = [a for a in cli.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return set(action.choices)


WORDS = [
    *sorted(subcommands()), "cost", "generalisation", "--quick", "--seeds", "--jobs", "--test-set",
    str(EXAMPLES / "chain4.toml"), "examples/nope.toml", str(DEPLOY / "local.toml"), str(DEPLOY / "two-hosts.toml"),
    "--epochs", "--steps", "--seed", "--goal", "--placement", "--set", "--out", "--from", "--learn", "--explore",
    "--scenario", "--listen", "--for", "--rate", "--law", "--host", "--plan", "--run-file", "--wait", "--save", "--web",
    "--watch", "--run-dir", "--connect", "--log", "lock", "kill", "freeze", "drop", "a1", "a9", "all", "0", "-1", "5",
    "1e9", "nan", "-5s", "5s", "single", "process", "on", "off", "learner.gamma=2", "task.goal=[1,2]", "run.epochs=0",
    "garbage", "tcp/127.0.0.1:1", "x=y", "--run-id", "bad/id", "--help", "demo", RUN_DIR, "local", "brain", "x.rrd",
]  # fmt: skip


def _refuse(what: str) -> Any:
    def refuse(*a: object, **k: object) -> None:
        raise Forbidden(f"a fuzzed command line tried to {what}")

    return refuse


@pytest.fixture
def no_work(monkeypatch, tmp_path):
    """Every subcommand's work replaced by Reached, and whatever would spawn a process or open a session made to
    raise Forbidden (a net under the table above: a new way to start work fails the test instead of running)."""
    reached: list[tuple[str, str]] = []
    for module, name in {place for places in WORK.values() for place in places}:

        def stub(*a: object, _at: tuple[str, str] = (module, name), **k: object) -> None:
            reached.append(_at)
            raise Reached(".".join(_at))

        monkeypatch.setattr(importlib.import_module(module), name, stub)
        if hasattr(cli, name):
            monkeypatch.setattr(cli, name, stub)
    monkeypatch.setattr(subprocess.Popen, "__init__", _refuse("start a process"))
    for name in ("fork", "forkpty", "posix_spawn", "posix_spawnp", "system"):
        monkeypatch.setattr(os, name, _refuse(f"start a process (os.{name})"))
    monkeypatch.setattr(multiprocessing.process.BaseProcess, "start", _refuse("start a worker process"))
    monkeypatch.setattr(zenoh, "open", _refuse("open a Zenoh session"))
    monkeypatch.chdir(tmp_path)
    cfg = run_config(EXAMPLES / "chain4.toml", run_id="demo", out=tmp_path / RUN_DIR)
    run = tmp_path / RUN_DIR
    run.mkdir(parents=True)
    cfg.write(run / "config.json")
    row = {"epoch": 0, "final_error": 1.0, "mean_error": 2.0, "steps": 2, "seconds": 0.1, "missed_cmds": 0}
    row |= {"max_step_seconds": 0.05, "final_angles_deg": dict.fromkeys(cfg.topo().dof_agents, 0.0), "errors": [3, 1]}
    (run / "metrics.jsonl").write_text(json.dumps(row) + "\n")
    (run / "poses.jsonl").write_text(json.dumps({"epoch": 0, "angles_deg": [[0.0] * 4, [1.0] * 4]}) + "\n")
    # held as a live run holds it: report, fault ... see a run in progress
    with open(run / ".lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        yield reached


def _main(argv: list[str]) -> int:
    try:
        return cli.main(argv)
    except SystemExit as e:  # argparse's usage errors and --help
        return e.code if isinstance(e.code, int) else 2
    except Reached:
        return 0


@settings(max_examples=200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.sampled_from(WORDS), min_size=1, max_size=7))
def test_the_cli_answers_every_command_line_with_a_code(no_work, capsys, argv):
    code = _main(argv)
    out = capsys.readouterr()
    assert isinstance(code, int) and "Traceback" not in out.err, (argv, out.err[-500:])


def test_every_subcommand_has_its_work_replaced():
    """A new subcommand must name where its work starts (WORK), or the property above could run it for real."""
    assert subcommands() == set(WORK)


REACH = {  # a command line of each subcommand that passes its checks
    "run": ["run", str(EXAMPLES / "chain4.toml")],
    "baseline": ["baseline", str(EXAMPLES / "chain4.toml")],
    "up": ["up", str(DEPLOY / "local.toml"), "--host", "local"],
    "report": ["report", RUN_DIR],
    "animate": ["animate", RUN_DIR],
    "view": ["view", RUN_DIR, "--save", "x.rrd"],
    "fault": ["fault", "demo", "kill", "a1", "--run-dir", RUN_DIR],
    "status": ["status", "demo", "--run-dir", RUN_DIR],
    "experiment": ["experiment", "all"],
    "down": ["down", str(DEPLOY / "local.toml"), "--host", "local"],
    "router": ["router", "--listen", "tcp/127.0.0.1:0"],
    "certs": ["certs", str(DEPLOY / "two-hosts-tls.toml"), "--out", "certs"],
}


@pytest.mark.parametrize("command", sorted(WORK))
def test_each_replacement_is_where_the_command_goes(no_work, command):
    """The stubs sit on the path each command really takes: a good command line ends at its own."""
    assert _main(REACH[command]) == 0 and len(no_work) == 1 and no_work[0] in WORK[command], no_work


def test_the_cli_property_can_fail(no_work, monkeypatch):
    """An uncaught exception inside a command reaches the property above (it catches only SystemExit)."""

    def broken(*a: object, **k: object) -> None:
        raise KeyError("a bug")

    monkeypatch.setattr(cli, "load_run", broken)
    with pytest.raises(KeyError):
        cli.main(["run", str(EXAMPLES / "chain4.toml")])


@pytest.mark.timeout(60)
@pytest.mark.parametrize("placement", ["single", "process"])
def test_the_net_under_the_table_catches_a_real_run(no_work, monkeypatch, placement):
    """Were a command's work missing from WORK, it would fail the property, not run: a real `kinswarm run`."""
    from kinswarm.actors.run import launch

    monkeypatch.setattr(cli, "run_swarm", REAL_RUN_SWARM)
    monkeypatch.setattr(launch, "run_swarm", REAL_RUN_SWARM)
    with pytest.raises(Forbidden):
        cli.main(["run", str(EXAMPLES / "chain4.toml"), "--placement", placement, "--epochs", "1"])


def test_hypothesis_draws_as_a_users_run_does():
    """CI=true would select Hypothesis's "ci" profile (fixed examples); conftest.py's profile draws afresh."""
    from hypothesis import settings as current

    assert current.default.derandomize is False and current.default.database is None
