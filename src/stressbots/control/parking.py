"""Waiting robots whose orbits drift into trouble: moving an orbit away before it is trapped.

A robot waiting for its turn orbits in place, but its heading drift moves its turning centre in a random
walk (tens of um per hundred seconds at the literature's noise). An orbit that drifts into the arena edge,
the docked structure or another orbit traps the robot: a turning robot pushing into anything is stopped
and cannot pivot off, and when its turn comes its first straight drive pushes into the same obstacle.
Every attempt then fails with "stopped during gross motion".

So before each docking phase the controller looks at every waiting orbit (:func:`orbit_gaps`) and moves
the ones closer than ``Tuning.park_margin_um`` to something. Under the STRING design robot D_j drives
straight only under P_{j-1}, which also drives every undocked robot above it straight (D_{j+1} .. D_k) and
keeps those below orbiting. :func:`park_move` therefore plans one manoeuvre for the whole group: wait
under P_k (all of D_1..D_k orbit) until D_j heads away from the obstacle, then P_{j-1} for as long as
moves D_j's centre ``Tuning.park_shift_um``; every straight mover's orbit disc, carried along its track,
must stay clear of the arena edge, the docked bodies, the still orbiting discs and (at the same instants)
of each other. Pure functions of arrays: the runner supplies the measured poses and identified rates.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..collision import point_rectangle_distance
from ..robots import TWO_PI, turning_centres

__all__ = ["ParkMove", "blocking_orbits", "orbit_gaps", "park_move", "straights_clear", "unblock_move"]


@dataclass(frozen=True)
class ParkMove:
    """Wait ``wait_s`` under P_k, then drive ``straight_s`` under P_{j-1}: D_j's orbit moves away from trouble."""

    robot: int
    wait_s: float
    straight_s: float
    gap_before_um: float
    gap_after_um: float


def orbit_gaps(centres, rstar, arena_um, docked_poses, docked_L, docked_W) -> np.ndarray:
    """Gap (um) of each orbit disc ``(centres (K, 2), rstar (K,))`` to the arena edge, the docked bodies and the
    other discs; the smallest per disc.

    >>> float(orbit_gaps(np.array([[100.0, 500.0]]), np.array([60.0]), (1000.0, 1000.0), np.zeros((0, 3)), [], [])[0])
    40.0
    """
    c = np.atleast_2d(np.asarray(centres, float))
    rs = np.asarray(rstar, float).reshape(-1)
    gap = np.full(len(c), np.inf)
    if arena_um is not None:
        w, h = arena_um
        gap = np.minimum(gap, np.min(np.stack([c[:, 0], w - c[:, 0], c[:, 1], h - c[:, 1]], axis=1), axis=1) - rs)
    for p, L, W in zip(np.atleast_2d(docked_poses), docked_L, docked_W, strict=False):
        gap = np.minimum(gap, point_rectangle_distance(c, np.asarray(p)[None, :], float(L), float(W))[0] - rs)
    if len(c) > 1:
        d = np.hypot(*(c[:, None, :] - c[None, :, :]).transpose(2, 0, 1)) - rs[:, None] - rs[None, :]
        np.fill_diagonal(d, np.inf)
        gap = np.minimum(gap, d.min(axis=1))
    return gap


def _wall_gaps(tracks, rstar, arena_um) -> np.ndarray:
    """Gap (um) of each disc (tracks (M, T, 2), radii (M,)) to the arena edge at every instant (M, T); inf without an arena."""
    if arena_um is None:
        return np.full(tracks.shape[:2], np.inf)
    w, h = arena_um
    x, y = tracks[..., 0], tracks[..., 1]
    return np.minimum(np.minimum(x, w - x), np.minimum(y, h - y)) - np.asarray(rstar, float)[:, None]


