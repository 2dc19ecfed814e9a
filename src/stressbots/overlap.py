"""Overlapped G_1 schedules: D_n turns toward its slot while D_{n-1} turns on its route (issue 15).

Under the three primitives of step 1 the pair's arm states are limited to (D_n, D_{n-1}) in
{(turn, turn): P_n, (straight, turn): P_{n-1}, (straight, straight): P_{n-2}} (SPEC 4); the lower robots
orbit under all three. The seed's scheme (App. 2) uses this in two stages: D_n drives to a_n while D_{n-1}
orbits back to its start (a whole number of its periods), then D_{n-1} drives its whole route while D_n
runs straight into its slot. But D_n only *has* to drive straight while D_{n-1} drives straight: while
D_{n-1} turns, on its route's arcs as on its orbit, D_n may turn as well. So D_n's path is

    F_0 | S_1 | F_1 | S_2 | ... | S_last

where ``F_0`` is free (any path, lasting D_{n-1}'s orbit before departure plus its route's first arc),
each ``S_j`` is a straight run as long (in time) as D_{n-1}'s stretch of route between two arcs, each
``F_j`` is free and as long as D_{n-1}'s arc ``j`` (a *window*), and ``S_last`` covers D_{n-1}'s last
stretch and its final approach and ends in D_n's slot. D_n's straight corridor is then only as long as
the last stretch (not the whole route), and D_{n-1} leaves at the departure phase that suits the pair
instead of after whole periods spent only on D_n's first stage.

The search works backwards from D_n's slot: for each window, the poses from which a path of exactly the
window's length reaches the next run's start (clockwise arc - straight - clockwise arc words, built by
integrating backwards, so their length is exact), the run before it, and a small beam of the candidates
whose run start is nearest to D_n's start (by shortest path). ``F_0`` is then a path of exactly the
needed length from D_n's start (:func:`stressbots.paths.path_of_length`). Every candidate schedule is
checked against the static obstacles and, sampled in time, between the two moving bodies.

Pure geometry and search over callables: the planner (:mod:`stressbots.planning`) supplies the obstacle
tests and applies the schedule to its timeline.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np

from . import paths as pathlib
from .kinematics import move
from .robots import Pose

__all__ = ["OverlapSettings", "PairSchedule", "backward_words", "joint_primitives", "overlap_schedule", "with_orbits"]


@dataclass(frozen=True)
class OverlapSettings:
    """Settings of the overlapped G_1 search.

    Attributes
    ----------
    window_min_s:
        Shortest arc of D_{n-1}'s route (s) used as a free window for D_n; shorter arcs D_n drives
        straight through (they would buy almost nothing and cost search).
    beam:
        Partial schedules (backwards from the slot) kept per window: more finds schedules in cluttered
        layouts, at a linear cost.
    turn_steps:
        Arc lengths tried per arc of a window's words (from 0 to the window's length, at most one turn).
    extra_periods:
        Whole periods of D_{n-1}'s orbit added beyond the least that lets D_n reach its first run (a
        longer ``F_0`` may clear an obstacle the shortest cannot).
    max_inserted_orbits:
        Most whole orbits D_{n-1} may insert into its route's longest straight (:func:`with_orbits`) when
        D_n's run beside that straight does not fit: each splits the run in two and gives D_n a window of
        one period to turn in.
    split_offsets:
        Shifts (fractions of the straight) tried for the inserted orbits when the even split's orbit is
        blocked.
    coarse_um:
        Spacing (um) of the quick test along every candidate run, before the exact one.
    routed_first:
        Run starts (nearest first) for which D_n's first path is routed around the obstacles when no
        direct path of a fitting length is clear (a roadmap search each: the costly part).
    roadmap_routes:
        Roadmap routes of D_{n-1} (found by the piece scheme's route search) also tried overlapped, per
        G_1 search, with D_n's first path not routed: the direct routes are tried in full first.
    """

    window_min_s: float = 0.5
    beam: int = 6
    turn_steps: int = 7
    extra_periods: int = 2
    max_inserted_orbits: int = 2
    split_offsets: tuple[float, ...] = (0.0, 0.15, -0.15, 0.3, -0.3)
    coarse_um: float = 40.0
    routed_first: int = 2
    roadmap_routes: int = 8


@dataclass(frozen=True)
class PairSchedule:
    """An overlapped G_1 schedule: both robots' whole paths from the start of step 1 (um, s).

    ``path_n`` and ``path_m`` (D_n and D_{n-1}) last ``duration_s`` at their speeds; ``pieces`` are the
    time intervals ``(t0_s, t1_s, free)`` of D_n's path: ``free`` for F_0 and the windows, else a run.
    """

    path_n: pathlib.Path
    path_m: pathlib.Path
    duration_s: float
    pieces: tuple[tuple[float, float, bool], ...]
    wait_s: float


def backward_words(end: np.ndarray, length_um: float, radius: float, steps: int) -> tuple[np.ndarray, list[tuple]]:
    """Poses from which a path of exactly ``length_um`` reaches ``end``, and those paths' segments.

    The paths are ``R a, S b, R c`` (clockwise arcs and a straight, ``a + b + c = length_um``, each arc
    under one turn) on a grid of ``steps`` values of ``a`` and ``c``; the start poses come from
    integrating each word backwards from ``end`` (:func:`stressbots.kinematics.move` runs arcs backwards
    exactly). Returns ``(K, 3)`` start poses and the K segment tuples.
    """
    ell = float(length_um)
    top = min(ell, 0.98 * 2.0 * math.pi * radius)
    grid = np.linspace(0.0, top, max(steps, 1)) if top > 0 else np.zeros(1)
    a, c = (g.ravel() for g in np.meshgrid(grid, grid, indexing="ij"))
    keep = ell - a - c >= -1e-9
    a, c = a[keep], c[keep]
    b = np.maximum(ell - a - c, 0.0)
    p = np.broadcast_to(np.asarray(end, float), (a.size, 3))
    kappa = 1.0 / radius
    p = move(move(move(p, -c, kappa), -b, 0.0), -a, kappa)
    words = [(("R", float(x)), ("S", float(y)), ("R", float(z))) for x, y, z in zip(a, b, c, strict=True)]
    return np.asarray(p, dtype=np.float64).reshape(-1, 3), words


def joint_primitives(path_n: pathlib.Path, v_n: float, path_m: pathlib.Path, v_m: float, n: int,
                     sliver_s: float = 1e-9) -> list[tuple[int, float]]:
    """The primitive steps ``(k, duration_s)`` that drive D_n along ``path_n`` and D_{n-1} along ``path_m``.

    D_n turning needs P_n (both turn); D_n straight with D_{n-1} turning P_{n-1}; both straight P_{n-2}.
    D_n turning while D_{n-1} drives straight is impossible: a ``ValueError``, except for slivers
    shorter than ``sliver_s`` (rounding at the paths' joints), which are driven with P_n.
    """
    a = [(k == "R", ell / v_n) for k, ell in path_n.segments]
    b = [(k == "R", ell / v_m) for k, ell in path_m.segments]
    out: list[tuple[int, float]] = []
    i = j = 0
    ra = a[0][1] if a else 0.0
    rb = b[0][1] if b else 0.0
    while i < len(a) and j < len(b):
        d = min(ra, rb)
        tn, tm = a[i][0], b[j][0]
        if tn and not tm and d > sliver_s:
            raise ValueError(f"D_n turns while D_(n-1) drives straight for {d:.3g} s")
        k = n if tn else (n - 1 if tm else n - 2)
        if d > 0:
            if out and out[-1][0] == k:
                out[-1] = (k, out[-1][1] + d)
            else:
                out.append((k, d))
        ra -= d
        rb -= d
        if ra <= 1e-12:
            i += 1
            ra = a[i][1] if i < len(a) else 0.0
        if rb <= 1e-12:
            j += 1
            rb = b[j][1] if j < len(b) else 0.0
    return out


def with_orbits(route_m: pathlib.Path, count: int, offset: float = 0.0) -> tuple[pathlib.Path, tuple[float, ...]]:
    """``route_m`` with ``count`` whole clockwise orbits inserted into its longest straight.

    The orbits split the straight into ``count + 1`` parts, even but for ``offset`` (a fraction of the
    straight, moving every cut). An orbit brings the robot back to the same pose, so the route still ends
    where it did; each is a window of one period in which D_n may turn. Returns the new route and the
    arc lengths (um along the new route) where the orbits start.
    """
    segs = list(route_m.segments)
    straights = [i for i, (k, _) in enumerate(segs) if k == "S"]
    if count <= 0 or not straights:
        return route_m, ()
    i = max(straights, key=lambda q: segs[q][1])
    b = segs[i][1]
    cuts = [b * ((j + 1) / (count + 1) + offset) for j in range(count)]
    if cuts[0] <= 0.0 or cuts[-1] >= b:
        return route_m, ()
    orbit = 2.0 * math.pi * route_m.radius
    parts: list[tuple[str, float]] = []
    prev = 0.0
    before = sum(ell for _, ell in segs[:i])
    at = []
    for j, c in enumerate(cuts):
        parts += [("S", c - prev), ("R", orbit)]
        at.append(before + c + j * orbit)
        prev = c
    parts.append(("S", b - prev))
    new = pathlib.Path(route_m.start, route_m.radius, tuple(segs[:i]) + tuple(parts) + tuple(segs[i + 1:]))
    return new, tuple(at)


def _m_structure(route_m: pathlib.Path, approach_m: pathlib.Path, v_m: float, window_min_s: float):
    """D_{n-1}'s timing after its departure: lead arc (s), windows ``[(t0, t1)]`` (s) and total (s)."""
    segs = route_m.segments
    lead = 0.0
    i0 = 0
    while i0 < len(segs) and segs[i0][0] == "R":
        lead += segs[i0][1] / v_m
        i0 += 1
    windows = []
    t = lead
    for kind, ell in segs[i0:]:
        d = ell / v_m
        if kind == "R" and d >= window_min_s:
            windows.append((t, t + d))
        t += d
    total = (route_m.length + approach_m.length) / v_m
    return lead, windows, total


def overlap_schedule(
    start_n: np.ndarray,
    start_m: np.ndarray,
    goal_n: np.ndarray,
    route_m: pathlib.Path,
    approach_m: pathlib.Path,
    wait_s: float,
    period_m_s: float,
    v_n: float,
    r_n: float,
    v_m: float,
    r_m: float,
    static_ok: Callable[[pathlib.Path], bool],
    joint_ok: Callable[[pathlib.Path, pathlib.Path], bool],
    poses_ok: Callable[[np.ndarray], np.ndarray],
    settings: OverlapSettings = OverlapSettings(),
    not_after_s: float = math.inf,
    first_path: Callable[[np.ndarray, float], pathlib.Path | None] | None = None,
    first_ok: Callable[[pathlib.Path], bool] | None = None,
) -> PairSchedule | None:
    """The shortest overlapped G_1 schedule found for one route of D_{n-1}, or None (see the module doc).

    ``route_m`` starts where D_{n-1} is after orbiting ``wait_s`` (plus any whole number of its periods
    ``period_m_s``) from ``start_m``; ``approach_m`` follows it into the slot. ``static_ok(path)`` tests
    D_n's path against the lower robots' orbits and the arena (``poses_ok(poses)`` the same for ``(K, 3)``
    poses, per pose); ``joint_ok(path_n, path_m)`` tests the two timed paths against each other.
    Schedules lasting ``not_after_s`` or more are not tried. When no direct first path of a fitting length
    is clear, ``first_path(run_start, t0_s)`` (a clear path lasting ``t0_s`` plus whole periods of
    D_{n-1}, or None) is asked for the ``settings.routed_first`` nearest run starts. ``first_ok(path)``
    tests D_n's first path (default ``static_ok``): D_{n-1} is on its start orbit all that time, so its
    orbit disc may be added as an obstacle there.
    """
    lead, windows, total_m = _m_structure(route_m, approach_m, v_m, settings.window_min_s)
    ends = [w[0] for w in windows] + [total_m]
    begins = [lead] + [w[1] for w in windows]
    runs = [e - b for b, e in zip(begins, ends, strict=True)]  # D_n's straight runs (s)
    start_n = np.asarray(start_n, float)
    beam = _backward_beam(np.asarray(goal_n, float), start_n, windows, runs, v_n, r_n, static_ok, poses_ok, settings)
    if not beam:
        return None

    def direct(s1: np.ndarray, orbit_s: float) -> pathlib.Path | None:
        try:
            first = pathlib.path_of_length(start_n, s1, r_n, v_n * (orbit_s + lead))
        except pathlib.InfeasibleLengthError:
            return None
        return first if (first_ok or static_ok)(first) else None

    for orbit_s, q, first in _first_paths(beam, start_n, v_n, r_n, lead, wait_s, period_m_s, total_m, not_after_s, direct,
                                          first_path, settings):
        path_n = pathlib.Path(Pose(*start_n), r_n, first.segments + tuple(beam[q][1]))
        path_m = pathlib.Path(Pose(*np.asarray(start_m, float)), r_m,
                              (("R", v_m * orbit_s),) + route_m.segments + approach_m.segments)
        if joint_ok(path_n, path_m):
            return PairSchedule(path_n, path_m, orbit_s + total_m, _pieces(orbit_s + lead, runs, windows), orbit_s)
    return None


def _backward_beam(goal_n: np.ndarray, start_n: np.ndarray, windows, runs: list[float], v_n: float, r_n: float,
                   static_ok, poses_ok, settings: OverlapSettings) -> list[tuple[np.ndarray, tuple]]:
    """D_n's path from its first run's start to its slot, built backwards from the slot: its last
    straight run, then each window's turn and the run before it (a beam of candidates, see
    :func:`_extend_beam`). Empty when a run is negative or nothing clears."""
    if min(runs) < -1e-9:
        return []
    h = np.array([math.sin(goal_n[2]), math.cos(goal_n[2]), 0.0])
    s_last = goal_n - v_n * runs[-1] * h
    tail = pathlib.Path(Pose(*s_last), r_n, (("S", v_n * runs[-1]),))
    if not static_ok(tail):
        return []
    beam: list[tuple[np.ndarray, tuple]] = [(s_last, tail.segments)]
    for j in range(len(windows) - 1, -1, -1):
        beam = _extend_beam(beam, windows[j], runs[j], start_n, v_n, r_n, static_ok, poses_ok, settings)
        if not beam:
            return []
    return beam


def _first_paths(beam, start_n, v_n, r_n, lead, wait_s, period_m_s, total_m, not_after_s, direct, routed, settings):
    """D_n's first paths ``(orbit_s, beam index, path)``, shortest schedule first: direct paths of the
    fitting lengths, then (``routed``) paths around the obstacles for the nearest run starts."""
    options: list[tuple[float, int]] = []
    for q, (s1, _) in enumerate(beam):
        base = float(pathlib.shortest_path_lengths(start_n[None, :], s1[None, :], r_n)[0])
        kmin = max(0, math.ceil((base / v_n - lead - wait_s) / period_m_s - 1e-9))
        options.extend((wait_s + k * period_m_s, q) for k in range(kmin, kmin + 1 + settings.extra_periods))
    for orbit_s, q in sorted(options):
        if orbit_s + total_m < not_after_s:
            first = direct(beam[q][0], orbit_s)
            if first is not None:
                yield orbit_s, q, first
    for q in range(min(settings.routed_first, len(beam)) if routed is not None else 0):
        first = routed(beam[q][0], wait_s + lead)
        if first is not None and first.length / v_n - lead + total_m < not_after_s:
            yield first.length / v_n - lead, q, first


def _pieces(t0: float, runs: Sequence[float], windows: Sequence[tuple[float, float]]) -> tuple[tuple[float, float, bool], ...]:
    """D_n's pieces ``(t0_s, t1_s, free)``: F_0 until ``t0``, then runs alternating with windows."""
    pieces = [(0.0, t0, True)]
    t = t0
    for j, run in enumerate(runs):
        pieces.append((t, t + run, False))
        t += run
        if j < len(windows):
            w = windows[j][1] - windows[j][0]
            pieces.append((t, t + w, True))
            t += w
    return tuple(pieces)


def _extend_beam(beam: Sequence[tuple[np.ndarray, tuple]], window: tuple[float, float], run_s: float, start_n: np.ndarray,
                 v_n: float, r_n: float, static_ok: Callable[[pathlib.Path], bool], poses_ok: Callable[[np.ndarray], np.ndarray],
                 settings: OverlapSettings):
    """One window backwards: for every partial schedule, the window's words and the run before them;
    the ``beam`` whose run starts are nearest D_n's start and clear of the static obstacles.

    ``poses_ok`` first tests, for all candidates at once, poses every ``settings.coarse_um`` along the run
    and the word's joints; the exact test (``static_ok``) then runs on the survivors, nearest first.
    """
    ell = v_n * (window[1] - window[0])
    run = v_n * run_s
    cands: list[tuple[float, int, np.ndarray, tuple]] = []
    along = np.append(np.arange(0.0, run, settings.coarse_um), run)
    for s_next, segs in beam:
        qs, words = backward_words(s_next, ell, r_n, settings.turn_steps)
        heads = np.column_stack([np.sin(qs[:, 2]), np.cos(qs[:, 2])])
        ps = qs.copy()
        ps[:, :2] -= run * heads
        kappa = 1.0 / r_n
        joint1 = move(qs, np.array([w[0][1] for w in words]), kappa)
        joint2 = move(joint1, np.array([w[1][1] for w in words]), 0.0)
        line = np.repeat(ps, along.size, axis=0)
        line[:, :2] += np.tile(along, len(ps))[:, None] * np.repeat(heads, along.size, axis=0)
        probe = np.vstack([line, joint1, joint2])
        ok = poses_ok(probe)
        clear = ok[: line.shape[0]].reshape(len(ps), along.size).all(axis=1) & ok[line.shape[0]: line.shape[0] + len(ps)]
        clear &= ok[line.shape[0] + len(ps):]
        idx = np.flatnonzero(clear)
        if not idx.size:
            continue
        score = pathlib.shortest_path_lengths(np.broadcast_to(start_n, (idx.size, 3)), ps[idx], r_n)
        cands.extend((float(score[j]), len(cands) + j, ps[c], (("S", run),) + words[c] + segs) for j, c in enumerate(idx))
    cands.sort(key=lambda x: (x[0], x[1]))
    kept: list[tuple[np.ndarray, tuple]] = []
    seen: set = set()
    for _, _, p, segs in cands:
        key = tuple(np.round(p, 3))
        if key in seen:
            continue
        seen.add(key)
        piece = pathlib.Path(Pose(*p), r_n, segs[:4])  # the run and the window's word
        if poses_ok(piece.sample(settings.coarse_um)).all() and static_ok(piece):
            kept.append((p, segs))
            if len(kept) >= settings.beam:
                break
    return kept
