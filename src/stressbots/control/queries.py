"""Pure geometric queries of the closed loop: plain arrays in, numbers out (no plant, no state).

Every function here is a function of poses and robot parameters only, so it can be tested on
hand-built snapshots. Poses are ``(x_um, y_um, theta_rad)`` with theta clockwise from +y (SPEC 2).
"""

from __future__ import annotations

import math

import numpy as np

from .. import paths as pathlib
from ..robots import TWO_PI, angle_difference

__all__ = ["fine_motion_length", "turn_fraction", "trim_steps", "pose_on_orbit", "line_pose", "line_coords", "merge", "in_funnel",
           "in_corridor", "best_departure", "meeting_cost", "interpolated_steps", "pose_region", "waypoint_region",
           "shortest_into"]


def fine_motion_length(r, fine_distance_um: float):
    """How far behind its slot (um) a robot of turning radius ``r`` (um, scalar or array) starts its fine motion:
    ``s_f = min(2.5 r, 3 fine_distance_um)`` (:func:`~stressbots.control.slot_approach.fine_start`).

    >>> float(fine_motion_length(200.0, 200.0)), fine_motion_length(np.array([200.0, 300.0]), 200.0).tolist()
    (500.0, [500.0, 600.0])
    """
    return np.minimum(2.5 * np.asarray(r, float), 3.0 * fine_distance_um)


def turn_fraction(pose: np.ndarray, point: np.ndarray, r: float, lateral_tol_um: float = 3.0):
    """Fraction of time to turn (rho) so that an interpolated arc from ``pose`` passes through ``point``.

    Returns ``(rho, arc_length_um, arrival_heading)`` or None when no clockwise arc of radius >= r
    reaches the point (it is behind, or left of the heading by more than ``lateral_tol_um``): the
    robot then needs gross motion (a loop) first. A point straight ahead within the tolerance gives
    rho = 0 (rounding must not turn "straight ahead" into "unreachable").
    """
    d = np.asarray(point[:2], float) - pose[:2]
    th = float(pose[2])
    along = d[0] * math.sin(th) + d[1] * math.cos(th)
    right = d[0] * math.cos(th) - d[1] * math.sin(th)
    if along <= 0.0 or right < -lateral_tol_um:
        return None
    if abs(right) <= lateral_tol_um:
        return 0.0, float(np.hypot(*d)), th
    arc = pathlib.arc_through(pose, point[:2])
    if not np.isfinite(arc.length_um) or arc.radius_um < r:
        return None
    return float(r / arc.radius_um), float(arc.length_um), th + float(arc.turn_rad)


def trim_steps(steps, total_s: float):
    """The first ``total_s`` seconds of primitive steps ``(k, duration_s)``."""
    out, left = [], total_s
    for k, d in steps:
        if left <= 1e-12:
            break
        out.append((k, min(d, left)))
        left -= min(d, left)
    return out


def pose_on_orbit(centre, radius_um: float, theta: float) -> np.ndarray:
    """The pose with heading ``theta`` on the clockwise orbit about ``centre`` (inverse of the turning centre)."""
    c = np.asarray(centre, dtype=np.float64)
    return np.array([c[0] - radius_um * math.cos(theta), c[1] + radius_um * math.sin(theta), float(np.mod(theta, TWO_PI))])


def line_pose(goal, back: float, right: float, dtheta: float) -> np.ndarray:
    """The pose ``back`` um behind ``goal`` on its approach line, ``right`` um to its right, turned by ``dtheta``."""
    th = float(goal[2])
    h = np.array([math.sin(th), math.cos(th)])
    rt = np.array([math.cos(th), -math.sin(th)])
    xy = np.asarray(goal[:2], float) - back * h + right * rt
    return np.array([xy[0], xy[1], float(np.mod(th + dtheta, TWO_PI))])


