"""D_{n-1}'s route to its station orbit (stressbots.control.station): pure geometry against brute force."""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.control.station import legs_clear, orbit_room, orbit_route, segment_disc_gaps

ARENA = (3000.0, 3000.0)


def sampled_gap(a, b, c, r, samples: int = 2001) -> float:
    """Brute force: the smallest distance from points along the segment to the disc's rim."""
    t = np.linspace(0.0, 1.0, samples)[:, None]
    p = np.asarray(a) + t * (np.asarray(b) - np.asarray(a))
    return float(np.min(np.hypot(*(p - np.asarray(c)).T)) - r)


coord = st.floats(0.0, 3000.0)


@settings(max_examples=80, deadline=None)
@given(coord, coord, coord, coord, coord, coord, st.floats(10.0, 400.0))
def test_segment_disc_gap_matches_sampling(ax, ay, bx, by, cx, cy, r):
    g = segment_disc_gaps(np.array([[ax, ay]]), np.array([[bx, by]]), np.array([[cx, cy]]), np.array([r]))[0, 0]
    brute = sampled_gap((ax, ay), (bx, by), (cx, cy), r)
    step = np.hypot(bx - ax, by - ay) / 2000.0
    assert brute - step - 1e-6 <= g <= brute + 1e-6


def route_is_clear(start, route, rstar, centres, radii, clearance) -> bool:
    """Every leg of the route keeps the capsule clearance (the first leg: never closer than it started)."""
    pts = [np.asarray(start)] + [np.asarray(p) for p in route]
    for n, (a, b) in enumerate(zip(pts[:-1], pts[1:], strict=True)):
        for c, r in zip(centres, radii, strict=True):
            need = rstar + clearance
            if n == 0:
                need = min(need, float(np.hypot(*(a - c))) - r - 1e-6)
            if sampled_gap(a, b, c, r) < need - 1.0:
                return False
        m = rstar + clearance
        if not (m - 1e-6 <= b[0] <= ARENA[0] - m + 1e-6 and m - 1e-6 <= b[1] <= ARENA[1] - m + 1e-6):
            return False
    return True


def test_blocked_straight_move_goes_around_the_orbit_in_the_way():
    """A lower robot's orbit sits on the straight line to the station: the route bends around it."""
    start, goal = np.array([600.0, 1500.0]), np.array([2400.0, 1500.0])
    centres, radii = np.array([[1500.0, 1500.0]]), np.array([250.0])
    assert not legs_clear(start[None], goal[None], 200.0, centres, radii, ARENA, 25.0, from_start=True)[0]
    route = orbit_route(start, goal, 200.0, centres, radii, ARENA, clearance=25.0)
    assert route is not None and len(route) >= 2
    assert np.allclose(route[-1], goal)
    assert route_is_clear(start, route, 200.0, centres, radii, 25.0)


def test_straight_move_when_clear_and_none_when_the_station_is_walled_in():
    start, goal = np.array([600.0, 600.0]), np.array([2400.0, 600.0])
    straight = orbit_route(start, goal, 200.0, np.zeros((0, 2)), np.zeros(0), ARENA, clearance=25.0)
    assert straight is not None and [list(p) for p in straight] == [list(goal)]
    # the station enclosed by a ring of orbits: no route
    ring = np.array([[2400.0 + 500.0 * np.cos(a), 1500.0 + 500.0 * np.sin(a)] for a in np.linspace(0, 2 * np.pi, 12, endpoint=False)])
    assert orbit_route(start, np.array([2400.0, 1500.0]), 200.0, ring, np.full(12, 150.0), ARENA, clearance=25.0) is None


@settings(max_examples=25, deadline=None)
@given(st.lists(st.tuples(st.floats(500.0, 2500.0), st.floats(500.0, 2500.0), st.floats(100.0, 300.0)), min_size=1, max_size=5),
       st.floats(300.0, 2700.0), st.floats(300.0, 2700.0))
def test_every_route_found_is_clear(discs, gx, gy):
    start = np.array([300.0, 300.0])
    centres = np.array([(x, y) for x, y, _ in discs])
    radii = np.array([r for _, _, r in discs])
    route = orbit_route(start, np.array([gx, gy]), 200.0, centres, radii, ARENA, clearance=25.0)
    if route is not None:
        assert np.allclose(route[-1], [gx, gy])
        assert route_is_clear(start, route, 200.0, centres, radii, 25.0)


@settings(max_examples=60, deadline=None)
@given(st.floats(300.0, 2700.0), st.floats(300.0, 2700.0), st.floats(0.0, 6.28), st.floats(80.0, 300.0), st.floats(150.0, 300.0),
       st.floats(30.0, 60.0))
def test_orbit_room_is_the_arena_gap_of_the_body_over_a_whole_orbit(x, y, th, r, L, W):
    """Against brute force: the body's gap to the arena edge, sampled along one whole clockwise orbit."""
    from stressbots.collision import arena_gap
    from stressbots.kinematics import move
    from stressbots.robots import orbit_radii

    pose = np.array([x, y, th])
    rstar = float(orbit_radii(L, W, r))
    room = orbit_room(pose[None], r, rstar, ARENA, np.zeros((0, 2)), [])[0]
    orbit = move(pose, np.linspace(0.0, 2.0 * np.pi * r, 1441), 1.0 / r)
    brute = float(arena_gap(orbit, L, W, ARENA).min())
    # the outer corner sweeps the orbit disc; sampling misses at most the chord's sagitta
    assert brute - 0.5 <= room <= brute + 1e-6


def test_orbit_room_counts_the_other_orbits():
    pose = np.array([[1000.0, 1000.0, 0.0]])  # heading +y: turning centre 100 um to the right
    free = orbit_room(pose, 100.0, 150.0, None, np.zeros((0, 2)), [])[0]
    near = orbit_room(pose, 100.0, 150.0, None, np.array([[1500.0, 1000.0]]), [200.0])[0]
    assert free == np.inf
    assert near == 400.0 - 150.0 - 200.0
