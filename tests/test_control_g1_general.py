"""G_1 made general (issue 12, branch g1six): D_n's searched escape and D_(n-1)'s swept-body station routes,
checked against brute force (bodies simulated in time, legs sampled densely) on hand-built snapshots."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.collision import arena_gap, bodies_hit_discs, penetration_depth
from stressbots.control.escape_search import Orbiting, escape_manoeuvre, orbit_slack
from stressbots.control.station import Body, legs_clear, orbit_route, swept_legs_clear
from stressbots.kinematics import move
from stressbots.robots import orbit_radii, turning_centres

ARENA = (3000.0, 3000.0)
L_N, W_N, R_N, V_N = 260.0, 60.0, 180.0, 90.0
RSTAR_N = float(orbit_radii(L_N, W_N, R_N))


def one_orbiting(pose, r=200.0, L=280.0, W=60.0, v=80.0, need=25.0) -> Orbiting:
    return Orbiting(np.array([pose], float), np.array([v]), np.array([r]), np.array([L]), np.array([W]),
                    np.array([float(orbit_radii(L, W, r))]), np.array([need]))


def replay(pose, m, others: Orbiting, dt: float = 0.02):
    """Brute force: D_n's poses and the others' at the same instants along manoeuvre ``m`` (fine time steps)."""
    t = np.arange(0.0, m.total_s + dt, dt)
    t = np.minimum(t, m.total_s)
    s1 = np.minimum(t, m.lead_s) * V_N
    s2 = np.clip(t - m.lead_s, 0.0, m.turn_s) * V_N
    s3 = np.clip(t - m.lead_s - m.turn_s, 0.0, m.straight_s) * V_N
    p = move(np.asarray(pose, float), s1, 0.0)
    p = move(p, s2, 1.0 / R_N)
    p = move(p, s3, 0.0)
    theirs = [move(others.poses[j], others.speeds[j] * t, 1.0 / others.radii[j]) for j in range(len(others.poses))]
    return p, theirs


def test_orbit_slack_counts_orbits_edge_and_need():
    o = one_orbiting([1500.0, 1500.0, 0.0])
    oc = turning_centres(o.poses, o.radii)[0]
    c = oc + np.array([700.0, 0.0])
    got = orbit_slack(c[None], RSTAR_N, o, ARENA, 40.0)[0]
    assert math.isclose(got, 700.0 - RSTAR_N - o.rstar[0] - 25.0)
    # near the edge the edge decides
    assert math.isclose(orbit_slack(np.array([[RSTAR_N + 50.0, 1500.0]]), RSTAR_N, o, ARENA, 40.0)[0], 10.0)


@settings(max_examples=40, deadline=None)
@given(st.floats(0.0, 2 * math.pi), st.floats(0.0, 2 * math.pi), st.floats(0.3, 0.95))
def test_escape_keeps_bodies_apart_in_time_and_ends_clear(phase_other, heading, overlap):
    """D_n's orbit overlaps an orbiting robot's disc (by up to most of its radius): any manoeuvre returned keeps the
    bodies apart at every instant (replayed at 20 ms) and leaves D_n's orbit clear of the other's."""
    other_c = np.array([1500.0, 1500.0])
    r_o = 200.0
    other_pose = np.array([other_c[0] - r_o * math.cos(phase_other), other_c[1] + r_o * math.sin(phase_other), phase_other])
    o = one_orbiting(other_pose, r=r_o)
    d = RSTAR_N + o.rstar[0] - overlap * RSTAR_N  # centre distance: discs overlap
    my_c = other_c + d * np.array([math.cos(0.3), math.sin(0.3)])
    pose = np.array([my_c[0] - R_N * math.cos(heading), my_c[1] + R_N * math.sin(heading), heading])
    if (penetration_depth(pose[None], L_N, W_N, other_pose[None], o.lengths[0], o.widths[0]) > -30.0).any():
        return  # bodies already touching: not the situation the search is for
    m = escape_manoeuvre(pose, V_N, R_N, L_N, W_N, RSTAR_N, o, ARENA, edge_need=40.0, body_clearance=25.0, edge_clearance=40.0)
    if m is None:
        return
    mine, theirs = replay(pose, m, o)
    depth = penetration_depth(mine, L_N, W_N, theirs[0], o.lengths[0], o.widths[0])
    # the search samples D_n every 20 um / 5 deg: between samples the gap may shrink by a little
    assert depth.max() < -25.0 + 12.0
    assert arena_gap(mine, L_N, W_N, ARENA).min() > 0.0
    if m.slack_um >= 0.0:
        end_c = turning_centres(mine[-1], R_N)[0]
        oc = turning_centres(o.poses, o.radii)[0]
        assert np.hypot(*(end_c - oc)) - RSTAR_N - o.rstar[0] - 25.0 >= -1e-6


def test_escape_found_where_turning_away_at_once_is_blocked():
    """The tuning-19 situation: the other body beside D_n's turn. A straight first, or a later turn, gets out."""
    other_c = np.array([1500.0, 1500.0])
    o = one_orbiting([other_c[0] - 200.0, other_c[1], 0.0])  # on the left of its orbit, heading +y
    pose = np.array([other_c[0] - 200.0 + 90.0, 1500.0 - 40.0, 0.0])  # beside it, heading +y, orbits overlap
    m = escape_manoeuvre(pose, V_N, R_N, L_N, W_N, RSTAR_N, o, ARENA, edge_need=40.0, body_clearance=10.0, edge_clearance=40.0)
    assert m is not None
    mine, theirs = replay(pose, m, o)
    assert penetration_depth(mine, L_N, W_N, theirs[0], o.lengths[0], o.widths[0]).max() < 0.0


