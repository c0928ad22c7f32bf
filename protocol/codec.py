"""The one codec: msgpack maps, validated field by field against the message dataclasses, and signed.

A payload is the msgpack body followed by a 16-byte keyed BLAKE2b digest of the body (the MAC), keyed
with the run's secret (`RunConfig.secret`, in the run's 0600 config.json). Validation alone cannot tell
a well-formed message with a plausible step from an impostor's, and such a message would silently change
learned state; with the MAC only holders of the run's config can speak on its keys.

`decode` never lets garbage through: a bad MAC, wrong version, run, kind, missing or extra fields, wrong
types, non-finite numbers — each raises `DecodeError` with the reason, which the receiving actor logs
before dropping the message. Learned state is only ever touched by values that passed here.

The step messages take a fast path first (`_fast`): straight-line checks generated once per message type,
accepting only exact types (a float field must hold a finite float, not an int) and returning the same
message the general path would. Anything it does not accept goes through the general path, which
accepts or rejects with the reason — so the fast path changes the speed of decoding, never its outcome.
"""

from __future__ import annotations

import dataclasses
import hashlib
import hmac
import math
import re
import threading
import types
import typing
from functools import cache, lru_cache
from typing import Any, TypeVar, get_args, get_origin

import msgpack

from . import messages
from .messages import MESSAGE_TYPES, SCHEMA_VERSION

M = TypeVar("M")
MAX_PAYLOAD = 1 << 20  # 1 MiB: nothing in the protocol comes near; a bigger payload is garbage or an attack
_ENVELOPE = ("v", "kind", "run", "src")
MAC_SIZE = 16  # bytes of BLAKE2b digest after the body: 128 bits, far beyond guessing on a live wire
BAD_MAC = "bad MAC: not signed with this run's key (forged, corrupted, or from another run)"
#: Every map key of a message is a name: an actor id, a reading (messages.Readings), a trace. Checked on both paths.
READING_NAME = re.compile(r"[A-Za-z0-9_+./-]{1,64}")
_is_name = READING_NAME.fullmatch


class DecodeError(ValueError):
    """A payload that is not a valid message of the expected kind; str(e) is the reason."""


@cache
def _field_names(cls: type) -> tuple[str, ...]:
    return tuple(f.name for f in dataclasses.fields(cls))


@lru_cache(maxsize=8)
def _keyed(key: bytes) -> Any:
    """A keyed BLAKE2b state to copy: copying skips hashing the key block again (~0.2 us a message)."""
    if not isinstance(key, bytes) or not key:
        raise ValueError("the MAC key must be non-empty bytes (RunConfig.key)")  # a programming error
    return hashlib.blake2b(key=key, digest_size=MAC_SIZE)


def _mac(body: bytes, key: bytes) -> bytes:
    h = _keyed(key).copy()
    h.update(body)
    return h.digest()


def sign(body: bytes, key: bytes) -> bytes:
    """`body` + its MAC: what goes on the wire. `encode` uses it; tests use it to sign hand-made bodies."""
    return body + _mac(body, key)


def encode(msg: Any, run: str, src: str, key: bytes) -> bytes:
    cls = type(msg)
    if cls is messages.Batch:  # each item as the map of its fields, under the batch's one envelope
        body = {"v": SCHEMA_VERSION, "kind": msg.KIND, "run": run, "src": src}
        body.update(of=msg.of, robots=list(msg.robots), items=[_item(m) for m in msg.items])
    else:
        body = (_bodies.get(cls) or _body(cls))(msg, run, src)
    return sign(_pack(body), key)


def _pack(body: Any) -> bytes:
    """msgpack.packb(body, use_bin_type=True), with this thread's Packer rather than a new one a message."""
    try:
        packer = _packers.packer
    except AttributeError:  # this thread's first message
        packer = _packers.packer = msgpack.Packer(use_bin_type=True)
    return packer.pack(body)


_packers = threading.local()  # a Packer keeps a buffer between its calls: one a thread (handlers run on several)
_bodies: dict[type, Any] = {}  # message class -> its body builder (_body)


