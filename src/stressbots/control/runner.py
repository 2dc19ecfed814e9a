"""Closed-loop assembly under control error: the two-step EDR strategy of seed Appendix 3.

The controller talks to the robots only through a :class:`stressbots.control.Plant` (``observe`` and
``apply``). Every ``replan_interval_s`` (t_x) it takes a camera frame, updates its estimates
(:mod:`stressbots.estimation`: filtered poses, identified speeds and turn rates) and re-plans the moving
robot's motion from where it really is. The nominal plan (:func:`stressbots.planning.plan_assembly`)
supplies the structure, the slots and the single robots' roadmap routes; the controller never replays
its timing.

**One-way robots and regions.** A robot that only turns clockwise cannot undo a small error to its
left without a full loop, so no step aims at an exact pose: every target is a region (the seed's A_i),
gross motion keeps a left bias (turns into long straights are cut short by up to 3 deg; the next
replan adds the missing clockwise turn), and the last seconds of a timed path run open loop rather
than being re-planned into a loop.

**G_1 (App. 3.3), as an orbit rendezvous.** Under P_n and P_{n-1} D_{n-1} orbits in place while D_n is a
free one-way robot (P_n turns it, P_{n-1} drives it straight); under P_{n-2} both drive straight.

1. *Transfer*: D_{n-1} moves its orbit to a station orbit, in straight legs: it orbits until it heads
   along the leg, then P_{n-2} drives it (and D_n) straight; clockwise bearing corrections (P_{n-1}
   bursts) keep it on course. D_n either turns with D_{n-1} for a chosen fraction of the wait and then
   runs straight on a track checked to be clear, or first drives to a chosen clear track, timed to
   D_{n-1}'s departure.
2. *Rendezvous*: D_n drives to a region on the tangent of D_{n-1}'s orbit that leads to D_{n-1}'s slot,
   timed to arrive 1.2 s before D_{n-1} passes the tangent point. Timing comes from waiting on its own
   orbit (and straights before it): any arrival time is reachable without long detours. D_n then runs
   straight; D_{n-1} leaves its orbit at the heading that best lines it up with D_n as measured.
3. *Meeting*: both drive straight into each other; self-aligning compliance (|alpha| < 60 deg,
   |w_y| < 80 um) forms G_1 wherever they meet. The remaining slots follow the pair (``retarget``).

**Docking of single robots (sigma_1, sigma_2).** Gross motion steers D_i (P_i turns, P_{i-1} straight,
lower robots orbiting) into the approach funnel behind its slot, outside the proximity region C_O: the
region from which it can merge onto the slot's approach line without a loop (to the line's right,
pointing left of it). Fine motion merges with an interpolated clockwise arc of radius r' >= r (P_i for
a fraction rho_a, P_{i-1} for rho_b, SPEC 8's ``r' = r (1 + rho_b / rho_a)``), drives straight in and
pushes; docking compliance absorbs the last angle error. Tight gaps use the seed's S_2f arc through the
docking point instead.

**Failure detection and recovery.** A robot that stops while it should move is in H (stuck): it backs
off by turning and tries again; a robot that misses its approach line loops back through the funnel; a
robot the camera loses is dead-reckoned until it is seen again; a path that would meet an orbit, the
structure or the arena edge is routed around them on a roadmap (one route, followed waypoint by
waypoint). Everything runs within a simulated time budget, and a run that fails says why.

Success is judged on the shape after a best rigid alignment (:mod:`stressbots.assessment`); the absolute
placement error is reported beside it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from .. import paths as pathlib
from .. import se2
from ..collision import (
    arena_gap,
    bodies_hit_discs,
    outside_arena,
    penetration_depth,
    point_rectangle_distance,
)
from ..errors import PlanningError
from ..kinematics import move
from ..robots import TWO_PI, angle_difference, front_midpoints, turning_centres
from . import docking
from .docking import DockOutcome, DockView
from .loop import PlantLoop
from .parking import orbit_gaps, park_move
from .queries import (
    best_departure,
    in_funnel,
    interpolated_steps,
    line_coords,
    line_pose,
    merge,
    pose_on_orbit,
    trim_steps,
    turn_fraction,
)
from .result import AssemblyResult, judge_run
from .station import orbit_route
from .targets import Targets, nominal_plan, structure_targets
from .tuning import ControllerOptions

__all__ = ["assemble", "stream", "STREAMS"]


STREAMS = ("routes",)
"""Names of the controller's random streams, each spawned from the run's seed (:func:`stream`)."""


def stream(seed: int | None, name: str) -> np.random.Generator:
    """The random generator of the named stream ``name`` for a run with ``seed`` (None counts as 0).

    Streams are independent (``SeedSequence(seed, spawn_key=(index of name,))``), so adding draws to
    one never shifts another.
    """
    return np.random.default_rng(np.random.SeedSequence(0 if seed is None else int(seed), spawn_key=(STREAMS.index(name),)))


class _Abort(Exception):
    """The run cannot go on; ``reason`` says why (reported as the result's ``failure``)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class _Replan(_Abort):
    """A stage of G_1 has no solution from here: the pair's gross motion is planned again (not a failure yet)."""


class _Budget(_Abort):
    def __init__(self, budget_s: float):
        super().__init__(f"not assembled within the time budget of {budget_s:g} s (simulated)")


class _Runner(PlantLoop):
    def __init__(self, scenario, plant, plan_result, opts: ControllerOptions, seed):
        super().__init__(scenario, plant, budget_s=opts.time_budget_s, who="closed-loop assembly")
        self.opts = opts
        self.tune = opts.tuning
        self.seed = seed
        self.tx = float(opts.replan_interval_s or scenario.control.replan_interval_s)
        # named random streams of this run (the roadmap's samples); never derived from the event count
        self.routes_rng = stream(seed, "routes")
        if not isinstance(plan_result, Targets):
            plan_result = Targets(plan_result.plan.goal_array(), tuple(plan_result.phases))
        self.pr = plan_result
        self.v, self.r = scenario.speeds_um_s, scenario.turn_radii_um
        self.nominal_goals = np.asarray(plan_result.goals, dtype=np.float64).copy()
        self.goals = self.nominal_goals.copy()
        self._stuck = False
        self._plan: tuple[Any, Any, float] | None = None
        self._warned: set = set()
        # rigid motion (phi, c_nom, c_meas) of the structure once G_1 formed
        self._motion: tuple[float, np.ndarray, np.ndarray] | None = None

    # -- plant I/O ------------------------------------------------------------------------------------

    def over_budget(self) -> Exception:
        return _Budget(self.budget_s)

    def after_drive(self, steps: Sequence[tuple[int, float]]) -> None:
        """Failure detection after every frame: robots lost to the camera, orbits drifting into trouble."""
        for i in np.flatnonzero(self.estimator.unseen == 3):
            self.log("lost", int(i), "not seen for 3 frames; dead-reckoning")
        self.watch_orbits([i for i in range(self.n) if not self.docked[i] and self.rank[i] < min(k for k, _ in steps)])

    def watch_orbits(self, orbiting: Sequence[int]) -> None:
        """Failure detection: an orbit (drifting with the heading noise) within 10 um of another orbit,
        a docked body or the arena edge is logged once. Paths are always planned around the orbits as
        measured, so the robot moving meanwhile keeps clear of them; a collision would show as a stall."""
        if not orbiting:
            return
        c = turning_centres(self.est[orbiting], self.r_hat[orbiting])
        rs = self.rstar[orbiting]
        for a, i in enumerate(orbiting):
            near = []
            for b, j in enumerate(orbiting[a + 1:], start=a + 1):
                gap = float(np.hypot(*(c[a] - c[b]))) - rs[a] - rs[b]
                if gap < self.tune.orbit_watch_um:
                    near.append((f"the orbit of {self.scn.names[j]}", gap))
            for j in np.flatnonzero(self.docked).tolist():
                gap = float(point_rectangle_distance(c[a][None, :], self.est[j][None, :], self.L[j], self.W[j])[0, 0]) - rs[a]
                if gap < self.tune.orbit_watch_um:
                    near.append((f"docked {self.scn.names[j]}", gap))
            if self.scn.arena_um is not None:
                w, h = self.scn.arena_um
                gap = float(min(c[a][0], w - c[a][0], c[a][1], h - c[a][1])) - rs[a]
                if gap < self.tune.orbit_watch_um:
                    near.append(("the arena edge", gap))
            for what, gap in near:
                key = (i, what)
                if key not in self._warned:
                    self._warned.add(key)
                    self.log("orbit-drift", i, f"the orbit of {self.scn.names[i]} is {gap:.0f} um from {what}")

    # -- geometry -------------------------------------------------------------------------------------

    def obstacles_hit(self, samples: np.ndarray, i: int, orbiting: Sequence[int], *, extra_discs=(), clearance: float | None = None,
                      target=None) -> bool:
        """Whether robot ``i``'s body along ``samples`` hits an orbit, a docked body or the arena edge.

        With ``target`` (a gross-motion goal pose), docked bodies are kept ``Tuning.gross_docked_clearance_um``
        away except within one body length of the target: a robot that touches the structure on the way
        is turned flush against the wrong edge by docking compliance and cannot pivot off again.
        """
        c = self.opts.clearance_um if clearance is None else clearance
        samples = np.asarray(samples, dtype=np.float64)
        orbiting = [j for j in orbiting if j != i]
        if orbiting or extra_discs:
            centres = [*turning_centres(self.est[orbiting], self.r_hat[orbiting])] if orbiting else []
            radii = list(self.rstar[orbiting]) if orbiting else []
            for cc, rr in extra_discs:
                centres.append(cc)
                radii.append(rr)
            if bodies_hit_discs(samples, self.L[i], self.W[i], np.array(centres), np.array(radii) + c).any():
                return True
        docked = np.flatnonzero(self.docked)
        if len(docked):
            need = np.full(len(samples), c)
            if target is not None:
                far = np.hypot(*(samples[:, :2] - np.asarray(target, float)[:2]).T) > self.L[i]
                need[far] = max(c, self.tune.gross_docked_clearance_um)
            hd = 0.5 * math.hypot(self.L[i], self.W[i])
            for j in docked:
                # only samples within reach of body j (bounding circles) need the exact rectangle test
                near = np.hypot(*(samples[:, :2] - self.est[j, :2]).T) < hd + 0.5 * math.hypot(self.L[j], self.W[j]) + need
                if near.any() and (penetration_depth(samples[near], self.L[i], self.W[i], self.est[j], self.L[j],
                                                     self.W[j]) > -need[near]).any():
                    return True
        if self.scn.arena_um is not None and (arena_gap(samples, self.L[i], self.W[i], self.scn.arena_um) < c).any():
            return True
        return False

    def park_orbits(self, k: int) -> None:
        """Before D_k's phase: move waiting orbits that drifted within ``Tuning.park_margin_um`` of the arena
        edge, the structure or another orbit (:mod:`stressbots.control.parking`); at most one move each."""
        waiting = [self.by_rank[j] for j in range(1, k + 1)]
        docked = np.flatnonzero(self.docked)
        gaps = orbit_gaps(turning_centres(self.est[waiting], self.r_hat[waiting]), self.rstar[waiting], self.scn.arena_um,
                          self.est[docked], self.L[docked], self.W[docked])
        for idx in np.argsort(gaps):
            i = waiting[int(idx)]
            j = int(self.rank[i])
            if gaps[idx] >= self.tune.park_margin_um or j == k:
                continue
            movers = [self.by_rank[m] for m in range(j, k + 1)]
            still = [self.by_rank[m] for m in range(1, j)]
            move_ = park_move(i, movers, still, self.est, self.r_hat, self.omega_hat, self.v_hat, self.rstar, self.scn.arena_um,
                              self.est[docked], self.L[docked], self.W[docked], shift_um=self.tune.park_shift_um,
                              clearance_um=self.tune.park_clearance_um)
            if move_ is None:
                self.log("park", i, f"the orbit of {self.scn.names[i]} is {gaps[idx]:.0f} um from trouble and no clear move takes it away")
                continue
            self.log("park", i, f"the orbit of {self.scn.names[i]} is {gaps[idx]:.0f} um from trouble: it moves "
                                f"{self.tune.park_shift_um:.0f} um away")
            self.replans += 1
            self.drive([(k, move_.wait_s), (j - 1, move_.straight_s)])

    def orbiting_below(self, k: int) -> list[int]:
        return [self.by_rank[j] for j in range(1, k)]

    # -- motion primitives ------------------------------------------------------------------------------

    def path_steps(self, path: pathlib.Path, v: float, turn_k: int, straight_k: int, limit_s: float | None = None):
        """The first ``limit_s`` seconds of ``path`` as primitive steps (all of it when None)."""
        out: list[tuple[int, float]] = []
        left = math.inf if limit_s is None else limit_s
        for kind, ell in path.segments:
            d = min(ell / v, left)
            out.append((turn_k if kind == "R" else straight_k, d))
            left -= d
            if left <= 1e-12:
                break
        return out

    def _route_or_detour(self, i: int, target: np.ndarray, orbiting: Sequence[int], extra_discs, routed, path):
        """The roadmap route itself when there is one (it was checked at a wider clearance), else a detour at
        the controller's clearance, else ``path`` unchanged."""
        if routed is not None:
            return routed
        detour = self.roadmap_route(i, target, orbiting, extra_discs, self.opts.clearance_um)[1]
        return path if detour is None else detour

    def steer(self, i: int, target: np.ndarray, turn_k: int, straight_k: int, orbiting: Sequence[int], *, extra_discs=(),
              max_cycles: int = 400, ready=None, via: bool = True, clearance: float | None = None) -> bool:
        """Gross motion: drive robot ``i`` to ``target`` by replanning every t_x; True when there.

        ``ready()`` True ends the gross motion early (the robot is already in the region from which the
        next step works: the seed's regions A_i instead of a point).

        Left bias: a turn that leads into a long straight is cut short by up to 3 deg, so the straight
        points a little left of where it must. Clockwise is the only correction a one-way robot makes
        cheaply: a turn overdone (speed or radius misidentified, drift) would cost a full loop at the
        next replan, a turn cut short costs a slight turn.
        """
        stalls = 0
        quiet = 0  # cycles left before the roadmap is asked again after it found no way around
        self._stuck = False
        for _ in range(max_cycles):
            v, r = self.v_hat[i], self.r_hat[i]
            p = self.est[i]
            if (ready is None and self.arrived(p, target)) or (ready is not None and ready()):
                return True
            path = pathlib.shortest_path(p, target, r)
            if self.obstacles_hit(path.sample(10.0), i, orbiting, extra_discs=extra_discs, clearance=clearance, target=target):
                if via and quiet > 0:
                    quiet -= 1  # the roadmap found nothing a moment ago: asking every t_x only costs time
                elif via:
                    # commit to one roadmap route: steer through its waypoints (replanning every t_x
                    # between them), instead of a new random route every t_x
                    c_eff = self.opts.clearance_um if clearance is None else clearance
                    points, routed = self.roadmap_route(i, target, orbiting, extra_discs, max(c_eff + 5.0, 20.0))
                    t_before = self.t
                    if len(points) > 1:
                        for w in points[:-1]:
                            self.steer(i, w, turn_k, straight_k, orbiting, extra_discs=extra_discs, max_cycles=60, ready=ready, via=False,
                                       clearance=clearance)
                            if ready is not None and ready():
                                return True
                        if self.t > t_before:
                            continue
                    found = self._route_or_detour(i, target, orbiting, extra_discs, routed, None)
                    if found is None:
                        quiet = self.tune.no_route_quiet_cycles
                        self.log("no-route", i, f"no way around the obstacles to its target; drives on, asks again in {quiet} t_x")
                    path = path if found is None else found
                else:
                    return False  # a waypoint of a committed route is out of reach: the caller re-plans
            self.replans += 1
            # the last leg runs whole: a one-way robot that stops short and overshoots needs a loop
            whole = path.length / v <= self.tune.whole_leg_factor * self.tx
            limit = None if whole else self.tx
            steps = self.path_steps(path, v, turn_k, straight_k, limit)
            if not whole:
                steps = self._left_biased(i, path, steps, straight_k, orbiting, extra_discs, clearance, target)
            before = self.est[i].copy()
            self.drive(steps)
            if float(np.hypot(*(self.est[i, :2] - before[:2]))) < self.tune.stall_fraction * v * sum(d for _, d in steps):
                stalls += 1
                if stalls >= self.tune.stall_count:
                    self.log("stuck", i, "stopped during gross motion (failure region H)")
                    self._stuck = True
                    return False
            else:
                stalls = 0
            if whole:
                return True
        return False

    def _left_biased(self, i: int, path, steps, straight_k: int, orbiting, extra_discs, clearance, target):
        """``steps`` with the turn into a long straight cut short by ``Tuning.left_bias_deg`` when that path is clear
        (see :meth:`steer`)."""
        v, r = self.v_hat[i], self.r_hat[i]
        segs = path.segments
        if not (len(segs) > 1 and segs[0][0] == "R" and segs[1][0] == "S" and segs[1][1] > 0.5 * v * self.tx):
            return steps
        cut_um = min(r * math.radians(self.tune.left_bias_deg), 0.5 * segs[0][1])
        biased = pathlib.Path(self.est[i], r, (("R", segs[0][1] - cut_um), ("S", segs[1][1] + cut_um)))
        if steps[0][1] > cut_um / v and not self.obstacles_hit(biased.sample(10.0), i, orbiting, extra_discs=extra_discs,
                                                               clearance=clearance, target=target):
            steps = [(steps[0][0], steps[0][1] - cut_um / v), (straight_k, cut_um / v), *steps[1:]]
            steps = trim_steps(steps, self.tx)
        return steps

    def arrived(self, pose: np.ndarray, target: np.ndarray) -> bool:
        """Inside the target region (the seed's regions instead of points): 25 um and 6 deg."""
        return bool(np.hypot(*(pose[:2] - target[:2])) <= self.tune.arrive_um
                    and abs(angle_difference(pose[2], target[2])) <= math.radians(self.tune.arrive_deg))

    def _obstacles(self, i: int, orbiting, extra_discs, box_margin: float = 0.0):
        from ..planning import Obstacles

        orbiting = [j for j in orbiting if j != i]
        centres = list(turning_centres(self.est[orbiting], self.r_hat[orbiting])) if orbiting else []
        radii = list(self.rstar[orbiting]) if orbiting else []
        for c, rr in extra_discs:
            centres.append(c)
            radii.append(rr)
        docked = np.flatnonzero(self.docked)
        return Obstacles(
            np.array(centres).reshape(-1, 2), np.array(radii, float), tuple("an orbit" for _ in radii),
            self.est[docked], self.L[docked] + 2.0 * box_margin, self.W[docked] + 2.0 * box_margin,
            tuple("a docked robot" for _ in docked), self.scn.arena_um,
        )

    def roadmap_route(self, i: int, target, orbiting, extra_discs, clearance: float):
        """``(waypoints, path)``: the planner's roadmap route from the measured pose around the orbits, the
        structure and the arena edge to ``target`` (waypoints end with it), at ``clearance``; ``([], None)``
        when there is none. Logged as a detour."""
        from ..planning import NoRoute, PlannerOptions, route

        rng = self.routes_rng
        opts = PlannerOptions(clearance_um=clearance, roadmap_nodes=(60, 200))
        # around the structure with the gross-motion clearance first (see obstacles_hit), else the plain one
        margins = (max(self.tune.gross_docked_clearance_um - clearance, 0.0), 0.0) if self.docked.any() else (0.0,)
        for margin in margins:
            obst = self._obstacles(i, orbiting, extra_discs, margin)
            try:
                _, routed, points = route(self.est[i][None, :], np.zeros(1), np.asarray(target, float), self.r_hat[i], self.L[i],
                                          self.W[i], obst, opts, rng, "")
                break
            except NoRoute:
                continue
        else:
            return [], None
        self.log("detour", i, f"route around obstacles ({routed.length:.0f} um, {len(points)} waypoints)")
        return [np.asarray(w, float) for w in points], routed

    def interpolated_steps(self, rho_turn: float, duration: float, turn_k: int, straight_k: int):
        """S_2f for ``duration`` s (:func:`~stressbots.control.queries.interpolated_steps`)."""
        return interpolated_steps(rho_turn, duration, turn_k, straight_k, self.opts.switch_period_s)

    def fine_start(self, i: int, goal: np.ndarray) -> np.ndarray:
        """The intermediate pose a_i: back along a clockwise arc that ends exactly in the slot.

        Only positions to a robot's right are reachable by one clockwise arc (seed Fig. 4), so a_i lies
        on a nominal arc of radius ``s_f / phi`` (arrival heading = the slot's): measured errors either
        way are then absorbed by a larger or smaller r'. ``phi`` is the largest of 25, 15, 8, 4 deg whose
        swept bodies clear the docked structure (tight gaps need an almost straight entry).
        """
        s_f = min(2.5 * self.r[i], 3.0 * self.opts.fine_distance_um)
        docked = np.flatnonzero(self.docked)
        for phi_deg in (25.0, 15.0, 8.0, 4.0):
            R = s_f / math.radians(phi_deg)
            back = move(goal, -np.linspace(0.0, s_f, 40), 1.0 / R)  # poses along the arc, slot first
            ok = True
            for j in docked:
                depth = penetration_depth(back[1:], self.L[i], self.W[i], self.est[j], self.L[j], self.W[j])
                if (depth > 0.5).any():
                    ok = False
                    break
            if ok and not (self.scn.arena_um is not None and (outside_arena(back, self.L[i], self.W[i], self.scn.arena_um) > 0).any()):
                return back[-1]
        h = np.array([math.sin(goal[2]), math.cos(goal[2])])
        return np.array([goal[0] - s_f * h[0], goal[1] - s_f * h[1], goal[2]])

    def fine_start_on(self, ph, i: int) -> np.ndarray:
        """The intermediate pose a_i on the nominal path: where its final approach arc begins.

        The planner ends every route with an interpolated clockwise arc into the slot, so from a_i the
        slot lies ahead and to the right, within reach of one arc of adjustable radius r', and the gross
        motion to a_i follows the nominal route instead of looping to a pose off it.
        """
        if not ph.path or ph.path_start is None:
            return self.fine_start(i, self.goals[i])
        path = pathlib.Path(ph.path_start, self.r[i], ph.path)
        s_f = ph.approach_um if ph.approach_um > 0 else min(self.opts.fine_distance_um, 0.8 * path.length)
        return np.asarray(path.pose_at(path.length - s_f), dtype=np.float64)

    # -- docking of single robots -------------------------------------------------------------------

    def dock_single(self, k: int, route_phase) -> None:
        """Dock D_k (k < n-1): gross motion into the approach funnel behind its slot, then the line approach.

        The approach line runs back from the slot along its heading. The funnel is the region from which a
        one-way robot can merge onto that line without a loop: to the line's right, pointing left of it
        (or on it), far enough behind the slot. The gross motion aims at a pose inside it (20 um right,
        6 deg left: the errors of the last leg then keep it inside) and stops as soon as the measured pose
        is in it; the fine motion (:meth:`line_approach`) merges and drives straight in. Where the line's
        corridor is blocked (a tight gap) the S_2f arc of the nominal plan is used instead.
        """
        i = self.by_rank[k]
        self.park_orbits(k)
        orbiting = self.orbiting_below(k)
        if self._motion is not None and (abs(self._motion[0]) > math.radians(5.0) or np.hypot(*(self._motion[2] - self._motion[1])) > 60.0):
            route_phase = None  # the pair formed in a re-planned frame: the nominal route no longer applies
        waypoints = [np.array(w) for w in (route_phase.waypoints if route_phase is not None else ())]
        misses = 0
        for attempt in range(self.tune.dock_attempts):
            goal = self.goals[i]
            back = self.approach_length(i)
            if back is None:
                a_pose = self.fine_start_on(route_phase, i) if route_phase is not None and attempt == 0 else self.fine_start(i, goal)
                a_pose = self.retargeted(a_pose)
                ready = None
            else:
                a_pose = self.line_pose(goal, back, 20.0, -math.radians(6.0))
                ready = lambda back=back: self.in_funnel(i, back)  # noqa: E731
            targets = [w for w in waypoints[:-1] if self._before(w, a_pose, route_phase, i)] + [a_pose]
            for tgt in targets:
                self.steer(i, tgt, k, k - 1, orbiting, ready=ready)
                if self._stuck:
                    break
            waypoints = []
            if self._stuck:
                self.back_off(i, k)
                continue
            if back is not None and not self.in_funnel(i, back):
                self.log("retry", i, f"attempt {attempt + 1}: the gross motion ended outside the approach funnel; steering again")
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
                self.log("retry", i, f"attempt {attempt + 1} missed the approach line; looping back")
                continue
            self.log("retry", i, f"attempt {attempt + 1} did not dock; backing off")
            self.back_off(i, k)
        raise _Abort(f"{self.scn.names[i]} did not dock in {self.tune.dock_attempts} attempts (last: "
                     f"{self.events[-1]['detail'] if self.events else ''})")

    line_pose = staticmethod(line_pose)

    def line_coords(self, i: int) -> tuple[float, float, float]:
        """``(behind_um, right_um, psi_rad)`` of robot ``i`` relative to its slot's approach line."""
        return line_coords(self.goals[i], self.est[i])

    def approach_length(self, i: int) -> float | None:
        """How far behind the slot the approach line is clear of the structure (450 down to 150 um), or None."""
        goal = self.goals[i]
        docked = np.flatnonzero(self.docked)
        for back in self.tune.approach_lengths_um:
            ok = True
            for right in (0.0, 60.0):
                line = np.stack([self.line_pose(goal, b, right * b / back, 0.0) for b in np.linspace(8.0, back, 24)])
                for j in docked:
                    if (penetration_depth(line, self.L[i], self.W[i], self.est[j], self.L[j], self.W[j]) > -3.0).any():
                        ok = False
                if self.scn.arena_um is not None and (outside_arena(line, self.L[i], self.W[i], self.scn.arena_um) > 0).any():
                    ok = False
            if ok:
                return back
        return None

    def merge(self, i: int, behind: float, right: float, psi: float):
        """The merge of robot ``i`` onto its approach line (:func:`~stressbots.control.queries.merge`)."""
        return merge(behind, right, psi, float(self.r_hat[i]))

    def in_funnel(self, i: int, back: float) -> bool:
        """Whether robot ``i`` can merge onto its approach line (:func:`~stressbots.control.queries.in_funnel`)."""
        return in_funnel(*self.line_coords(i), back, float(self.r_hat[i]), self.tune)

    def dock_view(self, i: int) -> DockView:
        """A frozen view of robot ``i`` for the docking policy (estimates as of the last frame)."""
        return DockView(self.est[i].copy(), float(self.v_hat[i]), float(self.r_hat[i]), float(self.omega_hat[i]),
                        self.goals[i].copy(), float(self.L[i]), float(self.v[i]), float(self.straight_drift.kappa[i]))

    def play(self, policy) -> Any:
        """Apply the steps a policy yields, frame by frame; return its outcome (the loop is the only plant I/O)."""
        try:
            steps = next(policy)
            while True:
                self.drive(steps)
                steps = policy.send(None)
        except StopIteration as stop:
            return stop.value

    def line_approach(self, i: int, k: int, attempt: int = 0) -> DockOutcome:
        """Fine motion along the approach line (:func:`stressbots.control.docking.line_approach`)."""
        outcome = self.play(docking.line_approach(lambda: self.dock_view(i), k, self.opts, self.tx,
                                                  loop_blocked=lambda: self.loop_blocked(i, k),
                                                  log=lambda kind, detail: self.log(kind, i, f"{self.scn.names[i]} {detail}"),
                                                  attempt=attempt))
        return self.dock_verdict(i, outcome)

    def dock_verdict(self, i: int, outcome: DockOutcome) -> DockOutcome:
        """Record a docking outcome: docked robots join the structure; the others are logged."""
        pose, goal = self.est[i], self.goals[i]
        dpos = float(np.hypot(*(pose[:2] - goal[:2])))
        dth = math.degrees(abs(angle_difference(pose[2], goal[2])))
        if outcome in (DockOutcome.DOCKED, DockOutcome.DOCKED_OFF_SLOT):
            self.docked[i] = True
            off = "" if outcome is DockOutcome.DOCKED else " (off its slot, flush against the structure: it cannot leave)"
            self.log("docked", i, f"{dpos:.1f} um, {dth:.1f} deg from the slot{off}")
        elif outcome is DockOutcome.STUCK:
            self.log("stuck", i, f"stopped {dpos:.0f} um / {dth:.0f} deg from the slot (failure region H)")
        return outcome

    def loop_blocked(self, i: int, k: int) -> bool:
        """Whether a full clockwise loop of robot ``i`` from where it is would meet the structure, a lower
        orbit or the arena edge (measured; no clearance: contact is what traps a turning robot)."""
        r = float(self.r_hat[i])
        loop = move(self.est[i], np.linspace(0.0, TWO_PI * r, 72), 1.0 / r)
        return self.obstacles_hit(loop, i, self.orbiting_below(k), clearance=0.0)

    def _before(self, w, a_pose, route_phase, i) -> bool:
        """Whether waypoint ``w`` comes before ``a_pose`` along the nominal route."""
        if route_phase is None or not route_phase.path:
            return True
        path = pathlib.Path(route_phase.path_start, self.r[i], route_phase.path)
        s = path.sample(5.0)
        kw = int(np.argmin(np.hypot(*(s[:, :2] - np.asarray(w)[:2]).T)))
        ka = int(np.argmin(np.hypot(*(s[:, :2] - np.asarray(a_pose)[:2]).T)))
        return kw < ka

    def retargeted(self, pose: np.ndarray) -> np.ndarray:
        """A nominal pose moved by the rigid motion the structure took when G_1 formed."""
        if self._motion is None:
            return np.asarray(pose, float)
        phi, c_nom, c_meas = self._motion
        d = np.asarray(pose[:2]) - c_nom
        cph, sph = math.cos(phi), math.sin(phi)
        rot = np.array([d[0] * cph + d[1] * sph, -d[0] * sph + d[1] * cph])
        return np.array([c_meas[0] + rot[0], c_meas[1] + rot[1], float(np.mod(pose[2] + phi, TWO_PI))])

    def fine_dock(self, i: int, k: int) -> bool:
        """Fine motion (S_2f) into the slot, then push; True when docked."""
        for _ in range(60):
            v, r = self.v_hat[i], self.r_hat[i]
            goal = self.goals[i]
            if self.near_slot(i):
                # already at the structure (e.g. it met it while turning): push, and let compliance act
                self.drive([(k - 1, self.opts.push_s)])
                return self.check_docked(i, k)
            fr = turn_fraction(self.est[i], goal, r)
            if fr is None or abs(angle_difference(fr[2], goal[2])) > math.radians(40):
                return False  # not reachable on one interpolated arc: gross motion again
            rho, length, _ = fr
            t_arc = length / v
            if t_arc <= self.tx:
                self.drive(self.interpolated_steps(rho, t_arc, k, k - 1) + [(k - 1, self.opts.push_s)])
                return self.check_docked(i, k)
            self.drive(self.interpolated_steps(rho, self.tx, k, k - 1))
        return False

    def near_slot(self, i: int) -> bool:
        """Whether robot ``i`` (measured) is at its slot within the docking tolerances."""
        goal = self.goals[i]
        return bool(
            np.hypot(*(self.est[i, :2] - goal[:2])) <= self.opts.dock_tol_um
            and abs(angle_difference(self.est[i, 2], goal[2])) <= math.radians(self.opts.dock_tol_deg)
        )

    def check_docked(self, i: int, k: int) -> bool:
        """Push until the robot stops; docked if it stopped at its slot (or flush off it), stuck (H) if elsewhere."""
        outcome = self.dock_verdict(i, self.play(docking.settle(lambda: self.dock_view(i), k, self.opts, self.tx)))
        return outcome in (DockOutcome.DOCKED, DockOutcome.DOCKED_OFF_SLOT)

    def back_off(self, i: int, k: int) -> None:
        """Recovery from H: a robot cannot reverse, so it turns away (arm down) and drives clear."""
        self.drive([(k, 0.5 * math.pi * self.r[i] / self.v[i]), (k - 1, 150.0 / self.v[i])])

    # -- G_1 (App. 3.3) as an orbit rendezvous ---------------------------------------------------------
    #
    # Under P_n and P_{n-1} D_{n-1} orbits in place (its pose is a function of time only) while D_n is a
    # free one-way car (P_n turns it, P_{n-1} drives it straight). Under P_{n-2} both drive straight. So:
    #
    # 1. transfer: D_{n-1} turns until it heads for its station orbit, then drives straight onto it
    #    (P_{n-2}); D_n turns with it for a chosen fraction of the turn, then runs straight on a track
    #    checked to be clear. D_{n-1}'s heading is corrected clockwise on the way (a left bias at
    #    departure makes every correction clockwise, so none costs a loop);
    # 2. rendezvous: D_n drives to a pose on the tangent of D_{n-1}'s orbit that leads to D_{n-1}'s slot,
    #    timed to arrive a little before D_{n-1} passes the tangent point, and runs straight on; D_{n-1}
    #    leaves its orbit at the heading that best lines it up with D_n as measured (the departure is
    #    timed from D_{n-1}'s measured heading and identified turn rate);
    # 3. both drive straight into each other: self-aligning compliance forms G_1.
    #
    # No step needs an exact pose: D_n's arrival may be early or late by a second (its straight run
    # absorbs it), D_{n-1}'s station may be tens of um off (the rendezvous is computed from the measured
    # orbit), and the meeting tolerates |alpha| < 60 deg and |w_y| < 80 um. The pair may form a little
    # away from its nominal place: the later slots follow it (``retarget``).

    def centre(self, i: int) -> np.ndarray:
        """Measured turning centre of robot ``i`` (with its identified radius)."""
        return turning_centres(self.est[i], self.r_hat[i])[0]

    def meet_distance(self, N: int, M: int) -> float:
        """Centre distance of D_n from D_{n-1}'s tangent point at departure: D_n clear of the orbit disc, plus 80 um."""
        rs = self.rstar[M] + 30.0
        lateral = self.r[M] - 0.5 * self.W[N]
        return 0.5 * self.L[N] + math.sqrt(max(rs * rs - lateral * lateral, 0.0)) + 80.0

    def station(self, N: int, M: int, D: float) -> np.ndarray:
        """Centre of the orbit D_{n-1} leaves from so that, meeting D_n from ``D`` away, it ends in its slot."""
        g = self.goals[M]
        th = float(g[2])
        h = np.array([math.sin(th), math.cos(th)])
        right = np.array([math.cos(th), -math.sin(th)])
        vM, vN = self.v_hat[M], self.v_hat[N]
        s_M = max(D - 0.5 * (self.L[M] + self.L[N]), 0.0) * vM / (vM + vN)
        tangent = g[:2] - s_M * h
        return tangent + self.r_hat[M] * right

    def form_pair(self) -> None:
        """G_1 (App. 3.3), re-planned from the measured poses whenever a stage has no solution.

        The first attempt aims at the nominal G_1 slots. When the transfer has no clear way, D_n finds no
        timed path to its approach line, or the rendezvous keeps missing, the gross motion sigma_1 of
        the pair is planned again from where the robots are (seed App. 3.3: re-plan when D_{n-1} is early
        or late), toward another *pair frame*: the whole target structure turned and shifted as a rigid
        body (success is judged on the shape after a best rigid alignment, SPEC 6). Frames are tried
        nearest the nominal one first, and only those whose station orbit, approach line, departure
        track and later slots are clear of the orbits as measured (:meth:`pair_frames`).
        """
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        lower = self.orbiting_below(n - 1)
        D = self.meet_distance(N, M)
        tried: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)]
        last = ""
        for frame_no in range(self.tune.pair_frames):
            if frame_no > 0:
                frames = [f for f in self.pair_frames(N, M, D, lower) if all(self._far(f, t) for t in tried)]
                if not frames:
                    break
                phi, dx, dy = frames[0]
                tried.append((phi, dx, dy))
                self.set_pair_frame(phi, dx, dy)
                self.replans += 1
                self.log("replan", N,
                         f"G_1 re-planned from the measured poses ({last}): the structure turned {math.degrees(phi):.0f} deg and shifted "
                         f"{math.hypot(dx, dy):.0f} um")
            try:
                c_star = self.station(N, M, D)
                self.transfer(N, M, c_star, D, lower)
                for attempt in range(self.tune.rendezvous_attempts):
                    if self.rendezvous(N, M, D, lower):
                        return
                    self.log("retry", N, f"rendezvous attempt {attempt + 1} missed; {self.scn.names[N]} re-plans its approach")
                raise _Replan(f"G_1 of {self.scn.names[N]} and {self.scn.names[M]} did not form in {self.tune.rendezvous_attempts} "
                              "rendezvous attempts")
            except _Replan as exc:
                last = exc.reason
        raise _Abort(f"G_1 not formed after {len(tried)} pair frame(s); last: {last}")

    @staticmethod
    def _far(a, b) -> bool:
        return abs(angle_difference(a[0], b[0])) > math.radians(10.0) or math.hypot(a[1] - b[1], a[2] - b[2]) > 150.0

    def set_pair_frame(self, phi: float, dx: float, dy: float) -> None:
        """Aim at the nominal structure turned clockwise by ``phi`` about the G_1 junction and shifted by (dx, dy)."""
        self.goals = self.framed_goals(phi, dx, dy)

    def framed_goals(self, phi: float, dx: float, dy: float) -> np.ndarray:
        N, M = self.by_rank[self.n], self.by_rank[self.n - 1]
        g = self.nominal_goals
        junction = 0.5 * (front_midpoints(g[[N]], self.L[[N]])[0] + front_midpoints(g[[M]], self.L[[M]])[0])
        out = se2.rotate_about(g, junction, phi)
        out[:, :2] += np.array([dx, dy])
        return out

    def pair_frames(self, N: int, M: int, D: float, lower) -> list[tuple[float, float, float]]:
        """Candidate pair frames ``(phi_rad, dx_um, dy_um)`` that look feasible from the measured poses, best first.

        A frame passes when, with the structure there: every slot lies inside the arena and clear of the
        orbit of every robot that docks after it; D_{n-1}'s station orbit is clear of the lower orbits and
        the arena edge; D_n's approach run (from its approach pose to its slot) and D_{n-1}'s departure
        track (tangent point to slot) are clear of the lower orbits and the arena edge, with the steering
        clearance. Cost: turning angle (1 um per 0.1 deg) plus shift plus how far D_{n-1} must move.
        """
        saved = self.goals.copy()
        out = []
        rank = self.rank
        orbit_c = turning_centres(self.est, self.r_hat)
        rs = self.rstar
        try:
            for phi_deg in self.tune.frame_turns_deg:
                for dist in self.tune.frame_shifts_um:
                    for ang in (np.arange(0.0, 360.0, 45.0) if dist > 0 else [0.0]):
                        dx, dy = dist * math.sin(math.radians(ang)), dist * math.cos(math.radians(ang))
                        phi = math.radians(phi_deg)
                        g = self.framed_goals(phi, dx, dy)
                        self.goals = g
                        if not self._frame_ok(N, M, D, lower, g, orbit_c, rs, rank):
                            continue
                        c_star = self.station(N, M, D)
                        cost = 10.0 * abs(phi_deg) + dist + 0.3 * float(np.hypot(*(c_star - self.centre(M))))
                        out.append((cost, (phi, dx, dy)))
        finally:
            self.goals = saved
        out.sort(key=lambda t: t[0])
        return [f for _, f in out]

    def _frame_ok(self, N, M, D, lower, g, orbit_c, rs, rank) -> bool:
        n = self.n
        if self.scn.arena_um is not None and (arena_gap(g, self.L, self.W, self.scn.arena_um) < self.tune.frame_slot_clearance_um).any():
            return False
        for a in range(n):
            later = [b for b in range(n) if rank[b] < rank[a]]
            if later and bodies_hit_discs(g[a][None, :], self.L[a], self.W[a], orbit_c[later],
                                          rs[later] + self.tune.frame_slot_clearance_um).any():
                return False
        c_star = self.station(N, M, D)
        if not self.orbits_free(M, c_star[None, :], [], lower, self.tune.frame_slot_clearance_um)[0]:
            return False
        q = self.approach_pose(N, M, c_star, D)
        run = move(q, np.linspace(0.0, float(np.hypot(*(q[:2] - g[N, :2]))), 24), 0.0)
        if self.obstacles_hit(run, N, lower, clearance=self.tune.wall_clearance_um):
            return False
        tangent = pose_on_orbit(c_star, self.r_hat[M], float(g[M, 2]))
        dep = move(tangent, np.linspace(0.0, float(np.hypot(*(tangent[:2] - g[M, :2]))), 16), 0.0)
        return not self.obstacles_hit(dep, M, lower, clearance=self.opts.clearance_um)

    # stage 1: D_{n-1} onto its station orbit ---------------------------------------------------------

    def _turn_together(self, N: int, M: int, t_turn: float, fraction: float) -> None:
        """D_{n-1} turns for ``t_turn`` s (its measured heading decides when it is done) while D_n turns
        ``fraction`` of that wait and then runs straight.

        D_n's turn is closed loop on its measured heading: a long open-loop turn with a turn rate not yet
        identified ends tens of degrees off, and the straight run after it goes astray."""
        n = self.n
        turn = t_turn * self.omega_hat[M]
        turned = 0.0
        n_turn, n_turned = fraction * t_turn * self.omega_hat[N], 0.0
        while True:
            left = (turn - turned) / self.omega_hat[M]
            if left <= 1e-3:
                break
            dt = left if left <= 1.6 * self.tx else self.tx
            a = min(dt, max((n_turn - n_turned) / self.omega_hat[N], 0.0))
            th0, thN0 = self.est[M, 2], self.est[N, 2]
            self.drive([(n, a), (n - 1, dt - a)])
            n_turned += float(np.mod(self.est[N, 2] - thN0 + 0.5, TWO_PI)) - 0.5
            turned += float(np.mod(self.est[M, 2] - th0 + 0.5, TWO_PI)) - 0.5
            if dt == left:
                break

    def transfer(self, N: int, M: int, c_star: np.ndarray, D: float, lower) -> None:
        """Stage 1: move D_{n-1}'s orbit to ``c_star`` in straight legs, D_n kept clear (see :meth:`form_pair`).

        Each leg: D_{n-1} orbits until it heads along the leg, then drives straight (P_{n-2}), which drives
        D_n straight too. D_n's track is either what it does anyway (it turns with D_{n-1} for a chosen
        fraction of the wait, then runs straight: :meth:`transfer_option`) or a track chosen for it
        (:meth:`transfer_run`), which D_n reaches first, timed to D_{n-1}'s departure. A leg too long for
        any clear track is shortened (900, 600, 400 um) when D_{n-1} can orbit at its end.
        """
        q_next = self.approach_pose(N, M, c_star, D)
        route = self.station_route(M, c_star, lower)
        for w in route[:-1]:
            self.log("transfer", M, f"{self.scn.names[M]}'s way to its station is blocked: it goes via an orbit at "
                                    f"({w[0]:.0f}, {w[1]:.0f}) um")
            self.transfer_leg(N, M, w, q_next, lower, final=False)
        self.transfer_leg(N, M, c_star, q_next, lower, final=True)

    def station_route(self, M: int, c_star: np.ndarray, lower) -> list[np.ndarray]:
        """Orbit centres D_{n-1} moves through to ``c_star`` (:func:`~stressbots.control.station.orbit_route`),
        clear of the lower orbits and the arena edge; ``[c_star]`` (one straight move) when there is no route."""
        cl = self.opts.clearance_um + 10.0  # transfer_option's check of D_{n-1}'s track
        cs = turning_centres(self.est[lower], self.r_hat[lower]) if lower else np.zeros((0, 2))
        rs = self.rstar[lower] if lower else np.zeros(0)
        route = orbit_route(self.centre(M), np.asarray(c_star, float), float(self.rstar[M]), cs, rs, self.scn.arena_um,
                            clearance=cl, spacing_um=self.tune.station_grid_um, leg_cost_um=self.tune.station_leg_cost_um)
        return route if route else [np.asarray(c_star, float)]

    def transfer_leg(self, N: int, M: int, c_star: np.ndarray, q_next, lower, *, final: bool) -> None:
        """Move D_{n-1}'s orbit to ``c_star`` (one stage of :meth:`transfer`); an intermediate orbit of a
        route (``final`` False) counts as reached within ``Tuning.station_tol_um``."""
        failed_runs = 0
        for attempt in range(8):
            cM = self.centre(M)
            d_vec = c_star - cM
            d = float(np.hypot(*d_vec))
            if d <= (self.tune.via_tol_um if attempt == 0 or not final else self.tune.station_tol_um):
                break
            u = d_vec / d
            th_dep = float(np.mod(math.atan2(u[0], u[1]) - math.radians(3.0), TWO_PI))
            t_turn = float(np.mod(th_dep - self.est[M, 2], TWO_PI)) / self.omega_hat[M]
            plan = tight = None
            why = f"{self.scn.names[N]} has no clear straight track while {self.scn.names[M]} moves {d:.0f} um to its station orbit"
            for leg in sorted({d, min(d, 900.0), min(d, 600.0), min(d, 400.0), min(d, 250.0)}, reverse=True):
                c_next = cM + leg * u
                if leg < d - 1.0 and not self.orbits_free(M, c_next[None, :], [], lower, 10.0)[0]:
                    continue
                try:
                    opt = self.transfer_option(N, M, t_turn, leg, th_dep, lower, c_next, q_next)
                except _Replan as exc:  # D_{n-1}'s own track is blocked this far: a shorter leg may clear
                    why = exc.reason
                    continue
                if opt is not None and opt[1] < 1e4:
                    plan = ("turn", opt[0], leg, c_next)
                    break
                start = self.transfer_run(N, M, leg, th_dep, lower, c_next, q_next)
                if start is not None:
                    plan = ("run", start, leg, c_next)
                    break
                if opt is not None:  # clear, though it leaves D_n in a tight spot: the shortest such leg
                    tight = ("turn", opt[0], leg, c_next)
            plan = plan or tight
            if plan is None:
                raise _Replan(why)
            kind, arg, leg, c_next = plan
            self.replans += 1
            if kind == "turn":
                self.log("transfer", M,
                         f"{self.scn.names[M]} moves its orbit {leg:.0f} um; {self.scn.names[N]} turns {arg:.0%} of the wait, then runs "
                         "straight")
                self._turn_together(N, M, t_turn, arg)
            else:
                self.log("transfer", M, f"{self.scn.names[M]} moves its orbit {leg:.0f} um; {self.scn.names[N]} first takes a clear track")
                if not self.arrive_timed(N, M, lambda arg=arg: arg, th_dep, lower):
                    # D_{n-1} still orbits where it was: choose again from where D_n is now
                    self.log("retry", N, f"{self.scn.names[N]} could not reach its track in time; the leg is planned again")
                    failed_runs += 1
                    if failed_runs >= 4:
                        raise _Replan(f"{self.scn.names[N]} cannot reach a clear track in time for {self.scn.names[M]}'s move")
                    continue
                self.wait_straight(M, th_dep)
            self.straight_leg(N, M, c_next, lower)
        if final:
            miss = float(np.hypot(*(c_star - self.centre(M))))
            self.log("station", M, f"{self.scn.names[M]} orbits {miss:.0f} um from its station")

    def wait_straight(self, M: int, th_dep: float) -> None:
        """D_n straight (P_{n-1}) while D_{n-1} orbits on to heading ``th_dep``."""
        n = self.n
        for _ in range(40):
            left = (float(np.mod(th_dep - self.est[M, 2] + 0.1, TWO_PI)) - 0.1) / self.omega_hat[M]
            if left <= 1e-3:
                return
            if left <= 1.6 * self.tx:
                self.drive([(n - 1, left)])
                return
            self.drive([(n - 1, self.tx)])

    def straight_leg(self, N: int, M: int, c_next, lower) -> None:
        """D_{n-1} straight (P_{n-2}) until its turning centre reaches ``c_next``; clockwise bearing fixes."""
        n = self.n
        for _ in range(200):
            c = self.centre(M)
            to = c_next - c
            h = np.array([math.sin(self.est[M, 2]), math.cos(self.est[M, 2])])
            rem = float(to @ h)
            if rem <= 5.0:
                return
            bearing = float(angle_difference(math.atan2(to[0], to[1]), self.est[M, 2]))
            steps = []
            if rem > 60.0 and math.radians(0.7) < bearing < math.radians(30.0):
                steps.append((n - 1, bearing / self.omega_hat[M]))
            dt = rem / self.v_hat[M]
            if dt > 1.6 * self.tx:
                dt = self.tx
            steps.append((n - 2, dt))
            if not self.track_clear(N, sum(d for _, d in steps) * self.v_hat[N] + 40.0, lower):
                self.log("transfer", N, f"{self.scn.names[N]}'s track runs out; {self.scn.names[M]} stops short and moves on from there")
                return
            self.drive(steps)

    def transfer_run(self, N: int, M: int, leg: float, th_dep: float, lower, c_next, q_next) -> np.ndarray | None:
        """A start pose for D_n's straight track during a leg of D_{n-1}, reachable in time; or None.

        Candidates: starts on a 150 um grid, 16 headings. A track is a timing buffer (1.2 s, driven while
        D_{n-1} still orbits: clear of its orbit) and then the leg (synchronous with D_{n-1}'s straight:
        bodies apart), all clear of the other orbits and the arena edge, ending clear of D_{n-1}'s new
        orbit. The cheapest to reach (plus a pull toward the next target) that a timed path reaches wins.
        """
        vN, vM = float(self.v_hat[N]), float(self.v_hat[M])
        c = self.tune.wall_clearance_um + 5.0  # the timed path's checks use self.tune.wall_clearance_um: keep the track inside them
        buf = self.tune.early_s * vN
        run_len = buf + leg * vN / vM * 1.15 + 40.0
        if self.scn.arena_um is None:
            return None
        w, h = self.scn.arena_um
        xs, ys = np.arange(75.0, w, 150.0), np.arange(75.0, h, 150.0)
        heads = np.radians(np.arange(0.0, 360.0, 22.5))
        X, Y, T = np.meshgrid(xs, ys, heads, indexing="ij")
        starts = np.stack([X.ravel(), Y.ravel(), T.ravel()], axis=1)
        s = np.arange(0.0, run_len + 1e-9, 40.0)
        K = len(s)
        hv = np.stack([np.sin(starts[:, 2]), np.cos(starts[:, 2])], axis=1)
        samples = np.empty((len(starts), K, 3))
        samples[:, :, :2] = starts[:, None, :2] + s[None, :, None] * hv[:, None, :]
        samples[:, :, 2] = starts[:, None, 2]
        flat = samples.reshape(-1, 3)
        bad = arena_gap(flat, self.L[N], self.W[N], (w, h)).reshape(len(starts), K) < c
        centres = [*turning_centres(self.est[lower], self.r_hat[lower])] if lower else []
        radii = [float(x) + c for x in self.rstar[lower]] if lower else []
        if centres:
            bad |= bodies_hit_discs(flat, self.L[N], self.W[N], np.array(centres), np.array(radii)).any(axis=1).reshape(len(starts), K)
        ok = ~bad.any(axis=1)
        cM = self.centre(M)
        # buffer: clear of D_{n-1}'s current orbit; end: clear of its new one
        nb = int(np.searchsorted(s, buf)) + 1
        ok &= ~bodies_hit_discs(samples[:, :nb].reshape(-1, 3), self.L[N], self.W[N], cM[None, :],
                                np.array([self.rstar[M] + c])).reshape(len(starts), nb).any(axis=1)
        ok &= ~bodies_hit_discs(samples[:, -1], self.L[N], self.W[N], np.asarray(c_next)[None, :], np.array([self.rstar[M] + 40.0]))[:, 0]
        # room for D_n to orbit (wait, or turn away) where its track ends
        end_c = turning_centres(samples[:, -1], self.r_hat[N])
        ok &= self.orbits_free(N, end_c, [(np.asarray(c_next), self.rstar[M] + self.tune.g1_clearance_um - self.tune.wall_clearance_um)],
                               lower, self.tune.wall_clearance_um)
        idx = np.flatnonzero(ok)
        if len(idx) == 0:
            return None
        # cheapest first (to reach, plus a pull toward the next target); then the synchronous check
        ends = samples[idx, -1]
        cost = pathlib.shortest_path_lengths(np.broadcast_to(self.est[N], (len(idx), 3)), starts[idx],
                                             self.r_hat[N]) + 0.5 * np.hypot(*(ends[:, :2] - np.asarray(q_next)[:2]).T)
        idx = idx[np.argsort(cost)]
        mdep = pose_on_orbit(cM, self.r_hat[M], th_dep)
        tm = np.arange(0.0, leg / vM + 1.0, 0.4)
        m_track = move(mdep, vM * tm, 0.0)
        n_s = buf + vN * tm
        keep = []
        for j in idx:
            # D_n may be up to 0.6 s early or late on its track: bodies apart for all three timings
            n_track = move(starts[j], np.maximum(np.concatenate([n_s, n_s - 0.6 * vN, n_s + 0.6 * vN]), 0.0), 0.0)
            if not (penetration_depth(n_track, self.L[N], self.W[N], np.tile(m_track, (3, 1)), self.L[M], self.W[M]) > -c).any():
                keep.append(j)
                if len(keep) >= 12:
                    break
        if not keep:
            return None
        disc = [(cM, self.rstar[M])]
        t_dep = float(np.mod(th_dep - self.est[M, 2], TWO_PI)) / self.omega_hat[M]
        period = TWO_PI / self.omega_hat[M]
        arrivals = [a for a in (t_dep + k * period - self.tune.early_s for k in range(3)) if a > 0.3]
        for j in keep:
            if self.loiter_path(N, starts[j], arrivals, lower, disc, tol_s=0.5) is not None:
                return starts[j]
        return starts[keep[0]]  # no timed path from here: D_n will wait on a free orbit first

    def transfer_option(self, N: int, M: int, t_turn: float, d: float, th_dep: float, lower, c_star, q_next):
        """``(fraction, cost)``: of D_{n-1}'s turn, D_n turns with it for the fraction (then runs straight); or None.

        Every fraction whose motion keeps D_n clear of the orbits, the arena edge and D_{n-1} (its orbit
        while it turns, its body while both drive straight, its new orbit afterwards) is a candidate; the
        one leaving D_n the shortest path to its next target ``q_next`` wins; the cost adds 1e5 um when that
        path is blocked and 1e4 um when D_n has no room to wait on its orbit there.
        """
        vN, rN, vM = self.v_hat[N], self.r_hat[N], self.v_hat[M]
        c = self.opts.clearance_um + 10.0
        t_straight = d / vM + 1.0
        mdep = pose_on_orbit(self.centre(M), self.r_hat[M], th_dep)
        s_m = np.linspace(0.0, vM * t_straight, 60)
        m_track = move(mdep, s_m, 0.0)
        if self._blocked(m_track, M, lower, c):
            raise _Replan(f"{self.scn.names[M]}'s straight move to its station orbit is blocked")
        m_disc = [(self.centre(M), self.rstar[M] + c)]
        new_disc = [(np.asarray(c_star, float), self.rstar[M] + 40.0)]
        best, best_len = None, math.inf
        for f in np.linspace(0.0, 1.0, 17):
            a = vN * f * t_turn
            b = vN * (1.0 - f) * t_turn
            arc = move(self.est[N], np.linspace(0.0, a, max(2, int(a / 10.0) + 2)), 1.0 / rN)
            run = move(arc[-1], np.linspace(0.0, b, max(2, int(b / 10.0) + 2)), 0.0)
            if self._blocked(np.vstack([arc, run]), N, lower, c, discs=m_disc):
                continue
            # synchronous with D_{n-1}'s straight: same times, bodies apart; then clear of its new orbit
            n_track = move(run[-1], s_m * vN / vM * 1.15, 0.0)
            if self._blocked(n_track, N, lower, c):
                continue
            if (penetration_depth(n_track, self.L[N], self.W[N], m_track, self.L[M], self.W[M]) > -c).any():
                continue
            end = move(run[-1], vN * d / vM, 0.0)
            if self._blocked(end[None, :], N, lower, c, discs=new_disc):
                continue
            nxt = pathlib.shortest_path(end, np.asarray(q_next, float), rN, approach_um=60.0)
            ell = nxt.length
            # prefer a clear way on, and room to wait on D_n's own orbit there (its timing reserve)
            if self._blocked(nxt.sample(10.0), N, lower, 0.0, discs=new_disc):
                ell += 1e5
            # room to orbit where the run ends, also if it runs long (speed error, drift): a robot that
            # meets the arena edge while turning is trapped there
            late = move(end, self.tune.track_overshoot * (b + vN * d / vM) + 40.0, 0.0)
            loops = np.vstack([move(e, np.linspace(0.0, TWO_PI * rN, 40), 1.0 / rN) for e in (end, late)])
            if self._blocked(loops, N, lower, self.opts.clearance_um, discs=new_disc):
                ell += 1e4
            if ell < best_len:
                best, best_len = float(f), ell
        return None if best is None else (best, best_len)

    def _blocked(self, samples: np.ndarray, i: int, lower, clearance: float, discs=()) -> bool:
        """Like :meth:`obstacles_hit`, but ``discs`` are kept clear of by their own radius, without ``clearance``."""
        return self.obstacles_hit(samples, i, lower, extra_discs=[(c, r - clearance) for c, r in discs], clearance=clearance)

    def track_clear(self, N: int, length: float, lower) -> bool:
        track = move(self.est[N], np.linspace(0.0, max(length, 1.0), 30), 0.0)
        return not self._blocked(track, N, lower, 0.0)

    # stage 2: the rendezvous -------------------------------------------------------------------------

    def loiter_path(self, N: int, target, arrivals: Sequence[float], lower, disc, tol_s: float = 0.3):
        """D_n waits on its own orbit, then takes its shortest path into the region around ``target``.

        Waiting on its own orbit (P_n: D_{n-1} orbits too) is the compact way for a one-way robot to
        arrive later: every arrival time from the shortest path's on to a period later is (almost always)
        available, and the path stays near where the robot is. The goal is a region, not a pose: any
        pose up to 100 um along D_n's approach line (timed accordingly), up to 40 um right or 20 um left
        of it and 6 deg either way will do, because D_{n-1}'s departure is fitted to the line D_n really
        ends on. A pose target would turn a small error to the left into a full loop. The first of
        ``arrivals`` (s from now, for ``target`` itself) that some wait meets within ``tol_s`` with a
        clear path wins; of those, the one nearest ``target``. Returns ``(path, goal, offset_s, arrival_s,
        loop)`` (``loop`` = (radius_um, count) of interpolated loops to drive first, or None) or None.
        """
        vN, rN = self.v_hat[N], self.r_hat[N]
        q = np.asarray(target, float)
        hq = np.array([math.sin(q[2]), math.cos(q[2])])
        rq = np.array([math.cos(q[2]), -math.sin(q[2])])
        grid = np.meshgrid([0.0, -50.0, 50.0, -100.0, 100.0], [0.0, 20.0, -20.0, 40.0], np.radians([0.0, 3.0, -3.0, 6.0, -6.0]),
                           indexing="ij")
        s, e, d = (g.ravel() for g in grid)
        goals = np.stack([q[0] + s * hq[0] + e * rq[0], q[1] + s * hq[1] + e * rq[1], np.mod(q[2] + d, TWO_PI)], axis=1)
        offset = s / vN  # further along the line: arrive correspondingly later
        penalty = np.abs(s) / 100.0 + np.abs(e) / 40.0 + np.abs(d) / math.radians(6.0)
        period = TWO_PI * rN / vN
        # a straight of a um first, then a wait of tw s on the orbit: the shortest path's length jumps by a
        # loop as the wait passes its first turn, and the straights fill those gaps in arrival time
        pre = np.array([0.0, 100.0, 200.0, 350.0, 500.0])
        tw = np.arange(0.0, period, 0.05)
        A, Tw = np.meshgrid(pre, tw, indexing="ij")
        A, Tw = A.ravel(), Tw.ravel()
        waits = move(move(self.est[N], A, 0.0), vN * Tw, 1.0 / rN)
        W, K = len(Tw), len(goals)
        ell = pathlib.shortest_path_lengths(np.repeat(waits, K, axis=0), np.tile(goals, (W, 1)), rN, approach_um=60.0).reshape(W, K)
        arr = (A / vN + Tw)[:, None] + ell / vN - offset[None, :]
        for want in arrivals:
            err = np.abs(arr - want)
            score = np.where(err <= tol_s, err + 0.1 * penalty[None, :] + 0.002 * A[:, None] / vN, np.inf).ravel()
            for flat in np.argsort(score)[:10]:
                if not np.isfinite(score[flat]):
                    break
                j, kk = divmod(int(flat), K)
                tail = pathlib.shortest_path(waits[j], goals[kk], rN, approach_um=60.0)
                segs = tuple(tail.segments)
                if Tw[j] > 0:
                    if segs and segs[0][0] == "R":
                        segs = (("R", segs[0][1] + vN * Tw[j]),) + segs[1:]
                    else:
                        segs = (("R", vN * Tw[j]),) + segs
                if A[j] > 0:
                    segs = (("S", float(A[j])),) + segs
                path = pathlib.Path(self.est[N], rN, segs)
                if not self.obstacles_hit(path.sample(10.0), N, lower, extra_discs=self._tight(disc),
                                          clearance=self.tune.wall_clearance_um):
                    return path, goals[kk], float(offset[kk]), float(want), None
        # Waiting on the orbit only shifts arrival times in steps (it eats into the path's first turn, then
        # costs a whole loop). One or two interpolated loops of radius R in [r, 1.6 r] (P_n / P_{n-1}
        # alternating) end where they began after 2 pi R / v: every arrival time in a window wider than
        # D_{n-1}'s period, continuously.
        ell0 = pathlib.shortest_path_lengths(np.broadcast_to(self.est[N], goals.shape), goals, rN, approach_um=60.0)
        radii = np.linspace(rN, 1.6 * rN, 61)
        for want in arrivals:
            for m in (1, 2):
                arr = m * TWO_PI * radii[:, None] / vN + ell0[None, :] / vN - offset[None, :]
                err = np.abs(arr - want)
                score = np.where(err <= tol_s, err + 0.1 * penalty[None, :] + 0.01 * radii[:, None] / rN, np.inf).ravel()
                for flat in np.argsort(score)[:6]:
                    if not np.isfinite(score[flat]):
                        break
                    jr, kk = divmod(int(flat), K)
                    R = float(radii[jr])
                    loop = move(self.est[N], np.linspace(0.0, TWO_PI * R, 72), 1.0 / R)
                    tail = pathlib.shortest_path(self.est[N], goals[kk], rN, approach_um=60.0)
                    if self.obstacles_hit(np.vstack([loop, tail.sample(10.0)]), N, lower, extra_discs=self._tight(disc),
                                          clearance=self.tune.wall_clearance_um):
                        continue
                    return tail, goals[kk], float(offset[kk]), float(want), (R, m)
        return None

    def _tight(self, disc, clearance: float | None = None):
        """D_{n-1}'s orbit disc(s) shrunk so that checks at ``Tuning.wall_clearance_um`` keep ``clearance``
        (default ``Tuning.g1_clearance_um``) from them."""
        clearance = self.tune.g1_clearance_um if clearance is None else clearance
        return [(c, r - self.tune.wall_clearance_um + clearance) for c, r in disc]

    def continued(self, N: int, arrivals: Sequence[float], lower, disc) -> pathlib.Path | None:
        """The last plan's goal, re-planned from the measured pose, if its timing still holds (plans persist).

        Without this, a plan that becomes marginally infeasible (a graze with an orbit, an arrival just
        outside the tolerance) would be replaced by a different one every t_x.
        """
        if self._plan is None:
            return None
        goal, offset, t_abs = self._plan
        vN, rN = self.v_hat[N], self.r_hat[N]
        want = min(arrivals, key=lambda a: abs(self.t + a - t_abs)) if arrivals else None
        if want is None or abs(self.t + want - t_abs) > 1.0:
            return None
        path = pathlib.shortest_path(self.est[N], goal, rN, approach_um=60.0)
        if abs(path.length / vN - offset - want) > 0.5:
            return None
        if self.obstacles_hit(path.sample(10.0), N, lower, extra_discs=self._tight(disc, 0.0), clearance=self.tune.wall_clearance_um - 5.0):
            return None
        self._plan = (goal, offset, self.t + want)
        return path

    def approach_pose(self, N: int, M: int, centre, D: float, early: float | None = None) -> np.ndarray:
        """Where D_n aims: on the tangent of D_{n-1}'s orbit (about ``centre``) leading to D_{n-1}'s slot,
        facing it, ``D`` plus ``early`` seconds (default ``Tuning.early_s``) of driving from the tangent point."""
        early = self.tune.early_s if early is None else early
        th_dep = float(self.goals[M, 2])
        tangent = pose_on_orbit(centre, self.r_hat[M], th_dep)
        h = np.array([math.sin(th_dep), math.cos(th_dep)])
        return np.array([*(tangent[:2] + (D + self.v_hat[N] * early) * h), np.mod(th_dep + math.pi, TWO_PI)])

    def rendezvous(self, N: int, M: int, D: float, lower) -> bool:
        th_dep = float(self.goals[M, 2])
        if not self.arrive_timed(N, M, lambda: self.approach_pose(N, M, self.centre(M), D), th_dep, lower):
            raise _Replan(f"{self.scn.names[N]} found no timed path to its approach line")
        return self.depart_and_meet(N, M)

    def arrive_timed(self, N: int, M: int, target_fn, th_dep: float, lower, early: float | None = None) -> bool:
        """D_n drives to ``target_fn()`` (a pose on a line it then runs straight along), arriving ``early``
        seconds before D_{n-1}, orbiting, reaches heading ``th_dep``. Replanned every t_x; the last leg
        runs whole. False if no timed way exists even from a holding orbit.
        """
        early = self.tune.early_s if early is None else early
        n = self.n
        self._plan = None
        holds = 0
        prev = None
        for _ in range(600):
            vN = self.v_hat[N]
            q = target_fn()
            disc = [(self.centre(M), self.rstar[M])]
            t_dep = float(np.mod(th_dep - self.est[M, 2], TWO_PI)) / self.omega_hat[M]
            period = TWO_PI / self.omega_hat[M]
            arrivals = [a for a in (t_dep + k * period - early for k in range(4)) if a > 0.3]
            path = self.continued(N, arrivals, lower, disc)
            if path is None and prev is not None and prev.length - vN * self.tx <= self.tune.final_leg_s * vN:
                # the final seconds: a small error can make the replanned path a loop (one-way robot);
                # the rest of the plan, driven open loop, misses by a few um at most
                rest = pathlib.sub_path(prev, min(vN * self.tx, prev.length), prev.length)
                self.log("final", N, f"{self.scn.names[N]} drives the last {rest.length:.0f} um of its plan open loop")
                self.drive(self.path_steps(rest, vN, n, n - 1, None))
                return True
            loop = None
            for tol in (0.3, 0.7):
                if path is not None:
                    break
                found = self.loiter_path(N, q, arrivals, lower, disc, tol_s=tol)
                path = None if found is None else found[0]
                self._plan = None if found is None else (found[1], found[2], self.t + found[3])
                loop = None if found is None else found[4]
            if loop is not None:
                R, m = loop
                self.log("loop", N, f"{self.scn.names[N]} circles {m} time(s) at radius {R:.0f} um to arrive on time")
                self.replans += 1
                total = m * TWO_PI * R / vN
                while total > 1e-6:  # the loop, a t_x at a time (it ends where it began)
                    d = min(self.tx, total)
                    self.drive(self.interpolated_steps(float(self.r_hat[N] / R), d, n, n - 1))
                    total -= d
                prev = None
                continue
            prev = path
            if path is None:
                # no timed way from here: go where D_n can wait on its orbit near the target, then retry
                holds += 1
                if holds > 3 or not self.to_holding(N, q, lower, disc):
                    return False
                continue
            self.replans += 1
            whole = path.length / vN <= 1.6 * self.tx
            self.drive(self.path_steps(path, vN, n, n - 1, None if whole else self.tx))
            if whole:
                return True
        return False

    def orbits_free(self, i: int, centres, discs, lower, clearance: float) -> np.ndarray:
        """Mask (K,): robot ``i`` could orbit about each of ``centres`` (K, 2) without meeting the arena edge,
        a lower robot's orbit, ``discs`` or a docked body (with ``clearance``)."""
        c = np.atleast_2d(np.asarray(centres, dtype=np.float64))
        rs = float(self.rstar[i])
        ok = np.ones(len(c), dtype=bool)
        if self.scn.arena_um is not None:
            w, h = self.scn.arena_um
            ok &= (c[:, 0] >= rs + clearance) & (c[:, 0] <= w - rs - clearance)
            ok &= (c[:, 1] >= rs + clearance) & (c[:, 1] <= h - rs - clearance)
        others = [*zip(turning_centres(self.est[lower], self.r_hat[lower]), self.rstar[lower], strict=True)] if lower else []
        for cc, rr in [*others, *discs]:
            ok &= np.hypot(*(c - cc).T) >= rs + float(rr) + clearance
        for j in np.flatnonzero(self.docked):
            ok &= point_rectangle_distance(c, self.est[j][None, :], self.L[j], self.W[j])[0] >= rs + clearance
        return ok

    def free_orbits(self, i: int, discs, lower, clearance: float = 15.0) -> np.ndarray:
        """Centres (K, 2) on a 100 um grid where robot ``i`` can orbit without meeting anything."""
        rs = float(self.rstar[i])
        if self.scn.arena_um is not None:
            lo, (w, h) = np.zeros(2), self.scn.arena_um
        else:
            lo = self.est[:, :2].min(axis=0) - 1500.0
            w, h = self.est[:, :2].max(axis=0) - lo + 1500.0
        xs = lo[0] + np.arange(rs + clearance, w - rs - clearance + 1e-9, 100.0)
        ys = lo[1] + np.arange(rs + clearance, h - rs - clearance + 1e-9, 100.0)
        if len(xs) == 0 or len(ys) == 0:
            return np.zeros((0, 2))
        cx, cy = np.meshgrid(xs, ys)
        c = np.stack([cx.ravel(), cy.ravel()], axis=1)
        return c[self.orbits_free(i, c, discs, lower, clearance)]

    def to_holding(self, N: int, q, lower, disc) -> bool:
        """Take D_n (untimed) onto a free orbit near ``q``, from which any arrival time is a wait away."""
        n = self.n
        # the same clearances as the timed paths' checks, so that waiting there passes them
        free = self.free_orbits(N, [(c, r + self.tune.g1_clearance_um - self.tune.wall_clearance_um - 5.0) for c, r in disc], lower,
                                clearance=self.tune.wall_clearance_um + 5.0)
        if len(free) == 0:
            return False
        rN = self.r_hat[N]
        heads = np.radians(np.arange(0.0, 360.0, 30.0))
        poses = np.concatenate([np.stack([free[:, 0] - rN * math.cos(t), free[:, 1] + rN * math.sin(t), np.full(len(free), t)],
                                         axis=1) for t in heads])
        # near the target, with a clear way on to it (the way there may be routed around obstacles)
        cost = 0.3 * pathlib.shortest_path_lengths(np.broadcast_to(self.est[N], poses.shape), poses, rN) + pathlib.shortest_path_lengths(
            poses, np.broadcast_to(np.asarray(q, float), poses.shape), rN, approach_um=60.0
        )
        order = np.argsort(cost)[:12]
        onward = [j for j in order if not self.obstacles_hit(pathlib.shortest_path(poses[j], q, rN, approach_um=60.0).sample(10.0), N,
                                                             lower, extra_discs=self._tight(disc), clearance=self.tune.wall_clearance_um)]
        hold = poses[onward[0] if onward else order[0]]
        self.log("hold", N,
                 f"{self.scn.names[N]} heads for a free orbit {np.hypot(*(hold[:2] - q[:2])):.0f} um from its target, to wait there")
        self.steer(N, hold, n, n - 1, lower, extra_discs=disc, max_cycles=120, clearance=self.tune.g1_clearance_um)
        return not self._stuck

    def depart_and_meet(self, N: int, M: int) -> bool:
        """D_n runs straight until D_{n-1} reaches the departure heading that best lines them up; both meet."""
        n = self.n
        for _ in range(40):
            best = self.best_departure(N, M)
            if best is None:
                self.log("miss", N, f"{self.scn.names[N]} is not on a line {self.scn.names[M]} can leave its orbit along")
                self.drive([(n, 0.5 * math.pi / self.omega_hat[N])])  # turn away from the orbit
                return False
            t_wait, cost = best
            if t_wait <= 1.6 * self.tx:
                self.drive([(n - 1, t_wait)])
                break
            self.drive([(n - 1, self.tx)])
        self.log("depart", M, f"{self.scn.names[M]} leaves its orbit toward {self.scn.names[N]}")
        for _ in range(60):
            before = self.est[[N, M]].copy()
            self.drive([(n - 2, self.tx)])
            moved = np.hypot(*(self.est[[N, M], :2] - before[:, :2]).T)
            if (moved < 0.2 * self.v[[N, M]] * self.tx).all():
                ends = front_midpoints(self.est[[N, M]], self.L[[N, M]])
                gap = float(np.hypot(*(ends[0] - ends[1])))
                if gap < self.tune.meet_gap_um:
                    self.drive([(n - 2, self.opts.push_s)])
                    self.docked[[N, M]] = True
                    for _ in range(4):  # frames of the still pair: its pose estimate is their mean
                        self.drive([(n - 2, 0.5)])
                    self.log("G_1", N, f"formed with {self.scn.names[M]} (front edges {gap:.1f} um apart)")
                    self.retarget(N, M)
                    return True
                self.log("stuck", N, f"the pair stopped {gap:.0f} um apart (failure region H)")
                raise _Abort(f"the G_1 pair stopped {gap:.0f} um apart (failure region H)")
        raise _Abort("G_1 did not form: the pair drove past each other")

    def best_departure(self, N: int, M: int):
        """``(wait_s, cost)`` of D_{n-1}'s best departure toward D_n as measured (:func:`~stressbots.control.queries.best_departure`)."""
        return best_departure(
            self.est[N], self.v_hat[N], self.L[N], self.centre(M), self.r_hat[M], self.est[M, 2], self.omega_hat[M],
            self.v_hat[M], self.L[M], self.rstar[M], self.tune.departure_cost_max,
        )

    def retarget(self, N: int, M: int) -> None:
        """Move the remaining slots with the rigid motion the pair actually took (SPEC 6)."""
        g = self.nominal_goals
        nom_axis = g[M, :2] - g[N, :2]
        meas_axis = self.est[M, :2] - self.est[N, :2]
        phi = math.atan2(meas_axis[0], meas_axis[1]) - math.atan2(nom_axis[0], nom_axis[1])  # clockwise angle
        c_nom = 0.5 * (g[M, :2] + g[N, :2])
        c_meas = 0.5 * (self.est[M, :2] + self.est[N, :2])
        cph, sph = math.cos(phi), math.sin(phi)
        self._motion = (phi, c_nom, c_meas)
        rest = [i for i in range(self.n) if not self.docked[i]]
        for i in rest:
            d = g[i, :2] - c_nom
            # clockwise rotation by phi (theta is clockwise from +y)
            rot = np.array([d[0] * cph + d[1] * sph, -d[0] * sph + d[1] * cph])
            self.goals[i, :2] = c_meas + rot
            self.goals[i, 2] = np.mod(g[i, 2] + phi, TWO_PI)
        self.goals[N] = self.est[N]
        self.goals[M] = self.est[M]
        if abs(math.degrees(phi)) > 0.5 or np.hypot(*(c_meas - c_nom)) > 5.0:
            self.log("retarget", None,
                     f"G_1 formed {np.hypot(*(c_meas - c_nom)):.1f} um / {math.degrees(phi):.1f} deg from nominal; later slots follow it")

    # -- the whole assembly ---------------------------------------------------------------------------

    def run(self) -> str | None:
        phases = self.pr.phases
        try:
            self.form_pair()
            for k in range(self.n - 2, 0, -1):
                i = self.by_rank[k]
                route = next((p for p in phases if p.kind == "route" and p.mover == i), None)
                self.dock_single(k, route)
        except _Abort as exc:
            return exc.reason
        return None