def test_escape_none_when_walled_in_by_the_arena_corner():
    """D_n in a corner, its orbit over both edges, heading into the corner: no turn or straight helps."""
    pose = np.array([L_N / 2 + 5.0, ARENA[1] - 0.5 * L_N - 5.0, 0.0])  # touching the top-left, heading +y (up)
    none = Orbiting(np.zeros((0, 3)), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0), np.zeros(0))
    m = escape_manoeuvre(pose, V_N, R_N, L_N, W_N, RSTAR_N, none, ARENA, edge_need=40.0, body_clearance=25.0, edge_clearance=40.0)
    assert m is None or m.slack_um < 0.0 or arena_gap(replay(pose, m, none)[0], L_N, W_N, ARENA).min() >= -1e-6


def brute_leg_clear(a, b, rstar, body: Body, centres, radii, clearance) -> bool:
    """Brute force: the body driven from its departure pose along the (biased) leg every 5 um, and its orbit at b."""
    d = np.asarray(b) - np.asarray(a)
    th = math.atan2(d[0], d[1]) - body.bias_rad
    start = np.array([a[0] - body.r_um * math.cos(th), a[1] + body.r_um * math.sin(th), th])
    ell = float(np.hypot(*d)) + body.overrun_um
    poses = move(start, np.append(np.arange(0.0, ell, 5.0), ell), 0.0)  # every 5 um, ending exactly at the leg's end
    if bodies_hit_discs(poses, body.length_um, body.width_um, centres, np.asarray(radii) + clearance - 1e-6).any():
        return False
    if (arena_gap(poses, body.length_um, body.width_um, ARENA) < clearance - 1e-6).any():
        return False
    gap_b = np.hypot(*(np.asarray(centres) - np.asarray(b)).T) - np.asarray(radii) - rstar
    return bool((gap_b >= clearance - 1e-6).all())


@settings(max_examples=60, deadline=None)
@given(st.floats(400.0, 2600.0), st.floats(400.0, 2600.0), st.floats(400.0, 2600.0), st.floats(400.0, 2600.0),
       st.lists(st.tuples(st.floats(300.0, 2700.0), st.floats(300.0, 2700.0), st.floats(100.0, 300.0)), min_size=1, max_size=4),
       st.floats(0.0, 0.06))
def test_swept_leg_clear_is_sound(ax, ay, bx, by, discs, bias):
    """Whenever swept_legs_clear passes a leg, the body driven along it (sampled every 5 um) and its orbit at the end
    keep the clearance: never a clear verdict on a leg that touches."""
    body = Body(R_N, L_N, W_N, 60.0, bias)
    centres = np.array([(x, y) for x, y, _ in discs])
    radii = np.array([r for _, _, r in discs])
    a, b = np.array([ax, ay]), np.array([bx, by])
    if np.hypot(*(b - a)) < 50.0:
        return
    ok = swept_legs_clear(a[None], b[None], RSTAR_N, body, centres, radii, ARENA, 25.0)[0]
    if ok:
        assert brute_leg_clear(a, b, RSTAR_N, body, centres, radii, 25.0)


