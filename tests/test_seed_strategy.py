"""The seed's two-step EDR strategy (issue 12 goal 2): its fine-motion formulas against simulated motion,
its regions on hand-built cases, and whole runs through the Plant protocol.

Independent truth: motion integrated step by step with :func:`stressbots.kinematics.move` (the simulator's
closed form), shapely geometry, and the simulated plant's own record of who docked.
"""

from __future__ import annotations

import json
import math
import pickle

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Point, box

from stressbots.assessment import shape_error
from stressbots.control import Plant, nominal_plan
from stressbots.errors import StressbotsError
from stressbots.generate import LITERATURE_NOISE, random_scenario
from stressbots.kinematics import move
from stressbots.paths import arc_through, interpolation_deviation, shortest_path
from stressbots.robots import angle_difference
from stressbots.scenario import Noise, load, to_toml
from stressbots.seed_fine_motion import arc_back, s2f_duty, s2f_steps, s3f_duty, s3f_radii, s3f_steps
from stressbots.seed_strategy import (
    assemble_seed,
    in_proximity,
    intermediate_reason,
    nominal_intermediate,
    region_path,
)
from stressbots.sim import SimulatedPlant
from stressbots.strategies import STRATEGIES, assemble_with

from .conftest import EXAMPLES
from .plants import ProtocolOnly


def _drive(pose, steps, turning_ks, v, r):
    """Integrate primitive steps for one robot that turns under the primitives in ``turning_ks``."""
    p = np.asarray(pose, float)
    for k, d in steps:
        p = move(p, v * d, 1.0 / r if k in turning_ks else 0.0)
    return p


# -- fine motion ----------------------------------------------------------------------------------


@settings(max_examples=60)
@given(
    st.floats(0, 3000), st.floats(0, 3000), st.floats(-7, 7),
    st.floats(60, 900), st.floats(0.05, 2.9), st.floats(100, 300), st.floats(50, 150),
)
def test_eq1_arc_through_the_docking_point_flown_as_s2f(x, y, th, dist, bearing, r, v):
    """Eq. (1)'s r' with the corrected duty rho_a = r / r' (P_i turning, P_(i-1) straight) ends on the point."""
    pose = np.array([x, y, th])
    # a point ahead-right at `bearing` (rad, clockwise from the heading), `dist` away
    point = pose[:2] + dist * np.array([math.sin(th + bearing / 2), math.cos(th + bearing / 2)])
    fine = s2f_duty(pose, point, r)
    arc = arc_through(pose, point)
    if arc.radius_um < r:
        assert fine is None
        return
    assert fine is not None
    assert fine.radius_um == pytest.approx(arc.radius_um)
    assert fine.rho_a == pytest.approx(r / arc.radius_um)
    assert fine.radius_um == pytest.approx(r * (1 + fine.rho_b / fine.rho_a))  # SPEC 8's relation
    period_s = 0.05
    duration = fine.length_um / v
    end = _drive(pose, s2f_steps(fine.rho_a, duration, period_s, 2, 1), {2}, v, r)
    # each symmetric cycle of the mean duty lands on the arc up to (r'-r)(beta - 2 sin(beta/2)) along it
    beta = v * period_s / fine.radius_um
    cycles = math.ceil(duration / period_s)
    tol = cycles * (fine.radius_um - r) * (beta - 2 * math.sin(beta / 2)) * 2 + interpolation_deviation(fine.radius_um, r,
                                                                                                        v * period_s) + 1e-6
    assert np.hypot(*(end[:2] - point)) <= tol
    assert abs(float(angle_difference(end[2], fine.arrival_rad))) <= 1e-6 + tol / fine.radius_um


@pytest.mark.parametrize("rhos", [(1 / 3, 1 / 3, 1 / 3), (1 / 3, 2 / 3, 0.0), (0.2, 0.3, 0.5), (0.1, 0.6, 0.3)])
def test_s3f_radii_match_a_simulated_interleaving_for_both_robots(rhos):
    """D_n turns under P_n only, D_(n-1) under P_n and P_(n-1): their mean radii are eqs. (2)-(3) corrected."""
    n, rN, rM, v = 4, 180.0, 230.0, 120.0
    steps = s3f_steps(rhos, 6.0, 0.02, n)
    assert {k for k, _ in steps} <= {n, n - 1, n - 2}
    start = np.array([100.0, 200.0, 0.3])
    endN = _drive(start, steps, {n}, v, rN)
    endM = _drive(start, steps, {n, n - 1}, v, rM)
    expected = s3f_radii(rhos, rN, rM)
    for end, want in zip((endN, endM), expected, strict=False):
        turn = float(np.mod(end[2] - start[2], 2 * math.pi))
        chord = float(np.hypot(*(end[:2] - start[:2])))
        measured = math.inf if turn < 1e-12 else chord / (2 * math.sin(turn / 2))
        if math.isinf(want):
            assert turn < 1e-12
        else:
            assert measured == pytest.approx(want, rel=2e-3)
    # and the inverse gives the duty back
    if rhos[0] > 0:
        assert s3f_duty(rN, expected[0], rM, expected[1]) == pytest.approx(rhos, abs=1e-12)