def pose_region(target, along_um, right_um, turn_rad) -> np.ndarray:
    """Goals ``(K, 3)`` around the pose ``target``: every ``s`` of ``along_um`` ahead of it (um, along its heading), ``e``
    of ``right_um`` to its right (um) and ``d`` of ``turn_rad`` clockwise (rad); the first of each sequence varies
    slowest, so with all three starting at 0 the first goal is ``target`` itself.

    >>> g = pose_region((0.0, 0.0, 0.0), (0.0, 10.0), (0.0, -5.0), (0.0,))
    >>> g.round(6).tolist()
    [[0.0, 0.0, 0.0], [-5.0, 0.0, 0.0], [0.0, 10.0, 0.0], [-5.0, 10.0, 0.0]]
    """
    q = np.asarray(target, dtype=np.float64)
    th = float(q[2])
    s, e, d = (g.ravel() for g in np.meshgrid(np.asarray(along_um, float), np.asarray(right_um, float), np.asarray(turn_rad, float),
                                              indexing="ij"))
    return np.stack([q[0] + s * math.sin(th) + e * math.cos(th), q[1] + s * math.cos(th) - e * math.sin(th),
                     np.mod(th + d, TWO_PI)], axis=1)


def waypoint_region(target, tuning) -> np.ndarray:
    """The goals ``(K, 3)`` a gross motion to the waypoint ``target`` may head for (:func:`pose_region`:
    ``Tuning.waypoint_region_um`` ahead, behind, left and right, ``Tuning.waypoint_region_deg`` either way; ``target``
    first).

    >>> from stressbots.control import Tuning
    >>> g = waypoint_region((0.0, 0.0, 0.0), Tuning())
    >>> g.shape, g[0].tolist()
    ((27, 3), [0.0, 0.0, 0.0])
    """
    um, rad = tuning.waypoint_region_um, math.radians(tuning.waypoint_region_deg)
    return pose_region(target, (0.0, -um, um), (0.0, -um, um), (0.0, -rad, rad))


def shortest_into(start, goals, r: float, min_saving_um: float) -> int:
    """Index of the goal of ``goals`` (``(K, 3)``, the target first) a one-way robot at ``start`` (turning radius ``r``, um)
    heads for: the one of the shortest path, when that saves at least ``min_saving_um`` (um) on the path to the target
    (``goals[0]``), else 0.

    A region is the target of a re-planned gross motion (the seed's regions A_i, not points): a robot whose turning
    circle passes a few um on the wrong side of its target's needs a loop more to reach it, and re-planned every t_x
    under speed and radius error it met the same miss at the end of each loop (held-out 33:1 at 2x circled a waypoint
    for 57 s). A nearby goal of the region then needs no loop; elsewhere the target itself is kept (saving less than
    ``min_saving_um``: about half a loop).

    >>> goals = pose_region((0.0, 300.0, 0.0), (0.0,), (0.0,), (0.0, math.radians(3.0)))  # the target; 3 deg clockwise
    >>> shortest_into((0.0, 0.0, 0.0), goals, 100.0, 300.0)  # straight ahead: the target itself
    0
    >>> shortest_into((-4.0, 0.0, 0.0), goals, 100.0, 300.0)  # 4 um left of its line: a loop to the target, none to goal 1
    1
    """
    lengths = pathlib.shortest_path_lengths(np.asarray(start, float)[None, :], np.asarray(goals, float), r)
    best = int(np.argmin(lengths))
    return best if lengths[0] - lengths[best] >= min_saving_um else 0


def line_coords(goal, pose) -> tuple[float, float, float]:
    """``(behind_um, right_um, psi_rad)`` of ``pose`` relative to the approach line of the slot ``goal``.

    The approach line runs back from the slot along its heading; ``behind`` is measured back along it,
    ``right`` to the slot's right, ``psi`` the heading relative to the slot's (positive = clockwise).
    Inverse of :func:`line_pose`: ``line_coords(goal, line_pose(goal, b, r, d)) == (b, r, d)``.
    """
    goal = np.asarray(goal, dtype=np.float64)
    th = float(goal[2])
    d = np.asarray(pose, dtype=np.float64)[:2] - goal[:2]
    h = np.array([math.sin(th), math.cos(th)])
    rt = np.array([math.cos(th), -math.sin(th)])
    return float(-(d @ h)), float(d @ rt), float(angle_difference(pose[2], th))


