"""The seed's compliance (App. 3.5): what a straight robot does against a static body, and head-on meetings.

Each rule reads the bodies where they touch and acts at once (compliance moves are instantaneous):
docking compliance turns a robot whose front corner meets a face of the structure (a docked robot)
inside the sticking cone flush about that corner (:func:`dock_rule`, checked by :func:`sweep`); anything
else against a static body's face is stuck (H), as SPEC 6 says: a front corner outside the cone, the
structure's corner on the robot's front edge, any front contact with a robot that is not docked. A body's
corner on a robot's long side grazes past, and two straight robots meeting head-on within the seed's
limits form G_1 (:func:`self_align`). Outcomes are ``(kind, detail)`` pairs of :class:`~.bodies.SimEvent` vocabulary;
``docked`` / ``stuck`` are set on the shared :class:`~.bodies.Bodies`.
"""

from __future__ import annotations

import math

import numpy as np

from ..kinematics import wrap
from ..robots import angle_difference, body_corners
from .bodies import (
    ARENA,
    ARRIVE_FLUSH_RAD,
    BISECT_UM,
    CONTACT_TOL_UM,
    FACE_TIE_UM,
    FLUSH_TOL_RAD,
    GRAZE_TOL_UM,
    SELF_ALIGN_MAX_INCIDENCE_RAD,
    SELF_ALIGN_MAX_OFFSET_UM,
    SLIDE_OVERSHOOT_UM,
    STICKING_CONE_RAD,
    SWEEP_UM,
    TOUCH_UM,
    Bodies,
    Trig,
    depth_one,
    faces_touched,
    heading_of,
    local,
    rotate_about,
    with_trig,
)


def contact_points(b: Bodies, i: int, j: int):
    """Touching corners: ``(points (k, 2), is_corner_of_i (k,))`` of bodies i and j.

    In plain floats (:func:`_corners`, :func:`_corner_distances`), bit-identical to
    :func:`stressbots.robots.body_corners` and :func:`stressbots.collision.point_rectangle_distance`: every
    docking compliance and head-on test asks this of one pair, where numpy's per-call cost dominates.
    """
    P = b.pose
    hl, hw = float(b.hl[i]), float(b.hw[i])
    hlj, hwj = float(b.hl[j]), float(b.hw[j])
    ti, tj = with_trig([tuple(P[i].tolist()), tuple(P[j].tolist())])
    ci, cj = _corners(ti, hl, hw), _corners(tj, hlj, hwj)
    eps = max(TOUCH_UM, 2.0 * depth_one(ti, tj, hl, hw, hlj, hwj)) + 1e-9
    d = _corner_distances([(ci, tj, hlj, hwj), (cj, ti, hl, hw)])
    di, dj = d[:4], d[4:]
    pts = [p for p, dd in zip(ci, di, strict=True) if dd <= eps] + [p for p, dd in zip(cj, dj, strict=True) if dd <= eps]
    own = np.arange(len(pts)) < sum(dd <= eps for dd in di)
    if not pts:  # degenerate crossing: fall back to the nearest corners
        pts = [ci[di.index(min(di))], cj[dj.index(min(dj))]]
        own = np.array([True, False])
    return np.array(pts, dtype=np.float64).reshape(-1, 2), own


def _corners(p: Trig, hl: float, hw: float) -> list[tuple[float, float]]:
    """:func:`stressbots.robots.body_corners` of one body (half sizes ``hl``, ``hw``): front-left,
    front-right, rear-right, rear-left, with its operations (``c +- hl h +- hw r``, r = (cos, -sin))."""
    x, y, s, c = p
    hx, hy, rx, ry = hl * s, hl * c, hw * c, hw * -s
    return [(x + hx - rx, y + hy - ry), (x + hx + rx, y + hy + ry), (x - hx + rx, y - hy + ry), (x - hx - rx, y - hy - ry)]


def _corner_distances(groups) -> list[float]:
    """Signed distances (um) of points to a body, as :func:`stressbots.collision.point_rectangle_distance`:
    ``groups`` of ``(points, body pose with trig, hl, hw)``; one ``np.hypot`` call for all."""
    us, vs = [], []
    for pts, (x, y, s, c), hl, hw in groups:
        for px, py in pts:
            dx, dy = px - x, py - y
            us.append(abs(dx * s + dy * c) - hl)
            vs.append(abs(dx * c + dy * -s) - hw)
    outside = np.hypot(np.maximum(us, 0.0), np.maximum(vs, 0.0)).tolist()
    return [o + min(max(u, v), 0.0) for o, u, v in zip(outside, us, vs, strict=True)]