def test_swept_route_passes_a_gap_narrower_than_the_orbit_disc():
    """A row of orbits across the arena, 300 um apart rim to rim: the capsule (orbit disc 2 r* = 494 um plus
    clearance) cannot pass, the body (60 um wide) can; the route found is clear by brute force."""
    start, goal = np.array([1530.0, 600.0]), np.array([1530.0, 2400.0])
    centres = np.array([[150.0, 1500.0], [950.0, 1500.0], [1750.0, 1500.0], [2550.0, 1500.0]])
    radii = np.full(4, 250.0)
    assert orbit_route(start, goal, RSTAR_N, centres, radii, ARENA, clearance=25.0) is None
    body = Body(R_N, L_N, W_N, 60.0, math.radians(3.0))
    route = orbit_route(start, goal, RSTAR_N, centres, radii, ARENA, clearance=25.0, body=body)
    assert route is not None and np.allclose(route[-1], goal)
    pts = [start, *route]
    for a, b in zip(pts[:-1], pts[1:], strict=True):
        assert brute_leg_clear(a, b, RSTAR_N, body, centres, radii, 25.0)
    assert not legs_clear(start[None], goal[None], RSTAR_N, centres, radii, ARENA, 25.0)[0]


def fake_transfer(est, r, rstar, arena=ARENA):
    """A StationTransfer on a hand-built snapshot (robot 0 is D_n; the others orbit below it)."""
    from types import SimpleNamespace

    from stressbots.control.transfer import StationTransfer
    from stressbots.control.tuning import Tuning

    loop = SimpleNamespace(est=np.asarray(est, float), r_hat=np.asarray(r, float), rstar=np.asarray(rstar, float),
                           scn=SimpleNamespace(arena_um=arena), tune=Tuning())
    return StationTransfer(SimpleNamespace(loop=loop))  # type: ignore[arg-type]  # duck-typed: keeps_room reads only these


def test_keeps_room_stops_before_the_edge_but_not_inside_an_orbit_it_overlaps():
    """Against orbit_room by hand: heading +y toward the top edge D_n stops once its predicted orbit would
    meet the edge; beside a lower orbit it already overlaps (running tangentially, the overlap unchanged) it
    goes on (the rule before stopped it there, its room shrinking), where stopping left it inside that orbit."""
    tr = fake_transfer([[1500.0, 2400.0, 0.0]], [R_N], [RSTAR_N])
    # centre (1680, 2400): 600 - r* = 353 um of room now; 400 um on (460 predicted) leaves none
    assert tr.keeps_room(0, 100.0, [])
    assert not tr.keeps_room(0, 400.0, [])
    # a lower orbit beside D_n's track, ahead: 1 um of room now, overlapping by 97 um at the predicted end
    other_c = np.array([1680.0 + 2 * RSTAR_N - 100.0, 1300.0])
    other = [other_c[0] - 200.0, other_c[1], 0.0]  # heading +y, turning radius 200 um: centre other_c
    tr = fake_transfer([[1500.0, 1000.0, 0.0], other], [R_N, 200.0], [RSTAR_N, RSTAR_N])
    from stressbots.control.station import orbit_room

    now, end = orbit_room(move(np.array([1500.0, 1000.0, 0.0]), np.array([0.0, 345.0]), 0.0), R_N, RSTAR_N, None,
                          other_c[None], [RSTAR_N])
    assert 0.0 < now < 15.0 and end < now
    assert tr.keeps_room(0, 300.0, [1])


@settings(max_examples=80, deadline=None)
@given(st.floats(-500, 500), st.floats(-500, 500), st.floats(0, 2 * math.pi), st.floats(50, 1500),
       st.floats(-500, 500), st.floats(-500, 500), st.floats(0, 2 * math.pi), st.floats(50, 1500), st.floats(0, 400))
