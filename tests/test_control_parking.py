"""Waiting orbits that drifted into trouble (stressbots.control.parking): pure queries on hand-built
snapshots, checked by replaying the manoeuvre with the kinematics (independent of the query's own
geometry). The straight-drift identification's tests are in test_straight_drift.py."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.control.parking import orbit_gaps, park_move
from stressbots.robots import orbit_radii, turning_centres

from .plants import replay_orbit_move

ARENA = (3000.0, 3000.0)
L, W, R, V = 250.0, 60.0, 230.0, 85.0
RSTAR = float(orbit_radii(L, W, R))


def wall_gap(centre) -> float:
    """Independent: gap (um) of an orbit disc about ``centre`` to the nearest arena wall."""
    return float(min(centre[0], ARENA[0] - centre[0], centre[1], ARENA[1] - centre[1])) - RSTAR


def replay(poses, move, still):
    """The move replayed independently at this module's speed and radius (:func:`tests.plants.replay_orbit_move`)."""
    return replay_orbit_move(poses, move, still, V, R)


@settings(max_examples=15, deadline=None)
@given(st.floats(0.0, 2 * math.pi), st.floats(2.0, 30.0), st.floats(0.0, 2 * math.pi))
def test_a_robot_drifted_next_to_the_wall_moves_away_and_nobody_hits_anything(theta, gap, theta_k):
    # D_j orbits ``gap`` um from the left wall; D_k (the next to dock) orbits in the middle; D_1 below D_j
    cj = np.array([RSTAR + gap, 1500.0])
    poses = np.array([
        [cj[0] - R * math.cos(theta), cj[1] + R * math.sin(theta), theta],   # D_j
        [1500.0 - R * math.cos(theta_k), 1500.0 + R * math.sin(theta_k), theta_k],  # D_k
        [1500.0 - R, 600.0, 0.0],  # a lower robot, orbiting throughout
    ])
    n = 3
    args: tuple = (np.full(n, R), np.full(n, V / R), np.full(n, V), np.full(n, RSTAR), ARENA, np.zeros((0, 3)), [], [])
    before = orbit_gaps(turning_centres(poses, R), np.full(n, RSTAR), ARENA, np.zeros((0, 3)), [], [])
    assert abs(before[0] - gap) < 1e-6
    move = park_move(0, [0, 1], [2], poses, *args, shift_um=150.0, clearance_um=25.0)
    assert move is not None
    path = replay(poses, move, [2])
    end = turning_centres(path[-1], R)
    assert wall_gap(end[0]) >= gap + 75.0 - 1e-6  # D_j's orbit moved at least half the shift away from the wall
    # nobody's orbit disc came closer to a wall or to another than it started (or 25 um)
    for t in range(len(path)):
        c = turning_centres(path[t], R)
        for a in range(n):
            assert wall_gap(c[a]) >= min(25.0, wall_gap(turning_centres(poses, R)[a])) - 1.0
            for b in range(a + 1, n):
                assert np.hypot(*(c[a] - c[b])) - 2 * RSTAR >= 25.0 - 1.0


def test_no_move_when_every_way_out_is_blocked():
    """D_j in a corner with the only mover's track walled in by orbits: no manoeuvre is offered."""
    cj = np.array([RSTAR + 5.0, RSTAR + 5.0])
    theta = 1.0
    poses = np.array([[cj[0] - R * math.cos(theta), cj[1] + R * math.sin(theta), theta]])
    blockers = np.array([[cj[0] + 2 * RSTAR + 10.0, cj[1]], [cj[0], cj[1] + 2 * RSTAR + 10.0], [cj[0] + 1.6 * RSTAR, cj[1] + 1.6 * RSTAR]])
    bposes = np.array([[c[0] - R, c[1], 0.0] for c in blockers])
    allp = np.vstack([poses, bposes])
    n = 4
    move = park_move(0, [0], [1, 2, 3], allp, np.full(n, R), np.full(n, V / R), np.full(n, V), np.full(n, RSTAR), ARENA,
                     np.zeros((0, 3)), [], [], shift_um=150.0, clearance_um=25.0)
    assert move is None


