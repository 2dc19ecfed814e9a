"""Overlapped G_1 schedules and pre-positioning (issue 15: shorter plans).

Truth is independent of the code under test: words and paths are integrated segment by segment with the
closed forms of :func:`stressbots.kinematics.move`; primitive steps are played with
:func:`stressbots.kinematics.advance` under SPEC 4's rule (under P_k, D_1..D_k turn); plans are checked by
the independent replay, and their durations against the planner with the overlap turned off.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots import paths
from stressbots.errors import PlanningError
from stressbots.generate import random_scenario
from stressbots.kinematics import advance, move
from stressbots.overlap import backward_words, joint_primitives, overlap_schedule, with_orbits
from stressbots.planning import PlannerOptions, plan_assembly
from stressbots.prepositioning import docking_costs, follower_ends, splice_straight
from stressbots.replay import replay
from stressbots.robots import Pose


def _integrate(start, segments, radius) -> np.ndarray:
    pose = np.asarray(start, float)
    for kind, ell in segments:
        pose = move(pose, ell, 1.0 / radius if kind == "R" else 0.0)
    return pose


def _same_pose(a, b, tol=1e-6) -> bool:
    return bool(np.allclose(a[:2], b[:2], atol=tol) and abs((a[2] - b[2] + math.pi) % (2 * math.pi) - math.pi) < 1e-8)


def _play(steps, poses, rank, speed, radius) -> np.ndarray:
    """SPEC 4: under P_k the robots of rank <= k turn, the others drive straight."""
    for k, d in steps:
        poses = advance(poses, rank <= k, speed, radius, d)
    return poses


@settings(max_examples=40, deadline=None)
@given(x=st.floats(-2000, 2000), y=st.floats(-2000, 2000), th=st.floats(0, 6.28), ell=st.floats(1.0, 3000.0),
       r=st.floats(100.0, 300.0), steps=st.integers(1, 7))
def test_backward_words_reach_the_end_with_exactly_the_length(x, y, th, ell, r, steps):
    end = np.array([x, y, th])
    starts, words = backward_words(end, ell, r, steps)
    assert len(starts) == len(words) > 0
    for p, word in zip(starts, words, strict=True):
        assert math.isclose(sum(w[1] for w in word), ell, rel_tol=1e-9, abs_tol=1e-6)
        assert all(w[1] >= 0 for w in word) and all(w[1] < 2 * math.pi * r for w in word if w[0] == "R")
        assert _same_pose(_integrate(p, word, r), end, tol=1e-6 * max(1.0, ell))


_SEGS = st.lists(st.tuples(st.sampled_from("RS"), st.floats(1.0, 800.0)), min_size=1, max_size=6)


@settings(max_examples=40, deadline=None)
@given(m_segs=_SEGS, split=st.lists(st.floats(0.0, 1.0), min_size=6, max_size=6), vn=st.floats(60, 150), vm=st.floats(60, 150),
       n=st.integers(2, 5))
def test_joint_primitives_drive_both_robots_along_their_paths(m_segs, split, vn, vm, n):
    # D_n may turn only where D_(n-1) turns: in each of D_(n-1)'s arcs it turns for a part, then goes straight.
    n_segs = []
    for (kind, ell), f in zip(m_segs, split, strict=False):
        t = ell / vm
        n_segs += [("R", f * t * vn), ("S", (1 - f) * t * vn)] if kind == "R" else [("S", t * vn)]
    rn, rm = 180.0, 220.0
    pn = paths.Path(Pose(0.0, 0.0, 0.3), rn, tuple(n_segs))
    pm = paths.Path(Pose(900.0, 100.0, 2.0), rm, tuple(m_segs))
    steps = joint_primitives(pn, vn, pm, vm, n)
    assert {k for k, _ in steps} <= {n, n - 1, n - 2}
    assert math.isclose(sum(d for _, d in steps), pm.length / vm, rel_tol=1e-9)
    rank = np.array([n, n - 1])
    end = _play(steps, np.array([list(pn.start), list(pm.start)]), rank, np.array([vn, vm]), np.array([rn, rm]))
    assert _same_pose(end[0], np.array(pn.end), tol=1e-6) and _same_pose(end[1], np.array(pm.end), tol=1e-6)


def test_joint_primitives_refuse_d_n_turning_while_its_partner_drives_straight():
    pn = paths.Path(Pose(0.0, 0.0, 0.0), 200.0, (("R", 100.0),))
    pm = paths.Path(Pose(0.0, 900.0, 0.0), 200.0, (("S", 100.0),))
    with pytest.raises(ValueError, match="turns while"):
        joint_primitives(pn, 100.0, pm, 100.0, 3)


@settings(max_examples=30, deadline=None)
@given(durs=st.lists(st.floats(0.1, 5.0), min_size=1, max_size=5), k=st.integers(2, 6), pick=st.integers(0, 4),
       a=st.floats(0.0, 1.0), b=st.floats(0.0, 1.0))
def test_splice_straight_leaves_the_docking_robot_alone_and_moves_the_next_one_straight(durs, k, pick, a, b):
    steps = [(k if j % 2 else k - 1, d) for j, d in enumerate(durs)]
    j = min(pick - pick % 2, len(durs) - 1 - (len(durs) - 1) % 2)  # a P_(k-1) step
    t_start = sum(d for _, d in steps[:j])
    t0 = t_start + a * steps[j][1]
    dt = (t_start + steps[j][1] - t0) * b
    out = splice_straight(steps, k, t0, dt)
    assert math.isclose(sum(d for _, d in out), sum(durs), rel_tol=1e-12)
    assert math.isclose(sum(d for kk, d in out if kk == k - 2), dt, abs_tol=1e-9)
    # D_k (rank k) moves exactly as before; D_(k-1) ends where the closed form says
    rank = np.array([k, k - 1])
    v, r = np.array([100.0, 120.0]), np.array([200.0, 170.0])
    p0 = np.array([[0.0, 0.0, 0.0], [800.0, 300.0, 1.0]])
    before, after = _play(steps, p0, rank, v, r), _play(out, p0, rank, v, r)
    assert np.allclose(after[0], before[0], atol=1e-9)
    want = follower_ends(p0[1], v[1], r[1], sum(durs), np.array([t0]), np.array([dt]))[0]
    assert _same_pose(after[1], want, tol=1e-6)


def test_docking_costs_match_a_brute_force_over_the_departure_phases():
    pose = np.array([[500.0, 400.0, 0.7]])
    target = np.array([1500.0, 1200.0, 2.0])
    cost, wait = docking_costs(pose, target, 100.0, 200.0, 12)
    period = 2 * math.pi * 200.0 / 100.0
    brute = min(w + paths.shortest_path(advance(pose, [True], 100.0, 200.0, w)[0], target, 200.0).length / 100.0
                for w in np.arange(12) * period / 12)
    assert math.isclose(float(cost[0]), brute, rel_tol=1e-9)
    assert 0.0 <= float(wait[0]) < period


@settings(max_examples=25, deadline=None)
@given(b=st.floats(50.0, 2000.0), count=st.integers(1, 3), offset=st.floats(-0.2, 0.2))
def test_inserted_orbits_end_the_route_where_it_ended(b, count, offset):
    r = 180.0
    route = paths.Path(Pose(100.0, 200.0, 0.4), r, (("R", 90.0), ("S", b), ("R", 300.0)))
    new, at = with_orbits(route, count, offset)
    if not at:
        return  # the shifted cuts fell off the straight
    assert len(at) == count
    assert math.isclose(new.length, route.length + count * 2 * math.pi * r, rel_tol=1e-12)
    assert _same_pose(_integrate(new.start, new.segments, r), np.array(route.end), tol=1e-6)
    for s in at:  # each orbit starts and ends on the original straight, at the same pose
        assert _same_pose(new.pose_at(s), new.pose_at(s + 2 * math.pi * r), tol=1e-6)


def test_an_overlapped_schedule_without_obstacles_ends_both_robots_in_their_slots():
    vn, rn, vm, rm = 110.0, 190.0, 90.0, 210.0
    start_n, start_m = np.array([300.0, 300.0, 0.5]), np.array([2500.0, 400.0, 4.0])
    goal_n = np.array([1400.0, 1500.0, math.pi / 2])
    goal_m = np.array([1400.0 + 260.0, 1500.0, 3 * math.pi / 2])
    approach = paths.Path(Pose(goal_m[0] + 160.0, goal_m[1], goal_m[2]), rm, (("S", 160.0),))
    route = paths.shortest_path(start_m, np.array(approach.start), rm)
    sched = overlap_schedule(start_n, start_m, goal_n, route, approach, 0.0, 2 * math.pi * rm / vm, vn, rn, vm, rm,
                             lambda _p: True, lambda _a, _b: True, lambda q: np.ones(len(q), bool))
    assert sched is not None
    assert _same_pose(_integrate(start_n, sched.path_n.segments, rn), goal_n, tol=1e-5)
    assert _same_pose(_integrate(start_m, sched.path_m.segments, rm), goal_m, tol=1e-5)
    assert math.isclose(sched.path_n.length / vn, sched.duration_s, rel_tol=1e-9)
    assert math.isclose(sched.path_m.length / vm, sched.duration_s, rel_tol=1e-9)
    joint_primitives(sched.path_n, vn, sched.path_m, vm, 2)  # D_n never turns while D_(n-1) drives straight
    # the seed's scheme needs D_n's straight run as long as D_(n-1)'s whole route; here only its last stretch
    assert sched.pieces[-1][1] - sched.pieces[-1][0] < (route.length + approach.length) / vm


@settings(max_examples=5, deadline=None)
@given(seed=st.integers(0, 10_000))
def test_overlapped_pair_plans_replay(seed):
    scn = random_scenario(2, seed, shape="pair", explicit_goals=bool(seed % 2))
    try:
        res = plan_assembly(scn)
    except PlanningError as exc:  # a refusal still says what blocks and what to change
        assert "\n" not in exc.message
        return
    assert replay(res.plan, scn, max_step_um=2.0).ok


@pytest.mark.parametrize("seed", [500, 501, 502, 503])
def test_overlapped_g1_is_shorter_than_the_piece_scheme(seed):
    """Not a theorem (the schedules differ, and a shape's first variant is kept), but on these pairs the
    overlapped G_1 is far shorter: D_n no longer needs a straight corridor as long as its partner's route."""
    scn = random_scenario(2, seed, shape="pair", explicit_goals=bool(seed % 2), heterogeneous=seed != 503)
    old = plan_assembly(scn, PlannerOptions(overlap_pair=False, preposition=False))
    new = plan_assembly(scn)
    assert replay(new.plan, scn, max_step_um=2.0).ok
    assert new.plan.duration_s < 0.8 * old.plan.duration_s
    assert any("G_1 overlapped" in note for note in new.notes)


def test_pre_positioning_shortens_the_next_docking_and_replays():
    # bench_planner's tee-4: D1 drives straight beside D2's long straight (P0 instead of P1)
    scn = random_scenario(4, 1068, shape="tee", explicit_goals=False, heterogeneous=True)
    off = plan_assembly(scn, PlannerOptions(preposition=False))
    on = plan_assembly(scn)
    assert replay(on.plan, scn, max_step_um=1.0).ok
    assert any("drove" in note and "straight while" in note for note in on.notes)

    def docking(res, rank: int) -> float:
        i = int(res.analysis.order_index[rank - 1])
        return sum(ph.duration_s for ph in res.phases if ph.mover == i and ph.kind in ("wait", "route", "approach"))

    assert docking(on, 1) < docking(off, 1) - 1.0  # D1's own docking, after D2 docked
    assert math.isclose(docking(on, 2), docking(off, 2), rel_tol=1e-9)  # D2 moves exactly as before
    assert on.plan.duration_s < off.plan.duration_s