def _gaps_along(tracks, rstar, arena_um, docked_poses, docked_L, docked_W, still_c, still_r) -> np.ndarray:
    """Smallest gap (um) over time of each mover's disc (tracks (M, T, 2)) to everything, movers included."""
    M, T, _ = tracks.shape
    gap = np.full(M, np.inf)
    flat = tracks.reshape(-1, 2)
    rs = np.repeat(np.asarray(rstar, float), T)
    if arena_um is not None:
        w, h = arena_um
        g = np.min(np.stack([flat[:, 0], w - flat[:, 0], flat[:, 1], h - flat[:, 1]], axis=1), axis=1) - rs
        gap = np.minimum(gap, g.reshape(M, T).min(axis=1))
    for p, L, W in zip(np.atleast_2d(docked_poses), docked_L, docked_W, strict=False):
        g = point_rectangle_distance(flat, np.asarray(p)[None, :], float(L), float(W))[0] - rs
        gap = np.minimum(gap, g.reshape(M, T).min(axis=1))
    for c, r in zip(np.atleast_2d(still_c), np.asarray(still_r, float).reshape(-1), strict=False):
        g = np.hypot(*(flat - c).T) - rs - r
        gap = np.minimum(gap, g.reshape(M, T).min(axis=1))
    for a in range(M):
        for b in range(a + 1, M):
            g = float((np.hypot(*(tracks[a] - tracks[b]).T) - rstar[a] - rstar[b]).min())
            gap[a], gap[b] = min(gap[a], g), min(gap[b], g)
    return gap


def _straight_tracks(centres, headings, speeds, duration_s: float, samples: int) -> np.ndarray:
    """Orbit-disc centres (M, T, 2) of movers driving straight ``duration_s`` s from ``centres`` (M, 2) along
    ``headings`` (rad) at ``speeds`` (um/s), at ``samples`` instants."""
    t = np.linspace(0.0, duration_s, samples)
    h = np.stack([np.sin(headings), np.cos(headings)], axis=1)  # (M, 2)
    return centres[:, None, :] + (speeds[:, None] * t[None, :])[:, :, None] * h[:, None, :]


def _tracks_clear(tracks, centres, rstar, gap0, arena_um, docked_poses, docked_L, docked_W, still_c, still_r,
                  clearance_um: float) -> tuple[bool, np.ndarray]:
    """Whether the movers' discs along ``tracks`` (M, T, 2; from ``centres``, radii ``rstar``) keep ``clearance_um``
    from everything, or (where their present gap ``gap0`` is smaller) get no closer, the arena edge judged apart (a
    mover whose disc starts overlapping another disc must not swap it for the edge); and each one's smallest gap."""
    gaps = _gaps_along(tracks, rstar, arena_um, docked_poses, docked_L, docked_W, still_c, still_r)
    walls = _wall_gaps(tracks, rstar, arena_um).min(axis=1)
    wall0 = _wall_gaps(centres[:, None, :], rstar, arena_um)[:, 0]
    clear = bool((gaps >= np.minimum(clearance_um, gap0 - 1e-6)).all() and (walls >= np.minimum(clearance_um, wall0 - 1e-6)).all())
    return clear, gaps


