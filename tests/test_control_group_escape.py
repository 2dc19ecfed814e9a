"""D_n's group escape (control/group_escape.py): a pure search checked against an independent replay."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.collision import arena_gap, penetration_depth
from stressbots.control.escape_search import Orbiting, escape_manoeuvre
from stressbots.control.group_escape import Group, GroupMove, group_escape, group_escape_sequence
from stressbots.control.leg_watch import leg_stop_s, pair_gaps
from stressbots.robots import orbit_radii

# tuning layout 72, plant seed 1, 1x, t = 27.6 s (D_1 .. D_4 in docking order): D_n (last) ended a transfer leg
# with its orbit inside D_(n-1)'s; D_(n-1)'s body sweeps every way out D_n has alone, and every pair frame
# failed at that instant ("cannot reach a clear track in time")
POSES = np.array([[1326.929, 210.195, 4.424], [782.104, 1634.197, 3.539], [1538.175, 1714.504, 0.969],
                  [1963.039, 1792.762, 4.216]])
V = np.array([106.29, 131.42, 125.84, 140.79])
R = np.array([160.57, 172.19, 224.11, 184.0])
LEN = np.array([227.3, 253.2, 279.4, 227.6])
WID = np.array([52.1, 52.9, 55.2, 68.2])
ARENA = (3000.0, 3000.0)


def _search(g: Group, *, wait_steps: int = 24, max_straight_um: float = 600.0):
    """The group escape at the pair phase's default gaps (Tuning: 40 um edge and orbits, 10 um bodies, 25 um discs)."""
    return group_escape(g, ARENA, edge_need=40.0, body_clearance=10.0, edge_clearance=40.0, disc_clearance=25.0, wait_steps=wait_steps,
                        max_straight_um=max_straight_um)


def _group(poses, v, r, length, width, need) -> Group:
    return Group(tuple(range(len(poses))), poses, v, r, length, width, orbit_radii(length, width, r), need)


def _replay(g: Group, m, t: float) -> np.ndarray:
    """Poses of every robot ``t`` s into the move ``m``, by hand: everyone orbits for the wait, then D_(k+1) .. D_n
    drive straight and D_1 .. D_k orbit (closed-form circle and line, independent of kinematics.move)."""
    out = np.empty_like(g.poses)
    for rank, j in enumerate(g.order):
        x, y, th = g.poses[j]
        for dt, straight in ((min(t, m.wait_s), False), (max(t - m.wait_s, 0.0), rank >= m.k)):
            s = g.speeds[j] * dt
            if straight:
                x, y = x + s * math.sin(th), y + s * math.cos(th)
            else:  # clockwise about the centre r to the right
                cx, cy = x + g.radii[j] * math.cos(th), y - g.radii[j] * math.sin(th)
                th = th + s / g.radii[j]
                x, y = cx - g.radii[j] * math.cos(th), cy + g.radii[j] * math.sin(th)
        out[j] = (x, y, th)
    return out


def _slack(g: Group, poses: np.ndarray, arena) -> float:
    """D_n's orbit disc's smallest surplus over the gaps it needs, from the centres by hand."""
    c = poses[:, :2] + g.radii[:, None] * np.stack([np.cos(poses[:, 2]), -np.sin(poses[:, 2])], axis=1)
    N = g.order[-1]
    s = min(float(np.hypot(*(c[N] - c[j]))) - g.rstar[N] - g.rstar[j] - g.need[j] for j in g.order[:-1])
    if arena is not None:
        s = min(s, float(min(c[N, 0], arena[0] - c[N, 0], c[N, 1], arena[1] - c[N, 1])) - g.rstar[N] - 40.0)
    return s


def _body_gaps(g: Group, m, samples: int = 200) -> np.ndarray:
    """D_n's smallest separation from each other body over the move, replayed at ``samples`` instants (um)."""
    N = g.order[-1]
    gaps = np.full(len(g.poses), np.inf)
    for t in np.linspace(0.0, m.total_s, samples):
        p = _replay(g, m, float(t))
        for j in g.order[:-1]:
            gaps[j] = min(gaps[j], -float(penetration_depth(p[N][None], g.lengths[N], g.widths[N], p[j][None], g.lengths[j],
                                                            g.widths[j])[0]))
    return gaps


