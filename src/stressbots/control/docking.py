"""Fine motion of a single robot along its slot's approach line: pure queries and the docking policy.

A docking robot drives straight into its slot; the slot's face is the structure's edge. Where it ends
is decided by two things the earlier controller looked at only in part:

- its *lateral miss* when its front reaches the face: ``right + behind * tan(psi)`` (line coordinates
  of :func:`~stressbots.control.queries.line_coords`);
- *docking compliance*: a robot that meets the face at incidence ``psi`` rotates about its leading front
  corner until flush, which moves its centre along the face by ``(L/2) sin(psi)`` (plus a second-order
  ``(W/2)(1 - cos psi)``). A robot 2 deg off and 250 um long ends 4.4 um further to that side.

:func:`contact_offset` predicts the final offset along the face from both. A one-way robot corrects
that offset cheaply only clockwise (a short turn adds to ``psi``), so the policy re-aims with short
clockwise bursts close to the slot, in frames shorter than t_x (:class:`~stressbots.control.tuning.Tuning`
``final_frame_s``): heading drift over the last hundred um is what the earlier single open-loop run
could not see. The last of them, with the run-in, is decided after a still look
(``Tuning.look_at_um`` short of the face the policy yields a :class:`~stressbots.control.loopview.Look`: the mean of
still frames halves a moving robot's heading error) and solved on the burst's own arc (:func:`burst_offset`).

A robot whose *front* touches anything can never leave it: turning about its turning centre (to its
right, outside the body) moves every point of its front edge forward, and it cannot reverse. So a robot
that stops flush against the face near its slot is docked there, off the slot or not
(:class:`DockOutcome.DOCKED_OFF_SLOT`): backing off is impossible, and the shape is judged as a whole.

Everything here is a function of a frozen :class:`~stressbots.control.loop.Snapshot`; the policy
:func:`line_approach` yields the primitive steps it wants applied and returns a :class:`DockOutcome`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Generator
from dataclasses import dataclass
from enum import Enum

import numpy as np

from ..robots import angle_difference
from .loopview import Look, Steps
from .queries import interpolated_steps, line_coords, merge, turn_fraction
from .tuning import ControllerOptions, Tuning

__all__ = ["LOOK_SLACK_UM", "DockOutcome", "DockView", "LineFix", "burst_lever_um", "burst_offset", "compliant_aim", "contact_offset",
           "incidence_bounds", "is_run_in", "lead_um", "line_approach", "loops_back", "reaim_turn_rad", "settle", "stopped_verdict",
           "walk_lead_um"]


LOOK_SLACK_UM = 2.0
"""um. A robot within this of its look point (``Tuning.look_at_um``) looks there: its frames end a ms past the point,
and its estimate scatters about it."""


class DockOutcome(Enum):
    """How a docking attempt ended."""

    DOCKED = "docked"
    """Stopped in its slot within the docking tolerances."""
    DOCKED_OFF_SLOT = "docked off its slot"
    """Stopped flush against the slot's face, beyond the tolerance along it: it cannot leave (front contact)."""
    MISSED = "missed"
    """Off its approach line without contact: gross motion loops it back into the funnel."""
    STUCK = "stuck"
    """Stopped elsewhere (failure region H): back off, if it can, and try again."""
    GAVE_UP = "gave up"
    """The approach ran out of frames without docking."""


@dataclass(frozen=True)
class LineFix:
    """A robot relative to its slot's approach line, with the offset it would dock at."""

    behind_um: float
    right_um: float
    psi_rad: float
    offset_um: float
    """:func:`contact_offset`: where along the face it ends if it drives straight on (+ = right)."""


def contact_offset(behind_um: float, right_um: float, psi_rad: float, length_um: float) -> float:
    """Predicted offset (um, + = right of the slot) along the face of a robot that drives straight in.

    ``right + behind * tan(psi)`` is where its centre line meets the face; docking compliance then turns it
    flush about its leading front corner, moving the centre by ``(L/2) sin(psi) + sign(psi) (W/2)(1 - cos psi)``
    (the second term is below 0.1 um for |psi| < 5 deg and is left out).

    >>> round(contact_offset(100.0, 0.0, 0.0, 250.0), 6)
    0.0
    >>> round(contact_offset(0.0, 3.0, math.radians(2.0), 250.0), 2)   # 3 um right, then (125 um) sin 2 deg
    7.36
    """
    return float(right_um + max(behind_um, 0.0) * math.tan(psi_rad) + 0.5 * length_um * math.sin(psi_rad))


