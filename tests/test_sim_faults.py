"""Joint faults, liveliness-aware stepping and the EpochStart guard of the simulator actor.

Most tests drive the actor's handlers directly with a recording node (no sockets); the last one runs
it in a real Zenoh session against a tiny test controller."""

from __future__ import annotations

import asyncio
import math
import time
from pathlib import Path
from typing import Any

import pytest
from conftest import RecordingNode, fault_message, run_config
from kinswarm.actors.files.config import RunConfig
from kinswarm.actors.runtime import Node, open_session
from kinswarm.actors.simulator.actor import SimActor
from kinswarm.protocol.keys import Keys
from kinswarm.protocol.messages import (
    Bye,
    Cmd,
    EpochDone,
    EpochStart,
    Event,
    Fault,
    JointStatus,
    Stop,
    Task,
)

DEG = math.radians(1)
GOAL = (4.16, 6.18)


_made: list[SimActor] = []


@pytest.fixture(autouse=True)
def _close_worlds() -> Any:
    """Each PyBullet world (and its URDF temp dir) goes away with its test, even a failing one."""
    yield
    while _made:
        _made.pop().world.close()


def make_sim(tmp_path: Path, chain4: Path, *, seed: int = 0, scenario: str | None = None, **kw: Any) -> SimActor:
    cfg = run_config(
        chain4,
        run_id="t",
        out=str(tmp_path),
        seed=seed,
        scenario=scenario,
        deadline_ms=kw.pop("deadline_ms", 60_000),
        **kw,
    )
    _made.append(SimActor(cfg, cfg.topo(), RecordingNode()))  # type: ignore[arg-type]
    return _made[-1]


fault = fault_message


def step(sim: SimActor, delta: float = DEG, skip: tuple[str, ...] = ()) -> dict[str, float]:
    """Every waited-for agent but `skip` sends `delta`; returns the angles after the step."""
    e, t = sim.epoch, sim.t
    assert e is not None
    for a in sorted(sim.waiting - set(skip)):
        sim._on_cmd(a, Cmd(epoch=e.epoch, step=t, delta=delta))
    assert sim.t == t + 1 or sim.epoch is None, "the step advanced"
    return sim.world.joint_positions()


def events(sim: SimActor) -> list[tuple[str, str, int, int]]:
    return [(e.event, e.target, e.epoch, e.step) for e in sim.node.of(Event)]  # type: ignore[attr-defined]


def test_lock_free_disturb(tmp_path, chain4):
    async def body() -> None:
        sim = make_sim(tmp_path, chain4)
        q0 = sim.topo.initial_angles()
        sim._on_epoch(EpochStart(epoch=0, steps=50, goal=GOAL))
        sim.apply_fault(fault("lock", "a2"))
        for _ in range(5):
            q = step(sim)
        assert q["a2"] == q0["a2"], "a locked joint ignores its commands"
        assert q["a1"] == pytest.approx(q0["a1"] + 5 * DEG) and q["a4"] == pytest.approx(q0["a4"] + 5 * DEG)
        assert sim.faults.summary() == {"a2": "locked"}

        sim.apply_fault(fault("free", "a2"))
        q = step(sim)
        assert q["a2"] == pytest.approx(q0["a2"] + DEG)

        sim.apply_fault(fault("disturb", "a3", steps=3, amplitude_deg=2.0))
        assert sim.faults.summary() == {"a3": "disturbed (3 steps left)"}
        before = q["a3"]
        moves = []
        for _ in range(3):
            q = step(sim)
            moves.append(q["a3"] - before)
            before = q["a3"]
        assert all(abs(m) <= math.radians(2.0) + 1e-12 for m in moves)
        assert all(abs(m - DEG) > 1e-9 for m in moves), "a disturbed joint ignores its commands"
        assert len(set(moves)) == 3
        assert sim.faults.summary() == {}
        q2 = step(sim)
        assert q2["a3"] == pytest.approx(q["a3"] + DEG), "after the disturbance the joint obeys again"
        assert events(sim) == [
            ("lock", "a2", 0, 0),
            ("free", "a2", 0, 5),
            ("disturb", "a3", 0, 6),
            ("disturb_end", "a3", 0, 9),
        ]
        assert sim.node.of(Event)[2].detail == "disturb a3 steps=3 amplitude_deg=2"  # type: ignore[attr-defined]
        assert sim.applied["a3"] == pytest.approx(DEG)

    asyncio.run(body())


