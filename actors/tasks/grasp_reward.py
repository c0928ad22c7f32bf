"""The grasp task's rewards (paper §5.5, Eq. 12) and the grasp agent's per-finger credit (tasks/grasp.py uses them).

The grasp agent (the compound root, no DOF) reads the task observation (the sim's contact readings: the
net force and torque on the object and every fingertip's contact) and sends each finger its reward with
the down pass. Reward modes (`--reward` in a grasp scene; docs/notebook/grasp.md):

paper    Eq. 12 as printed, one global reward for all fingers: the reaching cases of Eq. 10 on
         D_goal (the fingertips' mean distance to their grasp points) plus R_f + R_tau + R_s, with
         R_f = e^(-c |F|), R_tau = e^(-c |tau|), R_s = e^(-c FC), FC = the summed friction-cone
         violation (sum of max(0, -margin)). With no contact every R_i is at its maximum.
contact  as paper, but R_f, R_tau, R_s are paid only while all fingertips touch (0 otherwise).
global   the `force` terms below, averaged over the fingers: one global reward (no per-finger credit).
force    (study 1's default, then named `shaped`) per finger i, from the grasp agent: out of contact,
         the reaching reward that works for the chain (-2 + k (D_i(t-1) - D_i(t)), D_i = distance to its
         grasp point); in contact,
         -|e_i|/f_grip (capped at 1) + k_f (|e_i(t-1)| - |e_i(t)|)/f_grip - 1 if it slips, where
         e_i = fn_i - fn_i* and fn* are the normal forces nearest to the present ones that balance the
         object (zero net force and torque with the present tangential forces) with at least f_grip
         each; e_i(t) is taken against the target of t-1, so other fingers' moves do not count as
         finger i's (a difference reward). The same e_i / f_grip goes down the finger as the state
         variable "force_error".
shaped   (default) contact goals: the grasp agent turns the balancing forces into a *position goal* per
         fingertip and each finger learns to reach it. In contact on its grasp point's face, the goal is
         where the tip must be for the contact to carry (fn_i*, ft_i*): goal_i = tip_i + n_i (depth_i -
         fn_i*/kn) + (ft_i*/kt - u_i) t_i (depth_i the present penetration, u_i = (p_i - anchor_i) . t_i
         the tangential spring's stretch, both sensed; kn, kt the contact stiffnesses from the scene).
         (fn*, ft*) balance the object at the present contact points: normal forces nearest the planned
         grip (the grasp points' balanced set, least force f_grip), tangential ones only as needed
         (grip_forces). Out of contact (or on another face) the goal is the grasp point if the tip is in
         front of its face, else the pre-grasp point `approach` out along the face normal.
         Reward per finger, against the goal of t-1 (a difference reward, as for `force`):
         -min(1, D_i(t)/D_tol) + k (D_i(t-1) - D_i(t)) / a_i, D_i = |tip_i - goal_i(t-1)|, a_i = the
         action scale the finger moved with. The grasp agent sends each finger "fine" = 1 while it
         is within D_fine of its goal; the finger then moves fine_action x the action
         size (a 1 degree step changes fn by more than the balance bound allows).
sensed   no planned contact points and no contact model (examples/grasp3-sensed.toml). A finger first
         goes to its pre-grasp point (`approach` out from its grasp point along the face normal; the
         grasp points are the scene's, Eq. 12's D_goal), then to its grasp point. Touching its grasp
         point's face, its goal is one descent step of the *sensed* balance error
         E = (|F|^2 + (tau/L)^2)/2 from where its tip is: goal_i = tip_i + c (dfn_i (-n_i) + dft_i t_i),
         at most step_max away, (dfn_i, dft_i) = balance_step: -dE/dfn_i and -dE/dft_i with the sensed
         F, tau and the finger's own contact point and normal, its normal force kept in [f_lo, f_hi] and
         its tangential force inside the cone (the sensed margin at least margin_min). c is a fixed gain
         (compliance, length per force unit), not the contact's 1/kn. Reward and "fine" as `shaped`,
         against the goal of t-1.

Numpy only: pure functions of the task observation, tested on their own (tests/test_grasp.py).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from .grasp_contacts import Contacts, Vec, contact_on_face, face_normal, towards
from .grasp_planned import balance_targets, contact_goals

GRASP_REWARDS: tuple[str, ...] = ("shaped", "sensed", "paper", "contact", "global", "force")


@dataclass(frozen=True)
class GraspParams:
    """Constants of the grasp rewards. D_min: Eq. 12's reach threshold, scaled to the fingers (the chain's
    3.0 would cover the whole hand); c: Eq. 12's c and c*; f_grip: the least normal force per finger."""

    D_min: float = 0.5
    c: float = 1.0
    k: float = 20.0
    k_f: float = 2.0
    f_grip: float = 2.0
    err_cap: float = 3.0  # force_error is sent clipped to [-err_cap, err_cap]
    D_tol: float = 0.05  # shaped: the distance to the contact goal at which the reward's penalty saturates
    D_fine: float = 0.05  # shaped: within this of its goal a finger moves with fine actions
    g_perp: float = 0.05  # the range of the state variable g_perp: [-g_perp, g_perp] (clipped)
    approach: float = 0.3  # shaped: a finger not in front of its grasp point's face goes first to the point
    # this far out along the face normal (the pre-grasp point), so that it does not press into another face
    compliance: float = 0.02  # sensed: length per force unit of the descent step (a gain, not the contact's 1/kn)
    f_lo: float = 2.0  # sensed: a finger pressing less than this is told to press harder (the least grip)
    f_hi: float = 5.0  # sensed: a finger pressing harder than this is told to ease off
    step_max: float = 0.05  # sensed: the descent step's length is clipped to this
    margin_min: float = 0.2  # sensed: the friction-cone margin (force units) a finger keeps
    pre_reached: float = 0.1  # sensed: within this of its pre-grasp point a finger turns towards the face


