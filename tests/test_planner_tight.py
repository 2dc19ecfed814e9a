"""Tight final approaches (issue 15, completeness): a slot whose rear lies near the arena edge; and the
step-wise clearance fallback of the controller's nominal plan.

A generated tee of 10 identical robots puts its stem's tip (D1's slot) 168 um from the arena's top edge:
no route reaches the start of the gentle approach, which starts ~160 um straight behind the slot. The
tight approach arcs start beside the slot instead. Truth is independent of the planner: the plan is
replayed from its file form at 1 um steps, approach paths are integrated segment by segment with the
closed forms of :func:`stressbots.kinematics.move`, and the room behind the slot is measured from the
slot's corners.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots import plans
from stressbots.errors import PlanningError
from stressbots.generate import random_scenario
from stressbots.kinematics import move
from stressbots.planning import Obstacles, PlannerOptions, plan_assembly
from stressbots.replay import replay

from .test_planner_search import _PLANNER

_EMPTY = Obstacles(np.zeros((0, 2)), np.zeros(0), (), np.zeros((0, 3)), np.zeros(0), np.zeros(0), (), None)


def _stem_near_edge():
    return random_scenario(10, 1170, shape="tee", explicit_goals=False, heterogeneous=False)


def _corners(pose, length, width) -> np.ndarray:
    x, y, th = pose
    h, rgt = np.array([math.sin(th), math.cos(th)]), np.array([math.cos(th), -math.sin(th)])
    return np.array([[x, y] + a * 0.5 * length * h + b * 0.5 * width * rgt for a in (-1, 1) for b in (-1, 1)])


def test_a_stem_tip_near_the_arena_edge_is_docked_by_a_tight_approach():
    scn = _stem_near_edge()
    res = plan_assembly(scn, PlannerOptions(max_candidates=1))
    assert res.analysis.order is not None
    d1 = res.analysis.order[0]
    i = scn.names.index(d1)
    goal = res.plan.goals[d1]
    top = _corners((goal.x, goal.y, goal.theta), scn.lengths_um[i], scn.widths_um[i])[:, 1].max()
    assert scn.arena_um is not None and scn.arena_um[1] - top < 0.5 * 400  # less room than the gentle approach needs
    assert any("tight approach" in note and f"'{d1}'" in note for note in res.notes)
    plan = plans.from_dict(json.loads(json.dumps(res.plan.to_dict())))
    rep = replay(plan, scn, max_step_um=1.0)
    assert rep.ok, rep.problems[:3]
    assert rep.docked.all()
    assert np.allclose(rep.final[:, :2], res.structure.goal_poses(scn.names)[:, :2], atol=0.5)


def test_without_tight_approaches_the_same_layout_is_refused_naming_d1():
    with pytest.raises(PlanningError, match=r"D1 \('R0'\)"):
        plan_assembly(_stem_near_edge(), PlannerOptions(max_candidates=1, tight_approach_deg=(), extended_search=False))


@settings(max_examples=30, deadline=None)
@given(x=st.floats(-2000, 2000), y=st.floats(-2000, 2000), th=st.floats(0, 6.28))
def test_tight_approach_ends_at_the_slot_heading_and_starts_beside_it(x, y, th):
    p = _PLANNER
    i = 0
    goal = np.array([x, y, th])
    path = p.approach_path(i, goal, 160.0, _EMPTY, "D?", tight=True)
    pose = np.asarray(path.start, float)
    for kind, ell in path.segments:
        pose = move(pose, ell, 1.0 / p.r[i] if kind == "R" else 0.0)
    assert np.allclose(pose[:2], goal[:2], atol=1e-6)
    assert abs(math.remainder(pose[2] - th, 2 * math.pi)) < 1e-9
    # the first option (90 deg) clears an empty arena: it starts turned a quarter, within one radius behind
    h = np.array([math.sin(th), math.cos(th)])
    back = float(np.dot(goal[:2] - np.asarray(path.start[:2], float), h))
    assert abs(math.remainder(path.start[2] - th + 0.5 * math.pi, 2 * math.pi)) < 1e-9
    assert back <= p.opts.tight_approach_radius * p.r[i] + 20.0 + 1e-6


def test_a_docking_too_tight_for_the_wide_clearance_alone_falls_back_in_that_step():
    """A generated comb of 9: D6's approach start is within 40 um of D7's docked body, so the wide
    clearance alone refuses it; the nominal plan plans that docking at the default clearance, keeps
    the wide one elsewhere, and its plan replays independently."""
    from stressbots.control.targets import PLAN_CLEARANCE_UM, nominal_plan

    scn = random_scenario(9, 1155, shape="comb", explicit_goals=True, heterogeneous=True)
    with pytest.raises(PlanningError, match=r"D6 \('R5'\)"):
        plan_assembly(scn, PlannerOptions(clearance_um=PLAN_CLEARANCE_UM, max_candidates=1, extended_search=False))
    res = nominal_plan(scn)
    fell_back = [note for note in res.notes if "um clearance" in note]
    assert fell_back and all("none found with 40 um" in note for note in fell_back)
    assert len(fell_back) < scn.n - 1  # G_1 and n - 2 dockings: most keep the wide clearance
    plan = plans.from_dict(json.loads(json.dumps(res.plan.to_dict())))
    rep = replay(plan, scn, max_step_um=1.0)
    assert rep.ok and rep.docked.all(), rep.problems[:3]
