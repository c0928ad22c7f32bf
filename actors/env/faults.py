"""Joint faults as the environments take them: a Fault (protocol/messages.py), a mapping of its fields, or its name
with the targets and sizes, as `kinswarm fault reverse a2` names one. Checked when applied (core.Stepper.check)."""

from __future__ import annotations

import itertools
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

from kinswarm.protocol.messages import Fault

OPTIONS = ("goal", "faults")  # what reset(options=...) takes
PARAMS = ("seconds", "steps", "rate", "ms", "amplitude_deg", "factor", "degrees")
_ids = itertools.count()


def as_fault(
    fault: Fault | Mapping[str, Any] | str, targets: Sequence[str] = (), params: Mapping[str, Any] = {}
) -> Fault:  # noqa: B006 - read only
    """A Fault from what the caller gave; one line naming what is wrong otherwise."""
    if isinstance(fault, Fault):
        if targets or params:
            raise ValueError("fault: a Fault takes no further targets or sizes")
        return fault
    if isinstance(fault, Mapping):
        fields = dict(fault)
        name, given = fields.pop("fault", None), fields.pop("targets", None)
        if given is None or isinstance(given, str):
            given = [given] if isinstance(given, str) else []
        return as_fault(name, [*given, *targets], {**fields, **params})  # type: ignore[arg-type]
    if not isinstance(fault, str):
        raise ValueError(f"fault: expected a Fault, a mapping or a fault's name, got {fault!r}")
    unknown = sorted(set(params) - set(PARAMS))
    if unknown:
        raise ValueError(f"fault {fault}: unknown field {unknown[0]!r} (a fault takes {', '.join(PARAMS)})")
    if not all(isinstance(t, str) for t in targets):
        raise ValueError(f"fault {fault}: targets are agent ids, got {list(targets)!r}")
    values = {k: params.get(k) for k in PARAMS}
    return Fault(id=f"env-{next(_ids)}", fault=fault, targets=list(targets), **values)


def as_faults(given: Any) -> list[Fault]:
    """reset's options["faults"]: a list of what `as_fault` takes (a lone one too)."""
    if isinstance(given, (Fault, Mapping, str)):
        given = [given]
    if not isinstance(given, (list, tuple)):
        raise ValueError(f"reset options faults: expected a list of faults, got {given!r}")
    return [as_fault(f) for f in given]


def reset_options(options: Mapping[str, Any] | None) -> tuple[Any, list[Fault] | None]:
    """reset's options: (the episode's goal or None, its faults or None: those the robot has stay). A key the env
    does not take is warned of, not refused: PettingZoo's API test resets with one of its own."""
    options = dict(options or {})
    for key in options:
        if key not in OPTIONS:
            warnings.warn(
                f"reset options: {key!r} is not one this env takes ({', '.join(OPTIONS)}); ignored", stacklevel=3
            )
    return options.get("goal"), as_faults(options["faults"]) if "faults" in options else None
