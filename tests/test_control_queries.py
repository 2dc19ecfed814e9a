"""Pure queries of the closed loop (stressbots.control.queries, se2, tuning) on hand-built snapshots.

Independent truth: the closed-form kinematics (:func:`stressbots.kinematics.move`) driven through the
manoeuvre a query returns, and shapely geometry for the slots of :func:`structure_targets`.
"""

from __future__ import annotations

import math
from dataclasses import FrozenInstanceError

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots import se2
from stressbots.control import ControllerOptions, Tuning, structure_targets
from stressbots.control.queries import (
    best_departure,
    in_funnel,
    line_coords,
    line_pose,
    merge,
    pose_on_orbit,
    turn_fraction,
)
from stressbots.kinematics import move
from stressbots.robots import angle_difference, orbit_radii, turning_centres

coord = st.floats(-2000.0, 2000.0)
angle = st.floats(-math.pi + 1e-3, math.pi - 1e-3)
poses = st.tuples(coord, coord, st.floats(0.0, 2 * math.pi))


@settings(max_examples=60, deadline=None)
@given(poses, st.floats(0.0, 800.0), st.floats(-200.0, 200.0), angle)
def test_line_coords_inverts_line_pose(goal, back, right, dtheta):
    goal = np.array(goal)
    b, r, d = line_coords(goal, line_pose(goal, back, right, dtheta))
    assert b == pytest.approx(back, abs=1e-6) and r == pytest.approx(right, abs=1e-6)
    assert d == pytest.approx(dtheta, abs=1e-9)


@settings(max_examples=60, deadline=None)
@given(poses, poses)
def test_se2_compose_inverse_and_frames(a, b):
    a, b = np.array(a), np.array(b)
    ident = se2.compose(a, se2.inverse(a))
    assert np.allclose(ident[:2], 0.0, atol=1e-9) and abs(angle_difference(ident[2], 0.0)) < 1e-9
    back = se2.from_frame(a, se2.to_frame(a, b))
    assert np.allclose(back[:2], b[:2], atol=1e-6) and abs(angle_difference(back[2], b[2])) < 1e-9
    # to_frame agrees with the approach-line coordinates: (right, ahead) = (right, -behind)
    bh, rt, ps = line_coords(a, b)
    local = se2.to_frame(a, b)
    assert local[0] == pytest.approx(rt, abs=1e-6) and local[1] == pytest.approx(-bh, abs=1e-6)
    assert local[2] == pytest.approx(ps, abs=1e-9)


@settings(max_examples=40, deadline=None)
@given(poses, st.tuples(coord, coord), st.floats(-math.pi, math.pi))
def test_se2_rotate_about_is_rigid(p, c, phi):
    p, c = np.array(p), np.array(c)
    q = se2.rotate_about(p, c, phi)
    assert np.hypot(*(q[:2] - c)) == pytest.approx(np.hypot(*(p[:2] - c)), abs=1e-6)
    assert abs(angle_difference(q[2], p[2] + phi)) < 1e-9
    # the heading turns with the body: the point ahead of p maps to the point ahead of q
    ahead = se2.rotate_about(np.array([*(p[:2] + 10.0 * se2.heading(p[2])), p[2]]), c, phi)
    assert np.allclose(ahead[:2], q[:2] + 10.0 * se2.heading(q[2]), atol=1e-6)


@settings(max_examples=80, deadline=None)
@given(st.floats(1.0, 40.0), st.floats(0.0, 60.0), st.floats(150.0, 250.0))
def test_merge_lands_on_the_line_parallel_to_it(psi_deg, right, r):
    """Driving the returned straight and arc (closed-form kinematics) ends parallel to the line, on it."""
    goal = np.array([1000.0, 1000.0, 0.7])
    behind = 5000.0  # a long corridor: a merge always exists from up to 60 um right, 1-40 deg left
    psi = -math.radians(psi_deg)
    m = merge(behind, right, psi, r)
    if right - r * (1.0 - math.cos(psi)) < -5.0:
        # the tightest arc (radius r, turning psi back) shifts the robot r (1 - cos psi) to the right:
        # from here it ends more than 5 um left of the line, and a one-way robot must loop
        assert m is None
        return
    assert m is not None
    s1, R = m
    assert R >= r - 1e-9 and s1 >= 0.0
    p = line_pose(goal, behind, right, psi)
    end = move(move(p, s1, 0.0), R * -psi, 1.0 / R)
    b, rt, d = line_coords(goal, end)
    assert abs(d) < 1e-9  # parallel to the line
    if right - r * (1.0 - math.cos(psi)) > 0.0:
        assert abs(rt) < 1e-6  # on it
    else:
        assert -5.0 - 1e-6 <= rt <= 0.0  # flattened with the tightest arc: at most 5 um left of it
    assert b >= 60.0 - 1e-6  # ends before the slot


