"""The grasp (paper §5.5): the object scene's validation, the contact model against hand-computed values, the net
wrench's signs, the reward variants (actors/tasks/grasp_reward.py), the grasp task's fingers."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
from conftest import run_config
from kinswarm.actors.files.runfile import task_of
from kinswarm.actors.learning.state import goal_along_motion
from kinswarm.actors.tasks.grasp_contacts import Contacts
from kinswarm.actors.tasks.grasp_planned import balance_targets, contact_goals, grip_forces
from kinswarm.actors.tasks.grasp_reward import GraspParams, GraspReward, balance_step, eq12
from kinswarm.protocol.robots import parse_robot
from kinswarm.protocol.scene import ObjectSpec, parse_scene
from kinswarm.protocol.spec import SpecError
from kinswarm.sim.scenes.contact import ContactModel, ContactReading, net_wrench

ROOT = Path(__file__).resolve().parent.parent
GRASP3 = ROOT / "examples" / "grasp3.toml"

HAND = parse_robot(
    {
        "name": "hand",
        "agent": [
            {"id": "hand", "compound": True},
            {"id": "f1", "parent": "hand", "link_length": 1.0},
            {"id": "f2", "parent": "hand", "link_length": 1.0},
        ],
    }
)
SCENE = """
kind = "object"
[object]
center = [0.0, 0.0]
half_extents = [1.0, 0.5]
mu = 0.5
kn = 10.0
kt = 4.0
cn = 2.0
ct = 1.0
max_depth = 0.2
[object.grasp]
f1 = [-1.0, 0.0]
f2 = [0.3, 0.5]
"""


def _parse(text: str):
    import tomllib

    return parse_scene(tomllib.loads(text), HAND, "scene.toml")


def test_grasp3_is_13_agents_around_a_compound_hand():
    cfg = run_config(GRASP3)
    t, obj = cfg.topo(), cfg.scene_spec.object
    assert len(t.agents) == 13 and len(t.dof_agents) == 12
    assert t.root == "hand" and t.agents["hand"].compound and not t.agents["hand"].has_dof
    assert t.end_effectors == ("f1_4", "f2_4", "f3_4")
    assert set(t.agents["hand"].children) == {"f1_1", "f2_1", "f3_1"}
    assert obj is not None and obj.mu == 0.5 and set(obj.grasp) == set(t.end_effectors)


def test_scene_parses():
    t = _parse(SCENE)
    assert t.object == ObjectSpec(
        center=(0.0, 0.0),
        half_extents=(1.0, 0.5),
        mu=0.5,
        kn=10.0,
        kt=4.0,
        cn=2.0,
        ct=1.0,
        max_depth=0.2,
        grasp={"f1": (-1.0, 0.0), "f2": (0.3, 0.5)},
    )
    assert t.object.contact == "link"  # the default: the fingertip link's whole capsule presses
    assert _parse(SCENE.replace("[object]\n", '[object]\ncontact = "tip"\n')).object.contact == "tip"


@pytest.mark.parametrize(
    ("change", "where", "what"),
    [
        (("[object]\n", "[object]\ncolour = 1\n"), "scene.object.colour", "unknown field"),
        (("[object]\n", '[object]\ncontact = "palm"\n'), "scene.object.contact", "must be one of link, tip"),
        (("mu = 0.5\n", ""), "scene.object.mu", "missing"),
        (("mu = 0.5\n", "mu = -0.1\n"), "scene.object.mu", ">= 0"),
        (("kn = 10.0\n", "kn = 0.0\n"), "scene.object.kn", "> 0"),
        (("max_depth = 0.2\n", "max_depth = 'deep'\n"), "scene.object.max_depth", "finite number"),
        (("half_extents = [1.0, 0.5]\n", "half_extents = [1.0, -0.5]\n"), "scene.object.half_extents", "> 0"),
        (("center = [0.0, 0.0]\n", "center = [0.0]\n"), "scene.object.center", "list of 2"),
        (("f2 = [0.3, 0.5]\n", "f2 = [0.3, 0.2]\n"), "scene.object.grasp.f2", "not on the object's boundary"),
        (("f2 = [0.3, 0.5]\n", "hand = [0.3, 0.5]\n"), "scene.object.grasp.hand", "not an end effector"),
        (("f2 = [0.3, 0.5]\n", ""), "scene.object.grasp", "no grasp point for end effector(s) f2"),
        (
            ("[object.grasp]\nf1 = [-1.0, 0.0]\nf2 = [0.3, 0.5]\n", "grasp = 3\n"),
            "scene.object.grasp",
            "must be a table",
        ),
    ],
)
def test_bad_object_names_file_field_and_fault(change, where, what):
    old, new = change
    assert old in SCENE
    with pytest.raises(SpecError) as e:
        _parse(SCENE.replace(old, new, 1))
    assert e.value.source == "scene.toml" and e.value.where == where and what in e.value.what, str(e.value)


def test_bad_object_file_error_names_the_file(tmp_path):
    p = tmp_path / "bad.toml"
    p.write_text(GRASP3.read_text().replace("mu = 0.5", "mu = true"))
    with pytest.raises(SpecError, match=r"bad\.toml: scene\.object\.mu: expected a finite number"):
        run_config(p)


SPEC = _parse(SCENE).object


def test_normal_spring_damper_and_tangential_spring_from_the_anchor():
    m = ContactModel(SPEC)
    # first contact on the right face (outward normal +x, tangent t = (0, 1)): d(depth)/dt from zero
    r = m.update("f", 0.1, (1.0, 0.0), (1.0, 0.0))
    assert r.contact and r.fn == pytest.approx(10 * 0.1 + 2 * 0.1) and r.ft == 0.0
    assert r.margin == pytest.approx(0.5 * 1.2) and r.force == pytest.approx((-1.2, 0.0))
    assert m.anchor("f") == (1.0, 0.0)
    # slides 0.05 along t at the same depth: ft = kt u + ct du/dt = 4 * 0.05 + 1 * 0.05
    r = m.update("f", 0.1, (1.0, 0.05), (1.0, 0.0))
    assert r.fn == pytest.approx(1.0) and r.ft == pytest.approx(0.25) and not r.slip
    assert r.margin == pytest.approx(0.5 - 0.25) and r.force == pytest.approx((-1.0, 0.25))


def test_coulomb_cap_slip_and_anchor_follows():
    m = ContactModel(SPEC)
    m.update("f", 0.1, (1.0, 0.0), (1.0, 0.0))
    m.update("f", 0.1, (1.0, 0.05), (1.0, 0.0))
    r = m.update("f", 0.1, (1.0, 0.3), (1.0, 0.0))  # u = 0.3, du = 0.25: trial 1.45 > mu fn = 0.5
    assert r.ft_trial == pytest.approx(4 * 0.3 + 0.25) and r.ft == pytest.approx(0.5)
    assert r.margin == pytest.approx(0.5 - 1.45) and r.slip
    assert m.anchor("f") == pytest.approx((1.0, 0.3 - 0.5 / 4))  # the spring now holds exactly the cap
    r = m.update("f", 0.1, (1.0, 0.3), (1.0, 0.0))  # standing still: at the cone's edge, no more slip
    assert r.ft == pytest.approx(0.5) and r.margin == pytest.approx(0.0, abs=1e-12) and not r.slip
    r = m.update("f", 0.0, None, None)  # contact lost: anchor dropped
    assert not r.contact and r.fn == 0.0 and m.anchor("f") is None
    r = m.update("f", 0.05, (1.0, 0.8), (1.0, 0.0))  # a new contact anchors where it begins
    assert m.anchor("f") == (1.0, 0.8) and r.ft == 0.0


def test_no_adhesion_when_retracting_fast():
    m = ContactModel(SPEC)
    m.update("f", 0.2, (1.0, 0.0), (1.0, 0.0))
    r = m.update("f", 0.01, (1.0, 0.0), (1.0, 0.0))  # kn 0.01 + cn (-0.19) < 0: clipped to 0
    assert r.contact and r.fn == 0.0


def _reading(point, normal, fn, ft=0.0):
    nx, ny = normal
    return ContactReading(
        True, 0.1, fn, ft, ft, 0.5 * fn - abs(ft), point, normal, (-fn * nx - ft * ny, -fn * ny + ft * nx)
    )


def test_net_wrench_signs():
    # pushing left (-x) at the top right corner turns the object counter-clockwise: tau > 0
    fx, fy, tau = net_wrench({"a": _reading((1.0, 0.5), (1.0, 0.0), 2.0)}, (0.0, 0.0))
    assert (fx, fy) == pytest.approx((-2.0, 0.0)) and tau == pytest.approx(+1.0)
    # pushing up (+y) on the bottom face right of centre: counter-clockwise too; about a shifted centre
    fx, fy, tau = net_wrench({"b": _reading((0.5, -0.5), (0.0, -1.0), 1.0)}, (0.0, 0.0))
    assert (fx, fy) == pytest.approx((0.0, 1.0)) and tau == pytest.approx(0.5)
    fx, fy, tau = net_wrench({"b": _reading((0.5, -0.5), (0.0, -1.0), 1.0)}, (1.0, 0.0))
    assert tau == pytest.approx(-0.5)
    # the tangential force: on the right face t = (0, 1); ft > 0 drags the object up
    _, fy, tau = net_wrench({"c": _reading((1.0, 0.0), (1.0, 0.0), 1.0, ft=0.25)}, (0.0, 0.0))
    assert fy == pytest.approx(0.25) and tau == pytest.approx(0.25)
    # the grasp3 balance: fn 2 on the left, 1 and 1 at y = +-0.35 on the right: zero net wrench
    r = {
        "a": _reading((-1.0, 0.0), (-1.0, 0.0), 2.0),
        "b": _reading((1.0, 0.35), (1.0, 0.0), 1.0),
        "c": _reading((1.0, -0.35), (1.0, 0.0), 1.0),
    }
    assert net_wrench(r, (0.0, 0.0)) == pytest.approx((0.0, 0.0, 0.0))


TIPS = ("a", "b", "c")
GRASP = {"a": (-1.0, 0.0), "b": (1.0, 0.35), "c": (1.0, -0.35)}


def _sense(fn: dict, ft: dict | None = None, net=(0.0, 0.0, 0.0), margin: dict | None = None) -> dict:
    s = {"net_fx": net[0], "net_fy": net[1], "net_torque": net[2]}
    for t in TIPS:
        touch = fn.get(t) is not None
        s[f"contact/{t}"] = 1.0 if touch else 0.0
        s[f"fn/{t}"] = fn.get(t) or 0.0
        s[f"ft/{t}"] = (ft or {}).get(t, 0.0)
        s[f"margin/{t}"] = (margin or {}).get(t, 0.0)
        if touch:
            s[f"px/{t}"], s[f"py/{t}"] = GRASP[t]
            s[f"nx/{t}"], s[f"ny/{t}"] = (-1.0, 0.0) if t == "a" else (1.0, 0.0)
    return s


def test_eq12_as_printed_pays_most_for_not_touching():
    p = GraspParams()
    none = Contacts.from_sense(_sense({}), TIPS)
    # inside D_min, approaching, no contact: e^(-c D) + R_f + R_tau + R_s = e^-0.2 + 3
    assert eq12(0.2, 0.3, none, p) == pytest.approx(math.exp(-0.2) + 3.0)
    # an unbalanced grasp with all three touching scores less
    touching = Contacts.from_sense(_sense({"a": 1.0, "b": 1.0, "c": 1.0}, net=(-1.0, 0.0, 0.0)), TIPS)
    assert eq12(0.2, 0.3, touching, p) == pytest.approx(math.exp(-0.2) + math.exp(-1.0) + 2.0)
    # outside D_min: -2 + the R_i; moving away inside it: -1 + the R_i
    assert eq12(0.8, 0.7, none, p) == pytest.approx(-2.0 + 3.0)
    assert eq12(0.2, 0.1, none, p) == pytest.approx(-1.0 + 3.0)
    # slip: R_s = e^(-c FC), FC = the summed cone violation
    slip = Contacts.from_sense(_sense({"a": 1.0, "b": 1.0, "c": 1.0}, margin={"a": -0.3, "b": 0.2}), TIPS)
    assert eq12(0.2, 0.3, slip, p) == pytest.approx(math.exp(-0.2) + 2.0 + math.exp(-0.3))
    # the contact variant pays the R_i only while all three touch
    assert eq12(0.2, 0.3, none, p, only_with_contact=True) == pytest.approx(math.exp(-0.2))
    assert eq12(0.2, 0.3, touching, p, only_with_contact=True) == pytest.approx(eq12(0.2, 0.3, touching, p))


def test_balance_targets():
    normals = {"a": (-1.0, 0.0), "b": (1.0, 0.0), "c": (1.0, 0.0)}
    balanced = Contacts.from_sense(_sense({"a": 2.0, "b": 1.0, "c": 1.0}), TIPS)
    assert balance_targets(balanced, GRASP, normals, (0.0, 0.0), 1.0) == pytest.approx({"a": 2, "b": 1, "c": 1})
    # equal forces are not balanced: the nearest balanced ones, with the least at f_grip, are 2 : 1 : 1
    equal = Contacts.from_sense(_sense({"a": 1.0, "b": 1.0, "c": 1.0}), TIPS)
    x = balance_targets(equal, GRASP, normals, (0.0, 0.0), 1.0)
    assert x["a"] == pytest.approx(2 * x["b"]) and x["b"] == pytest.approx(x["c"]) and min(x.values()) >= 1.0 - 1e-9
    # nobody touches: the grip, 2 : 1 : 1 at the least force f_grip
    none = Contacts.from_sense(_sense({}), TIPS)
    assert balance_targets(none, GRASP, normals, (0.0, 0.0), 1.5) == pytest.approx({"a": 3.0, "b": 1.5, "c": 1.5})


def test_reward_modes():
    tips0 = {"a": (-1.5, 0.0, 0.0), "b": (1.5, 0.35, 0.0), "c": (1.5, -0.35, 0.0)}
    tips1 = {"a": (-1.4, 0.0, 0.0), "b": (1.5, 0.35, 0.0), "c": (1.5, -0.35, 0.0)}
    out: dict = {}
    for mode in ("paper", "contact", "global", "force"):
        g = GraspReward(mode, GRASP, (0.0, 0.0), (1.0, 0.5))
        first, ctx = g.step(tips0, _sense({}))
        assert first is None and {t: c["force_error"] for t, c in ctx.items()} == pytest.approx(
            {"a": -2.0, "b": -1.0, "c": -1.0}
        )  # e / f_grip
        assert g.goals == GRASP  # every mode but shaped: the goals are the grasp points
        out[mode], _ = g.step(tips1, _sense({}))
    D0, D1 = 0.5, (0.4 + 0.5 + 0.5) / 3
    assert out["paper"] == pytest.approx(dict.fromkeys(TIPS, math.exp(-D1) + 3.0))  # D <= D_min, approaching
    assert D1 < D0 and out["contact"] == pytest.approx(dict.fromkeys(TIPS, math.exp(-D1)))
    # force: per finger, out of contact the chain's -2 + k (D_i(t-1) - D_i(t)); a moved closer by 0.1
    assert out["force"] == pytest.approx({"a": -2.0 + 20 * 0.1, "b": -2.0, "c": -2.0})
    assert out["global"] == pytest.approx(dict.fromkeys(TIPS, (0.0 - 2.0 - 2.0) / 3))


def test_force_reward_in_contact_credits_a_fingers_own_move():
    g = GraspReward("force", GRASP, (0.0, 0.0), (1.0, 0.5))
    tips = {t: (*GRASP[t], 0.0) for t in TIPS}
    g.step(tips, _sense({"a": 1.0, "b": 1.0, "c": 1.0}, net=(-1.0, 0.0, 0.0)))
    target = g._target
    assert target is not None
    # a pushes harder, towards its target: rewarded; b, c did not move: their error is unchanged
    r, ctx = g.step(tips, _sense({"a": 2.0, "b": 1.0, "c": 1.0}, net=(-0.5, 0.0, 0.0)))
    assert r is not None
    e_a0, e_a1, f = 1.0 - target["a"], 2.0 - target["a"], g.p.f_grip
    assert r["a"] == pytest.approx(-min(1.0, abs(e_a1) / f) + g.p.k_f * (abs(e_a0) - abs(e_a1)) / f)
    assert r["a"] > r["b"]
    # a finger that slips pays 1 more
    r2, _ = g.step(tips, _sense({"a": 2.0, "b": 1.0, "c": 1.0}, margin={"b": -0.1}, net=(-0.5, 0.0, 0.0)))
    r3, _ = GraspReward("force", GRASP, (0.0, 0.0), (1.0, 0.5)).step(tips, _sense({"a": 2.0, "b": 1.0, "c": 1.0}))
    assert r2 is not None and r3 is None and r2["b"] < r2["c"] - 0.99


def test_reward_names_fit_the_task():
    assert run_config(GRASP3, ['task.reward="contact"']).task["reward"] == "contact"
    with pytest.raises(
        SpecError, match="task.reward: 'strict' is not one of shaped, sensed, paper, contact, global, force"
    ):
        run_config(GRASP3, ['task.reward="strict"'])
    with pytest.raises(SpecError, match="task.reward: 'contact' is not one of shaped, paper, strict"):
        run_config(ROOT / "examples" / "chain4.toml", ['task.reward="contact"'])
    with pytest.raises(ValueError, match="unknown grasp reward"):
        GraspReward("strict", GRASP, (0.0, 0.0), (1.0, 0.5))


def test_state_of_the_finger_agents():
    """Every finger agent: S_i on one finger's scale plus g_perp (7 fine sets over +-0.05), computed from its own
    geometry; fine steps (fine_action, 0.1 by default) while the grasp agent says "fine"."""
    task = task_of(run_config(GRASP3))
    st = task.learner("f2_3", {})
    assert st.state_names[-1] == "g_perp" and st.state_ranges[-1] == (-0.05, 0.05) and st.state_sets[-1] == 7
    assert st.state_ranges[2] == (0.0, pytest.approx(3.2)) and len(st.state_sets) == 7
    finger = task.agent("f2_3", st)
    from kinswarm.actors.tasks.base import StepView

    view = StepView(0, 1, (0.0, 0.0, 0.0), (0.8, 0.0, 0.0), (2.0, 0.0), (2.0, 0.5), {"fine": 1.0}, {}, None)
    assert finger.state(view) == [goal_along_motion(view.frame, view.tip, view.goal)]
    assert finger.scale(view) == 0.1 and finger.scale(StepView(**{**view.__dict__, "sense": {}})) == 1.0
    assert task_of(run_config(GRASP3, ["task.fine_action=1.0"])).agent("f2_3", st).scale(view) == 1.0
    with pytest.raises(SpecError, match="task.fine_action: must be in"):
        run_config(GRASP3, ["task.fine_action=0.0"])
    with pytest.raises(SpecError, match="task.grasp_state: unknown field"):
        run_config(GRASP3, ['task.grasp_state="force"'])
    # collision_state: + "collided" (its own move refused by the object), with the penalty and the tabu
    on = ["task.collision_state=true", "task.collision_penalty=-1.0", "task.collision_tabu=true"]
    task = task_of(run_config(GRASP3, on))
    st = task.learner("f2_3", {})
    assert tuple(st.state_names[-2:]) == ("g_perp", "collided") and st.state_sets[-1] == 2
    finger = task.agent("f2_3", st)
    hit = StepView(**{**view.__dict__, "sense": {"collided": 1.0}, "last_action": 2})
    assert finger.state(hit)[-1] == 1.0 and finger.reward(hit, 0.5) == -0.5 and finger.avoid(hit) == [2]
    assert finger.reward(view, 0.5) == 0.5 and finger.avoid(view) == []
    with pytest.raises(SpecError, match="task.collision_penalty: must be <= 0"):
        run_config(GRASP3, ["task.collision_penalty=1.0"])


def _wrench_of(fn: dict, ft: dict, points: dict, normals: dict) -> tuple[float, float, float]:
    return net_wrench({t: _reading(points[t], normals[t], fn[t], ft[t]) for t in fn}, (0.0, 0.0))


def test_grip_forces_balance_with_the_least_grip():
    normals = {"a": (-1.0, 0.0), "b": (1.0, 0.0), "c": (1.0, 0.0)}
    fn0 = {"a": 4.0, "b": 2.0, "c": 2.0}
    # at the grasp points the planned grip is already balanced: no tangential force needed
    fn, ft = grip_forces(GRASP, normals, (0.0, 0.0), fn0, 2.0)
    assert fn == pytest.approx(fn0) and ft == pytest.approx(dict.fromkeys(TIPS, 0.0), abs=1e-9)
    # off the grasp points, with finger a below both others: no normal forces alone can cancel the torque
    # (fn_b (y_b - y_a) + fn_c (y_c - y_a) > 0); friction does, inside the cones, the least normal force f_grip
    off = {"a": (-1.0, -0.39), "b": (1.0, 0.46), "c": (1.0, -0.36)}
    fn, ft = grip_forces(off, normals, (0.0, 0.0), fn0, 2.0)
    assert _wrench_of(fn, ft, off, normals) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)
    assert min(fn.values()) == pytest.approx(2.0) and all(abs(ft[t]) < 0.5 * fn[t] for t in TIPS)
    # a grip below f_grip is scaled up (it stays balanced)
    fn, ft = grip_forces(off, normals, (0.0, 0.0), {"a": 1.0, "b": 0.5, "c": 0.5}, 3.0)
    assert min(fn.values()) == pytest.approx(3.0)
    assert _wrench_of(fn, ft, off, normals) == pytest.approx((0.0, 0.0, 0.0), abs=1e-9)


def _contact_sense(touch: dict, anchor: dict, depth: dict, normals: dict) -> dict:
    s = _sense(dict.fromkeys(touch, 1.0))
    for t, p in touch.items():
        s[f"px/{t}"], s[f"py/{t}"] = p
        s[f"nx/{t}"], s[f"ny/{t}"] = normals[t]
        s[f"ax/{t}"], s[f"ay/{t}"] = anchor[t]
        s[f"depth/{t}"] = depth[t]
    return s


def test_contact_goals_by_hand():
    faces = {"a": (-1.0, 0.0), "b": (1.0, 0.0), "c": (1.0, 0.0)}
    tips = {"a": (-0.95, 0.12), "b": (1.02, 0.35), "c": (1.6, -0.35)}
    # a touches off its grasp point, 0.15 deep, its spring stretched 0.05 from the anchor; b on the top face
    sense = _contact_sense(
        {"a": (-1.0, 0.1), "b": (0.9, 0.5)}, {"a": (-1.0, 0.05), "b": (0.9, 0.5)}, {"a": 0.15, "b": 0.1},
        {"a": (-1.0, 0.0), "b": (0.0, 1.0)},
    )  # fmt: skip
    obs = Contacts.from_sense(sense, TIPS)
    goals, fn, ft = contact_goals(obs, GRASP, faces, (0.0, 0.0), 2.0, 10.0, 4.0, tips)
    # the forces: balanced at a's contact point and b's and c's grasp points (b is on the wrong face)
    points = {"a": (-1.0, 0.1), "b": GRASP["b"], "c": GRASP["c"]}
    fn_want, ft_want = grip_forces(points, faces, (0.0, 0.0), {"a": 4.0, "b": 2.0, "c": 2.0}, 2.0)
    assert fn == pytest.approx(fn_want) and ft == pytest.approx(ft_want) and abs(ft["a"]) > 0.01
    # a: t = (-n_y, n_x) = (0, -1), u = (p - anchor) . t = -0.05; goal = tip + n (depth - fn/kn) + (ft/kt - u) t
    dn, du = 0.15 - fn["a"] / 10.0, ft["a"] / 4.0 + 0.05
    assert goals["a"] == pytest.approx((-0.95 - dn, 0.12 - du))
    # b touches the wrong face, c does not touch: both are sent to their grasp points
    assert goals["b"] == GRASP["b"] and goals["c"] == GRASP["c"]


def test_goal_along_motion():
    # joint at the origin, tip at (1, 0): increasing the angle moves the tip towards +y
    assert goal_along_motion((0.0, 0.0, 0.3), (1.0, 0.0), (1.0, 0.1)) == pytest.approx(0.1)
    assert goal_along_motion((0.0, 0.0, 0.3), (1.0, 0.0), (1.2, -0.1)) == pytest.approx(-0.1)
    assert goal_along_motion((1.0, 1.0, 0.0), (1.0, 3.0), (0.5, 3.0)) == pytest.approx(0.5)
    assert goal_along_motion((1.0, 1.0, 0.0), (1.0, 1.0), (0.5, 3.0)) == 0.0


def test_shaped_reward_reaches_for_the_contact_goals_with_fine_steps():
    g = GraspReward("shaped", GRASP, (0.0, 0.0), (1.0, 0.5), fine_action=0.1)
    p = g.p
    tips0 = {"a": (-1.5, 0.0), "b": (1.03, 0.35), "c": (1.5, -0.35)}
    r, ctx = g.step(tips0, _sense({}))
    assert r is None and g.goals == GRASP  # nobody touches: the goals are the grasp points
    assert {t: c["fine"] for t, c in ctx.items()} == {"a": 0.0, "b": 1.0, "c": 0.0}  # b within D_fine
    tips1 = {"a": (-1.4, 0.0), "b": (1.02, 0.35), "c": (1.5, -0.35)}
    r, _ = g.step(tips1, _sense({}))
    assert r is not None
    # -min(1, D/D_tol) + k (D(t-1) - D(t)) / a; b moved with fine steps: its progress counts 1/0.1 times
    assert r["a"] == pytest.approx(-1.0 + p.k * 0.1)
    assert r["b"] == pytest.approx(-0.02 / p.D_tol + p.k * 0.01 / 0.1)
    assert r["c"] == pytest.approx(-1.0)
    # holding a reached goal costs nothing, holding 0.02 short of it costs, moving away from it costs more
    g.step({**tips1, "b": GRASP["b"]}, _sense({}))
    r_held, _ = g.step({**tips1, "b": GRASP["b"]}, _sense({}))
    r_short, _ = g.step({**tips1, "b": (1.02, 0.35)}, _sense({}))
    r_away, _ = g.step({**tips1, "b": (1.03, 0.35)}, _sense({}))
    assert r_held is not None and r_short is not None and r_away is not None
    assert r_held["b"] == pytest.approx(0.0) and r_held["b"] > r_away["b"]
    assert r_away["b"] == pytest.approx(-0.03 / p.D_tol - p.k * 0.01 / 0.1)


def _ik(world, fingers, q: dict, leaf: str, target, heading: float | None = None, iters: int = 100) -> dict:
    """Damped least-squares IK of one finger's tip (and its heading, if given), by finite differences on
    the real PyBullet world."""
    import numpy as np

    def pose(qq: dict) -> np.ndarray:
        world.reset(qq)
        x, y, h = world.tip_poses()[leaf]
        return np.array([x, y] if heading is None else [x, y, h])

    want = np.array(list(target) + ([] if heading is None else [heading]))
    chain = fingers[leaf]
    for _ in range(iters):
        p = pose(q)
        e = want - p
        if heading is not None:
            e[2] = (e[2] + math.pi) % (2 * math.pi) - math.pi
        if np.linalg.norm(e) < 1e-6:
            break
        J = np.zeros((len(e), len(chain)))
        for j, a in enumerate(chain):
            d = pose({**q, a: q[a] + 1e-6}) - p
            if heading is not None:
                d[2] = (d[2] + math.pi) % (2 * math.pi) - math.pi
            J[:, j] = d / 1e-6
        dq = J.T @ np.linalg.solve(J @ J.T + 1e-6 * np.eye(len(e)), e)
        q = {**q, **{a: q[a] + float(dq[j]) for j, a in enumerate(chain)}}
    world.reset(q)
    return q


@pytest.mark.parametrize("contact", ["link", "tip"])
def test_fingertips_at_their_contact_goals_balance_the_real_object(contact):
    """The goals agree with the simulated contacts: three tips touching off their grasp points, in the real
    PyBullet scene, moved to the goals the grasp agent computes, leave the object balanced."""
    import dataclasses

    from kinswarm.actors.report.grasp import BALANCE
    from kinswarm.sim.scenes.contact import GraspScene
    from kinswarm.sim.world import World

    cfg = run_config(GRASP3)
    topo = cfg.topo()
    obj = dataclasses.replace(cfg.scene_spec.object, contact=contact)
    world = World(topo)
    try:
        scene = GraspScene(world, obj)
        q = world.joint_positions()
        start = {"f1_4": (-0.97, -0.2), "f2_4": (1.02, 0.45), "f3_4": (0.97, -0.3)}  # touching, unbalanced
        for leaf, (x, y) in start.items():
            q = _ik(world, scene.fingers, q, leaf, (x + (-0.5 if x < 0 else 0.5), y))
        scene.reset()
        for leaf, t in start.items():
            q = _ik(world, scene.fingers, q, leaf, t)
        g = GraspReward("shaped", obj.grasp, obj.center, obj.half_extents, kn=obj.kn, kt=obj.kt)
        before = []
        for _ in range(3):
            scene.sense_contacts()
            scene.sense_contacts()  # at rest: no damper force
            before.append(math.hypot(*scene.wrench[:2]))
            g.step(world.tip_poses(), scene.task_sense())
            for leaf, goal in g.goals.items():
                q = _ik(world, scene.fingers, q, leaf, goal)
        scene.sense_contacts()
        scene.sense_contacts()
        r = scene.readings
        mean_fn = sum(x.fn for x in r.values()) / 3
        F, tau = math.hypot(*scene.wrench[:2]), abs(scene.wrench[2])
        assert all(x.contact and x.margin >= 0.0 for x in r.values())
        assert before[0] > 1.0, before  # it started unbalanced
        assert F < BALANCE * mean_fn and tau < BALANCE * mean_fn * obj.char_length, (F, tau, mean_fn)
    finally:
        world.close()


def test_a_finger_not_in_front_of_its_face_goes_to_the_pre_grasp_point():
    g = GraspReward("shaped", GRASP, (0.0, 0.0), (1.0, 0.5))
    out = g.p.approach
    # a below the object (not in front of the left face), b beside its face, c pressing the bottom face
    tips = {"a": (-0.8, -0.9), "b": (1.4, 0.3), "c": (0.9, -0.55)}
    sense = _contact_sense({"c": (0.9, -0.5)}, {"c": (0.9, -0.5)}, {"c": 0.05}, {"c": (0.0, -1.0)})
    g.step(tips, sense)
    assert g.goals["a"] == pytest.approx((-1.0 - out, 0.0)) and g.goals["b"] == GRASP["b"]
    assert g.goals["c"] == pytest.approx((1.0 + out, -0.35))  # wrong face, below its own: out and round
    g.step({**tips, "a": (-1.3, 0.2)}, _sense({}))  # now in front of its face: straight to the grasp point
    assert g.goals["a"] == GRASP["a"]


def test_tip_contact_is_the_fingertip_sphere_only():
    """contact = "tip": only a sphere of the capsule's radius at the fingertip presses (depth = r - its
    distance to the face); "link": the fingertip link's whole capsule. A distal link lying along the face
    with its tip sticking out touches in "link" mode only."""
    import dataclasses

    from kinswarm.sim.scenes.contact import GraspScene
    from kinswarm.sim.world import World

    cfg = run_config(GRASP3)
    topo, obj = cfg.topo(), cfg.scene_spec.object
    world = World(topo)
    try:
        q = world.joint_positions()
        q = _ik(world, GraspScene(world, obj).fingers, q, "f1_4", (-1.03, 0.1))  # 0.07 deep
        readings = {}
        for contact in ("link", "tip"):
            scene = GraspScene(world, dataclasses.replace(obj, contact=contact))
            scene.reset()
            readings[contact] = scene.readings["f1_4"]
        tip = readings["tip"]
        assert tip.contact and tip.depth == pytest.approx(0.07, abs=1e-6) and tip.normal == pytest.approx((-1.0, 0.0))
        assert tip.point == pytest.approx((-1.0, 0.1), abs=1e-6)
        assert readings["link"].depth >= tip.depth - 1e-9  # the capsule is at least as deep as its end
        # the distal link's base 0.05 from the face (its capsule 0.05 deep), the link pointing away up-left:
        # its fingertip is 0.57 off the face
        h = math.radians(135.0)
        tip_xy = (-1.05 + 0.8 * math.cos(h), 0.8 * math.sin(h))
        q = _ik(world, GraspScene(world, obj).fingers, q, "f1_4", tip_xy, heading=h)
        for contact in ("link", "tip"):
            scene = GraspScene(world, dataclasses.replace(obj, contact=contact))
            scene.reset()
            readings[contact] = scene.readings["f1_4"]
        assert readings["link"].contact and readings["link"].depth == pytest.approx(0.05, abs=1e-4)
        assert readings["link"].point == pytest.approx((-1.0, 0.0), abs=1e-4)
        assert not readings["tip"].contact and readings["tip"].fn == 0.0
    finally:
        world.close()


def test_pad_keeps_links_out_and_below_the_radius_the_fingertip_centre():
    """solid = "pad" (examples/grasp3-sensed.toml): a fingertip pressing its face is allowed; a distal link sunk
    into the object with its fingertip out of it (the link's side or base pressing) is refused, where the "links"
    rule of grasp3.toml lets it through. A fingertip that entered through the face next to the one it presses, its
    link coming up through the bottom face at the corner, is refused only with max_depth below the links' radius
    (no fingertip centre inside the object): at grasp3's 0.3 the pad rule alone lets it through."""
    import dataclasses

    from kinswarm.sim.scenes.contact import GraspScene
    from kinswarm.sim.world import World

    cfg = run_config(ROOT / "examples" / "grasp3-sensed.toml")
    topo, pad = cfg.topo(), cfg.scene_spec.object
    links = run_config(GRASP3).scene_spec.object
    assert pad.solid == "pad" and links.solid == "links"
    strict = dataclasses.replace(pad, max_depth=0.095)  # below the capsules' radius 0.1
    world = World(topo)
    try:
        fingers = GraspScene(world, pad).fingers
        q = _ik(world, fingers, world.joint_positions(), "f1_4", (-1.54, 0.0))
        q = _ik(world, fingers, q, "f1_4", (-1.04, 0.0))  # the tip 0.06 deep
        for obj in (pad, links, strict):
            assert GraspScene(world, obj).too_deep() == []
        # the distal link's base 0.05 inside the left face, pointing away up-left: its fingertip is out
        h = math.radians(135.0)
        q = _ik(world, fingers, q, "f1_4", (-0.95 + 0.8 * math.cos(h), 0.8 * math.sin(h)), heading=h)
        assert GraspScene(world, pad).too_deep() == ["f1_4"] and GraspScene(world, links).too_deep() == []
        # at the corner: the fingertip centre 0.05 inside the left face and 0.1 above the bottom one, its link
        # coming up through the bottom face (docs/notebook/grasp.md, Corners)
        q = _ik(world, fingers, q, "f1_4", (-0.95, -1.0))
        q = _ik(world, fingers, q, "f1_4", (-0.95, -0.5), heading=math.radians(90.0))
        assert GraspScene(world, strict).too_deep() == ["f1_4"]
        assert GraspScene(world, pad).too_deep() == [] and GraspScene(world, links).too_deep() == []
    finally:
        world.close()


def test_pad_tries_a_refused_fingers_joints_one_by_one():
    """A finger whose move is refused keeps the moves of the joints that alone keep it out (solid = "pad"); with
    "links" the whole finger holds."""
    import dataclasses

    from kinswarm.protocol.scene import SceneSpec
    from kinswarm.sim.scenes.object import ObjectScene
    from kinswarm.sim.world import World

    cfg = run_config(ROOT / "examples" / "grasp3-sensed.toml")
    topo, pad = cfg.topo(), cfg.scene_spec.object
    world = World(topo)
    try:
        scene = ObjectScene(world, SceneSpec(kind="object", object=pad), math.radians(1.0))
        q = _ik(world, scene.contacts.fingers, world.joint_positions(), "f1_4", (-1.54, 0.0))
        q = _ik(world, scene.contacts.fingers, q, "f1_4", (-1.015, 0.0))  # the tip 0.085 deep
        scene.reset()
        assert scene.contacts.too_deep() == []
        # f1_3 turns the tip 0.3 into the face (refused), f1_4 alone turns it a little (kept)
        applied = scene.move({"f1_3": math.radians(-15.0), "f1_4": math.radians(-1.0)})
        assert applied["f1_3"] == 0.0 and applied["f1_4"] == pytest.approx(math.radians(-1.0))
        assert scene.contacts.blocked == 1 and scene.contacts.too_deep() == []
        assert world.joint_positions()["f1_3"] == pytest.approx(q["f1_3"])
        # each joint senses whether the object refused its own move (a refused joint, a kept one, one not asked)
        assert [scene.agent_sense(a)["collided"] for a in ("f1_3", "f1_4", "f2_3")] == [1.0, 0.0, 0.0]
        assert scene.agent_sense("f1_4")["fn"] >= 0.0  # the fingertip still senses its contact
        links = ObjectScene(world, SceneSpec(kind="object", object=dataclasses.replace(pad, solid="links")), 0.01)
        world.reset(q)
        links.reset()
        applied = links.move({"f1_3": math.radians(-15.0), "f1_4": math.radians(-1.0)})
        assert applied["f1_3"] == 0.0 and applied["f1_4"] == 0.0  # "links": the whole finger holds
    finally:
        world.close()


def test_balance_step_descends_the_sensed_balance_error():
    """`sensed`: each finger's force change is the descent of E = (|F|^2 + (tau/L)^2)/2 in its own forces, from
    sensed quantities only, with its own normal force kept in [f_grip, f_hi]. Finger a presses the left face, b
    and c the right one (GRASP): a pressing harder than b + c pushes the object right, so a eases off and b, c
    press harder; a torque is taken up by b and c in opposite ways; moved along the steps, E falls."""
    p = GraspParams()
    fn = {"a": 5.0, "b": 2.0, "c": 2.0}  # a presses 1 more than b + c: F = (1, 0) on the object
    obs = Contacts.from_sense(_sense(fn, net=(1.0, 0.0, 0.0), margin=dict.fromkeys(fn, 1.0)), TIPS)
    d = {t: balance_step(obs, t, (0.0, 0.0), 1.0, p) for t in TIPS}
    assert d["a"][0] == pytest.approx(-1.0) and d["b"][0] == pytest.approx(1.0) and d["c"][0] == pytest.approx(1.0)
    assert all(v[1] == pytest.approx(0.0) for v in d.values())
    # a counter-clockwise torque 0.7: b (above the centre, normal +x) eases off, c (below) presses harder
    obs = Contacts.from_sense(_sense(fn, net=(0.0, 0.0, 0.7), margin=dict.fromkeys(fn, 1.0)), TIPS)
    db, dc = balance_step(obs, "b", (0.0, 0.0), 1.0, p)[0], balance_step(obs, "c", (0.0, 0.0), 1.0, p)[0]
    assert db == pytest.approx(-0.35 * 0.7) and dc == pytest.approx(0.35 * 0.7)
    # a finger below the grip presses, one above f_hi eases off, one at its cone's edge eases its tangential force
    low = Contacts.from_sense(_sense({"a": 1.0}, margin={"a": 1.0}), TIPS)
    assert balance_step(low, "a", (0.0, 0.0), 1.0, p)[0] == pytest.approx(p.f_lo - 1.0)
    high = Contacts.from_sense(_sense({"a": 6.0}, margin={"a": 1.0}), TIPS)
    assert balance_step(high, "a", (0.0, 0.0), 1.0, p)[0] == pytest.approx(p.f_hi - 6.0)
    edge = Contacts.from_sense(_sense({"a": 3.0}, ft={"a": 1.5}, margin={"a": 0.0}), TIPS)
    assert balance_step(edge, "a", (0.0, 0.0), 1.0, p)[1] == pytest.approx(-p.margin_min)
    # the wrench after small steps along (dfn, dft) of every finger at once is smaller (a descent direction)
    fn = {"a": 4.6, "b": 1.7, "c": 2.4}
    ft = {"a": 0.2, "b": -0.1, "c": 0.0}
    NORMALS = {"a": (-1.0, 0.0), "b": (1.0, 0.0), "c": (1.0, 0.0)}  # noqa: N806

    def wrench(fn, ft):
        tips = {
            t: ContactReading(
                True,
                0.1,
                fn[t],
                ft[t],
                ft[t],
                1.0,
                GRASP[t],
                NORMALS[t],
                (-fn[t] * NORMALS[t][0] - ft[t] * NORMALS[t][1], -fn[t] * NORMALS[t][1] + ft[t] * NORMALS[t][0]),
            )
            for t in TIPS
        }
        return net_wrench(tips, (0.0, 0.0))

    E = lambda w: 0.5 * (w[0] ** 2 + w[1] ** 2 + w[2] ** 2)  # noqa: E731
    w = wrench(fn, ft)
    obs = Contacts.from_sense(_sense(fn, ft, net=w, margin=dict.fromkeys(fn, 1.0)), TIPS)
    d = {t: balance_step(obs, t, (0.0, 0.0), 1.0, p) for t in TIPS}
    w2 = wrench({t: fn[t] + 0.05 * d[t][0] for t in TIPS}, {t: ft[t] + 0.05 * d[t][1] for t in TIPS})
    assert E(w2) < 0.9 * E(w)


def test_sensed_goals_plan_nothing():
    """`sensed`: a finger goes to its pre-grasp point first, then to its grasp point, and touching its face it is
    sent one descent step from where its tip is (at most step_max away), whatever kn would plan."""
    g = GraspReward("sensed", GRASP, (0.0, 0.0), (1.0, 0.5), kn=1e6, kt=1e6)  # no contact model is used
    p, out = g.p, g.p.approach
    tips = {"a": (-0.5, -1.2), "b": (1.0 + out + 0.15, 0.35), "c": (1.8, -0.35)}
    g.step(tips, _sense({}))
    assert g.goals["a"] == pytest.approx((-1.0 - out, 0.0)) and g.goals["c"] == pytest.approx((1.0 + out, -0.35))
    assert g.goals["b"] == pytest.approx((1.0 + out, 0.35))
    tips = {**tips, "b": (1.0 + out + 0.05, 0.35)}
    g.step(tips, _sense({}))  # b is within pre_reached of its pre-grasp point: now to its grasp point
    assert g.goals["b"] == GRASP["b"] and g.goals["a"] == pytest.approx((-1.0 - out, 0.0))
    # b touches its face: F = (-1, 0) (b and c press more than a): b eases off, out along +x
    tips = {**tips, "b": (1.05, 0.35)}
    sense = _contact_sense({"b": (1.0, 0.35)}, {"b": (1.0, 0.35)}, {"b": 0.05}, {"b": (1.0, 0.0)})
    sense.update({"fn/b": 3.0, "margin/b": 1.0, "net_fx": -1.0})
    g.step(tips, sense)
    assert g.goals["b"] == pytest.approx((1.05 + p.compliance * 1.0, 0.35))
    _, context = g.step({**tips, "b": (1.05 + p.compliance, 0.35)}, sense)
    assert context["b"]["fine"] == 1.0 and context["b"]["force_error"] == 0.0  # no force target is planned
    sense["net_fx"] = -100.0  # a large error: the step is clipped to step_max
    g.step(tips, sense)
    assert g.goals["b"] == pytest.approx((1.05 + p.step_max, 0.35))


def test_sensed_detour_goes_round_the_corner():
    """`sensed`, detour: a finger touching another face than its own is sent to the point `approach` out along both
    normals from the corner between the two faces, then on to its pre-grasp point; without detour straight on."""
    below = _contact_sense({"a": (-0.5, -0.5)}, {"a": (-0.5, -0.5)}, {"a": 0.05}, {"a": (0.0, -1.0)})
    tips = {"a": (-0.5, -0.55), "b": (1.8, 0.35), "c": (1.8, -0.35)}
    straight = GraspReward("sensed", GRASP, (0.0, 0.0), (1.0, 0.5))
    straight.step(tips, below)
    out = straight.p.approach
    assert straight.goals["a"] == pytest.approx((-1.0 - out, 0.0))  # through the object's corner
    g = GraspReward("sensed", GRASP, (0.0, 0.0), (1.0, 0.5), detour=True)
    g.step(tips, below)
    assert g.goals["a"] == pytest.approx((-1.0 - out, -0.5 - out))
    g.step({**tips, "a": (-0.9, -0.9)}, _sense({}))  # off the face, not yet round: still the corner
    assert g.goals["a"] == pytest.approx((-1.0 - out, -0.5 - out))
    g.step({**tips, "a": (-1.0 - out + 0.05, -0.5 - out)}, _sense({}))  # round the corner: to the pre-grasp point
    assert g.goals["a"] == pytest.approx((-1.0 - out, 0.0))
    g.reset()
    assert g._via == dict.fromkeys(TIPS, None)