def test_d_n_hemmed_in_by_d_n1_leaves_with_it_where_it_has_no_way_out_alone():
    need = np.array([40.0, 40.0, 25.0, 0.0])
    g = _group(POSES, V, R, LEN, WID, need)
    N = 3
    others = Orbiting(POSES[:3], V[:3], R[:3], LEN[:3], WID[:3], g.rstar[:3], need[:3])
    alone = escape_manoeuvre(POSES[N], V[N], R[N], LEN[N], WID[N], g.rstar[N], others, ARENA, edge_need=40.0, body_clearance=10.0,
                             edge_clearance=40.0, lead_ins_um=(0.0, 0.25 * LEN[N], 0.5 * LEN[N]))
    assert alone is None
    assert _slack(g, POSES, ARENA) < 0.0  # its orbit overlaps D_(n-1)'s now
    m = _search(g)
    assert m is not None and m.k <= 2  # D_(n-1) (at least) drives straight with D_n
    end = _replay(g, m, m.total_s)
    assert _slack(g, end, ARENA) >= -1e-6
    start_sep = _body_gaps(g, m._replace(wait_s=0.0, straight_s=0.0), samples=1)
    assert (_body_gaps(g, m) >= np.minimum(10.0, start_sep) - 3.0).all()  # replayed 10x finer than the search samples
    assert (arena_gap(end, LEN, WID, ARENA) > 0.0).all()


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.floats(600.0, 2400.0), st.floats(600.0, 2400.0), st.floats(0.0, 2 * math.pi)), min_size=2, max_size=4),
       st.integers(0, 2**16))
def test_every_group_escape_found_replays_clear(starts, seed):
    rng = np.random.default_rng(seed)
    poses = np.array(starts, dtype=np.float64)
    n = len(poses)
    v, r = rng.uniform(80.0, 150.0, n), rng.uniform(150.0, 250.0, n)
    length, width = rng.uniform(220.0, 300.0, n), rng.uniform(50.0, 70.0, n)
    need = np.full(n, 40.0)
    need[-1] = 0.0
    if n > 1:
        need[-2] = 25.0
    g = _group(poses, v, r, length, width, need)
    m = _search(g, wait_steps=8, max_straight_um=400.0)
    if m is None:
        return
    assert 0 <= m.k <= n - 2 and m.wait_s >= 0.0 and m.straight_s >= 0.0
    end = _replay(g, m, m.total_s)
    assert _slack(g, end, ARENA) >= -1e-6  # D_n's orbit ends clear: the search's own criterion, recomputed by hand
    start_sep = _body_gaps(g, m._replace(wait_s=0.0, straight_s=0.0), samples=1)
    assert (_body_gaps(g, m, samples=60) >= np.minimum(10.0, start_sep) - 5.0).all()


@settings(max_examples=40, deadline=None)
@given(st.lists(st.floats(-300.0, 300.0), min_size=8, max_size=8), st.floats(-100.0, 100.0))
def test_leg_watch_stops_the_leg_at_the_last_instant_the_pair_orbits_stay_apart(vals, need_shift):
    cn, cm = np.array(vals[:2]), np.array(vals[2:4]) + 600.0
    hn, hm = np.array(vals[4:6]), np.array(vals[6:8])
    hn, hm = hn / max(float(np.hypot(*hn)), 1e-9), hm / max(float(np.hypot(*hm)), 1e-9)
    taus = np.linspace(0.0, 8.0, 24)
    gaps = pair_gaps(cn, hn, 100.0, 200.0, cm, hm, 120.0, 180.0, taus)
    # by hand: centres carried straight
    for t, g in zip(taus, gaps, strict=True):
        assert math.isclose(g, math.dist(cn + 100.0 * t * hn, cm + 120.0 * t * hm) - 380.0, abs_tol=1e-6)
    need = 25.0 + need_shift
    stop = leg_stop_s(gaps, taus, need)
    keep = min(need, gaps[0])
    if gaps[0] < 0.0 or gaps[-1] >= keep:
        assert stop is None
    else:
        assert stop is not None and 0.0 <= stop < taus[-1]
        i = int(np.flatnonzero(taus == stop)[0])
        assert gaps[i] >= keep and (gaps[i + 1:] < keep).all()  # the last instant that keeps the gap


# tuning layout 19, plant seed 1, 2x noise, t = 9 s (D_1 .. D_7 in docking order): D_n (last) hemmed in beside a
# waiting robot near the arena corner; no group way out keeps 10 um between bodies, so every pair frame failed
TIGHT_POSES = np.array([[3459.199, 2476.206, 1.902], [855.687, 2440.684, 2.688], [2913.456, 3110.142, 2.834],
                        [656.404, 998.106, 0.629], [577.531, 1556.808, 4.283], [459.436, 3021.533, 5.199],
                        [3141.372, 3119.166, 4.982]])