def reach_cases(D: float, D_prev: float, D_min: float, c: float) -> float:
    """The reaching part of Eq. 12 (Eq. 10's three cases) on D_goal."""
    dD = D - D_prev
    if D > D_min:
        return -2.0
    if dD <= 0.0:
        return math.exp(-c * D)
    return -1.0


def eq12(D: float, D_prev: float, obs: Contacts, p: GraspParams, only_with_contact: bool = False) -> float:
    """Eq. 12 as printed: the reach cases plus R_f + R_tau + R_s (only while all touch, if asked)."""
    base = reach_cases(D, D_prev, p.D_min, p.c)
    if only_with_contact and not obs.all_touch:
        return base
    fx, fy, tau = obs.net
    R_f = math.exp(-p.c * math.hypot(fx, fy))
    R_tau = math.exp(-p.c * abs(tau))
    R_s = math.exp(-p.c * obs.cone_violation())
    return base + R_f + R_tau + R_s


def balance_step(obs: Contacts, tip: str, center: Vec, L: float, p: GraspParams) -> tuple[float, float]:
    """(dfn, dft): how finger `tip`'s contact forces should change to lower the sensed balance error
    E = (|F|^2 + (tau/L)^2)/2 (the negative gradient of E in its own normal and tangential force; the other
    fingers' forces held), with its normal force kept in [f_lo, f_hi] and its tangential force inside the
    friction cone (the sensed margin at least margin_min). Everything read here is sensed: the net wrench on
    the object and the finger's own contact; nothing is planned."""
    fx, fy, tau = obs.net
    (px, py), (nx, ny) = obs.point[tip], obs.normal[tip]
    tx, ty = -ny, nx
    rx, ry = px - center[0], py - center[1]
    # f_i = -fn n + ft t: dF/dfn = -n, dtau/dfn = r x (-n); dF/dft = t, dtau/dft = r x t
    dfn = (fx * nx + fy * ny) + tau / L**2 * (rx * ny - ry * nx)
    dft = -(fx * tx + fy * ty) - tau / L**2 * (rx * ty - ry * tx)
    fn = obs.fn[tip]
    dfn += max(0.0, p.f_lo - fn) - max(0.0, fn - p.f_hi)
    shortfall = p.margin_min - obs.margin[tip]
    if shortfall > 0.0:  # near or over the cone's edge: ease the tangential spring
        dft -= math.copysign(shortfall, obs.ft[tip])
    return dfn, dft