def park_move(j: int, movers: list[int], still: list[int], poses, radii, rates, speeds, rstar, arena_um,
              docked_poses, docked_L, docked_W, *, shift_um: float, clearance_um: float, held: bool = False,
              keep_um: float = 0.0) -> ParkMove | None:
    """The manoeuvre that moves robot ``j``'s orbit ``shift_um`` away from its nearest obstacle, or None.

    ``movers``: the undocked robots that drive straight with ``j`` under P_{j-1} (``j`` included);
    ``still``: those that keep orbiting. ``poses`` (n, 3), ``radii`` / ``rates`` / ``speeds`` / ``rstar``
    (n,): measured poses, identified turning radii (um), turn rates (rad/s), speeds (um/s) and orbit-disc
    radii. Candidate departure headings: away from the obstacle and up to 60 deg either side; each is
    reached by waiting (every robot of ``movers`` and ``still`` orbits meanwhile). A candidate is taken
    when D_j's gap grows and every mover keeps ``clearance_um`` (or, if it starts closer, does not get
    closer). The shortest wait wins. ``held``: D_j's disc already overlaps the obstacle, so it may be unable
    to turn (a turning robot pushing into anything stops): only a straight along the heading it has, no wait.
    ``keep_um``: every other mover's orbit ends at least this far from trouble (or, if closer already, no closer): a
    park move must not make another (one pushed a waiting orbit from 167 to 27 um off the arena edge, where it drifted
    into it within 50 s: tuning 68:0 at 1x).
    """
    poses = np.asarray(poses, float)
    centres = turning_centres(poses, radii)
    docked_poses = np.atleast_2d(np.asarray(docked_poses, float)).reshape(-1, 3)
    everyone = movers + still
    now = orbit_gaps(centres[everyone], rstar[everyone], arena_um, docked_poses, docked_L, docked_W)
    gap0 = dict(zip(everyone, now, strict=True))
    away = _away(centres[j], everyone.index(j), centres[everyone], rstar[everyone], arena_um, docked_poses, docked_L, docked_W)
    straight_s = shift_um / speeds[j]

    def accept(ends: np.ndarray) -> bool:
        end = orbit_gaps(ends[movers.index(j)][None, :], rstar[[j]], arena_um, docked_poses, docked_L, docked_W)[0]
        if not end > gap0[j] + 0.5 * shift_um:
            return False
        if keep_um <= 0.0 or len(movers) == 1:
            return True
        after = orbit_gaps(np.vstack([ends, centres[still]]), rstar[everyone], arena_um, docked_poses, docked_L, docked_W)
        return all(after[a] >= min(gap0[m], keep_um) - 1e-6 for a, m in enumerate(movers) if m != j)

    cands = [(float(poses[j, 2]), straight_s)] if held else None
    return _best_move(j, movers, still, poses, centres, rates, speeds, rstar, arena_um, docked_poses, docked_L, docked_W, away,
                      straight_s, gap0, clearance_um, accept, cands)


def _best_move(j, movers, still, poses, centres, rates, speeds, rstar, arena_um, docked_poses, docked_L, docked_W, away,
               straight_s: float, gap0: dict, clearance_um: float, accept, candidates=None, loops: int = 0) -> ParkMove | None:
    """The cheapest move of D_j's orbit whose movers' discs keep ``clearance_um`` (or do not get closer) and whose
    end centres (M, 2), in the order of ``movers``, pass ``accept``. Candidates: ``(heading, straight_s)`` pairs
    (shortest wait + straight wins), by
    default headings within 60 deg of ``away`` for ``straight_s`` s (shortest wait wins); each also after up to
    ``loops`` extra loops of D_j."""
    everyone = movers + still
    devs = np.radians([0.0, 20.0, -20.0, 40.0, -40.0, 60.0, -60.0])
    cands = candidates if candidates is not None else [(math.atan2(away[0], away[1]) + dev, straight_s) for dev in devs]
    best, best_cost = None, math.inf
    for (th, straight), m in ((c, m) for c in cands for m in range(loops + 1)):
        # m extra loops of D_j: the other movers, turning at their own rates, then head elsewhere
        wait = (float(np.mod(th - poses[j, 2], TWO_PI)) + m * TWO_PI) / rates[j]
        # everyone orbits for ``wait`` (heading + rate * wait, same centre)
        after = poses.copy()
        after[everyone, 2] = np.mod(poses[everyone, 2] + rates[everyone] * wait, TWO_PI)
        tracks = _straight_tracks(centres[movers], after[movers, 2], speeds[movers], straight, 24)
        clear, gaps = _tracks_clear(tracks, centres[movers], rstar[movers], np.array([gap0[m] for m in movers]), arena_um,
                                    docked_poses, docked_L, docked_W, centres[still], rstar[still], clearance_um)
        cost = wait if candidates is None else wait + straight
        if clear and accept(tracks[:, -1]) and cost < best_cost:
            best, best_cost = ParkMove(j, wait, straight, float(gap0[j]), float(gaps[movers.index(j)])), cost
    return best


