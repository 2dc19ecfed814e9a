"""What a closed-loop run achieved: :class:`AssemblyResult` (``result.json``'s content)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

__all__ = ["AssemblyResult", "judge_run"]


@dataclass(frozen=True, eq=False)
class AssemblyResult:
    """What a closed-loop run achieved (poses in rad, scenario order)."""

    success: bool
    seed: int | None
    names: tuple[str, ...]
    final_true: np.ndarray | None
    final_observed: np.ndarray
    goals: np.ndarray
    nominal_goals: np.ndarray
    docked: np.ndarray
    shape_error_rms_um: float
    shape_rotation_deg: float
    placement_error_um: np.ndarray
    heading_error_deg: np.ndarray
    duration_s: float
    replans: int
    events: tuple[dict, ...]
    failure: str | None
    trace_t: np.ndarray = field(repr=False, default_factory=lambda: np.zeros(0))
    trace_poses: np.ndarray = field(repr=False, default_factory=lambda: np.zeros((0, 0, 3)))

    def to_dict(self) -> dict[str, Any]:
        """The ``result.json`` content (SPEC 7 keys first).

        ``goal`` is the nominal slot (``position_error_um`` and ``heading_error_deg`` are measured from
        it: the absolute placement error); ``goal_after_G1`` is the slot the controller aimed at once the
        pair had formed where it did (later slots follow the pair, SPEC 6).
        """
        final = self.final_true if self.final_true is not None else self.final_observed
        robots = []
        for i, name in enumerate(self.names):
            robots.append(
                {
                    "name": name,
                    "final": _deg(final[i]),
                    "goal": _deg(self.nominal_goals[i]),
                    "docked": bool(self.docked[i]),
                    "position_error_um": float(self.placement_error_um[i]),
                    "heading_error_deg": float(self.heading_error_deg[i]),
                    "observed": _deg(self.final_observed[i]),
                    "goal_after_G1": _deg(self.goals[i]),
                }
            )
        return {
            "success": bool(self.success),
            "seed": self.seed,
            "robots": robots,
            "mode": "closed-loop",
            "shape_error_rms_um": float(self.shape_error_rms_um),
            "shape_rotation_deg": float(self.shape_rotation_deg),
            "shape_metric": "RMS distance of corresponding body corners after the best proper rigid motion (2-D Kabsch), um",
            "duration_s": float(self.duration_s),
            "replans": int(self.replans),
            "failure": self.failure,
            "events": list(self.events),
        }


def _deg(p) -> list[float]:
    return [float(p[0]), float(p[1]), float(math.degrees(p[2]) % 360.0)]


def judge_run(scenario, plant, *, seed: int | None, failure: str | None, estimates: np.ndarray, goals: np.ndarray,
              nominal_goals: np.ndarray, docked: np.ndarray, shape_tol_um: float, duration_s: float, replans: int,
              events, trace_t, trace_poses) -> AssemblyResult:
    """The :class:`AssemblyResult` of a finished run of either strategy (:mod:`stressbots.strategies`).

    Success needs no failure reason, every robot docked and the RMS shape error after the best rigid
    alignment (um) within ``shape_tol_um``. A plant that offers ``true_poses()`` (the simulator) is
    asked for them only now, for the result; otherwise the controller's ``estimates`` stand in. One that
    also offers ``docked`` (the simulator) has the last word on which robots are docked (SPEC 6: success is
    every robot docked): a robot stopped against a structure corner a few degrees off flush sits within the
    controller's tolerances of its slot, but it is stuck, and no later robot docks on it. Placement
    and heading errors are measured from the nominal slots (absolute placement, reported beside the shape).
    """
    from ..assessment import shape_error
    from ..robots import angle_difference

    true = plant.true_poses() if hasattr(plant, "true_poses") else None
    final = np.asarray(true if true is not None else estimates, dtype=np.float64)
    shape = shape_error(final, nominal_goals, scenario.lengths_um, scenario.widths_um)
    docked = np.asarray(docked, dtype=bool).copy()
    stuck = []
    if true is not None and hasattr(plant, "docked"):  # the simulator knows which robots compliance really docked
        stuck = [scenario.names[i] for i in np.flatnonzero(docked & ~np.asarray(plant.docked, dtype=bool))]
        docked &= np.asarray(plant.docked, dtype=bool)
    success = failure is None and bool(np.all(docked)) and shape.rms_um <= shape_tol_um
    if failure is None and stuck:
        failure = (f"the plant did not dock {', '.join(stuck)}: stopped against the structure but not flush on it "
                   "(failure region H), though the controller counted it docked")
    elif failure is None and not success:
        failure = f"shape error {shape.rms_um:.1f} um RMS exceeds {shape_tol_um:g} um"
    return AssemblyResult(
        success=success,
        seed=seed,
        names=scenario.names,
        final_true=None if true is None else np.asarray(true, dtype=np.float64),
        final_observed=np.asarray(estimates, dtype=np.float64).copy(),
        goals=np.asarray(goals, dtype=np.float64).copy(),
        nominal_goals=np.asarray(nominal_goals, dtype=np.float64).copy(),
        docked=docked,
        shape_error_rms_um=float(shape.rms_um),
        shape_rotation_deg=float(shape.rotation_deg),
        placement_error_um=np.hypot(*(final[:, :2] - nominal_goals[:, :2]).T),
        heading_error_deg=np.degrees(np.abs(angle_difference(final[:, 2], nominal_goals[:, 2]))),
        duration_s=duration_s,
        replans=replans,
        events=tuple(events),
        failure=failure,
        trace_t=np.asarray(trace_t),
        trace_poses=np.asarray(trace_poses),
    )
