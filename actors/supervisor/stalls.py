"""A stall is a fault the supervisor sees (the leader, while an epoch runs): the lockstep makes no progress of its own
— the sim's step stops advancing (the sim is frozen, dead or cut off), or steps end only at the deadline without some
agents' commands (a frozen root holds its whole subtree) — for the run's stall bound. It is recorded with what is
missing and since when (events.jsonl "stall", and `kinswarm status`), its end too ("stall_end"); past the run's
stall limit the run ends with an error naming the actor. A partition is a pause, not a stall. Event-driven: judged
on each status of the sim, and by a timer re-armed by each (the sim's own silence)."""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

from kinswarm.protocol.messages import JointStatus

if TYPE_CHECKING:
    from .core import Supervisor

SIM_SILENT = "__sim_silent__"  # mailbox key: no status from the sim for the stall bound


class StallError(RuntimeError):
    pass


class StallWatch:
    def __init__(self, sup: Supervisor) -> None:
        self.sup = sup
        self.bound, self.limit = sup.cfg.stall_bound, sup.cfg.stall_limit_s
        self.step: tuple[int, int] | None = None
        self.progress_at = time.monotonic()
        self.late_since: dict[str, float] = {}  # agent -> when its commands stopped coming (as the sim saw it)
        self.since: float | None = None  # the stall's start, while stalled
        self.why = ""
        self._silence = None

    def arm(self) -> None:
        if self._silence is not None:
            self._silence.cancel()
        self._silence = self.sup.later(self.bound, SIM_SILENT)

    def epoch_started(self, now: float) -> None:
        """An epoch's start went out: the clock of a stall starts again from it."""
        self.progress_at = now

    def on_joints(self, j: JointStatus) -> None:
        now = time.monotonic()
        if (j.epoch, j.step) != self.step:
            self.step, self.progress_at = (j.epoch, j.step), now
        for a in list(self.late_since):
            if a not in j.late:
                del self.late_since[a]
        for a, n in j.late.items():  # n steps at the deadline: late since about n deadlines ago
            self.late_since.setdefault(a, now - n * self.sup.cfg.deadline_ms / 1000)
        self.arm()
        self.judge(now)

    def on_silent(self) -> None:
        waking = self.sup.waking
        if waking is not None and waking.just_woke():  # the supervisor itself did not run: not the sim's silence
            self.woke(time.monotonic())
            return
        self.judge(time.monotonic(), silent=True)

    def woke(self, now: float) -> None:
        """The supervisor woke from a stall of its own: the time it did not run is no one's lack of progress."""
        self.progress_at = max(self.progress_at, now)
        if self._silence is not None:
            self.arm()

    def judge(self, now: float, silent: bool = False) -> None:
        sup = self.sup
        if not sup.epochs.training or sup.epochs.running is None or sup.hosts.missing:
            self._end(now)  # between epochs, or paused: not a stall
            return
        stuck = sorted(a for a, t in self.late_since.items() if now - t >= self.bound)
        still = now - self.progress_at >= self.bound
        if not (stuck or still or silent):
            self._end(now)
            return
        why = self._why(now, stuck, still or silent)
        if self.since is None:
            self.since = min([self.progress_at if still or silent else now, *(self.late_since[a] for a in stuck)])
            self.why = why
            sup.event("stall", self._culprit(stuck), f"no progress for {now - self.since:.1f} s: {why}")
        self.why = why
        if now - self.since >= self.limit:
            raise StallError(f"stalled for {now - self.since:.0f} s (run.stall_limit_s {self.limit:g}): {why}")

    def _end(self, now: float) -> None:
        if self.since is not None:
            self.sup.event("stall_end", "swarm", f"progress again after {now - self.since:.1f} s ({self.why})")
            self.since, self.why = None, ""

    def _down(self) -> list[str]:
        """The agents that are down (token gone, frozen), root first: a stall's likeliest cause."""
        sup = self.sup
        return [a for a in sup.topo.order if ("agent", a) not in sup.alive or a in sup.faults.frozen]

    def _culprit(self, stuck: list[str]) -> str:
        down = self._down()
        return down[0] if down else stuck[0] if stuck else "sim"

    def _why(self, now: float, stuck: list[str], still: bool) -> str:
        parts = []
        down = self._down()
        if down:
            frozen = set(self.sup.faults.frozen)
            parts.append("down: " + ", ".join(f"{a} (frozen)" if a in frozen else a for a in down))
        if still:
            at = "" if self.step is None else f" (epoch {self.step[0]} step {self.step[1]})"
            parts.append(f"the sim's step has not advanced for {now - self.progress_at:.1f} s{at}")
        if stuck:
            since = max(now - self.late_since[a] for a in stuck)
            parts.append(f"steps end at the deadline without commands from {', '.join(stuck)} ({since:.1f} s)")
        return "; ".join(parts)

    def status(self, now: float) -> str:
        return "" if self.since is None else f"stalled {now - self.since:.1f} s: {self.why}"

    def stop(self) -> None:
        if self._silence is not None:
            self._silence.cancel()