def assemble(scenario, plant, *, seed: int | None = None, plan=None, time_budget_s: float | None = None,
             options: ControllerOptions | None = None) -> AssemblyResult:
    """Assemble ``scenario``'s structure through ``plant`` in closed loop (seed Appendix 3).

    Parameters
    ----------
    scenario:
        The scenario (robots, design, target structure, ``[control]`` settings).
    plant:
        Anything with ``observe()`` and ``apply(waveform)`` (:class:`stressbots.control.Plant`).
    seed:
        Recorded in the result (the controller itself is deterministic; the plant has its own seed).
    plan:
        A nominal :class:`stressbots.planning.PlanResult` to follow (computed when None; Monte Carlo
        runs share one).
    time_budget_s:
        Simulated time budget (overrides ``options``).
    """
    from dataclasses import replace

    from ..planning import PlanResult

    opts = options or ControllerOptions()
    if time_budget_s is not None:
        opts = replace(opts, time_budget_s=float(time_budget_s))
    no_plan = None
    if plan is None:
        try:
            plan = nominal_plan(scenario)
        except PlanningError as exc:
            # the controller needs the slots, not the nominal schedule: it re-plans everything from the
            # measured poses (G_1 as a rendezvous, single robots by routing); only the routes' hints are lost
            no_plan = str(exc)
            plan = structure_targets(scenario)
    if not isinstance(plan, (PlanResult, Targets)):
        raise TypeError("plan must be a PlanResult from stressbots.planning.plan_assembly")
    run = _Runner(scenario, plant, plan, opts, seed)
    if no_plan is not None:
        run.log("no-plan", None, f"the planner found no nominal plan ({no_plan}); the controller plans from the measured poses alone")
    failure = run.run()
    return judge_run(scenario, plant, seed=seed, failure=failure, estimates=run.est, goals=run.goals,
                     nominal_goals=run.nominal_goals, docked=run.docked, shape_tol_um=opts.shape_tol_um, duration_s=run.t,
                     replans=run.replans, events=run.events, trace_t=run.trace_t, trace_poses=run.trace_p)
