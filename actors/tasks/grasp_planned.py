"""The planned grasp of the `shaped` reward (the reference the `sensed` one does without): balancing forces from the
contact model (balance_targets, grip_forces) turned into a position goal per fingertip (contact_goals). It reads the
scene's grasp points, face normals and contact stiffnesses: a model, which is why it is the reference and not the skill.
Numpy only (tests/test_grasp.py)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np

from .grasp_contacts import Contacts, Vec, contact_on_face, in_front


def balance_targets(
    obs: Contacts, grasp: Mapping[str, Vec], normals: Mapping[str, Vec], center: Vec, f_grip: float
) -> dict[str, float]:
    """fn*: the normal forces nearest (least squares) to the present ones that cancel the net wrench,
    with at least f_grip each. A fingertip out of contact is placed at its grasp point with that face's
    outward normal and no force. Internal forces (the null space of the grasp matrix) raise the smallest
    to f_grip when they can; otherwise the result is clipped at f_grip."""
    tips = list(obs.contact)
    G = np.zeros((3, len(tips)))  # wrench of a unit normal force at each contact: [-n; (p - c) x (-n)]
    w_t = np.zeros(3)  # wrench of the tangential forces
    fn = np.zeros(len(tips))
    for j, t in enumerate(tips):
        if obs.contact[t] and t in obs.point:
            (px, py), (nx, ny) = obs.point[t], obs.normal[t]
            fn[j] = obs.fn[t]
        else:
            (px, py), (nx, ny) = grasp[t], normals[t]
        rx, ry = px - center[0], py - center[1]
        G[:, j] = (-nx, -ny, -(rx * ny - ry * nx))
        if obs.contact[t]:
            tx, ty = -ny, nx
            ft = obs.ft[t]
            w_t += (ft * tx, ft * ty, ft * (rx * ty - ry * tx))
    x = fn - np.linalg.pinv(G) @ (G @ fn + w_t)
    if x.min() < f_grip:
        _, sv, vt = np.linalg.svd(G)
        rank = int((sv > 1e-9 * max(1.0, sv.max())).sum())
        null = vt[rank:]
        v = next((v * np.sign(v.sum()) for v in null if np.all(v * np.sign(v.sum()) > 1e-9)), None)
        if v is not None:
            alpha = max((f_grip - xi) / vi for xi, vi in zip(x, v, strict=True))
            x = x + max(alpha, 0.0) * v
        x = np.maximum(x, f_grip)
    return {t: float(x[j]) for j, t in enumerate(tips)}


def grip_forces(
    points: Mapping[str, Vec],
    normals: Mapping[str, Vec],
    center: Vec,
    fn0: Mapping[str, float],
    f_grip: float,
    lam: float = 1.0,
) -> tuple[dict[str, float], dict[str, float]]:
    """(fn*, ft*): contact forces at `points` (outward `normals`) with zero net force and torque, the
    normal ones nearest to the preferred `fn0` and the tangential ones small: minimise
    |fn - fn0|^2 + lam |ft|^2 subject to G_n fn + G_t ft = 0 (a linear KKT system), then scaled up (a
    balanced set stays balanced) until the least normal force is f_grip. Tangential forces are along
    t = (-n_y, n_x), as the contact model's."""
    tips = list(points)
    n = len(tips)
    A = np.zeros((3, 2 * n))  # wrench on the object of a unit normal push / unit tangential force
    for j, t in enumerate(tips):
        (px, py), (nx, ny) = points[t], normals[t]
        rx, ry = px - center[0], py - center[1]
        tx, ty = -ny, nx
        A[:, j] = (-nx, -ny, -(rx * ny - ry * nx))
        A[:, n + j] = (tx, ty, rx * ty - ry * tx)
    h_inv = np.concatenate([np.ones(n), np.full(n, 1.0 / lam)])
    g = np.concatenate([[fn0[t] for t in tips], np.zeros(n)])
    AH = A * h_inv
    x = g - h_inv * (A.T @ (np.linalg.pinv(AH @ A.T) @ (A @ g)))
    least = x[:n].min()
    if least > 1e-9 and least < f_grip:
        x *= f_grip / least
    return {t: float(x[j]) for j, t in enumerate(tips)}, {t: float(x[n + j]) for j, t in enumerate(tips)}


def contact_goals(
    obs: Contacts,
    grasp: Mapping[str, Vec],
    normals: Mapping[str, Vec],
    center: Vec,
    f_grip: float,
    kn: float,
    kt: float,
    tips: Mapping[str, Sequence[float]],
    half_extents: Vec | None = None,
    approach: float = 0.0,
) -> tuple[dict[str, Vec], dict[str, float], dict[str, float]]:
    """(goal per fingertip, fn*, ft*) of the `shaped` reward: where each tip must be for its contact to
    carry (fn_i*, ft_i*). The forces balance the object at the present contact points (grip_forces: normal
    forces nearest to the planned grip, the least normal force of the grasp points' balanced set at
    f_grip; tangential ones only as needed), with the planned grasp point and face normal for a finger out
    of contact or touching another face than its grasp point's; such a finger is sent to its grasp point
    when its tip is in front of that face (outside it, within its extent; `half_extents` given), else to the
    pre-grasp point `approach` out along the face normal. In contact: goal = tip + n (depth - fn*/kn) +
    (ft*/kt - u) t, u the tangential spring's stretch."""
    on_face = contact_on_face(obs, normals)
    planned = Contacts(
        contact=dict.fromkeys(grasp, False),
        fn=dict.fromkeys(grasp, 0.0),
        ft=dict.fromkeys(grasp, 0.0),
        margin=dict.fromkeys(grasp, 0.0),
        point={},
        normal={},
        net=(0.0, 0.0, 0.0),
    )
    fn0 = balance_targets(planned, grasp, normals, center, f_grip)  # the planned grip, least force f_grip
    points = {t: obs.point[t] if on_face[t] else grasp[t] for t in grasp}
    nrm = {t: obs.normal[t] if on_face[t] else normals[t] for t in grasp}
    fn_t, ft_t = grip_forces(points, nrm, center, fn0, f_grip)
    goals: dict[str, Vec] = {}
    for t, g in grasp.items():
        if not on_face[t]:
            goals[t] = (float(g[0]), float(g[1]))
            if half_extents is not None and not in_front(tips[t], g, normals[t], center, half_extents):
                goals[t] = (g[0] + approach * normals[t][0], g[1] + approach * normals[t][1])
            continue
        assert obs.depth is not None and obs.anchor is not None
        (nx, ny), (px, py), (ax, ay) = obs.normal[t], obs.point[t], obs.anchor[t]
        tx, ty = -ny, nx
        u = (px - ax) * tx + (py - ay) * ty  # the tangential spring's stretch
        dn = obs.depth[t] - fn_t[t] / kn  # > 0: too deep, the goal is outwards
        du = ft_t[t] / kt - u
        goals[t] = (tips[t][0] + dn * nx + du * tx, tips[t][1] + dn * ny + du * ty)
    return goals, fn_t, ft_t