def test_a_fault_before_the_first_epoch_is_stamped_at_its_step_0(tmp_path, chain4):
    """A joint fault that reaches the sim before any epoch (sent while a resumed run comes up) acts from the first
    epoch's step 0, and its event says so: not epoch -1 (seen in the chaos hour: 25 such events after resumes)."""

    async def body() -> None:
        sim = make_sim(tmp_path, chain4, epochs=10)
        q0 = sim.topo.initial_angles()
        sim.apply_fault(fault("lock", "a2"))
        sim.apply_fault(fault("offset", "a3", degrees=2.0))
        assert events(sim) == []  # not yet: the epoch it acts in is not known
        sim._on_epoch(EpochStart(epoch=7, steps=50, goal=GOAL))  # a resumed run's first epoch
        q = step(sim)
        assert q["a2"] == q0["a2"], "locked from the first step"
        sim.apply_fault(fault("free", "a2"))
        assert events(sim) == [("lock", "a2", 7, 0), ("offset", "a3", 7, 0), ("free", "a2", 7, 1)]

    asyncio.run(body())


def test_disturbed_lock_stays_locked_at_new_angle_and_faults_persist_across_epochs(tmp_path, chain4):
    async def body() -> None:
        sim = make_sim(tmp_path, chain4)
        q0 = sim.topo.initial_angles()
        sim._on_epoch(EpochStart(epoch=0, steps=6, goal=GOAL))
        sim.apply_fault(fault("lock", "all"))
        assert sim.faults.locked == set(sim.dof)
        sim.apply_fault(fault("disturb", "a1", steps=2))  # default amplitude
        assert sim.faults.summary()["a1"] == "disturbed (2 steps left), then locked"
        step(sim)
        q = step(sim)
        assert q["a1"] != q0["a1"] and abs(q["a1"] - q0["a1"]) <= 2 * math.radians(2.0)
        for _ in range(4):
            q2 = step(sim)
        assert q2 == q, "locked again at the disturbed angle"
        assert sim.epoch is None
        done = sim.node.of(EpochDone)[0]  # type: ignore[attr-defined]
        assert done.final_angles == q

        sim._on_epoch(EpochStart(epoch=1, steps=3, goal=GOAL))
        assert sim.world.joint_positions() == q0, "the reset still puts every joint at its initial angle"
        step(sim)
        assert sim.world.joint_positions() == q0, "a broken joint stays broken"

    asyncio.run(body())


def test_model_faults_move_and_read_wrong_and_free_ends_them(tmp_path, chain4):
    """reverse, scale, deadzone (the motor) and offset, lag (the encoder): each as specified, composed per joint,
    listed in status and events, ended by `free`."""

    async def body() -> None:
        sim = make_sim(tmp_path, chain4)
        q0 = sim.topo.initial_angles()
        sim._on_epoch(EpochStart(epoch=0, steps=50, goal=GOAL))
        sim.apply_fault(fault("reverse", "a1"))
        sim.apply_fault(fault("scale", "a2", factor=3.0))
        sim.apply_fault(fault("deadzone", "a3", degrees=1.5))
        q = step(sim)
        assert q["a1"] == pytest.approx(q0["a1"] - DEG), "reversed: the motor turns the other way"
        assert q["a2"] == pytest.approx(q0["a2"] + 3 * DEG), "scaled: 3 x the command"
        assert q["a3"] == q0["a3"], "a 1 degree command is inside a 1.5 degree dead zone"
        assert q["a4"] == pytest.approx(q0["a4"] + DEG)
        sim.apply_fault(fault("scale", "a1", factor=0.5))  # composes with the reversal
        q1 = step(sim)
        assert q1["a1"] == pytest.approx(q["a1"] - 0.5 * DEG)
        assert sim.faults.summary() == {
            "a1": "reversed, scaled x0.5",
            "a2": "scaled x3",
            "a3": "dead zone 1.5 deg",
        }

        sim.apply_fault(fault("offset", "a4", degrees=-5.0))
        sim.apply_fault(fault("lag", "a2", steps=2))
        node: RecordingNode = sim.node  # type: ignore[assignment]
        seen: list[dict[str, float]] = []
        true: list[dict[str, float]] = []
        for _ in range(4):  # each step ends by publishing the next step's readings
            n = len(node.sent)
            true.append(step(sim))
            seen.append({k.rsplit("/", 1)[1]: m.q for k, m in node.sent[n:] if "/sim/obs/" in k})
        assert [r["a4"] for r in seen] == pytest.approx([t["a4"] - math.radians(5) for t in true]), "offset"
        assert seen[2]["a2"] == true[0]["a2"] and seen[3]["a2"] == true[1]["a2"], "lag: the angle of 2 steps ago"
        assert seen[0]["a2"] == true[0]["a2"], "lag from the fault on: no reading older than the fault"
        assert [r["a1"] for r in seen] == [t["a1"] for t in true], "other encoders read true"

        sim.apply_fault(fault("free", "all"))
        assert sim.faults.summary() == {} and not sim.faults.moves_changed
        q = sim.world.joint_positions()
        q2 = step(sim)
        assert all(q2[a] == pytest.approx(q[a] + DEG) for a in sim.dof), "free: the joints obey again"
        assert [e[:2] for e in events(sim)[:5]] == [
            ("reverse", "a1"),
            ("scale", "a2"),
            ("deadzone", "a3"),
            ("scale", "a1"),
            ("offset", "a4"),
        ]
        assert sim.node.of(Event)[1].detail == "scale a2 factor=3"  # type: ignore[attr-defined]

    asyncio.run(body())


