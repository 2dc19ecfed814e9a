"""The nominal assembly planner: every plan it returns replays soundly, failures say what blocks them.

Truth here is independent of the planner: the replay verifier integrates SPEC 3's closed forms itself,
and the checks below re-derive what a plan must satisfy (accessible prefix primitives, docked robots only
pushing, final bodies at their slots and disjoint) from the plan file alone.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from stressbots import plans
from stressbots.collision import pairwise_overlaps
from stressbots.errors import PlanningError
from stressbots.generate import random_scenario
from stressbots.planning import PlannerOptions, plan_assembly
from stressbots.replay import replay
from stressbots.robots import Pose
from stressbots.scenario import load, loads

from .conftest import EXAMPLES, assert_user_error

#: A deterministic planning budget (structure variants tried) instead of wall time, so that a loaded
#: machine cannot change a test's outcome.
DETERMINISTIC = PlannerOptions(time_budget_s=float("inf"), max_candidates=2)


def _independent_checks(scn, result) -> None:
    """What any sound plan must satisfy, checked from the plan file's content alone."""
    plan = plans.from_dict(json.loads(json.dumps(result.plan.to_dict())))  # through the file format
    order = list(result.analysis.order)
    # 1. Every primitive is a prefix state D_1..D_k of the voltage order (Lemma 1's accessible states).
    prefixes = {frozenset(order[:k]) for k in range(len(order) + 1)}
    for p in plan.primitives:
        assert frozenset(p.turning) in prefixes, p
    # 2. Replaying the file (finely, with the independent integrator) docks everyone with no overlap.
    rep = replay(plan, scn, max_step_um=1.0)
    assert rep.ok, rep.problems
    goals = plan.goal_array()
    assert np.allclose(rep.final[:, :2], goals[:, :2], atol=1e-6)
    dth = np.angle(np.exp(1j * (rep.final[:, 2] - goals[:, 2])))
    assert np.allclose(dth, 0.0, atol=1e-9)
    assert pairwise_overlaps(rep.final, scn.lengths_um, scn.widths_um, tol_um=1e-6) == []
    # 3. Once a robot has docked, every later step keeps it straight (it only pushes).
    turning = plan.turning_matrix()
    t_end = np.cumsum(plan.durations())
    for i, name in enumerate(scn.names):
        col = plan.robots.index(name)
        after = t_end > rep.dock_times_s[i] + 1e-9
        later = after & np.concatenate([[False], after[:-1]])  # steps starting after the docking time
        assert not turning[later, col].any(), f"{name} turns after docking"
    # 4. The docking order is the seed's: D_n and D_{n-1} together, then D_{n-2}..D_1 one at a time.
    t = {name: rep.dock_times_s[scn.index(name)] for name in order}
    assert math.isclose(t[order[-1]], t[order[-2]], abs_tol=1e-6)
    for k in range(len(order) - 2):
        assert t[order[k]] > t[order[k + 1]]


def test_example_plan_is_sound_and_fast():
    scn = load(EXAMPLES / "four-robots.toml")
    result = plan_assembly(scn)
    _independent_checks(scn, result)
    s = result.summary
    assert 0 < s["efficiency"] <= 1.0 + 1e-9
    assert s["lower_bound_s"] <= s["duration_s"]
    assert s["order"] == ["B", "D", "A", "C"]


def test_plan_is_a_function_of_the_seed():
    scn = load(EXAMPLES / "four-robots.toml")
    a = plan_assembly(scn, PlannerOptions(seed=3)).plan.to_dict()
    b = plan_assembly(scn, PlannerOptions(seed=3)).plan.to_dict()
    a.pop("provenance"), b.pop("provenance")
    assert a == b


@settings(max_examples=5, suppress_health_check=[HealthCheck.too_slow], deadline=None)
@given(
    n=st.integers(2, 4),
    seed=st.integers(0, 10_000),
    shape=st.sampled_from(["tee", "cross", "comb", "ladder"]),
    explicit=st.booleans(),
)
def test_random_feasible_scenarios_replay_soundly(n, seed, shape, explicit):
    scn = random_scenario(n, seed, shape="pair" if n == 2 else shape, explicit_goals=explicit)
    try:
        result = plan_assembly(scn, DETERMINISTIC)
    except PlanningError as exc:  # incompleteness is allowed, but must be explained in one line
        assert "\n" not in exc.message and exc.message
        return
    _independent_checks(scn, result)


