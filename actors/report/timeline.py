"""A run's events as a timeline a plot can draw: how long each joint fault (or an agent's loss) lasts, and event
labels that never sit on top of each other. Read from `events.jsonl` rows alone (actors/report/__init__.py reads
them)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

# Joint faults that last until freed (or, for disturb, until it ends): drawn as spans, not as instants.
LASTING = {
    "lock": "locked",
    "disturb": "disturbed",
    "reverse": "reversed",
    "scale": "scaled",
    "deadzone": "dead zone",
    "offset": "reads offset",
    "lag": "reads late",
    "lost": "lost",  # the agent, not the joint: from its loss until it is back
}
ENDS = {"free": tuple(k for k in LASTING if k != "lost"), "disturb_end": ("disturb",), "handback": ("lost",),
        "alive": ("lost",)}  # fmt: skip


@dataclass(frozen=True)
class Span:
    """A joint fault from (epoch, step) to (epoch, step), the end excluded; None: to the end of the run."""

    target: str
    fault: str
    start: tuple[int, int]
    end: tuple[int, int] | None

    @property
    def label(self) -> str:
        return f"{self.target} {LASTING[self.fault]}"

    def within(self, epoch: int, steps: int) -> tuple[int, int] | None:
        """The steps [a, b) of `epoch` (of `steps` steps) this fault lasts over, or None."""
        if self.start[0] > epoch or (self.end is not None and self.end[0] < epoch):
            return None
        a = self.start[1] if self.start[0] == epoch else 0
        b = self.end[1] if self.end is not None and self.end[0] == epoch else steps
        return (a, b) if b > a else None


def _placed(ev: dict[str, Any]) -> bool:
    e, s = ev.get("epoch", -1), ev.get("step", -1)
    return isinstance(e, int) and isinstance(s, int) and e >= 0 and s >= 0


def fault_spans(events: Sequence[dict[str, Any]]) -> list[Span]:
    """Every lasting joint fault, from the event that began it to the one that ended it (a fault applied again
    while it lasts — a scenario's step-0 lock in every epoch — continues the same span)."""
    open_: dict[tuple[str, str], tuple[int, int]] = {}
    spans: list[Span] = []
    for ev in sorted((e for e in events if _placed(e)), key=lambda e: (e["epoch"], e["step"])):
        kind, target, at = str(ev.get("event")), str(ev.get("target")), (ev["epoch"], ev["step"])
        if kind in LASTING:
            open_.setdefault((target, kind), at)
        for ended in ENDS.get(kind, ()):
            if (start := open_.pop((target, ended), None)) is not None:
                spans.append(Span(target, ended, start, at))
    spans += [Span(t, k, start, None) for (t, k), start in open_.items()]
    return sorted(spans, key=lambda s: (s.start, s.target, s.fault))


def faulty_at(spans: Sequence[Span], epoch: int, steps: int, step: int) -> dict[str, str]:
    """Joint (or agent) -> what is wrong with it at `step` of `epoch` (of `steps` steps)."""
    return {s.target: LASTING[s.fault] for s in spans if (w := s.within(epoch, steps)) and w[0] <= step < w[1]}


def active_at_end(events: Sequence[dict[str, Any]]) -> dict[str, list[str]]:
    """Joint -> what is wrong with it when the run ended (the faults never freed)."""
    out: dict[str, list[str]] = {}
    for s in fault_spans(events):
        if s.end is None:
            out.setdefault(s.target, []).append(LASTING[s.fault])
    return out


def one_per_command(events: Sequence[dict[str, Any]], near: int = 25) -> list[dict[str, Any]]:
    """The events with each command once: a `fault` the supervisor recorded as it passed the request on is left out
    when what carried it out recorded it too (the sim's `lock a2`, a scenario's `scenario ... requested`, in the
    same epoch within `near` steps), so a plot draws one command as one line, at the step it took effect."""
    done: dict[tuple[int, str], list[tuple[int, str, str]]] = {}
    for ev in events:
        if ev.get("event") != "fault" and _placed(ev):
            done.setdefault((ev["epoch"], str(ev.get("event"))), []).append(
                (ev["step"], str(ev.get("target", "")), str(ev.get("detail", "")))
            )
    out = []
    for ev in events:
        if ev.get("event") == "fault" and _placed(ev):
            detail = str(ev.get("detail", ""))
            kind, targets = detail.split(" ")[0], set(str(ev.get("target", "")).split(","))
            applied = [t for s, t, _ in done.get((ev["epoch"], kind), []) if abs(s - ev["step"]) <= near]
            asked = [d for s, _, d in done.get((ev["epoch"], "scenario"), []) if abs(s - ev["step"]) <= near]
            if any("all" in targets or t in targets for t in applied) or any(
                detail.startswith(d.removesuffix(" requested")) for d in asked
            ):
                continue
        out.append(ev)
    return out


def label_groups(events: Sequence[dict[str, Any]], steps: int, share: float = 0.03) -> list[tuple[int, str]]:
    """One label per group of events less than `share` of the epoch's steps apart: (the first step, "lost a2 ·
    adopt a2"), so no two labels on an axis overlap. Same-kind events at a step are one: "lock a2,a3"."""
    at: dict[int, dict[str, list[str]]] = {}
    for ev in events:
        at.setdefault(ev["step"], {}).setdefault(str(ev.get("event", "?")), []).append(str(ev.get("target", "")))
    gap = max(1.0, share * steps)
    groups: list[tuple[int, list[str]]] = []
    for step in sorted(at):
        parts = [f"{k} {','.join(dict.fromkeys(t))}" for k, t in at[step].items()]
        if groups and step - groups[-1][0] < gap:
            groups[-1][1].extend(p for p in parts if p not in groups[-1][1])
        else:
            groups.append((step, parts))
    return [(step, " · ".join(parts)) for step, parts in groups]