def test_agents_are_not_told_of_model_faults(tmp_path, chain4):
    """What the agents receive (their encoder readings and the task) carries no trace of a motor fault: with a1
    reversed, a step's messages to the agents are exactly those of the intact robot in the same pose; the fault
    goes only to observers (metrics/event, metrics/joints)."""

    async def run(faulty: bool) -> list[tuple[str, Any]]:
        sim = make_sim(tmp_path, chain4)
        sim._on_epoch(EpochStart(epoch=0, steps=10, goal=GOAL))
        if faulty:
            sim.apply_fault(fault("reverse", "a1"))
            sim.apply_fault(fault("scale", "a2", factor=3.0))
        node: RecordingNode = sim.node  # type: ignore[assignment]
        n = len(node.sent)
        step(sim, delta=0.0)  # no move: the same pose either way
        return [(k, m) for k, m in node.sent[n:] if "/metrics/" not in k]

    intact, faulty = asyncio.run(run(False)), asyncio.run(run(True))
    assert intact == faulty and intact, "the agents' messages are the same"
    for _, m in faulty:
        assert "reverse" not in repr(m) and "scale" not in repr(m)


def test_bad_model_faults_are_refused_with_the_reason():
    from kinswarm.protocol.faults import check_fault

    cases = {
        "scale: needs factor": fault("scale", "a1"),
        "factor must be nonzero": fault("scale", "a1", factor=0.0),
        "deadzone: degrees must be in (0, 180]": fault("deadzone", "a1", degrees=-1.0),
        "offset: needs degrees": fault("offset", "a1"),
        "lag: needs steps": fault("lag", "a1"),
        "lag: steps must be at most 1000": fault("lag", "a1", steps=5000),
        "reverse: does not take factor": fault("reverse", "a1", factor=2.0),
        "scale: factor must be nonzero, at most 100 in size, got nan": fault("scale", "a1", factor=float("nan")),
    }
    for expected, f in cases.items():
        assert expected in check_fault(f), (expected, check_fault(f))
    assert check_fault(fault("offset", "a1", degrees=-5.0)) == ""


def test_disturbance_replays_with_the_seed(tmp_path, chain4):
    async def run(seed: int) -> list[float]:
        sim = make_sim(tmp_path, chain4, seed=seed)
        sim._on_epoch(EpochStart(epoch=0, steps=20, goal=GOAL))
        sim.apply_fault(fault("disturb", "a2", "a4", steps=10, amplitude_deg=5.0))
        for _ in range(10):
            q = step(sim)
        return [q["a2"], q["a4"]]

    a, b, c = (asyncio.run(run(s)) for s in (7, 7, 8))
    assert a == b and a != c


