"""Closed-loop assembly under control error: the two-step EDR strategy of seed Appendix 3.

The controller talks to the robots only through a :class:`stressbots.control.Plant` (``observe`` and
``apply``). It follows the phases of a nominal plan (:func:`stressbots.planning.plan_assembly`) but never
trusts them blindly: every ``replan_interval_s`` (t_x) it measures the poses and replans the moving
robot's motion from where it really is.

**Gross motion (sigma_1).** The mover steers toward its phase target (a roadmap waypoint, the start of
D_n's next run, a cut point of D_{n-1}'s route, or the intermediate pose a_i behind a slot): a shortest
one-way path from the measured pose, checked against the orbit discs, the structure and the arena (a new
roadmap route when it is blocked), of which one t_x is executed before measuring again. Once the target
is within one t_x, the rest is executed and the next target taken.

**Fine motion (sigma_2).** From a_i (outside the proximity region C_O) a docking robot D_i drives an
interpolated turn (S_2f: P_i for a fraction rho_a, P_{i-1} for rho_b, SPEC 8's corrected
``r' = r (1 + rho_b / rho_a)``) whose radius, recomputed from every measurement with the corrected seed
eq. 1, passes through its docking point. The arrival angle that leaves is absorbed by docking compliance
(the +-45 deg sticking cone). The G_1 pair closes with the three-primitive S_3f (P_n, P_{n-1}, P_{n-2};
``r'_n = r (1 + (rho_b + rho_c) / rho_a)`` and ``r'_{n-1} = r (1 + rho_c / (rho_a + rho_b))``) when both
arcs are realisable, else both drive straight; self-aligning compliance absorbs |alpha| < 60 deg and
|w_y| < 80 um.

**G_1 (App. 3.3).** D_n is not corrected during its straight runs (it cannot be: it drives straight
while D_{n-1} moves). When D_{n-1} is late, D_n would overrun its track: the controller then inserts a
loop (D_n drives back to its run start while D_{n-1} orbits) and carries on (the seed's "re-plan sigma_1
when one robot enters its region and the other does not").

**Failure detection and recovery.** A robot that stops far from its slot is stuck (failure region H):
it backs off by turning and tries again. A robot the camera loses is dead-reckoned with the nominal model
until it is seen again. Everything runs within a simulated time budget.

After G_1 forms, the remaining slots are re-targeted by the rigid motion that maps the nominal pair onto
the measured one: the pair may legitimately end shifted or rotated (SPEC 6), and later robots dock onto
the structure as it really is. Success is judged on the shape after a best rigid alignment
(:mod:`stressbots.assessment`); the absolute placement error is reported beside it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from . import paths as pathlib
from .assessment import SHAPE_TOL_UM, shape_error
from .collision import bodies_hit_discs, outside_arena, penetration_depth
from .electrostatics import analyse_scenario
from .errors import PlanningError
from .kinematics import advance, move
from .robots import TWO_PI, angle_difference, front_midpoints, orbit_radii, turning_centres
from .waveform import synthesize

__all__ = ["ControllerOptions", "AssemblyResult", "assemble", "nominal_plan"]

PLAN_CLEARANCE_UM = 40.0
"""Clearance of the nominal plans the controller follows: room for tens of um of control error."""


def nominal_plan(scenario, *, seed: int = 0):
    """The nominal plan a closed-loop run follows: planned with a wide clearance, else the default one."""
    from .planning import PlannerOptions, plan_assembly

    try:
        return plan_assembly(scenario, PlannerOptions(clearance_um=PLAN_CLEARANCE_UM, seed=seed))
    except PlanningError:
        return plan_assembly(scenario, PlannerOptions(seed=seed))


@dataclass(frozen=True)
class ControllerOptions:
    """Closed-loop settings (um, s, deg).

    Attributes
    ----------
    replan_interval_s:
        t_x, the time between measurements; default the scenario's ``[control]`` value.
    time_budget_s:
        Simulated time after which the run is declared failed.
    fine_distance_um:
        Distance of the intermediate pose a_i behind a slot, where fine motion takes over.
    switch_period_s:
        Period of the primitive alternation in interpolated turning (shorter = closer to the arc).
    push_s:
        How long a docking robot keeps pushing after its fine motion, for compliance to act.
    dock_tol_um, dock_tol_deg:
        A stationary robot this close to its slot counts as docked (camera error included).
    clearance_um:
        Clearance kept by replanned paths from orbits, the structure and the arena edge.
    shape_tol_um:
        Success threshold on the RMS shape error after best rigid alignment.
    """

    replan_interval_s: float | None = None
    time_budget_s: float = 4000.0
    fine_distance_um: float = 200.0
    switch_period_s: float = 0.2
    push_s: float = 1.5
    dock_tol_um: float = 30.0
    dock_tol_deg: float = 15.0
    clearance_um: float = 5.0
    shape_tol_um: float = SHAPE_TOL_UM


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
        """The ``result.json`` content (SPEC 7 keys first)."""
        final = self.final_true if self.final_true is not None else self.final_observed
        robots = []
        for i, name in enumerate(self.names):
            robots.append(
                {
                    "name": name,
                    "final": _deg(final[i]),
                    "goal": _deg(self.goals[i]),
                    "docked": bool(self.docked[i]),
                    "position_error_um": float(self.placement_error_um[i]),
                    "heading_error_deg": float(self.heading_error_deg[i]),
                    "observed": _deg(self.final_observed[i]),
                    "nominal_goal": _deg(self.nominal_goals[i]),
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


class _Abort(Exception):
    """The run cannot go on; ``reason`` says why (reported as the result's ``failure``)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class _Budget(_Abort):
    def __init__(self, budget_s: float):
        super().__init__(f"not assembled within the time budget of {budget_s:g} s (simulated)")


def _turn_fraction(pose: np.ndarray, point: np.ndarray, r: float, lateral_tol_um: float = 3.0):
    """Fraction of time to turn (rho) so that an interpolated arc from ``pose`` passes through ``point``.

    Returns ``(rho, arc_length_um, arrival_heading)`` or None when no clockwise arc of radius >= r
    reaches the point (it is behind, or left of the heading by more than ``lateral_tol_um``): the
    robot then needs gross motion (a loop) first. A point straight ahead within the tolerance gives
    rho = 0 (rounding must not turn "straight ahead" into "unreachable").
    """
    d = np.asarray(point[:2], float) - pose[:2]
    th = float(pose[2])
    along = d[0] * math.sin(th) + d[1] * math.cos(th)
    right = d[0] * math.cos(th) - d[1] * math.sin(th)
    if along <= 0.0 or right < -lateral_tol_um:
        return None
    if abs(right) <= lateral_tol_um:
        return 0.0, float(np.hypot(*d)), th
    arc = pathlib.arc_through(pose, point[:2])
    if not np.isfinite(arc.length_um) or arc.radius_um < r:
        return None
    return float(r / arc.radius_um), float(arc.length_um), th + float(arc.turn_rad)


class _Runner:
    def __init__(self, scenario, plant, plan_result, opts: ControllerOptions, seed):
        self.scn = scenario
        self.plant = plant
        self.opts = opts
        self.seed = seed
        self.tx = float(opts.replan_interval_s or scenario.control.replan_interval_s)
        self.analysis = analyse_scenario(scenario)
        if not self.analysis.is_string:
            raise PlanningError("closed-loop assembly needs a STRING design: " + "; ".join(self.analysis.reasons))
        self.pr = plan_result
        n = scenario.n
        self.n = n
        self.rank = np.empty(n, dtype=int)
        for k, i in enumerate(self.analysis.order_index):
            self.rank[i] = k + 1
        self.by_rank = {int(self.rank[i]): i for i in range(n)}
        self.v, self.r = scenario.speeds_um_s, scenario.turn_radii_um
        self.L, self.W = scenario.lengths_um, scenario.widths_um
        self.rstar = orbit_radii(self.L, self.W, self.r)
        self.nominal_goals = plan_result.plan.goal_array()
        self.goals = self.nominal_goals.copy()
        self.docked = np.zeros(n, dtype=bool)
        self.state = np.zeros(n, dtype=np.uint8)
        self.t = 0.0
        self.replans = 0
        self.events: list[dict] = []
        self.unseen = np.zeros(n, dtype=int)
        obs = np.asarray(plant.observe(), dtype=np.float64)
        self.est = np.where(np.isnan(obs), scenario.starts, obs)
        self.trace_t = [0.0]
        self.trace_p = [self.est.copy()]
        self.omega_nom = self.v / self.r
        # Online identification (every robot's true speed and turn rate differ from nominal by a few %):
        # straight chunks measure the speed, turning chunks the turn rate; planning then uses
        # r_hat = v_hat / omega_hat for geometry and v_hat for timing.
        self.v_hat = self.v.astype(float).copy()
        self.omega_hat = self.omega_nom.copy()
        self._helper = None
        self._motion = None  # rigid motion (phi, c_nom, c_meas) of the structure once G_1 formed

    # -- plant I/O ------------------------------------------------------------------------------------

    def log(self, kind: str, robot: int | None = None, detail: str = "") -> None:
        self.events.append({"t_s": round(self.t, 3), "kind": kind, "robot": None if robot is None else self.scn.names[robot], "detail": detail})

    def observe(self) -> np.ndarray:
        obs = np.asarray(self.plant.observe(), dtype=np.float64)
        seen = ~np.isnan(obs).any(axis=1)
        self.est[seen] = obs[seen]
        self.est[:, 2] = np.mod(self.est[:, 2], TWO_PI)
        self.unseen = np.where(seen, 0, self.unseen + 1)
        for i in np.flatnonzero(self.unseen == 3):
            self.log("lost", int(i), "not seen for 3 frames; dead-reckoning")
        return self.est

    @property
    def r_hat(self) -> np.ndarray:
        return self.v_hat / self.omega_hat

    def drive(self, steps: Sequence[tuple[int, float]]) -> None:
        """Apply primitive steps ``(k, duration_s)``, dead-reckon, observe, and identify speeds/turn rates."""
        steps = [(int(k), float(d)) for k, d in steps if d > 1e-9]
        if not steps:
            return
        if self.t + sum(d for _, d in steps) > self.opts.time_budget_s:
            raise _Budget(self.opts.time_budget_s)
        wf = synthesize(self.analysis, [(f"P{k}", d) for k, d in steps], initial=self.state)
        self.plant.apply(wf)
        before = self.est.copy()
        seen_before = self.unseen == 0
        turn_time = np.zeros(self.n)
        total = 0.0
        for k, d in steps:
            turning = self.rank <= k
            moving = ~self.docked
            self.est[moving] = advance(self.est, turning, self.v_hat, self.r_hat, d)[moving]
            turn_time += np.where(turning, d, 0.0)
            total += d
            self.t += d
        self.state = np.asarray(self.analysis.primitive_at(steps[-1][0]).state, dtype=np.uint8)
        self.observe()
        ok = seen_before & (self.unseen == 0) & ~self.docked & (total >= 0.3)
        for i in np.flatnonzero(ok):
            if turn_time[i] >= total - 1e-9:  # turned the whole time
                rate = float(np.mod(self.est[i, 2] - before[i, 2], TWO_PI)) / total
                if 0.7 * self.omega_nom[i] < rate < 1.3 * self.omega_nom[i]:
                    self.omega_hat[i] += 0.2 * (rate - self.omega_hat[i])
            elif turn_time[i] <= 1e-9:  # straight the whole time
                speed = float(np.hypot(*(self.est[i, :2] - before[i, :2]))) / total
                if 0.7 * self.v[i] < speed < 1.3 * self.v[i]:
                    self.v_hat[i] += 0.2 * (speed - self.v_hat[i])
        self.trace_t.append(self.t)
        self.trace_p.append(self.est.copy())

    # -- geometry -------------------------------------------------------------------------------------

    def obstacles_hit(self, samples: np.ndarray, i: int, orbiting: Sequence[int], *, extra_discs=()) -> bool:
        """Whether robot ``i``'s body along ``samples`` hits an orbit, a docked body or the arena edge."""
        c = self.opts.clearance_um
        orbiting = [j for j in orbiting if j != i]
        if orbiting or extra_discs:
            centres = [*turning_centres(self.est[orbiting], self.r[orbiting])] if orbiting else []
            radii = list(self.rstar[orbiting]) if orbiting else []
            for cc, rr in extra_discs:
                centres.append(cc)
                radii.append(rr)
            if bodies_hit_discs(samples, self.L[i], self.W[i], np.array(centres), np.array(radii) + c).any():
                return True
        docked = np.flatnonzero(self.docked)
        for j in docked:
            if (penetration_depth(samples, self.L[i], self.W[i], self.est[j], self.L[j], self.W[j]) > -c).any():
                return True
        if self.scn.arena_um is not None:
            if (outside_arena(samples, self.L[i], self.W[i], self.scn.arena_um) > 0).any():
                return True
        return False

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

    def steer(self, i: int, target: np.ndarray, turn_k: int, straight_k: int, orbiting: Sequence[int], *, extra_discs=(), max_cycles: int = 400, guard=None) -> bool:
        """Gross motion: drive robot ``i`` to ``target`` by replanning every t_x; True when there.

        ``guard()`` may return False to stop early (e.g. D_n's straight run is used up).
        """
        for _ in range(max_cycles):
            v, r = self.v_hat[i], self.r_hat[i]
            p = self.est[i]
            if self.arrived(p, target):
                return True
            path = pathlib.shortest_path(p, target, r)
            if self.obstacles_hit(path.sample(10.0), i, orbiting, extra_discs=extra_discs):
                detour = self.detour(i, target, orbiting, extra_discs)
                if detour is not None:
                    path = detour
            self.replans += 1
            # the last leg runs whole: a one-way robot that stops short and overshoots needs a loop
            whole = path.length / v <= 1.6 * self.tx
            limit = None if whole else self.tx
            if guard is not None:
                allowed = guard()
                if allowed is not None and allowed < (path.length / v if whole else self.tx):
                    if allowed <= 1e-6:
                        return False
                    self.drive(self.path_steps(path, v, turn_k, straight_k, allowed))
                    return False
            self.drive(self.path_steps(path, v, turn_k, straight_k, limit))
            if whole:
                return True
        return False

    def arrived(self, pose: np.ndarray, target: np.ndarray) -> bool:
        """Inside the target region (the seed's regions instead of points): 25 um and 6 deg."""
        return bool(np.hypot(*(pose[:2] - target[:2])) <= 25.0 and abs(angle_difference(pose[2], target[2])) <= math.radians(6.0))

    def _obstacles(self, i: int, orbiting, extra_discs):
        from .planning import _Obstacles

        orbiting = [j for j in orbiting if j != i]
        centres = list(turning_centres(self.est[orbiting], self.r[orbiting])) if orbiting else []
        radii = list(self.rstar[orbiting]) if orbiting else []
        for c, rr in extra_discs:
            centres.append(c)
            radii.append(rr)
        docked = np.flatnonzero(self.docked)
        return _Obstacles(
            np.array(centres).reshape(-1, 2), np.array(radii, float), tuple("an orbit" for _ in radii),
            self.est[docked], self.L[docked], self.W[docked], tuple("a docked robot" for _ in docked), self.scn.arena_um,
        )

    def timed_detour(self, i: int, target, duration_s: float, orbiting, extra_discs) -> pathlib.Path | None:
        """A collision-free path of exactly ``duration_s``: routed around obstacles, then stretched."""
        from .planning import PlannerOptions, _NoRoute, _Planner, _route

        if self._helper is None:
            self._helper = _Planner(self.scn, self.analysis, self.pr.structure, PlannerOptions(clearance_um=self.opts.clearance_um, roadmap_nodes=(60, 200)))
        obst = self._obstacles(i, orbiting, extra_discs)
        rng = np.random.default_rng(np.random.SeedSequence([0 if self.seed is None else int(self.seed), len(self.events), i]))
        try:
            _, routed, _ = _route(self.est[i][None, :], np.zeros(1), np.asarray(target, float), self.r_hat[i], self.L[i], self.W[i], obst, self._helper.opts, rng, "")
        except _NoRoute:
            return None
        want = self.v_hat[i] * max(duration_s, 0.0)
        if routed.length >= want:
            return routed
        return self._helper._stretch(routed, want, obst, self.L[i], self.W[i]) or routed

    def detour(self, i: int, target, orbiting, extra_discs) -> pathlib.Path | None:
        """A roadmap route around the obstacles from the measured pose (rarely needed)."""
        path = self.timed_detour(i, target, 0.0, orbiting, extra_discs)
        if path is not None:
            self.log("detour", i, f"route around obstacles ({path.length:.0f} um)")
        return path

    def interpolated_steps(self, rho_turn: float, duration: float, turn_k: int, straight_k: int):
        """S_2f for ``duration`` s: symmetric cycles (half turn, straight, half turn) with turn fraction rho."""
        if rho_turn >= 0.995:
            return [(turn_k, duration)]
        if rho_turn <= 0.005:
            return [(straight_k, duration)]
        cycles = max(1, math.ceil(duration / self.opts.switch_period_s))
        T = duration / cycles
        out = []
        for _ in range(cycles):
            out += [(turn_k, 0.5 * rho_turn * T), (straight_k, (1 - rho_turn) * T), (turn_k, 0.5 * rho_turn * T)]
        return out

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
        i = self.by_rank[k]
        orbiting = self.orbiting_below(k)
        waypoints = [np.array(w) for w in (route_phase.waypoints if route_phase is not None else ())]
        for attempt in range(4):
            # a_i on the nominal route (moved with the structure when it was re-targeted)
            a_pose = self.fine_start_on(route_phase, i) if route_phase is not None and attempt == 0 else self.fine_start(i, self.goals[i])
            a_pose = self.retargeted(a_pose)
            # gross motion through the nominal route's waypoints before a_i, then to a_i
            targets = [w for w in waypoints[:-1] if self._before(w, a_pose, route_phase, i)] + [a_pose]
            for tgt in targets:
                self.steer(i, tgt, k, k - 1, orbiting)
            waypoints = []
            if self.fine_dock(i, k, orbiting):
                return
            self.log("retry", i, f"attempt {attempt + 1} did not dock; backing off")
            self.back_off(i, k)
        raise _Abort(f"{self.scn.names[i]} did not dock in 4 attempts (stuck in the failure region H)")

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

    def fine_dock(self, i: int, k: int, orbiting) -> bool:
        """Fine motion (S_2f) into the slot, then push; True when docked."""
        for _ in range(60):
            v, r = self.v_hat[i], self.r_hat[i]
            goal = self.goals[i]
            fr = _turn_fraction(self.est[i], goal, r)
            if fr is None or abs(angle_difference(fr[2], goal[2])) > math.radians(40):
                return False  # not reachable on one interpolated arc: gross motion again
            rho, length, _ = fr
            t_arc = length / v
            if t_arc <= self.tx:
                self.drive(self.interpolated_steps(rho, t_arc, k, k - 1) + [(k - 1, self.opts.push_s)])
                return self.check_docked(i, k)
            self.drive(self.interpolated_steps(rho, self.tx, k, k - 1))
        return False

    def check_docked(self, i: int, k: int) -> bool:
        """Push until the robot stops; docked if it stopped at its slot, stuck (H) if elsewhere."""
        for _ in range(6):
            before = self.est[i].copy()
            self.drive([(k - 1, self.tx)])
            moved = float(np.hypot(*(self.est[i, :2] - before[:2])))
            if moved < 0.2 * self.v[i] * self.tx:
                goal = self.goals[i]
                dpos = float(np.hypot(*(self.est[i, :2] - goal[:2])))
                dth = abs(angle_difference(self.est[i, 2], goal[2]))
                if dpos <= self.opts.dock_tol_um and dth <= math.radians(self.opts.dock_tol_deg):
                    self.docked[i] = True
                    self.log("docked", i, f"{dpos:.1f} um, {math.degrees(dth):.1f} deg from the slot")
                    return True
                self.log("stuck", i, f"stopped {dpos:.0f} um / {math.degrees(dth):.0f} deg from the slot (failure region H)")
                return False
        return False

    def back_off(self, i: int, k: int) -> None:
        """Recovery from H: a robot cannot reverse, so it turns away (arm down) and drives clear."""
        self.drive([(k, 0.5 * math.pi * self.r[i] / self.v[i]), (k - 1, 150.0 / self.v[i])])

    # -- G_1 --------------------------------------------------------------------------------------------

    def form_pair(self, phases) -> None:
        """Step 1: follow the pair's phases; re-plan sigma_1 from the measured poses when out of step."""
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        lower = self.orbiting_below(n - 1)
        queue = list(phases)
        replans = 0
        while queue:
            ph = queue.pop(0)
            ok = True
            if ph.kind == "pair-A":
                ok = self.follow_a_phase(N, M, ph, lower)
            elif ph.kind == "pair-B":
                ok = self.pair_piece(N, M, ph, lower)
            if not ok:
                replans += 1
                if replans > 8:
                    raise _Abort("G_1 could not be synchronised: 8 re-plans of sigma_1 did not bring the pair into step")
                self.log("replan", N, f"G_1 out of step after a {ph.kind} phase: sigma_1 re-planned from the measured poses")
                queue = self.replan_pair(N, M)
        self.close_pair(N, M, lower)

    def follow_a_phase(self, N: int, M: int, ph, lower) -> bool:
        """D_n drives to the start of its next run while D_{n-1} orbits back to its departure heading.

        The phase lasts as long as D_{n-1}, at its measured turn rate, needs to come back to the planned
        departure heading (the planned number of turns); D_n's path of exactly that duration is computed
        from its measured pose and driven open loop, re-timed once half way with the turn rate measured
        meanwhile; then D_n steers into its region if it is not there. Returns False when D_{n-1} ends
        out of step (the caller re-plans).
        """
        n = self.n
        target = np.array(ph.target)
        disc = [(turning_centres(self.est[M], self.r_hat[M])[0], self.rstar[M])]
        turns_planned = self.omega_nom[M] * ph.duration_s
        delta = float(np.mod(ph.partner_end[2] - self.est[M, 2], TWO_PI)) if ph.partner_end is not None else 0.0
        k = max(0, round((turns_planned - delta) / TWO_PI))
        # D_{n-1} aims to stop a little before its departure heading: past it, its route would need a loop
        want = max(delta + TWO_PI * k - math.radians(20.0), 0.0)
        turned = 0.0
        retimed = False
        path = self.timed_a_path(N, target, want / self.omega_hat[M], lower, disc)
        if path is None:
            return False
        self.replans += 1
        done = 0.0
        vN = self.v_hat[N]
        while path.length - done > 1e-6:
            th0 = self.est[M, 2]
            self.drive(self.path_steps(pathlib.sub_path(path, done, done + vN * self.tx), vN, n, n - 1))
            done += vN * self.tx
            turned += float(np.mod(self.est[M, 2] - th0, TWO_PI))
            left = (want - turned) / self.omega_hat[M]
            if not retimed and done > 0.4 * path.length and left > 4.0 * self.tx:
                retimed = True
                new = self.timed_a_path(N, target, left, lower, disc)
                if new is not None:
                    path, done = new, 0.0
        # D_n's straight run tolerates a heading error (self-alignment absorbs up to 60 deg at the end);
        # correcting it would cost a loop. Only a position error makes it steer again.
        if np.hypot(*(self.est[N, :2] - target[:2])) > 40.0:
            self.steer(N, target, n, n - 1, lower, extra_discs=disc, max_cycles=60)
        if ph.partner_end is None:
            return True
        still = float(np.mod(ph.partner_end[2] - self.est[M, 2] + 0.5, TWO_PI)) - 0.5  # > 0: still to turn
        return math.radians(3.0) <= still <= math.radians(55.0)

    def timed_a_path(self, N: int, target, duration: float, lower, disc) -> pathlib.Path | None:
        """D_n's collision-free path to ``target`` lasting ``duration`` s (at its identified speed)."""
        vN, rN = self.v_hat[N], self.r_hat[N]
        try:
            cand = pathlib.path_of_length(self.est[N], target, rN, vN * duration)
        except pathlib.InfeasibleLengthError:
            return None
        if self.obstacles_hit(cand.sample(10.0), N, lower, extra_discs=disc):
            cand = self.timed_detour(N, target, duration, lower, disc)
            if cand is None or cand.length < vN * duration - 1.0:
                return None
        return cand

    def replan_pair(self, N: int, M: int) -> list:
        """Plan the pair's remaining phases from the measured poses (using D_{n-1}'s measured turn rate)."""
        from dataclasses import replace as dc_replace

        from .planning import PlannerOptions, _NoRoute, _Planner
        from .robots import Pose

        robots = []
        for i, rb in enumerate(self.scn.robots):
            robots.append(dc_replace(rb, start=Pose(*self.est[i]), speed_um_s=float(self.v_hat[i]), turn_radius_um=float(self.r_hat[i])))
        scn2 = self.scn.with_robots(robots)
        for clearance in (PLAN_CLEARANCE_UM, 10.0):
            planner = _Planner(scn2, self.analysis, self.pr.structure, PlannerOptions(clearance_um=clearance, seed=len(self.events)))
            try:
                planner.form_pair()
            except (_NoRoute, PlanningError):
                continue
            return [p for p in planner.tl.phases if p.kind.startswith("pair")]
        raise _Abort("sigma_1 could not be re-planned from the measured poses")

    def pair_piece(self, N: int, M: int, ph, lower) -> bool:
        """D_{n-1} drives to the end of its piece while D_n runs straight; False if D_n's run runs out."""
        n = self.n
        run_start = np.array(ph.run[0])
        run_len = float(ph.run[1])
        hN = np.array([math.sin(run_start[2]), math.cos(run_start[2])])
        target = np.array(ph.target)
        a = 0.0
        if ph.last:
            target = self.fine_start_on(ph, M)
            a = float(pathlib.shortest_path(target, self.goals[M], self.r_hat[M]).length) * self.v_hat[N] / self.v_hat[M]
        slack = 40.0 + self.v_hat[N] * math.radians(40.0) / self.omega_hat[M]

        def room() -> float:
            # D_n may run on until 0.4 a from its slot in the last piece (its partner is then a away)
            done = float((self.est[N, :2] - run_start[:2]) @ hN)
            end = run_len - (0.4 * a if ph.last else 0.0) + slack
            return max(0.0, (end - done) / self.v_hat[N])

        return self.steer(M, target, n - 1, n - 2, lower, guard=room)

    def close_pair(self, N: int, M: int, lower) -> None:
        """Fine motion of the pair: S_3f arcs through both docking points, or both straight."""
        n = self.n
        for _ in range(80):
            gN, gM = self.goals[N], self.goals[M]
            fN = _turn_fraction(self.est[N], gN, self.r_hat[N])
            fM = _turn_fraction(self.est[M], gM, self.r_hat[M])
            ends = front_midpoints(self.est[[N, M]], self.L[[N, M]])
            gap = float(np.hypot(*(ends[0] - ends[1])))
            # S_3f: D_n turns under P_n only (rho_a), D_{n-1} under P_n and P_{n-1} (rho_a + rho_b).
            # When an arc is out of reach the robot drives straight and compliance takes the rest.
            rho_a = fN[0] if fN is not None else 0.0
            rho_ab = fM[0] if fM is not None else 0.0
            rho_a = min(rho_a, rho_ab)
            steps = [(n - 2, self.tx)]
            if rho_ab > 0.005 and gap > 30.0:
                cycles = max(1, math.ceil(self.tx / self.opts.switch_period_s))
                T = self.tx / cycles
                steps = []
                for _c in range(cycles):
                    steps += [(n, rho_a * T), (n - 1, (rho_ab - rho_a) * T), (n - 2, (1.0 - rho_ab) * T)]
            before = self.est[[N, M]].copy()
            self.drive(steps)
            moved = np.hypot(*(self.est[[N, M], :2] - before[:, :2]).T)
            ends = front_midpoints(self.est[[N, M]], self.L[[N, M]])
            gap = float(np.hypot(*(ends[0] - ends[1])))
            if gap < 20.0 and (moved < 0.2 * self.v[[N, M]] * self.tx).all():
                self.drive([(n - 2, self.opts.push_s)])  # let self-alignment finish
                self.docked[[N, M]] = True
                self.log("G_1", N, f"formed with {self.scn.names[M]} (front edges {gap:.1f} um apart)")
                self.retarget(N, M)
                return
            if (moved < 0.2 * self.v[[N, M]] * self.tx).all() and gap >= 20.0:
                self.log("stuck", N, f"the pair stopped {gap:.0f} um apart (failure region H)")
                raise _Abort(f"the G_1 pair stopped {gap:.0f} um apart (failure region H)")
        raise _Abort("G_1 did not form during its fine motion")

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
            self.log("retarget", None, f"G_1 formed {np.hypot(*(c_meas - c_nom)):.1f} um / {math.degrees(phi):.1f} deg from nominal; later slots follow it")

    # -- the whole assembly ---------------------------------------------------------------------------

    def run(self) -> str | None:
        phases = self.pr.phases
        try:
            self.form_pair([p for p in phases if p.kind.startswith("pair")])
            for k in range(self.n - 2, 0, -1):
                i = self.by_rank[k]
                route = next((p for p in phases if p.kind == "route" and p.mover == i), None)
                self.dock_single(k, route)
        except _Abort as exc:
            return exc.reason
        return None


def assemble(scenario, plant, *, seed: int | None = None, plan=None, time_budget_s: float | None = None, options: ControllerOptions | None = None) -> AssemblyResult:
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

    from .planning import PlanResult, plan_assembly

    opts = options or ControllerOptions()
    if time_budget_s is not None:
        opts = replace(opts, time_budget_s=float(time_budget_s))
    if plan is None:
        plan = nominal_plan(scenario)
    if not isinstance(plan, PlanResult):
        raise TypeError("plan must be a PlanResult from stressbots.planning.plan_assembly")
    run = _Runner(scenario, plant, plan, opts, seed)
    failure = run.run()
    true = plant.true_poses() if hasattr(plant, "true_poses") else None
    final = np.asarray(true if true is not None else run.est, dtype=np.float64)
    shape = shape_error(final, run.nominal_goals, scenario.lengths_um, scenario.widths_um)
    placement = np.hypot(*(final[:, :2] - run.nominal_goals[:, :2]).T)
    heading = np.degrees(np.abs(angle_difference(final[:, 2], run.nominal_goals[:, 2])))
    success = failure is None and bool(run.docked.all()) and shape.rms_um <= opts.shape_tol_um
    if failure is None and not success:
        failure = f"shape error {shape.rms_um:.1f} um RMS exceeds {opts.shape_tol_um:g} um"
    return AssemblyResult(
        success=success,
        seed=seed,
        names=scenario.names,
        final_true=None if true is None else np.asarray(true, dtype=np.float64),
        final_observed=run.est.copy(),
        goals=run.goals.copy(),
        nominal_goals=run.nominal_goals.copy(),
        docked=run.docked.copy(),
        shape_error_rms_um=float(shape.rms_um),
        shape_rotation_deg=float(shape.rotation_deg),
        placement_error_um=placement,
        heading_error_deg=heading,
        duration_s=run.t,
        replans=run.replans,
        events=tuple(run.events),
        failure=failure,
        trace_t=np.asarray(run.trace_t),
        trace_poses=np.asarray(run.trace_p),
    )
