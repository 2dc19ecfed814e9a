"""What the controller aims at: the slots of the target structure, from a nominal plan or without one."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..assessment import kabsch_2d
from ..collision import arena_gap, bodies_hit_discs
from ..electrostatics import analyse_scenario
from ..errors import PlanningError
from ..robots import body_corners, orbit_radii, turning_centres
from ..se2 import rotate_about

__all__ = ["PLAN_CLEARANCE_UM", "Targets", "nominal_plan", "refit_slots", "structure_targets"]

PLAN_CLEARANCE_UM = 40.0
"""Clearance of the nominal plans the controller follows: room for tens of um of control error."""


def nominal_plan(scenario, *, seed: int = 0):
    """The nominal plan a closed-loop run follows: a wide clearance (:data:`PLAN_CLEARANCE_UM`) in every
    step where one is found, the planner's default clearance in the steps where none is
    (:attr:`stressbots.planning.PlannerOptions.fallback_clearance_um`): one search, so a layout that
    cannot be planned is refused after one search instead of two."""
    from ..planning import PlannerOptions, plan_assembly

    default = PlannerOptions(seed=seed)
    return plan_assembly(scenario, PlannerOptions(clearance_um=PLAN_CLEARANCE_UM, seed=seed, fallback_clearance_um=default.clearance_um))


@dataclass(frozen=True)
class Targets:
    """What the controller takes from a nominal plan: the slots and (optionally) the planned phases.

    A :class:`stressbots.planning.PlanResult` provides both; :func:`structure_targets` provides the slots
    of the target structure alone, for layouts the planner cannot plan.
    """

    goals: np.ndarray
    phases: tuple = ()


def structure_targets(scenario) -> Targets:
    """The slots of the scenario's target structure without a nominal plan.

    Of the candidate structures (a named shape's variants, or the explicit goals), the one whose slots
    lie inside the arena and clear of the start orbits of every robot that docks after them, with the
    least lower bound on the plan's duration (:func:`stressbots.planning.lower_bound_s`).
    """
    from ..planning import lower_bound_s
    from ..structures import target_structures

    analysis = analyse_scenario(scenario)
    if not analysis.is_string:
        raise PlanningError("closed-loop assembly needs a STRING design: " + "; ".join(analysis.reasons))
    n = scenario.n
    rank = np.empty(n, dtype=int)
    assert analysis.order_index is not None  # a STRING design always has its order
    for k, i in enumerate(analysis.order_index):
        rank[i] = k + 1
    robots = [scenario.robots[i] for i in analysis.order_index]
    L, W, R = scenario.lengths_um, scenario.widths_um, scenario.turn_radii_um
    centres, rs = turning_centres(scenario.starts, R), orbit_radii(L, W, R)
    best = None
    for st in target_structures(robots, scenario.structure):
        g = st.goal_poses(scenario.names)
        clear = scenario.arena_um is None or bool((arena_gap(g, L, W, scenario.arena_um) >= 0.0).all())
        for a in range(n):
            later = [b for b in range(n) if rank[b] < rank[a]]
            if later and bodies_hit_discs(g[a][None, :], L[a], W[a], centres[later], rs[later]).any():
                clear = False
        key = (not clear, lower_bound_s(scenario, st, rank))
        if best is None or key < best[0]:
            best = (key, g)
    if best is None:
        raise PlanningError("no target structure for these robots")
    return Targets(np.asarray(best[1], dtype=np.float64))


def refit_slots(nominal_goals: np.ndarray, estimates: np.ndarray, docked: np.ndarray, lengths_um: np.ndarray,
                widths_um: np.ndarray) -> tuple[np.ndarray, tuple[float, np.ndarray, np.ndarray]] | None:
    """The slots moved with the rigid motion that best maps the docked robots' nominal bodies onto their estimates.

    The judge scores the shape after the best rigid alignment of every robot's body corners (SPEC 6), so a robot yet
    to dock is best aimed at its slot in the frame the docked ones actually took, not the frame G_1 alone took: a
    robot docked a few um along its face then pulls the later slots a share of that with it, and the errors of later
    robots stop adding to it. ``(slots (n, 3), motion)`` with ``motion = (phi_rad clockwise, c_nom, c_meas)`` as
    :func:`~stressbots.control.slot_approach.retarget` takes it; None with fewer than two robots docked.

    >>> nominal = np.array([[0.0, 0.0, 0.0], [0.0, 300.0, 0.0], [0.0, 600.0, 0.0]])
    >>> est = nominal + np.array([5.0, 0.0, 0.0])
    >>> slots, _ = refit_slots(nominal, est, np.array([True, True, False]), np.full(3, 250.0), np.full(3, 60.0))
    >>> np.round(slots[2], 6).tolist()
    [5.0, 600.0, 0.0]
    """
    d = np.flatnonzero(np.asarray(docked, dtype=bool))
    if len(d) < 2:
        return None
    src = body_corners(nominal_goals[d], lengths_um[d], widths_um[d]).reshape(-1, 2)
    dst = body_corners(estimates[d], lengths_um[d], widths_um[d]).reshape(-1, 2)
    rot, t = kabsch_2d(src, dst)
    phi = -float(np.arctan2(rot[1, 0], rot[0, 0]))  # clockwise, the heading convention
    c_nom = nominal_goals[d, :2].mean(axis=0)
    c_meas = rot @ c_nom + t
    slots = rotate_about(nominal_goals, c_nom, phi)
    slots[:, :2] += c_meas - c_nom
    return slots, (phi, c_nom, c_meas)
