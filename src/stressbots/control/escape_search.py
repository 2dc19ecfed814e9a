"""D_n's way out when its orbit overlaps another: a searched turn-then-straight, checked body to body in time.

During G_1 every robot but D_n orbits in place under P_n and P_{n-1} (its pose is a known function of
time), while D_n turns (P_n) or runs straight (P_{n-1}). When D_n's own orbit comes to overlap another
robot's orbit disc (a track ending beside a lower orbit at 2x noise, a failed meeting), no path of the
pair phase from there is clear at its clearances, and turning "away" at once may sweep D_n into the other
body: the fixed escape then did nothing, and every pair frame failed at the same instant with nothing
moved (tuning layouts 19 and 47 at 1x, more at 2x). :func:`escape_manoeuvre` searches instead: every
turn of a ``turn_step_deg`` grid followed by a straight, D_n's body compared with every other body *at the
same instants* (they keep orbiting meanwhile), the arena edge and the docked bodies; the quickest that
leaves D_n's orbit disc the gaps it needs wins. Discs may overlap while bodies stay apart, so a way out
exists far more often than the disc test alone allows. A pure function of a snapshot.
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

from ..collision import arena_gap, penetration_depth, point_rectangle_distance
from ..kinematics import move
from ..robots import turning_centres

__all__ = ["Orbiting", "Manoeuvre", "orbit_slack", "escape_manoeuvre"]


class Orbiting(NamedTuple):
    """The robots orbiting in place meanwhile (m of them): measured poses (m, 3), speeds (um/s), turning
    radii (um), body lengths and widths (um), orbit-disc radii ``r*`` (um) and the gap (um) D_n's orbit disc
    needs from each one's."""

    poses: np.ndarray
    speeds: np.ndarray
    radii: np.ndarray
    lengths: np.ndarray
    widths: np.ndarray
    rstar: np.ndarray
    need: np.ndarray


class Manoeuvre(NamedTuple):
    """D_n runs straight (P_{n-1}) ``lead_s`` seconds, turns (P_n) ``turn_s`` seconds, then runs straight
    ``straight_s`` seconds; after it its orbit disc's smallest surplus over the gaps it needs is ``slack_um``
    (>= 0: clear)."""

    lead_s: float
    turn_s: float
    straight_s: float
    slack_um: float

    @property
    def total_s(self) -> float:
        """Duration of the whole manoeuvre (s)."""
        return self.lead_s + self.turn_s + self.straight_s


def orbit_slack(centres, rstar: float, others: Orbiting, arena_um, edge_need: float, docked=None) -> np.ndarray:
    """Smallest surplus (um, (K,)) of orbit discs about ``centres`` (K, 2), radius ``rstar``, over the gaps they
    need: ``others.need`` from each orbiting robot's disc, ``edge_need`` from the arena edge ``(w, h)`` (None:
    unbounded) and from the docked bodies ``docked = (poses, L, W)``.

    >>> o = Orbiting(np.array([[0.0, 0.0, 0.0]]), np.array([10.0]), np.array([100.0]), np.array([200.0]), np.array([50.0]),
    ...              np.array([150.0]), np.array([25.0]))
    >>> float(orbit_slack(np.array([[600.0, 0.0]]), 150.0, o, None, 40.0)[0])  # its centre (100, 0): 500 - 150 - 150 - 25
    175.0
    """
    c = np.atleast_2d(np.asarray(centres, dtype=np.float64))
    slack = np.full(len(c), np.inf)
    if len(others.poses):
        oc = turning_centres(others.poses, others.radii)
        d = np.hypot(*(c[:, None, :] - oc[None]).transpose(2, 0, 1))
        slack = np.minimum(slack, (d - rstar - others.rstar[None, :] - others.need[None, :]).min(axis=1))
    if arena_um is not None:
        w, h = arena_um
        edge = np.min(np.stack([c[:, 0], w - c[:, 0], c[:, 1], h - c[:, 1]], axis=1), axis=1)
        slack = np.minimum(slack, edge - rstar - edge_need)
    if docked is not None and len(docked[0]):
        for p, Lj, Wj in zip(*docked, strict=True):
            slack = np.minimum(slack, point_rectangle_distance(c, np.asarray(p)[None, :], Lj, Wj)[:, 0] - rstar - edge_need)
    return slack


