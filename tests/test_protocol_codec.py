import dataclasses
import math

import msgpack
import pytest
from kinswarm.protocol import codec
from kinswarm.protocol.keys import Keys, check_id
from kinswarm.protocol.messages import (
    MESSAGE_TYPES,
    SCHEMA_VERSION,
    AgentTrace,
    Batch,
    Bye,
    Checkpoint,
    Cmd,
    Down,
    EpochDone,
    EpochStart,
    Event,
    Fault,
    FaultReply,
    Heartbeat,
    JointStatus,
    Obs,
    Saved,
    Setup,
    Stop,
    SwarmStatus,
    Task,
    Up,
)

KEY = b"0123456789abcdef0123456789abcdef"
OTHER_KEY = b"fedcba9876543210fedcba9876543210"

SAMPLES = [
    Obs(epoch=1, step=2, q=0.5),
    Obs(epoch=1, step=2, q=0.5, sense={"clearance": 0.25, "collided": 1.0, "shield+": 0.0}),
    Task(epoch=0, step=7, goal=(4.16, 6.18), tips={"a4": (1.0, 2.0, 0.3)}),
    Task(epoch=0, step=7, goal=(4.16, 6.18), tips={"a4": (1.0, 2.0, 0.3)}, sense={"fn/f1_4": 2.0, "net_fx": -0.1}),
    Down(epoch=3, step=4, base=(1.0, 2.0, 0.5), goal=(4.0, 6.0), reward=-1.5),
    Down(epoch=3, step=0, base=(0.0, 0.0, 0.0), goal=(4.0, 6.0), reward=None),
    Up(epoch=1, step=9, tips={"l2": (1.0, 1.0, 0.0), "r2": (-1.0, 1.0, 3.0)}, action=2),
    Up(epoch=1, step=9, tips={"a7": (5.5, 2.0, 0.0)}, action=0, sense={"clearance": 0.125}),
    Cmd(epoch=1, step=9, delta=-0.0174),
    EpochStart(epoch=5, steps=500, goal=(1.0, 2.0)),
    EpochStart(epoch=5, steps=3, goal=(1.0, 2.0), path=[(1.0, 2.0), (1.5, 2.0), (2.0, 2.0)]),
    EpochDone(
        epoch=5,
        steps=2,
        final_error=0.1,
        mean_error=0.2,
        errors=[0.3, 0.1],
        final_angles={"a1": 0.1},
        missed_cmds=0,
        seconds=0.5,
        max_step_seconds=0.01,
    ),
    EpochDone(
        epoch=5,
        steps=2,
        final_error=0.1,
        mean_error=0.2,
        errors=[0.3, 0.1],
        final_angles={"a1": 0.1},
        missed_cmds=0,
        seconds=0.5,
        max_step_seconds=0.01,
        angles=[[0.1, 0.2], [0.15, 0.25]],
    ),
    Checkpoint(epoch=2, directory="/tmp/x"),
    Saved(epoch=2, path="/tmp/x/a1.npz", error=""),
    Stop(reason="done"),
    Bye(steps=1200, rejected=3),
    Fault(
        id="f1", fault="drop", targets=["a2", "a3"], seconds=30.0, steps=None, rate=0.05, ms=None, amplitude_deg=None
    ),
    Fault(id="f2", fault="disturb", targets=["all"], seconds=None, steps=300, rate=None, ms=None, amplitude_deg=2.0),
    FaultReply(id="f1", error="", detail="drop a2,a3 rate=0.05 seconds=30"),
    Event(epoch=-1, step=-1, event="restart", target="a3", detail="after kill; from epoch 4"),
    JointStatus(epoch=2, step=40, q={"a1": 0.1, "a2": -0.2}, delta={"a1": 0.0175, "a2": 0.0}, faults={"a2": "lock"}),
    SwarmStatus(
        epoch=2,
        epochs=60,
        role={"sim": "sim", "a1": "agent"},
        alive={"sim": 1, "a1": 0},
        pid={"sim": 100, "a1": 101},
        host={"sim": "h", "a1": "h"},
        restarts={"sim": 0, "a1": 2},
        faults={"sim": [], "a1": ["drop rate=0.05"]},
    ),
    Setup(plan="two-hosts", config="{}", scenario=""),
    Heartbeat(host="brain", seq=7, leader=1),
    Fault(
        id="f3",
        fault="scale",
        targets=["a2"],
        seconds=None,
        steps=None,
        rate=None,
        ms=None,
        amplitude_deg=None,
        factor=3.0,
    ),  # fmt: skip
    AgentTrace(
        epoch=2,
        agent="a1",
        names=["q", "g_perp"],
        steps=[0, 1],
        states=[[0.1, -0.2], [0.1, -0.1]],
        actions=[2, 1],
        expected=[[0.0, 0.5, 1.0], [0.1, 0.2, 0.3]],
        beliefs=[[0.2, 0.3, 0.5], []],
    ),  # fmt: skip
    Batch(of="cmd", robots=[0, 3], items=[Cmd(epoch=1, step=9, delta=-0.0174), Cmd(epoch=1, step=9, delta=0.0)]),
    Batch(
        of="down",
        robots=[1],
        items=[Down(epoch=3, step=4, base=(1.0, 2.0, 0.5), goal=(4.0, 6.0), reward=None, sense={"fine": 1.0})],
    ),
]