def test_s3f_duty_refuses_d_n_turning_more_than_its_partner():
    assert s3f_duty(200.0, 300.0, 200.0, 600.0) is None  # rho_a = 2/3 > rho_a + rho_b = 1/3
    assert s3f_duty(200.0, 150.0, 200.0, 600.0) is None  # r' below r


# -- C_O and A_i -------------------------------------------------------------------------------


def test_proximity_region_membership_by_hand():
    obj = box(0, 0, 260, 60)
    co = obj.buffer(2 * 264.0)
    pts = np.array([[130.0, 30.0], [130.0, 60 + 527.0], [130.0, 60 + 529.0], [-600.0, 30.0], [260 + 373.0, 60 + 373.0]])
    inside = in_proximity(co, pts)
    assert inside.tolist() == [co.covers(Point(*p)) for p in pts] == [True, True, False, False, True]


def _rejection(*args, **kwargs) -> str:
    """``intermediate_reason`` for a pose the test expects rejected: the reason, never ``None``."""
    reason = intermediate_reason(*args, **kwargs)
    assert reason is not None, "expected a rejection"
    return reason


def test_intermediate_region_membership_by_hand():
    r = 200.0
    goal = np.array([0.0, 0.0, 0.0])  # slot at the origin, heading +y
    co = box(-130, 130, 130, 190).buffer(2 * 264.0)  # the structure ahead of the slot, expanded by 2 r*
    a_pose, s = nominal_intermediate(goal, r, co, 0.5, margin_um=20.0)
    assert not co.buffer(20.0).covers(Point(*a_pose[:2]))  # outside C_O with the margin
    assert s > 0
    arc = arc_through(a_pose, goal[:2])
    assert arc.radius_um == pytest.approx(2 * r, rel=1e-9)  # S_2f(sym): r' = 2 r
    assert float(angle_difference(a_pose[2] + arc.turn_rad, goal[2])) == pytest.approx(0.0, abs=1e-9)
    kw = dict(region_um=40.0, region_rad=math.radians(8), cone_rad=math.radians(45))
    assert intermediate_reason(a_pose, a_pose, goal, r, co, **kw) is None
    far = a_pose + np.array([60.0, 0.0, 0.0])
    assert "from a_i" in _rejection(far, a_pose, goal, r, co, **kw)
    turned = a_pose + np.array([0.0, 0.0, math.radians(12)])
    assert "heading" in _rejection(turned, a_pose, goal, r, co, **kw)
    inside = np.array([0.0, -200.0, 0.0])  # in C_O, the slot straight ahead
    assert intermediate_reason(inside, inside, goal, r, co, **kw) == "inside C_O"
    left = np.array([600.0, -600.0, math.radians(90)])  # heading +x: the slot lies to its left
    assert "no clockwise arc" in _rejection(left, left, goal, r, None, **kw)
    sharp = np.array([-400.0, -100.0, 0.0])  # the slot is ahead-right, but its arc turns 152 deg on the way
    assert "compliance cone" in _rejection(sharp, sharp, goal, 10.0, None, **kw)


def test_region_path_avoids_a_loop_and_ends_in_the_region():
    r = 200.0
    a_pose = np.array([0.0, 1000.0, 0.0])
    start = np.array([-3.0, 0.0, 0.0])  # 3 um left of the straight into a_pose: the exact pose needs a loop
    exact = shortest_path(start, a_pose, r)
    assert exact.length > 1000.0 + 2 * math.pi * r * 0.9
    p = region_path(start, a_pose, 40.0, math.radians(8), r)
    assert p.length < 1000.0 + 25.0
    end = np.array(p.end)
    assert np.hypot(*(end[:2] - a_pose[:2])) <= 0.5 * 40.0 * math.sqrt(2) + 1e-9
    assert abs(float(angle_difference(end[2], a_pose[2]))) <= 0.5 * math.radians(8) + 1e-12
    # a start whose exact path needs no loop keeps the exact pose
    on_line = np.array([0.0, 0.0, 0.0])
    assert np.allclose(np.array(region_path(on_line, a_pose, 40.0, math.radians(8), r).end), a_pose, atol=1e-9)


