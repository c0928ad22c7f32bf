"""The plumbing of run-file tables: a msgspec error in TOML's words and the user's place (file or flag), the paths a
file names made absolute, tables merged over their bases, a value set at a dotted key, values made plain for TOML."""

from __future__ import annotations

import dataclasses
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import msgspec
from kinswarm.actors.files.config import ConfigError
from kinswarm.protocol.spec import SpecError

#: fields that name files, resolved against where they were written (a file's against it, a flag's the working dir)
PATH_KEYS = (("run", "from"), ("run", "scenario"), ("learner", "policy"))


def spec_error(e: msgspec.ValidationError, source: str, section: str, values: Any = None) -> SpecError:
    """msgspec's "Expected `int`, got `str` - at `$.seed`" or a __post_init__'s "field: what" (of a nested table too:
    "radius: must be > 0 - at `$.circle`") as a SpecError naming the field, in TOML's words ("expected an integer,
    got a string 'x'"). `values`: the section's table, where the value found wrong is looked up to be shown."""
    text = str(e)
    where = section
    m = re.fullmatch(r"(.*) - at `\$\.?(.*)`", text, re.S)
    if m:
        text, path = m.group(1), m.group(2).replace("$", "")
        where = f"{section}.{path}" if path else section
        text = toml_words(text, value_at(values, path))
        text = text[0].lower() + text[1:]
    field, sep, what = text.partition(": ")
    if sep and re.fullmatch(r"[a-z_]+", field):
        return SpecError(source, f"{where}.{'from' if field == 'from_dir' else field}", what)
    return SpecError(source, where, text)


# msgspec's names of types as a TOML file has them; `null` is a field left out (TOML has no null)
_TOML_TYPES = {
    "int": "an integer",
    "float": "a number",
    "str": "a string",
    "bool": "true or false",
    "array": "a list",
    "object": "a table",
}
_NOTHING = object()


def toml_words(text: str, value: Any = _NOTHING) -> str:
    """`Expected `array | null`, got `str`` -> `Expected a list, got a string '[1,'`."""

    def names(m: re.Match[str]) -> str:
        kinds = [_TOML_TYPES.get(t.strip(), t.strip()) for t in m.group(1).split("|") if t.strip() != "null"]
        return " or ".join(kinds) or m.group(0)

    got = re.fullmatch(r"(Expected `[^`]+`), got `(\w+)`", text)
    if got:
        shown = f" {value!r:.60}" if isinstance(value, (str, int, float)) and not isinstance(value, bool) else ""
        text = f"{got.group(1)}, got {_TOML_TYPES.get(got.group(2), got.group(2))}{shown}"
    text = re.sub(r"Expected `array` of length (\d+), got (\d+)", r"Expected a list of \1 values, got \2", text)
    text = re.sub(r"`([a-z]+(?: \| [a-z]+)*)`", names, text)
    return re.sub(r"`(\w+)`", r"\1", text)


def value_at(values: Any, path: str) -> Any:
    """The value at a msgspec path (`goal[1]`, `extra_state[0].name`) of a table, or _NOTHING."""
    node = values
    for name, index in re.findall(r"(\w+)|\[(\d+)\]", path):
        try:
            node = node[name] if name else node[int(index)]
        except (KeyError, IndexError, TypeError):
            return _NOTHING
    return node if path else _NOTHING


def absolute_paths(data: dict[str, Any], base: Path) -> None:
    for section, key in PATH_KEYS:
        table = data.get(section)
        if isinstance(table, dict) and key in table:
            table[key] = absolute(table[key], base)
    if isinstance(data.get("robot"), str):
        data["robot"] = absolute(data["robot"], base)


def merged(under: dict[str, Any], over: Mapping[str, Any]) -> dict[str, Any]:
    """`over`'s fields laid over `under`'s, table by table (a list or value replaces)."""
    out = dict(under)
    for k, v in over.items():
        out[k] = merged(out[k], v) if isinstance(v, Mapping) and isinstance(out.get(k), dict) else v
    return out


def absolute(value: Any, base: Path) -> Any:
    """A path as written, made absolute; a NUL left as it is, for the check of the field to name (no path has one)."""
    return str((base / value).resolve()) if isinstance(value, str) and value and "\0" not in value else value


def put(data: dict[str, Any], keys: tuple[str, ...], value: Any) -> None:
    node = data
    for i, k in enumerate(keys[:-1]):
        nxt = node.setdefault(k, {})
        if not isinstance(nxt, dict):
            raise ConfigError(f"--set {'.'.join(keys)}: {'.'.join(keys[: i + 1])} is not a table")
        node = nxt
    node[keys[-1]] = value


def copied(v: Any) -> Any:
    if isinstance(v, Mapping):
        return {k: copied(x) for k, x in v.items()}
    if isinstance(v, list | tuple):
        return [copied(x) for x in v]
    return v


def plain(v: Any) -> Any:
    """TOML- and JSON-friendly: tuples and dataclasses as lists and tables, None left out of tables."""
    if dataclasses.is_dataclass(v) and not isinstance(v, type):
        return {f.name: plain(getattr(v, f.name)) for f in dataclasses.fields(v)}
    if isinstance(v, Mapping):
        return {k: plain(x) for k, x in v.items() if x is not None}
    if isinstance(v, list | tuple):
        return [plain(x) for x in v]
    if isinstance(v, float) and not math.isfinite(v):
        raise ConfigError(f"not a finite number: {v!r}")
    return v
