"""Pure geometry of G_1 (seed App. 3.3) as an orbit rendezvous: plain numbers and arrays in and out.

Where D_n meets D_{n-1} (:func:`meet_distance`), the orbit D_{n-1} leaves from (:func:`station_centre`),
where D_n aims (:func:`approach_pose`), the slots in a *pair frame* (:func:`framed_goals`, a rigid motion
of the whole structure), whether two frames differ (:func:`frames_apart`) and discs shrunk to a clearance
(:func:`tight_discs`). Used by :mod:`~stressbots.control.pair` and its stages.
"""

from __future__ import annotations

import math

import numpy as np

from .. import se2
from ..collision import penetration_depth
from ..kinematics import move
from ..robots import TWO_PI, angle_difference, front_midpoints
from .queries import fine_motion_length, pose_on_orbit

__all__ = ["approach_pose", "approach_room", "body_gap_along", "deepest_overlap",
           "framed_goals", "frames_apart", "meet_distance", "pair_can_keep_apart",
           "pressed_together", "station_centre", "tight_discs"]


def frames_apart(a, b) -> bool:
    """Whether pair frames ``a`` and ``b`` (``(phi_rad, dx_um, dy_um)``) differ by over 10 deg or 150 um
    (a frame near one already tried would fail the same way)."""
    return abs(angle_difference(a[0], b[0])) > math.radians(10.0) or math.hypot(a[1] - b[1], a[2] - b[2]) > 150.0


def meet_distance(rstar_M: float, r_M: float, L_N: float, W_N: float) -> float:
    """Centre distance (um) of D_n from D_{n-1}'s tangent point at departure: D_n clear of the orbit disc
    (radius ``rstar_M`` plus 30 um; D_{n-1}'s turning radius ``r_M``, D_n's body ``L_N`` x ``W_N``), plus 80 um."""
    rs = rstar_M + 30.0
    lateral = r_M - 0.5 * W_N
    return 0.5 * L_N + math.sqrt(max(rs * rs - lateral * lateral, 0.0)) + 80.0


def station_centre(goal_M: np.ndarray, D: float, L_M: float, L_N: float, v_M: float, v_N: float, r_M: float) -> np.ndarray:
    """Centre (um) of the orbit D_{n-1} leaves from so that, meeting D_n from ``D`` away, it ends in its slot
    ``goal_M``: the pair closes the gap at speeds ``v_M`` + ``v_N``, D_{n-1} covering its share from the
    tangent point (turning radius ``r_M``, clockwise orbit to the slot's right)."""
    g = goal_M
    th = float(g[2])
    h = np.array([math.sin(th), math.cos(th)])
    right = np.array([math.cos(th), -math.sin(th)])
    vM, vN = v_M, v_N
    s_M = max(D - 0.5 * (L_M + L_N), 0.0) * vM / (vM + vN)
    tangent = g[:2] - s_M * h
    return tangent + r_M * right


def approach_pose(centre: np.ndarray, th_dep: float, r_M: float, D: float, v_N: float, early: float) -> np.ndarray:
    """Where D_n aims: on the tangent of D_{n-1}'s orbit (about ``centre``, radius ``r_M``) at heading
    ``th_dep`` (rad, leading to D_{n-1}'s slot), facing it, ``D`` plus ``early`` seconds of driving at
    ``v_N`` (um/s) from the tangent point."""
    tangent = pose_on_orbit(centre, r_M, th_dep)
    h = np.array([math.sin(th_dep), math.cos(th_dep)])
    return np.array([*(tangent[:2] + (D + v_N * early) * h), np.mod(th_dep + math.pi, TWO_PI)])


def framed_goals(nominal_goals: np.ndarray, L: np.ndarray, N: int, M: int, phi: float, dx: float, dy: float) -> np.ndarray:
    """The slots ``nominal_goals`` (n, 3) turned clockwise by ``phi`` (rad) about the G_1 junction (midpoint of
    D_n's and D_{n-1}'s front edges) and shifted by ``(dx, dy)`` um: a *pair frame* (a rigid motion of the
    whole structure, so its shape is unchanged)."""
    g = nominal_goals
    junction = 0.5 * (front_midpoints(g[[N]], L[[N]])[0] + front_midpoints(g[[M]], L[[M]])[0])
    out = se2.rotate_about(g, junction, phi)
    out[:, :2] += np.array([dx, dy])
    return out