def straights_clear(movers: list[int], still: list[int], poses, radii, speeds, rstar, arena_um, docked_poses, docked_L, docked_W,
                    duration_s: float, clearance_um: float) -> bool:
    """Whether the straight of a group move, driven ``duration_s`` s on from the measured ``poses`` (each mover along
    the heading it has), keeps every mover's orbit disc ``clearance_um`` (um) from the arena edge, the docked bodies
    and the other discs, or (where it is closer already) no closer; the arena edge is judged apart, as in a park
    move's plan. Checked before every t_x of the straight: a 490 um straight planned clear of the arena edge ran a
    waiting orbit 34 um into it (the heading after the wait was 10 deg off the plan).

    >>> p = np.array([[500.0, 500.0, 0.0]])   # heading +y: its disc (centre y = 500, r* 120) 380 um below the top edge
    >>> def clear(s): return straights_clear([0], [], p, np.array([100.0]), np.array([100.0]), np.array([120.0]),
    ...                                      (1000.0, 1000.0), np.zeros((0, 3)), [], [], s, 25.0)
    >>> clear(3.0), clear(4.0)   # 100 um/s: 80 um, then -20 um from the edge
    (True, False)
    """
    poses = np.asarray(poses, float)
    centres = turning_centres(poses, radii)
    docked_poses = np.atleast_2d(np.asarray(docked_poses, float)).reshape(-1, 3)
    everyone = movers + still
    gap0 = orbit_gaps(centres[everyone], rstar[everyone], arena_um, docked_poses, docked_L, docked_W)[:len(movers)]
    tracks = _straight_tracks(centres[movers], poses[movers, 2], speeds[movers], duration_s, 12)
    return _tracks_clear(tracks, centres[movers], rstar[movers], gap0, arena_um, docked_poses, docked_L, docked_W, centres[still],
                         rstar[still], clearance_um)[0]


def blocking_orbits(centres, rstar, points, reach_um: float) -> np.ndarray:
    """Which orbit discs ``(centres (K, 2), rstar (K,))`` come within ``reach_um`` (um) of any of ``points``
    (P, 2): the waiting orbits that block a way a moving robot needs (``reach_um``: its half diagonal plus
    clearance). Boolean (K,).

    >>> blocking_orbits(np.array([[0.0, 0.0], [500.0, 0.0]]), np.array([100.0, 100.0]), np.array([[150.0, 0.0]]), 60.0).tolist()
    [True, False]
    """
    c = np.atleast_2d(np.asarray(centres, float))
    q = np.atleast_2d(np.asarray(points, float))[:, :2]
    if not len(c) or not len(q):
        return np.zeros(len(c), dtype=bool)
    d = np.hypot(*(c[:, None, :] - q[None, :, :]).transpose(2, 0, 1)).min(axis=1)
    return d < np.asarray(rstar, float).reshape(-1) + reach_um


