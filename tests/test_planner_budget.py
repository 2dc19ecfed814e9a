"""The planner's search budget (issue 15: fail fast) and the extended G_1 search's parking-track cuts.

Truth: the number of G_1 schedules the planner actually tries (counted by wrapping the method that
tries one), plans compared field by field with and without a budget, and the independent replay.
"""

from __future__ import annotations

import json
from typing import Any

import pytest

from stressbots import planning
from stressbots.errors import PlanningError
from stressbots.generate import random_scenario
from stressbots.planning import PlannerOptions, plan_assembly
from stressbots.replay import replay


def _counting(monkeypatch) -> list[int]:
    count = [0]
    orig = planning._Planner._schedule_pair

    def counted(self, *args, **kwargs):
        count[0] += 1
        return orig(self, *args, **kwargs)

    monkeypatch.setattr(planning._Planner, "_schedule_pair", counted)
    return count


# A generated ladder whose G_1 only the extended search of the piece scheme forms (88 G_1 schedules; the
# overlapped schedules, tried first by default, are turned off where these tests are about that search): D4 must loop back to a
# parking run between the pieces of D3's route, around D1's orbit and short of the arena edge.
_HARD: dict[str, Any] = dict(n=4, seed=1071, shape="ladder", explicit_goals=True, heterogeneous=True)


@pytest.mark.parametrize("budget", [10, 30])
def test_a_search_stops_at_its_budget_and_says_what_blocks(monkeypatch, budget):
    count = _counting(monkeypatch)
    scn = random_scenario(**_HARD)
    with pytest.raises(PlanningError) as err:
        plan_assembly(scn, PlannerOptions(search_budget=budget, overlap_pair=False))
    assert count[0] == budget  # every schedule up to the budget, none after it
    msg = err.value.message
    assert f"search budget of {budget} G_1 schedules spent" in msg
    assert "cannot form G_1 with D4" in msg and "; to make it plannable: " in msg


def test_the_extended_search_plans_the_hard_ladder_and_the_plan_replays():
    scn = random_scenario(**_HARD)
    with pytest.raises(PlanningError):
        plan_assembly(scn, PlannerOptions(extended_search=False, overlap_pair=False))
    res = plan_assembly(scn, PlannerOptions(search_budget=None, overlap_pair=False))
    assert replay(res.plan, scn, max_step_um=1.0).ok


def test_the_default_budget_bounds_the_search_and_its_plan_replays(monkeypatch):
    count = _counting(monkeypatch)
    scn = random_scenario(**_HARD)
    try:
        res = plan_assembly(scn, PlannerOptions(overlap_pair=False))
    except PlanningError as exc:
        assert "; to make it plannable: " in exc.message
    else:
        assert replay(res.plan, scn, max_step_um=1.0).ok
    assert 0 < count[0] <= planning.SEARCH_BUDGET_DEFAULT


@pytest.mark.parametrize("layout", [dict(n=4, seed=1068, shape="tee", explicit_goals=False, heterogeneous=True),
                                    dict(n=5, seed=1087, shape="comb", explicit_goals=True, heterogeneous=True)])
def test_a_budget_the_search_fits_in_leaves_the_plan_unchanged(layout: dict[str, Any]):
    scn = random_scenario(**layout)
    unbounded = plan_assembly(scn, PlannerOptions(search_budget=None)).plan.to_dict()
    bounded = plan_assembly(scn, PlannerOptions()).plan.to_dict()
    for d in (unbounded, bounded):
        d.pop("provenance", None)
    assert json.dumps(bounded, sort_keys=True) == json.dumps(unbounded, sort_keys=True)


def test_a_layout_only_the_extended_search_plans_is_planned_within_the_budget_and_replays():
    # The standard search cannot form G_1 here; the extended one (parking runs that fit in the track left
    # after D_{n-1}'s wait, runs that stop short of the track's end) can, well within the default budget.
    scn = random_scenario(3, 1053, shape="comb", explicit_goals=True, heterogeneous=False)
    with pytest.raises(PlanningError):
        plan_assembly(scn, PlannerOptions(extended_search=False, overlap_pair=False))
    res = plan_assembly(scn, PlannerOptions(overlap_pair=False))
    rep = replay(res.plan, scn, max_step_um=1.0)
    assert rep.ok, rep.problems


def test_the_nominal_plan_searches_once_at_both_clearances(monkeypatch):
    """G_1 fails at the wide clearance and is searched again at the default one in the same search; the
    schedules the wide attempt tried are refunded, so each clearance's attempts stay within one default
    budget (before, a whole second search at the default clearance followed the wide one)."""
    from stressbots.control.targets import PLAN_CLEARANCE_UM, nominal_plan

    by_clearance: dict[float, int] = {}
    orig = planning._Planner._schedule_pair

    def counted(self, *args, **kwargs):
        by_clearance[self.opts.clearance_um] = by_clearance.get(self.opts.clearance_um, 0) + 1
        return orig(self, *args, **kwargs)

    monkeypatch.setattr(planning._Planner, "_schedule_pair", counted)
    # the piece search only: with the overlapped G_1 schedules both attempts plan this ladder at once
    monkeypatch.setattr(planning._Planner, "_overlap_first", lambda *_args: False)
    monkeypatch.setattr(planning._Planner, "_overlap_route", lambda *_args: False)
    try:
        nominal_plan(random_scenario(**_HARD))
    except PlanningError as exc:
        assert "; to make it plannable: " in exc.message
    assert by_clearance[PLAN_CLEARANCE_UM] > 0 and by_clearance[PlannerOptions().clearance_um] > 0
    assert max(by_clearance.values()) <= planning.SEARCH_BUDGET_DEFAULT


@pytest.mark.parametrize("wait0", [1.0, 2.0, 3.5])
def test_extended_parking_cuts_fit_in_the_track_left_after_the_wait(wait0):
    from stressbots import paths
    from stressbots.electrostatics import analyse_scenario
    from stressbots.robots import Pose
    from stressbots.scenario import load
    from stressbots.structures import target_structures

    from .conftest import EXAMPLES

    scn = load(EXAMPLES / "four-robots.toml")
    analysis = analyse_scenario(scn)
    assert analysis.order_index is not None
    st0 = target_structures([scn.robots[i] for i in analysis.order_index], scn.structure)[0]
    found = {}
    for extended in (False, True):
        p = planning._Planner(scn, analysis, st0, PlannerOptions(), extended=extended)
        N, M = p.by_rank[scn.n], p.by_rank[scn.n - 1]
        obst = p.obstacles([p.by_rank[j] for j in range(1, scn.n - 1)], [])
        full = paths.Path(Pose(*p.tl.poses[M]), p.r[M], (("S", 20.0 * p.v[M]),))
        park = (p.tl.poses[N].copy(), 900.0)  # a track from D_n's own start: D_n drives the wait along it
        found[extended] = list(p._park_cuts(N, M, full, 20.0, 600.0, park, obst, 100.0, wait0))
        left_s = (900.0 - p.v[N] * wait0) / p.v[N]
    assert set(found[False]) <= set(found[True])  # the standard cuts are still tried
    new = [c for c in found[True] if c not in found[False]]
    assert new and found[True][0] in new  # the fitting cuts come first
    assert all(piece <= left_s + 1e-9 for piece in found[True][0][:-1])  # every run on the track fits in what is left
    assert all(abs(sum(c) - 20.0) < 1e-6 for c in found[True])  # the pieces make up D_{n-1}'s whole route
