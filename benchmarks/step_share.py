"""Where the in-process floor's step goes: the learners' compiled kernel, the Python around it, the rest.

    python benchmarks/step_share.py [--epochs 4] [--steps 500] [--repeats 3]

Runs `floors.py`'s in-process loop (chain4's four learners and kinematics, no messages) with a timer around each
call of the compiled kernel (`kernels.decide`), of `Learner.decide` and `Learner.observe`, and of the kinematics'
walk, and measures numba's own cost of a call with the same arguments (a kernel that does nothing). What is left of
a kernel call after that is the learner's compute proper: the floor under any step shape, batched or not, that
keeps this learner. The timers add ~0.1 µs a call; the first epoch is counted, so rows are created as they are
when a swarm learns from scratch. Medians of the repeats, in microseconds.
"""

from __future__ import annotations

import argparse
import statistics
import time

import floors  # benchmarks/ is this script's directory, so first on sys.path
import numba
from kinswarm.actors.learning import kernels
from kinswarm.actors.learning.learner import Learner


@numba.njit
def _nothing(*args):  # noqa: ANN002, ANN202 - numba's call of the kernel's argument types, without the kernel
    return 0


def _timed(owner: object, name: str, label: str, acc: dict[str, list[float]], first: list | None = None) -> None:
    """Wrap owner.name so that each call adds its wall time (and 1 to its count) to acc[label]; the first call's
    arguments go to `first` when given."""
    inner = getattr(owner, name)
    total = acc.setdefault(label, [0.0, 0.0])

    def wrapper(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        if first is not None and not first:
            first.append(args)
        t = time.perf_counter()
        r = inner(*args, **kwargs)
        total[0] += time.perf_counter() - t
        total[1] += 1
        return r

    wrapper.signatures = getattr(inner, "signatures", None)  # type: ignore[attr-defined]  # Learner asks
    setattr(owner, name, wrapper)


def dispatch_cost(args: tuple, calls: int = 100_000) -> float:
    """Seconds a call of an njit function costs with these arguments when it computes nothing."""
    _nothing(*args)
    t = time.perf_counter()
    for _ in range(calls):
        _nothing(*args)
    return (time.perf_counter() - t) / calls


def one(epochs: int, steps: int) -> dict[str, float]:
    acc: dict[str, list[float]] = {}
    captured: list[tuple] = []
    originals = (kernels.decide, Learner.decide, Learner.observe, floors.kinematics._walk)
    try:
        _timed(kernels, "decide", "kernel", acc, captured)
        _timed(Learner, "decide", "decide", acc)
        _timed(Learner, "observe", "observe", acc)
        _timed(floors.kinematics, "_walk", "walk", acc)
        rate = floors.inprocess_rate(epochs, steps, seed=1)
    finally:
        kernels.decide, Learner.decide, Learner.observe, floors.kinematics._walk = originals
    n_steps = acc["walk"][1]  # one walk a step
    per_step = {label: 1e6 * seconds / n_steps for label, (seconds, _) in acc.items()}
    dispatch = 1e6 * dispatch_cost(captured[0]) * acc["kernel"][1] / n_steps
    return {
        "step (in-process floor)": 1e6 / rate,
        "four Learner.decide": per_step["decide"],
        "  their kernel calls": per_step["kernel"],
        "    numba's call": dispatch,
        "    compute proper": per_step["kernel"] - dispatch,
        "four Learner.observe": per_step["observe"],
        "kinematics walk": per_step["walk"],
        "kernel calls a decide": acc["kernel"][1] / acc["decide"][1],  # a count, printed apart from the times
    }


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--epochs", type=int, default=4)
    ap.add_argument("--steps", type=int, default=500)
    ap.add_argument("--repeats", type=int, default=3)
    a = ap.parse_args()
    floors.inprocess_rate(1, 1, seed=1)  # the kernel loaded from numba's cache (ms) before any timer is on
    runs = [one(a.epochs, a.steps) for _ in range(a.repeats)]
    print(f"chain4 in-process, {a.epochs} x {a.steps} steps, {a.repeats} repeats: µs per step (median)")
    calls = statistics.median(r.pop("kernel calls a decide") for r in runs)
    for name in runs[0]:
        print(f"{name:<28} {statistics.median(r[name] for r in runs):8.1f}")
    print(f"(kernel calls a decide: {calls:.2f}; a call again when memberships tie or phi grows)")


if __name__ == "__main__":
    main()