def merge(behind: float, right: float, psi: float, r: float, min_left_um: float = 60.0):
    """The merge onto the approach line from ``(right, psi)``: ``(straight_um, radius_um)``, or None.

    From the line's right, pointing left of it, the robot drives straight, then an interpolated
    clockwise arc of radius >= r that ends on the line, parallel to it. Returns None when no such merge
    ends at least ``min_left_um`` before the slot (then the robot must loop). ``r``: the robot's
    (identified) turning radius, um.
    """
    if psi >= -1e-6:
        return None
    c = 1.0 - math.cos(psi)
    if right - r * c < -5.0:
        return None  # even the tightest arc ends more than 5 um left of the line
    if right - r * c <= 0.0:
        R = r  # flatten now: the tightest arc, ending (slightly) left of the line
    else:
        R = min(1.5 * r, right / c) if c > 1e-12 else 1.5 * r
        R = max(R, r)
    s1 = max(0.0, (right - R * c) / math.sin(-psi))
    used = s1 * math.cos(psi) + R * math.sin(-psi)
    if used > behind - min_left_um:
        return None
    return s1, R


def in_funnel(behind: float, right: float, psi: float, back: float, r: float, tuning) -> bool:
    """Whether a robot at line coordinates ``(behind, right, psi)`` is in the approach funnel of a corridor
    ``back`` um long: within the funnel's bounds (:class:`~stressbots.control.tuning.Tuning`; pointing at most
    ``Tuning.funnel_psi_deg`` left of the line), and able to merge onto the line even if it points
    ``merge_heading_margin_deg`` less to the left than measured (or already on the line, aligned)."""
    if (not (tuning.funnel_min_behind_um <= behind <= back + tuning.funnel_extra_um) or right > tuning.funnel_right_um
            or right < -2.0 or psi < -math.radians(tuning.funnel_psi_deg)):
        return False
    if abs(right + behind * math.sin(psi)) <= 3.0 and abs(psi) <= math.radians(1.0) and abs(right) <= 5.0:
        return True
    return merge(behind, right, psi + math.radians(tuning.merge_heading_margin_deg), r) is not None


def in_corridor(behind: float, right: float, psi: float, back: float, tuning) -> bool:
    """Whether a robot at line coordinates ``(behind, right, psi)`` (um, um, rad) is already *in* the approach
    corridor of a ``back`` um long line, heading along it: between the funnel's nearest and farthest
    distances behind the slot, no more than ``Tuning.funnel_right_um`` right of the line, within
    ``Tuning.corridor_psi_deg`` of its heading, and heading for a lateral miss at the slot
    (``right + behind tan(psi)``) within ``Tuning.corridor_miss_um`` either way. The line approach takes such
    a robot from there (clockwise bursts fix a left miss, a right one is driven in or looped back where a
    loop is free); gross motion cannot: its aim lies behind the robot, and the loop back to it meets the
    structure, so it gave up (six times) a robot already on its line.

    >>> from stressbots.control.tuning import Tuning
    >>> in_corridor(300.0, 14.0, math.radians(-4.0), 450.0, Tuning()), in_corridor(300.0, 14.0, math.radians(30.0), 450.0, Tuning())
    (True, False)
    """
    if not (tuning.funnel_min_behind_um <= behind <= back + tuning.funnel_extra_um) or right > tuning.funnel_right_um:
        return False
    if abs(psi) > math.radians(tuning.corridor_psi_deg):
        return False
    return abs(right + behind * math.tan(psi)) <= tuning.corridor_miss_um


