import math

import msgpack
import pytest
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys, check_id
from kinswarm.protocol.messages import (
    MESSAGE_TYPES,
    Checkpoint,
    Cmd,
    Down,
    EpochDone,
    EpochStart,
    Obs,
    Saved,
    Stop,
    Task,
    Up,
)

SAMPLES = [
    Obs(epoch=1, step=2, q=0.5),
    Task(epoch=0, step=7, goal=(4.16, 6.18), tips={"a4": (1.0, 2.0, 0.3)}),
    Down(epoch=3, step=4, base=(1.0, 2.0, 0.5), goal=(4.0, 6.0), reward=-1.5),
    Down(epoch=3, step=0, base=(0.0, 0.0, 0.0), goal=(4.0, 6.0), reward=None),
    Up(epoch=1, step=9, tips={"l2": (1.0, 1.0, 0.0), "r2": (-1.0, 1.0, 3.0)}, action=2),
    Cmd(epoch=1, step=9, delta=-0.0174),
    EpochStart(epoch=5, steps=500, goal=(1.0, 2.0)),
    EpochDone(epoch=5, steps=2, final_error=0.1, mean_error=0.2, errors=[0.3, 0.1],
              final_angles={"a1": 0.1}, missed_cmds=0, seconds=0.5),
    Checkpoint(epoch=2, directory="/tmp/x"),
    Saved(epoch=2, path="/tmp/x/a1.npz", error=""),
    Stop(reason="done"),
]


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_round_trip(msg):
    assert codec.decode(codec.encode(msg, "run1", "me"), type(msg), "run1") == msg


def test_every_message_type_has_a_sample():
    assert {type(m) for m in SAMPLES} == set(MESSAGE_TYPES.values())


def _raw(**over):
    body = {"v": 1, "kind": "cmd", "run": "run1", "src": "a1", "epoch": 1, "step": 2, "delta": 0.01}
    body.update(over)
    return msgpack.packb({k: v for k, v in body.items() if v is not ...})


@pytest.mark.parametrize(
    "payload, reason",
    [
        (b"\xc1garbage", "not msgpack"),
        (b"", "not msgpack"),
        (msgpack.packb([1, 2, 3]), "expected a map"),
        (_raw(v=2), "schema version 2"),
        (_raw(kind="obs"), "kind 'obs'"),
        (_raw(kind="nope"), "unknown kind"),
        (_raw(run="other"), "run 'other'"),
        (_raw(src=5), "src"),
        (_raw(delta=...), "missing field 'delta'"),
        (_raw(extra=1), "unexpected field 'extra'"),
        (_raw(delta="0.1"), "delta: expected a number"),
        (_raw(delta=math.nan), "finite"),
        (_raw(delta=math.inf), "finite"),
        (_raw(step=1.5), "step: expected an integer"),
        (_raw(step=True), "step: expected an integer"),
        (b"\xdb" + (2**21).to_bytes(4, "big") + b"x" * (2**21), "exceeds"),
    ],
)
def test_rejections_name_the_reason(payload, reason):
    with pytest.raises(codec.DecodeError, match=reason):
        codec.decode(payload, Cmd, "run1")


def test_nested_field_errors_name_the_path():
    good = codec.encode(SAMPLES[4], "r", "x")
    body = msgpack.unpackb(good)
    body["tips"]["r2"] = [1.0, "x", 0.0]
    with pytest.raises(codec.DecodeError, match=r"tips\.r2\[1\]: expected a number"):
        codec.decode(msgpack.packb(body), Up, "r")
    body["tips"]["r2"] = [1.0, 0.0]
    with pytest.raises(codec.DecodeError, match="tips.r2: expected a list of 3"):
        codec.decode(msgpack.packb(body), Up, "r")


def test_ints_on_the_wire_are_accepted_as_floats():
    # other msgpack clients may send 1 for 1.0
    m = codec.decode(_raw(delta=1), Cmd, "run1")
    assert m.delta == 1.0 and isinstance(m.delta, float)


def test_keys_live_under_the_run_prefix():
    k = Keys("r-1")
    assert k.down("a2") == "ks/r-1/a/a2/down"
    assert k.cmd("a1") == "ks/r-1/sim/cmd/a1"
    assert k.parse_alive("ks/r-1/alive/agent/a3") == ("agent", "a3")
    assert k.parse_alive("ks/other/alive/agent/a3") is None


@pytest.mark.parametrize("bad", ["", "a/b", "a*", "a$b", "x" * 65, "sp ace"])
def test_ids_that_would_change_a_key_are_refused(bad):
    with pytest.raises(ValueError):
        check_id("run id", bad)
