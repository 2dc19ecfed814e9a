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
from ..robots import TWO_PI, angle_difference, front_midpoints
from .queries import pose_on_orbit

__all__ = ["approach_pose", "framed_goals", "frames_apart", "meet_distance", "station_centre", "tight_discs"]


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


def tight_discs(disc, wall_clearance_um: float, clearance_um: float) -> list:
    """Discs ``(centre, radius)`` shrunk so that obstacle checks at ``wall_clearance_um`` keep ``clearance_um``
    from them."""
    return [(c, r - wall_clearance_um + clearance_um) for c, r in disc]