@pytest.mark.parametrize("msg", SAMPLES, ids=lambda m: type(m).__name__)
def test_round_trip(msg):
    assert codec.decode(codec.encode(msg, "run1", "me", KEY), type(msg), "run1", KEY) == msg


@pytest.mark.parametrize("msg", [m for m in SAMPLES if type(m) is not Batch], ids=lambda m: type(m).__name__)
def test_encode_makes_the_bytes_of_the_map_of_envelope_and_fields_in_order(msg):
    # the generated body builder and the per-thread Packer are speed only: the bytes are the plain recipe's
    body = {"v": SCHEMA_VERSION, "kind": msg.KIND, "run": "run1", "src": "me"}
    body.update((f.name, getattr(msg, f.name)) for f in dataclasses.fields(msg))
    assert codec.encode(msg, "run1", "me", KEY) == codec.sign(msgpack.packb(body, use_bin_type=True), KEY)


def test_every_message_type_has_a_sample():
    assert {type(m) for m in SAMPLES} == set(MESSAGE_TYPES.values())


def _raw(key=KEY, **over):
    """A hand-made cmd body, signed with `key` (the run's by default): it passes the MAC, then the checks."""
    body = {"v": SCHEMA_VERSION, "kind": "cmd", "run": "run1", "src": "a1", "epoch": 1, "step": 2, "delta": 0.01}
    body.update(over)
    return codec.sign(msgpack.packb({k: v for k, v in body.items() if v is not ...}), key)


GOOD = codec.encode(Cmd(epoch=1, step=2, delta=0.01), "run1", "a1", KEY)


def _flip(payload: bytes, i: int) -> bytes:
    return payload[:i] + bytes([payload[i] ^ 0x01]) + payload[i + 1 :]


