"""How a viewer goes away: `kinswarm view … --web` ends at Ctrl-C with one line (no `Exception ignored in:
RecordingStream.__del__` from the interpreter's exit), and `--view web`'s viewer, which ends with its run, says so.
No viewer is served here: a served one listens on fixed ports."""

from __future__ import annotations

import pytest
from kinswarm.actors.report import recording


class _Exit(Exception):
    def __init__(self, code: int) -> None:
        self.code = code


def test_ctrl_c_ends_the_served_viewer_at_once_with_one_line(monkeypatch, capsys):
    def interrupted(_: float) -> None:
        raise KeyboardInterrupt

    def exit_now(code: int) -> None:  # os._exit: the stream's own shutdown never runs with the interrupt
        raise _Exit(code)

    monkeypatch.setattr(recording.time, "sleep", interrupted)
    monkeypatch.setattr(recording.os, "_exit", exit_now)
    with pytest.raises(_Exit) as e:
        recording.serve_until_interrupted()
    assert e.value.code == 130
    out, err = capsys.readouterr()
    assert out == "kinswarm: serving; Ctrl-C to stop\n" and err == "kinswarm: the viewer stopped\n"


@pytest.mark.parametrize(("view", "said"), [("web", True), ("here", False), ("x.rrd", False)])
def test_the_live_web_viewer_says_it_goes_with_the_run(capsys, view, said):
    class Proc:
        def join(self, timeout: float | None = None) -> None:
            pass

        def is_alive(self) -> bool:
            return False

    class Queue:
        def put(self, item: object) -> None:
            assert item is None

    live = recording.LiveRecording.__new__(recording.LiveRecording)  # its recorder process stood in for
    live.view, live.out, live.queue, live.proc = view, "/runs/r1", Queue(), Proc()
    live.close()
    err = capsys.readouterr().err
    if said:
        assert err == recording.web_gone("/runs/r1") + "\n"
        assert err.count("\n") == 1 and "kinswarm view /runs/r1 --web" in err
    else:
        assert err == ""