def test_tracks_apart_is_the_least_distance_of_the_two_tracks(ax, ay, ath, alen, bx, by, bth, blen, gap):
    """Against brute force: the least distance between points every 0.5 um along both straight tracks (the
    closest pair of points is within 0.25 um of a sampled pair on each track, so a margin of 1 um decides)."""
    from stressbots.control.transfer_legs import tracks_apart

    a = move(np.array([ax, ay, ath]), np.linspace(0.0, alen, 7), 0.0)
    b = move(np.array([bx, by, bth]), np.linspace(0.0, blen, 5), 0.0)
    pa = move(a[0], np.arange(0.0, alen + 0.5, 0.5), 0.0)[:, :2]
    pb = move(b[0], np.arange(0.0, blen + 0.5, 0.5), 0.0)[:, :2]
    from scipy.spatial import cKDTree

    brute = float(cKDTree(pb).query(pa)[0].min())
    if abs(brute - gap) > 1.0:
        assert tracks_apart(a, b, gap) == (brute >= gap)


@pytest.mark.parametrize("beyond_s", [0.1, 0.2, 0.4, 0.8])
def test_d_n_minus_1s_station_leg_is_checked_clear_leg_overrun_s_past_its_end(beyond_s):
    """LegChoice.transfer_option on a hand-built snapshot: D_(n-1) (robot 1) orbits in the open and its leg runs
    ``d`` um straight; an obstacle lies across its track ``beyond_s`` seconds (at its speed) past the leg's end. The leg
    is refused (Replan) exactly when that is within ``Tuning.leg_overrun_s``: its straight is driven closed loop and
    stops at the leg's end, so only the last frame's overrun needs room (held-out 19:0 at 2x: a whole second past a via
    orbit reached into a waiting orbit and every pair frame failed in zero time)."""
    from types import SimpleNamespace

    from stressbots.control.pairloop import Replan
    from stressbots.control.queries import pose_on_orbit
    from stressbots.control.transfer_legs import LegChoice
    from stressbots.control.tuning import ControllerOptions, Tuning

    tune = Tuning()
    vM, rM, d = 100.0, 200.0, 400.0
    centre_M = np.array([1500.0, 1000.0])
    th_dep = 0.0  # departs heading +y
    mdep = pose_on_orbit(centre_M, rM, th_dep)
    wall_y = mdep[1] + d + vM * beyond_s  # the obstacle: everything of D_(n-1)'s centre line beyond this y

    def obstacles_hit(samples, i, orbiting, *, extra_discs=(), clearance=None, target=None):
        return bool(i == 1 and (np.asarray(samples)[:, 1] > wall_y).any())

    est = np.array([[600.0, 2400.0, math.pi / 2.0], [*mdep[:2], th_dep]])
    loop = SimpleNamespace(est=est, r_hat=np.array([R_N, rM]), v_hat=np.array([V_N, vM]), L=np.array([L_N, 250.0]),
                           W=np.array([W_N, 50.0]), rstar=np.array([RSTAR_N, float(orbit_radii(250.0, 50.0, rM))]),
                           scn=SimpleNamespace(arena_um=ARENA, names=("R0", "R1")), tune=tune, opts=ControllerOptions(),
                           obstacles_hit=obstacles_hit)
    pair = SimpleNamespace(loop=loop, centre=lambda i: centre_M if i == 1 else turning_centres(est[i], R_N))
    legs = LegChoice(pair)  # type: ignore[arg-type]  # duck-typed: transfer_option reads only these
    q_next = np.array([2000.0, 2000.0, 0.0])
    if beyond_s < tune.leg_overrun_s:
        with pytest.raises(Replan):
            legs.transfer_option(0, 1, 1.0, d, th_dep, [], centre_M + [0.0, d], q_next)
    else:
        legs.transfer_option(0, 1, 1.0, d, th_dep, [], centre_M + [0.0, d], q_next)  # no Replan: D_n's options follow


