"""Closed-form kinematics (SPEC 3): the formula, exact composition, group motion, sampling, bodies."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots import kinematics as km
from stressbots.robots import body_corners, turning_centres

TWO_PI = 2 * math.pi

coord = st.floats(-5000, 5000, allow_nan=False)
heading = st.floats(-50, 50, allow_nan=False)
radius = st.floats(1.0, 2000.0)
length = st.floats(0.0, 5000.0)
poses = st.tuples(coord, coord, heading)


def spec_arc(pose, s, r):
    """SPEC 3 literally: after arc length s on the clockwise circle of radius r."""
    x, y, t = pose
    dphi = s / r
    return np.array([x + r * (math.cos(t) - math.cos(t + dphi)), y + r * (math.sin(t + dphi) - math.sin(t)), t + dphi])


def spec_straight(pose, s):
    x, y, t = pose
    return np.array([x + s * math.sin(t), y + s * math.cos(t), t])


def assert_pose_close(a, b, atol=1e-9):
    a, b = np.asarray(a, float), np.asarray(b, float)
    np.testing.assert_allclose(a[..., :2], b[..., :2], atol=atol, rtol=0)
    dtheta = np.mod(a[..., 2] - b[..., 2] + math.pi, TWO_PI) - math.pi
    np.testing.assert_allclose(dtheta, 0.0, atol=1e-9)


@settings(max_examples=100)
@given(poses, length, radius)
def test_move_matches_spec_arc_and_straight(pose, s, r):
    scale = 1.0 + abs(pose[0]) + abs(pose[1]) + s
    assert_pose_close(km.move(pose, s, 1.0 / r), spec_arc(pose, s, r), atol=1e-11 * scale)
    assert_pose_close(km.move(pose, s, 0.0), spec_straight(pose, s), atol=1e-11 * scale)


def test_heading_convention_and_turning_centre():
    # facing +y, a straight goes up; a clockwise quarter turn ends to the right facing +x
    np.testing.assert_allclose(km.move([0, 0, 0], 10.0, 0.0), [0, 10, 0], atol=1e-12)
    np.testing.assert_allclose(km.move([0, 0, 0], 100 * math.pi, 1 / 200), [200, 200, math.pi / 2], atol=1e-9)
    # facing +x (theta = pi/2) a straight goes +x
    np.testing.assert_allclose(km.move([0, 0, math.pi / 2], 10.0, 0.0), [10, 0, math.pi / 2], atol=1e-12)
    # the arc stays on the circle about robots.turning_centres
    p0 = np.array([3.0, -4.0, 0.7])
    c = turning_centres(p0, 150.0)[0]
    pts = km.move(p0, np.linspace(0, 2000, 57), 1 / 150)
    np.testing.assert_allclose(np.hypot(*(pts[:, :2] - c).T), 150.0, atol=1e-9)


@settings(max_examples=60)
@given(poses, radius, st.floats(0, 1000))
def test_derivative_is_the_model(pose, r, s):
    # d/ds (x, y, theta) = (sin theta, cos theta, kappa): seed eq. 4
    h = 1e-4
    for kappa in (0.0, 1.0 / r):
        a, b = km.move(pose, s - h, kappa), km.move(pose, s + h, kappa)
        mid = km.move(pose, s, kappa)
        d = (b[:2] - a[:2]) / (2 * h)
        np.testing.assert_allclose(d, [math.sin(mid[2]), math.cos(mid[2])], atol=1e-6)


@settings(max_examples=80)
@given(poses, length, length, st.sampled_from([0.0, 1 / 7.0, 1 / 200.0, 1 / 1e4]))
def test_composition_is_exact(pose, s1, s2, kappa):
    one = km.move(pose, s1 + s2, kappa)
    two = km.move(km.move(pose, s1, kappa), s2, kappa)
    scale = 1 + abs(pose[0]) + abs(pose[1]) + s1 + s2
    assert_pose_close(one, two, atol=1e-12 * scale)
    # negative length runs the arc backwards
    assert_pose_close(km.move(one, -s2, kappa), km.move(pose, s1, kappa), atol=1e-12 * scale)


def test_full_loop_returns_and_angles_wrapped():
    p = np.array([[1.0, 2.0, -0.3], [5.0, 5.0, 7.0], [0.0, 0.0, 2 * math.pi]])
    out = km.move(p, 2 * math.pi * 200.0, 1 / 200.0)
    np.testing.assert_allclose(out[:, :2], p[:, :2], atol=1e-10)
    assert np.all((out[:, 2] >= 0) & (out[:, 2] < TWO_PI))
    np.testing.assert_allclose(out[:, 2], km.wrap(p[:, 2]), atol=1e-12)
    assert km.wrap(-1e-300) == 0.0 and km.wrap(-0.0) == 0.0
    assert km.wrap(np.nextafter(0.0, -1)) == 0.0


def test_tiny_and_huge_arcs_are_accurate():
    # 1e-12 um on a tight arc, and a straight of 1 m on a 1e12 um radius
    out = km.move([0, 0, 0], 1e-12, 1 / 176.0)
    np.testing.assert_allclose(out, [1e-12**2 / (2 * 176), 1e-12, 1e-12 / 176], rtol=1e-9, atol=0)
    out = km.move([0, 0, 0], 1e6, 1e-12)
    np.testing.assert_allclose(out[:2], [1e6**2 * 1e-12 / 2, 1e6], rtol=1e-9)


@settings(max_examples=40)
@given(
    st.lists(st.tuples(poses, st.booleans(), st.floats(1, 300), st.floats(10, 500)), min_size=1, max_size=8),
    st.floats(0, 20),
)
def test_advance_group_equals_each_robot(robots, dt):
    p = np.array([r[0] for r in robots])
    turning = np.array([r[1] for r in robots])
    speed = np.array([r[2] for r in robots])
    rad = np.array([r[3] for r in robots])
    out = km.advance(p, turning, speed, rad, dt)
    assert out.shape == p.shape
    for i in range(len(robots)):
        s = speed[i] * dt
        want = spec_arc(p[i], s, rad[i]) if turning[i] else spec_straight(p[i], s)
        assert_pose_close(out[i], want, atol=1e-10 * (1 + abs(p[i, 0]) + abs(p[i, 1]) + s))
    # per-robot durations
    dts = np.linspace(0, dt, len(robots))
    out2 = km.advance(p, turning, speed, rad, dts)
    for i in range(len(robots)):
        assert_pose_close(out2[i], km.advance(p[i : i + 1], turning[i : i + 1], speed[i], rad[i], dts[i])[0])


def test_advance_rejects_bad_radius_and_accepts_straight_with_inf():
    with pytest.raises(ValueError, match="radius"):
        km.advance([[0, 0, 0]], [True], 100.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="radius"):
        km.advance([[0, 0, 0]], [True], 100.0, -5.0, 1.0)
    out = km.advance([[0, 0, 0], [0, 0, 0]], [False, True], 100.0, [0.0, np.inf], 1.0)
    np.testing.assert_allclose(out, [[0, 100, 0], [0, 100, 0]])


def test_follow_and_poses_along():
    start = np.array([10.0, -20.0, 1.0])
    lengths = np.array([100.0, 0.0, 250.0, 40.0])
    kappas = np.array([1 / 200, 0.0, 0.0, 1 / 200])
    nodes = km.follow(start, lengths, kappas)
    assert nodes.shape == (5, 3)
    p = start
    for s, k in zip(lengths, kappas, strict=False):
        p = spec_arc(p, s, 1 / k) if k else spec_straight(p, s)
    assert_pose_close(nodes[-1], p)
    s = np.array([0.0, 50.0, 100.0, 200.0, 350.0, 390.0, 1e9])
    out = km.poses_along(start, lengths, kappas, s)
    assert_pose_close(out[0], km.wrap_pose(start))
    assert_pose_close(out[1], km.move(start, 50.0, 1 / 200))
    assert_pose_close(out[3], km.move(nodes[1], 100.0, 0.0))
    assert_pose_close(out[5], nodes[-1])
    assert_pose_close(out[6], nodes[-1])  # clipped
    # batched paths: (N, K) lengths
    starts = np.array([[0, 0, 0], [1, 1, 1.0]])
    nb = km.follow(starts, np.array([[10.0, 20.0], [5.0, 0.0]]), np.array([[0.0, 0.1], [0.1, 0.0]]))
    assert nb.shape == (2, 3, 3)
    assert_pose_close(nb[1, -1], km.move(starts[1], 5.0, 0.1))
    # empty sequence
    assert_pose_close(km.poses_along(start, [], [], [0.0, 3.0]), [km.wrap_pose(start)] * 2)


def test_sample_arclengths_keeps_joints():
    s = km.sample_arclengths([10.0, 0.0, 3.0], 4.0)
    assert s[0] == 0.0 and s[-1] == 13.0
    assert 10.0 in s
    assert np.all(np.diff(s) <= 4.0 + 1e-12) and np.all(np.diff(s) >= 0)
    with pytest.raises(ValueError):
        km.sample_arclengths([1.0], 0.0)


@settings(max_examples=30)
@given(st.integers(1, 5), st.integers(1, 6), st.floats(5, 200), st.integers(0, 10**6))
def test_trajectory_replays_steps(n, k, step_um, seed):
    rng = np.random.default_rng(seed)
    poses = np.column_stack([rng.uniform(0, 3000, (n, 2)), rng.uniform(-7, 7, n)])
    turning = rng.random((k, n)) < 0.5
    durations = rng.uniform(0, 5, k)
    durations[0] = 0.0 if k > 1 else durations[0]
    speed = rng.uniform(50, 200, n)
    rad = rng.uniform(100, 300, n)
    times, traj = km.trajectory(poses, turning, durations, speed, rad, step_um=step_um)
    assert traj.shape == (times.size, n, 3)
    assert np.all(np.diff(times) >= 0) and math.isclose(times[-1], durations.sum(), abs_tol=1e-9)
    # every robot moves at most step_um between samples
    gaps = np.hypot(*(np.diff(traj[..., :2], axis=0)).transpose(2, 0, 1))
    assert np.all(gaps <= step_um * (1 + 1e-9))
    # the end equals chaining advance
    p = poses
    for row, dt in zip(turning, durations, strict=False):
        p = km.advance(p, row, speed, rad, dt)
    assert_pose_close(traj[-1], p, atol=1e-8)
    # coarse sampling ends at the same place
    _, coarse = km.trajectory(poses, turning, durations, speed, rad)
    assert coarse.shape[0] == k + 1
    assert_pose_close(coarse[-1], traj[-1], atol=1e-9)


def test_trajectory_validates():
    with pytest.raises(ValueError, match="durations"):
        km.trajectory([[0, 0, 0]], [[True]], [1.0, 2.0], 1.0, 1.0)
    with pytest.raises(ValueError, match=">= 0"):
        km.trajectory([[0, 0, 0]], [[True]], [-1.0], 1.0, 1.0)
    with pytest.raises(ValueError, match="radius"):
        km.trajectory([[0, 0, 0]], [[True]], [1.0], 1.0, 0.0)


def test_body_outlines_shape_and_geometry():
    poses = np.array([[[0, 0, 0], [100, 0, math.pi / 2]], [[5, 5, 1.0], [0, 0, 3.0]]])
    out = km.body_outlines(poses, [260.0, 200.0], 60.0)
    assert out.shape == (2, 2, 4, 2)
    np.testing.assert_allclose(out[0, 0], body_corners(poses[0, 0], 260.0, 60.0)[0])
    np.testing.assert_allclose(out[1, 1], body_corners(poses[1, 1], 200.0, 60.0)[0])
    # front edge of a robot facing +y is at y = L/2
    np.testing.assert_allclose(out[0, 0, :2, 1], 130.0)
    edges = np.hypot(*(out[..., 1, :] - out[..., 0, :]).T)
    np.testing.assert_allclose(edges, 60.0)


segment_lists = st.lists(st.tuples(st.sampled_from([0.0, 0.0, 1.0]), length, radius), min_size=1, max_size=8)


@settings(max_examples=200, deadline=None)
@given(start=poses, segments=segment_lists, s_frac=st.floats(-0.1, 1.1))
def test_one_path_in_plain_floats_is_bit_identical_to_the_array_composition(start, segments, s_frac):
    """``follow`` and ``poses_from_joints`` of one path run in plain floats (``_follow_one``, ``_move_one``);
    truth: ``move`` on arrays, one segment after the other, and on a batch of one query."""
    lengths = np.array([s for _, s, _ in segments])
    kappas = np.array([k / r for k, _, r in segments])
    fast = km.follow(np.array(start), lengths, kappas)
    pose, slow = np.array(start), [np.array(start)]
    for s, k in zip(lengths, kappas, strict=True):
        pose = km.move(pose[None, :], np.array([s]), np.array([k]))[0]
        slow.append(pose)
    assert np.array_equal(fast, np.stack(slow))
    cum = np.concatenate([[0.0], np.cumsum(lengths)])
    s = s_frac * cum[-1]
    one = km.poses_from_joints(fast, cum, kappas, s)
    batch = km.poses_from_joints(fast, cum, kappas, np.array([s]))[0]
    assert np.array_equal(one, batch)


@settings(max_examples=200, deadline=None)
@given(starts=st.lists(poses, min_size=1, max_size=6), segments=st.lists(segment_lists, min_size=6, max_size=6))
def test_end_poses_of_many_paths_in_plain_floats_are_bit_identical_to_move_segment_by_segment(starts, segments):
    """``follow_ends`` (one sine and one cosine call for every segment of every path); truth: ``move`` on
    arrays, one segment after the other, per path."""
    paths = [[(s, k / r) for k, s, r in segs] for segs in segments[: len(starts)]]
    fast = km.follow_ends(starts, paths)
    for start, path, end in zip(starts, paths, fast, strict=True):
        pose = np.array(start)
        for s, k in path:
            pose = km.move(pose[None, :], np.array([s]), np.array([k]))[0]
        assert np.array_equal(np.array(end), pose)