def compliant_aim(pose, goal, r: float, length_um: float, tol_um: float = 0.01) -> np.ndarray | None:
    """The point (um, 2,) an S_2f arc from ``pose`` should pass through so that the robot, turned flush by
    docking compliance, ends in the slot ``goal``; None when no clockwise arc of radius >= ``r`` does.

    One arc cannot fix both position and heading: an arc through the slot itself arrives turned by ``e``
    (rad, + = clockwise) from the slot's heading, and compliance then moves the centre ``(L/2) sin e`` along
    the face (:func:`contact_offset`): 29 um for a 250 um robot arriving 13 deg off, which alone failed the
    shape tolerance at twice the literature's noise. So the arc aims ``x`` um along the face with
    ``x + (L/2) sin e(x) = 0``. Aiming further right turns the arrival further clockwise, so the left side
    grows with ``x`` and the root is found by bisection over ``|x| <= L`` to ``tol_um`` (a fixed-point
    iteration oscillates: its gain is about ``L / behind``, over 1 close to the slot). Points the arc
    cannot reach count as too far left (left of the heading) or too far right (radius below ``r``). A robot
    already pointing right of where it must arrive has no root, only the jump where straight ahead ends
    (3 um, :func:`~stressbots.control.queries.turn_fraction`): it drives straight, the least it can miss by.

    >>> g = np.array([0.0, 0.0, 0.0])
    >>> start = np.array([-10.0, -200.0, math.radians(-10.0)])   # 200 um behind, pointing 10 deg left
    >>> a = compliant_aim(start, g, 100.0, 250.0)
    >>> heading = turn_fraction(start, a, 100.0)[2]
    >>> round(math.degrees(turn_fraction(start, g[:2], 100.0)[2]), 1)   # an arc through the slot: 15.7 deg off
    15.7
    >>> bool(abs(contact_offset(0.0, line_coords(g, np.array([*a, heading]))[1], heading, 250.0)) < 0.5)
    True
    """
    pose, goal = np.asarray(pose, dtype=np.float64), np.asarray(goal, dtype=np.float64)
    right_unit = np.array([math.cos(goal[2]), -math.sin(goal[2])])  # along the face, to the slot's right

    def excess(x: float) -> float:
        """Where the robot would end along the face (um, + = right) for an arc aimed ``x`` um right."""
        point = goal[:2] + x * right_unit
        fr = turn_fraction(pose, point, r)
        if fr is None:  # left of the heading: too far left; right of it (tighter than r, or behind): too far right
            d = point - pose[:2]
            return math.inf if d[0] * math.cos(pose[2]) - d[1] * math.sin(pose[2]) > 0.0 else -math.inf
        if fr[0] == 0.0:  # within 3 um of straight ahead it drives straight, and meets the face on its own line
            return contact_offset(*line_coords(goal, pose), length_um)
        return x + 0.5 * length_um * math.sin(float(angle_difference(fr[2], goal[2])))

    lo, hi = -float(length_um), float(length_um)
    if not (excess(lo) < 0.0 < excess(hi)):
        return None
    while hi - lo > tol_um:
        mid = 0.5 * (lo + hi)
        if excess(mid) < 0.0:
            lo = mid
        else:
            hi = mid
    ends = [x for x in (lo, hi) if math.isfinite(excess(x))]  # a jump (straight to arc) leaves no root: the nearer side
    x = min(ends, key=lambda x: abs(excess(x))) if ends else lo
    return goal[:2] + x * right_unit