def test_arc_back_is_undone_by_driving_the_arc():
    goal = np.array([500.0, 700.0, 1.0])
    a = arc_back(goal, 350.0, 420.0)
    assert np.allclose(move(a, 350.0, 1 / 420.0), goal, atol=1e-9)


# -- whole runs ---------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def example():
    scn = load(EXAMPLES / "four-robots.toml")
    return scn, nominal_plan(scn)


def test_seed_strategy_assembles_the_example_without_noise(example):
    scn, plan = example
    scn = scn.with_noise(Noise())
    sim = SimulatedPlant(scn, seed=0)
    assert isinstance(ProtocolOnly(sim), Plant)
    res = assemble_seed(scn, ProtocolOnly(sim), seed=0, plan=plan)
    assert res.success, (res.failure, res.events[-5:])
    assert res.final_true is None  # it saw only the protocol
    assert sim.docked.all()  # the plant's own record
    assert shape_error(sim.true_poses(), plan.plan.goal_array(), scn.lengths_um, scn.widths_um).rms_um <= 1.0
    kinds = [e["kind"] for e in res.events]
    assert {"a_n", "A_n", "G_1", "a_i", "A_i", "docked"} <= set(kinds)


@pytest.mark.parametrize("seed", [1, 2])
def test_seed_strategy_at_literature_noise_ends_with_a_reason(example, seed):
    scn, plan = example
    res = assemble_seed(scn, ProtocolOnly(SimulatedPlant(scn, seed=seed)), seed=seed, plan=plan, time_budget_s=150.0)
    assert res.duration_s <= 150.0
    if not res.success:
        assert isinstance(res.failure, str) and res.failure
        assert res.events[-1]["kind"] == "failure" and res.events[-1]["detail"] == res.failure


@pytest.fixture(scope="module")
def small():
    scn = random_scenario(3, 330, shape="tee", noise=LITERATURE_NOISE)
    return scn, nominal_plan(scn)


def test_same_seed_same_run(small):
    scn, plan = small
    a = assemble_seed(scn, SimulatedPlant(scn, seed=2), seed=2, plan=plan, time_budget_s=120.0)
    b = assemble_seed(scn, SimulatedPlant(scn, seed=2), seed=2, plan=plan, time_budget_s=120.0)
    assert a.events == b.events and a.success == b.success and a.failure == b.failure
    assert a.final_true is not None and b.final_true is not None  # the simulator knows the truth
    assert np.array_equal(a.final_true, b.final_true) and np.array_equal(a.trace_poses, b.trace_poses)


def test_strategies_dispatch_by_name(small):
    scn, plan = small
    assert set(STRATEGIES) == {"rendezvous", "seed"}
    assert pickle.loads(pickle.dumps(assemble_with)) is assemble_with
    res = assemble_with("seed", scn, SimulatedPlant(scn, seed=2), seed=2, plan=plan, time_budget_s=30.0)
    assert res.duration_s <= 30.0 and not res.success and "time budget" in res.failure
    with pytest.raises(StressbotsError, match="unknown strategy"):
        assemble_with("nope", scn, SimulatedPlant(scn, seed=2))


def test_simulate_strategy_seed_writes_it_into_result_json(small, tmp_path, run_cli):
    scn, _ = small
    path = tmp_path / "small.toml"
    path.write_text(to_toml(scn.with_noise(Noise())))
    r = run_cli("simulate", str(path), "--strategy", "seed", "--seed", "3", "--out", str(tmp_path / "out"), "-q")
    assert r.code == 0, r.err
    doc = json.loads((tmp_path / "out" / "result.json").read_text())
    assert doc["strategy"] == "seed" and doc["success"] is True and doc["seed"] == 3
    bad = run_cli("simulate", str(path), "--strategy", "ours", "--out", str(tmp_path / "o2"))
    assert bad.code == 2 and bad.err.startswith("error:")


def test_the_seeds_timed_orbit_then_go_never_plans_a_negative_wait():
    """Regression (bench_strategies, tee-6 layout 360, plant seed 3): the secant search for D_n's wait in
    ``seed_pair.orbit_then_go`` ran out of its bracket to a wait of -548 um and the Path it built raised
    ValueError, ending the whole benchmark. The run now ends with a failure reason (or assembles)."""
    from stressbots.strategies import assemble_with

    scn = random_scenario(6, 360, shape="tee", noise=LITERATURE_NOISE)
    res = assemble_with("seed", scn, SimulatedPlant(scn, seed=3), seed=3, plan=nominal_plan(scn))
    assert res.success or res.failure