def test_planner_solves_random_layouts_it_is_known_to_solve():
    """A regression guard on fixed seeds (the success rate itself is measured in benchmarks/)."""
    solved = 0
    cases = [(3, 1), (3, 2), (4, 1), (5, 2)]
    for n, seed in cases:
        scn = random_scenario(n, 100 + seed, shape=("tee", "cross", "comb")[seed % 3], explicit_goals=bool(seed % 2))
        try:
            plan_assembly(scn, DETERMINISTIC)
            solved += 1
        except PlanningError:
            pass
    assert solved == len(cases), f"{solved}/{len(cases)}"


def test_heterogeneous_rotated_structure_with_shuffled_file_order():
    scn = random_scenario(5, 11, shape="cross", heterogeneous=True, shuffle=True)
    assert scn.structure is not None and scn.structure.at.theta != 0.0
    result = plan_assembly(scn)
    _independent_checks(scn, result)
    assert len({r.speed_um_s for r in scn.robots}) == 5


# ----------------------------------------------------------------------------------------------------
# What blocks a plan is said exactly

BASE = """
arena_um = [3000.0, 3000.0]
[[robots]]
name = "A"
snap_down_V = 120.0
release_V = 15.0
start = {a}
[[robots]]
name = "B"
snap_down_V = 140.0
release_V = 30.0
start = {b}
[[robots]]
name = "C"
snap_down_V = 160.0
release_V = 45.0
start = [2400.0, 2400.0, 180.0]
[structure]
shape = "tee"
at = [1500.0, 1500.0, 0.0]
"""


def test_overlapping_orbits_are_reported_with_the_overlap():
    scn = loads(BASE.format(a="[600.0, 600.0, 0.0]", b="[900.0, 700.0, 0.0]"))
    with pytest.raises(PlanningError, match=r"orbits of D1 \('A'\) and D2 \('B'\) overlap at the start by \d+\.\d um"):
        plan_assembly(scn)


def test_orbit_leaving_the_arena_is_reported():
    scn = loads(BASE.format(a="[30.0, 600.0, 0.0]", b="[600.0, 2400.0, 90.0]"))
    with pytest.raises(PlanningError, match=r"orbit of D1 \('A'\) leaves the arena by"):
        plan_assembly(scn)


def test_non_string_design_is_refused_with_the_reason():
    text = BASE.format(a="[600.0, 600.0, 0.0]", b="[600.0, 2400.0, 90.0]").replace("release_V = 30.0", "release_V = 10.0")
    with pytest.raises(PlanningError, match="not STRING"):
        plan_assembly(loads(text))


def test_invalid_explicit_goals_name_the_robot():
    text = """
arena_um = [3000.0, 3000.0]
[[robots]]
name = "A"
snap_down_V = 120.0
release_V = 15.0
start = [600.0, 600.0, 0.0]
goal = [1500.0, 1200.0, 0.0]
[[robots]]
name = "B"
snap_down_V = 140.0
release_V = 30.0
start = [600.0, 2400.0, 90.0]
goal = [1500.0, 1500.0, 90.0]
[[robots]]
name = "C"
snap_down_V = 160.0
release_V = 45.0
start = [2400.0, 2400.0, 180.0]
goal = [1760.0, 1500.0, 270.0]
"""
    with pytest.raises(PlanningError, match=r"D1 \(robot 'A'\)"):
        plan_assembly(loads(text))