def _collides(mine: np.ndarray, t: np.ndarray, L: float, W: float, others: Orbiting, body_floor: np.ndarray, arena_um,
              edge_floor: float, docked, docked_floor: float) -> np.ndarray:
    """Mask (S,): D_n's body at ``mine`` (S, 3) at times ``t`` (S,) comes within ``body_floor[j]`` of orbiting body
    j at the same instant, within ``edge_floor`` of the arena edge, or within ``docked_floor`` of a docked body."""
    s = len(mine)
    hit = np.zeros(s, dtype=bool)
    # every orbiting body (and below, every docked one) against every sample in one call: the same pairs, so the
    # same depths, without a call per body (this runs ~40,000 times in a failing G_1 phase)
    k = len(others.poses)
    if k:
        theirs = move(others.poses[:, None, :], others.speeds[:, None] * t[None, :], (1.0 / others.radii)[:, None])
        depth = penetration_depth(np.tile(mine, (k, 1)), L, W, theirs.reshape(-1, 3), np.repeat(others.lengths, s),
                                  np.repeat(others.widths, s)).reshape(k, s)
        hit |= (depth > -np.asarray(body_floor, dtype=np.float64)[:, None]).any(axis=0)
    if arena_um is not None:
        hit |= arena_gap(mine, L, W, arena_um) < edge_floor
    if docked is not None and len(docked[0]):
        poses_d = np.atleast_2d(np.asarray(docked[0], dtype=np.float64))
        b = len(poses_d)
        depth = penetration_depth(np.tile(mine, (b, 1)), L, W, np.repeat(poses_d, s, axis=0),
                                  np.repeat(np.asarray(docked[1], dtype=np.float64), s),
                                  np.repeat(np.asarray(docked[2], dtype=np.float64), s)).reshape(b, s)
        hit |= (depth > -docked_floor).any(axis=0)
    return hit


def escape_manoeuvre(pose, speed: float, radius: float, L: float, W: float, rstar: float, others: Orbiting, arena_um, *,
                     edge_need: float, body_clearance: float, edge_clearance: float, docked=None, turn_step_deg: float = 15.0,
                     max_straight_um: float = 900.0, sample_um: float = 20.0, min_gain_um: float = 20.0,
                     lead_ins_um: tuple[float, ...] = (0.0, 60.0, 120.0)) -> Manoeuvre | None:
    """The quickest (straight-)turn-straight that takes D_n's orbit clear (:func:`orbit_slack` >= 0); None when none.

    D_n (``pose``, ``speed`` um/s, turning ``radius`` and orbit disc ``rstar`` um, body ``L`` x ``W``) runs
    straight each of ``lead_ins_um`` first (0: none), turns
    clockwise by each multiple of ``turn_step_deg`` below a full loop, then drives straight up to
    ``max_straight_um`` (sampled every ``sample_um``); the ``others`` orbit meanwhile. A candidate counts only
    while D_n's body stays ``body_clearance`` from every other body at the same instant and from the docked
    bodies, and ``edge_clearance`` from the arena edge (or its present gap, if smaller: it is there already).
    When no candidate clears every gap, the one with the largest slack is returned if that gains at least
    ``min_gain_um`` over the present slack (a step out of the overlap; the caller searches again from there).

    >>> o = Orbiting(np.array([[0.0, 0.0, 0.0]]), np.array([10.0]), np.array([100.0]), np.array([200.0]), np.array([50.0]),
    ...              np.array([150.0]), np.array([25.0]))
    >>> pose = np.array([150.0, 150.0, 1.0])  # its orbit disc overlaps the other's by ~200 um
    >>> round(float(orbit_slack(turning_centres(pose, 100.0), 150.0, o, None, 40.0)[0]))
    -202
    >>> m = escape_manoeuvre(pose, 10.0, 100.0, 200.0, 50.0, 150.0, o, None, edge_need=40.0, body_clearance=10.0,
    ...                      edge_clearance=10.0)
    >>> m.turn_s, m.straight_s, m.slack_um >= 0.0  # straight on for 220 um takes it clear
    (0.0, 22.0, True)
    """
    pose = np.asarray(pose, dtype=np.float64)
    now = float(orbit_slack(turning_centres(pose, radius), rstar, others, arena_um, edge_need, docked)[0])
    # what D_n is closer to already (it is there) it may stay as close to, never closer
    edge_floor = edge_clearance
    if arena_um is not None:
        edge_floor = min(edge_clearance, float(arena_gap(pose[None, :], L, W, arena_um)[0]) - 1e-6)
    sep = np.array([-float(penetration_depth(pose[None, :], L, W, others.poses[j][None, :], others.lengths[j], others.widths[j])[0])
                    for j in range(len(others.poses))])
    body_floor = np.minimum(body_clearance, sep - 1e-6)
    col = (others, body_floor, arena_um, edge_floor, docked, body_clearance)
    s_run = np.arange(0.0, max_straight_um + 1e-9, sample_um)
    best: tuple[float, Manoeuvre] | None = None
    fallback: Manoeuvre | None = None
    for m, clear in _candidates(pose, speed, radius, L, W, rstar, others, arena_um, edge_need, docked, col, s_run,
                                lead_ins_um=lead_ins_um, turn_step_deg=turn_step_deg, sample_um=sample_um):
        if clear:
            if best is None or m.total_s < best[0]:
                best = (m.total_s, m)
        elif m.slack_um >= now + min_gain_um and (fallback is None or m.slack_um > fallback.slack_um):
            fallback = m
    return best[1] if best is not None else fallback


