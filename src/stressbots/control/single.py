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
log, gross motion and obstacle checks) and drives only through it; :func:`fine_start`,
:func:`approach_start_on_route`, :func:`approach_length`, :func:`retarget` and :func:`before_on_route`
are pure geometry.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from functools import partial
from typing import Any, Protocol

import numpy as np

from .. import paths as pathlib
from ..collision import arena_gap, outside_arena, penetration_depth
from ..kinematics import move
from ..robots import TWO_PI, angle_difference
from . import docking
from .docking import DockOutcome, DockView
from .gross import SteerOutcome
from .loopview import DockingLoop
from .queries import fine_motion_length, in_corridor, in_funnel, line_coords, line_pose, merge, turn_fraction

__all__ = ["SingleDocking", "SingleLoop", "approach_length", "approach_start_on_route", "before_on_route", "fine_start", "retarget",
           "way_points"]


Bodies = tuple[np.ndarray, np.ndarray, np.ndarray]
"""Docked bodies as ``(poses (m, 3), lengths (m,), widths (m,))`` (um, rad)."""


class SingleLoop(DockingLoop, Protocol):
    """What single-robot docking uses of the closed loop (:class:`~stressbots.control.loop.PlantLoop` and the controller)."""

    events: list[dict]
    straight_drift: Any
    t: float
    """Simulated time (s) of the latest frame."""

    def park_orbits(self, k: int) -> None: ...

    def unblock_orbits(self, k: int, i: int, points: np.ndarray) -> bool: ...

    def escape(self, i: int, turn_k: int, straight_k: int, orbiting: Sequence[int]) -> bool: ...

    def boxed_in(self, i: int, orbiting: Sequence[int]) -> bool: ...

    def free_move(self, i: int, orbiting: Sequence[int]) -> tuple[float, float] | None: ...

    def drive_move(self, i: int, turn_k: int, straight_k: int, move_: tuple[float, float], orbiting: Sequence[int]) -> None: ...


# -- pure geometry ------------------------------------------------------------------------------------

def fine_start(goal: np.ndarray, r: float, length: float, width: float, fine_distance_um: float, bodies: Bodies,
               arena_um: tuple[float, float] | None, *, straight_if_none: bool = True) -> np.ndarray | None:
    """The intermediate pose a_i: back along a clockwise arc that ends exactly in the slot ``goal``.

    Only positions to a robot's right are reachable by one clockwise arc (seed Fig. 4), so a_i lies
    on a nominal arc of radius ``s_f / phi`` (arrival heading = the slot's): measured errors either
    way are then absorbed by a larger or smaller r'. ``s_f = min(2.5 r, 3 fine_distance_um)`` (um);
    ``phi`` is the largest of 25, 15, 8, 4 deg whose swept bodies (``length`` x ``width`` um) clear the
    docked ``bodies`` by 0.5 um and stay inside the arena (tight gaps need an almost straight entry);
    when none does, a_i is ``s_f`` straight behind the slot (None without ``straight_if_none``: that pose may lie
    outside the arena).
    """
    s_f = fine_motion_length(r, fine_distance_um)
    for phi_deg in (25.0, 15.0, 8.0, 4.0):
        R = s_f / math.radians(phi_deg)
        back = move(goal, -np.linspace(0.0, s_f, 40), 1.0 / R)  # poses along the arc, slot first
        ok = True
        for pj, lj, wj in zip(*bodies, strict=True):
            depth = penetration_depth(back[1:], length, width, pj, lj, wj)
            if (depth > 0.5).any():
                ok = False
                break
        if ok and not (arena_um is not None and (outside_arena(back, length, width, arena_um) > 0).any()):
            return back[-1]
    return straight_behind(goal, r, fine_distance_um) if straight_if_none else None


