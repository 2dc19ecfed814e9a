"""Prefixed shortest paths (stressbots.control.prefixed) and gross motion's use of them.

Independent truth: the end pose of a path by exact kinematics (:func:`stressbots.kinematics.follow` through
``Path.end``), brute-force enumeration of the same grid for the ordering, and a loop with exact kinematics
(tests/test_control_gross.py's ``KinematicLoop``) for the gross motion.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots import paths as pathlib
from stressbots import planning
from stressbots.collision import penetration_depth
from stressbots.control.gross import GrossMotion, SteerOutcome, arrived
from stressbots.control.prefixed import prefixed_paths, remaining_prefix
from stressbots.kinematics import move
from stressbots.robots import Pose

from .test_control_gross import ARENA, BesideTheStructure, L, W

coord = st.floats(0.0, 3000.0)
heading = st.floats(0.0, 2.0 * math.pi, exclude_max=True)


@settings(max_examples=30, deadline=None)
@given(coord, coord, heading, coord, coord, heading, st.floats(80.0, 400.0))
def test_every_prefixed_path_ends_at_the_target_comes_once_and_shortest_first(x0, y0, t0, x1, y1, t1, r):
    start, target = (x0, y0, t0), np.array([x1, y1, t1])
    paths = list(prefixed_paths(start, target, r, limit=25))
    assert paths and paths[0].length == pytest.approx(pathlib.shortest_path(start, target, r).length, abs=1e-6)
    for p in paths:
        end = np.array(p.end)
        assert np.hypot(*(end[:2] - target[:2])) < 1e-6
        assert abs(math.remainder(end[2] - t1, 2.0 * math.pi)) < 1e-9
        assert p.start == pathlib.Path(Pose(*start), r).start  # from the robot's pose
    lengths = np.array([p.length for p in paths])
    assert (np.diff(lengths) >= -1e-6).all()  # shortest first (to rounding)
    keys = [tuple((k, round(v)) for k, v in p.segments) for p in paths]
    assert len(set(keys)) == len(keys)


def test_prefixed_lengths_match_a_brute_force_over_the_grid():
    """The shortest distinct lengths equal those of every (turn, straight) grid point composed by hand."""
    start, target, r = np.array([500.0, 500.0, 1.0]), np.array([1500.0, 900.0, 4.0]), 150.0
    brute = set()
    for phi in np.radians(np.arange(0.0, 360.0, 15.0)):
        for s in np.arange(0.0, 1500.0 + 1e-9, 50.0):
            mid = move(move(start, np.array([r * phi]), 1.0 / r)[-1], np.array([s]), 0.0)[-1]
            brute.add(round(r * phi + s + pathlib.shortest_path(mid, target, r).length, 3))
    got = [round(p.length, 3) for p in prefixed_paths(start, target, r, limit=10)]
    assert got[0] == min(brute) and set(got) <= brute


@settings(max_examples=30, deadline=None)
@given(st.floats(0.0, 300.0), st.floats(0.0, 600.0), st.floats(0.0, 1.0))
def test_the_rest_of_a_prefix_is_what_is_left_of_it_along_the_path(turn, straight, frac):
    """The prefix is the path's first clockwise arc and the straight after it (segments as normalised: a prefix that
    runs into the shortest path's own first turn is one arc with it; the path is the same)."""
    path = pathlib.Path(Pose(1000.0, 1000.0, 0.3), 120.0, (("R", turn), ("S", straight), ("R", 200.0), ("S", 300.0)))
    segs = list(path.segments)
    t = segs.pop(0)[1] if segs[0][0] == "R" else 0.0
    s = segs[0][1] if segs and segs[0][0] == "S" else 0.0
    done = frac * (t + s)
    rest = remaining_prefix(path, path.pose_at(done))
    if t + s - done < 10.0:  # within a sample of the prefix's end: either answer
        return
    assert rest is not None
    assert rest[0] + rest[1] == pytest.approx(t + s - done, abs=10.0)  # samples 10 um apart
    assert 0.0 <= rest[0] <= t + 1e-9 and 0.0 <= rest[1] <= s + 1e-9
    off = np.array(path.pose_at(done)) + np.array([0.0, 0.0, 0.0])
    off[:2] += 200.0 * np.array([math.cos(off[2]), -math.sin(off[2])])  # 200 um to the right of the path there
    if np.hypot(*(path.sample(10.0)[:, :2] - off[:2]).T).min() > 30.0:
        assert remaining_prefix(path, off) is None


def test_a_robot_whose_shortest_path_turns_into_the_structure_drives_on_first_and_arrives(monkeypatch):
    """Beside a docked body whose side it runs along, the shortest path's first clockwise turn sweeps into it; the
    prefixed detour drives past it first, with no roadmap search, and arrives without touching it."""
    def no_roadmap(*a, **k):
        raise AssertionError("the roadmap was asked")

    monkeypatch.setattr(planning, "route", no_roadmap)
    start = np.array([1000.0, 600.0, 0.0])  # heading +y
    body = np.array([1000.0 + W + 40.0, 900.0, 0.0])  # parallel, on its right (clockwise) side, 40 um gap
    target = np.array([1500.0, 700.0, math.pi])  # behind and to the right: its shortest path turns right at once
    loop = BesideTheStructure(start, body)
    loop.tune = replace(loop.tune, prefixed_checks_max=200)  # off by default
    shortest = pathlib.shortest_path(start, target, float(loop.r_hat[0]))
    assert (penetration_depth(shortest.sample(10.0), L, W, body[None], L, W) > 0.0).any()  # the premise
    assert GrossMotion(loop).steer(0, target, 1, 0, []) is SteerOutcome.ARRIVED
    assert arrived(loop.est[0], target, loop.tune)
    trail = np.array(loop.trail)
    assert (penetration_depth(trail, L, W, body[None], L, W) < 0.0).all()
    assert any(kind == "detour" and "first" in detail for kind, detail in loop.events)
    assert ARENA  # the loop's arena (the detour stays inside it: arena_gap is part of the obstacle check)