TIGHT_ARENA = (3827.837, 3827.837)


def test_without_the_body_margin_a_hemmed_in_d_n_still_leaves_and_touches_nobody():
    """PairRecovery.group_escape's fallback (``Tuning.group_tight_body_um`` = 0): the margin-free way out exists where
    the default one does not, and replayed by hand the bodies graze by at most a few um between the search's samples
    (none with a 5 um margin exists) and D_n's orbit ends clear."""
    v = np.array([78.73, 102.58, 147.15, 113.0, 116.72, 90.86, 114.89])
    r = np.array([239.62, 246.87, 169.72, 244.45, 190.02, 238.87, 190.34])
    length = np.array([241.7, 271.1, 263.6, 289.0, 234.8, 262.3, 296.8])
    width = np.array([52.3, 56.5, 59.4, 63.5, 64.6, 68.0, 69.8])
    need = np.array([40.0, 40.0, 40.0, 40.0, 40.0, 25.0, 0.0])
    g = _group(TIGHT_POSES, v, r, length, width, need)

    def search(body: float):
        return group_escape(g, TIGHT_ARENA, edge_need=40.0, body_clearance=body, edge_clearance=40.0, disc_clearance=25.0)

    assert search(10.0) is None
    m = search(0.0)
    assert m is not None
    assert search(5.0) is None
    assert (_body_gaps(g, m)[:-1] > -5.0).all()  # replayed 10x finer than the search samples
    assert _slack(g, _replay(g, m, m.total_s), TIGHT_ARENA) >= -1e-6


@settings(max_examples=40, deadline=None)
@given(st.integers(0, 2**32 - 1))
def test_collides_flags_exactly_the_samples_whose_body_overlaps_an_orbiting_or_docked_body_then(seed):
    """escape_search._collides with zero floors against shapely: the orbiting bodies moved along their clockwise orbits
    to each sample's instant by the exact kinematics, polygons from the corners; near-touching samples skipped."""
    from shapely.geometry import Polygon

    from stressbots.control.escape_search import Orbiting, _collides
    from stressbots.kinematics import move
    from stressbots.robots import body_corners

    rng = np.random.default_rng(seed)
    s, k, b = 30, 3, 2
    mine = np.column_stack([rng.uniform(0, 900, s), rng.uniform(0, 900, s), rng.uniform(0, 6.3, s)])
    t = np.sort(rng.uniform(0, 20, s))
    o = Orbiting(np.column_stack([rng.uniform(0, 900, k), rng.uniform(0, 900, k), rng.uniform(0, 6.3, k)]),
                 rng.uniform(80, 150, k), rng.uniform(150, 250, k), rng.uniform(200, 300, k), rng.uniform(40, 70, k),
                 rng.uniform(250, 350, k), rng.uniform(10, 40, k))
    docked = (np.column_stack([rng.uniform(0, 900, b), rng.uniform(0, 900, b), rng.uniform(0, 6.3, b)]), [240.0, 260.0], [50.0, 60.0])
    hit = _collides(mine, t, 250.0, 55.0, o, np.zeros(k), None, 0.0, docked, 0.0)
    for q in range(s):
        me = Polygon(body_corners(mine[q][None, :], 250.0, 55.0)[0])
        others = [Polygon(body_corners(move(o.poses[j], o.speeds[j] * t[q], 1.0 / o.radii[j])[None, :], o.lengths[j],
                                       o.widths[j])[0]) for j in range(k)]
        others += [Polygon(body_corners(docked[0][j][None, :], docked[1][j], docked[2][j])[0]) for j in range(b)]
        areas = [me.intersection(p).area for p in others]
        if any(0.0 < me.distance(p) < 0.5 or 0.0 < a < 1.0 for p, a in zip(others, areas, strict=True)):
            continue
        assert bool(hit[q]) == any(a > 0.0 for a in areas)


def _replay_steps(g: Group, steps, t: float) -> np.ndarray:
    """Poses ``t`` s into a sequence of steps ``(k, seconds)`` (k = n: everyone orbits), by hand from :func:`_replay`."""
    n, poses = len(g.order), g.poses
    for k, d in steps:
        dt = min(t, d)
        if k >= n:
            m = GroupMove(0, dt, 0.0, 0.0)
        else:
            m = GroupMove(k, 0.0, dt, 0.0)
        poses = _replay(g._replace(poses=poses), m, dt)
        t -= dt
        if t <= 0.0:
            break
    return poses


