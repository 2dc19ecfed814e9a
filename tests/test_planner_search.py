"""The planner's wider search (issue 15): whole-period paths that orbit first or stretch one leg, the
seed-scheme restriction, comparing structure variants, and failure messages that say what to change.

Truth is independent of the code under test: paths are integrated segment by segment with the closed
forms of :func:`stressbots.kinematics.move`, durations checked against whole numbers of periods, and
plans against the replay verifier.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.electrostatics import analyse_scenario
from stressbots.errors import PlanningError
from stressbots.generate import random_scenario
from stressbots.kinematics import move
from stressbots.planning import Obstacles, PlannerOptions, _Planner, plan_assembly
from stressbots.replay import replay
from stressbots.scenario import load
from stressbots.structures import target_structures

from .conftest import EXAMPLES


def _integrate(start, segments, radius) -> np.ndarray:
    pose = np.asarray(start, float)
    for kind, ell in segments:
        pose = move(pose, ell, 1.0 / radius if kind == "R" else 0.0)
    return pose


def _planner(opts: PlannerOptions | None = None) -> _Planner:
    scn = load(EXAMPLES / "four-robots.toml")
    analysis = analyse_scenario(scn)
    assert analysis.order_index is not None  # the example is a STRING
    st0 = target_structures([scn.robots[i] for i in analysis.order_index], scn.structure)[0]
    return _Planner(scn, analysis, st0, opts or PlannerOptions())


_EMPTY = Obstacles(np.zeros((0, 2)), np.zeros(0), (), np.zeros((0, 3)), np.zeros(0), np.zeros(0), (), None)
_PLANNER = _planner()


@settings(max_examples=25, deadline=None)
@given(
    x=st.floats(-1500, 1500), y=st.floats(-1500, 1500), th0=st.floats(0, 6.28), th1=st.floats(0, 6.28),
    wait0=st.floats(0, 10), period=st.floats(5, 20),
)
def test_orbit_first_path_lasts_whole_periods_and_ends_at_the_goal(x, y, th0, th1, wait0, period):
    p = _PLANNER
    p._orbit_first_on = True
    v, r = 100.0, 200.0
    start, goal = np.array([0.0, 0.0, th0]), np.array([x, y, th1])
    path = p._orbit_first(start, goal, v, r, 260.0, 60.0, wait0, period, _EMPTY)
    assert path is not None  # no obstacles: some phase and some k always fit
    kind, first = path.segments[0]
    assert kind == "R" and 0.0 < first < 2.0 * math.pi * r  # it orbits less than one turn first
    k = (path.length / v - wait0) / period
    assert abs(k - round(k)) < 1e-6 and round(k) >= 0
    end = _integrate(start, path.segments, r)
    assert np.allclose(end[:2], goal[:2], atol=1e-6)
    assert abs((end[2] - goal[2] + math.pi) % (2 * math.pi) - math.pi) < 1e-8


def test_stretch_leg_keeps_the_other_legs_shortest_and_is_exact():
    from stressbots import paths

    p = _PLANNER
    r = 200.0
    nodes = (np.array([0.0, 0.0, 0.0]), np.array([600.0, 900.0, 1.2]), np.array([1500.0, 400.0, 3.0]))
    shortest = sum(paths.shortest_path(a, b, r).length for a, b in zip(nodes[:-1], nodes[1:], strict=False))
    want = shortest + 300.0  # only the second leg can take 300 um more (gaps in the feasible lengths)
    path = p._stretch_leg(nodes, r, want, _EMPTY, 260.0, 60.0)
    assert path is not None
    assert math.isclose(path.length, want, abs_tol=1e-6)
    assert np.allclose(_integrate(nodes[0], path.segments, r)[:2], nodes[-1][:2], atol=1e-6)
    # the route still passes its waypoint: one of the two legs is untouched
    legs = [paths.shortest_path(a, b, r) for a, b in zip(nodes[:-1], nodes[1:], strict=False)]
    assert path.segments[: len(legs[0].segments)] == legs[0].segments or path.segments[-len(legs[1].segments):] == legs[1].segments


def test_comparing_variants_never_lengthens_the_plan_and_plans_replay():
    scn = load(EXAMPLES / "four-robots.toml")
    first = plan_assembly(scn, PlannerOptions(variants_compared=1))
    best = plan_assembly(scn, PlannerOptions(variants_compared=3))
    assert best.summary["duration_s"] <= first.summary["duration_s"] + 1e-9
    assert replay(best.plan, scn, max_step_um=2.0).ok


def test_seed_scheme_is_one_piece_and_its_failure_says_what_to_change():
    """The seed's scheme cannot stretch D_n's corridor: it fails on this pair, naming the robots, the
    obstacle (the corridor) and the change that would help; the full planner plans it in pieces."""
    scn = random_scenario(2, 501, shape="pair", explicit_goals=True)
    seed = PlannerOptions(max_pieces=1, departure_phases=1, pair_candidates=1, variants_compared=1, orbit_phases=0, overlap_pair=False,
                          preposition=False)
    with pytest.raises(PlanningError) as info:
        plan_assembly(scn, seed)
    msg = info.value.message
    assert "D2 ('R1')" in msg and "D1 ('R0')" in msg and "free corridor" in msg
    assert "to make it plannable:" in msg and "\n" not in msg
    full = plan_assembly(scn, PlannerOptions(overlap_pair=False))
    assert sum(ph.kind == "pair-B" for ph in full.phases) > 1
    assert replay(full.plan, scn, max_step_um=2.0).ok
