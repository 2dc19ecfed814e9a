"""Docking of single robots (sigma_1, sigma_2 for D_k, k < n-1): the single-robot phase of the closed loop.

Gross motion steers D_k (P_k turns, P_{k-1} straight, lower robots orbiting) into the approach funnel
behind its slot, outside the proximity region C_O: the region from which it can merge onto the slot's
approach line without a loop (to the line's right, pointing left of it). Fine motion
(:func:`stressbots.control.docking.line_approach`) merges with an interpolated clockwise arc, drives
straight in and pushes; docking compliance absorbs the last angle error. Where the line's corridor is
blocked by the structure (a tight gap), the seed's S_2f arc through the docking point is used instead
(:meth:`SingleDocking.fine_dock`). A robot that stalls (failure region H) backs off by turning; one that
misses its line loops back through the funnel.

:class:`SingleDocking` is handed the closed loop (:class:`SingleLoop`: ``drive``, estimates, the event
log, gross motion and obstacle checks) and drives only through it; where it aims and what a robot can
reach from where it is (the approach line, a_i, the arc in) it asks of
:class:`~stressbots.control.slot_approach.SlotApproach`. :func:`way_points` and :func:`before_on_route`
are pure geometry.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, Protocol

import numpy as np

from .. import paths as pathlib
from ..kinematics import move
from ..robots import TWO_PI, angle_difference
from . import docking, landing
from .docking import DockOutcome, DockView
from .gross import SteerOutcome
from .loopview import DockingLoop, Look
from .queries import line_pose, waypoint_region
from .slot_approach import SlotApproach
from .targets import refit_slots

FLUSH_REACH_UM = 10.0
"""um. The bodies a stopped robot's front edge comes this close to, as measured, are the ones it may be flush against
(:meth:`SingleDocking._flush_verdict`): a few times the position error of a still look."""

__all__ = ["SingleDocking", "SingleLoop", "before_on_route", "way_points"]


class SingleLoop(DockingLoop, Protocol):
    """What single-robot docking uses of the closed loop (:class:`~stressbots.control.loop.PlantLoop` and the controller)."""

    events: list[dict]
    nominal_goals: np.ndarray
    """The plan's slots (n, 3), the shape the run is judged against."""
    t: float
    """Simulated time (s) of the latest frame."""

    def look(self, frames: int, prior_frames: float) -> None: ...

    def park_orbits(self, k: int) -> None: ...

    def unblock_orbits(self, k: int, i: int, points: np.ndarray) -> bool: ...

    def escape(self, i: int, turn_k: int, straight_k: int, orbiting: Sequence[int]) -> bool: ...

    def boxed_in(self, i: int, orbiting: Sequence[int]) -> bool: ...

    def free_move(self, i: int, orbiting: Sequence[int]) -> tuple[float, float] | None: ...

    def drive_move(self, i: int, turn_k: int, straight_k: int, move_: tuple[float, float], orbiting: Sequence[int]) -> None: ...


# -- pure geometry ------------------------------------------------------------------------------------

def way_points(goal: np.ndarray, a_pose: np.ndarray, back: float | None, r: float = 0.0, step_um: float = 25.0) -> np.ndarray:
    """Points (P, 2) a docking robot needs free of waiting orbits: its aim ``a_pose``, the approach corridor
    from there to the slot ``goal`` (the line ``back`` um long; the straight chord of the S_2f arc when
    ``back`` is None) and, with a turning radius ``r`` (um), the clockwise loop through the aim (a one-way
    robot arrives on it: an orbit beside the aim left no way in, though the aim itself was clear);
    ``step_um`` apart (um).

    >>> way_points(np.array([0.0, 0.0, 0.0]), np.array([20.0, -200.0, 0.1]), 100.0, step_um=50.0).shape
    (4, 2)
    """
    a = np.asarray(a_pose, float)[:2]
    if back is None:
        g = np.asarray(goal, float)[:2]
        m = max(2, int(np.hypot(*(a - g)) / step_um) + 1)
        pts = g + np.linspace(0.0, 1.0, m)[:, None] * (a - g)
    else:
        line = np.stack([line_pose(goal, float(b), 0.0, 0.0)[:2] for b in np.linspace(0.0, back, max(2, int(back / step_um) + 1))])
        pts = np.vstack([line, a[None, :]])
    if r > 0.0:
        s = np.linspace(0.0, TWO_PI * r, max(8, int(TWO_PI * r / step_um) + 1))
        pts = np.vstack([pts, move(np.asarray(a_pose, float), s, 1.0 / r)[:, :2]])
    return pts


