"""The seed's two-step EDR strategy as written (seed App. 3.2-3.5), selectable as ``--strategy seed``.

This is a faithful implementation of the paper's control strategy, not a tuned one: it exists so the
project's own controller (``rendezvous``, :func:`stressbots.control.assemble`) can be compared with what
the seed describes, on the same plants. It talks to the robots only through the
:class:`~stressbots.control.Plant` protocol and returns the same
:class:`~stressbots.control.AssemblyResult`.

The strategy (reachability ``R_i --sigma_1--> A_i --sigma_2--> G_i``):

- **C_O** (App. 3.2): the docking object O (the partner's slot body for the G_1 pair, the structure built
  so far for a docking robot) expanded by ``2 r*`` (:meth:`stressbots.structures.Structure.proximity_region`).
- **A_i**: a region around a nominal intermediate configuration ``a_i`` outside C_O, from which fine
  motion reaches the goal: ``a_i`` lies back along a clockwise arc of radius ``r'`` that ends in the slot
  (S_2f(sym), ``r' = 2 r``, first; flatter duties when that arc's swept bodies hit the structure). A
  measured pose is *in A_i* when it is within :attr:`SeedSettings.region_um` / ``region_deg`` of ``a_i``,
  outside C_O, and its eq. (1) arc through the docking point is realisable (``r' >= r``) and arrives
  within the compliance cone (:func:`intermediate_reason`).
- **sigma_1** (gross motion, App. 3.3): every ``t_x`` (``replan_interval_s``) measure the poses and
  re-plan the shortest one-way path (:func:`stressbots.paths.shortest_path`) into A_i (through the
  nominal plan's route waypoints outside C_O), execute ``t_x`` of it; the last leg runs whole. The path
  aims at ``a_i`` itself unless that needs a loop, then at a nearby pose of the region (:func:`region_path`).
- **sigma_2** (fine motion, App. 3.1): from the measured pose, eq. (1) gives ``r'`` through the docking
  point ``p_g,i`` and the corrected duty ``rho_a = r / r'`` gives S_2f; ``r'`` is re-computed every ``t_x``
  (the seed's "reducing or increasing r'"); at the end the robot pushes straight and docking compliance
  takes the last angle error. Leaving the preimage sends it back to sigma_1.
- **G_1** (App. 3.3, :mod:`stressbots.seed_pair`): stage 1 drives D_n to ``A_n'`` while D_(n-1) orbits and
  comes back to its departure pose; stage 2 re-plans D_(n-1) to ``A_(n-1)`` while D_n drives straight to
  ``A_n``; when one robot enters its region and the other does not, sigma_1 is re-planned from the
  measured poses; from ``A_n x A_(n-1)`` both fly S_3f arcs and self-aligning compliance forms the pair.
- **H**: a robot that stops anywhere but in its goal is in the failure region; as in the seed, the
  assembly then terminates, and the result says which robot and where.

Region sizes: the seed bounds A_i by the cylinder ``C_alpha,i`` (:func:`stressbots.bounds.cylinder`). That
bound is a worst case without credit for re-planning, and at the literature's noise it is wider than the
compliance cones (no ``A_i*`` exists: ``stressbots bounds`` says "not guaranteed"), so the regions used
are the cylinder clipped to :attr:`SeedSettings.region_um` / ``region_deg`` (and floored by
``min_region_um`` / ``min_region_deg``, the camera's share); the cylinder is logged with each target.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from .control import AssemblyResult, ControllerOptions, nominal_plan
from .control.result import judge_run
from .robots import TWO_PI
from .seed_loop import (
    SeedLoop,
    SeedSettings,
    SeedStop,
    dock_single,
    in_proximity,
    intermediate_reason,
    nominal_intermediate,
    region_path,
)
from .seed_pair import form_pair

__all__ = ["SeedSettings", "assemble_seed", "intermediate_reason", "in_proximity", "nominal_intermediate", "region_path"]


# -- the whole assembly ----------------------------------------------------------------------------


def _rigid_goals(nominal: np.ndarray, N: int, M: int, measured: np.ndarray):
    """``(phi, c_nom, c_meas)``: the rigid motion that takes the pair's nominal slots onto the measured pair."""
    nom_axis = nominal[M, :2] - nominal[N, :2]
    meas_axis = measured[M, :2] - measured[N, :2]
    phi = math.atan2(meas_axis[0], meas_axis[1]) - math.atan2(nom_axis[0], nom_axis[1])  # clockwise
    return phi, 0.5 * (nominal[M, :2] + nominal[N, :2]), 0.5 * (measured[M, :2] + measured[N, :2])