def test_other_faults_and_bad_faults_are_ignored(tmp_path, chain4):
    """Faults that are not the robot's pass it by unseen; a bad joint fault changes nothing and is a `refused` event
    with its reason."""

    async def body() -> None:
        sim = make_sim(tmp_path, chain4)
        sim.apply_fault(fault("kill", "a2"))
        sim.apply_fault(fault("drop", "a2", rate=0.5))
        assert not sim.node.sent  # type: ignore[attr-defined]
        sim.apply_fault(fault("lock", "zz"))  # not an agent
        sim.apply_fault(fault("disturb", "a1"))  # no steps
        assert not sim.faults.moves_changed
        assert not sim.node.sent  # type: ignore[attr-defined]  # before the first epoch: stamped at its step 0
        sim._on_epoch(EpochStart(epoch=0, steps=50, goal=GOAL))
        sent = [(m.event, m.target, m.detail, m.epoch, m.step) for m in sim.node.of(Event)]  # type: ignore[attr-defined]
        assert sent == [
            ("refused", "zz", "lock zz: lock: 'zz' is not an agent of this run (a1, a2, a3, a4)", 0, 0),
            ("refused", "a1", "disturb a1: disturb: needs steps", 0, 0),
        ]

    asyncio.run(body())


def test_scenario_applies_joint_faults_and_forwards_the_others(tmp_path, chain4):
    sc = tmp_path / "s.toml"
    sc.write_text(
        'name = "t"\n'
        '[[event]]\nstep = 2\nfault = "lock"\ntarget = "a1"\n'
        '[[event]]\nstep = 3\nepoch = 0\nfault = "kill"\ntarget = "a3"\n'
        '[[event]]\nstep = 4\nfault = "free"\ntarget = "all"\n'
    )

    async def body() -> None:
        sim = make_sim(tmp_path, chain4, scenario=str(sc))
        assert sim.keys.fault("request") in sim.outputs()
        for epoch in (0, 1):
            sim._on_epoch(EpochStart(epoch=epoch, steps=6, goal=GOAL))
            for _ in range(6):
                step(sim)
        node: RecordingNode = sim.node  # type: ignore[assignment]
        requests = [(k, m) for k, m in node.sent if isinstance(m, Fault)]
        assert [(k, m.id, m.fault, m.targets) for k, m in requests] == [
            (sim.keys.fault("request"), "scenario-0-3-1", "kill", ["a3"])
        ], "the kill is only in epoch 0, and goes to the supervisor"
        ev = events(sim)
        # the kill goes to the supervisor, and on the timeline at its exact step as what the scenario asked
        assert ev[:6] == [("lock", "a1", 0, 2), ("scenario", "a3", 0, 3), *(("free", a, 0, 4) for a in sim.dof)]
        assert ev[6] == ("lock", "a1", 1, 2), "an entry without an epoch repeats every epoch"
        q = sim.world.joint_positions()
        q0 = sim.topo.initial_angles()
        assert q["a1"] == pytest.approx(q0["a1"] + 4 * DEG)  # locked for steps 2 and 3 of 6

    asyncio.run(body())


def test_epoch_start_guard(tmp_path, chain4):
    async def body() -> None:
        sim = make_sim(tmp_path, chain4)
        node: RecordingNode = sim.node  # type: ignore[assignment]
        sim._on_epoch(EpochStart(epoch=0, steps=3, goal=GOAL))
        step(sim)
        q = sim.world.joint_positions()
        for replay in (0, 1):  # mid-run: neither a replay nor the next epoch resets the world
            sim._on_epoch(EpochStart(epoch=replay, steps=3, goal=(0.0, 0.0)))
            assert sim.t == 1 and sim.world.joint_positions() == q and sim.epoch.goal == GOAL  # type: ignore[union-attr]
        step(sim)
        step(sim)
        assert sim.epoch is None and len(node.of(EpochDone)) == 1
        sim._on_epoch(EpochStart(epoch=0, steps=3, goal=GOAL))
        sim._on_epoch(EpochStart(epoch=2, steps=3, goal=GOAL))
        sim._on_epoch(EpochStart(epoch=1, steps=0, goal=GOAL))
        assert sim.epoch is None
        sim._on_epoch(EpochStart(epoch=1, steps=3, goal=GOAL))
        assert sim.epoch is not None and sim.epoch.epoch == 1 and sim.t == 0
        # a resumed run's simulator starts at the epoch after its checkpoint, and from there only the next one follows
        resumed = make_sim(tmp_path, chain4)
        resumed._on_epoch(EpochStart(epoch=5, steps=1, goal=GOAL))
        assert resumed.epoch is not None and resumed.epoch.epoch == 5
        step(resumed)
        for wrong in (5, 7, 4):
            resumed._on_epoch(EpochStart(epoch=wrong, steps=1, goal=GOAL))
            assert resumed.epoch is None
        resumed._on_epoch(EpochStart(epoch=6, steps=1, goal=GOAL))
        assert resumed.epoch is not None and resumed.epoch.epoch == 6

    asyncio.run(body())