# -- the runner's parking policy: how often one orbit is moved in one phase -----------------------------------


def _runner_with_orbit_near_the_wall():
    """A 4-robot run whose only waiting robot (D_1, during D_2's phase) orbits 10 um from the left wall."""
    from stressbots.control import structure_targets
    from stressbots.control.runner import _Runner
    from stressbots.control.tuning import ControllerOptions
    from stressbots.generate import random_scenario
    from stressbots.sim import SimulatedPlant

    scn = random_scenario(4, 3, shape="tee")
    run = _Runner(scn, SimulatedPlant(scn, seed=0), structure_targets(scn), ControllerOptions(), 0)
    i = run.by_rank[1]
    r, rstar = float(run.r_hat[i]), float(run.rstar[i])
    assert scn.arena_um is not None
    h = scn.arena_um[1] / 2.0
    # heading 0 (+y): the turning centre lies r to the right (+x) of the robot
    run.estimator.pose[i] = (rstar + 10.0 - r, h, 0.0)
    return run, i


def _scripted_drive(run, i, held: bool, record_waits: bool = False):
    """``run.drive`` replaced by noiseless kinematics on D_1's and D_2's estimates: under P_p the robots of rank <= p
    orbit and the others drive straight (P_2: the wait; P_0: the straight); robot ``i`` does not move if ``held``.
    Returns the durations of the straights driven (and of the waits, with ``record_waits``)."""
    from stressbots.kinematics import move

    straights = []

    def drive(steps):
        for prim, dur in steps:
            run.t += dur
            for m in range(run.n):
                if run.rank[m] > 2 or (held and m == i):
                    continue  # the pair is not simulated here
                curv = 1.0 / float(run.r_hat[m]) if run.rank[m] <= prim else 0.0
                run.estimator.pose[m] = move(run.estimator.pose[m], np.array([float(run.v_hat[m]) * dur]), curv)[-1]
            if prim < 2 or record_waits:
                straights.append(dur)

    run.drive = drive
    return straights


def _moves(run) -> list:
    """The park moves the run has made (its log)."""
    return [e for e in run.events if e["kind"] == "park" and "it moves" in e["detail"]]


def test_an_orbit_that_drifts_back_into_trouble_is_moved_again_in_the_same_phase():
    run, i = _runner_with_orbit_near_the_wall()
    start = run.estimator.pose.copy()
    _scripted_drive(run, i, held=False)
    run.park_orbits(2)
    assert len(_moves(run)) == 1 and wall_gap_of(run, i) > run.tune.park_margin_um
    run.park_orbits(2)
    assert len(_moves(run)) == 1  # clear now: no move
    for m in range(1, run.tune.park_moves_per_phase + 1):
        run.estimator.pose[:] = start  # drifted back
        run.park_orbits(2)
        assert len(_moves(run)) == min(m + 1, run.tune.park_moves_per_phase)  # moved again, at most this many per phase
    run.estimator.pose[:] = start
    run.park_orbits(3, top=1)
    assert len(_moves(run)) == run.tune.park_moves_per_phase + 1  # a new phase may move it again


def test_an_orbit_move_that_did_not_widen_the_gap_is_not_repeated_in_its_phase():
    run, i = _runner_with_orbit_near_the_wall()
    calls = _scripted_drive(run, i, held=True, record_waits=True)  # held: neither the wait nor the straight moves it
    run.park_orbits(2)
    assert len(calls) >= 1
    run.park_orbits(2)
    run.park_orbits(2)
    assert len(calls) <= 2  # one move (a wait, at most one straight), not repeated


