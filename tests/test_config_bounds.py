"""The resolved run's checks (actors/files/config.py RunConfig): each field's bounds are declared beside it
(actors/files/bounds.py) and checked by one loop. Every bad value is refused with its one line, as it was when the
checks were written out by hand in __post_init__ (the lines below were read from that version, unchanged)."""

from __future__ import annotations

import dataclasses
import inspect
import math

import pytest
from kinswarm.actors.files.bounds import CHECKS, checks, first_problem, integer
from kinswarm.actors.files.config import MAX_FLEET, ConfigError, RunConfig

BASE = {"run_id": "r", "out": "/x", "robot": {}, "task": {"kind": "reach"}}
ENDPOINT = "expected an endpoint like tcp/127.0.0.1:7447 (protocol/host:port), got"
REFUSED = [
    ("epochs", 0, "epochs: expected an integer >= 1, got 0"),
    ("epochs", True, "epochs: expected an integer >= 1, got True"),
    ("epochs", 1.5, "epochs: expected an integer >= 1, got 1.5"),
    ("steps", 0, "steps: expected an integer >= 1, got 0"),
    ("seed", -1, "seed: expected an integer >= 0, got -1"),
    ("seed", 2**63, "seed: expected an integer below 2**63, got 9223372036854775808"),
    ("seed", "3", "seed: expected an integer >= 0, got '3'"),
    ("deadline_ms", 0, "deadline_ms: expected an integer >= 1, got 0"),
    ("checkpoint_every", -1, "checkpoint_every: expected an integer >= 0, got -1"),
    ("max_restarts", -2, "max_restarts: expected an integer >= 0, got -2"),
    ("lease_ms", 99, "lease_ms: expected an integer >= 100, got 99"),
    ("lease_ms", 60_001, "lease_ms: expected at most 60000, got 60001"),
    ("fleet", 0, f"fleet: expected an integer in [1, {MAX_FLEET}], got 0"),
    ("fleet", 1025, "fleet: expected an integer in [1, 1024], got 1025"),
    ("fleet", True, "fleet: expected an integer in [1, 1024], got True"),
    ("fleet_goals", "all", "fleet_goals: 'all' is not one of same, spread"),
    ("learn", 1, "learn: expected true or false, got 1"),
    ("explore", "yes", "explore: expected true or false, got 'yes'"),
    ("successive", None, "successive: expected true or false, got None"),
    ("placement", "cloud", "placement: 'cloud' is not one of process, single, inprocess"),
    ("controller", "pid", "controller: 'pid' is not one of agents, pinv, greedy, rule, turn"),
    ("action_deg", 0, "action_deg: expected a number in (0, 45], got 0"),
    ("action_deg", 46, "action_deg: expected a number in (0, 45], got 46"),
    ("action_deg", True, "action_deg: expected a number in (0, 45], got True"),
    ("action_deg", math.nan, "action_deg: expected a number in (0, 45], got nan"),
    ("action_deg", "1", "action_deg: expected a number in (0, 45], got '1'"),
    ("restart_window_s", 0, "restart_window_s: expected a number > 0, got 0"),
    ("restart_window_s", math.inf, "restart_window_s: expected a number > 0, got inf"),
    ("restart_window_s", False, "restart_window_s: expected a number > 0, got False"),
    ("stall_s", -1, "stall_s: expected a number of seconds >= 0, got -1"),
    ("stall_s", math.nan, "stall_s: expected a number of seconds >= 0, got nan"),
    ("stall_limit_s", "5", "stall_limit_s: expected a number of seconds >= 0, got '5'"),
    ("secret", "short", "secret: expected a string of at least 16 characters"),
    ("secret", 12345678901234567, "secret: expected a string of at least 16 characters"),
    ("listen", "nowhere", f"--listen: {ENDPOINT} 'nowhere'"),
    ("listen", "tcp/127.0.0.1:70000", f"--listen: {ENDPOINT} 'tcp/127.0.0.1:70000'"),
    ("hosts", "h1", "hosts: expected a list of host names, got 'h1'"),
    ("hosts", [1], "hosts: expected a list of host names, got [1]"),
    ("task", {}, "task: expected a table with a kind"),
    ("task", {"kind": 3}, "task: expected a table with a kind"),
    ("task", [], "task: expected a table with a kind"),
]


@pytest.mark.parametrize(("name", "value", "line"), REFUSED, ids=[f"{n}={v!r}" for n, v, _ in REFUSED])
def test_a_bad_value_is_refused_in_its_one_line(name: str, value: object, line: str) -> None:
    with pytest.raises(ConfigError) as e:
        RunConfig(**{**BASE, name: value})
    assert str(e.value) == line


def test_a_run_id_that_is_no_key_chunk_is_refused_as_every_id_is() -> None:
    with pytest.raises(ValueError, match=r"^run id 'a/b' must be 1-64 letters, digits, '_' or '-'$") as e:
        RunConfig(**{**BASE, "run_id": "a/b"})
    assert not isinstance(e.value, ConfigError)


def test_a_bound_on_two_fields() -> None:
    with pytest.raises(ConfigError, match=r"^fleet: only the learning agents drive a fleet; controller 'pinv' drives"):
        RunConfig(**{**BASE, "fleet": 2, "controller": "pinv"})
    assert RunConfig(**{**BASE, "fleet": 2}).fleet == 2 and RunConfig(**{**BASE, "controller": "pinv"}).fleet == 1


def test_every_bound_is_declared_beside_its_field() -> None:
    """Each field that is refused above declares its checks; __post_init__ is the one loop over them."""
    declared = {f.name for f in dataclasses.fields(RunConfig) if f.metadata.get(CHECKS)}
    assert {n for n, _, _ in REFUSED} | {"run_id"} == declared
    body = inspect.getsource(RunConfig.__post_init__)
    assert "first_problem(self)" in body and len(body.splitlines()) <= 4
    assert RunConfig(**BASE).epochs == 60  # the defaults pass their own checks


def test_the_loop_finds_the_first_problem_in_field_order() -> None:
    @dataclasses.dataclass
    class Two:
        a: int = dataclasses.field(default=1, metadata=checks(integer(1)))
        b: int = dataclasses.field(default=1, metadata=checks(integer(1)))

    assert first_problem(Two()) == ""
    assert first_problem(Two(b=0)) == "b: expected an integer >= 1, got 0"
    assert first_problem(Two(a=0, b=0)) == "a: expected an integer >= 1, got 0"
