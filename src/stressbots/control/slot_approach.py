"""How a single robot D_k (k < n-1) can approach its slot, as measured: where its gross motion aims and what it can
reach from where it is. Queries only: nothing here drives the robots or writes the event log.

The slot's *approach line* runs back from the slot along its heading; its clear length behind the slot
(:func:`approach_length`, reachable corridors first, :func:`lead_in_clear`) decides between the line approach and the
seed's S_2f arc. The gross motion aims either at a pose in the line's funnel or at the intermediate pose a_i, where an
S_2f arc into the slot begins (:func:`fine_start`, :func:`approach_start_on_route` on the nominal route, moved with the
structure by :func:`retarget`). :class:`SlotApproach` asks these of the closed loop's estimates for robot ``i``: its
aim, its line coordinates, corridor and funnel, the one arc from where it is into the slot, and whether a loop or that
arc is clear. :class:`~stressbots.control.single.SingleDocking` holds one and drives by its answers.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from .. import paths as pathlib
from ..collision import arena_gap, outside_arena, penetration_depth
from ..kinematics import move
from ..robots import TWO_PI, angle_difference
from . import docking
from .escapes import loop_poses
from .loopview import DockingLoop
from .queries import (
    fine_motion_length,
    in_corridor,
    in_funnel,
    line_coords,
    line_pose,
    merge,
    pose_region,
    turn_fraction,
    waypoint_region,
)

__all__ = ["Bodies", "SlotApproach", "approach_length", "approach_start_on_route", "fine_start", "funnel_aim_left_rad", "lead_in_clear",
           "retarget", "straight_behind", "tight_starts"]


Bodies = tuple[np.ndarray, np.ndarray, np.ndarray]
"""Docked bodies as ``(poses (m, 3), lengths (m,), widths (m,))`` (um, rad)."""


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


TIGHT_TAIL_UM = 20.0
"""um. The tight arcs of :func:`tight_starts` end this far straight behind the slot, as the planner's do: an arc that ends in
the slot itself sweeps the front corner through the neighbour it docks against."""


def tight_starts(goal: np.ndarray, rho: float, length: float, width: float, bodies: Bodies, arena_um: tuple[float, float] | None,
                 turns_deg: Sequence[float]) -> list[np.ndarray]:
    """Intermediate poses a_i at the starts of clockwise arcs of radius ``rho`` (um) turning ``turns_deg`` to the slot
    ``goal``'s heading :data:`TIGHT_TAIL_UM` behind it, in that order, whose swept ``length`` x ``width`` bodies clear the
    docked ``bodies`` by 0.5 um and stay inside the arena: the planner's tight final approaches
    (:meth:`stressbots.dock_planning.DockPlanning.approach_path`), which start beside the slot, for a slot whose rear lies
    near the arena edge.

    >>> a = tight_starts(np.array([500.0, 500.0, 0.0]), 100.0, 50.0, 10.0, (np.zeros((0, 3)), [], []), None, [90.0])[0]
    >>> np.round(a, 6).tolist()   # a quarter turn back from heading +y, 20 um behind: right and below it, heading -x
    [600.0, 380.0, 4.712389]
    """
    out = []
    pre = line_pose(goal, TIGHT_TAIL_UM, 0.0, 0.0)
    for turn in turns_deg:
        s = rho * math.radians(turn)
        back = move(pre, -np.linspace(0.0, s, 40), 1.0 / rho)  # poses along the arc, its end first
        if any((penetration_depth(back, length, width, pj, lj, wj) > 0.5).any() for pj, lj, wj in zip(*bodies, strict=True)):
            continue
        if arena_um is not None and (outside_arena(back, length, width, arena_um) > 0).any():
            continue
        out.append(back[-1])
    return out


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


def funnel_aim_left_rad(behind_um: float, length_um: float, kappa_rad_per_um: float, funnel_psi_deg: float,
                        aim_left_deg: float = 6.0) -> float:
    """How far left of its approach line (rad) a robot's funnel aim ``behind_um`` um behind its slot points:
    ``aim_left_deg`` (``Tuning.funnel_aim_left_deg``), and more by the turn that undoes the offset an identified
    clockwise drift ``kappa_rad_per_um`` adds on the way in
    (:func:`~stressbots.control.docking.lead_um`, the line approach's own lead, over the lever ``behind + L/2``), at most
    1 deg short of the funnel's ``funnel_psi_deg``.

    The line approach leads left by that offset; an aim that did not would be a pose it loops back from at once, and
    the loop back to the aim ends where it starts (with a 9 deg/mm bias identified, six attempts missed in place,
    held-out 39:3 at 2x). A counter-clockwise drift needs nothing: it carries the robot left, which bursts fix.

    >>> round(math.degrees(funnel_aim_left_rad(450.0, 250.0, 0.0, 12.0)), 6)
    6.0
    >>> round(math.degrees(funnel_aim_left_rad(450.0, 250.0, math.radians(9.0) / 1000.0, 12.0)), 2)   # 9 deg/mm
    8.47
    """
    lead = docking.lead_um(behind_um, length_um, math.degrees(max(kappa_rad_per_um, 0.0)) * 1000.0, 0.0)
    turn = math.radians(aim_left_deg) + lead / (max(behind_um, 0.0) + 0.5 * length_um)
    return min(turn, math.radians(funnel_psi_deg - 1.0))


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


# -- robot i and its slot, as measured ---------------------------------------------------------------

class SlotApproach:
    """How robot ``i`` of the closed loop ``loop`` can approach its slot (estimates as of the last frame): the queries
    single-robot docking (:class:`~stressbots.control.single.SingleDocking`) aims and decides by."""

    def __init__(self, loop: DockingLoop):
        self.loop = loop

    def bodies(self) -> Bodies:
        """The docked bodies as measured: ``(poses (m, 3), lengths (m,), widths (m,))``."""
        lp = self.loop
        docked = np.flatnonzero(lp.docked)
        return lp.est[docked], lp.L[docked], lp.W[docked]

    # -- where to aim ---------------------------------------------------------------------------------

    def aim(self, i: int, attempt: int, route_phase,
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
            if not self.clear_of_edge(i, a_pose):
                a_pose = next((p for p in self.tight_aims(i, goal) if self.clear_of_edge(i, p)), a_pose)
            ready = None
        else:
            a_pose = self._aim_behind(i, goal, back, orbiting)
            ready = lambda back=back: self.in_funnel(i, back)  # noqa: E731
        return goal, back, a_pose, ready

    def _aim_behind(self, i: int, goal: np.ndarray, back: float, orbiting: Sequence[int]) -> np.ndarray:
        """The pose robot ``i``'s gross motion aims at in the approach funnel of slot ``goal`` (corridor ``back`` um):
        ``Tuning.funnel_aim_right_um`` right of the line, pointing :meth:`aim_left_rad` left of it (the errors of the last
        leg then keep it in the funnel), at the
        corridor's end, or half or all of ``Tuning.aim_behind_extra_um`` further back: the nearest from which a clockwise
        loop keeps clear of the ``orbiting`` robots, the structure and the arena edge (the corridor's end when none does).

        A one-way robot that arrives off its aim (30 um too far right, say) gets back to it only by a loop. Aimed at the
        corridor's end, that loop met the structure ahead, the roadmap sent the robot on a tour round the structure,
        and every tour ended the same way (1400 s for one robot). Only as far back as the loop needs: every um further
        is a longer straight approach, and aimed 150 um back throughout, marginal shape errors and missed approaches
        cost as many trials as the loops saved."""
        lp = self.loop
        extra, r = lp.tune.aim_behind_extra_um, float(lp.r_hat[i])
        right = lp.tune.funnel_aim_right_um
        poses = [line_pose(goal, b, right, -self.aim_left_rad(i, b)) for b in (back, back + 0.5 * extra, back + extra)]
        s = np.linspace(0.0, TWO_PI * r, int(TWO_PI * r / 10.0) + 2)  # a loop sampled every 10 um
        # each loop checked as the gross motion checks its way to the aim
        return next((p for p in poses if not lp.obstacles_hit(move(p, s, 1.0 / r), i, orbiting, target=p)), poses[0])

    def aim_left_rad(self, i: int, behind_um: float) -> float:
        """How far left of its approach line (rad) robot ``i``'s funnel aim ``behind_um`` um behind its slot points
        (:func:`funnel_aim_left_rad` with its identified straight-line drift)."""
        lp = self.loop
        return funnel_aim_left_rad(behind_um, float(lp.L[i]), float(lp.straight_drift.kappa[i]), lp.tune.funnel_psi_deg,
                                   lp.tune.funnel_aim_left_deg)

    def aim_region(self, i: int, goal: np.ndarray, back: float | None, a_pose: np.ndarray) -> np.ndarray | None:
        """Goals ``(K, 3)`` robot ``i``'s gross motion may head for instead of its aim ``a_pose`` in the approach funnel of
        slot ``goal`` (corridor ``back`` um): ``a_pose`` first, then poses 40 and 80 um further back,
        10 um less to the right, 3 deg either way, those inside the funnel (:func:`~stressbots.control.queries.in_funnel`):
        never nearer the slot nor further right, where the line approach has less room to merge (goals 40 um nearer and
        15 um further right gave more docks off the line at 2x). The funnel test ends the gross motion wherever it enters. With
        no funnel (``back`` None) the aim is the intermediate pose a_i and its region that of a waypoint
        (:func:`~stressbots.control.queries.waypoint_region`: inside the arrival region the S_2f fine motion starts from).
        None (the aim itself) unless ``Tuning.region_aims``."""
        lp = self.loop
        if not lp.tune.region_aims:
            return None
        if back is None:
            return waypoint_region(a_pose, lp.tune)
        r = float(lp.r_hat[i])
        region = pose_region(a_pose, (0.0, -40.0, -80.0), (0.0, -10.0), (0.0, math.radians(3.0), -math.radians(3.0)))
        inside = [k == 0 or in_funnel(*line_coords(goal, g), back, r, lp.tune) for k, g in enumerate(region)]
        return region[np.asarray(inside)]

    def fine_start(self, i: int, goal: np.ndarray, route_phase=None) -> np.ndarray:
        """The intermediate pose a_i of robot ``i`` for slot ``goal`` (:func:`fine_start`, docked bodies as measured).
        Where no S_2f arc into the slot fits and the nominal route ``route_phase`` is given, its a_i (the planner's own
        final arc) rather than the pose straight behind the slot: by the arena edge that pose lay outside the arena, and
        every later attempt aimed there (tuning 118:0 at 1x)."""
        lp = self.loop
        pose = fine_start(goal, lp.r[i], lp.L[i], lp.W[i], lp.opts.fine_distance_um, self.bodies(), lp.scn.arena_um,
                          straight_if_none=False)
        if pose is None and route_phase is not None:
            pose = self._route_start(route_phase, i)
        return pose if pose is not None else straight_behind(goal, lp.r[i], lp.opts.fine_distance_um)

    def clear_of_edge(self, i: int, pose: np.ndarray) -> bool:
        """Whether robot ``i``'s body at ``pose`` keeps ``Tuning.escape_clearance_um`` from the arena edge: the least
        clearance a roadmap route is asked at, so an aim closer to the edge (or beyond it) is no route's end."""
        lp = self.loop
        arena = lp.scn.arena_um
        return arena is None or float(arena_gap(np.asarray(pose, float)[None], lp.L[i], lp.W[i], arena)[0]) >= lp.tune.escape_clearance_um

    def tight_aims(self, i: int, goal: np.ndarray) -> list[np.ndarray]:
        """a_i of robot ``i``'s tight arcs into slot ``goal`` (:func:`tight_starts`; ``Tuning.tight_aim_deg`` at
        ``Tuning.tight_aim_radius`` times its identified turning radius), docked bodies as measured."""
        lp = self.loop
        rho = lp.tune.tight_aim_radius * float(lp.r_hat[i])
        return tight_starts(goal, rho, lp.L[i], lp.W[i], self.bodies(), lp.scn.arena_um, lp.tune.tight_aim_deg)

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
        return approach_length(lp.goals[i], lp.L[i], lp.W[i], lp.tune.approach_lengths_um, self.bodies(), lp.scn.arena_um,
                               lp.tune.approach_lead_in_radii * float(lp.r_hat[i]), float(lp.r_hat[i]), lp.opts.clearance_um,
                               unreachable_ok=not lp.tune.arc_when_line_unreachable)

    # -- the approach line ----------------------------------------------------------------------------

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

    # -- from where it is ------------------------------------------------------------------------------

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
        the slot as :meth:`~stressbots.control.single.SingleDocking.fine_dock` steers it: arriving within
        ``Tuning.fine_arc_arrival_deg`` of the slot's heading, its compliant aim within ``Tuning.arc_in_aim_um`` of the
        slot. The arc keeps ``Tuning.escape_clearance_um`` from the docked bodies, the orbits and the arena edge until one
        body length from the slot (a gap's sides are met only there), and from there does not run into the docked
        bodies. A robot that came within 100 um of a_i 30 deg off (a gap between docked neighbours) had only the loop
        back, no route, and escaped into the gap, pinned.
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
                           for pj, lj, wj in zip(*self.bodies(), strict=True)))

    def slot_arc(self, i: int) -> tuple[float, float, np.ndarray | None] | None:
        """``(rho, length_um, aim)``: the one interpolated clockwise arc (:func:`~stressbots.control.queries.turn_fraction`)
        that takes robot ``i`` from its measured pose to where docking compliance ends it in its slot (``aim``,
        :func:`~stressbots.control.docking.compliant_aim`; None: the slot itself); None when no such arc arrives within
        ``Tuning.fine_arc_arrival_deg`` of the slot's heading. What :meth:`~stressbots.control.single.SingleDocking.fine_dock`
        steers and :meth:`can_arc_in` checks."""
        lp = self.loop
        goal, r = lp.goals[i], float(lp.r_hat[i])
        aim = docking.compliant_aim(lp.est[i], goal, r, float(lp.L[i]))
        fr = turn_fraction(lp.est[i], goal if aim is None else aim, r)
        if fr is None or abs(angle_difference(fr[2], goal[2])) > math.radians(lp.tune.fine_arc_arrival_deg):
            return None
        return fr[0], fr[1], aim

    def loop_blocked(self, i: int, k: int, clearance_um: float = 0.0) -> bool:
        """Whether a full clockwise loop of robot ``i`` from where it is would come within ``clearance_um`` of the
        structure, a lower orbit or the arena edge (measured; by default no clearance: contact is what traps a turning
        robot)."""
        lp = self.loop
        r = float(lp.r_hat[i])
        return lp.obstacles_hit(loop_poses(lp.est[i], r), i, lp.orbiting_below(k), clearance=clearance_um)