def test_a_park_refused_after_its_wait_is_tried_again_once_its_orbit_drifted_closer():
    """A park whose straight is not clear after its wait (here the robot is held: its heading after the wait is the
    one it had) is not tried again at the same gap, but is once the orbit drifted ``park_retry_drift_um`` closer."""
    run, i = _runner_with_orbit_near_the_wall()
    run.tune = replace(run.tune, park_retry_drift_um=20.0)  # off (inf) by default
    calls = _scripted_drive(run, i, held=True, record_waits=True)
    run.park_orbits(2)
    refused = [e for e in run.events if e["kind"] == "park" and "after the wait its straight is not clear" in e["detail"]]
    waits = 1 + run.tune.park_replans_after_wait  # the wait, and one per re-plan from where it stopped
    assert len(refused) == 1 and len(calls) == waits  # waits, no straight
    run.park_orbits(2)
    assert len(calls) == waits  # same poses: not again
    run.estimator.pose[i, 0] -= 0.5 * run.tune.park_retry_drift_um
    run.park_orbits(2)
    assert len(calls) == waits  # drifted, but less than park_retry_drift_um
    run.estimator.pose[i, 0] -= run.tune.park_retry_drift_um
    run.park_orbits(2)
    assert len(calls) == 2 * waits  # drifted on: new waits


def test_by_default_a_park_refused_after_its_wait_is_not_tried_again_in_its_phase():
    run, i = _runner_with_orbit_near_the_wall()
    calls = _scripted_drive(run, i, held=True, record_waits=True)
    run.park_orbits(2)
    run.estimator.pose[i, 0] -= 100.0  # however far it drifts
    run.park_orbits(2)
    assert len(calls) == 1 + run.tune.park_replans_after_wait


@pytest.mark.parametrize("replans", [0, 1, 2])
def test_a_park_whose_straight_is_not_clear_after_its_wait_is_planned_again_from_there(replans):
    """Held through its wait (its heading after the wait is the one it had), the robot's straight is not clear; each
    re-plan from there is another wait, up to ``park_replans_after_wait``; then it is refused."""
    run, i = _runner_with_orbit_near_the_wall()
    run.tune = replace(run.tune, park_replans_after_wait=replans)
    calls = _scripted_drive(run, i, held=True, record_waits=True)
    run.park_orbits(2)
    again = [e for e in run.events if e["kind"] == "park" and "planned again from here" in e["detail"]]
    assert len(calls) == 1 + replans and len(again) == replans
    assert not _moves(run)


def test_a_park_released_after_its_first_wait_moves_on_its_re_planned_wait():
    """Held through its first wait only (then it turns freely): the re-planned wait turns it to a clear straight, and
    the orbit moves away from the wall (measured on the estimates the scripted kinematics drove)."""
    run, i = _runner_with_orbit_near_the_wall()
    gap0 = wall_gap_of(run, i)
    first = [True]
    calls = _scripted_drive(run, i, held=False, record_waits=True)
    drive = run.drive

    def held_once(steps):
        if first[0]:  # the first wait: robot i stays where it is (the others orbit)
            first[0] = False
            pose = run.estimator.pose[i].copy()
            drive(steps)
            run.estimator.pose[i] = pose
            return
        drive(steps)

    run.drive = held_once
    run.park_orbits(2)
    assert len(_moves(run)) == 1 and len(calls) >= 3  # two waits, then the straight
    assert wall_gap_of(run, i) >= gap0 + 0.5 * run.tune.park_shift_um - 1.0


def wall_gap_of(run, i: int) -> float:
    """Independent: the wall gap of robot ``i``'s orbit disc from its estimate (turning centre r to the right)."""
    p = run.estimator.pose[i]
    centre = (p[0] + run.r_hat[i] * math.cos(p[2]), p[1] - run.r_hat[i] * math.sin(p[2]))
    assert run.scn.arena_um is not None
    w, h = run.scn.arena_um
    return float(min(centre[0], w - centre[0], centre[1], h - centre[1])) - float(run.rstar[i])


def test_a_waiting_orbit_under_d_n_minus_1s_orbit_is_moved_off_it_when_that_orbit_counts():
    """After a station-transfer leg D_(n-1)'s orbit disc counts as trouble (``among``): a waiting orbit it overlaps
    is moved off it (measured gap to that disc grows); without ``among`` nothing moves."""
    run, i = _runner_with_orbit_near_the_wall()
    m = run.by_rank[3]
    assert run.scn.arena_um is not None
    w, h = run.scn.arena_um
    run.estimator.pose[i] = (0.5 * w - float(run.r_hat[i]), 0.5 * h, 0.0)  # turning centre at the arena's middle
    run.estimator.pose[m] = (0.5 * w - float(run.r_hat[m]) + 150.0, 0.5 * h, 0.0)  # its centre 150 um to the right
    _scripted_drive(run, i, held=False)
    run.park_orbits(4, top=2)
    assert _moves(run) == []
    before = disc_gap(run, i, m)
    run.park_orbits(4, top=2, among=[m])
    assert len(_moves(run)) == 1 and disc_gap(run, i, m) > before + run.tune.park_progress_um