def test_cli_plan_writes_files_and_reports_errors(run_cli, tmp_path):
    out = tmp_path / "p"
    res = run_cli("plan", EXAMPLES / "four-robots.toml", "--out", out)
    assert res.code == 0, res.err
    data = json.loads((out / "plan.json").read_text())
    assert data["format"] == "stressbots.plan/1" and set(data) >= {"robots", "primitives", "steps"}
    assert (out / "plan.png").stat().st_size > 10_000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["provenance"]["seed"] == 0 and "numpy" in summary["provenance"]["versions"]
    bad = tmp_path / "bad.toml"
    bad.write_text(BASE.format(a="[600.0, 600.0, 0.0]", b="[900.0, 700.0, 0.0]"))
    assert_user_error(run_cli("plan", bad, "--out", tmp_path / "q"), "bad.toml", "overlap")
    assert_user_error(run_cli("plan", tmp_path / "missing.toml", "--out", tmp_path / "q"), "no such file")
    # the output folder may not be the input file
    assert_user_error(run_cli("plan", bad, "--out", bad), "input file")
    assert bad.read_text().startswith("\narena_um")


# ----------------------------------------------------------------------------------------------------
# The replay verifier catches bad plans


def _example_plan():
    scn = load(EXAMPLES / "four-robots.toml")
    return scn, plan_assembly(scn)


def test_replay_catches_a_wrong_duration_and_a_turning_docked_robot():
    scn, result = _example_plan()
    plan = result.plan
    steps = list(plan.steps)
    k = len(steps) // 2
    steps[k] = plans.PlanStep(steps[k].primitive, steps[k].duration_s + 0.7)
    rep = replay(plans.Plan(plan.robots, plan.primitives, tuple(steps), plan.goals), scn)
    assert not rep.ok
    # after the last robot docks, a turning primitive makes docked robots turn
    longer = plan.steps + (plans.PlanStep(f"P{scn.n}", 1.0),)
    rep = replay(plans.Plan(plan.robots, plan.primitives, longer, plan.goals), scn)
    assert any("docked robot" in p for p in rep.problems)


def test_replay_catches_inaccessible_primitives_and_overlaps():
    scn, result = _example_plan()
    plan = result.plan
    odd = plans.PlanPrimitive("X", ("A",))  # A alone down is not a prefix state of B, D, A, C
    rep = replay(
        plans.Plan(plan.robots, plan.primitives + (odd,), plan.steps, plan.goals),
        scn,
        accessible_turning={frozenset(p.turning) for p in plan.primitives},
    )
    assert any("not an accessible control state" in p for p in rep.problems)
    # goals that put two robots in one place: they can never both dock
    goals = dict(plan.goals)
    goals["A"] = Pose(*goals["B"])
    rep = replay(plans.Plan(plan.robots, plan.primitives, plan.steps, goals), scn)
    assert not rep.ok


GAP = """
arena_um = [3600.0, 3600.0]
[electrodes]
margin_V = 2.0
[[robots]]
name = "D1"
snap_down_V = 109.0
release_V = 3.0
start = [600.0, 600.0, 0.0]
goal = [1800.0, 1540.0, 0.0]
[[robots]]
name = "D2"
snap_down_V = 125.0
release_V = 20.0
start = [3000.0, 600.0, 0.0]
goal = [1740.0, 1540.0, 0.0]
[[robots]]
name = "D3"
snap_down_V = 145.0
release_V = 38.0
start = [600.0, 3000.0, 90.0]
goal = [1860.0, 1540.0, 0.0]
[[robots]]
name = "D4"
snap_down_V = 165.0
release_V = 55.0
start = [3000.0, 3000.0, 180.0]
goal = [1670.0, 1700.0, 90.0]
[[robots]]
name = "D5"
snap_down_V = 185.0
release_V = 70.0
start = [1800.0, 2800.0, 270.0]
goal = [1930.0, 1700.0, 270.0]
"""


def test_docking_into_a_gap_between_docked_neighbours():
    """D1's slot is exactly one body wide between D2 and D3: its approach must start outside the gap."""
    scn = loads(GAP)
    result = plan_assembly(scn)
    _independent_checks(scn, result)
    goals = result.plan.goal_array()
    i1, i2, i3 = scn.index("D1"), scn.index("D2"), scn.index("D3")
    # the neighbours touch D1's slot on both sides (zero clearance): a real gap
    gaps = [abs(goals[i1, 0] - goals[j, 0]) - 0.5 * (scn.widths_um[i1] + scn.widths_um[j]) for j in (i2, i3)]
    assert np.allclose(gaps, 0.0, atol=1e-9)