def test_merge_refuses_a_robot_pointing_right_of_the_line_or_too_close():
    assert merge(400.0, 20.0, 0.0, 200.0) is None
    assert merge(400.0, 20.0, math.radians(5.0), 200.0) is None
    # 15 um right, 1 deg left: the straight alone takes ~860 um, more than the 340 um left before the slot
    assert merge(400.0, 15.0, -math.radians(1.0), 150.0) is None
    assert merge(1500.0, 15.0, -math.radians(1.0), 150.0) is not None


def test_funnel_on_hand_built_line_poses():
    t, r = Tuning(), 200.0
    assert in_funnel(300.0, 0.0, 0.0, 450.0, r, t)  # on the line, aligned
    assert in_funnel(500.0, 20.0, -math.radians(6.0), 450.0, r, t)  # right of it, pointing left: merges
    assert not in_funnel(300.0, 20.0, -math.radians(6.0), 450.0, r, t)  # the same, but the merge would end too near the slot
    assert not in_funnel(300.0, -100.0, 0.0, 450.0, r, t)  # left of the line: a one-way robot must loop
    assert not in_funnel(60.0, 0.0, 0.0, 450.0, r, t)  # too close to the slot
    assert not in_funnel(500.0, 20.0, math.radians(6.0), 450.0, r, t)  # right of it, pointing right


@settings(max_examples=60, deadline=None)
@given(st.floats(20.0, 800.0), st.floats(5.0, 400.0), st.floats(150.0, 250.0))
def test_turn_fraction_arc_passes_through_the_point(ahead, rightward, r):
    pose = np.array([200.0, -50.0, 1.1])
    point = se2.from_frame(pose, np.array([rightward, ahead, 0.0]))[:2]
    fr = turn_fraction(pose, point, r)
    if fr is None:  # only when the arc through the point would be tighter than r
        R = (ahead**2 + rightward**2) / (2.0 * rightward)
        assert R < r + 1e-6
        return
    rho, length, heading = fr
    assert 0.0 <= rho <= 1.0 + 1e-12
    end = move(pose, length, rho / r)  # interpolated turning: mean curvature rho / r
    assert np.hypot(*(end[:2] - point)) < 1e-6
    assert abs(angle_difference(end[2], heading)) < 1e-9


def test_turn_fraction_refuses_points_behind_or_left():
    pose = np.array([0.0, 0.0, 0.0])
    assert turn_fraction(pose, np.array([0.0, -100.0]), 200.0) is None  # behind
    assert turn_fraction(pose, np.array([-50.0, 300.0]), 200.0) is None  # left


@settings(max_examples=40, deadline=None)
@given(st.tuples(coord, coord), st.floats(100.0, 300.0), st.floats(0.0, 2 * math.pi))
def test_pose_on_orbit_has_that_turning_centre(c, r, th):
    p = pose_on_orbit(np.array(c), r, th)
    assert np.allclose(turning_centres(p, r)[0], c, atol=1e-6)
    assert abs(angle_difference(p[2], th)) < 1e-12


def _departure_snapshot(heading_n_deg):
    cM, rM, vM, wM = np.array([0.0, 0.0]), 200.0, 100.0, 0.5
    pN = np.array([1500.0, 200.0, math.radians(heading_n_deg)])  # on the line y = 200
    return pN, 100.0, 260.0, cM, rM, 0.0, wM, vM, 260.0, float(orbit_radii(260.0, 60.0, rM)), 0.6


def test_best_departure_lines_the_pair_up_head_on():
    """D_{n-1} orbits about the origin (heading 0 now); D_n drives toward it along y = 200, the tangent
    line of the orbit at heading 90 deg: the best departure is after a quarter turn, head-on."""
    args = _departure_snapshot(270.0)
    wait, cost = best_departure(*args)
    assert wait == pytest.approx(math.radians(90.0) / args[6], abs=math.radians(0.5) / args[6])
    assert cost < 0.02
    # the pair then meets: D_{n-1} from its tangent point, D_n straight on
    assert np.allclose(pose_on_orbit(args[3], args[4], math.radians(90.0))[:2], [0.0, 200.0], atol=1e-9)


def test_best_departure_none_when_d_n_points_away():
    assert best_departure(*_departure_snapshot(90.0)) is None


def test_tuning_is_frozen_and_options_carry_it():
    t = Tuning()
    with pytest.raises(FrozenInstanceError):
        t.pair_frames = 1  # type: ignore[misc]
    assert ControllerOptions().tuning == t
    assert ControllerOptions(tuning=Tuning(pair_frames=2)).tuning.pair_frames == 2