def disc_gap(run, a: int, b: int) -> float:
    """Independent: gap (um) between the orbit discs of robots ``a`` and ``b`` (turning centres r to the right)."""
    cs = []
    for j in (a, b):
        p = run.estimator.pose[j]
        cs.append((p[0] + run.r_hat[j] * math.cos(p[2]), p[1] - run.r_hat[j] * math.sin(p[2])))
    return float(math.hypot(cs[0][0] - cs[1][0], cs[0][1] - cs[1][1]) - run.rstar[a] - run.rstar[b])


def test_a_group_straight_is_driven_a_t_x_at_a_time_and_stops_before_an_orbit_meets_the_arena_edge():
    """The straight of a group move heading for the arena edge (a heading the plan did not expect) stops while the
    orbit is still ``park_clearance_um`` clear of the edge, replayed by noiseless kinematics; a clear one runs whole."""
    run, i = _runner_with_orbit_near_the_wall()
    _scripted_drive(run, i, held=False)
    run.estimator.pose[i, 2] = 1.5 * math.pi  # heading -x: straight at the left edge
    run.estimator.pose[i, 0] += 300.0  # its disc 310 um from that edge
    before = run.estimator.pose[i].copy()
    run._drive_group_straight(i, 2, 20.0)  # 20 s would run it far into the edge
    gap = wall_gap_of(run, i)
    assert run.tune.park_clearance_um <= gap < 310.0
    assert any("stops" in e["detail"] for e in run.events)
    run.estimator.pose[i] = before
    run.estimator.pose[i, 2] = 0.5 * math.pi  # heading +x: away from it
    run._drive_group_straight(i, 2, 2.0)
    assert math.isclose(run.estimator.pose[i, 0] - before[0], 2.0 * float(run.v_hat[i]), rel_tol=1e-6)


def test_tending_during_g1_moves_a_waiting_orbit_near_the_wall_and_counts_the_move():
    """G_1's timed arrivals tend the waiting orbits (rendezvous.Tending): an orbit 10 um from the wall is moved past the
    park margin, once; nothing is moved when none is near trouble."""
    run, i = _runner_with_orbit_near_the_wall()
    _scripted_drive(run, i, held=False)
    meeting = run.pair.meeting
    assert meeting._tended(run.n) and meeting.tend_moves == 1
    assert wall_gap_of(run, i) > run.tune.park_margin_um
    assert not meeting._tended(run.n) and meeting.tend_moves == 1


def test_a_timed_arrival_that_stops_on_tending_returns_as_soon_as_an_orbit_moved():
    """Tending.STOP: the timed run to a clear track was planned from poses a park move changed, so it returns False
    before D_n drives anything; the move is counted (the transfer leg then plans again rather than count a failure)."""
    from stressbots.control.rendezvous import Tending

    run, _ = _runner_with_orbit_near_the_wall()
    n = run.n
    N, M = run.by_rank[n], run.by_rank[n - 1]
    calls: list[tuple] = []
    driven: list = []

    def park(k, top=None, margin_um=None, among=()):
        calls.append((k, top, tuple(among)))
        run.t += 1.0  # a park move takes time

    run.park_orbits = park
    run.drive = driven.append
    assert run.pair.meeting.arrive_timed(N, M, lambda: run.est[N].copy(), 0.0, [], tend=Tending.STOP) is False
    assert run.pair.meeting.tend_moves == 1 and calls == [(n, n - 2, (M,))] and driven == []