def reaim_turn_rad(fix: LineFix, length_um: float, max_deg: float, radius_um: float | None = None) -> float:
    """Clockwise turn (rad, >= 0) that brings a negative predicted offset back to zero, at most ``max_deg``.

    A turn by ``d`` adds about ``(behind + L/2) d`` to :func:`contact_offset`. With ``radius_um`` (the robot's
    turning radius) the turn is solved on the arc itself (:func:`burst_offset`): the arc carries the robot
    ``r sin d`` closer to the face, so the straight-line lever overstates what a burst of a few degrees does close
    to the face (at 26 um out, 5 deg on a 250 um radius leaves the robot 4 um short and the estimate 1 um too
    far left). Zero when the robot would end on or right of its slot: a one-way robot cannot turn left.

    >>> fix = LineFix(200.0, 0.0, 0.0, -6.5)
    >>> round(math.degrees(reaim_turn_rad(fix, 250.0, 5.0)), 3)
    1.146
    """
    if fix.offset_um >= 0.0:
        return 0.0
    cap = math.radians(max_deg)
    linear = -fix.offset_um / burst_lever_um(fix.behind_um, length_um)
    if radius_um is None:
        return float(min(linear, cap))
    lo, hi = 0.0, min(cap, 4.0 * linear)
    if burst_offset(fix, hi, radius_um, length_um) < 0.0:
        return float(hi)
    for _ in range(40):  # the offset grows monotonically with the turn over this range
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if burst_offset(fix, mid, radius_um, length_um) < 0.0 else (lo, mid)
    return float(hi)


def burst_offset(fix: LineFix, turn_rad: float, radius_um: float, length_um: float) -> float:
    """:func:`contact_offset` (um) after a clockwise burst of ``turn_rad`` on an arc of ``radius_um`` from ``fix``.

    >>> fix = LineFix(100.0, -5.0, 0.0, contact_offset(100.0, -5.0, 0.0, 250.0))
    >>> round(burst_offset(fix, 0.0, 200.0, 250.0), 6)
    -5.0
    """
    s, c = math.sin(turn_rad), 1.0 - math.cos(turn_rad)
    sp, cp = math.sin(fix.psi_rad), math.cos(fix.psi_rad)
    right = fix.right_um + radius_um * (s * sp + c * cp)
    behind = fix.behind_um - radius_um * (s * cp - c * sp)
    return contact_offset(behind, right, fix.psi_rad + turn_rad, length_um)


def burst_lever_um(behind_um: float, length_um: float) -> float:
    """What a clockwise burst moves the predicted docking offset (um per rad): the centre line swings over the
    ``behind_um`` left to the face, and compliance adds half the robot's length (:func:`contact_offset`).

    >>> burst_lever_um(100.0, 250.0), burst_lever_um(-3.0, 250.0)
    (225.0, 125.0)
    """
    return max(behind_um, 0.0) + 0.5 * length_um


def stopped_verdict(pose, goal, *, dock_tol_um: float, dock_tol_deg: float, flush_um: float, off_slot_um: float) -> DockOutcome:
    """What a robot that stopped while pushing toward its slot is: docked, docked off its slot, or stuck.

    Docked within ``dock_tol_um`` / ``dock_tol_deg`` of the slot; docked off its slot when its heading is
    within ``dock_tol_deg``, its centre within ``flush_um`` of the slot's face line and within
    ``off_slot_um`` along it (flush against the face it was to dock on: it cannot leave); stuck otherwise.

    >>> g = np.array([0.0, 0.0, 0.0])
    >>> stopped_verdict(np.array([5.0, 0.0, 0.0]), g, dock_tol_um=30, dock_tol_deg=15, flush_um=12, off_slot_um=80).name
    'DOCKED'
    >>> stopped_verdict(np.array([45.0, -3.0, 0.01]), g, dock_tol_um=30, dock_tol_deg=15, flush_um=12, off_slot_um=80).name
    'DOCKED_OFF_SLOT'
    >>> stopped_verdict(np.array([5.0, -60.0, 0.0]), g, dock_tol_um=30, dock_tol_deg=15, flush_um=12, off_slot_um=80).name
    'STUCK'
    """
    pose, goal = np.asarray(pose, float), np.asarray(goal, float)
    dth = abs(float(angle_difference(pose[2], goal[2])))
    if float(np.hypot(*(pose[:2] - goal[:2]))) <= dock_tol_um and dth <= math.radians(dock_tol_deg):
        return DockOutcome.DOCKED
    behind, right, _ = line_coords(goal, pose)
    if dth <= math.radians(dock_tol_deg) and abs(behind) <= flush_um and abs(right) <= off_slot_um:
        return DockOutcome.DOCKED_OFF_SLOT
    return DockOutcome.STUCK


