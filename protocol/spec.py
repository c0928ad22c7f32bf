"""What every spec parser of a run file shares: the one error type, naming the file, the field and the fault, and
the checks of numbers and vectors."""

from __future__ import annotations

import math
import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any


class SpecError(ValueError):
    """A run file (or a part of it: robot, scene, task, ...) that does not fit; str(e) is one line:
    `<file>: <field>: <what is wrong>`."""

    def __init__(self, source: str, where: str, what: str) -> None:
        super().__init__(f"{shown(source)}: {shown(where)}: {one_line(what)}")
        self.source, self.where, self.what = source, where, what

    def __reduce__(self) -> tuple:  # pickled with its three parts: a worker process's error reaches its parent whole
        return (type(self), (self.source, self.where, self.what))


def one_line(text: str) -> str:
    """`text` with what would break its line (a line break, a tab, any character not printable) written as Python
    writes it in a string: the message stays one line, and says exactly what the value held."""
    return text if text.isprintable() else "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)


def shown(name: str) -> str:
    """A file or field name as it is, or quoted (repr) when it holds what cannot be shown on the line."""
    return name if name.isprintable() else repr(name)


def number(src: str, where: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise SpecError(src, where, f"expected a finite number, got {v!r}")
    return float(v)


def vector(src: str, where: str, v: Any, n: int) -> tuple[float, ...]:
    if not isinstance(v, (list, tuple)) or len(v) != n:
        raise SpecError(src, where, f"expected a list of {n} numbers, got {v!r}")
    return tuple(number(src, f"{where}[{i}]", x) for i, x in enumerate(v))


def table(src: str, where: str, v: Any, known: set[str] | frozenset[str]) -> dict[str, Any]:
    """`v` as a table whose keys are all in `known` (the first unknown one is named, with what is known)."""
    if not isinstance(v, dict):
        raise SpecError(src, where, f"must be a table, got {v!r:.60}")
    bad = sorted(set(v) - set(known))
    if bad:
        name = bad[0] if str(bad[0]).isprintable() else repr(bad[0])  # a key like "\n" is named on the one line
        raise SpecError(src, f"{where}.{name}", f"unknown field (expected {', '.join(sorted(known))})")
    return v


def read_toml(path: str | Path, error: Callable[[str, str, str], Exception] = SpecError) -> dict[str, Any]:
    """A TOML file's document; a file that cannot be read, or is no TOML, is `error(file, where, what)`: one line."""
    p = Path(path)
    try:
        text = p.read_text()
    except (OSError, ValueError) as e:  # ValueError: a NUL in the name
        raise error(str(p), "file", f"cannot read: {getattr(e, 'strerror', None) or e}") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as e:
        raise error(str(p), "toml", str(e)) from None
