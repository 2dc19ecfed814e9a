"""The plant loop both closed-loop strategies share: the only code that calls ``plant.apply`` and
``plant.observe``.

A :class:`PlantLoop` holds what a controller knows between frames: the filtered estimates
(:class:`stressbots.estimation.Estimator`: poses, identified speeds and turn rates), the arm state the
last primitive left, the simulated time (s), the event log and the trace of estimates. :meth:`drive`
turns primitive steps ``(k, duration_s)`` into a waveform, plays it, reads the next frame and updates
the estimates; a step that would pass the time budget is refused before anything is applied
(:meth:`PlantLoop.over_budget` names the error each strategy raises). Both the default controller
(:mod:`stressbots.control.runner`) and the paper's strategy (:mod:`stressbots.seed_loop`) build on it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..electrostatics import analyse_scenario
from ..errors import PlanningError
from ..estimation import Estimator
from ..robots import orbit_radii
from ..waveform import synthesize
from .straight_drift import StraightDrift

__all__ = ["PlantLoop"]


class PlantLoop:
    """Plant I/O, estimates, arm state, time, events and trace of one closed-loop run.

    Parameters
    ----------
    scenario, plant:
        The scenario and anything with ``observe()`` / ``apply(waveform)`` (:class:`stressbots.control.Plant`).
    budget_s:
        Simulated time budget (s): :meth:`drive` refuses steps that would pass it.
    who:
        How the strategy is named in the error for a design that is not STRING.
    """

    def __init__(self, scenario, plant, *, budget_s: float, who: str):
        self.scn = scenario
        self.plant = plant
        self.budget_s = float(budget_s)
        self.analysis = analyse_scenario(scenario)
        if not self.analysis.is_string:
            raise PlanningError(f"{who} needs a STRING design: " + "; ".join(self.analysis.reasons))
        n = scenario.n
        self.n = n
        self.rank = np.empty(n, dtype=int)
        assert self.analysis.order_index is not None  # a STRING design always has its order
        for k, i in enumerate(self.analysis.order_index):
            self.rank[i] = k + 1
        self.by_rank = {int(self.rank[i]): i for i in range(n)}
        self.L, self.W = scenario.lengths_um, scenario.widths_um
        self.docked = np.zeros(n, dtype=bool)
        self.state = np.zeros(n, dtype=np.uint8)
        self.t = 0.0
        self.replans = 0
        self.events: list[dict] = []
        obs = np.asarray(plant.observe(), dtype=np.float64)
        self.estimator = Estimator(obs, scenario.starts, scenario.speeds_um_s, scenario.turn_radii_um)
        nz = scenario.noise
        self.straight_drift = StraightDrift(n, drift_rad_per_um=nz.heading_drift_rad_per_um,
                                            camera_heading_rad=nz.camera_heading_sd_rad,
                                            camera_position_um=nz.camera_position_sd_um)
        self.straight_drift.frame(obs, np.zeros(n, dtype=bool), np.zeros(n))  # the first frame starts no run
        self.trace_t = [0.0]
        self.trace_p = [self.est.copy()]

    def log(self, kind: str, robot: int | None = None, detail: str = "") -> None:
        """Append an event (``t_s``, ``kind``, robot name or None, ``detail``) to the run's log."""
        name = None if robot is None else self.scn.names[robot]
        self.events.append({"t_s": round(self.t, 3), "kind": kind, "robot": name, "detail": detail})

    @property
    def est(self) -> np.ndarray:
        """Filtered pose estimates (n, 3) (um, rad)."""
        return self.estimator.pose

    @property
    def v_hat(self) -> np.ndarray:
        """Identified speeds (um/s)."""
        return self.estimator.speed

    @property
    def omega_hat(self) -> np.ndarray:
        """Identified turn rates with the arm down (rad/s)."""
        return self.estimator.turn_rate

    @property
    def r_hat(self) -> np.ndarray:
        """Identified turning radii (um)."""
        return self.estimator.radius

    @property
    def rstar(self) -> np.ndarray:
        """Radii (um) of the discs the robots sweep when orbiting, with their identified turning radii."""
        return orbit_radii(self.L, self.W, self.r_hat)

    def over_budget(self) -> Exception:
        """The error :meth:`drive` raises for steps past the time budget (each strategy names its own)."""
        return RuntimeError(f"not assembled within the time budget of {self.budget_s:g} s (simulated)")

    def after_drive(self, steps: Sequence[tuple[int, float]]) -> None:
        """Called after every frame :meth:`drive` read (failure detection hooks); nothing by default."""

    def drive(self, steps: Sequence[tuple[int, float]]) -> None:
        """Apply primitive steps ``(k, duration_s)``, then update the estimates from the next frame."""
        steps = [(int(k), float(d)) for k, d in steps if d > 1e-9]
        if not steps:
            return
        total = math.fsum(d for _, d in steps)
        if self.t + total > self.budget_s + 1e-9:
            raise self.over_budget()
        self.plant.apply(synthesize(self.analysis, [(f"P{k}", d) for k, d in steps], initial=self.state))
        frame = self.plant.observe()
        self.estimator.update([(self.rank <= k, d) for k, d in steps], self.docked.copy(), frame)
        straight = (self.rank > max(k for k, _ in steps)) & ~self.docked
        self.straight_drift.frame(frame, straight, self.v_hat * total)
        self.estimator.straight_curvature = self.straight_drift.kappa  # predictions follow the identified drift
        self.t += total
        self.state = np.asarray(self.analysis.primitive_at(steps[-1][0]).state, dtype=np.uint8)
        self.after_drive(steps)
        self.trace_t.append(self.t)
        self.trace_p.append(self.est.copy())