def front_face(b: Bodies, i: int, j: int, pts):
    """For robot i pressing its front on body j: ``(contact point, outward normal of j's face, alpha)``,
    or ``None`` when the contact is not on i's front edge."""
    P = b.pose
    u, v = local(pts, P[i])
    tol = 1e-3 + max(0.0, b.pair_depth(i, j))
    if not np.all((np.abs(u - b.hl[i]) <= tol) & (np.abs(v) <= b.hw[i] + tol)):
        return None
    c = pts.mean(axis=0)
    h = np.array([math.sin(P[i, 2]), math.cos(P[i, 2])])
    # The face of j that i's front meets. A contact at a corner of j lies on two faces: keep those
    # it is not behind (e.g. a corner sliding along one face onto a collinear one is already past
    # the other), then take the one most opposed to i's heading.
    faces = faces_touched(pts, P[j], b.hl[j], b.hw[j], tol)
    best = max(out for _, out in faces)
    nrm = max((m for m, out in faces if out >= best - FACE_TIE_UM), key=lambda m: float(-(m @ h)))
    alpha = angle_difference(P[i, 2], heading_of(-nrm))
    return c, nrm, float(alpha)


def flush(b: Bodies, i: int, j: int) -> bool:
    """Whether robot i's front edge lies flush (within :data:`~.bodies.FLUSH_TOL_RAD`) on a face of j."""
    pts, _ = contact_points(b, i, j)
    ff = front_face(b, i, j, pts)
    return ff is not None and abs(ff[2]) <= FLUSH_TOL_RAD


def dock_rule(b: Bodies, i: int, j: int, speed: np.ndarray):
    """Straight robot i pushing into static body j: docking compliance, a graze past j's corner or stuck.

    Docking compliance needs all of SPEC 6: j is part of the structure (docked), the incidence is inside
    the sticking cone, and a front corner of i is on j's face (or i's front edge is within
    :data:`~.bodies.ARRIVE_FLUSH_RAD` of flush: it arrived flush). The
    robot stays stuck where it met j otherwise; it moves again when its motion no longer pushes.
    Returns ``(kind, detail, slide)`` with ``slide = (velocity (2,), duration_s)`` for a graze.
    """
    P = b.pose
    pts, own = contact_points(b, i, j)
    ff = front_face(b, i, j, pts)
    name_j = b.names[j]
    if ff is None:
        u, v = local(pts, P[i])
        if np.all(np.abs(np.abs(v) - b.hw[i]) <= 1e-3) and not own.any():
            # j's corner on i's long side: i slides past it, straight on.
            h = np.array([math.sin(P[i, 2]), math.cos(P[i, 2])])
            dist = float(np.max(u) + b.hl[i]) + SLIDE_OVERSHOOT_UM
            return "graze", f"slides past a corner of {name_j}", (speed[i] * h, dist / speed[i])
        b.stuck[i] = False
        return "contact", "stopped (contact not on its front)", None
    c, _, alpha = ff
    deg = math.degrees(alpha)
    b.docked[i] = False
    b.stuck[i] = True
    if not b.docked[j]:
        return "stuck", f"front against {name_j}, which is not part of the structure (H)", None
    if abs(alpha) > STICKING_CONE_RAD:
        return "stuck", f"incidence {deg:.1f} deg outside the sticking cone on {name_j} (H)", None
    if abs(alpha) > ARRIVE_FLUSH_RAD and not own.any():
        return "stuck", f"front edge on a corner of {name_j}: no front corner on its face (H)", None
    return _docking_compliance(b, i, c, alpha)


def _docking_compliance(b: Bodies, i: int, c, alpha: float):
    """Inside the sticking cone: turn about the contact point ``c`` until flush (docked), or until the
    turn sweeps into another body (stuck)."""
    deg = math.degrees(alpha)
    phi, blocker = sweep(b, i, c, -alpha)
    b.pose[i] = rotate_about(b.pose[i], c, phi)
    if blocker is None:
        b.docked[i] = True
        b.stuck[i] = False
        return "dock", f"docking compliance: incidence {deg:.2f} deg inside the sticking cone, now flush", None
    b.stuck[i] = True
    b.docked[i] = False
    return "stuck", f"docking compliance ({deg:.2f} deg) obstructed by {b.label(blocker)}", None


