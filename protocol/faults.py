"""The fault vocabulary (docs/faults.md) and the one check every fault passes, wherever it comes from
(the `kinswarm fault` CLI, a scenario file, the supervisor receiving a request)."""

from __future__ import annotations

import math

from .messages import Fault

# The robot's model: what a controller that assumes the model gets wrong, and a learner can relearn. `free` ends them.
MODEL_FAULTS = ("reverse", "scale", "deadzone", "offset", "lag")
JOINT_FAULTS = ("lock", "free", "disturb", *MODEL_FAULTS)  # the robot: applied by the sim, unknown to the agents
PROCESS_FAULTS = ("kill", "freeze", "thaw", "restart")  # the processes: applied by the supervisor
LINK_FAULTS = ("drop", "delay", "duplicate", "corrupt", "clear")  # the messages: applied in the runtime
FAULTS = JOINT_FAULTS + PROCESS_FAULTS + LINK_FAULTS
ALL = "all"  # target: every agent

DISTURB_AMPLITUDE_DEG = 2.0  # default: uniform in +-2 degrees per step, twice the action size

# which optional fields each fault takes; the others must be None
_PARAMS: dict[str, tuple[str, ...]] = {
    "lock": (),
    "free": (),
    "disturb": ("steps", "amplitude_deg"),
    "reverse": (),  # the motor turns the other way
    "scale": ("factor",),  # the motor moves factor x the command
    "deadzone": ("degrees",),  # commands smaller than this move nothing
    "offset": ("degrees",),  # the encoder reads q + degrees
    "lag": ("steps",),  # the encoder reads the angle of `steps` steps ago
    "kill": (),
    "freeze": ("seconds",),
    "thaw": (),
    "restart": (),
    "drop": ("rate", "seconds"),
    "delay": ("ms", "seconds"),
    "duplicate": ("rate", "seconds"),
    "corrupt": ("rate", "seconds"),
    "clear": (),
}
_REQUIRED: dict[str, tuple[str, ...]] = {
    "drop": ("rate",),
    "delay": ("ms",),
    "disturb": ("steps",),
    "scale": ("factor",),
    "deadzone": ("degrees",),
    "offset": ("degrees",),
    "lag": ("steps",),
}
_OPTIONAL_FIELDS = ("seconds", "steps", "rate", "ms", "amplitude_deg", "factor", "degrees")
MAX_LAG_STEPS = 1000  # the encoder's memory is kept per step


def check_fault(f: Fault, agents: list[str] | None = None) -> str:
    """Return what is wrong with `f` ("" when nothing is). `agents`: the run's agent ids, if known."""
    if f.fault not in FAULTS:
        return f"unknown fault {f.fault!r}; expected one of {', '.join(FAULTS)}"
    if not f.targets:
        return f"{f.fault}: no target given"
    if agents is not None:
        for t in f.targets:
            if t != ALL and t not in agents:
                return f"{f.fault}: {t!r} is not an agent of this run ({', '.join(agents)})"
    allowed = _PARAMS[f.fault]
    for name in _OPTIONAL_FIELDS:
        if getattr(f, name) is not None and name not in allowed:
            takes = ", ".join(allowed) or "nothing"
            return f"{f.fault}: does not take {name} (takes {takes})"
    for name in _REQUIRED.get(f.fault, ()):
        if getattr(f, name) is None:
            return f"{f.fault}: needs {name}"
    if f.rate is not None and not 0.0 <= f.rate <= 1.0:
        return f"{f.fault}: rate must be in [0, 1], got {f.rate}"
    if f.seconds is not None and not f.seconds > 0:
        return f"{f.fault}: seconds must be > 0, got {f.seconds}"
    if f.steps is not None and f.steps < 1:
        return f"{f.fault}: steps must be >= 1, got {f.steps}"
    if f.ms is not None and not 0 <= f.ms <= 60_000:
        return f"{f.fault}: ms must be in [0, 60000], got {f.ms}"
    if f.amplitude_deg is not None and not 0 < f.amplitude_deg <= 90:
        return f"{f.fault}: amplitude_deg must be in (0, 90], got {f.amplitude_deg}"
    if f.factor is not None and not (math.isfinite(f.factor) and 0 < abs(f.factor) <= 100):
        return f"{f.fault}: factor must be nonzero, at most 100 in size, got {f.factor}"
    if f.degrees is not None:
        lo = 0 if f.fault == "deadzone" else -180
        if not lo < f.degrees <= 180:
            return f"{f.fault}: degrees must be in ({lo}, 180], got {f.degrees}"
    if f.fault == "lag" and f.steps is not None and f.steps > MAX_LAG_STEPS:
        return f"lag: steps must be at most {MAX_LAG_STEPS}, got {f.steps}"
    if f.robot is not None:
        if f.fault not in JOINT_FAULTS:  # kill, freeze and message faults act on an agent: every robot's joint
            return f"{f.fault}: acts on an agent, so on every robot of a fleet; only joint faults take a robot"
        if f.robot < 0:
            return f"{f.fault}: robot must be >= 0, got {f.robot}"
    return ""


def expand_targets(targets: list[str], agents: list[str]) -> list[str]:
    """`all` -> every agent; otherwise the targets in order, each once."""
    if ALL in targets:
        return list(agents)
    return list(dict.fromkeys(targets))


def describe(f: Fault) -> str:
    """One line for logs, events and the CLI: `drop a2,a3 rate=0.05 seconds=30`."""
    extras = [f"{n}={getattr(f, n):g}" for n in _OPTIONAL_FIELDS if getattr(f, n) is not None]
    robot = [f"robot={f.robot}"] if f.robot is not None else []
    return " ".join([f.fault, ",".join(f.targets), *extras, *robot])