def _body(cls: type) -> Any:
    """The body builder of message class `cls`, generated once: `(msg, run, src) -> {"v": ..., "kind": ..., "run":
    run, "src": src, "epoch": msg.epoch, ...}`, the envelope then the fields in their order, as one dict display
    (the same map, so the same bytes, as filling a dict field by field; ~1 us less a message)."""
    items = [f'"v": {SCHEMA_VERSION!r}', f'"kind": {cls.KIND!r}', '"run": run', '"src": src']  # type: ignore[attr-defined]
    items += [f"{name!r}: msg.{name}" for name in _field_names(cls)]
    scope: dict[str, Any] = {}
    exec(
        compile(
            f"def body(msg, run, src):\n    return {{{', '.join(items)}}}\n", f"<codec body of {cls.__name__}>", "exec"
        ),
        scope,
    )
    _bodies[cls] = scope["body"]
    return scope["body"]


def _item(msg: Any) -> dict[str, Any]:
    return {name: getattr(msg, name) for name in _field_names(type(msg))}


Check = typing.Callable[[Any, str], Any]


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise DecodeError(f"{where}: expected a number, got {type(value).__name__}")
    if not math.isfinite(value):
        raise DecodeError(f"{where}: expected a finite number, got {value!r}")
    return float(value)


def _integer(value: Any, where: str) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise DecodeError(f"{where}: expected an integer, got {type(value).__name__}")
    return value