def best_departure(pN, vN: float, LN: float, cM, rM: float, thM: float, wM: float, vM: float, LM: float, rstarM: float, cost_max: float):
    """``(wait_s, cost)`` of D_{n-1}'s best departure heading, given D_n's measured line; None if none fits.

    For each candidate heading within 20 deg of facing D_n, D_{n-1} leaves its orbit at the tangent
    point; both then drive straight. The cost is the larger of |w_y| / 80 um and |alpha| / 60 deg at the
    moment the front edges meet (the self-alignment limits); only departures within the next period
    before D_n reaches D_{n-1}'s orbit count.

    Inputs are D_n's pose ``pN``, speed and length; D_{n-1}'s orbit centre ``cM``, radius ``rM``, current
    heading ``thM``, turn rate ``wM`` (rad/s), speed, length and orbit-disc radius ``rstarM``.
    """
    th = np.mod(pN[2] + math.pi + np.radians(np.arange(-20.0, 20.01, 0.5)), TWO_PI)
    wait = np.mod(th - thM, TWO_PI) / wM
    # D_n after the wait (straight), D_{n-1} at its tangent point
    hN = np.array([math.sin(pN[2]), math.cos(pN[2])])
    fN = pN[:2] + (0.5 * LN + vN * wait)[:, None] * hN  # D_n's front midpoint at departure
    pM = cM[None, :] - rM * np.stack([np.cos(th), -np.sin(th)], axis=1)
    hM = np.stack([np.sin(th), np.cos(th)], axis=1)
    fM = pM + 0.5 * LM * hM
    rel = fN - fM
    closing = vM + vN * (-(hN[None, :] * hM).sum(axis=1))
    gap_along = (rel * hM).sum(axis=1)
    t_meet = gap_along / np.maximum(closing, 1e-9)
    fN_meet = fN + vN * t_meet[:, None] * hN
    fM_meet = fM + vM * t_meet[:, None] * hM
    right = np.stack([np.cos(th), -np.sin(th)], axis=1)
    w_y = np.abs(((fN_meet - fM_meet) * right).sum(axis=1))
    alpha = np.abs(np.degrees(angle_difference(th, pN[2] + math.pi)))
    # D_n must still be outside the orbit disc when D_{n-1} leaves
    clear = np.hypot(*(fN - cM).T) > rstarM + 10.0
    ok = clear & (gap_along > 0) & (closing > 0)
    cost = np.maximum(w_y / 80.0, alpha / 60.0)
    cost = np.where(ok, cost, np.inf)
    j = int(np.argmin(cost))
    if not np.isfinite(cost[j]) or cost[j] > cost_max:
        return None
    return float(wait[j]), float(cost[j])


def meeting_cost(pN, vN: float, LN: float, pM, vM: float, LM: float) -> float | None:
    """Cost of D_n and D_(n-1) meeting as they are: both drive straight from the measured poses ``pN``, ``pM``
    (um, rad) at speeds ``vN``, ``vM`` (um/s); the larger of |w_y| / 80 um and |alpha| / 60 deg when the front
    edges meet, as in :func:`best_departure` (the self-alignment limits). None when their fronts are not closing
    on each other (D_n's front behind D_(n-1)'s, or the gap opening).

    >>> round(meeting_cost(np.array([0.0, 0.0, 0.0]), 100.0, 200.0, np.array([30.0, 400.0, np.pi]), 100.0, 200.0), 3)
    0.375
    >>> meeting_cost(np.array([0.0, 0.0, np.pi]), 100.0, 200.0, np.array([0.0, 400.0, 0.0]), 100.0, 200.0) is None  # back to back
    True
    """
    hN = np.array([math.sin(pN[2]), math.cos(pN[2])])
    hM = np.array([math.sin(pM[2]), math.cos(pM[2])])
    fN = np.asarray(pN, float)[:2] + 0.5 * LN * hN
    fM = np.asarray(pM, float)[:2] + 0.5 * LM * hM
    closing = vM + vN * float(-(hN @ hM))
    gap_along = float((fN - fM) @ hM)
    if closing <= 0.0 or gap_along <= 0.0:
        return None
    t_meet = gap_along / closing
    right = np.array([math.cos(pM[2]), -math.sin(pM[2])])
    w_y = abs(float(((fN + vN * t_meet * hN) - (fM + vM * t_meet * hM)) @ right))
    alpha = abs(math.degrees(float(angle_difference(pM[2], pN[2] + math.pi))))
    return max(w_y / 80.0, alpha / 60.0)


def interpolated_steps(rho_turn: float, duration: float, turn_k: int, straight_k: int, period_s: float) -> list[tuple[int, float]]:
    """S_2f for ``duration`` s: symmetric cycles (half turn, straight, half turn) with turn fraction ``rho_turn``.

    The mean radius is ``r / rho_turn`` (SPEC 8); cycles last at most ``period_s``.

    >>> interpolated_steps(0.5, 0.4, 3, 2, 0.2)
    [(3, 0.05), (2, 0.1), (3, 0.05), (3, 0.05), (2, 0.1), (3, 0.05)]
    """
    if rho_turn >= 0.995:
        return [(turn_k, duration)]
    if rho_turn <= 0.005:
        return [(straight_k, duration)]
    cycles = max(1, math.ceil(duration / period_s - 1e-9))
    T = duration / cycles
    out: list[tuple[int, float]] = []
    for _ in range(cycles):
        out += [(turn_k, 0.5 * rho_turn * T), (straight_k, (1 - rho_turn) * T), (turn_k, 0.5 * rho_turn * T)]
    return out