@dataclass(frozen=True)
class DockView:
    """What the docking policy reads each frame (a frozen view of the loop's estimates for one robot)."""

    pose: np.ndarray
    speed_um_s: float
    radius_um: float
    turn_rate_rad_s: float
    goal: np.ndarray
    length_um: float
    nominal_speed_um_s: float
    drift_rad_per_um: float = 0.0
    """Identified straight-line curvature (+ = clockwise; :class:`~stressbots.control.straight_drift.StraightDrift`)."""
    walk_var_rad2_per_um: float = 0.0
    """Heading variance (rad^2) the drift's random walk adds per um driven (the scenario's declared drift,
    :mod:`stressbots.drift`): the part of the drift no identification predicts."""
    slot: np.ndarray | None = None
    """Where docking compliance is to leave the robot, when that is not ``goal`` (a chosen incidence: ``goal`` is its
    pose at contact, :func:`~stressbots.control.landing.landing_pose`); where it stops is judged against this."""

    @property
    def flush_slot(self) -> np.ndarray:
        """The slot a stopped robot is judged against: ``slot``, else ``goal``."""
        return self.goal if self.slot is None else self.slot


def _fix(view: DockView, aim_left_um: float) -> LineFix:
    behind, right, psi = line_coords(view.goal, view.pose)
    right += aim_left_um  # aim a little left of the slot: every later correction is then clockwise
    return LineFix(behind, right, psi, contact_offset(behind, right, psi, view.length_um))


def lead_um(behind_um: float, length_um: float, kappa_deg_per_mm: float, base_um: float) -> float:
    """How far left of its slot (um) a robot ``behind_um`` out aims: the offset a clockwise heading drift of
    ``kappa_deg_per_mm`` would add before it docks (the arc's ``kappa s^2 / 2`` plus compliance's
    ``(L/2) kappa s``), plus ``base_um``. Drift to the right then carries it onto the slot; drift to the
    left is corrected by clockwise bursts (:func:`reaim_turn_rad`), the only cheap correction.

    >>> round(lead_um(0.0, 250.0, 2.0, 1.0), 6)
    1.0
    >>> round(lead_um(200.0, 250.0, 2.0, 0.0), 2)   # (200^2 / 2 + 125 * 200) um^2 * 2 deg/mm
    1.57
    """
    s = max(behind_um, 0.0)
    return float(base_um + math.radians(kappa_deg_per_mm) / 1000.0 * (0.5 * s * s + 0.5 * length_um * s))


def walk_lead_um(behind_um: float, length_um: float, walk_var_rad2_per_um: float, sigmas: float) -> float:
    """How far left of its slot (um) a robot ``behind_um`` out aims for the heading drift's random walk:
    ``sigmas`` standard deviations of the docking offset the walk adds before it docks.

    The walk ``W`` (variance ``w`` per um) moves the point where the centre line meets the face by
    ``int_0^s W`` and, through docking compliance, the centre by ``(L/2) W(s)`` more, so the offset's
    variance is ``w (s^3 / 3 + (L/2) s^2 + (L/2)^2 s)``. A one-way robot fixes a miss to the left with a
    clockwise burst but never one to the right, so it aims left by this much; the lead shrinks as the
    slot nears, and the bursts follow it.

    >>> round(walk_lead_um(0.0, 250.0, 2e-6, 1.0), 6)
    0.0
    >>> round(walk_lead_um(200.0, 250.0, 2e-6, 1.0), 2)   # 2e-6 rad^2/um: the literature's 3.7 deg/mm, half walk
    4.65
    """
    s, h = max(behind_um, 0.0), 0.5 * length_um
    return float(sigmas * math.sqrt(max(walk_var_rad2_per_um, 0.0) * (s**3 / 3.0 + h * s * s + h * h * s)))