class GraspReward:
    """The grasp agent's reward, goals and per-finger context, one call per step (it keeps t-1)."""

    def __init__(
        self,
        mode: str,
        grasp: Mapping[str, Vec],
        center: Vec,
        half_extents: Vec,
        params: GraspParams | None = None,
        kn: float = 20.0,
        kt: float = 20.0,
        fine_action: float = 1.0,
        detour: bool = False,
    ) -> None:
        """kn, kt: the contact stiffnesses (the scene's), to turn forces into displacements; fine_action: the
        fingers' action scale within D_fine of their goal (the grasp task's fine_action), for the k term;
        detour (sensed): a finger touching another face than its own goes round the corner between the two."""
        if mode not in GRASP_REWARDS:
            raise ValueError(f"unknown grasp reward {mode!r}; allowed: {', '.join(GRASP_REWARDS)}")
        self.mode, self.grasp, self.center, self.fine_action = mode, dict(grasp), center, fine_action
        self.kn, self.kt, self.detour = kn, kt, detour
        self.tips, self.half_extents = tuple(grasp), half_extents
        self.normals = {t: face_normal(g, center, half_extents) for t, g in grasp.items()}
        self.p = params or GraspParams()
        self.reset()

    def reset(self) -> None:
        self._D: dict[str, float] | None = None
        self._err: dict[str, float] | None = None
        self._target: dict[str, float] | None = None
        self._tips: dict[str, Vec] | None = None
        self._fine: dict[str, bool] = dict.fromkeys(self.tips, False)
        self._pressing: dict[str, bool] = dict.fromkeys(self.tips, False)  # sensed: past the pre-grasp point
        self._via: dict[str, Vec | None] = dict.fromkeys(self.tips, None)  # sensed, detour: the corner to go round
        self.goals: dict[str, Vec] = {t: (float(g[0]), float(g[1])) for t, g in self.grasp.items()}

    def step(
        self, tips: Mapping[str, Sequence[float]], sense: Mapping[str, float]
    ) -> tuple[dict[str, float] | None, dict[str, dict[str, float]]]:
        """(reward per fingertip for the transition into this step, or None at an epoch's first step;
        context per fingertip for the finger's state: force_error, and with `shaped` the flag "fine").
        `goals` then holds each fingertip's goal for this step (its grasp point except with `shaped`)."""
        if self.mode in ("shaped", "sensed"):
            return self._step_goals(tips, sense)
        p = self.p
        obs = Contacts.from_sense(sense, self.tips)
        D = {t: math.hypot(tips[t][0] - g[0], tips[t][1] - g[1]) for t, g in self.grasp.items()}
        target = balance_targets(obs, self.grasp, self.normals, self.center, p.f_grip)
        err = {t: obs.fn[t] - target[t] for t in self.tips}
        # against the previous step's target: only finger i's own move counts for it (difference reward)
        err_own = err if self._target is None else {t: obs.fn[t] - self._target[t] for t in self.tips}
        rewards: dict[str, float] | None = None
        if self._D is not None and self._err is not None:
            D_goal, D_prev = sum(D.values()) / len(D), sum(self._D.values()) / len(self._D)
            if self.mode in ("paper", "contact"):
                r = eq12(D_goal, D_prev, obs, p, only_with_contact=self.mode == "contact")
                rewards = dict.fromkeys(self.tips, r)
            else:
                per = {t: self._finger(t, obs, D[t], self._D[t], err_own[t], self._err[t]) for t in self.tips}
                if self.mode == "global":
                    r = sum(per.values()) / len(per)
                    rewards = dict.fromkeys(self.tips, r)
                else:
                    rewards = per
        self._D, self._err, self._target = D, err, target
        cap = p.err_cap
        context = {t: {"force_error": max(-cap, min(cap, err[t] / p.f_grip))} for t in self.tips}
        return rewards, context

    def _step_goals(
        self, tips: Mapping[str, Sequence[float]], sense: Mapping[str, float]
    ) -> tuple[dict[str, float] | None, dict[str, dict[str, float]]]:
        p = self.p
        obs = Contacts.from_sense(sense, self.tips)
        now = {t: (float(tips[t][0]), float(tips[t][1])) for t in self.tips}
        rewards: dict[str, float] | None = None
        if self._tips is not None:  # against the goals of t-1 (a difference reward)
            rewards = {}
            for t in self.tips:
                gx, gy = self.goals[t]
                D_prev = math.hypot(self._tips[t][0] - gx, self._tips[t][1] - gy)
                D = math.hypot(now[t][0] - gx, now[t][1] - gy)
                scale = self.fine_action if self._fine[t] else 1.0
                rewards[t] = -min(1.0, D / p.D_tol) + p.k * (D_prev - D) / scale
        if self.mode == "sensed":
            goals = self._sensed_goals(obs, now)
            target = {t: obs.fn[t] for t in self.tips}  # no force target: the force error sent down is 0
        else:
            goals, target, self.ft_target = contact_goals(
                obs,
                self.grasp,
                self.normals,
                self.center,
                p.f_grip,
                self.kn,
                self.kt,
                tips,
                self.half_extents,
                p.approach,
            )
        self.goals, self._tips, self._target = goals, now, target
        cap = p.err_cap
        context = {}
        for t in self.tips:
            D = math.hypot(now[t][0] - goals[t][0], now[t][1] - goals[t][1])
            self._fine[t] = D < p.D_fine
            e = (obs.fn[t] - target[t]) / p.f_grip
            context[t] = {"force_error": max(-cap, min(cap, e)), "fine": 1.0 if self._fine[t] else 0.0}
        return rewards, context

    def _sensed_goals(self, obs: Contacts, now: Mapping[str, Vec]) -> dict[str, Vec]:
        """`sensed`: a finger touching its grasp point's face goes one descent step of the sensed balance
        error (balance_step) from its tip; any other finger to its grasp point or pre-grasp point."""
        p, on_face = self.p, contact_on_face(obs, self.normals)
        L = max(self.half_extents)
        goals: dict[str, Vec] = {}
        for t, g in self.grasp.items():
            n = self.normals[t]
            pre = (g[0] + p.approach * n[0], g[1] + p.approach * n[1])
            if self.detour and obs.contact[t] and not on_face[t]:
                # on another face: the straight way to the pre-grasp point cuts through the object
                self._via[t], self._pressing[t] = self._corner(t, obs.normal[t], now[t]), False
            via = self._via[t]
            if via is not None:
                if math.hypot(now[t][0] - via[0], now[t][1] - via[1]) >= p.pre_reached:
                    goals[t] = via
                    continue
                self._via[t] = None  # round the corner: on to the pre-grasp point
            if not self._pressing[t] and math.hypot(now[t][0] - pre[0], now[t][1] - pre[1]) < p.pre_reached:
                self._pressing[t] = True  # at the pre-grasp point: from now on towards the face
            if not on_face[t]:
                goals[t] = (float(g[0]), float(g[1])) if self._pressing[t] else pre
                continue
            dfn, dft = balance_step(obs, t, self.center, L, p)
            (nx, ny), (tx, ty) = obs.normal[t], (-obs.normal[t][1], obs.normal[t][0])
            dx, dy = p.compliance * (-dfn * nx + dft * tx), p.compliance * (-dfn * ny + dft * ty)
            goals[t] = towards(now[t], (now[t][0] + dx, now[t][1] + dy), p.step_max)
        return goals

    def _corner(self, t: str, touched: Vec, tip: Vec) -> Vec:
        """The point `approach` out along both faces' normals from the object's corner between the face the
        finger touches (its sensed normal) and its own face (opposite faces: the corner on the tip's side)."""
        n, c, h, a = self.normals[t], self.center, self.half_extents, self.p.approach
        s = [n[i] + touched[i] for i in (0, 1)]
        side = [math.copysign(1.0, s[i]) if abs(s[i]) > 0.5 else math.copysign(1.0, tip[i] - c[i]) for i in (0, 1)]
        return (c[0] + side[0] * (h[0] + a), c[1] + side[1] * (h[1] + a))

    def _finger(self, t: str, obs: Contacts, D: float, D_prev: float, err: float, err_prev: float) -> float:
        p = self.p
        if not obs.contact[t]:
            return -2.0 + p.k * (D_prev - D)  # the chain's shaped reaching reward, towards the grasp point
        r = -min(1.0, abs(err) / p.f_grip) + p.k_f * (abs(err_prev) - abs(err)) / p.f_grip
        if obs.margin[t] < 0.0:
            r -= 1.0  # it slips
        return r
