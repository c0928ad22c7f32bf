"""Property tests: thousands of generated inputs against every door bad input comes through — the codec, the run-file,
robot, scene, scenario and plan loaders, and the CLI's argument checks. Each must answer with its own one-line error
(or accept), never an uncaught exception. The swarm itself is not started here: run_swarm and the experiments are
replaced by stubs that only record that the command got that far."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import msgpack
import pytest
import tomli_w
from conftest import EXAMPLES
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from kinswarm.actors import cli
from kinswarm.actors.config import ConfigError
from kinswarm.actors.plan import PlanError, load_plan
from kinswarm.actors.runfile import read_run_file, resolve
from kinswarm.actors.scenario import ScenarioError, load_scenario
from kinswarm.protocol import codec
from kinswarm.protocol.messages import MESSAGE_TYPES, SCHEMA_VERSION
from kinswarm.protocol.spec import SpecError
from kinswarm.protocol.topology import load_robot

KEY = b"k" * 32
FAST = settings(max_examples=1500, deadline=None, suppress_health_check=[HealthCheck.too_slow])
SOME = settings(max_examples=600, deadline=None, suppress_health_check=[HealthCheck.too_slow])

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


@FAST
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


WORDS = [
    "run", "baseline", "report", "fault", "status", "experiment", "up", "down", "certs", "router",
    str(EXAMPLES / "chain4.toml"), "examples/nope.toml", "--epochs", "--steps", "--seed", "--goal", "--placement",
    "--set", "--out", "--from", "--learn", "--explore", "--scenario", "--listen", "--for", "--rate", "--law",
    "lock", "kill", "freeze", "drop", "a1", "a9", "all", "0", "-1", "5", "1e9", "nan", "-5s", "5s", "single",
    "process", "on", "off", "learner.gamma=2", "task.goal=[1,2]", "run.epochs=0", "garbage", "tcp/127.0.0.1:1",
    "x=y", "--run-id", "bad/id", "--help",
]  # fmt: skip


@pytest.fixture
def no_swarm(monkeypatch, tmp_path):
    """Stand-ins for what would start a swarm or an experiment: the checks before them are what is fuzzed."""
    calls = []
    monkeypatch.setattr(cli, "run_swarm", lambda *a, **k: calls.append(a) or {"final_error": [], "steps_per_second": 0})
    monkeypatch.chdir(tmp_path)
    return calls


@settings(max_examples=1200, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(st.sampled_from(WORDS), min_size=1, max_size=7))
def test_the_cli_answers_every_command_line_with_a_code(no_swarm, capsys, argv):
    if argv[0] in ("experiment", "up", "down", "router", "status", "fault") and len(argv) > 1:
        argv = argv[:1] + ["--help"] if argv[0] in ("up", "router") else argv  # those would wait for peers
    try:
        code = cli.main(argv)
    except SystemExit as e:  # argparse's usage errors and --help
        code = e.code if isinstance(e.code, int) else 2
    out = capsys.readouterr()
    assert isinstance(code, int) and "Traceback" not in out.err, (argv, out.err[-500:])


def test_the_cli_property_can_fail(no_swarm, monkeypatch):
    """An uncaught exception inside a command reaches the property above (it catches only SystemExit)."""

    def broken(*a: object, **k: object) -> None:
        raise KeyError("a bug")

    monkeypatch.setattr(cli, "load_run", broken)
    with pytest.raises(KeyError):
        cli.main(["run", str(EXAMPLES / "chain4.toml")])
