"""A plan played open loop: its whole waveform on a fresh simulated plant, judged against its goals.

Open loop is the nominal plan with no feedback at all. With no control error every robot ends in its
slot (planner, waveform synthesis and simulator agree to rounding); with the literature's noise it shows
how far a plan drifts without measurements, which is what the closed loop (:mod:`stressbots.control`) is
for. ``stressbots simulate --plan`` and the demo's comparison runs both use :func:`run_open_loop` and
:func:`result_document`.

Examples
--------
>>> from stressbots.scenario import load
>>> from stressbots.control import nominal_plan
>>> scn = load("examples/four-robots.toml")                      # doctest: +SKIP
>>> run = run_open_loop(scn, nominal_plan(scn).plan, seed=0)     # doctest: +SKIP
>>> run.assessment.success                                       # doctest: +SKIP
True
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from .assessment import Assessment, assess
from .errors import StressbotsError

__all__ = ["OpenLoopRun", "plan_goals", "result_document", "run_open_loop"]


@dataclass(frozen=True)
class OpenLoopRun:
    """One open-loop run: the plant after the whole waveform and its judgement.

    ``goals`` are the slots ``(n, 3)`` (um, rad) the run is judged against, ``observed`` one camera frame
    after the run (NaN rows for dropped robots), ``wall_s`` the wall time (s) of the simulation alone.
    """

    scenario: Any
    plant: Any  # stressbots.sim.SimulatedPlant (recorded trace)
    goals: np.ndarray
    assessment: Assessment
    observed: np.ndarray
    wall_s: float


def plan_goals(scenario, plan, *, source: str | None = None) -> np.ndarray:
    """Slots ``(n, 3)`` of every robot: the plan's ``goals``, else the scenario's.

    Raises
    ------
    StressbotsError
        A robot has a slot in neither (the run could not be judged), naming the robot.
    """
    goals = np.full((scenario.n, 3), np.nan)
    for i, r in enumerate(scenario.robots):
        g = plan.goals.get(r.name, r.goal)
        if g is None:
            raise StressbotsError(
                f"no goal for robot {r.name!r}: the plan has no 'goals' and the scenario gives none, so the run cannot be assessed",
                source=source,
                field="goals",
            )
        goals[i] = tuple(g)
    return goals


def run_open_loop(scenario, plan, *, seed: int | None, source: str | None = None) -> OpenLoopRun:
    """Play ``plan``'s waveform on a fresh :class:`~stressbots.sim.SimulatedPlant` (seeded, trajectory
    recorded) from the start poses, observe once and judge the final poses against :func:`plan_goals`."""
    from .sim import SimulatedPlant, plan_waveform

    goals = plan_goals(scenario, plan, source=source)
    wf = plan_waveform(scenario, plan, source=source)
    t0 = time.perf_counter()
    plant = SimulatedPlant(scenario, seed=seed, record=True)
    plant.apply(wf)
    wall = time.perf_counter() - t0
    observed = plant.observe()
    a = assess(scenario.names, plant.true_poses(), goals, plant.docked, scenario.lengths_um, scenario.widths_um)
    return OpenLoopRun(scenario, plant, goals, a, observed, wall)


def result_document(run: OpenLoopRun, *, scenario_source: str | None, plan_source: str | None) -> dict[str, Any]:
    """``result.json`` of an open-loop run: success, seed, per-robot rows (with ``stuck`` and
    ``left_arena``), the assessment's summary, the plant's events and hidden factors, timing, provenance."""
    from .outputs import provenance

    scn, plant, a = run.scenario, run.plant, run.assessment
    summary = a.summary()
    return {
        "success": a.success,
        "seed": plant.seed,
        "mode": "open-loop",
        "scenario": scenario_source,
        "plan": plan_source,
        "noise": scn.noise.to_file_units(),
        "duration_s": plant.time_s,
        "robots": [
            {**row, "stuck": bool(plant.stuck[k]), "left_arena": bool(plant.arena_hits[k])}
            for k, row in enumerate(a.robot_rows(run.observed))
        ],
        **{k: v for k, v in summary.items() if k != "success"},
        "events": [e.as_dict() for e in plant.events],
        "plant": {
            "speed_factors": dict(zip(scn.names, plant.speed_factors.tolist(), strict=True)),
            "radius_factors": dict(zip(scn.names, plant.radius_factors.tolist(), strict=True)),
        },
        "wall_time_s": run.wall_s,
        "provenance": provenance(plant.seed),
    }