def deepest_overlap(centres, rstar, i: int, others) -> tuple[int, float] | None:
    """``(j, depth_um)``: the robot ``j`` of ``others`` whose orbit disc (``centres`` (n, 2), radii ``rstar`` (n,), um)
    reaches deepest into robot ``i``'s, and how deep; None when none overlaps it.

    >>> deepest_overlap(np.array([[0.0, 0.0], [300.0, 0.0], [900.0, 0.0]]), np.array([200.0, 200.0, 200.0]), 0, [1, 2])
    (1, 100.0)
    """
    c = np.asarray(centres, float)
    r = np.asarray(rstar, float)
    js = np.asarray(list(others), dtype=int)
    if js.size == 0:
        return None
    depth = r[i] + r[js] - np.hypot(*(c[js] - c[i]).T)
    k = int(np.argmax(depth))
    return (int(js[k]), float(depth[k])) if depth[k] > 0.0 else None


def tight_discs(disc, wall_clearance_um: float, clearance_um: float) -> list:
    """Discs ``(centre, radius)`` shrunk so that obstacle checks at ``wall_clearance_um`` keep ``clearance_um``
    from them."""
    return [(c, r - wall_clearance_um + clearance_um) for c, r in disc]


def body_gap_along(track: np.ndarray, i: int, j: int, L, W) -> float:
    """The least gap (um; < 0: overlap) between robots ``i``'s and ``j``'s bodies along ``track`` ``(S, n, 3)`` (poses at
    the same instants: :meth:`~stressbots.control.loop.PlantLoop.predicted_track`); ``L``, ``W`` body lengths and widths
    (um) indexed like the robots. The gap is the separating-axis one (:func:`~stressbots.collision.penetration_depth`), at
    most the true distance.

    >>> track = np.zeros((3, 2, 3)); track[:, 0, 0] = [200.0, 67.0, 150.0]   # side by side, 7 um apart at the middle
    >>> round(body_gap_along(track, 0, 1, np.array([250.0, 250.0]), np.array([60.0, 60.0])), 6)
    7.0
    """
    depth = penetration_depth(track[:, i], L[i], W[i], track[:, j], L[j], W[j])
    return float(-np.max(depth))


def pressed_together(pose_N, body_N, pose_M, body_M, *, within_um: float, dt_s: float = 0.2) -> float | None:
    """The separation (um) of D_n's and D_{n-1}'s bodies when they are within ``within_um`` of each other and every
    primitive of the pair brings them closer at once, else None: P_n (both turn), P_{n-1} (D_n straight, D_{n-1}
    turns) and P_{n-2} (both straight), each driven ``dt_s`` s by exact kinematics. ``body_*`` = ``(length_um,
    width_um, speed_um_s, radius_um)``.

    Such a pair is wedged: no manoeuvre of G_1 separates it, and the plant stops bodies that push into each other.
    The failure message says so (issue 12, goal 6) instead of naming only the last stage that failed.

    >>> n, m = (237.8, 69.3, 144.9, 263.5), (286.3, 68.6, 143.1, 200.4)   # held-out 55:1 at 2x noise, t = 12 s
    >>> round(pressed_together(np.array([2382.2, 1866.1, 0.263]), n, np.array([2304.2, 1976.0, 4.151]), m, within_um=10.0))
    -6
    >>> body = (250.0, 60.0, 130.0, 200.0)   # side by side 4 um apart, heading opposite ways: they can slide apart
    >>> pressed_together(np.array([0.0, 0.0, 0.0]), body, np.array([64.0, 0.0, math.pi]), body, within_um=10.0) is None
    True
    """
    (L_N, W_N, v_N, r_N), (L_M, W_M, v_M, r_M) = body_N, body_M

    def sep(a, b) -> float:
        return -float(penetration_depth(np.asarray(a, float)[None], L_N, W_N, np.asarray(b, float)[None], L_M, W_M)[0])

    now = sep(pose_N, pose_M)
    if now > within_um:
        return None
    for k_N, k_M in ((1.0 / r_N, 1.0 / r_M), (0.0, 1.0 / r_M), (0.0, 0.0)):
        a = move(np.asarray(pose_N, float), np.array([v_N * dt_s]), k_N)[-1]
        b = move(np.asarray(pose_M, float), np.array([v_M * dt_s]), k_M)[-1]
        if sep(a, b) >= now:
            return None
    return now


