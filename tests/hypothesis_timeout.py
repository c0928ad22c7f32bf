"""pytest-timeout for Hypothesis tests: a hung example ends its test.

pytest-timeout's signal method ends a test by raising pytest's own failure inside it. Hypothesis takes that for a
failing example and runs the example again to shrink it: a hung example hangs again, the timer has already fired, and
the test never ends (seen: a fuzzed command line that started a real experiment sat past a 40-minute limit). Here the
timer of a Hypothesis test raises TimedOut instead, which is no Exception, so Hypothesis lets it through (it catches
Exception, SystemExit, GeneratorExit and pytest's failure) and pytest reports the test failed and goes on to the
next. conftest.py imports the hook; other tests keep pytest-timeout's own handler."""

from __future__ import annotations

import signal
import threading
from types import FrameType
from typing import Any

import pytest


class TimedOut(BaseException):
    """A Hypothesis test ran past its pytest-timeout limit."""


@pytest.hookimpl(tryfirst=True)
def pytest_timeout_set_timer(item: pytest.Item, settings: Any) -> bool | None:
    if (
        settings.method != "signal"
        or not getattr(getattr(item, "obj", None), "is_hypothesis_test", False)
        or threading.current_thread() is not threading.main_thread()
    ):
        return None  # pytest-timeout's own timer

    def handler(signum: int, frame: FrameType | None) -> None:
        from pytest_timeout import dump_stacks

        dump_stacks(item.config.get_terminal_writer())  # where it hung, as pytest-timeout shows it
        raise TimedOut(f"Timeout (>{settings.timeout:g}s) in a Hypothesis test: it ends here, not shrunk")

    def cancel() -> None:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, signal.SIG_DFL)

    item.cancel_timeout = cancel  # type: ignore[attr-defined]  # pytest-timeout's cancel hook calls it
    signal.signal(signal.SIGALRM, handler)
    signal.setitimer(signal.ITIMER_REAL, settings.timeout)
    return True
