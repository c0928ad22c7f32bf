"""The step's keys, declared once (protocol/keys.py `STEP`): every key an actor sends on parses back to its kind and
agent, nothing else parses as a step key, and the access control of a deploy plan denies the sim and each agent
exactly the step keys the declaration says are not theirs."""

from __future__ import annotations

from pathlib import Path

import pytest
import zenoh
from kinswarm.protocol.keys import STEP, Keys, StepKey, agent_denied, agent_keys, sim_denied, step_key
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