def aim_lead(view: DockView, behind_um: float, tune: Tuning, loop_blocked: Callable[[], bool]) -> tuple[float, float]:
    """``(lead_um, walk_um)``: how far left of its slot a robot ``behind_um`` out on its approach line aims, and the
    part of that which is room for the drift's random walk (:func:`walk_lead_um`; ``_frame`` judges misses to the
    right after it). The lead adds up what the identified drift plus ``Tuning.lead_drift_deg_per_mm`` would add
    (:func:`lead_um`), the docking offset of a heading estimate off by ``Tuning.aim_heading_sigma_deg`` (a burst
    planned far out overshoots by that much, and a one-way robot fixes only what ends up to the left), and
    ``Tuning.aim_walk_sigmas`` of the walk, ``Tuning.blocked_walk_sigmas`` more while ``loop_blocked()`` (a miss to
    the right is then for good: driven in or trapped). An identified counter-clockwise drift counts as none: aiming
    right of the slot would bet on it, and what it really does (it carries the robot left) clockwise bursts fix.

    A right-first landing (:func:`incidence_bounds`) leads no further than the bursts its kept incidence spares can
    take back (a larger lead docked right-first robots up to 30 um left of their slots, tuning 2x). At the run-in, the
    last decision, the others keep ``Tuning.run_in_lead_share`` of their lead (nothing later takes it back); a
    right-first one keeps all of it: a miss to the right sets its front edge on the face's corner (stuck, H, for
    good), one to the left costs shape only (tuning layouts at 1x, seed 0: trials with a robot stuck 4 -> 1)."""
    kappa = math.degrees(max(view.drift_rad_per_um, 0.0)) * 1000.0 + tune.lead_drift_deg_per_mm
    lead = lead_um(behind_um, view.length_um, kappa, tune.aim_left_um)
    lead += math.radians(tune.aim_heading_sigma_deg) * burst_lever_um(behind_um, view.length_um)
    sigmas = tune.aim_walk_sigmas + (tune.blocked_walk_sigmas if tune.blocked_walk_sigmas > 0.0 and loop_blocked() else 0.0)
    walk = walk_lead_um(behind_um, view.length_um, view.walk_var_rad2_per_um, sigmas)
    lead += walk
    first, now, keep = incidence_bounds(view, tune.incidence_keep_share)
    if first < 0:  # a right-first robot can take back only what its anticlockwise incidence spares
        cap = max(-keep - now, 0.0) * burst_lever_um(behind_um, view.length_um)
        lead, walk = min(lead, cap), min(walk, cap)
    if first >= 0 and is_run_in(behind_um, view.speed_um_s, tune):
        lead, walk = lead * tune.run_in_lead_share, walk * tune.run_in_lead_share  # the run-in: no burst comes after it
    return lead, walk


