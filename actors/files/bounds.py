"""A field's bounds, declared beside it: `field(..., metadata=checks(integer(1)))`. Each check says what is wrong
with a value, in one line that names the field ("" when nothing is), and `first_problem` runs every field's checks in
the order the fields are declared: the one loop a dataclass's `__post_init__` needs (actors/files/config.py)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from typing import Any

#: (the field's name, its value, the whole object: a bound on one field may depend on another) -> the problem, or ""
Check = Callable[[str, Any, Any], str]
CHECKS = "checks"  # the metadata key


def checks(*each: Check) -> dict[str, tuple[Check, ...]]:
    """A field's metadata: its checks, run in order; the first problem is the field's."""
    return {CHECKS: each}


def first_problem(obj: Any) -> str:
    """The first problem of the first field of `obj` (a dataclass) that has one, in declaration order; "" if none."""
    for f in dataclasses.fields(obj):
        for check in f.metadata.get(CHECKS, ()):
            if problem := check(f.name, getattr(obj, f.name), obj):
                return problem
    return ""


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_number(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


def integer(lo: int) -> Check:
    """An integer (not a bool) >= `lo`."""
    return lambda name, v, _: "" if _is_int(v) and v >= lo else f"{name}: expected an integer >= {lo}, got {v!r}"


def integer_in(lo: int, hi: int) -> Check:
    """An integer (not a bool) in [lo, hi]."""
    return lambda name, v, _: (
        "" if _is_int(v) and lo <= v <= hi else f"{name}: expected an integer in [{lo}, {hi}], got {v!r}"
    )


def below(hi: int, shown: str) -> Check:
    """Below `hi` (written `shown`); after `integer`, which says what the value must be."""
    return lambda name, v, _: "" if v < hi else f"{name}: expected an integer below {shown}, got {v}"


def at_most(hi: int) -> Check:
    """At most `hi`; after `integer`, which says what the value must be."""
    return lambda name, v, _: "" if v <= hi else f"{name}: expected at most {hi}, got {v}"


def one_of(choices: Sequence[str]) -> Check:
    return lambda name, v, _: "" if v in choices else f"{name}: {v!r} is not one of {', '.join(choices)}"


def boolean(name: str, v: Any, _: Any) -> str:
    return "" if isinstance(v, bool) else f"{name}: expected true or false, got {v!r}"


def number_in(lo: float, hi: float) -> Check:
    """A number (not a bool) in (lo, hi]."""
    return lambda name, v, _: (
        "" if _is_number(v) and lo < v <= hi else f"{name}: expected a number in ({lo}, {hi}], got {v!r}"
    )


def positive(name: str, v: Any, _: Any) -> str:
    """A finite number > 0."""
    return "" if _is_number(v) and math.isfinite(v) and v > 0 else f"{name}: expected a number > 0, got {v!r}"


def seconds(name: str, v: Any, _: Any) -> str:
    """A finite number of seconds >= 0."""
    ok = _is_number(v) and math.isfinite(v) and v >= 0
    return "" if ok else f"{name}: expected a number of seconds >= 0, got {v!r}"