def _string(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise DecodeError(f"{where}: expected a string, got {type(value).__name__}")
    return value


@cache
def _checker(tp: Any) -> Check:
    """A validating converter for field type `tp`, built once per type (decode is on the step's hot path)."""
    origin = get_origin(tp)
    if tp is float:
        return _number
    if tp is int:
        return _integer
    if tp is str:
        return _string
    if origin in (types.UnionType, typing.Union):  # `float | None`
        (inner,) = [a for a in get_args(tp) if a is not type(None)]
        check_inner = _checker(inner)
        return lambda v, where: None if v is None else check_inner(v, where)
    if origin is tuple and get_args(tp) == (float, Ellipsis):  # Coords: a goal, frame or tip of the robot's kind
        _finite = math.isfinite
        sizes = messages.COORD_SIZES

        def check_coords(value: Any, where: str) -> tuple:
            if not isinstance(value, (list, tuple)) or len(value) not in sizes:
                raise DecodeError(f"{where}: expected a list of {' or '.join(map(str, sizes))}, got {value!r:.60}")
            if all(type(v) is float and _finite(v) for v in value):
                return tuple(value)
            return tuple(_number(v, f"{where}[{i}]") for i, v in enumerate(value))

        return check_coords
    if origin is tuple:
        checks = [_checker(a) for a in get_args(tp)]
        n = len(checks)
        all_floats = all(a is float for a in get_args(tp))
        _finite = math.isfinite

        def check_tuple(value: Any, where: str) -> tuple:
            if not isinstance(value, (list, tuple)) or len(value) != n:
                raise DecodeError(f"{where}: expected a list of {n}, got {value!r:.60}")
            if all_floats and all(type(v) is float and _finite(v) for v in value):
                return tuple(value)  # the common case, without building a `where` per element
            return tuple(c(v, f"{where}[{i}]") for i, (c, v) in enumerate(zip(checks, value, strict=True)))

        return check_tuple
    if origin is list:
        check_item = _checker(get_args(tp)[0])

        def check_list(value: Any, where: str) -> list:
            if not isinstance(value, (list, tuple)):
                raise DecodeError(f"{where}: expected a list, got {type(value).__name__}")
            return [check_item(v, f"{where}[{i}]") for i, v in enumerate(value)]

        return check_list
    if origin is dict:
        check_value = _checker(get_args(tp)[1])

        def check_dict(value: Any, where: str) -> dict:
            if not isinstance(value, dict):
                raise DecodeError(f"{where}: expected a map, got {type(value).__name__}")
            out = {}
            for k, v in value.items():
                if not isinstance(k, str) or not _is_name(k):
                    raise DecodeError(f"{where}: expected names (letters, digits, _+-./) as keys, got {k!r:.40}")
                out[k] = check_value(v, f"{where}.{k}")
            return out

        return check_dict
    raise TypeError(f"unsupported field type {tp!r}")  # a bug in messages.py, not bad input


@cache
def _schema(cls: type) -> tuple[tuple[tuple[str, Check], ...], frozenset[str]]:
    hints = {k: v for k, v in typing.get_type_hints(cls, vars(messages)).items() if k != "KIND"}
    return tuple((k, _checker(v)) for k, v in hints.items()), frozenset(hints) | frozenset(_ENVELOPE)


def _fast_field(name: str, tp: Any, lines: list[str]) -> bool:
    """Append checks of field `name` (local variable `name`, `_` on failure) to `lines`; False if `tp` has none."""
    finite = "type({x}) is float and {x} - {x} == 0.0"  # a finite float: x - x is nan for inf and nan

    def vec(x: str, n: int) -> list[str]:
        items = ", ".join(f"{x}{i}" for i in range(n))
        checks = " and ".join(finite.format(x=f"{x}{i}") for i in range(n))
        return [
            f"if type({x}) not in seq or len({x}) != {n}: return None",
            f"{items}{',' if n == 1 else ''} = {x}",
            f"if not ({checks}): return None",
        ]

    def coords(x: str) -> list[str]:  # Coords: one of COORD_SIZES finite floats
        return [
            f"if type({x}) not in seq or len({x}) not in {messages.COORD_SIZES!r}: return None",
            f"for c in {x}:",
            f"    if not ({finite.format(x='c')}): return None",
        ]

    def vec_len(t: Any) -> int | None:
        args = get_args(t)
        return len(args) if get_origin(t) is tuple and args and all(a is float for a in args) else None

    origin = get_origin(tp)
    if tp is int:
        lines.append(f"if type({name}) is not int: return None")
    elif tp is float:
        lines.append(f"if not ({finite.format(x=name)}): return None")
    elif tp is str:
        lines.append(f"if type({name}) is not str: return None")
    elif origin in (types.UnionType, typing.Union) and set(get_args(tp)) == {float, type(None)}:
        lines.append(f"if {name} is not None and not ({finite.format(x=name)}): return None")
    elif (n := vec_len(tp)) is not None:
        lines += vec(name, n)
        lines.append(f"{name} = tuple({name})")
    elif origin is tuple and get_args(tp) == (float, Ellipsis):
        lines += coords(name)
        lines.append(f"{name} = tuple({name})")
    elif origin is dict and get_args(tp)[0] is str and get_args(tp)[1] == messages.Coords:
        lines.append(f"if type({name}) is not dict: return None")
        lines.append(f"for k, v in {name}.items():")
        lines.append("    if type(k) is not str or not is_name(k): return None")
        lines += ["    " + line for line in coords("v")]
        lines.append(f"{name} = {{k: tuple(v) for k, v in {name}.items()}}")
    elif origin is dict and get_args(tp) == (str, float):
        lines.append(f"if type({name}) is not dict: return None")
        lines.append(f"for k, v in {name}.items():")
        lines.append(f"    if type(k) is not str or not is_name(k) or not ({finite.format(x='v')}): return None")
        lines.append(f"{name} = dict({name}) if {name} else {{}}")  # the receiver's own (local(): not the sender's)
    elif origin is dict and get_args(tp)[0] is str and (n := vec_len(get_args(tp)[1])) is not None:
        lines.append(f"if type({name}) is not dict: return None")
        lines.append(f"for k, v in {name}.items():")
        lines.append("    if type(k) is not str or not is_name(k): return None")
        lines += ["    " + line for line in vec("v", n)]
        lines.append(f"{name} = {{k: tuple(v) for k, v in {name}.items()}}")
    else:
        return False
    return True


@cache
def _fast(cls: type, envelope: bool = True) -> Any:
    """The fast path for `cls`: body -> message, or None for "ask the general path"; None if `cls` has none.
    Without `envelope`: a Batch's item, the map of the fields alone (the batch's envelope is checked once).

    Generated source, e.g. for Cmd: `if len(b) != 7 or b.get("v") != 2 or ... : return None`,
    `epoch = b.get("epoch")`, `if type(epoch) is not int: return None`, ..., then the message."""
    hints = {k: v for k, v in typing.get_type_hints(cls, vars(messages)).items() if k != "KIND"}
    if hasattr(cls, "__post_init__") or getattr(cls, "__slots__", None) is not None:
        return None  # built field by field below: only for plain dataclasses
    if envelope:
        lines = [
            f"if len(b) != {len(hints) + len(_ENVELOPE)} or b.get('v') != {SCHEMA_VERSION!r}"
            f" or b.get('kind') != {cls.KIND!r}"  # type: ignore[attr-defined]
            " or b.get('run') != run or type(b.get('src')) is not str: return None"
        ]
    else:
        lines = [f"if len(b) != {len(hints)}: return None"]
    for name, tp in hints.items():
        lines.append(f"{name} = b.get({name!r})")
        if not _fast_field(name, tp, lines):
            return None
    # what the dataclass __init__ does, without its per-field object.__setattr__ (the messages are frozen)
    lines += ["m = new(cls)", "d = m.__dict__", *(f"d[{k!r}] = {k}" for k in hints), "return m"]
    src = "def fast(b, run):\n" + "".join(f"    {line}\n" for line in lines)
    # seq: msgpack gives lists; local() hands in the sender's tuples
    scope: dict[str, Any] = {"new": object.__new__, "cls": cls, "is_name": _is_name, "seq": (list, tuple)}
    exec(compile(src, f"<codec fast path for {cls.__name__}>", "exec"), scope)
    return scope["fast"]


def decode(payload: bytes, expect: type[M], run: str, key: bytes) -> M:
    """Verify the MAC with `key`, then decode and validate one message of type `expect` for run `run`."""
    if expect is messages.Batch:
        return decode_batch(payload, None, run, key)  # type: ignore[return-value]
    body = _verified(payload, key)
    if type(body) is dict and (fast := _fast(expect)) is not None and (m := fast(body, run)) is not None:
        return m
    _envelope(body, expect.KIND, run)  # type: ignore[attr-defined]
    return expect(**_checked(body, expect, ""))


def decode_batch(payload: bytes, of: type | None, run: str, key: bytes) -> messages.Batch:
    """Verify the MAC with `key`, then decode and validate a Batch of `of` messages (None: of any step message) for
    run `run`: its envelope, its robots (ascending integers >= 0, one per item) and every item as a message of its
    kind (the item's index in the reason). One bad item refuses the batch: it is one actor's one step."""
    body = _verified(payload, key)
    _envelope(body, messages.Batch.KIND, run)
    allowed = frozenset(_field_names(messages.Batch)) | frozenset(_ENVELOPE)
    if set(body) != allowed:
        raise DecodeError(f"batch: expected the fields {sorted(allowed - set(_ENVELOPE))}")
    kind = body["of"]
    if of is None:
        of = messages.BATCHED.get(kind) if type(kind) is str else None
        if of is None:
            raise DecodeError(f"batch of {kind!r:.40}: not a step message")
    elif kind != of.KIND:  # type: ignore[attr-defined]
        raise DecodeError(f"batch of {kind!r:.40}, expected {of.KIND!r}")  # type: ignore[attr-defined]
    robots, items = body["robots"], body["items"]
    _robots(robots, items)
    fast = _fast(of, False)
    out = []
    for i, item in enumerate(items):
        m = fast(item, run) if type(item) is dict and fast is not None else None
        if m is None:
            if not isinstance(item, dict):
                raise DecodeError(f"items[{i}]: expected a map, got {type(item).__name__}")
            m = of(**_checked(item, of, f"items[{i}]."))
        out.append(m)
    return messages.Batch(of=of.KIND, robots=list(robots), items=out)  # type: ignore[attr-defined]


def _robots(robots: Any, items: Any) -> None:
    if not isinstance(robots, list) or not isinstance(items, list):
        raise DecodeError("batch: robots and items must be lists")
    if not robots or len(robots) != len(items):
        raise DecodeError(f"batch: {len(robots)} robots for {len(items)} items (one each, at least one)")
    last = -1
    for r in robots:
        if type(r) is not int or r <= last:
            raise DecodeError(f"batch: robots must be ascending integers >= 0, got {robots!r:.80}")
        last = r


def _verified(payload: bytes, key: bytes) -> Any:
    """The msgpack body of `payload`, once its MAC is verified with `key`."""
    n = len(payload)
    if n > MAX_PAYLOAD:
        raise DecodeError(f"payload of {n} bytes exceeds {MAX_PAYLOAD}")
    mac = _keyed(key)  # checks the key even for a payload refused below
    if n <= MAC_SIZE:
        raise DecodeError(f"payload of {n} bytes is too short to carry a body and its {MAC_SIZE}-byte MAC")
    packed = payload[:-MAC_SIZE]
    h = mac.copy()
    h.update(packed)
    # first, before msgpack sees a byte of it: an unsigned payload is not parsed at all
    if not hmac.compare_digest(h.digest(), payload[-MAC_SIZE:]):
        raise DecodeError(BAD_MAC)
    try:
        return msgpack.unpackb(packed, raw=False, strict_map_key=True)
    except Exception as e:  # msgpack raises several unrelated types for garbage
        raise DecodeError(f"not msgpack: {type(e).__name__}: {e}"[:200]) from None


def _envelope(body: Any, kind: str, run: str) -> None:
    if not isinstance(body, dict):
        raise DecodeError(f"expected a map, got {type(body).__name__}")
    if body.get("v") != SCHEMA_VERSION:
        raise DecodeError(f"schema version {body.get('v')!r}, expected {SCHEMA_VERSION}")
    got = body.get("kind")
    if got != kind:
        known = "" if isinstance(got, str) and got in MESSAGE_TYPES else " (unknown kind)"  # a list is unhashable
        raise DecodeError(f"kind {got!r}{known}, expected {kind!r}")
    if body.get("run") != run:
        raise DecodeError(f"run {body.get('run')!r}, expected {run!r}")
    if not isinstance(body.get("src"), str):
        raise DecodeError("src: expected a string")


def _checked(body: dict[str, Any], cls: type, where: str) -> dict[str, Any]:
    """The fields of a message of type `cls` from `body` (with the envelope, or a Batch's item without), checked;
    `where` prefixes the reason (a batch item's index)."""
    checks, allowed = _schema(cls)
    if where:
        allowed = allowed - frozenset(_ENVELOPE)
    if len(body) != len(allowed) or not allowed.issuperset(body):
        extra = sorted(str(k) for k in set(body) - allowed)
        if extra:
            raise DecodeError(f"{where}unexpected field {extra[0]!r}")
    fields = {}
    for name, check in checks:
        if name not in body:
            raise DecodeError(f"{where}missing field {name!r}")
        fields[name] = check(body[name], where + name)
    return fields


def local(msg: M, sent_run: str, src: str, run: str) -> M | None:
    """`msg`, sent by `src` of run `sent_run`, as a receiver of run `run` in the sender's own process gets it, no
    bytes in between: checked as `decode` checks a body (the same generated fast path, on the same fields and
    envelope), into a message of its own (fresh tuples and maps). None when the fast path cannot tell (a field it
    leaves to the general path, e.g. a numpy float, or a message it would refuse, another run's among them): the
    caller encodes and decodes it then, for the same message or the same reason. The MAC is the caller's to match."""
    cls = type(msg)
    if cls is messages.Batch:
        return _local_batch(msg, sent_run, run)  # type: ignore[return-value]
    fast = _fast(cls)
    if fast is None:
        return None
    return fast({**msg.__dict__, "v": SCHEMA_VERSION, "kind": cls.KIND, "run": sent_run, "src": src}, run)  # type: ignore[attr-defined]


def _local_batch(batch: messages.Batch, sent_run: str, run: str) -> messages.Batch | None:
    """local() of a Batch: the envelope, the robots and every item as decode_batch checks them, into fresh ones."""
    cls = messages.BATCHED.get(batch.of) if type(batch.of) is str else None
    fast = _fast(cls, False) if cls is not None else None
    if fast is None or sent_run != run or type(batch.items) not in (list, tuple):
        return None
    try:
        _robots(list(batch.robots) if type(batch.robots) in (list, tuple) else batch.robots, list(batch.items))
    except DecodeError:
        return None
    items = []
    for m in batch.items:
        if type(m) is not cls or (m := fast(m.__dict__, run)) is None:
            return None
        items.append(m)
    return messages.Batch(of=batch.of, robots=list(batch.robots), items=items)


def sender(payload: bytes) -> str:
    """Best-effort, unverified `src` of a payload (MAC stripped), for log lines about rejected messages."""
    try:
        body = msgpack.unpackb(payload[:-MAC_SIZE], raw=False)
        return str(body.get("src", "?"))[:64] if isinstance(body, dict) else "?"
    except Exception:
        return "?"