def line_approach(
    see: Callable[[], DockView], k: int, opts: ControllerOptions, tx: float, *, loop_blocked: Callable[[], bool],
    log: Callable[[str, str], None], attempt: int = 0,
) -> Generator[Steps | Look, None, DockOutcome]:
    """Fine motion along the approach line of robot ``D_k`` (P_k turns it, P_{k-1} drives it straight).

    ``attempt`` (0 first): each earlier miss widens the offsets accepted without a loop by
    ``Tuning.miss_relax_um`` and the largest re-aim burst by ``Tuning.reaim_max_deg`` (at twice the
    literature's noise a robot could otherwise loop back six times and never dock).

    Merge (straight, interpolated clockwise arc) onto the line, then drive along it aiming
    :func:`lead_um` left of the slot, with a clockwise burst whenever the predicted docking offset
    (:func:`contact_offset`) falls further left than that; the last ``Tuning.final_run_um`` go in frames of
    ``Tuning.final_frame_s``. ``Tuning.look_at_um`` short of the face it stops once and the loop reads
    ``Tuning.look_frames`` still frames (it yields a :class:`~stressbots.control.loopview.Look`); the last re-aim
    burst and the run-in are decided on that estimate. Drive in, push, wait for the robot to stop and judge where
    (:func:`stopped_verdict`). ``see()`` gives the latest view after each yielded list of steps (or look) was applied.
    """
    tune = opts.tuning
    look_at = tune.look_at_um if tune.look_frames > 0 else None  # None once it looked
    for _ in range(tune.approach_frames):
        view = see()
        behind, right, psi = line_coords(view.goal, view.pose)
        if (float(np.hypot(*(view.pose[:2] - view.flush_slot[:2]))) <= opts.dock_tol_um
                and abs(float(angle_difference(view.pose[2], view.flush_slot[2]))) <= math.radians(opts.dock_tol_deg)
                and line_coords(view.flush_slot, view.pose)[0] <= tune.at_face_um):
            break  # at the structure already: push and judge
        if look_at is not None and behind <= look_at + LOOK_SLACK_UM:
            look_at = None
            yield Look(tune.look_frames, tune.look_prior_frames)  # stop and look before the last decisions
            continue
        lead, walk = aim_lead(view, behind, tune, loop_blocked)
        # line coordinates about the aim point, ``lead`` left of the slot
        fix = LineFix(behind, right + lead, psi, contact_offset(behind, right + lead, psi, view.length_um))
        steps = _frame(fix, view, k, opts, tx, loop_blocked, log, attempt, walk, look_at)
        if steps is None:
            return DockOutcome.MISSED
        yield steps
        if steps[-1][0] == k - 1 and steps[-1][1] > max(tx, tune.final_frame_s) + 1e-9:  # the run in, with the push
            break
    else:
        return DockOutcome.GAVE_UP
    return (yield from settle(see, k, opts, tx))


def loops_back(view: DockView, k: int, opts: ControllerOptions, tx: float, *, loop_blocked: Callable[[], bool],
               attempt: int = 0) -> bool:
    """Whether :func:`line_approach` started from ``view`` would loop robot ``D_k`` back at once (its first frame: a
    miss it cannot correct from there). The test the gross motion's end must pass where the approach funnel's bounds
    are too coarse (after a miss in place)."""
    policy = line_approach(lambda: view, k, opts, tx, loop_blocked=loop_blocked, log=lambda *_: None, attempt=attempt)
    try:
        while isinstance(next(policy), Look):
            pass
    except StopIteration as stop:
        return stop.value is DockOutcome.MISSED
    return False


