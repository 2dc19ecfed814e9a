"""Fine motion of the seed's two-step EDR strategy (seed App. 3.1, SPEC 8): pure functions.

Fine motion replaces a point-to-point path by *interpolated turning*: alternating a turning and a
straight primitive makes a robot follow, on average, a clockwise arc of radius ``r' >= r``. The seed
uses it from an intermediate configuration ``a_i`` to the docking point ``p_g,i``:

- **eq. (1), corrected** (SPEC 8: ``dy = y_g - y_a``): the one clockwise arc from ``a_i`` through
  ``p_g,i`` has radius ``r' = (dx^2 + dy^2) / (2 (dx cos theta_a - dy sin theta_a))``
  (:func:`stressbots.paths.arc_through`);
- **S_2f** (single robots): ``P_i`` (turning) for a fraction ``rho_a`` of every switching period and
  ``P_(i-1)`` (straight) for ``rho_b = 1 - rho_a``: ``r' = r (1 + rho_b / rho_a)`` (SPEC 8; the seed
  prints the ratio upside down), so ``rho_a = r / r'`` (:func:`s2f_duty`, :func:`s2f_steps`);
- **S_3f** (the G_1 pair): ``P_n``, ``P_(n-1)``, ``P_(n-2)`` for ``rho_a``, ``rho_b``, ``rho_c``. D_n turns
  only under ``P_n``, D_(n-1) under ``P_n`` and ``P_(n-1)``, so (eqs. 2-3 corrected)
  ``r'_n = r_n (1 + (rho_b + rho_c) / rho_a)`` and ``r'_(n-1) = r_(n-1) (1 + rho_c / (rho_a + rho_b))``
  (:func:`s3f_duty`, :func:`s3f_radii`, :func:`s3f_steps`). Both radii are set by one duty triple, so the
  pair's arcs are feasible only when ``r_n / r'_n <= r_(n-1) / r'_(n-1) <= 1``.

Fractions are of time, equal to fractions of distance since a robot's speed is the same in both arm
states. The step lists use *symmetric* cycles (half the turning at each end of a period): then each
cycle ends on the ideal arc (:func:`stressbots.paths.interpolated_arc`), whatever the period.

Everything is in um, s and rad (heading clockwise from +y, SPEC 2). Step lists are
``[(k, duration_s), ...]`` with ``k`` the primitive index (``P_k``).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import paths
from .kinematics import move

__all__ = ["S2f", "s2f_duty", "s2f_steps", "s3f_duty", "s3f_radii", "s3f_steps", "arc_back"]

_STRAIGHT_RHO = 1e-9
"""A turning fraction below this is a straight line (a point dead ahead: r' = inf)."""


class S2f(NamedTuple):
    """The S_2f arc from a pose through a point: duty, radius (um), length (um), arrival heading (rad)."""

    rho_a: float
    rho_b: float
    radius_um: float
    length_um: float
    arrival_rad: float


def s2f_duty(pose, point, radius_um: float) -> S2f | None:
    """The S_2f duty that takes a robot of turning radius ``radius_um`` from ``pose`` through ``point``.

    Eq. (1) gives the arc's radius ``r'``; the corrected duty relation gives ``rho_a = r / r'``. None when
    no clockwise arc of radius ``>= r`` passes through the point (it lies to the left, behind, or too
    sharply to the right: outside the S_2f cone of seed Fig. 4a).

    Examples
    --------
    >>> d = s2f_duty((0.0, 0.0, 0.0), (400.0, 400.0), 200.0)   # quarter turn on a 400 um circle
    >>> round(d.rho_a, 6), round(d.radius_um, 6), round(d.arrival_rad, 6)
    (0.5, 400.0, 1.570796)
    """
    arc = paths.arc_through(pose, point)
    r_prime = float(arc.radius_um)
    if math.isnan(r_prime) or r_prime < radius_um * (1.0 - 1e-12):
        return None
    rho_a = 0.0 if math.isinf(r_prime) else min(1.0, radius_um / r_prime)
    return S2f(rho_a, 1.0 - rho_a, r_prime, float(arc.length_um), float(pose[2]) + float(arc.turn_rad))


def _cycles(duration_s: float, period_s: float) -> tuple[int, float]:
    count = max(1, math.ceil(duration_s / period_s - 1e-9))
    return count, duration_s / count


def s2f_steps(rho_a: float, duration_s: float, period_s: float, turn_k: int, straight_k: int) -> list[tuple[int, float]]:
    """S_2f for ``duration_s``: cycles ``P_i (rho_a T / 2), P_(i-1) (rho_b T), P_i (rho_a T / 2)``.

    ``T <= period_s`` divides the duration evenly. A duty of 0 or 1 is a single straight or turn.
    """
    if duration_s <= 0.0:
        return []
    if rho_a >= 1.0 - _STRAIGHT_RHO:
        return [(turn_k, duration_s)]
    if rho_a <= _STRAIGHT_RHO:
        return [(straight_k, duration_s)]
    count, T = _cycles(duration_s, period_s)
    half = 0.5 * rho_a * T
    return [step for _ in range(count) for step in ((turn_k, half), (straight_k, (1.0 - rho_a) * T), (turn_k, half))]


def s3f_radii(rhos, radius_n_um: float, radius_nm1_um: float) -> tuple[float, float]:
    """Eqs. (2)-(3), corrected: ``(r'_n, r'_(n-1))`` of S_3f(rho_a, rho_b, rho_c) (inf = straight)."""
    a, b, c = (float(x) for x in rhos)
    r_n = math.inf if a <= _STRAIGHT_RHO else radius_n_um * (1.0 + (b + c) / a)
    r_m = math.inf if a + b <= _STRAIGHT_RHO else radius_nm1_um * (1.0 + c / (a + b))
    return r_n, r_m


def s3f_duty(radius_n_um: float, r_prime_n: float, radius_nm1_um: float, r_prime_nm1: float) -> tuple[float, float, float] | None:
    """The S_3f duty ``(rho_a, rho_b, rho_c)`` that gives D_n radius ``r'_n`` and D_(n-1) ``r'_(n-1)``.

    Inverting eqs. (2)-(3): ``rho_a = r_n / r'_n`` and ``rho_a + rho_b = r_(n-1) / r'_(n-1)``; None when
    that needs ``rho_b < 0`` (D_n would have to turn more than D_(n-1)) or a radius below the robot's own.

    Examples
    --------
    >>> [round(x, 6) for x in s3f_duty(200.0, 600.0, 200.0, 300.0)]   # S_3f(sym)
    [0.333333, 0.333333, 0.333333]
    """
    if r_prime_n < radius_n_um * (1.0 - 1e-12) or r_prime_nm1 < radius_nm1_um * (1.0 - 1e-12):
        return None
    a = 0.0 if math.isinf(r_prime_n) else radius_n_um / r_prime_n
    ab = 0.0 if math.isinf(r_prime_nm1) else radius_nm1_um / r_prime_nm1
    if a > ab + 1e-12:
        return None
    a, ab = min(a, 1.0), min(max(ab, a), 1.0)
    return a, ab - a, 1.0 - ab


def s3f_steps(rhos, duration_s: float, period_s: float, n: int) -> list[tuple[int, float]]:
    """S_3f for ``duration_s``: symmetric cycles ``P_n a/2, P_(n-1) b/2, P_(n-2) c, P_(n-1) b/2, P_n a/2``.

    Both robots' motion is then symmetric within each cycle (D_n: turn, straight, turn; D_(n-1) the
    same with its longer turns), so each cycle ends on both ideal arcs.
    """
    if duration_s <= 0.0:
        return []
    a, b, c = (float(x) for x in rhos)
    count, T = _cycles(duration_s, period_s)
    cycle = [(n, 0.5 * a * T), (n - 1, 0.5 * b * T), (n - 2, c * T), (n - 1, 0.5 * b * T), (n, 0.5 * a * T)]
    cycle = [(k, d) for k, d in cycle if d > 1e-12]
    return [step for _ in range(count) for step in cycle]


def arc_back(goal, length_um, r_prime_um: float) -> np.ndarray:
    """Poses ``length_um`` back along the clockwise arc of radius ``r'`` that ends in ``goal``.

    The intermediate configuration ``a_i`` of a nominal fine motion: from it, the S_2f/S_3f arc of radius
    ``r'`` arrives at the goal with the goal's heading. Vectorised over ``length_um``.
    """
    kappa = 0.0 if math.isinf(r_prime_um) else 1.0 / r_prime_um
    return move(np.asarray(goal, dtype=np.float64), -np.asarray(length_um, dtype=np.float64), kappa)