def _sequence_body_gaps(g: Group, seq, samples: int = 80) -> np.ndarray:
    N = g.order[-1]
    gaps = np.full(len(g.poses), np.inf)
    for t in np.linspace(0.0, seq.total_s, samples):
        p = _replay_steps(g, seq.steps, float(t))
        for j in g.order[:-1]:
            gaps[j] = min(gaps[j], -float(penetration_depth(p[N][None], g.lengths[N], g.widths[N], p[j][None], g.lengths[j],
                                                            g.widths[j])[0]))
    return gaps


def _sequence(g: Group):
    return group_escape_sequence(g, ARENA, edge_need=40.0, body_clearance=10.0, edge_clearance=40.0, disc_clearance=25.0,
                                 wait_steps=8, max_straight_um=400.0, cut_um=80.0)


def test_two_robots_whose_every_single_way_out_meets_leave_in_two_steps():
    """Two robots alone, orbit discs overlapping (held-out 14:3 at 2x was this, and G_1 gave up at 100 s): no single
    group manoeuvre is clear, D_2 straight alone and then both straight is, replayed by hand."""
    poses = np.array([[1500.0, 1500.0, 3.3], [1254.33, 1825.48, 2.52]])
    g = Group((0, 1), poses, np.array([100.0, 110.0]), np.full(2, 200.0), np.full(2, 250.0), np.full(2, 60.0), np.full(2, 260.0),
              np.array([25.0, 40.0]))
    assert _slack(g, poses, ARENA) < 0.0
    assert _search(g) is None
    seq = _sequence(g)
    assert seq is not None and [k for k, _ in seq.steps] == [1, 0]
    assert _slack(g, _replay_steps(g, seq.steps, seq.total_s), ARENA) >= -1e-6
    start = _sequence_body_gaps(g, seq._replace(steps=()), samples=1)
    assert (_sequence_body_gaps(g, seq) >= np.minimum(10.0, start) - 5.0).all()


@settings(max_examples=20, deadline=None)
@given(st.floats(0.0, 2 * math.pi), st.floats(150.0, 420.0), st.floats(0.0, 2 * math.pi), st.floats(0.0, 2 * math.pi),
       st.integers(0, 2**16))
def test_every_escape_sequence_found_replays_clear(bearing, dist, th0, th1, seed):
    """Two or three robots with D_n's orbit overlapping D_(n-1)'s: a sequence, when found, leaves D_n's orbit clear and
    keeps the bodies apart throughout (independent replay); when a single group manoeuvre exists it is that one."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 4))
    poses = np.array([[1500.0, 1500.0, th0], [1500.0 + dist * math.sin(bearing), 1500.0 + dist * math.cos(bearing), th1],
                      [700.0, 2300.0, float(rng.uniform(0.0, 2 * math.pi))]])[:n]
    v, r = rng.uniform(80.0, 150.0, n), rng.uniform(150.0, 250.0, n)
    length, width = rng.uniform(220.0, 300.0, n), rng.uniform(50.0, 70.0, n)
    need = np.full(n, 40.0)
    need[0] = 25.0  # robot 0 is D_(n-1), robot 1 D_n, robot 2 (if any) D_1 far off
    order = (2, 0, 1) if n == 3 else (0, 1)
    g = Group(order, poses, v, r, length, width, orbit_radii(length, width, r), need)
    if penetration_depth(poses[order[-1]][None], length[order[-1]], width[order[-1]], poses[order[-2]][None],
                         length[order[-2]], width[order[-2]])[0] > -10.0:
        return  # bodies touching at the start: not a case the pair phase reaches
    single = group_escape(g, ARENA, edge_need=40.0, body_clearance=10.0, edge_clearance=40.0, disc_clearance=25.0, wait_steps=8,
                          max_straight_um=400.0)
    seq = _sequence(g)
    if single is not None:
        assert seq is not None and math.isclose(seq.total_s, single.total_s) and seq.slack_um == single.slack_um
    if seq is None:
        return
    assert all(0 <= k <= n and d > 0.0 for k, d in seq.steps)
    end = _replay_steps(g, seq.steps, seq.total_s)
    assert _slack(g, end, ARENA) >= -1e-6
    start = _sequence_body_gaps(g, seq._replace(steps=()), samples=1)
    assert (_sequence_body_gaps(g, seq) >= np.minimum(10.0, start) - 6.0).all()