@settings(max_examples=12, deadline=None)
@given(st.floats(110.0, 320.0), st.floats(-0.6, 0.6))
def test_a_park_move_leaves_no_other_mover_within_keep_of_trouble(gap_k, turn_k):
    """D_j 10 um from the left wall; the other mover D_k, heading down about when D_j heads away from the wall, orbits
    ``gap_k`` um above the bottom wall. With ``keep_um`` the move (replayed independently) leaves D_k at least
    min(its gap, keep_um) from every wall and disc, or there is none; without it a move may leave D_k closer."""
    keep = 100.0
    poses = np.array([
        [RSTAR + 10.0 - R, 1500.0, 0.0],   # D_j: heading +y, turning centre r to its right
        [1500.0 - R * math.cos(math.pi / 2 + turn_k), RSTAR + gap_k + R * math.sin(math.pi / 2 + turn_k), math.pi / 2 + turn_k],
    ])
    n = 2
    args: tuple = (np.full(n, R), np.full(n, V / R), np.full(n, V), np.full(n, RSTAR), ARENA, np.zeros((0, 3)), [], [])
    gaps0 = orbit_gaps(turning_centres(poses, R), np.full(n, RSTAR), ARENA, np.zeros((0, 3)), [], [])
    move = park_move(0, [0, 1], [], poses, *args, shift_um=150.0, clearance_um=25.0, keep_um=keep)
    if move is not None:
        end = turning_centres(replay(poses, move, [])[-1], R)
        assert wall_gap(end[0]) >= 10.0 + 75.0 - 1.0
        assert min(wall_gap(end[1]), float(np.hypot(*(end[0] - end[1]))) - 2 * RSTAR) >= min(gaps0[1], keep) - 1.0


def test_without_keep_the_cheapest_park_move_pushes_the_other_mover_near_the_wall():
    """The case the keep rule is for (the same layout, D_k 160 um above the bottom wall): the cheapest move leaves it
    45 um from the wall (it would need parking next); with ``keep_um`` 100 no move is offered."""
    poses = np.array([[RSTAR + 10.0 - R, 1500.0, 0.0], [1500.0 - R * math.cos(math.pi / 2), RSTAR + 160.0 + R, math.pi / 2]])
    args: tuple = (np.full(2, R), np.full(2, V / R), np.full(2, V), np.full(2, RSTAR), ARENA, np.zeros((0, 3)), [], [])
    move = park_move(0, [0, 1], [], poses, *args, shift_um=150.0, clearance_um=25.0)
    assert move is not None
    assert wall_gap(turning_centres(replay(poses, move, [])[-1], R)[1]) < 100.0
    assert park_move(0, [0, 1], [], poses, *args, shift_um=150.0, clearance_um=25.0, keep_um=100.0) is None


@pytest.mark.parametrize("short", [(100.0, 60.0), ()])
def test_a_shorter_park_move_is_taken_when_no_full_one_is_clear(short):
    """D_1 10 um from the left wall; D_2 (the robot of the phase, a mover too) orbits 110 um from the right wall with the
    same heading, so every full 150 um shift ends D_2's orbit within ``park_margin_um`` of the right wall; a shorter one
    (``park_short_shifts_um``) does not. Without shorter shifts there is no move."""
    run, i = _runner_with_orbit_near_the_wall()
    run.tune = replace(run.tune, park_short_shifts_um=short)
    k = run.by_rank[2]
    for a in (run.r_hat, run.v_hat, run.omega_hat, run.rstar):  # D_2 turns as D_1 does: same heading throughout
        a[k] = a[i]
    assert run.scn.arena_um is not None
    w, h = run.scn.arena_um
    run.estimator.pose[k] = (w - float(run.rstar[k]) - 110.0 - float(run.r_hat[k]), h / 2.0 + 700.0, 0.0)
    gap0 = wall_gap_of(run, i)
    _scripted_drive(run, i, held=False)
    run.park_orbits(2)
    moves = _moves(run)
    if not short:
        assert not moves
        return
    shift = float(moves[0]["detail"].split("moves ")[1].split(" um")[0]) if len(moves) == 1 else math.nan
    assert shift in short
    assert wall_gap_of(run, i) >= gap0 + 0.5 * shift - 1.0
    assert wall_gap_of(run, k) >= run.tune.park_margin_um - 1.0