def test_liveliness_aware_stepping(tmp_path, chain4):
    async def body() -> None:
        sim = make_sim(tmp_path, chain4)
        sim._on_alive("a3", True)  # seen alive: changes nothing
        sim._on_epoch(EpochStart(epoch=0, steps=10, goal=GOAL))
        assert sim.waiting == set(sim.dof), "agents never seen stay expected"
        for a in ("a1", "a2", "a4"):
            sim._on_cmd(a, Cmd(epoch=0, step=0, delta=DEG))
        assert sim.t == 0
        sim._on_alive("a3", False)  # down mid-step: stop waiting for it
        assert sim.t == 1 and sim.down == {"a3"}
        assert sim.waiting == {"a1", "a2", "a4"}
        q = step(sim)
        assert q["a3"] == sim.topo.initial_angles()["a3"], "a down agent's joint holds"
        sim._on_alive("a3", True)  # back mid-step: waited for from the next step, not this one
        assert "a3" not in sim.waiting
        step(sim)
        assert sim.waiting == set(sim.dof)
        sim._on_alive("zz", False)  # not a joint: ignored
        assert sim.down == set()
        # every agent down: the deadline runs the step (nothing missed), the joints do not race
        for a in sim.dof:
            sim._on_alive(a, False)
        t = sim.t
        assert sim.t == t and not sim.waiting
        sim._on_deadline()
        assert sim.t == t + 1 and sim.missed == 0
        sim._on_alive("a1", True)
        sim._on_deadline()
        assert sim.missed == 0, "a1 came back mid-step: not missed in that step"
        sim._on_deadline()
        assert sim.missed == 1, "... but in the next"

    asyncio.run(body())


def test_status_reports_angles_increments_and_faults(tmp_path, chain4):
    async def body() -> None:
        sim = make_sim(tmp_path, chain4)
        sim._on_epoch(EpochStart(epoch=0, steps=10, goal=GOAL))
        sim.apply_fault(fault("lock", "a2"))
        step(sim)
        sim._on_status()
        sim._status.cancel()  # type: ignore[union-attr]
        (st,) = sim.node.of(JointStatus)  # type: ignore[attr-defined]
        assert (st.epoch, st.step) == (0, 1) and st.q == sim.world.joint_positions()
        assert st.delta["a2"] == 0.0 and st.delta["a1"] == pytest.approx(DEG)
        assert st.faults == {"a2": "locked"}

    asyncio.run(body())


# -- in a real Zenoh session ---------------------------------------------------------------------
class TestController:
    """Stands in for the agents: holds their liveliness tokens and sends +1 degree for each live one."""

    __test__ = False

    def __init__(self, session: Any, cfg: RunConfig) -> None:
        self.node = Node(session, Keys(cfg.run_id), "controller", "test", cfg.key)
        self.dof = cfg.topo().dof_agents
        k = self.node.keys
        for key in (k.task, k.obs("*"), k.metrics("*"), k.rep_all):
            self.node.listen(key)
        self.tokens = {a: session.liveliness().declare_token(k.alive("agent", a)) for a in self.dof}
        self.got: dict[type, list[Any]] = {}
        self.on_task: Any = None

    async def wait_for(self, kind: type, pred: Any = lambda m: True, timeout: float = 20.0) -> Any:
        """Read the mailbox until a message of `kind` satisfying `pred` has arrived (Tasks feed on_task)."""
        k = self.node.keys
        kinds = {
            k.task: Task,
            k.metrics("epoch"): EpochDone,
            k.metrics("event"): Event,
            k.metrics("joints"): JointStatus,
            k.rep("sim", "sim"): Bye,
        }
        deadline = time.monotonic() + timeout
        while not any(pred(m) for m in self.got.get(kind, [])):
            key, payload = await self.node.recv(timeout=deadline - time.monotonic())
            if key in kinds and (m := self.node.decode(key, payload, kinds[key])) is not None:
                self.got.setdefault(kinds[key], []).append(m)
                if isinstance(m, Task) and self.on_task is not None:
                    self.on_task(m)
        return next(m for m in self.got[kind] if pred(m))