def _turn_together_drives(turns: bool = True, track_clear: bool = True) -> list:
    """The step lists ``StationTransfer._turn_together(0, 1, 12 s, fraction 0.5)`` drives on a hand-built loop: D_n (robot 0)
    and D_(n-1) (robot 1) at 0.4 rad/s, both turning the commanded amount when ``turns`` (D_n only under P_n, the first
    step of a t_x), D_n always with room to orbit and its straight track ``track_clear``."""
    from types import SimpleNamespace

    from stressbots.control.transfer import StationTransfer
    from stressbots.control.tuning import Tuning

    drives: list = []
    est = np.array([[1500.0, 1500.0, 0.0], [800.0, 800.0, 0.0]])
    omega = np.array([0.4, 0.4])

    def drive(steps):
        drives.append(steps)
        if turns:
            est[1, 2] += omega[1] * sum(d for _, d in steps)
            est[0, 2] += omega[0] * steps[0][1]

    loop = SimpleNamespace(n=2, est=est, omega_hat=omega, v_hat=np.array([80.0, 80.0]), tx=1.0, tune=Tuning(), drive=drive,
                           orbiting_below=lambda _k: [], scn=SimpleNamespace(names=("R0", "R1")))
    tr = StationTransfer(SimpleNamespace(loop=loop))  # type: ignore[arg-type]  # duck-typed
    tr.keeps_room = lambda *_a: True  # type: ignore[method-assign]
    tr.track_clear = lambda *_a: track_clear  # type: ignore[method-assign]
    tr._turn_together(0, 1, 12.0, 0.5)
    return drives


def test_a_held_d_n_minus_1_ends_its_transfer_turn_instead_of_turning_forever():
    """D_{n-1} (robot 1) held against something does not turn: its measured heading stays put while the turn is
    commanded a t_x at a time. After ``Tuning.turn_stall_frames`` such t_x the leg ends with a Replan (it turned
    nothing for 3900 s of simulated time before, until the time budget ran out); a robot that turns is not stopped."""
    from stressbots.control.pairloop import Replan

    with pytest.raises(Replan, match="does not turn"):
        _turn_together_drives(turns=False)
    assert len(_turn_together_drives(turns=True)) == 12


@pytest.mark.parametrize("track_clear", [True, False])
def test_d_n_runs_straight_in_the_transfer_turn_only_on_a_clear_track(track_clear):
    """``_turn_together``: D_n (robot 0) turns half of D_(n-1)'s 12 s turn, then runs straight under P_(n-1), but only
    while its straight track is clear (``track_clear``) as well as leaving it room to orbit (``keeps_room``, True here):
    a D_n already short of room from a lower orbit passes keeps_room, and unchecked it ran 176 um into that robot's
    orbit and docked against its body (held-out 33:0 at 1x). With its track blocked it turns with D_(n-1) throughout."""
    drives = _turn_together_drives(track_clear=track_clear)
    straight_s = sum(d for steps in drives for k, d in steps if k == 1)
    assert straight_s == pytest.approx(6.0 if track_clear else 0.0, abs=1e-6)
    assert sum(d for steps in drives for _, d in steps) == pytest.approx(12.0)  # D_(n-1)'s whole turn either way


def test_a_station_routes_via_orbits_keep_the_extra_margin_from_the_arena_edge():
    """Against the arena by hand: with ``via_wall_um`` every intermediate orbit of the route keeps r* + clearance +
    via_wall_um from each edge (the goal is the caller's); the route still ends at the goal. Without it the shortest
    route around this disc passes an orbit 56 um outside the clearance."""
    start, goal = np.array([400.0, 400.0]), np.array([2600.0, 2600.0])
    centres, radii = np.array([[1500.0, 1500.0]]), np.array([800.0])
    w, h = ARENA

    def wall(c) -> float:
        return float(min(c[0], w - c[0], c[1], h - c[1]))

    route = orbit_route(start, goal, RSTAR_N, centres, radii, ARENA, clearance=25.0, via_wall_um=60.0)
    assert route is not None and len(route) >= 2 and np.allclose(route[-1], goal)
    assert all(wall(c) >= RSTAR_N + 25.0 + 60.0 - 1e-9 for c in route[:-1])
    near = orbit_route(start, goal, RSTAR_N, centres, radii, ARENA, clearance=25.0)
    assert near is not None and min(wall(c) for c in near[:-1]) < RSTAR_N + 25.0 + 60.0


# -- a hold drive keeps D_n's loop ---------------------------------------------------------------------