def _frame(fix: LineFix, view: DockView, k: int, opts: ControllerOptions, tx: float, loop_blocked, log, attempt: int = 0,
           walk_um: float = 0.0, look_at_um: float | None = None) -> Steps | None:
    """The steps of one frame along the line (``fix`` relative to the aim point); None: loop back.

    Misses to the right are judged ``walk_um`` (:func:`walk_lead_um`) right of the aim point: that lead is
    room for the random walk to use, not an error (a loop would not dock any closer). ``look_at_um``: where the robot
    is yet to stop and look (``Tuning.look_at_um``); its frame ends there, and no run-in comes before the look."""
    tune = opts.tuning
    relax_um = tune.miss_relax_um * attempt
    burst_max = math.radians(tune.reaim_max_deg * (1 + attempt))
    v, r = view.speed_um_s, view.radius_um
    final = fix.behind_um <= tune.final_run_um
    frame_s = _frame_s(fix.behind_um, v, tx, tune, look_at_um)
    burst: Steps = []
    spare, least = math.inf, 0.0  # the largest and least clockwise burst (rad) a kept incidence allows
    if final:
        kept = _keep_incidence(fix, view, tune.incidence_keep_share, loop_blocked, log, run_in=is_run_in(fix.behind_um, v, tune))
        if kept is None:
            return None
        fix, spare, least = kept
    if fix.offset_um < -tune.reaim_tol_um:
        turn = max(reaim_turn_rad(fix, view.length_um, 1e3, r), least)
        if turn > spare:  # no more than the anticlockwise incidence can spare
            turn = spare
            left_um = -fix.offset_um - turn * burst_lever_um(fix.behind_um, view.length_um)
            if left_um > tune.small_miss_um + relax_um and not loop_blocked():
                log("miss", f"would dock {left_um:.0f} um left of its aim keeping its incidence: loops back")
                return None
        if turn > burst_max:  # too far left for a burst: merge, or loop back
            m = merge(fix.behind_um, fix.right_um, fix.psi_rad, r)
            if m is not None:
                return _merge_steps(m, fix, view, k, opts, tx)
            if not loop_blocked():
                log("miss", f"would dock {-fix.offset_um:.0f} um left of its aim ({fix.right_um:.0f} um, "
                            f"{math.degrees(fix.psi_rad):.1f} deg): loops back")
                return None
            # no loop: the whole turn (not a capped burst) is the least it can miss by
            turn = max(burst_max, reaim_turn_rad(fix, view.length_um, tune.blocked_reaim_max_deg))
        burst = [(k, turn / view.turn_rate_rad_s)]
    elif fix.offset_um - walk_um > (tune.final_right_um + relax_um if final else tune.aligned_um):
        m = merge(fix.behind_um, fix.right_um, fix.psi_rad, r)
        if m is not None:
            return _merge_steps(m, fix, view, k, opts, tx)
        off_r, right_r = fix.offset_um - walk_um, fix.right_um - walk_um
        small = off_r <= tune.small_miss_um + relax_um and abs(right_r) <= tune.small_miss_um + relax_um
        blocked = loop_blocked()
        if not small and off_r <= tune.late_miss_um and blocked:
            # a loop from here would meet the structure (a turning robot cannot pivot off it): drive on
            log("late", f"drives on {fix.offset_um:.0f} um off its line: a loop here would meet the structure")
            small = True
        if not (small or (final and blocked)):
            log("miss", f"would dock {fix.offset_um:.0f} um right of its aim ({fix.right_um:.0f} um, "
                        f"{math.degrees(fix.psi_rad):.1f} deg): loops back")
            return None
    left_s = max(fix.behind_um, 0.0) / v
    if final and left_s <= tune.final_frame_s and look_at_um is None:
        return burst + [(k - 1, left_s + opts.push_s)]
    return burst + [(k - 1, frame_s)]


def is_run_in(behind_um: float, v: float, tune: Tuning) -> bool:
    """Whether a robot ``behind_um`` out on its line, driving at ``v`` um/s, is at its run-in: in the final run and
    within one final frame (``Tuning.final_frame_s``) of the face, the approach's last decision."""
    return behind_um <= tune.final_run_um and max(behind_um, 0.0) <= v * tune.final_frame_s


def _frame_s(behind_um: float, v: float, tx: float, tune: Tuning, look_at_um: float | None) -> float:
    """How long (s) a frame ``behind_um`` out on the line drives: ``Tuning.final_frame_s`` in the final run, else up to
    its start (at most t_x); never past the look point."""
    frame_s = tune.final_frame_s if behind_um <= tune.final_run_um else min(tx, (behind_um - tune.final_run_um) / v + 1e-3)
    if look_at_um is not None and behind_um > look_at_um:
        frame_s = min(frame_s, (behind_um - look_at_um) / v + 1e-3)
    return frame_s


def incidence_bounds(view: DockView, keep_share: float) -> tuple[int, float, float]:
    """For a robot aiming at a chosen incidence (``view.slot`` set: its goal is its pose at contact), ``(lead, now,
    keep)``: which front corner is to lead (+1 left: turned clockwise, -1 right: anticlockwise; 0: no chosen incidence,
    or ``keep_share`` 0), its heading now from the slot's (rad, + = clockwise) and the least incidence (rad, >= 0) that
    still makes that corner lead: ``keep_share`` of the chosen one.

    Docking compliance turns a robot flush about the corner that meets the face first. A right-first landing reached
    square, or turned clockwise, leads with its left corner, off the face it was chosen for, and sticks: 7 of the 14
    robots stuck on held-out layouts at twice the literature's noise (seeds 0-3) were right-first landings whose
    clockwise re-aim bursts had eaten the anticlockwise incidence, 4 more left-first ones reached turned the wrong way.

    >>> v = DockView(np.array([0.0, 0.0, math.radians(-1.0)]), 80.0, 200.0, 0.4, np.array([0.0, 0.0, math.radians(-6.0)]),
    ...              250.0, 80.0, slot=np.array([0.0, 0.0, 0.0]))
    >>> lead, now, keep = incidence_bounds(v, 0.5)
    >>> lead, round(math.degrees(now), 6), round(math.degrees(keep), 6)
    (-1, -1.0, 3.0)
    """
    if view.slot is None or keep_share <= 0.0:
        return 0, 0.0, 0.0
    planned = float(angle_difference(view.goal[2], view.slot[2]))
    if abs(planned) < 1e-9:
        return 0, 0.0, 0.0
    return (1 if planned > 0 else -1), float(angle_difference(view.pose[2], view.slot[2])), keep_share * abs(planned)