@pytest.mark.parametrize(
    "payload, reason",
    [
        (b"", "too short"),
        (b"\xc1garbage", "too short"),
        (b"\xc1garbage that is long enough to carry a MAC", "bad MAC"),
        (GOOD[:-1], "bad MAC"),  # truncated
        (GOOD[: -codec.MAC_SIZE], "bad MAC"),  # the MAC cut off: the body alone
        (
            msgpack.packb(
                {"v": SCHEMA_VERSION, "kind": "cmd", "run": "run1", "src": "a1", "epoch": 1, "step": 2, "delta": 0.01}
            )
            + b"\0" * codec.MAC_SIZE,
            "bad MAC",
        ),  # forged: a well-formed body
        (_flip(GOOD, 5), "bad MAC"),  # one bit of the body flipped in transit
        (_flip(GOOD, len(GOOD) - 1), "bad MAC"),  # one bit of the MAC flipped
        (_raw(OTHER_KEY), "bad MAC"),  # another run's key, or an impostor's
        (_raw(OTHER_KEY, step=3), "not signed with this run's key"),  # a plausible wrong step from an impostor
        (codec.sign(b"\xc1", KEY), "not msgpack"),
        (codec.sign(msgpack.packb([1, 2, 3]), KEY), "expected a map"),
        (_raw(v=1), "schema version 1"),  # signed with the right key: an old actor of this run
        (_raw(v=SCHEMA_VERSION + 1), f"schema version {SCHEMA_VERSION + 1}"),
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
        codec.decode(payload, Cmd, "run1", KEY)


def test_the_mac_is_checked_before_anything_else():
    # a body with every fault at once, unsigned: the MAC is the reason given, msgpack never sees it
    junk = msgpack.packb({"v": 99, "kind": "nope", "run": "other"}) + b"\0" * codec.MAC_SIZE
    with pytest.raises(codec.DecodeError, match="^bad MAC: not signed with this run's key"):
        codec.decode(junk, Cmd, "run1", KEY)


def test_the_mac_binds_the_key_not_just_the_run():
    # two runs with the same id but different secrets do not hear each other
    p = codec.encode(Cmd(epoch=0, step=1, delta=0.0), "run1", "a1", OTHER_KEY)
    with pytest.raises(codec.DecodeError, match="bad MAC"):
        codec.decode(p, Cmd, "run1", KEY)
    assert codec.decode(p, Cmd, "run1", OTHER_KEY) == Cmd(epoch=0, step=1, delta=0.0)


@pytest.mark.parametrize("key", [b"", None, "text"])
def test_a_missing_key_is_a_programming_error(key):
    with pytest.raises(ValueError, match="MAC key") as e:
        codec.encode(Cmd(epoch=0, step=1, delta=0.0), "run1", "a1", key)
    assert not isinstance(e.value, codec.DecodeError)
    with pytest.raises(ValueError, match="MAC key") as e:
        codec.decode(GOOD, Cmd, "run1", key)
    assert not isinstance(e.value, codec.DecodeError)  # not a bad message: a bug in the caller


def test_sender_reads_the_claimed_src_past_the_mac():
    assert codec.sender(GOOD) == "a1"
    assert codec.sender(_raw(OTHER_KEY, src="impostor")) == "impostor"  # unverified: for log lines only
    assert codec.sender(b"") == "?" and codec.sender(b"\xc1garbage") == "?"


def test_nested_field_errors_name_the_path():
    good = codec.encode(SAMPLES[6], "r", "x", KEY)
    body = msgpack.unpackb(good[: -codec.MAC_SIZE])
    body["tips"]["r2"] = [1.0, "x", 0.0]
    with pytest.raises(codec.DecodeError, match=r"tips\.r2\[1\]: expected a number"):
        codec.decode(codec.sign(msgpack.packb(body), KEY), Up, "r", KEY)
    body["tips"]["r2"] = [1.0, 0.0, 0.0, 0.0]  # a tip is 2, 3 or 7 floats (messages.COORD_SIZES)
    with pytest.raises(codec.DecodeError, match="tips.r2: expected a list of 2 or 3 or 7"):
        codec.decode(codec.sign(msgpack.packb(body), KEY), Up, "r", KEY)


@pytest.mark.parametrize("name", ["", "a b", "x" * 65, "é", "a*b", "$x"])
def test_reading_names_are_checked_on_both_paths(name, monkeypatch):
    """Scene readings travel by one route, validated: a map key that is not a name is refused, fast path or not."""
    body = msgpack.unpackb(codec.encode(SAMPLES[1], "run1", "sim", KEY)[: -codec.MAC_SIZE])
    body["sense"][name] = 1.0
    payload = codec.sign(msgpack.packb(body), KEY)
    with pytest.raises(codec.DecodeError, match="expected names"):
        codec.decode(payload, Obs, "run1", KEY)
    monkeypatch.setattr(codec, "_fast", lambda cls, envelope=True: None)
    with pytest.raises(codec.DecodeError, match="expected names"):
        codec.decode(payload, Obs, "run1", KEY)


def test_ints_on_the_wire_are_accepted_as_floats():
    # other msgpack clients may send 1 for 1.0
    m = codec.decode(_raw(delta=1), Cmd, "run1", KEY)
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


def _outcome(payload, kind):
    try:
        m = codec.decode(payload, kind, "run1", KEY)
        return ("ok", m, {k: type(v) for k, v in vars(m).items()})
    except codec.DecodeError as e:
        return ("rejected", str(e))


def _variants():
    """Bodies near the step messages' fast path: good ones, and ones each of its checks must send on."""
    step = [m for m in SAMPLES if isinstance(m, (Obs, Task, Down, Up, Cmd, EpochStart, Stop))]
    for msg in step:
        body = msgpack.unpackb(codec.encode(msg, "run1", "me", KEY)[: -codec.MAC_SIZE])
        yield type(msg), body
        for name, value in body.items():
            for other in (1, True, 2.5, math.inf, -math.nan, None, "x", [1.0, 2.0, 3.0], {"a4": [1.0, 2.0, 3.0]}):
                yield type(msg), {**body, name: other}
            if isinstance(value, list):
                yield type(msg), {**body, name: [*value[:-1], 1]}  # an int among floats
                yield type(msg), {**body, name: [*value, 0.0]}
                yield type(msg), {**body, name: [*value[:-1], math.inf]}
            if isinstance(value, dict):
                for k, v in value.items():
                    if isinstance(v, list):  # tips
                        yield type(msg), {**body, name: {**value, k: [*v[:-1], 7]}}
                        yield type(msg), {**body, name: {**value, k: v[:-1]}}
                        yield type(msg), {**body, name: {**value, k: [*v[:-1], math.nan]}}
                    else:  # readings
                        for bad in (7, math.nan, "x", None, [1.0]):
                            yield type(msg), {**body, name: {**value, k: bad}}
                        yield type(msg), {**body, name: {**value, "bad name": v}}
                    yield type(msg), {**body, name: {1: v}}
                yield type(msg), {**body, name: {}}
        yield type(msg), {k: v for k, v in body.items() if k != list(body)[-1]}  # a field missing
        yield type(msg), {**body, "extra": 1}


def test_the_fast_path_decides_exactly_as_the_general_path(monkeypatch):
    payloads = [(kind, codec.sign(msgpack.packb(body, strict_types=False), KEY)) for kind, body in _variants()]
    fast = [_outcome(p, kind) for kind, p in payloads]
    assert sum(o[0] == "ok" for o in fast) > 20 and sum(o[0] == "rejected" for o in fast) > 100
    monkeypatch.setattr(codec, "_fast", lambda cls, envelope=True: None)  # the general path alone
    assert [_outcome(p, kind) for kind, p in payloads] == fast


def test_the_fast_path_covers_the_step_messages():
    for kind in (Obs, Task, Down, Up, Cmd):
        assert codec._fast(kind) is not None, kind


@pytest.mark.parametrize("msg", [m for m in SAMPLES if type(m) in (Obs, Task, Down, Up, Cmd)])
def test_a_message_handed_over_in_process_is_the_one_its_bytes_decode_to(msg):
    """codec.local (a Node of the same session, no bytes): the message decode would give, in containers of its own."""
    got = codec.local(msg, "run1", "me", "run1")
    assert got == codec.decode(codec.encode(msg, "run1", "me", KEY), type(msg), "run1", KEY)
    for name, value in got.__dict__.items():
        if isinstance(value, dict) and value:
            assert value is not getattr(msg, name)  # the receiver's own map: the sender's stays the sender's


@pytest.mark.parametrize(
    "msg",
    [
        Obs(epoch=1, step=2, q=math.nan),
        Down(epoch=3, step=4, base=(1.0, math.inf, 0.5), goal=(4.0, 6.0), reward=-1.5),
        Task(epoch=0, step=7, goal=(4.16, 6.18, 1.0, 2.0), tips={"a4": (1.0, 2.0, 0.3)}),  # no Coords of 4
        Up(epoch=0, step=1, tips={"bad key!": (1.0, 2.0, 0.3)}, action=1),
        Obs(epoch=1, step=2, q=0.5, sense={"x": math.nan}),
    ],
)
def test_in_process_a_message_the_wire_would_refuse_is_left_to_the_wire_path(msg):
    """codec.local cannot pass what decode refuses: it says None, and the bytes' way gives the reason."""
    assert codec.local(msg, "run1", "me", "run1") is None
    with pytest.raises(codec.DecodeError):
        codec.decode(codec.encode(msg, "run1", "me", KEY), type(msg), "run1", KEY)


def test_in_process_a_message_of_another_run_is_not_taken():
    cmd = Cmd(epoch=0, step=1, delta=0.0)
    assert codec.local(cmd, "run1", "me", "run1") == cmd
    assert codec.local(cmd, "run2", "me", "run1") is None  # the receiver's bytes path then says why
    with pytest.raises(codec.DecodeError, match="run 'run2'"):
        codec.decode(codec.encode(cmd, "run2", "me", KEY), Cmd, "run1", KEY)


# -- a fleet's Batch: one payload, one item per robot ------------------------------------------------------------------
CMD = {"epoch": 1, "step": 2, "delta": 0.0}


def _batch_body(**over):
    body = {
        "v": SCHEMA_VERSION,
        "kind": "batch",
        "run": "run1",
        "src": "a1",
        "of": "cmd",
        "robots": [0, 2],
        "items": [{"epoch": 1, "step": 2, "delta": 0.01}, {"epoch": 1, "step": 2, "delta": -0.01}],
    }
    body.update(over)
    return codec.sign(msgpack.packb(body), KEY)


def test_a_batch_decodes_into_its_robots_messages():
    b = codec.decode_batch(_batch_body(), Cmd, "run1", KEY)
    assert b.robots == [0, 2] and b.items == [Cmd(epoch=1, step=2, delta=0.01), Cmd(epoch=1, step=2, delta=-0.01)]


@pytest.mark.parametrize(
    "over, reason",
    [
        ({"of": "down"}, "batch of 'down', expected 'cmd'"),
        ({"robots": [2, 0]}, "ascending"),
        ({"robots": [0, 0]}, "ascending"),
        ({"robots": [-1, 0]}, "ascending"),
        ({"robots": [0]}, "1 robots for 2 items"),
        ({"robots": [], "items": []}, "at least one"),
        ({"items": [CMD, {"epoch": 1, "step": 2, "delta": float("nan")}]}, "items[1].delta"),
        ({"items": [{"epoch": 1, "step": 2}, CMD]}, "items[0].missing field 'delta'"),
        ({"items": [{**CMD, "x": 1}, CMD]}, "unexpected"),
        ({"items": [5, CMD]}, "items[0]: expected a map"),
        ({"run": "run2"}, "run 'run2'"),
    ],
)  # fmt: skip
def test_a_bad_batch_is_refused_whole_with_the_item_named(over, reason):
    with pytest.raises(codec.DecodeError) as e:
        codec.decode_batch(_batch_body(**over), Cmd, "run1", KEY)
    assert reason in str(e.value)


def test_a_batch_handed_over_in_process_is_the_one_its_bytes_decode_to():
    batch = next(m for m in SAMPLES if type(m) is Batch and m.of == "down")
    got = codec.local(batch, "run1", "me", "run1")
    assert got == codec.decode(codec.encode(batch, "run1", "me", KEY), Batch, "run1", KEY)
    assert got.items[0].sense is not batch.items[0].sense  # the receiver's own maps
    nan = Batch(of="cmd", robots=[0, 1], items=[Cmd(epoch=0, step=0, delta=0.0), Cmd(epoch=0, step=0, delta=math.nan)])
    assert codec.local(nan, "run1", "me", "run1") is None  # left to the bytes' way, which says why
    with pytest.raises(codec.DecodeError, match=r"items\[1\]\.delta"):
        codec.decode_batch(codec.encode(nan, "run1", "me", KEY), Cmd, "run1", KEY)
    assert codec.local(Batch(of="cmd", robots=[1, 0], items=nan.items), "run1", "me", "run1") is None
    assert codec.local(Batch(of="obs", robots=[0, 1], items=nan.items), "run1", "me", "run1") is None
