"""Moving D_{n-1}'s orbit to its station: a route of straight legs between free orbit centres.

Under P_n and P_{n-1} D_{n-1} orbits in place; under P_{n-2} it drives straight. So its orbit moves in
straight *legs*: it orbits until it heads along the leg, then drives straight, and its turning centre
moves by the same vector as its body. The body stays inside its orbit disc (radius ``r*``) carried along
the leg, so a leg is clear when the *capsule* of radius ``r*`` around the segment between the two centres
keeps clear of the other orbits and the arena edge. One straight leg to the station is what the
controller tried first; when another robot's orbit lies across it, every pair frame failed with "the
straight move to its station orbit is blocked". :func:`orbit_route` finds a few legs instead, through
free orbit centres on a grid (shortest total length plus a cost per leg, Dijkstra on the visibility
graph of the grid), a pure function of the measured orbits.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from ..collision import arena_gap
from ..robots import turning_centres

__all__ = ["Body", "segment_disc_gaps", "legs_clear", "swept_legs_clear", "orbit_route", "orbit_room"]


def segment_disc_gaps(a, b, centres, radii) -> np.ndarray:
    """Gaps (E, K): distance from each segment ``a[e]``-``b[e]`` (E, 2) to each disc (K) minus its radius (um).

    >>> g = segment_disc_gaps(np.array([[0.0, 0.0]]), np.array([[100.0, 0.0]]), np.array([[50.0, 30.0]]), np.array([10.0]))
    >>> float(g[0, 0])
    20.0
    """
    a = np.atleast_2d(np.asarray(a, float))
    b = np.atleast_2d(np.asarray(b, float))
    c = np.atleast_2d(np.asarray(centres, float)).reshape(-1, 2)
    r = np.asarray(radii, float).reshape(-1)
    d = b - a
    dd = np.maximum((d * d).sum(axis=1), 1e-12)
    t = ((c[None, :, :] - a[:, None, :]) * d[:, None, :]).sum(axis=2) / dd[:, None]
    t = np.clip(t, 0.0, 1.0)
    p = a[:, None, :] + t[:, :, None] * d[:, None, :]
    return np.hypot(*(p - c[None, :, :]).transpose(2, 0, 1)) - r[None, :]


def orbit_room(poses, r: float, rstar: float, arena_um, centres, radii) -> np.ndarray:
    """Room (um, (K,)) each pose in ``poses`` (K, 3) leaves its robot to orbit in place: the gap of the orbit
    disc (turning radius ``r``, disc radius ``rstar``) to the arena edge ``(w, h)`` (None: unbounded) and to
    the discs ``(centres, radii)``; negative when the orbit would meet one.

    A one-way robot whose orbit meets the arena edge, while the edge also lies ahead of it, is trapped for
    good: it can neither pivot off the edge nor drive through it. A robot that keeps room to orbit can
    always wait (P_n) or turn away; the pair phase keeps D_n there whenever it stops.

    >>> float(orbit_room(np.array([[500.0, 500.0, 0.0]]), 100.0, 150.0, (1000.0, 1000.0), np.zeros((0, 2)), [])[0])
    250.0
    """
    c = turning_centres(poses, r)
    room = np.full(len(c), np.inf)
    if arena_um is not None:
        w, h = arena_um
        room = np.min(np.stack([c[:, 0], w - c[:, 0], c[:, 1], h - c[:, 1]], axis=1), axis=1) - rstar
    rr = np.asarray(radii, float).reshape(-1)
    if len(rr):
        d = np.hypot(*(c[:, None, :] - np.atleast_2d(np.asarray(centres, float))[None]).transpose(2, 0, 1)) - rr[None, :] - rstar
        room = np.minimum(room, d.min(axis=1))
    return room


def _inside(p, arena_um, m: float) -> np.ndarray:
    w, h = arena_um
    return (p[:, 0] >= m) & (p[:, 0] <= w - m) & (p[:, 1] >= m) & (p[:, 1] <= h - m)


def legs_clear(a, b, rstar: float, centres, radii, arena_um, clearance: float, *, from_start: bool = False) -> np.ndarray:
    """Mask (E,): the capsule of radius ``rstar`` around each leg ``a[e]``-``b[e]`` keeps ``clearance`` from
    the discs ``(centres, radii)`` and stays that far inside the arena ``(w, h)`` (None: unbounded).

    With ``from_start`` the ``a`` ends are where the robot orbits now: a leg may start closer than
    ``clearance`` to a disc or the edge (it is there already) but must not come closer than it starts.
    """
    a = np.atleast_2d(np.asarray(a, float))
    b = np.atleast_2d(np.asarray(b, float))
    ok = np.ones(len(a), dtype=bool)
    need = rstar + clearance
    if len(np.asarray(radii).reshape(-1)):
        gaps = segment_disc_gaps(a, b, centres, radii)
        if from_start:
            now = np.hypot(*(a[:, None, :] - np.atleast_2d(centres)[None]).transpose(2, 0, 1)) - np.asarray(radii)[None, :]
            ok &= (gaps >= np.minimum(need, now - 1e-6)).all(axis=1)
        else:
            ok &= (gaps >= need).all(axis=1)
    if arena_um is not None:
        # a segment lies inside the (convex) arena when both ends do
        ok &= _inside(b, arena_um, need)
        if not from_start:
            ok &= _inside(a, arena_um, need)
    return ok


class Body(NamedTuple):
    """The moving robot as :func:`swept_legs_clear` sees it: turning radius ``r_um`` (its body centre lies that
    far left of its turning centre, across its heading), body ``length_um`` x ``width_um``, and how far past a
    leg's end it may run on (``overrun_um``: the transfer's check of D_{n-1}'s own track runs a second long)
    and how far left of the leg's heading it departs (``bias_rad``: the transfer's left bias, so that every
    correction on the way is clockwise)."""

    r_um: float
    length_um: float
    width_um: float
    overrun_um: float = 0.0
    bias_rad: float = 0.0


def swept_legs_clear(a, b, rstar: float, body: Body, centres, radii, arena_um, clearance: float, *,
                     from_start: bool = False) -> np.ndarray:
    """Mask (E,): what the robot really sweeps on each leg ``a[e]``-``b[e]`` keeps ``clearance`` from the discs
    ``(centres, radii)`` and the arena edge ``(w, h)`` (None: unbounded): its body driving straight, a
    rectangle ``leg + L + overrun`` long and ``W`` wide from its departure pose (``body.r_um`` left of the
    start centre, heading ``body.bias_rad`` left of the leg), and
    its orbit disc (``rstar``) about ``b``. Before the leg it orbits about ``a``, where it is already.

    The capsule of :func:`legs_clear` (radius ``r*`` all along) is what the orbit disc would sweep if it
    moved bodily; the body itself is only ``W`` wide across the leg, so gaps between two orbits narrower
    than an orbit disc let a station move through (tuning layout 104: D_{n-1} walled into an arena corner
    by three orbits had no capsule route at all). With ``from_start`` a disc the ``a`` orbit is closer to
    than ``clearance`` already may be passed as close as that.

    >>> body = Body(100.0, 200.0, 50.0)
    >>> a, b = np.array([[500.0, 500.0]]), np.array([[500.0, 2500.0]])       # heading +y, body 100 um to the left
    >>> bool(swept_legs_clear(a, b, 150.0, body, np.array([[700.0, 1500.0]]), np.array([100.0]), None, 10.0)[0])
    True
    >>> bool(legs_clear(a, b, 150.0, np.array([[700.0, 1500.0]]), np.array([100.0]), None, 10.0)[0])  # the capsule: no
    False
    """
    a = np.atleast_2d(np.asarray(a, float))
    b = np.atleast_2d(np.asarray(b, float))
    d = b - a
    ell = np.maximum(np.hypot(*d.T), 1e-9)
    th = np.arctan2(d[:, 0], d[:, 1]) - body.bias_rad  # the heading it departs at (theta clockwise from +y)
    u = np.stack([np.sin(th), np.cos(th)], axis=1)
    left = np.stack([-np.cos(th), np.sin(th)], axis=1)
    swept_len = ell + body.length_um + body.overrun_um
    mid = a + body.r_um * left + 0.5 * (ell + body.overrun_um)[:, None] * u
    swept = np.column_stack([mid, th])
    half_w = np.full(len(a), 0.5 * body.width_um)
    ok = np.ones(len(a), dtype=bool)
    cs = np.atleast_2d(np.asarray(centres, float)).reshape(-1, 2)
    rr = np.asarray(radii, float).reshape(-1)
    if len(rr):
        rel = cs[None, :, :] - mid[:, None, :]  # (E, K, 2)
        along = np.abs((rel * u[:, None, :]).sum(axis=2)) - 0.5 * swept_len[:, None]
        across = np.abs((rel * left[:, None, :]).sum(axis=2)) - half_w[:, None]
        rect = np.hypot(np.maximum(along, 0.0), np.maximum(across, 0.0)) + np.minimum(np.maximum(along, across), 0.0)
        gaps = rect - rr[None, :]
        need = np.full(gaps.shape, clearance)
        if from_start:
            now = np.hypot(*(a[:, None, :] - cs[None]).transpose(2, 0, 1)) - rr[None, :] - rstar
            need = np.minimum(need, now - 1e-6)
        ok &= (gaps >= need).all(axis=1)
        ok &= (np.hypot(*(b[:, None, :] - cs[None]).transpose(2, 0, 1)) - rr[None, :] - rstar >= clearance).all(axis=1)
    if arena_um is not None:
        ok &= _inside(b, arena_um, rstar + clearance)
        ok &= arena_gap(swept, swept_len, 2.0 * half_w, arena_um) >= clearance
    return ok


def orbit_route(start, goal, rstar: float, centres, radii, arena_um, *, clearance: float, spacing_um: float = 150.0,
                leg_cost_um: float = 200.0, max_legs: int = 4, body: Body | None = None,
                via_wall_um: float = 0.0) -> list[np.ndarray] | None:
    """Orbit centres (the last is ``goal``) of the shortest clear route of straight legs from ``start``.

    ``centres`` / ``radii``: the discs to keep clear of (other robots' orbit discs), ``rstar``: the moving
    robot's orbit-disc radius; legs are checked with :func:`legs_clear`. Nodes are ``start``, ``goal`` and
    the free centres of a ``spacing_um`` grid over the arena; each leg costs its length plus
    ``leg_cost_um`` (the orbiting before it, and a chance for error). None when no route of at most
    ``max_legs`` legs exists (the goal itself not free counts as none). Needs a bounded arena. With
    ``body`` the legs are checked by what the robot sweeps (:func:`swept_legs_clear`) instead of the capsule.
    ``via_wall_um``: the grid's orbits keep this much more than ``clearance`` from the arena edge (an orbit that lands
    there off its plan, or drifts while it waits, meets the edge and traps its robot; another orbit can be moved).

    >>> route = orbit_route(np.array([500.0, 1000.0]), np.array([1500.0, 1000.0]), 100.0,
    ...                     np.array([[1000.0, 1000.0]]), np.array([150.0]), (2000.0, 2000.0), clearance=10.0)
    >>> len(route) >= 2 and np.allclose(route[-1], [1500.0, 1000.0])
    True
    """
    start, goal = np.asarray(start, float), np.asarray(goal, float)
    if arena_um is None:
        return None
    def clear(a, b, first: bool) -> np.ndarray:
        if body is None:
            return legs_clear(a, b, rstar, centres, radii, arena_um, clearance, from_start=first)
        return swept_legs_clear(a, b, rstar, body, centres, radii, arena_um, clearance, from_start=first)

    if clear(start[None], goal[None], True)[0]:
        return [goal]
    w, h = arena_um
    m = rstar + clearance + via_wall_um
    xs, ys = np.arange(m, w - m + 1e-9, spacing_um), np.arange(m, h - m + 1e-9, spacing_um)
    gx, gy = np.meshgrid(xs, ys)
    grid = np.stack([gx.ravel(), gy.ravel()], axis=1)
    if len(np.asarray(radii).reshape(-1)):
        free = (np.hypot(*(grid[:, None, :] - np.atleast_2d(centres)[None]).transpose(2, 0, 1))
                >= np.asarray(radii)[None, :] + rstar + clearance).all(axis=1)
        grid = grid[free]
    nodes = np.vstack([start, goal, grid])
    K = len(nodes)
    i, j = np.triu_indices(K, k=1)
    first = i == 0
    ok = np.zeros(len(i), dtype=bool)
    ok[first] = clear(nodes[i[first]], nodes[j[first]], True)
    # a leg may be driven either way: checked from both ends (the swept body is not symmetric)
    rest = ~first
    ok[rest] = clear(nodes[i[rest]], nodes[j[rest]], False) if body is None else \
        clear(nodes[i[rest]], nodes[j[rest]], False) & clear(nodes[j[rest]], nodes[i[rest]], False)
    i, j = i[ok], j[ok]
    cost = np.hypot(*(nodes[i] - nodes[j]).T) + leg_cost_um
    graph = csr_matrix((np.concatenate([cost, cost]), (np.concatenate([i, j]), np.concatenate([j, i]))), shape=(K, K))
    dist, pred = dijkstra(graph, indices=0, return_predecessors=True)
    if not np.isfinite(dist[1]):
        return None
    path = [1]
    while path[-1] != 0:
        path.append(int(pred[path[-1]]))
    legs = [nodes[p] for p in reversed(path[:-1])]
    return legs if len(legs) <= max_legs else None