def _candidates(pose: np.ndarray, speed: float, radius: float, L: float, W: float, rstar: float, others: Orbiting, arena_um,
                edge_need: float, docked, col: tuple, s_run: np.ndarray, *, lead_ins_um: tuple[float, ...], turn_step_deg: float,
                sample_um: float) -> Iterator[tuple[Manoeuvre, bool]]:
    """The candidates of :func:`escape_manoeuvre`'s search, lazily, each with whether it takes D_n's orbit clear: for
    each lead-in (um) and each clockwise turn on the ``turn_step_deg`` (deg) grid whose sweep keeps the clearances
    (``col``: :func:`_collides`'s arguments after the body's size), the straight of ``s_run`` (um along it) that clears
    D_n's orbit soonest, else the one with the largest :func:`orbit_slack` (um) before D_n's body first comes too close."""
    for lead in lead_ins_um:
        # a short straight first: the body beside D_n's turn may be gone by the time it turns
        s_lead = np.arange(0.0, lead + 1e-9, sample_um) if lead > 0 else np.zeros(1)
        pre = move(pose, s_lead, 0.0)
        if lead > 0 and _collides(pre, s_lead / speed, L, W, *col).any():
            continue
        t0 = float(s_lead[-1] / speed)
        for a in np.radians(np.arange(0.0, 360.0 - 1e-9, turn_step_deg)):
            s_arc = np.linspace(0.0, a * radius, max(2, int(math.degrees(a) / 5.0) + 2))
            arc = move(pre[-1], s_arc, 1.0 / radius)
            t_arc = t0 + s_arc / speed
            if _collides(arc, t_arc, L, W, *col).any():
                continue
            run = move(arc[-1], s_run, 0.0)
            hit = _collides(run, t_arc[-1] + s_run / speed, L, W, *col)
            free = len(run) if not hit.any() else int(np.argmax(hit))
            if free == 0:
                continue
            slack = orbit_slack(turning_centres(run[:free], radius), rstar, others, arena_um, edge_need, docked)
            ok = np.flatnonzero(slack >= 0.0)
            k = int(ok[0]) if len(ok) else int(np.argmax(slack))
            m = Manoeuvre(t0, float(t_arc[-1] - t0), float(s_run[k] / speed), float(slack[k]))
            yield m, bool(len(ok))
