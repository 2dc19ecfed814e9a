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