def straight_behind(goal: np.ndarray, r: float, fine_distance_um: float) -> np.ndarray:
    """The pose ``s_f`` um (:func:`~stressbots.control.queries.fine_motion_length`) straight behind the slot ``goal``:
    :func:`fine_start`'s a_i when no S_2f arc fits.

    >>> straight_behind(np.array([500.0, 500.0, 0.0]), 100.0, 200.0).tolist()   # heading +y: s_f = 250 um back
    [500.0, 250.0, 0.0]
    """
    s_f = fine_motion_length(r, fine_distance_um)
    h = np.array([math.sin(goal[2]), math.cos(goal[2])])
    return np.array([goal[0] - s_f * h[0], goal[1] - s_f * h[1], goal[2]])


def approach_start_on_route(ph, r: float, fine_distance_um: float) -> np.ndarray | None:
    """The intermediate pose a_i on the nominal route phase ``ph``: where its final approach arc begins.

    The planner ends every route with an interpolated clockwise arc into the slot, so from a_i the slot
    lies ahead and to the right, within reach of one arc of adjustable radius r', and the gross motion
    to a_i follows the nominal route instead of looping to a pose off it. ``s_f`` (um) back from the end
    is the route's own approach length, else ``min(fine_distance_um, 0.8 length)``. None when the phase
    has no path (``r``: the robot's nominal turn radius, um).
    """
    if not ph.path or ph.path_start is None:
        return None
    path = pathlib.Path(ph.path_start, r, ph.path)
    s_f = ph.approach_um if ph.approach_um > 0 else min(fine_distance_um, 0.8 * path.length)
    return np.asarray(path.pose_at(path.length - s_f), dtype=np.float64)


def approach_length(goal: np.ndarray, length: float, width: float, lengths_um: Sequence[float], bodies: Bodies,
                    arena_um: tuple[float, float] | None, lead_in_um: float = 0.0, r: float = 0.0, wall_um: float = 0.0,
                    *, unreachable_ok: bool = True) -> float | None:
    """How far behind the slot ``goal`` its approach line is clear, or None.

    The first of ``lengths_um`` (longest first, e.g. 450 down to 150 um) for which a ``length`` x
    ``width`` body along the line, and along a line fanning out to 60 um right at its far end, keeps
    over 3 um from every docked body and stays in the arena: the corridor the funnel merge and the
    straight run need. With ``lead_in_um`` (and the robot's turn radius ``r``, um) the longest corridor
    whose funnel a one-way robot can reach (:func:`lead_in_clear`) is preferred: it enters the funnel
    from behind, so a corridor that ends at the arena edge has a funnel no path reaches. When no clear
    corridor is reachable so, the longest clear one (as without ``lead_in_um``), or None without
    ``unreachable_ok``: the robot then arcs into its slot from a_i (:func:`fine_start`, or the nominal route's).
    """
    first = None
    for back in lengths_um:
        ok = True
        for right in (0.0, 60.0):
            line = np.stack([line_pose(goal, b, right * b / back, 0.0) for b in np.linspace(8.0, back, 24)])
            for pj, lj, wj in zip(*bodies, strict=True):
                if (penetration_depth(line, length, width, pj, lj, wj) > -3.0).any():
                    ok = False
            if arena_um is not None and (outside_arena(line, length, width, arena_um) > 0).any():
                ok = False
        if ok:
            first = back if first is None else first
            if lead_in_clear(goal, back, lead_in_um, r, length, width, bodies, arena_um, wall_um):
                return back
    return first if unreachable_ok or lead_in_um <= 0.0 else None