def test_structure_targets_clear_of_later_orbits():
    """Slots chosen without a nominal plan: inside the arena and clear of the start orbit of every robot
    docking after them (checked with shapely, independently of the controller's own geometry)."""
    shapely = pytest.importorskip("shapely.geometry")
    from stressbots.electrostatics import analyse_scenario
    from stressbots.generate import random_scenario
    from stressbots.robots import body_corners

    scn = random_scenario(5, 3, shape="comb")
    goals = structure_targets(scn).goals
    order = analyse_scenario(scn).order_index
    assert order is not None  # a STRING scenario has a docking order
    rank = {int(i): k + 1 for k, i in enumerate(order)}
    L, W, R = scn.lengths_um, scn.widths_um, scn.turn_radii_um
    centres, rs = turning_centres(scn.starts, R), orbit_radii(L, W, R)
    assert scn.arena_um is not None  # random scenarios always have an arena
    w, h = scn.arena_um
    arena = shapely.box(0.0, 0.0, w, h)
    for a in range(scn.n):
        body = shapely.Polygon(body_corners(goals[a][None, :], L[a : a + 1], W[a : a + 1])[0])
        assert arena.contains(body)
        for b in range(scn.n):
            if rank[b] < rank[a]:
                assert not body.intersects(shapely.Point(*centres[b]).buffer(rs[b], 256)), (a, b)


# -- the slots follow the structure as docked (session 29) --------------------------------------------------------


@settings(max_examples=50, deadline=None)
@given(st.floats(-20.0, 20.0), st.floats(-20.0, 20.0), st.floats(-4.0, 4.0), st.integers(2, 5), st.integers(0, 2**31 - 1))
def test_refit_slots_moves_the_rest_with_the_rigid_motion_the_docked_ones_took(dx, dy, phi_deg, m, seed):
    """Docked robots estimated exactly where one rigid motion (clockwise ``phi`` about the origin, then ``(dx, dy)``)
    takes their slots: every other slot is moved by that same motion (brute force with :func:`se2`-free arithmetic),
    and ``retarget`` with the returned motion moves any nominal pose the same way."""
    from stressbots.control.slot_approach import retarget
    from stressbots.control.targets import refit_slots

    rng = np.random.default_rng(seed)
    n = m + 3
    nominal = np.column_stack([rng.uniform(500, 2500, n), rng.uniform(500, 2500, n), rng.uniform(0, 2 * math.pi, n)])
    phi = math.radians(phi_deg)
    c, s = math.cos(phi), math.sin(phi)

    def moved(p):
        x, y = p[..., 0], p[..., 1]
        return np.stack([x * c + y * s + dx, -x * s + y * c + dy, np.mod(p[..., 2] + phi, 2 * math.pi)], axis=-1)

    docked = np.zeros(n, dtype=bool)
    docked[:m] = True
    est = np.where(docked[:, None], moved(nominal), np.nan)
    fit = refit_slots(nominal, est, docked, rng.uniform(200, 300, n), rng.uniform(50, 80, n))
    assert fit is not None
    slots, motion = fit
    want = moved(nominal)
    assert np.allclose(slots[:, :2], want[:, :2], atol=1e-6)
    assert np.allclose(angle_difference(slots[:, 2], want[:, 2]), 0.0, atol=1e-9)
    assert np.allclose(retarget(nominal[-1], motion)[:2], want[-1, :2], atol=1e-6)


def test_refit_slots_needs_two_docked_robots():
    from stressbots.control.targets import refit_slots

    g = np.array([[0.0, 0.0, 0.0], [0.0, 300.0, 0.0]])
    assert refit_slots(g, g, np.array([True, False]), np.full(2, 250.0), np.full(2, 60.0)) is None


def test_refit_slots_splits_one_robots_miss_with_the_rest():
    """Three docked in a row, the middle one 9 um to the right of its slot: by symmetry the best fit of their corners
    only translates, by the mean of the three offsets, so the next slot moves 3 um right (not 9, not 0)."""
    from stressbots.control.targets import refit_slots

    g = np.array([[0.0, 0.0, 0.0], [0.0, 300.0, 0.0], [0.0, 600.0, 0.0], [0.0, 900.0, 0.0]])
    est = g.copy()
    est[1, 0] += 9.0
    fit = refit_slots(g, est, np.array([True, True, True, False]), np.full(4, 250.0), np.full(4, 60.0))
    assert fit is not None
    assert np.allclose(fit[0][3], [3.0, 900.0, 0.0], atol=1e-9)
