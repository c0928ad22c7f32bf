"""The supervisor's own parts: the restart policy, and a run that owns everything it starts — when `run()` returns,
no task, timer or actor it started is left."""

from __future__ import annotations

import asyncio

import pytest
from conftest import EXAMPLES, free_port, run_config
from kinswarm.actors.runtime import open_session
from kinswarm.actors.supervisor import SinglePlacement, Supervisor
from kinswarm.actors.supervisor.restarts import RestartBudgetSpent, RestartPolicy


def test_restart_policy_backs_off_and_gives_up_within_its_window():
    p = RestartPolicy(["a1", "a2"], max_restarts=3, window_s=60.0)
    assert [p.on_exit("a1", t) for t in (0.0, 1.0, 2.0)] == [0.1, 0.2, 0.4]
    with pytest.raises(
        RestartBudgetSpent, match=r"agent a1 exited 4 times within 60 s \(restart policy: at most 3\); giving up"
    ):
        p.on_exit("a1", 3.0)
    assert p.on_exit("a2", 0.0) == 0.1  # each agent its own budget
    assert p.on_exit("a1", 100.0) == 0.1  # the window has moved on: the old exits no longer count
    p.request("a2")  # a `restart` fault: at once, outside the budget
    assert p.on_exit("a2", 100.0) == 0.0 and p.on_exit("a2", 100.5) == 0.1  # (its exit at 0 is out of the window)
    assert p.totals == {"a1": 5, "a2": 3}
    long = RestartPolicy(["a"], 9, 60.0)
    assert [long.on_exit("a", float(t)) for t in range(7)] == [0.1, 0.2, 0.4, 0.8, 1.6, 2.0, 2.0]  # capped at 2 s


@pytest.mark.timeout(60)
def test_a_run_leaves_no_task_timer_or_actor_behind(tmp_path):
    """Structured: the supervisor's timers (status, restarts, thaws) and the actors' tasks all end with run()."""
    out = tmp_path / "r"
    out.mkdir()
    listen = f"tcp/127.0.0.1:{free_port()}"
    cfg = run_config(EXAMPLES / "chain4.toml", out=str(out), epochs=2, steps=30, placement="single", listen=listen)
    cfg.write(out / "config.json")

    async def main() -> tuple[set[asyncio.Task], Supervisor]:
        session = open_session(listen=[listen])
        try:
            placement = SinglePlacement(cfg, cfg.topo(), session)
            sup = Supervisor(cfg, cfg.topo(), session, placement)
            result = await sup.run()
            assert not result.error and len(result.epochs) == 2
            assert all(t.done() for t in placement.tasks.values())
            return asyncio.all_tasks() - {asyncio.current_task()}, sup  # type: ignore[operator]
        finally:
            session.close()

    left, sup = asyncio.run(main())
    assert left == set() and sup._timers == set()
    assert (out / "metrics.jsonl").read_text().count("\n") == 2 and (out / "events.jsonl").exists()


def test_a_stop_while_the_swarm_starts_stops_the_start() -> None:
    """`kinswarm down` before the first epoch: the readiness wait handles the mailbox through `_handle`, which once
    let a Stop go by (only the epochs' waits acted on it), so the run went on to train."""
    from kinswarm.actors.supervisor.core import Supervisor, _Down
    from kinswarm.protocol.keys import Keys
    from kinswarm.protocol.messages import Stop

    class Decoded:  # the mailbox's item, already decoded (the codec is tested on its own)
        def decode(self, key: str, payload: object, expect: type) -> object:
            return payload if isinstance(payload, expect) else None

    sup = Supervisor.__new__(Supervisor)
    sup.keys, sup.node = Keys("r"), Decoded()

    async def recv(timeout: float | None) -> tuple[str, object]:
        return sup.keys.ctl("stop"), Stop(reason="kinswarm down from h1")

    sup._recv = recv  # type: ignore[method-assign]
    sup.lead = True
    with pytest.raises(_Down, match="stop requested"):
        asyncio.run(sup._handle(1.0))
    sup.lead = False  # a follower's supervisor stops when its leader tells the actors, not on the request itself
    asyncio.run(sup._handle(1.0))
