"""The controller's state estimation: pose filter and identification of speed and turn rate.

The truth is synthetic: robots moved by the closed-form kinematics with known speeds and radii, seen
through a camera with known noise.
"""

from __future__ import annotations

import math

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.estimation import Estimator
from stressbots.kinematics import advance, move
from stressbots.robots import angle_difference


def _camera(rng, poses, pos_sd=2.0, head_sd=math.radians(1.0)):
    out = poses.copy()
    out[:, :2] += rng.normal(0.0, pos_sd, (len(poses), 2))
    out[:, 2] = np.mod(out[:, 2] + rng.normal(0.0, head_sd, len(poses)), 2 * math.pi)
    return out


def _run(true_v, true_r, schedule, seed=0, frozen=None, noise=True):
    """Drive robots with ``schedule`` = [[(turning mask, duration)], ...] per frame; return (estimator, truth)."""
    rng = np.random.default_rng(seed)
    n = len(true_v)
    truth = np.column_stack([np.linspace(500.0, 2500.0, n), np.full(n, 1500.0), np.zeros(n)])
    frozen = np.zeros(n, dtype=bool) if frozen is None else frozen
    cam = (lambda p: _camera(rng, p)) if noise else (lambda p: p.copy())
    est = Estimator(cam(truth), truth, np.full(n, 100.0), np.full(n, 200.0))
    for steps in schedule:
        for turning, d in steps:
            moved = advance(truth, turning, true_v, true_r, d)
            truth = np.where(frozen[:, None], truth, moved)
        est.update(steps, frozen, cam(truth))
    return est, truth


def test_speed_identified_from_mixed_drives():
    """Drives that mix turning and straight motion still give the speed (the path scales with v)."""
    true_v, true_r = np.array([107.0, 94.0]), np.array([206.0, 193.0])
    rng = np.random.default_rng(1)
    schedule = []
    for _ in range(80):
        a = float(rng.uniform(0.0, 1.0))
        turn = np.array([True, True])
        schedule.append([(turn, a), (~turn, 1.0 - a)])
    est, _ = _run(true_v, true_r, schedule)
    assert np.allclose(est.speed, true_v, rtol=0.006), est.speed


def test_turn_rate_identified_over_an_orbit():
    true_v, true_r = np.array([103.0]), np.array([191.0])
    turn = np.array([True])
    est, _ = _run(true_v, true_r, [[(turn, 1.0)]] * 40)
    assert abs(est.turn_rate[0] - true_v[0] / true_r[0]) / (true_v[0] / true_r[0]) < 0.002
    # the orbit's chords scale with the speed too (radius v / omega at a known omega)
    assert abs(est.speed[0] - true_v[0]) / true_v[0] < 0.005


def test_a_held_robot_is_placed_at_the_mean_of_its_frames():
    est, truth = _run(np.array([100.0]), np.array([200.0]), [[(np.array([False]), 1.0)]] * 36, frozen=np.array([True]))
    err = np.hypot(*(est.pose[0, :2] - truth[0, :2]))
    assert err < 1.5  # one frame: 2 um sd per axis; the mean of 36: 0.33 um
    assert abs(math.remainder(est.pose[0, 2] - truth[0, 2], 2 * math.pi)) < math.radians(0.6)


def test_a_frame_far_from_the_prediction_replaces_it():
    est = Estimator(np.array([[0.0, 0.0, 0.0]]), np.zeros((1, 3)), np.array([100.0]), np.array([200.0]))
    est.update([(np.array([False]), 1.0)], np.array([False]), np.array([[0.0, 40.0, 0.0]]))  # it stopped early
    assert np.allclose(est.pose[0], [0.0, 40.0, 0.0])


def test_unseen_robot_keeps_its_prediction():
    est = Estimator(np.array([[0.0, 0.0, 0.0]]), np.zeros((1, 3)), np.array([100.0]), np.array([200.0]))
    est.update([(np.array([False]), 1.0)], np.array([False]), np.full((1, 3), np.nan))
    assert np.allclose(est.pose[0], [0.0, 100.0, 0.0]) and est.unseen[0] == 1


@settings(max_examples=40, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.floats(0.05, 2.0)), min_size=1, max_size=12))
def test_exact_model_and_camera_keep_the_estimate_exact(steps):
    """With the true model and a perfect camera the filter never moves the estimate off the truth."""
    sched = [[(np.array([t]), d)] for t, d in steps]
    est, truth = _run(np.array([100.0]), np.array([200.0]), sched, noise=False)
    assert np.allclose(est.pose[0, :2], truth[0, :2], atol=1e-6)
    assert abs(math.remainder(est.pose[0, 2] - truth[0, 2], 2 * math.pi)) < 1e-9
    assert abs(est.speed[0] - 100.0) < 1e-6 and abs(est.turn_rate[0] - 0.5) < 1e-9


