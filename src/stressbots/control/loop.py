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
from ..waveform import Hold, Synthesizer
from .straight_drift import StraightDrift, StraightDriftSettings

__all__ = ["LOOK_FRAME_S", "PlantLoop", "frame_pieces"]

LOOK_FRAME_S = 0.05
"""s between the still frames of a look (:meth:`PlantLoop.look`) when the loop reads one frame per step list (no
``frame_interval_s``): the controller's default frame interval (``ControllerOptions.frame_interval_s``)."""


def frame_pieces(steps: Sequence[tuple[int, float]], interval_s: float | None, frames: int = 1) -> list[list[tuple[int, float]]]:
    """``steps`` ``(k, duration_s)`` cut into consecutive pieces, a frame to be read after each: the last ``frames``
    frames ``interval_s`` s of driving apart, the first piece all the driving before them (a step may be split; a
    remainder under 1 us stays with its piece). One piece when ``interval_s`` is None or 0 or ``frames`` is 1; fewer
    frames when the steps are shorter than ``(frames - 1) interval_s``.

    >>> [[(k, round(d, 9)) for k, d in p] for p in frame_pieces([(2, 0.7), (1, 0.3)], 0.1, 3)]
    [[(2, 0.7), (1, 0.1)], [(1, 0.1)], [(1, 0.1)]]
    >>> [[(k, round(d, 9)) for k, d in p] for p in frame_pieces([(2, 0.15)], 0.1, 5)]
    [[(2, 0.05)], [(2, 0.1)]]
    >>> frame_pieces([(2, 0.25)], None)
    [[(2, 0.25)]]
    """
    total = math.fsum(d for _, d in steps)
    if not interval_s or frames <= 1 or total <= 1e-9:
        return [list(steps)]
    cuts = [total - j * interval_s for j in range(frames - 1, 0, -1)]
    cuts = [c for c in cuts if c > 1e-6] + [total]
    out: list[list[tuple[int, float]]] = []
    piece: list[tuple[int, float]] = []
    t = 0.0
    for k, d in steps:
        while d > 1e-9:
            take = min(d, cuts[len(out)] - t)
            if d - take < 1e-6:
                take = d
            piece.append((k, take))
            t += take
            d -= take
            if t >= cuts[len(out)] - 1e-6 and len(out) < len(cuts) - 1:
                out.append(piece)
                piece = []
    out.append(piece)
    return [p for p in out if p]


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
    frame_interval_s, frames_per_step:
        :meth:`drive` reads the last ``frames_per_step`` frames of a step list ``frame_interval_s`` s of driving apart
        (plays it in pieces, :func:`frame_pieces`, a frame after each; the pose filter takes them all in). None or 1:
        one frame per step list.
    """

    def __init__(self, scenario, plant, *, budget_s: float, who: str, frame_interval_s: float | None = None,
                 frames_per_step: int = 1, drift_turn_max_deg: float = 0.0):
        self.scn = scenario
        self.frame_interval_s = frame_interval_s
        self.frames_per_step = int(frames_per_step)
        self.plant = plant
        self.budget_s = float(budget_s)
        self.analysis = analyse_scenario(scenario)
        self.synthesize = Synthesizer(self.analysis)  # the waveform of each frame's steps
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
                                            camera_position_um=nz.camera_position_sd_um,
                                            settings=StraightDriftSettings(max_turn_rad=math.radians(drift_turn_max_deg)))
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

    def predicted_track(self, steps: Sequence[tuple[int, float]], dt_s: float = 0.1) -> np.ndarray:
        """Every robot's predicted poses ``(S, n, 3)`` along primitive steps ``(k, duration_s)`` from the estimates: the
        start, then every ``dt_s`` s or less (each step cut evenly) and the end of each step; docked robots stay. A query
        of the estimator's model (identified speeds, radii and straight drift), nothing is driven.

        Checking two bodies against each other at the same instants is what a disc check cannot do: an orbit disc
        stands for wherever its robot may be, these poses say where it is."""
        frozen = self.docked.copy()
        p = self.est.copy()
        out = [p]
        for k, d in steps:
            cuts = max(1, math.ceil(d / dt_s - 1e-9))
            for _ in range(cuts):
                p = self.estimator.predict([(self.rank <= k, d / cuts)], frozen, start=p)
                out.append(p)
        return np.stack(out)

    def look(self, frames: int, prior_frames: float) -> None:
        """Read ``frames`` camera frames while nobody moves, ``frame_interval_s`` s apart, and let the estimator take their
        mean (:meth:`~stressbots.estimation.Estimator.look`, the estimate counting as ``prior_frames`` frames).

        Each frame is preceded by a Hold at the drive band's low level: a constant level inside the band flips no arm
        (the band's rule), and without a Drive no robot moves (SPEC 4), so the frames differ by camera noise only. The
        Holds' time counts against the budget like any step's."""
        dt = self.frame_interval_s or LOOK_FRAME_S
        if frames <= 0:
            return
        if self.t + frames * dt > self.budget_s + 1e-9:
            raise self.over_budget()
        level = self.analysis.electrodes.drive_low_V
        shots = []
        for _ in range(frames):
            self.plant.apply((Hold(level, dt),))
            shots.append(np.asarray(self.plant.observe(), dtype=np.float64))
        self.estimator.look(np.stack(shots), self.docked.copy(), prior_frames)
        self.t += frames * dt
        self.trace_t.append(self.t)
        self.trace_p.append(self.est.copy())

    def drive(self, steps: Sequence[tuple[int, float]]) -> None:
        """Apply primitive steps ``(k, duration_s)``, then update the estimates from the next frame."""
        steps = [(int(k), float(d)) for k, d in steps if d > 1e-9]
        if not steps:
            return
        total = math.fsum(d for _, d in steps)
        if self.t + total > self.budget_s + 1e-9:
            raise self.over_budget()
        pieces = frame_pieces(steps, self.frame_interval_s, self.frames_per_step)
        for m, piece in enumerate(pieces):
            self.plant.apply(self.synthesize([(f"P{k}", d) for k, d in piece], initial=self.state))
            self.state = np.asarray(self.analysis.primitive_at(piece[-1][0]).state, dtype=np.uint8)
            frame = self.plant.observe()
            turning = [(self.rank <= k, d) for k, d in piece]
            if m < len(pieces) - 1:
                self.estimator.blend(turning, self.docked.copy(), frame)
        self.estimator.update([(self.rank <= k, d) for k, d in steps], self.docked.copy(), frame, tail=turning)
        turn_s = np.zeros(self.n)
        for k, d in steps:
            turn_s += np.where(self.rank <= k, d, 0.0)
        straight_s = np.maximum(total - turn_s, 0.0)
        # a frame with a short turn counts too, less the turn (StraightDrift's turn-corrected runs)
        self.straight_drift.frame(frame, ~self.docked, self.v_hat * straight_s, self.estimator.turn_rate * turn_s)
        self.estimator.straight_curvature = self.straight_drift.kappa  # predictions follow the identified drift
        self.t += total
        self.after_drive(steps)
        self.trace_t.append(self.t)
        self.trace_p.append(self.est.copy())