@pytest.mark.timeout(60)
def test_sim_in_a_zenoh_session(tmp_path, chain4, endpoint):
    cfg = run_config(chain4, run_id="zt", out=str(tmp_path), steps=40, deadline_ms=5000)

    async def body() -> None:
        session = open_session(listen=[endpoint])
        sim_node = Node(session, Keys(cfg.run_id), "sim", "sim", cfg.key)
        ctl = TestController(session, cfg)
        sim = SimActor(cfg, cfg.topo(), sim_node)
        task = asyncio.create_task(sim.run())
        k = ctl.node.keys
        senders = set(ctl.dof)

        def on_task(t: Task) -> None:
            if t.step == 10:
                ctl.node.send(
                    k.ctl("fault"),
                    Fault(
                        id="live",
                        fault="lock",
                        targets=["a2"],
                        seconds=None,
                        steps=None,
                        rate=None,
                        ms=None,
                        amplitude_deg=None,
                    ),
                )
            if t.step == 20:  # a3 dies: no more cmds, and its token goes
                senders.discard("a3")
                ctl.tokens["a3"].undeclare()
                ctl.node.send(k.ctl("epoch"), EpochStart(epoch=0, steps=40, goal=(0.0, 0.0)))  # a replay
            for a in sorted(senders):
                ctl.node.send(k.cmd(a), Cmd(epoch=t.epoch, step=t.step, delta=DEG))

        ctl.on_task = on_task
        try:
            await ctl.node.wait_matched([k.ctl("epoch"), k.ctl("fault"), k.ctl("stop")], timeout=10)
            while sim_node._token is None:  # the sim is wired
                await asyncio.sleep(0.01)
            ctl.node.send(k.ctl("epoch"), EpochStart(epoch=0, steps=40, goal=GOAL))
            done = await ctl.wait_for(EpochDone)
            assert done.steps == 40 and len(done.errors) == 40
            # a3 went down: no step waited for it (a step that did would have ended by its deadline, a3 missed)
            assert done.missed_cmds == 0
            q0 = sim.topo.initial_angles()
            assert done.final_angles["a3"] == pytest.approx(q0["a3"] + 20 * DEG, abs=1.5 * DEG)
            assert done.final_angles["a1"] == pytest.approx(q0["a1"] + 40 * DEG)
            ev = await ctl.wait_for(Event)
            assert (ev.event, ev.target, ev.epoch) == ("lock", "a2", 0) and ev.detail == "lock a2"
            # a live fault lands when it arrives (sent at step 10; how many cmds overtake it depends on
            # delivery paths): a2 moved until the step the lock event names, and not after
            assert ev.step >= 10
            assert done.final_angles["a2"] == pytest.approx(q0["a2"] + ev.step * DEG, abs=1.5 * DEG)
            st = await ctl.wait_for(JointStatus, lambda s: s.step == 40)
            assert st.faults == {"a2": "locked"}
            # the replay never restarts the epoch: it lands while the epoch runs (ignored), or, on a loaded machine
            # whose loop reaches its mailbox only after the inline steps ran to the end, after it (the supervisor
            # asking again: the same EpochDone goes out again)
            assert all(d == done for d in ctl.got[EpochDone]), "the replayed EpochStart restarted the epoch"
            ctl.node.send(k.ctl("stop"), Stop(reason="test"))
            bye = await ctl.wait_for(Bye)
            assert bye.steps == 40 and bye.rejected == 0
            await asyncio.wait_for(task, 10)
        finally:
            task.cancel()
            await asyncio.gather(task, return_exceptions=True)
            for tok in ctl.tokens.values():
                try:
                    tok.undeclare()
                except Exception:
                    pass
            ctl.node.close()
            sim_node.close()
            session.close()

    asyncio.run(body())
