"""Every key, declared once (protocol/keys.py `KEYS`, the step's among them in `STEP`): every key an actor sends on
parses back to its kind and names, nothing else parses as a step key, the access control of a deploy plan denies the
sim and each agent exactly the keys the declaration says are not theirs, and a liveliness token's change reads back
as it was made."""

from __future__ import annotations

from pathlib import Path

import pytest
import zenoh
from kinswarm.protocol.keys import (
    GONE,
    HELD,
    KEYS,
    STEP,
    UP,
    Key,
    Keys,
    StepKey,
    agent_denied,
    agent_keys,
    parse_token_change,
    run_of,
    shape,
    sim_denied,
    step_key,
    token_change,
)
from kinswarm.protocol.robots import load_robot

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(params=["chain4.toml", "tree5.toml"])
def topo(request):
    return load_robot(EXAMPLES / request.param)


def test_every_step_key_parses_back_to_its_kind_and_agent(topo) -> None:
    k = Keys("run-1")
    made = {StepKey("task", ""): k.task}
    for a in topo.order:
        made |= {StepKey("down", a): k.down(a), StepKey("up", a): k.up(a), StepKey("cmd", a): k.cmd(a)}
        made |= {StepKey("obs", a): k.obs(a)}
    assert {step.kind for step in made} == set(STEP)
    for step, key in made.items():
        assert k.parse_step(key) == step, key
        assert key == f"{k.root}/{step_key(step.kind, step.agent)}"


@pytest.mark.parametrize(
    "key",
    [
        "ks/run-1/ctl/stop",
        "ks/run-1/rep/agent/a2",
        "ks/run-1/alive/agent/a2",
        "ks/run-1/metrics/epoch",
        "ks/run-12/a/a2/down",  # another run's root, one character longer
        "ks/run/a/a2/down",
        "ks/run-1/a/a2/b/down",  # a chunk too many
        "ks/run-1/a//down",
        "ks/run-1/sim/obs/",
        "ks/run-1/sim/cmd/*",  # a wildcard is no agent
        "ks/run-1/sim/task/x",
        "ks/run-1/a/a2/sideways",
        "ks/run-1",
        "__alive__",
    ],
)
def test_nothing_else_is_a_step_key(key: str) -> None:
    assert Keys("run-1").parse_step(key) is None


def _hits(denied: tuple[str, ...], key: str) -> bool:
    return any(zenoh.KeyExpr(f"ks/r/{d}").intersects(zenoh.KeyExpr(f"ks/r/{key}")) for d in denied)


def test_the_sim_and_each_agent_are_denied_what_is_not_theirs(topo) -> None:
    sim_sends = [step_key("task"), *(step_key("obs", a) for a in topo.order)]
    agents_send = {a: agent_keys(topo, a) for a in topo.order}
    every_agent_key = {key for step, stand_in in agents_send.values() for key in (*step, *stand_in)}
    assert not any(_hits(sim_denied(), key) for key in sim_sends)
    assert all(_hits(sim_denied(), key) for key in every_agent_key)
    for a, (step, stand_in) in agents_send.items():
        denied = agent_denied(topo, a)
        assert not any(_hits(denied, key) for key in (*step, *stand_in)), a
        assert all(_hits(denied, key) for key in sim_sends), a
        others = every_agent_key - {*step, *stand_in}
        assert others and all(_hits(denied, key) for key in others), a


@pytest.mark.parametrize("kind", sorted(KEYS))
def test_every_kind_s_key_parses_back_to_its_kind_and_names(kind: str) -> None:
    k = Keys("run-1")
    names = tuple(f"n{i}" for i in range(KEYS[kind][0].count("{}")))
    key = k.key(kind, *names)
    assert key == f"{k.root}/{shape(kind, *names)}" and k.parse(key) == Key(kind, names)
    assert key.startswith(k.prefix(kind)) and run_of(key) == "run-1"
    assert Keys("run-2").parse(key) is None  # another run's


def test_the_named_keys_are_the_declared_ones() -> None:
    k = Keys("r")
    assert k.parse(k.rep("bye", "a2")) == Key("rep", ("bye", "a2"))
    assert k.parse(k.host("h1")) == Key("host", ("h1",)) and k.parse(k.ctl("stop")) == Key("ctl", ("stop",))
    assert k.parse_alive(k.alive("agent", "a3")) == ("agent", "a3") and k.parse_alive(k.ctl("stop")) is None
    assert k.parse(k.ctl("*")) is None and k.parse("ks/r/ctl/host/h1/x") is None and k.parse("__alive__") is None
    assert set(STEP) == {"down", "up", "cmd", "obs", "task"} and all(STEP[s] == KEYS[s] for s in STEP)
    assert all(k.step(kind, "a1").startswith(k.step_prefixes) for kind in STEP)
    assert not any(k.key(kind, "x", "y").startswith(k.step_prefixes) for kind in KEYS if kind not in STEP)


@pytest.mark.parametrize("sign", [UP, GONE, HELD])
def test_a_token_change_reads_back(sign: str) -> None:
    key = Keys("r").alive("agent", "a2")
    assert parse_token_change(token_change(sign, key)) == (sign, key)


def test_the_run_s_keys_are_denied_to_the_sim_and_the_agents_as_declared(topo) -> None:
    """Beyond the step: the control keys are the supervisors' (and a tool's), fault requests a tool's or the sim's;
    replies, metrics and tokens anyone's of the run."""
    sim, a = sim_denied(), agent_denied(topo, topo.order[1])
    for key in ("ctl/stop", "ctl/epoch", "ctl/host/h1", "ctl/setup/p"):
        assert _hits(sim, key) and _hits(a, key), key
    assert _hits(a, "fault/request") and not _hits(sim, "fault/request")
    for key in ("rep/agent/a2", "rep/bye/a2", "metrics/event", "metrics/epoch"):
        assert not _hits(sim, key) and not _hits(a, key), key