def lead_in_clear(goal: np.ndarray, back: float, lead_in_um: float, r: float, length: float, width: float, bodies: Bodies,
                  arena_um: tuple[float, float] | None, wall_um: float) -> bool:
    """Whether a one-way robot can get onto the approach line of slot ``goal`` at ``back`` um behind it.

    True when some pose on the line between ``back`` and ``back + lead_in_um`` behind the slot (um) is
    joined to ``back`` by a clear stretch of line and has a clear clockwise loop (radius ``r``): a robot
    reaches such a loop tangentially from the open arena and leaves it onto the line. Clear means a
    ``length`` x ``width`` body keeps over 3 um from the docked ``bodies`` and over ``wall_um`` from the
    arena edge. A funnel backed against the arena edge fails this (every way onto it comes from outside).
    True when ``lead_in_um`` is 0.
    """
    if lead_in_um <= 0.0:
        return True

    def clear(poses: np.ndarray) -> bool:
        for pj, lj, wj in zip(*bodies, strict=True):
            if (penetration_depth(poses, length, width, pj, lj, wj) > -3.0).any():
                return False
        return not (arena_um is not None and (arena_gap(poses, length, width, arena_um) < wall_um).any())

    arc = np.linspace(0.0, TWO_PI * r, 72)
    for b in np.linspace(back, back + lead_in_um, 5):
        pose = line_pose(goal, float(b), 0.0, 0.0)
        if not clear(move(pose, arc, 1.0 / r)):
            continue
        if b == back or clear(np.stack([line_pose(goal, float(q), 0.0, 0.0) for q in np.linspace(back, b, 12)])):
            return True
    return False


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


