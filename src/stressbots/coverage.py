"""Regions the closed-loop controller aims at, and how often the true poses lie in them (Monte Carlo).

:mod:`stressbots.bounds` answers the seed's question (App. 3.2-3.4): does the worst-case error region fit
in the docking region, i.e. is ``A_i*`` non-empty? At the literature's noise it never is, yet the
controller (:mod:`stressbots.control`) assembles almost every layout, because it measures and re-plans.
This module describes the regions that controller actually aims at, at the moments it commits to an
open-loop stretch, and measures by simulation how often the *true* pose lies inside them.

Regions (slot frame of the robot's goal pose; ``e`` lateral um to the slot's right, ``psi`` heading
relative to the slot's, clockwise positive)
-----------------------------------------------------------------------------------------------------
- **funnel** (``A_i`` of the controller, single robots D_1..D_{n-2}): the approach funnel behind the slot
  from which the robot merges onto its approach line without a loop
  (:func:`stressbots.control.queries.in_funnel`, thresholds of :class:`~stressbots.control.tuning.Tuning`).
  Moment: the first camera frame of the robot's docking phase whose *estimate* is in the funnel, i.e.
  where its gross motion ends. Approximation: the corridor length is the longest of
  ``Tuning.approach_lengths_um`` (the controller shortens it where the structure blocks it).
- **straight-in** (the controller's aim for the final approach): ``|e| <= Tuning.small_miss_um`` and
  ``|psi| <= Tuning.arrive_deg``. Moment: the start of the robot's final straight run before its first
  contact with the structure (the end of the last Drive in which its arm was down).
- **capture** (``G_i*``: what the docking model and the controller's docking test accept): inside the
  +-45 deg sticking cone and, after docking compliance turns the robot about its leading front corner
  until flush, within ``ControllerOptions.dock_tol_um`` of the slot (:func:`capture_offset`). Same moment.
- **rendezvous** (G_1): D_n and D_{n-1} about to drive straight into each other. Moment: the controller's
  ``depart`` event. The region is on the predicted meeting (both straight at their true speeds,
  :func:`straight_meeting`): ``rendezvous-aim`` is the controller's departure test
  (``max(|w_y| / 80 um, |alpha| / 60 deg) <= Tuning.departure_cost_max``), ``rendezvous-capture`` the
  self-alignment limits ``|w_y| < 80 um``, ``|alpha| < 60 deg``.

The true poses come from the plant side only (:class:`RecordingPlant`: the true pose at every camera
frame; :meth:`stressbots.sim.SimulatedPlant.drive_log`: at the end of every Drive), the moments from
the controller's result (events and estimate trace) and the simulator's contact events: the controller
runs unchanged.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .robots import angle_difference

__all__ = [
    "ControllerRegions",
    "DockingCapture",
    "StraightInAim",
    "RendezvousRegion",
    "Sample",
    "RegionCoverage",
    "ControllerCoverage",
    "RecordingPlant",
    "approach_coords",
    "capture_offset",
    "straight_meeting",
    "tally",
    "samples_of_run",
    "controller_coverage",
]


# ----------------------------------------------------------------------------------------------------
# geometry (pure)


def approach_coords(goal, poses) -> tuple[np.ndarray, np.ndarray]:
    """``(e_um, psi_rad)`` of poses ``(N, 3)`` on a straight run toward the slot ``goal``.

    ``e`` is where the robot's centre line crosses the line through the slot's centre across its heading,
    measured to the slot's right; ``psi`` the heading relative to the slot's (clockwise positive). A
    straight run keeps both constant, so they describe the whole final approach.

    >>> e, psi = approach_coords([0.0, 0.0, 0.0], [[10.0, -100.0, 0.0]])
    >>> float(e[0]), float(psi[0])
    (10.0, 0.0)
    """
    g = np.asarray(goal, dtype=np.float64)
    p = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    th = float(g[2])
    d = p[:, :2] - g[:2]
    along = d[:, 0] * math.sin(th) + d[:, 1] * math.cos(th)
    right = d[:, 0] * math.cos(th) - d[:, 1] * math.sin(th)
    psi = np.asarray(angle_difference(p[:, 2], th), dtype=np.float64)
    with np.errstate(over="ignore", invalid="ignore"):
        e = right - along * np.tan(psi)
    return e, psi


def capture_offset(e_um, psi_rad, length_um: float, width_um: float) -> np.ndarray:
    """Lateral offset (um) from the slot after docking compliance, for a straight approach ``(e, psi)``.

    The leading front corner (the left one for ``psi > 0``: the body is turned clockwise) meets the face
    the slot's front edge lies on; the robot then turns about that corner until its front edge is flush
    (seed App. 3.5). With ``L``, ``W`` the body: at contact the centre is ``a_c = (L/2)(1 - cos psi) -
    (W/2) sin psi`` along the slot's axis from the slot's centre, at lateral position ``e + a_c tan psi``;
    the corner lies ``(L/2) sin psi - (W/2) cos psi`` to its right, and the flush body's centre ``W/2``
    right of the corner. Mirror image for ``psi < 0``.
    Valid for ``|psi| < 90 deg`` and a face long enough to take the corner.

    >>> float(capture_offset(12.0, 0.0, 260.0, 60.0))
    12.0
    """
    e = np.asarray(e_um, dtype=np.float64)
    psi = np.asarray(psi_rad, dtype=np.float64)
    a = np.abs(psi)
    hl, hw = 0.5 * length_um, 0.5 * width_um
    a_c = hl * (1.0 - np.cos(a)) - hw * np.sin(a)
    shift = a_c * np.tan(a) + hl * np.sin(a) + hw * (1.0 - np.cos(a))
    return e + np.sign(psi) * shift


@dataclass(frozen=True)
class DockingCapture:
    """``G_i*`` of a docking robot: straight approaches ``(e, psi)`` that dock within ``tol_um`` of the slot.

    Attributes: ``tol_um`` (the controller's docking tolerance), ``cone_rad`` (the sticking cone), the
    robot's ``length_um`` and ``width_um``.
    """

    tol_um: float
    cone_rad: float
    length_um: float
    width_um: float

    def contains(self, e_um, psi_rad) -> np.ndarray:
        psi = np.asarray(psi_rad, dtype=np.float64)
        off = capture_offset(e_um, psi, self.length_um, self.width_um)
        return (np.abs(psi) <= self.cone_rad) & (np.abs(off) <= self.tol_um)

    def lateral_limits(self, psi_rad) -> tuple[np.ndarray, np.ndarray]:
        """``(e_min, e_max)`` at headings ``psi`` (the offset is ``e`` plus a shift of ``psi`` alone)."""
        shift = capture_offset(0.0, psi_rad, self.length_um, self.width_um)
        return -self.tol_um - shift, self.tol_um - shift

    def size(self) -> str:
        return f"|e_f|<={self.tol_um:g} um, |psi|<={math.degrees(self.cone_rad):g} deg"


@dataclass(frozen=True)
class StraightInAim:
    """The controller's aim for the final straight run: ``|e| <= lateral_um`` and ``|psi| <= heading_rad``."""

    lateral_um: float
    heading_rad: float

    def contains(self, e_um, psi_rad) -> np.ndarray:
        return (np.abs(np.asarray(e_um)) <= self.lateral_um) & (np.abs(np.asarray(psi_rad)) <= self.heading_rad)

    def size(self) -> str:
        return f"|e|<={self.lateral_um:g} um, |psi|<={math.degrees(self.heading_rad):g} deg"


def straight_meeting(p_n, v_n: float, l_n: float, p_m, v_m: float, l_m: float) -> tuple[float, float]:
    """``(w_y_um, alpha_rad)`` where two robots driving straight into each other meet (seed App. 3.5).

    The meeting axis is the bisector of D_{n-1}'s heading and the reverse of D_n's; ``w_y`` is the offset
    of the two front-edge midpoints across it when they meet along it, ``alpha`` the incidence
    ``theta_m - theta_n - pi`` (wrapped). ``w_y`` is inf when they do not close on each other.

    >>> w, a = straight_meeting([0.0, 500.0, math.pi], 100.0, 260.0, [30.0, 0.0, 0.0], 100.0, 260.0)
    >>> round(w, 6), round(a, 6)
    (30.0, 0.0)
    """
    pn, pm = np.asarray(p_n, float), np.asarray(p_m, float)
    hn = np.array([math.sin(pn[2]), math.cos(pn[2])])
    hm = np.array([math.sin(pm[2]), math.cos(pm[2])])
    alpha = float(angle_difference(pm[2], pn[2] + math.pi))
    u = hm - hn
    u = u / max(float(np.hypot(*u)), 1e-12)
    perp = np.array([u[1], -u[0]])
    fn, fm = pn[:2] + 0.5 * l_n * hn, pm[:2] + 0.5 * l_m * hm
    gap = float((fn - fm) @ u)
    closing = float(v_m * (hm @ u) - v_n * (hn @ u))
    if gap <= 0.0 or closing <= 1e-12:
        return math.inf, alpha
    t = gap / closing
    w = float(((fn + v_n * t * hn) - (fm + v_m * t * hm)) @ perp)
    return abs(w), alpha


@dataclass(frozen=True)
class RendezvousRegion:
    """Predicted meetings accepted: ``|w_y| < max_offset_um`` and ``|alpha| < max_incidence_rad``, each
    scaled by ``fraction`` (1: self-alignment's limits; ``Tuning.departure_cost_max``: the controller's)."""

    max_offset_um: float
    max_incidence_rad: float
    fraction: float = 1.0

    def contains(self, w_y_um, alpha_rad) -> np.ndarray:
        w, a = np.abs(np.asarray(w_y_um, float)), np.abs(np.asarray(alpha_rad, float))
        return (w < self.fraction * self.max_offset_um) & (a < self.fraction * self.max_incidence_rad)

    def size(self) -> str:
        return f"|w_y|<{self.fraction * self.max_offset_um:g} um, |alpha|<{math.degrees(self.fraction * self.max_incidence_rad):g} deg"


# ----------------------------------------------------------------------------------------------------
# samples and their tally (pure)


@dataclass(frozen=True)
class Sample:
    """One moment of one run: where the true pose was in a region's coordinates, and whether inside.

    ``coords`` are the region's two coordinates (``(e_um, psi_deg)``, ``(behind_um, right_um)`` or
    ``(w_y_um, alpha_deg)``); ``xy`` the robot's true position (um) for pictures.
    """

    region: str
    robot: str
    scale: float
    trial: int
    coords: tuple[float, float]
    xy: tuple[float, float]
    inside: bool


@dataclass(frozen=True)
class RegionCoverage:
    """Coverage of one region at one noise scale: ``inside`` of ``samples`` moments, with a Wilson interval."""

    region: str
    robot: str
    size: str
    scale: float
    samples: int
    inside: int
    fraction: float
    low: float
    high: float
    seed_verdict: str

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def tally(samples: Sequence[Sample], sizes: dict[tuple[str, str], str], verdicts: dict[str, str] | None = None,
          confidence: float = 0.95) -> tuple[RegionCoverage, ...]:
    """Count samples per (region, robot, scale), in first-seen order, with Wilson intervals.

    ``sizes`` maps ``(region, robot)`` to the region's size text; ``verdicts`` robot names to the seed's
    ``A_i*`` verdict ("-" when missing; a pair ``"A+B"`` gets both, ``"yes / no"``).
    """
    from .montecarlo import wilson_interval

    groups: dict[tuple[str, str, float], list[bool]] = {}
    for s in samples:
        groups.setdefault((s.region, s.robot, s.scale), []).append(bool(s.inside))
    out = []
    for (region, robot, scale), flags in groups.items():
        k, n = int(sum(flags)), len(flags)
        lo, hi = wilson_interval(k, n, confidence)
        verdict = " / ".join((verdicts or {}).get(part, "-") for part in robot.split("+"))
        out.append(RegionCoverage(region, robot, sizes.get((region, robot), "-"), float(scale), n, k, k / n, lo, hi, verdict))
    return tuple(out)


# ----------------------------------------------------------------------------------------------------
# recording the truth (plant side)


class RecordingPlant:
    """A plant wrapper that keeps the true poses at every camera frame (the controller sees only the frame).

    Wraps a :class:`stressbots.sim.SimulatedPlant` (made with ``log_drives=True`` for moments inside a
    waveform); ``frames[k]`` is the truth when the ``k``-th frame was taken.
    """

    def __init__(self, plant):
        self.plant = plant
        self.frames: list[np.ndarray] = []

    def observe(self) -> np.ndarray:
        self.frames.append(self.plant.true_poses())
        return self.plant.observe()

    def apply(self, waveform) -> None:
        self.plant.apply(waveform)

    def __getattr__(self, name: str):  # reports (judge_run) read the wrapped plant's truth
        return getattr(self.plant, name)


# ----------------------------------------------------------------------------------------------------
# the moments of one run


#: Simulator events that are not a contact (arm changes, the end of a slide).
_NOT_CONTACT = ("arm_flip", "arm_chatter", "slide_off")


@dataclass(frozen=True)
class ControllerRegions:
    """The controller's regions for a scenario and its settings (:meth:`of`): the approach funnel (its
    longest corridor), the straight-in aim, each robot's docking capture and the G_1 rendezvous regions."""

    funnel_back_um: float
    tuning: Any
    aim: StraightInAim
    capture: dict[str, DockingCapture]
    meet_aim: RendezvousRegion
    meet_capture: RendezvousRegion

    @classmethod
    def of(cls, scenario, options) -> ControllerRegions:
        from .sim import SELF_ALIGN_MAX_INCIDENCE_RAD, SELF_ALIGN_MAX_OFFSET_UM, STICKING_CONE_RAD

        t = options.tuning
        cap = {r.name: DockingCapture(options.dock_tol_um, STICKING_CONE_RAD, r.length_um, r.width_um) for r in scenario.robots}
        return cls(
            max(t.approach_lengths_um), t, StraightInAim(t.small_miss_um, math.radians(t.arrive_deg)), cap,
            RendezvousRegion(SELF_ALIGN_MAX_OFFSET_UM, SELF_ALIGN_MAX_INCIDENCE_RAD, t.departure_cost_max),
            RendezvousRegion(SELF_ALIGN_MAX_OFFSET_UM, SELF_ALIGN_MAX_INCIDENCE_RAD),
        )

    def sizes(self, order: Sequence[str]) -> dict[tuple[str, str], str]:
        out = {}
        for nm in order[:-2]:
            out[("funnel", nm)] = (f"{self.tuning.funnel_min_behind_um:g}-{self.funnel_back_um + self.tuning.funnel_extra_um:g} um "
                                   f"behind, <={self.tuning.funnel_right_um:g} um right")
            out[("straight-in", nm)] = self.aim.size()
            out[("capture", nm)] = self.capture[nm].size()
        pair = f"{order[-1]}+{order[-2]}"
        out[("rendezvous-aim", pair)] = self.meet_aim.size()
        out[("rendezvous-capture", pair)] = self.meet_capture.size()
        return out


def _frame_at(trace_t: np.ndarray, t_s: float) -> int:
    return int(np.argmin(np.abs(np.asarray(trace_t) - t_s)))


def _rendezvous_samples(scenario, result, rec, regions: ControllerRegions, N: int, M: int, scale: float, trial: int) -> list[Sample]:
    depart = next((e for e in result.events if e["kind"] == "depart"), None)
    if depart is None or len(rec.frames) < len(result.trace_t):
        return []
    truth = rec.frames[_frame_at(result.trace_t, depart["t_s"])]
    v = scenario.speeds_um_s * rec.plant.speed_factors
    L = scenario.lengths_um
    w, a = straight_meeting(truth[N], float(v[N]), float(L[N]), truth[M], float(v[M]), float(L[M]))
    pair = f"{scenario.names[N]}+{scenario.names[M]}"
    xy = (float(truth[N, 0]), float(truth[N, 1]))
    coords = (w, math.degrees(a))
    return [Sample(name, pair, scale, trial, coords, xy, bool(reg.contains(w, a)))
            for name, reg in (("rendezvous-aim", regions.meet_aim), ("rendezvous-capture", regions.meet_capture))]


def _first_contact(plant, name: str, structure: set[str], t_from: float) -> float | None:
    for ev in plant.events:
        if ev.robot == name and ev.time_s > t_from and ev.other in structure and ev.kind not in _NOT_CONTACT:
            return float(ev.time_s)
    return None


def _approach_sample(scenario, result, rec, regions: ControllerRegions, i: int, structure: set[str], t_from: float, scale: float,
                     trial: int) -> list[Sample]:
    """Straight-in and capture at the start of robot ``i``'s final straight run before its first contact."""
    name = scenario.names[i]
    t_c = _first_contact(rec.plant, name, structure, t_from)
    if t_c is None:
        return []
    times, turning, poses = rec.plant.drive_log()
    c = int(np.searchsorted(times, t_c - 1e-12))  # the Drive during which it touched
    if c >= len(times) or turning[c, i]:
        return []  # it met the structure on an arc: no straight approach to judge
    before = np.flatnonzero(turning[:c, i])
    pose = poses[before[-1], i] if len(before) else poses[max(c - 1, 0), i]
    e, psi = approach_coords(result.goals[i], pose[None, :])
    coords = (float(e[0]), math.degrees(float(psi[0])))
    xy = (float(pose[0]), float(pose[1]))
    return [Sample("straight-in", name, scale, trial, coords, xy, bool(regions.aim.contains(e[0], psi[0]))),
            Sample("capture", name, scale, trial, coords, xy, bool(regions.capture[name].contains(e[0], psi[0])))]


def _funnel_sample(scenario, result, rec, regions: ControllerRegions, i: int, t_from: float, t_to: float, scale: float,
                   trial: int) -> list[Sample]:
    """The approach funnel at the first frame of the docking phase whose estimate is in it."""
    from .control.queries import in_funnel, line_coords

    goal = result.goals[i]
    r = float(scenario.turn_radii_um[i])
    tt = np.asarray(result.trace_t)
    for j in np.flatnonzero((tt >= t_from) & (tt <= t_to)):
        if j >= len(rec.frames) or not np.isfinite(result.trace_poses[j, i]).all():
            continue
        if in_funnel(*line_coords(goal, result.trace_poses[j, i]), regions.funnel_back_um, r, regions.tuning):
            truth = rec.frames[j][i]
            b, rt, psi = line_coords(goal, truth)
            ok = in_funnel(b, rt, psi, regions.funnel_back_um, r, regions.tuning)
            return [Sample("funnel", scenario.names[i], scale, trial, (b, rt), (float(truth[0]), float(truth[1])), bool(ok))]
    return []


def samples_of_run(scenario, result, rec: RecordingPlant, regions: ControllerRegions, *, scale: float = 1.0,
                   trial: int = 0) -> list[Sample]:
    """Every region's sample of one closed-loop run (:func:`stressbots.control.assemble` through ``rec``)."""
    from .electrostatics import analyse_scenario

    analysis = analyse_scenario(scenario)
    order = list(analysis.order_index or ())
    n = len(order)
    N, M = order[-1], order[-2]
    out = _rendezvous_samples(scenario, result, rec, regions, N, M, scale, trial)
    g1_plant = next((ev.time_s for ev in rec.plant.events if ev.kind == "self_align"), None)
    g1_ctl = next((e["t_s"] for e in result.events if e["kind"] == "G_1"), None)
    if g1_plant is None or g1_ctl is None:
        return out
    docked_at = {e["robot"]: e["t_s"] for e in result.events if e["kind"] == "docked"}
    t_ctl = float(g1_ctl)
    for k in range(n - 3, -1, -1):  # D_{n-2} .. D_1, in docking order
        i = order[k]
        structure = {scenario.names[j] for j in order[k + 1:]}
        t_end = float(docked_at.get(scenario.names[i], result.duration_s))
        out += _funnel_sample(scenario, result, rec, regions, i, t_ctl, t_end, scale, trial)
        out += _approach_sample(scenario, result, rec, regions, i, structure, float(g1_plant), scale, trial)
        if scenario.names[i] not in docked_at:
            break
        t_ctl = t_end
    return out


# ----------------------------------------------------------------------------------------------------
# Monte Carlo


@dataclass(frozen=True, eq=False)
class ControllerCoverage:
    """Coverage of the controller's regions over closed-loop trials (``stressbots bounds --trials N``)."""

    scenario: str
    trials: int
    seed: int
    scales: tuple[float, ...]
    successes: tuple[int, ...]
    regions: tuple[RegionCoverage, ...]
    samples: tuple[Sample, ...]
    goals: np.ndarray
    order: tuple[str, ...]

    def to_dict(self) -> dict[str, Any]:
        return {
            "format": "stressbots.coverage/1",
            "scenario": self.scenario,
            "trials": self.trials,
            "seed": self.seed,
            "noise_scales": list(self.scales),
            "successes": list(self.successes),
            "moments": {
                "funnel": "first frame of the docking phase whose estimate is in the approach funnel (gross motion ends)",
                "straight-in, capture": "start of the final straight run before the first contact with the structure",
                "rendezvous-aim, rendezvous-capture": "the controller's depart event (D_n and D_(n-1) drive straight into each other)",
            },
            "regions": [r.to_dict() for r in self.regions],
            "samples": [dict(s.__dict__) for s in self.samples],
        }


def controller_coverage(
    scenario,
    *,
    trials: int,
    seed: int = 0,
    scales: Sequence[float] = (1.0, 2.0),
    verdicts: dict[str, str] | None = None,
    plan=None,
    options=None,
    progress: Callable[[int, int], None] | None = None,
) -> ControllerCoverage:
    """Run ``trials`` closed-loop assemblies at each noise scale and tally every region's coverage.

    Trial ``t`` uses plant seed :func:`stressbots.trial.trial_seeds` ``(seed, trials)[t]`` at every scale
    (common random numbers), the scenario's ``[noise]`` times the scale, the default controller
    (:func:`stressbots.control.assemble`) following one nominal plan. ``verdicts`` (robot name -> the
    seed's ``A_i*`` verdict) is copied beside each region.
    """
    from .control import ControllerOptions, assemble, nominal_plan
    from .control.targets import structure_targets
    from .electrostatics import analyse_scenario
    from .errors import PlanningError
    from .sim import SimulatedPlant
    from .trial import trial_seeds

    opts = options or ControllerOptions()
    if plan is None:
        try:
            plan = nominal_plan(scenario)
        except PlanningError:  # as the controller does: the slots alone
            plan = structure_targets(scenario)
    regions = ControllerRegions.of(scenario, opts)
    analysis = analyse_scenario(scenario)
    order = tuple(scenario.names[i] for i in (analysis.order_index or ()))
    seeds = trial_seeds(int(seed), int(trials))
    samples: list[Sample] = []
    successes = []
    done, total = 0, len(seeds) * len(scales)
    for scale in scales:
        scn = replace(scenario, noise=scenario.noise.scaled(float(scale)))
        ok = 0
        for t, s in enumerate(seeds):
            rec = RecordingPlant(SimulatedPlant(scn, seed=s, log_drives=True))
            res = assemble(scn, rec, seed=s, plan=plan, options=opts)
            ok += bool(res.success)
            samples += samples_of_run(scn, res, rec, regions, scale=float(scale), trial=t)
            done += 1
            if progress is not None:
                progress(done, total)
        successes.append(ok)
    return ControllerCoverage(
        scenario.name, int(trials), int(seed), tuple(float(s) for s in scales), tuple(successes),
        tally(samples, regions.sizes(order), verdicts), tuple(samples),
        np.asarray(plan.plan.goal_array() if hasattr(plan, "plan") else plan.goals, dtype=np.float64), order,
    )