def sweep(b: Bodies, i: int, c, phi: float):
    """Rotate robot i about ``c`` by up to ``phi`` (rad); stop at first touch of another body.

    Returns ``(phi_reached, blocker)``; ``blocker`` is a robot index, ``ARENA`` or ``None``.
    """
    if abs(phi) < 1e-12:
        return phi, None
    P = b.pose
    corners = body_corners(P[i], 2 * b.hl[i], 2 * b.hw[i])[0]
    reach = float(np.max(np.hypot(*(corners - c).T)))
    m = int(min(max(2, math.ceil(abs(phi) * reach / SWEEP_UM)), 4000))
    others = np.array([k for k in range(b.n) if k != i], dtype=int)
    ci = np.full(others.size, i)
    cj = others
    if b.arena is not None:
        ci = np.append(ci, i)
        cj = np.append(cj, ARENA)
    if ci.size == 0:
        return phi, None

    def gaps(phis):
        poses = np.repeat(P[None], np.size(phis), axis=0)
        poses[:, i] = rotate_about(P[i], c, phis)
        return b.gaps(poses, ci, cj)

    g0 = gaps(np.zeros(1))[0]
    thr = np.minimum(-GRAZE_TOL_UM, g0 - CONTACT_TOL_UM)
    phis = phi * np.arange(1, m + 1) / m
    bad = gaps(phis) < thr
    rows = bad.any(axis=1)
    if not rows.any():
        return phi, None
    k = int(np.argmax(rows))
    lo, hi = (phis[k - 1] if k else 0.0), phis[k]
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        if (gaps(np.array([mid]))[0] < thr).any():
            hi = mid
        else:
            lo = mid
        if abs(hi - lo) * reach < BISECT_UM:
            break
    col = int(np.argmax(bad[k]))
    return lo, int(cj[col])


def self_align(b: Bodies, i: int, j: int) -> tuple[str, str]:
    """Two straight robots meeting head-on: form G_1 within the seed's limits, else stuck."""
    P = b.pose
    alpha = float(angle_difference(P[i, 2], P[j, 2] + math.pi))
    hi_ = np.array([math.sin(P[i, 2]), math.cos(P[i, 2])])
    hj_ = np.array([math.sin(P[j, 2]), math.cos(P[j, 2])])
    axis = hi_ - hj_
    axis /= np.linalg.norm(axis)
    th = heading_of(axis)
    mi = P[i, :2] + b.hl[i] * hi_
    mj = P[j, :2] + b.hl[j] * hj_
    across = np.array([math.cos(th), -math.sin(th)])
    w_y = float((mj - mi) @ across)
    nums = f"alpha {math.degrees(alpha):.1f} deg, w_y {w_y:.1f} um"
    if abs(alpha) >= SELF_ALIGN_MAX_INCIDENCE_RAD or abs(w_y) >= SELF_ALIGN_MAX_OFFSET_UM:
        b.stuck[[i, j]] = True
        b.docked[[i, j]] = False
        return "stuck", f"head-on outside the self-alignment limits ({nums}) (H)"
    junction = 0.5 * (mi + mj)
    new_i = np.array([*(junction - b.hl[i] * axis), wrap(th)])
    new_j = np.array([*(junction + b.hl[j] * axis), wrap(th + math.pi)])
    if _obstructed(b, i, j, new_i, new_j):
        b.stuck[[i, j]] = True
        b.docked[[i, j]] = False
        return "stuck", f"self-alignment ({nums}) obstructed by a third body (H)"
    b.pose[i], b.pose[j] = new_i, new_j
    b.docked[[i, j]] = True
    b.stuck[[i, j]] = False
    return "self_align", f"G_1 formed ({nums})"


def _obstructed(b: Bodies, i: int, j: int, new_i, new_j) -> bool:
    """Whether moving i and j to ``new_i`` / ``new_j`` (the aligned pair) overlaps a third body or leaves
    the arena (beyond what already touched)."""
    others = np.array([k for k in range(b.n) if k not in (i, j)], dtype=int)
    if not (others.size or b.arena is not None):
        return False
    P = b.pose
    ci = np.concatenate([np.full(others.size, i), np.full(others.size, j)])
    cj = np.concatenate([others, others])
    if b.arena is not None:
        ci = np.append(ci, [i, j])
        cj = np.append(cj, [ARENA, ARENA])
    before = b.gaps(P[None], ci, cj)[0]
    moved = P.copy()
    moved[i], moved[j] = new_i, new_j
    after = b.gaps(moved[None], ci, cj)[0]
    return bool((after < np.minimum(-GRAZE_TOL_UM, before - CONTACT_TOL_UM)).any())