def before_on_route(w, a_pose, route_phase, r: float) -> bool:
    """Whether waypoint ``w`` comes before ``a_pose`` along the nominal route of ``route_phase`` (nearest
    samples 5 um apart; True without a route). ``r``: the robot's nominal turn radius (um)."""
    if route_phase is None or not route_phase.path:
        return True
    path = pathlib.Path(route_phase.path_start, r, route_phase.path)
    s = path.sample(5.0)
    kw = int(np.argmin(np.hypot(*(s[:, :2] - np.asarray(w)[:2]).T)))
    ka = int(np.argmin(np.hypot(*(s[:, :2] - np.asarray(a_pose)[:2]).T)))
    return kw < ka


# -- the phase ----------------------------------------------------------------------------------------

class SingleDocking:
    """Docking of the single robots D_k (k < n-1) for a closed loop ``loop``, one robot at a time."""

    def __init__(self, loop: SingleLoop):
        self.loop = loop
        self.approach = SlotApproach(loop)
        """Where robot ``i`` aims and what it can reach from where it is (queries of the loop's estimates)."""
        self.flush_slots: dict[int, np.ndarray] = {}
        """Robots aiming at a chosen incidence (:meth:`land`): the slot docking compliance leaves them in, their goal
        once docked."""

    def dock(self, k: int, route_phase) -> None:
        """Dock D_k (k < n-1): gross motion into the approach funnel behind its slot, then the line approach.

        The approach line runs back from the slot along its heading. The funnel is the region from which a
        one-way robot can merge onto that line without a loop: to the line's right, pointing left of it
        (or on it), far enough behind the slot. The gross motion aims at a pose inside it
        (``Tuning.funnel_aim_right_um`` right, ``Tuning.funnel_aim_left_deg`` left: the errors of the last leg then keep
        it inside) and stops as soon as the measured pose
        is in it; the fine motion (:meth:`line_approach`) merges and drives straight in. Where the line's
        corridor is blocked (a tight gap) the S_2f arc of the nominal plan is used instead.
        """
        lp = self.loop
        i = lp.by_rank[k]
        self.land(i)
        lp.park_orbits(k)
        orbiting = lp.orbiting_below(k)
        if lp.motion is not None and (abs(lp.motion[0]) > math.radians(5.0) or np.hypot(*(lp.motion[2] - lp.motion[1])) > 60.0):
            route_phase = None  # the pair formed in a re-planned frame: the nominal route no longer applies
        waypoints = [np.array(w) for w in (route_phase.waypoints if route_phase is not None else ())]
        misses = 0
        missed_at = -1.0  # time (s) of the last missed line approach
        for attempt in range(lp.tune.dock_attempts):
            goal, back, a_pose, ready = self.approach.aim(i, attempt, route_phase, orbiting)
            lp.unblock_orbits(k, i, way_points(goal, a_pose, back, float(lp.r_hat[i])))
            targets = [w for w in waypoints[:-1] if before_on_route(w, a_pose, route_phase, lp.r[i])] + [a_pose]
            # missed in place inside the funnel: the funnel test (16:0) or arriving in the aim's region (13:3, 2x) would end
            # the gross motion at once for the same miss, so it ends where the line approach takes the robot (accepts)
            t_attempt, in_place = lp.t, ready is not None and lp.t == missed_at and ready()
            stuck = self._steer_through(i, k, orbiting, targets, partial(self.accepts, i, k, misses) if in_place else ready,
                                        partial(self.approach.cut_in, i, k, back),
                                        self.approach.aim_region(i, goal, back, a_pose))
            waypoints = []
            # the corridor shortcut only from somewhere new: from where a line approach just missed (a blocked loop back
            # left the robot there) it would miss again, and six attempts ran out at the same instant
            if back is not None and not self.approach.in_funnel(i, back) and self.approach.in_corridor(i, back) and lp.t > missed_at:
                b, r, psi = self.approach.line_coords(i)
                lp.log("corridor", i, f"attempt {attempt + 1}: {lp.scn.names[i]} is in its approach corridor ({b:.0f} um behind, "
                                      f"{r:.0f} um right, {math.degrees(psi):.1f} deg): the line approach takes it from here")
            elif stuck and self.near_slot(i) and self.check_docked(i, k):
                return  # it stopped at its own slot (a blocked gross motion drove it in): docking compliance docked it
            elif stuck:
                self._clear_the_way(i, k, goal, a_pose, back)
                continue
            elif back is not None and not self.approach.in_funnel(i, back):
                lp.log("retry", i, f"attempt {attempt + 1}: the gross motion ended outside the approach funnel; steering again")
                if lp.t == t_attempt:  # it did not move (at its aim already): nor would the same attempt again
                    self.back_off(i, k)
                continue
            if back is not None:
                outcome = self.line_approach(i, k, misses)
            else:
                outcome = DockOutcome.DOCKED if self.fine_dock(i, k) else DockOutcome.STUCK
            if outcome in (DockOutcome.DOCKED, DockOutcome.DOCKED_OFF_SLOT):
                return
            if outcome is DockOutcome.MISSED:
                # no contact: the gross motion (obstacle-checked) loops back into the funnel
                misses += 1
                missed_at = lp.t
                lp.log("retry", i, f"attempt {attempt + 1} missed the approach line; looping back")
                continue
            lp.log("retry", i, f"attempt {attempt + 1} did not dock; backing off")
            self.back_off(i, k)
        raise lp.abort(f"{lp.scn.names[i]} did not dock in {lp.tune.dock_attempts} attempts (last: "
                       f"{lp.events[-1]['detail'] if lp.events else ''})")

    def _steer_through(self, i: int, k: int, orbiting: Sequence[int], targets, ready: Callable[[], bool] | None,
                       cut_in: Callable[[], tuple[str, str] | None], aim_region: np.ndarray | None = None) -> bool:
        """Gross motion sigma_1 of robot ``i`` (D_k) to each of ``targets`` in turn (waypoints of the nominal route, then
        its aim); whether one ended stuck (failure region H: the rest are skipped, the caller's recovery takes over).

        Each waypoint is reached when the robot arrives in its region
        (:func:`~stressbots.control.queries.waypoint_region`, also the goals its path may head for); the aim's goals are
        ``aim_region`` (None: the aim itself). ``cut_in`` ends a leg whose path is blocked where the fine motion can
        start (:meth:`~stressbots.control.slot_approach.SlotApproach.cut_in`).

        A waypoint whose path is blocked is dropped (``Tuning.skip_blocked_waypoints``): the nominal route was planned
        around the nominal orbits and structure, and routing to its waypoint around the measured ones led a robot down
        a 300 um corridor between two drifted orbits and the arena edge, where it was boxed in; the aim (or the
        next waypoint) is routed from where the robot is instead."""
        lp = self.loop

        def skip_or_cut_in(tgt: np.ndarray) -> tuple[str, str] | None:
            return cut_in() or ("skip", f"{lp.scn.names[i]}'s way to its nominal route's waypoint ({tgt[0]:.0f}, {tgt[1]:.0f}) um "
                                        "is blocked: it heads for its next target")

        last = len(targets) - 1
        return any(lp.steer(i, tgt, k, k - 1, orbiting, ready=ready,
                            ready_if_blocked=partial(skip_or_cut_in, tgt) if n < last and lp.tune.skip_blocked_waypoints else cut_in,
                            waypoint=n < last, region=waypoint_region(tgt, lp.tune) if n < last else aim_region)
                   is SteerOutcome.STUCK for n, tgt in enumerate(targets))

    def _clear_the_way(self, i: int, k: int, goal: np.ndarray, a_pose: np.ndarray, back: float | None) -> None:
        """Recovery of robot ``i`` (D_k) whose gross motion toward ``a_pose`` stopped it in failure region H: waiting
        orbits over its way to the slot ``goal`` are moved off it, else (none moved) it backs off (:meth:`back_off`)."""
        lp = self.loop
        # a waiting orbit in the way (over the path, or the robot pinned against it) is moved off it;
        # retrying the same way unchanged met the same orbit every time
        path = pathlib.shortest_path(lp.est[i], a_pose, lp.r_hat[i])
        if not lp.unblock_orbits(k, i, np.vstack([lp.est[i][None, :2], path.sample(20.0)[:, :2],
                                                  way_points(goal, a_pose, back, float(lp.r_hat[i]))])):
            self.back_off(i, k)

    def land(self, i: int) -> None:
        """Aim robot ``i`` where docking compliance takes it (:func:`~stressbots.control.landing.landing_pose`, docked
        bodies as measured): its slot, moved along the face, or reached at a chosen incidence; log the change."""
        lp = self.loop
        est = lp.est
        n_, m_ = lp.by_rank[len(lp.by_rank)], lp.by_rank[len(lp.by_rank) - 1]  # the G_1 pair, D_n and D_(n-1)
        if lp.docked[n_] and lp.docked[m_]:
            est = est.copy()
            est[[n_, m_]] = landing.aligned_pair(est[n_], est[m_], float(lp.L[n_]), float(lp.L[m_]))
        docked = np.flatnonzero(lp.docked)
        land = landing.landing_pose(lp.goals[i], float(lp.L[i]), float(lp.W[i]), (est[docked], lp.L[docked], lp.W[docked]),
                                    lp.tune, landing.noise_scale(lp.scn.noise))
        if land.note:
            lp.goals[i] = land.aim
            if not np.array_equal(land.aim, land.slot):
                self.flush_slots[i] = land.slot
            lp.log("landing", i, f"{lp.scn.names[i]}'s slot {land.note} (docking compliance needs a front corner on a face)")

    # -- fine motion ----------------------------------------------------------------------------------

    def dock_view(self, i: int) -> DockView:
        """A frozen view of robot ``i`` for the docking policy (estimates as of the last frame)."""
        lp = self.loop
        return DockView(lp.est[i].copy(), float(lp.v_hat[i]), float(lp.r_hat[i]), float(lp.omega_hat[i]),
                        lp.goals[i].copy(), float(lp.L[i]), float(lp.v[i]), float(lp.straight_drift.kappa[i]),
                        float(lp.straight_drift.walk_var_per_um), self.flush_slots.get(i))

    def play(self, policy) -> Any:
        """Apply the steps a policy yields, frame by frame; return its outcome (the loop is the only plant I/O)."""
        try:
            steps = next(policy)
            while True:
                if isinstance(steps, Look):
                    self.loop.look(steps.frames, steps.prior_frames)
                else:
                    self.loop.drive(steps)
                steps = policy.send(None)
        except StopIteration as stop:
            return stop.value

    def line_approach(self, i: int, k: int, attempt: int = 0) -> DockOutcome:
        """Fine motion along the approach line (:func:`stressbots.control.docking.line_approach`)."""
        lp = self.loop
        outcome = self.play(docking.line_approach(lambda: self.dock_view(i), k, lp.opts, lp.tx, loop_blocked=self._loop_blocked(i, k),
                                                  log=lambda kind, detail: lp.log(kind, i, f"{lp.scn.names[i]} {detail}"),
                                                  attempt=attempt))
        return self.dock_verdict(i, outcome)

    def _loop_blocked(self, i: int, k: int) -> Callable[[], bool]:
        """Whether a loop back of robot ``i`` (D_k) from where it is would meet the structure, a lower orbit or the edge."""
        return lambda: self.approach.loop_blocked(i, k, self.loop.tune.loop_back_clearance_um)

    def accepts(self, i: int, k: int, attempt: int = 0) -> bool:
        """Whether the line approach of robot ``i`` (D_k) takes it from where it is (its first frame would not loop it
        back: :func:`~stressbots.control.docking.loops_back`)."""
        lp = self.loop
        return not docking.loops_back(self.dock_view(i), k, lp.opts, lp.tx, loop_blocked=self._loop_blocked(i, k), attempt=attempt)

    def dock_verdict(self, i: int, outcome: DockOutcome) -> DockOutcome:
        """Record a docking outcome: docked robots join the structure; the others are logged."""
        lp = self.loop
        if outcome in (DockOutcome.DOCKED, DockOutcome.DOCKED_OFF_SLOT):
            outcome = self._flush_verdict(i, outcome)
        pose, goal = lp.est[i], lp.goals[i]
        dpos = float(np.hypot(*(pose[:2] - goal[:2])))
        dth = math.degrees(abs(angle_difference(pose[2], goal[2])))
        if outcome in (DockOutcome.DOCKED, DockOutcome.DOCKED_OFF_SLOT):
            lp.docked[i] = True
            if i in self.flush_slots:  # it was aiming at its pose at contact; the slot is where compliance leaves it
                lp.goals[i] = self.flush_slots.pop(i)
                dpos = float(np.hypot(*(pose[:2] - lp.goals[i, :2])))
                dth = math.degrees(abs(angle_difference(pose[2], lp.goals[i, 2])))
            off = "" if outcome is DockOutcome.DOCKED else " (off its slot, flush against the structure: it cannot leave)"
            lp.log("docked", i, f"{dpos:.1f} um, {dth:.1f} deg from the slot{off}")
            self.refit()
        elif outcome is DockOutcome.STUCK:
            lp.log("stuck", i, f"stopped {dpos:.0f} um / {dth:.0f} deg from the slot (failure region H)")
        return outcome

    def _flush_verdict(self, i: int, outcome: DockOutcome) -> DockOutcome:
        """``outcome`` (docked), or STUCK when robot ``i``, stopped at its slot, is not flush against the body it touches.

        A still look (``Tuning.flush_look_frames``) sharpens its heading; turned from that body's edges by more than the
        look's heading error allows (``Tuning.flush_tol_deg``, ``Tuning.flush_tol_sigmas``), it stopped on a corner of
        the structure (failure region H) and is not counted docked (nor docked against by the robots after it). The
        caller's recovery backs it off; a one-way robot pushing against a corner can rarely leave it, so mostly the run
        ends honestly stuck instead of claiming a structure the plant does not hold."""
        lp, tune = self.loop, self.loop.tune
        if tune.flush_look_frames <= 0:
            return outcome
        lp.look(tune.flush_look_frames, tune.look_prior_frames)
        others = np.flatnonzero(lp.docked)
        others = others[others != i]
        found = landing.contact_misalignment(lp.est[i], float(lp.L[i]), float(lp.W[i]), (lp.est[others], lp.L[others], lp.W[others]),
                                             FLUSH_REACH_UM)
        if found is None:
            return outcome
        sd = float(lp.scn.noise.camera_heading_sd_rad) / math.sqrt(tune.flush_look_frames + tune.look_prior_frames)
        tol = math.radians(tune.flush_tol_deg) + tune.flush_tol_sigmas * sd
        mis, j = found
        if abs(mis) <= tol:
            return outcome
        lp.log("not-flush", i, f"{lp.scn.names[i]} stopped turned {math.degrees(mis):+.1f} deg from {lp.scn.names[others[j]]}'s edge "
                               f"(at most {math.degrees(tol):.1f} deg is flush): it met a corner of the structure (failure region H)")
        return DockOutcome.STUCK

    def refit(self) -> None:
        """Move the slots of the robots yet to dock, and the nominal route's frame, with the structure as docked
        (:func:`~stressbots.control.targets.refit_slots`): the judge aligns the whole structure, not G_1 alone."""
        lp = self.loop
        rest = ~lp.docked
        fit = refit_slots(lp.nominal_goals, lp.est, lp.docked, lp.L, lp.W) if rest.any() else None
        if fit is None:
            return
        moved = np.hypot(*(fit[0][rest, :2] - lp.goals[rest, :2]).T)
        lp.goals[rest] = fit[0][rest]
        lp.motion = fit[1]
        if float(moved.max()) > 5.0:
            lp.log("refit", None, f"the slots still to fill follow the structure as docked: moved up to {moved.max():.1f} um "
                                  f"({math.degrees(fit[1][0]):.1f} deg from nominal)")

    def fine_dock(self, i: int, k: int) -> bool:
        """Fine motion (S_2f) into the slot, then push; True when docked."""
        lp = self.loop
        for _ in range(60):
            v = lp.v_hat[i]
            if self.near_slot(i):
                # already at the structure (e.g. it met it while turning): push, and let compliance act
                lp.drive([(k - 1, lp.opts.push_s)])
                return self.check_docked(i, k)
            arc_in = self.approach.slot_arc(i)
            if arc_in is None:
                return False  # not reachable on one interpolated arc: gross motion again
            rho, length, _ = arc_in
            t_arc = length / v
            if t_arc <= lp.tx:
                lp.drive(lp.interpolated_steps(rho, t_arc, k, k - 1) + [(k - 1, lp.opts.push_s)])
                return self.check_docked(i, k)
            lp.drive(lp.interpolated_steps(rho, lp.tx, k, k - 1))
        return False

    def near_slot(self, i: int) -> bool:
        """Whether robot ``i`` (measured) is at its slot within the docking tolerances."""
        lp = self.loop
        goal = self.flush_slots.get(i, lp.goals[i])
        return bool(
            np.hypot(*(lp.est[i, :2] - goal[:2])) <= lp.opts.dock_tol_um
            and abs(angle_difference(lp.est[i, 2], goal[2])) <= math.radians(lp.opts.dock_tol_deg)
        )

    def check_docked(self, i: int, k: int) -> bool:
        """Push until the robot stops; docked if it stopped at its slot (or flush off it), stuck (H) if elsewhere."""
        outcome = self.dock_verdict(i, self.play(docking.settle(lambda: self.dock_view(i), k, self.loop.opts, self.loop.tx)))
        return outcome in (DockOutcome.DOCKED, DockOutcome.DOCKED_OFF_SLOT)

    def back_off(self, i: int, k: int) -> None:
        """Recovery from H: a robot cannot reverse, so it turns away (arm down) and drives clear.

        The way off is checked (:meth:`stressbots.control.escapes.Escapes.escape`: the cheapest turn-then-straight
        that goes no deeper and ends clear, and keeps a robot that can move on where it can). With none, a robot
        that can still move on from where it is takes the cheapest such move (a turn, then one body length; the
        next attempt plans from there: staying put, every later attempt failed at the same instant); only one
        already boxed in backs off blindly, a quarter turn and 150 um: driven blindly, robots that had stopped
        short of an obstacle turned into it and were pinned for good.
        """
        lp = self.loop
        orbiting = lp.orbiting_below(k)
        if lp.escape(i, k, k - 1, orbiting):
            return
        m = lp.free_move(i, orbiting)
        if m is not None:
            lp.log("move-on", i, f"{lp.scn.names[i]} finds no clear way off; turns {m[0]:.1f} s, then {m[1]:.1f} s straight where it "
                                 "can still move on")
            lp.drive_move(i, k, k - 1, m, orbiting)
            return
        lp.drive([(k, 0.5 * math.pi * lp.r[i] / lp.v[i]), (k - 1, 150.0 / lp.v[i])])