def _run(loop: SeedLoop, plan) -> np.ndarray:
    """Form G_1, then dock D_(n-2)..D_1; returns the goals aimed at (after the pair formed)."""
    n = loop.n
    structure = plan.structure
    nominal = plan.plan.goal_array()
    N, M = loop.by_rank[n], loop.by_rank[n - 1]
    form_pair(loop, structure, nominal)
    phi, c_nom, c_meas = _rigid_goals(nominal, N, M, loop.est)
    moved = structure.moved(phi, c_meas - c_nom, c_nom)
    goals = moved.goal_poses(loop.scn.names)
    goals[N], goals[M] = loop.est[N], loop.est[M]
    if abs(math.degrees(phi)) > 0.5 or np.hypot(*(c_meas - c_nom)) > 5.0:
        loop.log("retarget", None,
                 f"G_1 formed {np.hypot(*(c_meas - c_nom)):.1f} um / {math.degrees(phi):.1f} deg from nominal; later slots follow it")
    for k in range(n - 2, 0, -1):
        i = loop.by_rank[k]
        route = next((p for p in plan.phases if p.kind == "route" and p.mover == i), None)
        waypoints = [] if route is None else [_moved_pose(w, phi, c_nom, c_meas) for w in route.waypoints[:-1]]
        dock_single(loop, k, goals[i], moved.proximity_region(loop.name(i), float(loop.rstar[i])), waypoints)
    return goals


def _moved_pose(pose, phi: float, c_nom, c_meas) -> np.ndarray:
    d = np.asarray(pose[:2], float) - c_nom
    c, s = math.cos(phi), math.sin(phi)
    return np.array([c_meas[0] + d[0] * c + d[1] * s, c_meas[1] - d[0] * s + d[1] * c, float(np.mod(pose[2] + phi, TWO_PI))])


def assemble_seed(scenario, plant, *, seed: int | None = None, plan=None, time_budget_s: float | None = None,
                  options: ControllerOptions | None = None, settings: SeedSettings | None = None) -> AssemblyResult:
    """Assemble ``scenario``'s structure through ``plant`` with the seed's two-step EDR strategy.

    Same interface and result as :func:`stressbots.control.assemble` (``options`` gives t_x, the time
    budget and the success threshold; ``settings`` the strategy's own numbers). A run that cannot go on
    returns ``success=False`` with the reason in ``failure``; it raises only for bad input (a non-STRING
    design, a plan that is not a ``PlanResult``). As with ours, a plant that offers ``true_poses()`` is
    asked for them after the run, for the result only (``final_true``, the errors); the strategy itself
    sees nothing but ``observe()``.
    """
    from .planning import PlanResult

    opts = options or ControllerOptions()
    if time_budget_s is not None:
        opts = replace(opts, time_budget_s=float(time_budget_s))
    cfg = settings or SeedSettings()
    if plan is None:
        plan = nominal_plan(scenario)
    if not isinstance(plan, PlanResult):
        raise TypeError("plan must be a PlanResult from stressbots.planning.plan_assembly")
    tx = float(opts.replan_interval_s or scenario.control.replan_interval_s)
    loop = SeedLoop(scenario, plant, tx=tx, budget_s=opts.time_budget_s, settings=cfg)
    nominal = plan.plan.goal_array()
    goals = nominal.copy()
    failure = None
    try:
        goals = _run(loop, plan)
    except SeedStop as stop:
        failure = stop.reason
    if failure is not None:
        loop.log("failure", None, failure)
    return judge_run(scenario, plant, seed=seed, failure=failure, estimates=loop.est, goals=goals, nominal_goals=nominal,
                     docked=loop.docked, shape_tol_um=opts.shape_tol_um, duration_s=loop.t, replans=loop.replans,
                     events=loop.events, trace_t=loop.trace_t, trace_poses=loop.trace_p)