def unblock_move(j: int, movers: list[int], still: list[int], poses, radii, rates, speeds, rstar, arena_um, docked_poses, docked_L,
                 docked_W, points, *, reach_um: float, margin_um: float, max_shift_um: float, clearance_um: float,
                 headings=None, loops: int = 0) -> ParkMove | None:
    """The manoeuvre that moves waiting robot ``j``'s orbit off the way ``points`` (P, 2) another robot needs, or None.

    Like :func:`park_move` (same group manoeuvre: wait under P_k, then P_{j-1} drives ``movers`` straight),
    off the ``points`` (the moving robot's aim, its approach corridor, where it is): of 24 headings, each
    with the shortest straight (at most ``max_shift_um``) that takes D_j's disc ``reach_um + margin_um``
    (um) clear of all of them, the cheapest (wait + straight) whose movers keep ``clearance_um``. A waiting
    robot is not needed until its own phase: moving its orbit costs one wait and one straight, while a
    route around it may not exist (its disc covers the aim) at all. ``headings`` (rad) replaces the 24
    candidate headings (e.g. only the one D_j has: a straight from where it is, no wait); each heading is
    also tried after up to ``loops`` extra loops of D_j (the other movers then head elsewhere). The last of
    ``movers`` is the docking robot (D_k); every other mover must not end its disc on the ``points`` (within its
    orbit radius + ``reach_um``) unless it started closer, and then not closer than it started.
    """
    poses = np.asarray(poses, float)
    centres = turning_centres(poses, radii)
    docked_poses = np.atleast_2d(np.asarray(docked_poses, float)).reshape(-1, 3)
    q = np.atleast_2d(np.asarray(points, float))[:, :2]
    everyone = movers + still
    gap0 = dict(zip(everyone, orbit_gaps(centres[everyone], rstar[everyone], arena_um, docked_poses, docked_L, docked_W), strict=True))
    need = float(rstar[j]) + reach_um + margin_um
    # every 15 deg: the shortest straight (10 um steps) that takes D_j's disc clear of all the points
    cands = []
    steps = np.arange(0.0, max_shift_um + 1e-9, 10.0)
    for th in (np.radians(np.arange(0.0, 360.0, 15.0)) if headings is None else np.asarray(headings, float)):
        h = np.array([math.sin(th), math.cos(th)])
        ends = centres[j][None, :] + steps[:, None] * h[None, :]
        ok = np.hypot(*(ends[:, None, :] - q[None, :, :]).transpose(2, 0, 1)).min(axis=1) >= need
        if ok.any():
            cands.append((float(th), float(steps[int(np.argmax(ok))] + margin_um) / speeds[j]))

    def dist(c: np.ndarray) -> float:
        return float(np.hypot(*(q - c).T).min())

    # the other waiting movers (not D_j, not the last: the docking robot itself) go straight too: none may end
    # its disc on the way when it started off it, nor closer to it when it started on it (an unblock move that
    # carried D_(j+1)'s orbit onto the docking robot's aim left it pinned there)
    others = [a for a, m in enumerate(movers[:-1]) if m != j]
    start = {a: dist(centres[movers[a]]) for a in others}
    reach = {a: float(rstar[movers[a]]) + reach_um for a in others}

    def accept(ends: np.ndarray) -> bool:
        if dist(ends[movers.index(j)]) < need:
            return False
        return all(dist(ends[a]) >= min(reach[a], start[a]) for a in others)

    return _best_move(j, movers, still, poses, centres, rates, speeds, rstar, arena_um, docked_poses, docked_L, docked_W, None, 0.0,
                      gap0, clearance_um, accept, cands, loops)


def _away(c, idx, centres, rstar, arena_um, docked_poses, docked_L, docked_W) -> np.ndarray:
    """Unit vector from robot ``idx``'s nearest obstacle (arena edge, docked body, other orbit) to its centre."""
    best, vec = np.inf, np.array([1.0, 0.0])
    if arena_um is not None:
        w, h = arena_um
        for g, v in ((c[0], (1.0, 0.0)), (w - c[0], (-1.0, 0.0)), (c[1], (0.0, 1.0)), (h - c[1], (0.0, -1.0))):
            if g < best:
                best, vec = g, np.array(v)
    for p, L, W in zip(docked_poses, docked_L, docked_W, strict=False):
        g = float(point_rectangle_distance(c[None, :], p[None, :], float(L), float(W))[0, 0])
        if g < best:
            d = c - p[:2]
            best, vec = g, d / max(float(np.hypot(*d)), 1e-9)
    for b in range(len(centres)):
        if b != idx:
            d = c - centres[b]
            g = float(np.hypot(*d)) - rstar[b]
            if g < best:
                best, vec = g, d / max(float(np.hypot(*d)), 1e-9)
    return vec
