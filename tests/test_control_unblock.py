"""Waiting orbits moved off a docking robot's way (stressbots.control.parking.blocking_orbits / unblock_move,
stressbots.control.single.way_points): pure queries on hand-built snapshots, checked by brute force and by
replaying the manoeuvre with the kinematics (independent of the query's own geometry)."""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.control.parking import blocking_orbits, unblock_move
from stressbots.control.single import way_points
from stressbots.robots import orbit_radii, turning_centres

from .plants import replay_orbit_move

ARENA = (3000.0, 3000.0)
L, W, R, V = 250.0, 60.0, 230.0, 85.0
RSTAR = float(orbit_radii(L, W, R))


@settings(max_examples=30, deadline=None)
@given(st.lists(st.tuples(st.floats(0, 3000), st.floats(0, 3000), st.floats(50, 400)), min_size=1, max_size=5),
       st.lists(st.tuples(st.floats(0, 3000), st.floats(0, 3000)), min_size=1, max_size=8), st.floats(0.0, 200.0))
def test_blocking_orbits_matches_brute_force(discs, points, reach):
    c = np.array([d[:2] for d in discs])
    rs = np.array([d[2] for d in discs])
    got = blocking_orbits(c, rs, np.array(points), reach)
    for a, (cx, cy, r) in enumerate(discs):
        want = any(math.hypot(px - cx, py - cy) < r + reach for px, py in points)
        assert got[a] == want


def test_way_points_run_from_the_slot_back_along_the_approach_line_to_the_aim():
    goal = np.array([1000.0, 1000.0, math.radians(90.0)])  # heading +x: the line runs back towards -x
    aim = np.array([600.0, 980.0, math.radians(84.0)])
    pts = way_points(goal, aim, 400.0, step_um=50.0)
    assert np.allclose(pts[0], goal[:2]) and np.allclose(pts[-1], aim[:2])
    assert np.allclose(pts[:-1, 1], 1000.0) and np.allclose(np.diff(pts[:-1, 0]), -50.0)
    chord = way_points(goal, aim, None, step_um=50.0)  # S_2f: the straight chord from slot to aim
    assert np.allclose(chord[0], goal[:2]) and np.allclose(chord[-1], aim[:2])
    looped = way_points(goal, aim, 400.0, 150.0, 50.0)  # plus the clockwise loop (r = 150 um) through the aim
    extra = looped[len(pts):]
    centre = aim[:2] + 150.0 * np.array([math.cos(aim[2]), -math.sin(aim[2])])  # right of the heading
    assert np.allclose(np.hypot(*(extra - centre).T), 150.0, atol=1e-6) and len(extra) >= 8


def replay(poses, move, still):
    """The move replayed independently at this module's speed and radius (:func:`tests.plants.replay_orbit_move`)."""
    return replay_orbit_move(poses, move, still, V, R)


@settings(max_examples=15, deadline=None)
@given(st.floats(0.0, 2 * math.pi), st.floats(0.0, 2 * math.pi), st.floats(-150.0, 150.0))
def test_an_orbit_over_the_aim_moves_off_it_and_nobody_hits_anything(theta, theta_k, offset):
    """D_j waits with its disc over D_k's aim and corridor; after the manoeuvre (replayed) its disc is the margin
    clear of every way point, and no mover's disc came within 25 um of another or of the arena edge."""
    cj = np.array([1500.0, 1500.0 + offset])
    poses = np.array([
        [cj[0] - R * math.cos(theta), cj[1] + R * math.sin(theta), theta],  # D_j, waiting
        [700.0 - R * math.cos(theta_k), 700.0 + R * math.sin(theta_k), theta_k],  # D_k, the docking robot
    ])
    pts = way_points(np.array([1900.0, 1500.0, math.radians(90.0)]), np.array([1300.0, 1480.0, 1.5]), 600.0, step_um=25.0)
    reach = 0.5 * math.hypot(L, W) + 15.0
    centres = turning_centres(poses, np.full(2, R))
    assert blocking_orbits(centres[:1], [RSTAR], pts, reach)[0]
    move = unblock_move(0, [0, 1], [], poses, np.full(2, R), np.full(2, V / R), np.full(2, V), np.full(2, RSTAR), ARENA,
                        np.zeros((0, 3)), [], [], pts, reach_um=reach, margin_um=30.0, max_shift_um=900.0, clearance_um=25.0)
    assert move is not None
    path = replay(poses, move, [])
    end = turning_centres(path[-1], np.full(2, R))
    assert np.hypot(*(pts - end[0]).T).min() >= RSTAR + reach + 30.0 - 2.0
    for t in range(len(path)):
        c = turning_centres(path[t], np.full(2, R))
        assert np.hypot(*(c[0] - c[1])) - 2 * RSTAR >= 25.0 - 1.0
        for a in range(2):
            assert min(c[a][0], ARENA[0] - c[a][0], c[a][1], ARENA[1] - c[a][1]) - RSTAR >= 25.0 - 1.0


def test_no_unblock_move_when_no_heading_clears_the_way_within_the_cap():
    """D_j's disc 100 um from the aim needs a straight of several hundred um; capped at 100 um, none is offered
    (and with the cap lifted one is: along the wall, not into it)."""
    cj = np.array([RSTAR + 40.0, 1500.0])
    poses = np.array([[cj[0] - R, cj[1], 0.0]])
    pts = np.array([[cj[0] + 100.0, 1500.0]])
    move = unblock_move(0, [0], [], poses, np.full(1, R), np.full(1, V / R), np.full(1, V), np.full(1, RSTAR), ARENA,
                        np.zeros((0, 3)), [], [], pts, reach_um=150.0, margin_um=30.0, max_shift_um=100.0, clearance_um=25.0)
    assert move is None
    move = unblock_move(0, [0], [], poses, np.full(1, R), np.full(1, V / R), np.full(1, V), np.full(1, RSTAR), ARENA,
                        np.zeros((0, 3)), [], [], pts, reach_um=150.0, margin_um=30.0, max_shift_um=900.0, clearance_um=25.0)
    assert move is not None
    end = replay(poses, move, [])[-1]
    c = turning_centres(end, np.full(1, R))[0]
    assert c[0] - RSTAR >= 40.0 - 1.0 - 1e-6  # not closer to the wall than it was
    assert np.hypot(*(c - pts[0])) >= RSTAR + 150.0 + 30.0 - 2.0