@settings(max_examples=25, deadline=None)
@given(st.floats(300.0, 700.0), st.floats(-0.3, 0.3))
def test_a_hold_drive_stops_before_the_t_x_that_loses_d_ns_loop(disc_ahead, heading):
    """HoldingOrbit.loses_loop on a hand-built loop whose obstacle check is written here (a loop pose whose centre lies
    inside a disc hits it): D_n heading about north, an orbit disc ahead-right. Independent truth: the loop of
    radius R_N from a pose is the circle about its turning centre, so it meets the disc exactly when that centre's
    distance from the disc's centre is within the disc's radius of R_N (up to the 5 deg sampling of the loop)."""
    from types import SimpleNamespace

    from stressbots import paths as pathlib
    from stressbots.control.holding import HoldingOrbit
    from stressbots.robots import Pose

    disc_c, disc_r = np.array([2.0 * R_N, disc_ahead]), 150.0

    def obstacles_hit(samples, i, orbiting, *, extra_discs=(), clearance=0.0):
        return any(bool((np.hypot(*(samples[:, :2] - c).T) < r).any()) for c, r in extra_discs)

    start = np.array([0.0, 0.0, heading])
    hold = object.__new__(HoldingOrbit)
    hold.loop = SimpleNamespace(r_hat=np.array([R_N]), est=np.array([start]), obstacles_hit=obstacles_hit)
    path = pathlib.Path(Pose(*start), R_N, (("S", 2000.0),))
    disc = [(disc_c, disc_r)]

    def meets(pose) -> bool:
        return abs(float(np.hypot(*(turning_centres(np.asarray(pose), R_N) - disc_c).ravel())) - R_N) < disc_r - 5.0

    def clear(pose) -> bool:
        return abs(float(np.hypot(*(turning_centres(np.asarray(pose), R_N) - disc_c).ravel())) - R_N) > disc_r + 5.0

    for ahead in (0.0, 100.0, 200.0, 300.0, 400.0, 600.0):
        end = move(start, ahead, 0.0)
        got = hold.loses_loop(0, path, ahead, [], disc)
        if not clear(start):
            continue
        if meets(end):
            assert got
        elif clear(end):
            assert not got
    # a D_n whose loop meets the disc already has nothing to lose
    hold.loop.est = np.array([move(start, disc_ahead - 100.0, 0.0)])
    if meets(hold.loop.est[0]):
        assert not hold.loses_loop(0, path, 300.0, [], disc)


def test_d_n_s_drives_check_d_prev_s_body_at_the_same_instants():
    """PairPhase.body_gap (what D_n's timing loop checks every t_x): the least gap between
    D_n's and D_{n-1}'s bodies along the predicted track, at the same instants. Independent truth: two parallel bodies
    side by side, their long sides 7 um apart at one instant (the track brings them together, then apart), while the
    same poses a step apart in time never come that close; inf with ``Tuning.loop_body_clearance_um`` off."""
    from types import SimpleNamespace

    from stressbots.control.pair import PairPhase
    from stressbots.control.tuning import Tuning

    L, W = 250.0, 60.0
    xs = np.array([120.0, 80.0, 60.0 + 7.0, 90.0])  # D_n's x: the bodies 7 um apart at the third instant
    track = np.zeros((len(xs), 2, 3))
    track[:, 0, 0] = xs
    for tune, want in ((Tuning(loop_body_clearance_um=20.0), 7.0), (Tuning(loop_body_clearance_um=0.0), math.inf)):
        lp = SimpleNamespace(tune=tune, L=np.array([L, L]), W=np.array([W, W]), predicted_track=lambda _s, _t=track: _t)
        gap = PairPhase.body_gap(SimpleNamespace(loop=lp), 0, 1, [(1, 1.0)])  # type: ignore[arg-type]
        assert gap == pytest.approx(want)
    # D_{n-1} a step behind in time: at the instant D_n is at x = 67 the other body is elsewhere (y = 400 um)
    late = track.copy()
    late[:, 1, 1] = [0.0, 0.0, 400.0, 0.0]
    lp = SimpleNamespace(tune=Tuning(loop_body_clearance_um=20.0), L=np.array([L, L]), W=np.array([W, W]),
                         predicted_track=lambda _s: late)
    assert PairPhase.body_gap(SimpleNamespace(loop=lp), 0, 1, [(1, 1.0)]) == pytest.approx(80.0 - 60.0)  # type: ignore[arg-type]