def pair_can_keep_apart(pose_N, body_N, pose_M, body_M, *, horizon_s: float, floor_um: float) -> bool:
    """Whether one of the pair's primitives, P_n (both turn), P_{n-1} (D_n straight, D_{n-1} turns) or P_{n-2} (both
    straight), held ``horizon_s`` s from these poses by exact kinematics, keeps the bodies ``floor_um`` apart (or as
    far apart as they are, if closer already) throughout. ``body_*`` = ``(length_um, width_um, speed_um_s, radius_um)``.

    A pair that fails this is one step from :func:`pressed_together`: whatever G_1 drives next brings the bodies into
    each other within the horizon. Checked on the predicted end of a step before the step is driven, it stops a
    transfer leg while the pair still has a way apart (held-out 47:2 and 9:2 at 2x: D_{n-1} stopped its leg at the
    last instant, "would touch", 60 um from D_n with every primitive closing at 100 um/s, and G_1 gave up).

    >>> n, m = (236.7, 67.4, 97.6, 162.2), (269.7, 66.5, 128.3, 251.7)   # held-out 47:2 at 2x, t = 90.2 s
    >>> pair_can_keep_apart(np.array([1897.3, 1822.9, 0.811]), n, np.array([2036.9, 1636.5, 5.622]), m, horizon_s=3.0,
    ...                     floor_um=10.0)
    False
    >>> pair_can_keep_apart(np.array([1826.5, 1755.7, 0.811]), n, np.array([2115.7, 1535.2, 5.622]), m, horizon_s=3.0,
    ...                     floor_um=10.0)   # one second of both straight earlier
    True
    """
    (L_N, W_N, v_N, r_N), (L_M, W_M, v_M, r_M) = body_N, body_M
    ts = np.linspace(0.0, horizon_s, max(2, int(horizon_s / 0.1) + 1))
    pN, pM = np.asarray(pose_N, float), np.asarray(pose_M, float)
    now = -float(penetration_depth(pN[None], L_N, W_N, pM[None], L_M, W_M)[0])
    floor = min(floor_um, now - 1e-6)
    for k_N, k_M in ((1.0 / r_N, 1.0 / r_M), (0.0, 1.0 / r_M), (0.0, 0.0)):
        a = move(pN, v_N * ts, k_N)
        b = move(pM, v_M * ts, k_M)
        if (-penetration_depth(a, L_N, W_N, b, L_M, W_M) >= floor).all():
            return True
    return False


def approach_room(goals: np.ndarray, radii: np.ndarray, rstar: np.ndarray, arena_um, fine_distance_um: float,
                  robots, behind_radii: float = 1.0) -> float:
    """The least room (um) any of ``robots`` has to come round onto its approach in the arena: for each, the gap
    between the arena edge and its orbit disc (radius ``rstar``) about the point ``behind_radii`` turning radii behind
    the start of its fine motion (:func:`~stressbots.control.queries.fine_motion_length` behind its slot, straight
    back along the slot's heading). inf without an arena or robots. Negative: a robot there cannot circle inside the
    arena; one whose slot faces away from a nearby wall must arrive from that wall's side.

    Slots whose approach starts at or beyond the arena edge (tee stems ending near a wall, tuning layouts 89 and
    118: 0 of 4 trials at 1x) left the robot in a dead end between the structure and the wall, boxed in.

    >>> g = np.array([[1000.0, 1000.0, 0.0], [1000.0, 600.0, 0.0]])   # slot 1 faces up: its approach comes from below
    >>> round(approach_room(g, np.full(2, 200.0), np.full(2, 260.0), (2000.0, 2000.0), 200.0, [1]))   # 700 um back
    -360
    >>> round(approach_room(g, np.full(2, 200.0), np.full(2, 260.0), (2000.0, 2000.0), 200.0, [0]))
    40
    """
    if arena_um is None or len(robots) == 0:
        return math.inf
    w, h = arena_um
    idx = list(robots)
    g = np.asarray(goals, float)[idx]
    r = np.asarray(radii, float)[idx]
    back = fine_motion_length(r, fine_distance_um) + behind_radii * r
    q = g[:, :2] - back[:, None] * np.stack([np.sin(g[:, 2]), np.cos(g[:, 2])], axis=1)
    edge = np.min(np.stack([q[:, 0], w - q[:, 0], q[:, 1], h - q[:, 1]], axis=1), axis=1)
    return float((edge - np.asarray(rstar, float)[idx]).min())