def retarget(pose: np.ndarray, motion: tuple[float, np.ndarray, np.ndarray] | None) -> np.ndarray:
    """A nominal pose moved by the rigid ``motion`` ``(phi_rad, c_nom, c_meas)`` the structure took when G_1
    formed (rotation by ``phi`` about ``c_nom``, then ``c_nom`` to ``c_meas``, um); unchanged when None."""
    if motion is None:
        return np.asarray(pose, float)
    phi, c_nom, c_meas = motion
    d = np.asarray(pose[:2]) - c_nom
    cph, sph = math.cos(phi), math.sin(phi)
    rot = np.array([d[0] * cph + d[1] * sph, -d[0] * sph + d[1] * cph])
    return np.array([c_meas[0] + rot[0], c_meas[1] + rot[1], float(np.mod(pose[2] + phi, TWO_PI))])


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

    def _bodies(self) -> Bodies:
        lp = self.loop
        docked = np.flatnonzero(lp.docked)
        return lp.est[docked], lp.L[docked], lp.W[docked]

    def dock(self, k: int, route_phase) -> None:
        """Dock D_k (k < n-1): gross motion into the approach funnel behind its slot, then the line approach.

        The approach line runs back from the slot along its heading. The funnel is the region from which a
        one-way robot can merge onto that line without a loop: to the line's right, pointing left of it
        (or on it), far enough behind the slot. The gross motion aims at a pose inside it (20 um right,
        6 deg left: the errors of the last leg then keep it inside) and stops as soon as the measured pose
        is in it; the fine motion (:meth:`line_approach`) merges and drives straight in. Where the line's
        corridor is blocked (a tight gap) the S_2f arc of the nominal plan is used instead.
        """
        lp = self.loop
        i = lp.by_rank[k]
        lp.park_orbits(k)
        orbiting = lp.orbiting_below(k)
        if lp.motion is not None and (abs(lp.motion[0]) > math.radians(5.0) or np.hypot(*(lp.motion[2] - lp.motion[1])) > 60.0):
            route_phase = None  # the pair formed in a re-planned frame: the nominal route no longer applies
        waypoints = [np.array(w) for w in (route_phase.waypoints if route_phase is not None else ())]
        misses = 0
        missed_at = -1.0  # time (s) of the last missed line approach
        for attempt in range(lp.tune.dock_attempts):
            goal, back, a_pose, ready = self._aim(i, attempt, route_phase, orbiting)
            lp.unblock_orbits(k, i, way_points(goal, a_pose, back, float(lp.r_hat[i])))
            targets = [w for w in waypoints[:-1] if before_on_route(w, a_pose, route_phase, lp.r[i])] + [a_pose]
            # missed in place (predicted) inside the funnel: the funnel test would end the gross motion at once for the
            # same miss (held-out 16:0 at 2x), so it drives to the aim itself (a loop back)
            t_attempt, in_place = lp.t, ready is not None and lp.t == missed_at and ready()
            stuck = self._steer_through(i, k, orbiting, targets, None if in_place else ready, partial(self.cut_in, i, k, back))
            waypoints = []
            # the corridor shortcut only from somewhere new: from where a line approach just missed (a blocked loop back
            # left the robot there) it would miss again, and six attempts ran out at the same instant
            if back is not None and not self.in_funnel(i, back) and self.in_corridor(i, back) and lp.t > missed_at:
                b, r, psi = self.line_coords(i)
                lp.log("corridor", i, f"attempt {attempt + 1}: {lp.scn.names[i]} is in its approach corridor ({b:.0f} um behind, "
                                      f"{r:.0f} um right, {math.degrees(psi):.1f} deg): the line approach takes it from here")
            elif stuck and self.near_slot(i) and self.check_docked(i, k):
                return  # it stopped at its own slot (a blocked gross motion drove it in): docking compliance docked it
            elif stuck:
                self._clear_the_way(i, k, goal, a_pose, back)
                continue
            elif back is not None and not self.in_funnel(i, back):
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

    def _aim(self, i: int, attempt: int, route_phase,
             orbiting: Sequence[int]) -> tuple[np.ndarray, float | None, np.ndarray, Callable[[], bool] | None]:
        """``(goal, back, a_pose, ready)`` of docking attempt ``attempt`` (from 0) of robot ``i`` (``orbiting``: the robots
        waiting on their orbits): its slot (um, um, rad),
        the approach line's length behind it (um; None: the line's corridor is blocked, the fine motion takes the S_2f
        arc from the intermediate pose a_i), the pose its gross motion sigma_1 aims at, and the test that ends that
        gross motion early (in the approach funnel; None: at a_i)."""
        lp = self.loop
        goal = lp.goals[i]
        back = self.approach_length(i)
        if back is None:
            # both in the measured frame (the slots follow G_1: PairPhase.retarget); only the nominal route's a_i is moved
            first = route_phase is not None and attempt == 0
            a_pose = self.fine_start_on(route_phase, i) if first else self.fine_start(i, goal, route_phase)
            ready = None
        else:
            a_pose = self._aim_behind(i, goal, back, orbiting)
            ready = lambda back=back: self.in_funnel(i, back)  # noqa: E731
        return goal, back, a_pose, ready

    def _aim_behind(self, i: int, goal: np.ndarray, back: float, orbiting: Sequence[int]) -> np.ndarray:
        """The pose robot ``i``'s gross motion aims at in the approach funnel of slot ``goal`` (corridor ``back`` um): 20 um
        right of the line, pointing 6 deg left of it (the errors of the last leg then keep it in the funnel), at the
        corridor's end, or half or all of ``Tuning.aim_behind_extra_um`` further back: the nearest from which a clockwise
        loop keeps clear of the ``orbiting`` robots, the structure and the arena edge (the corridor's end when none does).

        A one-way robot that arrives off its aim (30 um too far right, say) gets back to it only by a loop. Aimed at the
        corridor's end, that loop met the structure ahead, the roadmap sent the robot on a tour round the structure,
        and every tour ended the same way (1400 s for one robot). Only as far back as the loop needs: every um further
        is a longer straight approach, and aimed 150 um back throughout, marginal shape errors and missed approaches
        cost as many trials as the loops saved."""
        lp = self.loop
        extra, r = lp.tune.aim_behind_extra_um, float(lp.r_hat[i])
        poses = [line_pose(goal, b, 20.0, -math.radians(6.0)) for b in (back, back + 0.5 * extra, back + extra)]
        s = np.linspace(0.0, TWO_PI * r, int(TWO_PI * r / 10.0) + 2)  # a loop sampled every 10 um
        # each loop checked as the gross motion checks its way to the aim
        return next((p for p in poses if not lp.obstacles_hit(move(p, s, 1.0 / r), i, orbiting, target=p)), poses[0])

    def _steer_through(self, i: int, k: int, orbiting: Sequence[int], targets, ready: Callable[[], bool] | None,
                       cut_in: Callable[[], tuple[str, str] | None]) -> bool:
        """Gross motion sigma_1 of robot ``i`` (D_k) to each of ``targets`` in turn (waypoints of the nominal route, then
        its aim; ``cut_in`` ends one whose path is blocked where the fine motion can start, :meth:`cut_in`); whether one
        ended stuck (failure region H: the rest are skipped, the caller's recovery takes over).

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
                            ready_if_blocked=partial(skip_or_cut_in, tgt) if n < last and lp.tune.skip_blocked_waypoints else cut_in)
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

    # -- where to aim ---------------------------------------------------------------------------------

    def fine_start(self, i: int, goal: np.ndarray, route_phase=None) -> np.ndarray:
        """The intermediate pose a_i of robot ``i`` for slot ``goal`` (:func:`fine_start`, docked bodies as measured).
        Where no S_2f arc into the slot fits and the nominal route ``route_phase`` is given, its a_i (the planner's own
        final arc) rather than the pose straight behind the slot: by the arena edge that pose lay outside the arena, and
        every later attempt aimed there (tuning 118:0 at 1x)."""
        lp = self.loop
        pose = fine_start(goal, lp.r[i], lp.L[i], lp.W[i], lp.opts.fine_distance_um, self._bodies(), lp.scn.arena_um,
                          straight_if_none=False)
        if pose is None and route_phase is not None:
            pose = self._route_start(route_phase, i)
        return pose if pose is not None else straight_behind(goal, lp.r[i], lp.opts.fine_distance_um)

    def fine_start_on(self, ph, i: int) -> np.ndarray:
        """a_i on the nominal route phase ``ph`` (:meth:`_route_start`), else :meth:`fine_start`."""
        pose = self._route_start(ph, i)
        return self.fine_start(i, self.loop.goals[i]) if pose is None else pose

    def _route_start(self, ph, i: int) -> np.ndarray | None:
        """a_i on the nominal route phase ``ph`` (:func:`approach_start_on_route`) moved with the structure
        (:func:`retarget`: the route is nominal, the slots follow G_1); None when the route has no final arc."""
        lp = self.loop
        pose = approach_start_on_route(ph, lp.r[i], lp.opts.fine_distance_um)
        return None if pose is None else retarget(pose, lp.motion)

    def approach_length(self, i: int) -> float | None:
        """How far behind robot ``i``'s slot the approach line is clear of the structure (:func:`approach_length`)."""
        lp = self.loop
        return approach_length(lp.goals[i], lp.L[i], lp.W[i], lp.tune.approach_lengths_um, self._bodies(), lp.scn.arena_um,
                               lp.tune.approach_lead_in_radii * float(lp.r_hat[i]), float(lp.r_hat[i]), lp.opts.clearance_um,
                               unreachable_ok=not lp.tune.arc_when_line_unreachable)

    def line_coords(self, i: int) -> tuple[float, float, float]:
        """``(behind_um, right_um, psi_rad)`` of robot ``i`` relative to its slot's approach line."""
        return line_coords(self.loop.goals[i], self.loop.est[i])

    def in_corridor(self, i: int, back: float) -> bool:
        """Whether robot ``i`` is already in its approach corridor, heading along it (:func:`~stressbots.control.queries.in_corridor`)."""
        return in_corridor(*self.line_coords(i), back, self.loop.tune)

    def merge(self, i: int, behind: float, right: float, psi: float):
        """The merge of robot ``i`` onto its approach line (:func:`~stressbots.control.queries.merge`)."""
        return merge(behind, right, psi, float(self.loop.r_hat[i]))

    def in_funnel(self, i: int, back: float) -> bool:
        """Whether robot ``i`` can merge onto its approach line (:func:`~stressbots.control.queries.in_funnel`)."""
        return in_funnel(*self.line_coords(i), back, float(self.loop.r_hat[i]), self.loop.tune)

    def cut_in(self, i: int, k: int, back: float | None) -> tuple[str, str] | None:
        """Why robot ``i`` (D_k), whose gross motion to its intermediate pose a_i is blocked, may start its fine motion
        from where it is (:meth:`can_arc_in`); None when it may not, or when it has an approach line (``back``): the line
        approach's clockwise bursts merge only from the funnel's shallow angles, and from 32 deg they docked a robot
        74 um off its slot."""
        lp = self.loop
        if back is not None or not self.can_arc_in(i, k):
            return None
        return "cut-in", (f"{lp.scn.names[i]} arcs into its slot from here ({np.hypot(*(lp.est[i, :2] - lp.goals[i, :2])):.0f} um "
                          "away): its way to a_i is blocked and a loop would meet an obstacle")

    def can_arc_in(self, i: int, k: int) -> bool:
        """Whether robot ``i`` (D_k), short of its intermediate pose a_i where a loop would meet the structure, the arena
        edge or a lower orbit, goes on with the fine motion from where it is.

        It must be within ``Tuning.arc_in_reach`` S_2f lengths of its slot, and one interpolated clockwise arc must reach
        the slot as :meth:`fine_dock` steers it: arriving within ``Tuning.fine_arc_arrival_deg`` of the slot's heading,
        its compliant aim within ``Tuning.arc_in_aim_um`` of the slot. The arc keeps ``Tuning.escape_clearance_um`` from
        the docked bodies, the orbits and the arena edge until one body length from the slot (a gap's sides are met
        only there), and from there does not run into the docked bodies. A robot that came within 100 um of a_i 30 deg
        off (a gap between docked neighbours) had only the loop back, no route, and escaped into the gap, pinned.
        """
        lp = self.loop
        p, goal, r = lp.est[i], lp.goals[i], float(lp.r_hat[i])
        if np.hypot(*(p[:2] - goal[:2])) > lp.tune.arc_in_reach * fine_motion_length(r, lp.opts.fine_distance_um):
            return False
        arc_in = self.slot_arc(i)
        if arc_in is None:
            return False
        rho, length, aim = arc_in
        if aim is not None and np.hypot(*(aim - goal[:2])) > lp.tune.arc_in_aim_um:
            return False  # an arc that must end that far along the face is not one into the slot
        if not self.loop_blocked(i, k):
            return False
        arc = move(p, np.linspace(0.0, length, 40), rho / r)
        far = np.hypot(*(arc[:, :2] - goal[:2]).T) > lp.L[i]
        return not (lp.obstacles_hit(arc[far], i, lp.orbiting_below(k), clearance=lp.tune.escape_clearance_um)
                    or any((penetration_depth(arc[:-1], lp.L[i], lp.W[i], pj, lj, wj) > 0.5).any()
                           for pj, lj, wj in zip(*self._bodies(), strict=True)))

    # -- fine motion ----------------------------------------------------------------------------------

    def dock_view(self, i: int) -> DockView:
        """A frozen view of robot ``i`` for the docking policy (estimates as of the last frame)."""
        lp = self.loop
        return DockView(lp.est[i].copy(), float(lp.v_hat[i]), float(lp.r_hat[i]), float(lp.omega_hat[i]),
                        lp.goals[i].copy(), float(lp.L[i]), float(lp.v[i]), float(lp.straight_drift.kappa[i]),
                        float(lp.straight_drift.walk_var_per_um))

    def play(self, policy) -> Any:
        """Apply the steps a policy yields, frame by frame; return its outcome (the loop is the only plant I/O)."""
        try:
            steps = next(policy)
            while True:
                self.loop.drive(steps)
                steps = policy.send(None)
        except StopIteration as stop:
            return stop.value

    def line_approach(self, i: int, k: int, attempt: int = 0) -> DockOutcome:
        """Fine motion along the approach line (:func:`stressbots.control.docking.line_approach`)."""
        lp = self.loop
        outcome = self.play(docking.line_approach(lambda: self.dock_view(i), k, lp.opts, lp.tx,
                                                  loop_blocked=lambda: self.loop_blocked(i, k),
                                                  log=lambda kind, detail: lp.log(kind, i, f"{lp.scn.names[i]} {detail}"),
                                                  attempt=attempt))
        return self.dock_verdict(i, outcome)

    def dock_verdict(self, i: int, outcome: DockOutcome) -> DockOutcome:
        """Record a docking outcome: docked robots join the structure; the others are logged."""
        lp = self.loop
        pose, goal = lp.est[i], lp.goals[i]
        dpos = float(np.hypot(*(pose[:2] - goal[:2])))
        dth = math.degrees(abs(angle_difference(pose[2], goal[2])))
        if outcome in (DockOutcome.DOCKED, DockOutcome.DOCKED_OFF_SLOT):
            lp.docked[i] = True
            off = "" if outcome is DockOutcome.DOCKED else " (off its slot, flush against the structure: it cannot leave)"
            lp.log("docked", i, f"{dpos:.1f} um, {dth:.1f} deg from the slot{off}")
        elif outcome is DockOutcome.STUCK:
            lp.log("stuck", i, f"stopped {dpos:.0f} um / {dth:.0f} deg from the slot (failure region H)")
        return outcome

    def loop_blocked(self, i: int, k: int) -> bool:
        """Whether a full clockwise loop of robot ``i`` from where it is would meet the structure, a lower
        orbit or the arena edge (measured; no clearance: contact is what traps a turning robot)."""
        lp = self.loop
        r = float(lp.r_hat[i])
        loop = move(lp.est[i], np.linspace(0.0, TWO_PI * r, 72), 1.0 / r)
        return lp.obstacles_hit(loop, i, lp.orbiting_below(k), clearance=0.0)

    def slot_arc(self, i: int) -> tuple[float, float, np.ndarray | None] | None:
        """``(rho, length_um, aim)``: the one interpolated clockwise arc (:func:`~stressbots.control.queries.turn_fraction`)
        that takes robot ``i`` from its measured pose to where docking compliance ends it in its slot (``aim``,
        :func:`~stressbots.control.docking.compliant_aim`; None: the slot itself); None when no such arc arrives within
        ``Tuning.fine_arc_arrival_deg`` of the slot's heading. What :meth:`fine_dock` steers and :meth:`can_arc_in` checks."""
        lp = self.loop
        goal, r = lp.goals[i], float(lp.r_hat[i])
        aim = docking.compliant_aim(lp.est[i], goal, r, float(lp.L[i]))
        fr = turn_fraction(lp.est[i], goal if aim is None else aim, r)
        if fr is None or abs(angle_difference(fr[2], goal[2])) > math.radians(lp.tune.fine_arc_arrival_deg):
            return None
        return fr[0], fr[1], aim

    def fine_dock(self, i: int, k: int) -> bool:
        """Fine motion (S_2f) into the slot, then push; True when docked."""
        lp = self.loop
        for _ in range(60):
            v = lp.v_hat[i]
            if self.near_slot(i):
                # already at the structure (e.g. it met it while turning): push, and let compliance act
                lp.drive([(k - 1, lp.opts.push_s)])
                return self.check_docked(i, k)
            arc_in = self.slot_arc(i)
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
        goal = lp.goals[i]
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

        The way off is checked (:meth:`stressbots.control.gross.GrossMotion.escape`: the cheapest turn-then-straight
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