def test_predictions_in_plain_floats_are_move_step_after_step_bit_for_bit():
    """``Estimator.predict`` (plain floats) against ``move`` on the arrays, one step after the other,
    frozen robots kept, headings wrapped at the end (the array form it replaced)."""
    rng = np.random.default_rng(8)
    n = 5
    est = Estimator(rng.uniform(0, 500, (n, 3)), np.zeros((n, 3)), rng.uniform(50, 150, n), rng.uniform(100, 300, n))
    for _ in range(100):
        est.speed = rng.uniform(40, 160, n)
        est.turn_rate = rng.uniform(0.2, 1.5, n)
        est.straight_curvature = rng.normal(0, 1e-4, n)
        steps = [(rng.random(n) < 0.5, float(rng.uniform(0, 2))) for _ in range(int(rng.integers(0, 4)))]
        frozen = rng.random(n) < 0.3
        p = est.pose.copy()
        for turning, d in steps:
            curvature = np.where(turning, est.turn_rate / est.speed, est.straight_curvature)
            p = np.where(frozen[:, None], p, move(p, est.speed * d, curvature))
        p[:, 2] = np.mod(p[:, 2], 2 * np.pi)
        assert np.array_equal(est.predict(steps, frozen), p)


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 12), st.floats(0.0, 10.0), st.integers(0, 2**31 - 1))
def test_a_look_is_the_weighted_mean_of_the_still_frames_and_the_estimate(m, prior, seed):
    """Frames of robots that did not move: a free robot's pose becomes (prior x estimate + sum of frames) / (prior + m)
    (headings about the estimate); a robot not seen in any frame keeps its estimate. Brute force on the arrays."""
    rng = np.random.default_rng(seed)
    truth = np.array([[100.0, 200.0, 0.02], [900.0, 400.0, 6.27]])
    est = Estimator(_camera(rng, truth), truth, np.full(2, 100.0), np.full(2, 200.0))
    before = est.pose.copy()
    frames = np.stack([_camera(rng, truth, pos_sd=3.0, head_sd=math.radians(2.0)) for _ in range(m)])
    frames[:, 1] = np.nan  # the second robot is never seen
    est.look(frames, np.zeros(2, dtype=bool), prior)
    dth = np.asarray(angle_difference(frames[:, 0, 2], before[0, 2]))
    want_xy = (prior * before[0, :2] + frames[:, 0, :2].sum(axis=0)) / (prior + m)
    want_th = before[0, 2] + dth.sum() / (prior + m)
    assert np.allclose(est.pose[0, :2], want_xy)
    assert abs(float(angle_difference(est.pose[0, 2], want_th))) < 1e-12
    assert np.array_equal(est.pose[1], before[1])


def test_a_look_sharpens_the_estimate_against_the_truth():
    """Twelve still frames at twice the literature's camera noise (4 um, 2 deg) bring a filtered estimate closer to the
    truth: over 200 robots the mean errors fall by more than a third (independent truth: the poses the frames were
    drawn about)."""
    rng = np.random.default_rng(7)
    truth = np.column_stack([rng.uniform(0, 3000, 200), rng.uniform(0, 3000, 200), rng.uniform(0, 2 * math.pi, 200)])
    est = Estimator(_camera(rng, truth, 4.0, math.radians(2.0)), truth, np.full(200, 100.0), np.full(200, 200.0))
    for _ in range(6):  # the fixed-gain filter's steady state, robots still
        est.update([(np.zeros(200, dtype=bool), 0.0)], np.zeros(200, dtype=bool), _camera(rng, truth, 4.0, math.radians(2.0)))
    err0 = np.hypot(*(est.pose[:, :2] - truth[:, :2]).T).mean(), np.abs(angle_difference(est.pose[:, 2], truth[:, 2])).mean()
    frames = np.stack([_camera(rng, truth, 4.0, math.radians(2.0)) for _ in range(12)])
    est.look(frames, np.zeros(200, dtype=bool), 3.0)
    err1 = np.hypot(*(est.pose[:, :2] - truth[:, :2]).T).mean(), np.abs(angle_difference(est.pose[:, 2], truth[:, 2])).mean()
    assert err1[0] < 0.67 * err0[0] and err1[1] < 0.67 * err0[1], (err0, err1)


def test_a_held_robot_adds_the_looks_frames_to_the_mean_since_it_stopped():
    """A docked robot is at the mean of all its frames since it stopped, the look's frames counted one by one."""
    rng = np.random.default_rng(3)
    truth = np.array([[500.0, 500.0, 1.0]])
    frozen = np.array([True])
    est = Estimator(_camera(rng, truth), truth, np.array([100.0]), np.array([200.0]))
    seen = []
    for _ in range(3):
        f = _camera(rng, truth)
        seen.append(f[0])
        est.update([(np.array([False]), 0.5)], frozen, f)
    frames = np.stack([_camera(rng, truth) for _ in range(5)])
    seen.extend(frames[:, 0])
    est.look(frames, frozen, 3.0)
    assert np.allclose(est.pose[0], np.mean(seen, axis=0))
