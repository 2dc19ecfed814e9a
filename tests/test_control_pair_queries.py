"""The G_1 phase's pure queries and recovery geometry on hand-built poses (stressbots.control.transfer_legs,
rendezvous, pair_recovery), each against an independent computation (corners by hand, approach-line
coordinates, distances between centres)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.control.pair_recovery import PairRecovery
from stressbots.control.queries import line_coords
from stressbots.control.rendezvous import arrival_region
from stressbots.control.transfer_legs import clear_tracks
from stressbots.robots import angle_difference, turning_centres


def corners(pose, L: float, W: float) -> np.ndarray:
    """The four corners of a body (theta clockwise from +y), by hand."""
    x, y, th = pose
    h = np.array([math.sin(th), math.cos(th)])
    r = np.array([math.cos(th), -math.sin(th)])
    return np.array([[x, y] + a * 0.5 * L * h + b * 0.5 * W * r for a in (-1, 1) for b in (-1, 1)])


@settings(max_examples=25, deadline=None)
@given(st.floats(100.0, 900.0), st.floats(0.0, 60.0), st.floats(100.0, 400.0))
def test_clear_tracks_keeps_the_body_inside_the_arena_along_the_whole_track(run_len, c, L):
    """Without discs, a straight track is clear iff both end bodies keep ``c`` from every wall (the arena is
    convex); the ends are the start and the last 40 um sample."""
    arena, W = (1200.0, 1000.0), 50.0
    far = (np.array([-1e6, -1e6]), 1.0)
    starts, samples, ok = clear_tracks(arena, L, W, run_len, 0.0, c, np.zeros((0, 2)), np.zeros(0), far, far)
    for k in range(0, len(starts), 7):
        ends = [samples[k, 0], samples[k, -1]]
        pts = np.vstack([corners(e, L, W) for e in ends])
        margin = float(np.min(np.concatenate([pts[:, 0] - c, arena[0] - c - pts[:, 0], pts[:, 1] - c, arena[1] - c - pts[:, 1]])))
        if abs(margin) < 1e-6:
            continue  # a corner exactly on the clearance line: either answer is a rounding of the same pose
        inside = margin > 0.0
        assert bool(ok[k]) == inside, (starts[k], ends)


def test_clear_tracks_keeps_the_buffer_clear_of_the_current_orbit_and_the_end_of_the_new_one():
    arena = (3000.0, 3000.0)
    none = np.zeros((0, 2)), np.zeros(0)
    far = (np.array([-1e6, -1e6]), 1.0)
    # heading +y from (1575, 975): the track passes (1575, 1200) during its first 300 um
    starts, _, ok_free = clear_tracks(arena, 200.0, 50.0, 600.0, 300.0, 10.0, *none, far, far)
    k = int(np.flatnonzero((starts[:, 0] == 1575.0) & (starts[:, 1] == 975.0) & (starts[:, 2] == 0.0))[0])
    _, _, ok_now = clear_tracks(arena, 200.0, 50.0, 600.0, 300.0, 10.0, *none, (np.array([1575.0, 1300.0]), 50.0), far)
    _, _, ok_end = clear_tracks(arena, 200.0, 50.0, 600.0, 300.0, 10.0, *none, far, (np.array([1575.0, 1575.0]), 50.0))
    _, _, ok_late = clear_tracks(arena, 200.0, 50.0, 600.0, 100.0, 10.0, *none, (np.array([1575.0, 1400.0]), 50.0), far)
    assert ok_free[k] and not ok_now[k] and not ok_end[k]
    assert ok_late[k]  # past the buffer D_{n-1} has left that orbit


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 3000.0), st.floats(0.0, 3000.0), st.floats(0.0, 2 * math.pi), st.floats(50.0, 300.0))
def test_arrival_region_lies_on_and_beside_the_target_line(x, y, th, v):
    target = np.array([x, y, th])
    goals, offset, penalty = arrival_region(target, v)
    for g, off, pen in zip(goals, offset, penalty, strict=True):
        behind, right, psi = line_coords(target, g)
        along = -behind
        assert math.isclose(off, along / v, abs_tol=1e-9)  # further along: later by that much driving
        assert -100.0 - 1e-6 <= along <= 100.0 + 1e-6 and -20.0 - 1e-6 <= right <= 40.0 + 1e-6
        assert abs(psi) <= math.radians(6.0) + 1e-9
        assert math.isclose(pen, abs(along) / 100.0 + abs(right) / 40.0 + abs(psi) / math.radians(6.0), abs_tol=1e-6)
    best = goals[np.argmin(penalty)]
    assert penalty.min() == 0.0 and np.allclose(best[:2], target[:2]) and abs(angle_difference(best[2], th)) < 1e-9


def fake_pair(est, r, rstar, arena=(2000.0, 2000.0)):
    """A PairRecovery on a hand-built snapshot: robot 0 is D_n, robot 1 D_{n-1}, the rest lower robots."""
    est = np.asarray(est, float)
    loop = SimpleNamespace(est=est, r_hat=np.asarray(r, float), rstar=np.asarray(rstar, float), n=len(est),
                           scn=SimpleNamespace(arena_um=arena), by_rank={len(est): 0, len(est) - 1: 1})
    pair = SimpleNamespace(loop=loop, centre=lambda i: turning_centres(loop.est[i], loop.r_hat[i])[0])
    return PairRecovery(pair), loop  # type: ignore[arg-type]  # duck-typed: escape_gaps reads only these


def test_escape_gaps_measure_orbits_and_edges_and_point_away():
    # D_n near the left edge heading +y (centre 100 um to its right), D_{n-1} and one lower robot elsewhere
    rec, loop = fake_pair([[150.0, 1000.0, 0.0], [1000.0, 1000.0, 0.0], [700.0, 1600.0, math.pi]], [100.0] * 3, [150.0] * 3)
    gaps = rec.escape_gaps(0, [1, 2])
    c = turning_centres(loop.est, loop.r_hat)
    assert math.isclose(gaps[0][0], float(np.hypot(*(c[0] - c[1]))) - 300.0)
    assert math.isclose(gaps[1][0], float(np.hypot(*(c[0] - c[2]))) - 300.0)
    # edges: left, right, bottom, top, measured from D_n's turning centre (250, 1000)
    assert [round(g) for g, _ in gaps[2:]] == [100, 1600, 850, 850]
    assert [a for _, a in gaps[2:]] == [0.5 * math.pi, 1.5 * math.pi, 0.0, math.pi]
    for g, away in gaps[:2]:
        # a straight run along "away" moves D_n's centre (with its body) away from that orbit: more room
        moved = loop.est[0] + np.array([10.0 * math.sin(away), 10.0 * math.cos(away), 0.0])
        rec2, _ = fake_pair([moved, loop.est[1], loop.est[2]], [100.0] * 3, [150.0] * 3)
        assert rec2.escape_gaps(0, [1, 2])[gaps.index((g, away))][0] > g


def test_meets_others_compares_bodies_at_the_same_instants():
    """Robots side by side, heading the same way, 50 um wide. By hand: 60 um centre to centre is a 10 um gap,
    inside g1_clearance already; 1500 um apart nothing meets; D_n straight while the robot 110 um to its
    right turns away (clockwise) only gains room; both turning clockwise with the other 110 um to the left,
    the gap between their long sides is 110 cos(turn) - 50 um: under 25 um once they have turned 48 deg."""
    from stressbots.control.tuning import Tuning

    def made(dx):
        rec, loop = fake_pair([[1000.0, 1000.0, 0.0], [1000.0 + dx, 1000.0, 0.0]], [150.0, 150.0], [200.0, 200.0])
        loop.v_hat, loop.L, loop.W, loop.tune = np.array([100.0, 100.0]), np.array([200.0, 200.0]), np.array([50.0, 50.0]), Tuning()
        return rec

    near, far = made(60.0), made(1500.0)
    assert near.meets_others(0, [1], 1.0 / 150.0, 1.0)
    assert not far.meets_others(0, [1], 1.0 / 150.0, 2.0)
    wide = made(110.0)
    assert not wide.meets_others(0, [1], 0.0, 1.0)
    left = made(-110.0)
    assert left.meets_others(0, [1], 1.0 / 150.0, 1.5)  # 1.5 s at 100 um/s on r = 150 um: 57 deg
    assert not left.meets_others(0, [1], 1.0 / 150.0, 0.9)  # 34 deg: 41 um apart


# -- meeting where they stand: the cost of both driving straight into each other -----------------------------


def _brute_meeting_cost(pN, vN, LN, pM, vM, LM, dt=1e-4, t_max=30.0):
    """Independent: step both bodies straight in time until D_n's front midpoint passes D_(n-1)'s front line; the
    lateral offset of the fronts then (um, along D_(n-1)'s right) and the heading mismatch, as a cost; None if the
    front never passes within ``t_max`` s or starts behind it."""
    def front(p, v, L, t):
        h = np.array([math.sin(p[2]), math.cos(p[2])])
        return p[:2] + (0.5 * L + v * t) * h, h

    def along(t):
        fN, _ = front(pN, vN, LN, t)
        fM, hM = front(pM, vM, LM, t)
        return float((fN - fM) @ hM)

    if along(0.0) <= 0.0:
        return None
    t = 0.0
    while along(t) > 0.0:
        t += dt
        if t > t_max:
            return None
    fN, _ = front(pN, vN, LN, t)
    fM, _ = front(pM, vM, LM, t)
    right = np.array([math.cos(pM[2]), -math.sin(pM[2])])
    alpha = abs(math.degrees(float(angle_difference(pM[2], pN[2] + math.pi))))
    return max(abs(float((fN - fM) @ right)) / 80.0, alpha / 60.0)


@settings(max_examples=40, deadline=None)
@given(st.floats(-60.0, 60.0), st.floats(50.0, 600.0), st.floats(-40.0, 40.0), st.floats(60.0, 150.0), st.floats(60.0, 150.0))
def test_meeting_cost_matches_stepping_both_bodies_straight(lateral, gap, mismatch_deg, vN, vM):
    from stressbots.control.queries import meeting_cost

    LN, LM = 220.0, 260.0
    pM = np.array([100.0, 200.0, 0.3])
    hM = np.array([math.sin(pM[2]), math.cos(pM[2])])
    right = np.array([math.cos(pM[2]), -math.sin(pM[2])])
    fN = pM[:2] + (0.5 * LM + gap) * hM + lateral * right
    thN = pM[2] + math.pi + math.radians(mismatch_deg)
    pN = np.array([*(fN - 0.5 * LN * np.array([math.sin(thN), math.cos(thN)])), thN])
    got = meeting_cost(pN, vN, LN, pM, vM, LM)
    want = _brute_meeting_cost(pN, vN, LN, pM, vM, LM)
    assert (got is None) == (want is None)
    if got is not None and want is not None:
        assert abs(got - want) < 0.01


def test_enters_discs_only_when_a_turn_carries_d_n_onto_an_orbit_it_is_not_on():
    """D_n at (1000, 1000) heading +y turns clockwise about (1150, 1000) (r = 150 um, 100 um/s; body 200 x 50 um).
    By hand: after a turn of a it is at (1150 - 150 cos a, 1000 + 150 sin a) heading a. A lower robot's orbit disc of
    r* = 200 um about (1150, 1350): at a = 90 deg D_n's long side lies at y = 1175, 175 um from the disc's centre
    (inside); at a = 20 deg its nearest corner is over 220 um away (outside), and at the start 279 um. A disc about
    (1000, 1250), which D_n's front already reaches (150 um), is not *entered* by any turn."""
    from dataclasses import replace

    from stressbots.control.tuning import Tuning

    def made(disc_centre):
        other = [disc_centre[0] - 150.0, disc_centre[1], 0.0]  # heading +y: its turning centre 150 um to its right
        rec, loop = fake_pair([[1000.0, 1000.0, 0.0], other], [150.0, 150.0], [150.0, 200.0])
        loop.v_hat, loop.L, loop.W = np.array([100.0, 100.0]), np.array([200.0, 200.0]), np.array([50.0, 50.0])
        loop.tune = replace(Tuning(), recovery_keeps_off_discs=True)
        return rec, loop

    def nearest(loop, a_deg, centre):
        a = math.radians(a_deg)
        pose = (1150.0 - 150.0 * math.cos(a), 1000.0 + 150.0 * math.sin(a), a)
        c = corners(pose, 200.0, 50.0)
        # distance from the centre to the rectangle: to each edge segment, by hand
        best = math.inf
        for p, q in ((c[0], c[1]), (c[1], c[3]), (c[3], c[2]), (c[2], c[0])):
            t = float(np.clip(np.dot(centre - p, q - p) / np.dot(q - p, q - p), 0.0, 1.0))
            best = min(best, float(np.hypot(*(centre - (p + t * (q - p))))))
        return best

    ahead = np.array([1150.0, 1350.0])
    rec, loop = made(ahead)
    assert nearest(loop, 0.0, ahead) > 200.0 and nearest(loop, 20.0, ahead) > 200.0 and nearest(loop, 90.0, ahead) < 200.0
    turn_s = lambda deg: math.radians(deg) * 150.0 / 100.0  # noqa: E731
    assert rec.enters_discs(0, [1], turn_s(90.0))
    assert not rec.enters_discs(0, [1], turn_s(20.0))
    on = np.array([1000.0, 1250.0])
    rec_on, loop_on = made(on)
    assert nearest(loop_on, 0.0, on) < 200.0
    assert not rec_on.enters_discs(0, [1], turn_s(90.0))
    loop.tune = Tuning()  # the default: off (session 13 measured no gain)
    assert not rec.enters_discs(0, [1], turn_s(90.0))


def _arc_or_line(pose, s: float, radius: float | None):
    """Pose after ``s`` um along a clockwise circle of ``radius`` (None: straight), by hand."""
    x, y, th = pose
    if radius is None:
        return x + s * math.sin(th), y + s * math.cos(th), th
    cx, cy = x + radius * math.cos(th), y - radius * math.sin(th)
    th2 = th + s / radius
    return cx - radius * math.cos(th2), cy + radius * math.sin(th2), th2


@settings(max_examples=30, deadline=None)
@given(st.floats(0.0, 2 * math.pi), st.floats(120.0, 420.0), st.floats(0.0, 2 * math.pi), st.floats(0.0, 2 * math.pi))
def test_pair_can_keep_apart_agrees_with_a_replay_of_the_three_primitives(bearing, dist, th_n, th_m):
    """True iff one of P_n (both turn), P_(n-1) (D_n straight), P_(n-2) (both straight), replayed by hand with
    shapely's polygon distance, keeps the bodies 10 um apart over the horizon (same instants, 1 um tolerance)."""
    from shapely.geometry import Polygon

    from stressbots.control.pair_geometry import pair_can_keep_apart

    body_n, body_m = (250.0, 60.0, 110.0, 200.0), (270.0, 55.0, 125.0, 240.0)
    pn = np.array([1000.0, 1000.0, th_n])
    pm = np.array([1000.0 + dist * math.sin(bearing), 1000.0 + dist * math.cos(bearing), th_m])

    def gap(a, b) -> float:
        ring = lambda p, body: Polygon(corners(p, body[0], body[1])[[0, 1, 3, 2]])  # noqa: E731
        return float(ring(a, body_n).distance(ring(b, body_m)))

    if gap(pn, pm) < 15.0:
        return  # the "as far apart as they are" clause: not what this replay checks
    ts = np.linspace(0.0, 3.0, 31)
    verdicts = []
    for rn, rm in ((body_n[3], body_m[3]), (None, body_m[3]), (None, None)):
        gaps = [gap(_arc_or_line(pn, body_n[2] * t, rn), _arc_or_line(pm, body_m[2] * t, rm)) for t in ts]
        verdicts.append(min(gaps))
    got = pair_can_keep_apart(pn, body_n, pm, body_m, horizon_s=3.0, floor_um=10.0)
    if got:
        assert max(verdicts) >= 10.0 - 1.0
    else:
        assert max(verdicts) < 10.0 + 1.0
