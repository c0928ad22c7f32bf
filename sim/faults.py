"""The robot's joint faults (docs/faults.md), as the simulator applies them: unknown to the agents, who see only what
a real robot would show them — a joint that does not move as commanded, an encoder that reads wrong.

- `lock`: the joint holds, whatever its agent commands.
- `disturb`: for `steps` steps the joint moves at random, uniform in ±amplitude per step.
- The robot's model (MODEL_FAULTS), what a controller that assumes the model gets wrong:
  `reverse` (the motor turns the other way), `scale` (it moves `factor` × the command), `deadzone` (commands
  smaller than `degrees` move nothing), `offset` (the encoder reads q + `degrees`), `lag` (the encoder reads the
  angle of `steps` steps ago).
- `free`: the joint is whole again, whatever was wrong with it.

Faults compose per joint: a command passes the dead zone, then the motor's sign and gain; a locked joint holds
and a disturbed one moves at random whatever the model says.
"""

from __future__ import annotations

import dataclasses
import math
import zlib
from collections import deque
from collections.abc import Mapping

import numpy as np
from kinswarm.protocol.faults import DISTURB_AMPLITUDE_DEG, describe
from kinswarm.protocol.messages import Fault


@dataclasses.dataclass(frozen=True)
class Disturbance:
    left: int  # steps still to disturb
    amplitude: float  # radians
    detail: str  # the fault that started it, for the disturb_end event


@dataclasses.dataclass
class Model:
    """What is wrong with one joint's motor and encoder (the identity when nothing is)."""

    sign: float = 1.0  # -1: reversed
    gain: float = 1.0  # scale
    deadzone: float = 0.0  # radians
    offset: float = 0.0  # radians
    lag: int = 0  # steps
    seen: deque[float] = dataclasses.field(default_factory=deque)  # the true angles of the last lag + 1 steps

    def move(self, cmd: float) -> float:
        return 0.0 if abs(cmd) < self.deadzone else self.sign * self.gain * cmd

    def read(self, q: float) -> float:
        if self.lag:
            self.seen.append(q)
            while len(self.seen) > self.lag + 1:
                self.seen.popleft()
            q = self.seen[0]
        return q + self.offset

    def describe(self) -> str:
        parts = ["reversed"] if self.sign < 0 else []
        if self.gain != 1.0:
            parts.append(f"scaled x{self.gain:g}")
        if self.deadzone:
            parts.append(f"dead zone {math.degrees(self.deadzone):g} deg")
        if self.offset:
            parts.append(f"reads {math.degrees(self.offset):+g} deg")
        if self.lag:
            parts.append(f"reads {self.lag} steps late")
        return ", ".join(parts)


class JointFaults:
    """Every joint fault of one robot; the sim actor asks it what moves and what the encoders read."""

    def __init__(self, dof: list[str], seed: int) -> None:
        self.dof = dof
        self.locked: set[str] = set()
        self.disturbed: dict[str, Disturbance] = {}
        self.model: dict[str, Model] = {}
        # Its own stream, apart from the agents' [seed, crc32(id)]: disturbances replay with the seed.
        self.rng = np.random.default_rng([seed, zlib.crc32(b"sim-disturb")])

    @property
    def moves_changed(self) -> bool:
        """Whether any joint moves other than as commanded (else the commands go to the scene as they are)."""
        return bool(self.locked or self.disturbed or self.model)

    def apply(self, f: Fault, agent: str) -> None:
        """Apply one checked joint fault (protocol/faults.py check_fault) to one joint."""
        if f.fault == "lock":
            self.locked.add(agent)
        elif f.fault == "free":
            self.locked.discard(agent)
            self.disturbed.pop(agent, None)
            self.model.pop(agent, None)
        elif f.fault == "disturb":
            assert f.steps is not None  # check_fault: disturb needs steps
            amp = f.amplitude_deg if f.amplitude_deg is not None else DISTURB_AMPLITUDE_DEG
            self.disturbed[agent] = Disturbance(f.steps, math.radians(amp), describe(f))
        else:
            m = self.model.setdefault(agent, Model())
            if f.fault == "reverse":
                m.sign = -1.0
            elif f.fault == "scale":
                assert f.factor is not None
                m.gain = f.factor
            elif f.fault == "deadzone":
                assert f.degrees is not None
                m.deadzone = math.radians(f.degrees)
            elif f.fault == "offset":
                assert f.degrees is not None
                m.offset = math.radians(f.degrees)
            elif f.fault == "lag":
                assert f.steps is not None
                m.lag = f.steps
            else:
                raise ValueError(f"not a joint fault: {f.fault!r}")

    def increments(self, cmds: Mapping[str, float]) -> dict[str, float]:
        """The agents' commands as the faulty robot carries them out: locked joints hold, disturbed ones move at
        random, the others as their motor's model says."""
        d: dict[str, float] = {}
        for a, v in cmds.items():
            if a in self.locked or a in self.disturbed:
                continue
            m = self.model.get(a)
            d[a] = v if m is None else m.move(v)
        for a in self.dof:  # in DOF order: the draws, hence the run, replay with the seed
            if (dist := self.disturbed.get(a)) is not None:
                d[a] = float(self.rng.uniform(-dist.amplitude, dist.amplitude))
        return d

    def readings(self, q: dict[str, float]) -> dict[str, float]:
        """What each joint's encoder reads this step, given the true angles (`q` itself when every encoder reads
        true: no copy on the step's path). Call once per step."""
        if not any(m.offset or m.lag for m in self.model.values()):
            return q
        return {a: (m.read(v) if (m := self.model.get(a)) is not None else v) for a, v in q.items()}

    def reset(self) -> None:
        """The robot was put back to its start: an encoder's memory of the angles before means nothing now."""
        for m in self.model.values():
            m.seen.clear()

    def count_step(self) -> list[tuple[str, str]]:
        """A step ended: disturbances count down. Returns the (joint, fault) of each that ended."""
        ended = []
        for a in [a for a in self.dof if a in self.disturbed]:
            d = self.disturbed[a]
            if d.left > 1:
                self.disturbed[a] = dataclasses.replace(d, left=d.left - 1)
            else:
                del self.disturbed[a]
                ended.append((a, d.detail))
        return ended

    def summary(self) -> dict[str, str]:
        """One phrase per faulty joint, for `kinswarm status`."""
        out: dict[str, str] = {}
        for a in self.dof:
            parts = []
            if (d := self.disturbed.get(a)) is not None:
                parts.append(f"disturbed ({d.left} steps left)" + (", then locked" if a in self.locked else ""))
            elif a in self.locked:
                parts.append("locked")
            if (m := self.model.get(a)) is not None and (text := m.describe()):
                parts.append(text)
            if parts:
                out[a] = ", ".join(parts)
        return out