def _keep_incidence(fix: LineFix, view: DockView, keep_share: float, loop_blocked, log,
                    run_in: bool) -> tuple[LineFix, float, float] | None:
    """A frame's ``fix`` and the largest and the least clockwise burst (rad) that keep the chosen incidence
    (:func:`incidence_bounds`); None: loop back. A left-first robot that would arrive turned too little clockwise gets
    its predicted offset moved left, and a least burst, so that the re-aim burst turns it up to the kept incidence
    (solved on its arc the burst alone may turn it a little less). Before its ``run_in`` (the last frame) the bursts
    still to come count: they give back the lead it is left of its pose at contact, ``offset / (behind + L/2)`` of
    clockwise turn (a burst for the whole bound 200 um out only sent the example's B right of its line, seed
    6598635715548540). A right-first one may spare only what its incidence has beyond it, and loops back (where a loop
    is clear) once it has none."""
    lead, now, keep = incidence_bounds(view, keep_share)
    if lead < 0:
        if now > -keep and not loop_blocked():
            log("miss", f"is turned {math.degrees(now):+.1f} deg from its slot, its aim {math.degrees(-keep):+.1f} deg or "
                        "more: its right front corner would not lead; loops back")
            return None
        return fix, max(-keep - now, 0.0), 0.0
    if lead > 0:
        lever = burst_lever_um(fix.behind_um, view.length_um)
        coming = 0.0 if run_in else max(-contact_offset(*line_coords(view.goal, view.pose), view.length_um), 0.0) / lever
        if now + coming < keep:  # the bursts that give back its lead left of its aim count: they turn it clockwise
            fix = LineFix(fix.behind_um, fix.right_um, fix.psi_rad, min(fix.offset_um, -lever * (keep - now - coming)))
            return fix, math.inf, keep - now - coming
    return fix, math.inf, 0.0


def _merge_steps(m, fix: LineFix, view: DockView, k: int, opts: ControllerOptions, tx: float) -> Steps:
    """Straight, then an interpolated clockwise arc of radius ``R`` onto the line (at most a frame of it)."""
    s1, R = m
    v, r = view.speed_um_s, view.radius_um
    t1, arc_t = s1 / v, R * (-fix.psi_rad) / v
    whole = t1 + arc_t <= 1.6 * tx
    steps = [(k - 1, t1 if whole else min(t1, tx))]
    left = (t1 + arc_t if whole else tx) - steps[0][1]
    if left > 1e-9:
        steps += interpolated_steps(r / R, min(arc_t, left), k, k - 1, opts.switch_period_s)
    return steps


def settle(see: Callable[[], DockView], k: int, opts: ControllerOptions, tx: float) -> Generator[Steps, None, DockOutcome]:
    """Push (P_{k-1}) a t_x at a time until the robot stops, then judge where it stopped (:func:`stopped_verdict`)."""
    tune = opts.tuning
    for _ in range(tune.settle_frames):
        before = see().pose.copy()
        yield [(k - 1, tx)]
        view = see()
        if float(np.hypot(*(view.pose[:2] - before[:2]))) < tune.settle_fraction * view.nominal_speed_um_s * tx:
            return stopped_verdict(view.pose, view.flush_slot, dock_tol_um=opts.dock_tol_um, dock_tol_deg=opts.dock_tol_deg,
                                   flush_um=tune.flush_um, off_slot_um=tune.off_slot_um)
    return DockOutcome.GAVE_UP
