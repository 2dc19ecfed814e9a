"""The nominal n-robot assembly planner (seed Appendix 2, generalised).

Every robot receives the same signal, so the planner can only choose a sequence of control primitives
P_k (SPEC 4: under P_k the robots D_1..D_k turn, the others drive straight). The seed reduces the
parallel problem to two robots moving together followed by single robots, and this module does the same:

**Step 1 - G_1.** D_n and D_{n-1} form the initial pair while D_1..D_{n-2} orbit in place (every
primitive used, P_n, P_{n-1}, P_{n-2}, turns them). D_{n-1} follows a route to its slot using
P_{n-1}/P_{n-2} (D_n drives straight meanwhile); D_n is driven with P_n/P_{n-1} while D_{n-1} orbits.
The seed does this in two stages: D_n first goes to a pose a_n (D_{n-1} orbiting back to its start), then
D_{n-1} drives its whole route while D_n drives straight into its slot. That fails when D_{n-1}'s route
is long: D_n's straight corridor leaves the arena or crosses an orbit (SPEC 5, "a known limit"). Here
D_{n-1}'s route may be cut into *pieces*. Between two pieces D_n runs the same short straight corridor
into its slot and then loops back along a path whose length is exactly a whole number of D_{n-1}'s orbit
periods, so D_{n-1} orbits back to where it stopped. One piece is exactly the seed's scheme.

**Steps 2..n-1 - docking.** D_i (i = n-2 .. 1) docks with P_i/P_{i-1} while D_1..D_{i-1} orbit and the
docked robots push. It may first wait on its orbit (P_i): the planner tries several departure phases
and takes the fastest collision-free route.

**Routes** avoid the orbit discs (radius r*), the structure and the arena edge with a clearance, and
end with a straight approach into the slot (touching allowed). A route is first tried direct (one
shortest one-way path), then through a lazily checked roadmap of waypoint poses (random and tangent to
the discs), growing until a route is found.

Every plan is replayed by :func:`stressbots.replay.replay`, an independent integrator, before it is
returned.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace

import numpy as np

from . import paths as pathlib
from .collision import (
    bodies_hit_discs,
    disc_overlaps,
    outside_arena,
    pairwise_overlaps,
    penetration_depth,
    point_rectangle_distance,
)
from .electrostatics import ControlAnalysis, analyse_scenario
from .errors import PlanningError
from .kinematics import advance, move
from .overlap import PairSchedule, joint_primitives, overlap_schedule, with_orbits
from .planner_options import SEARCH_BUDGET_DEFAULT as SEARCH_BUDGET_DEFAULT
from .planner_options import SHORTEST, PlannerOptions
from .plans import Plan, PlanPrimitive, merge_steps
from .prepositioning import docking_costs, follower_ends, splice_straight, straight_windows
from .replay import ReplayReport, replay
from .robots import TWO_PI, Pose, orbit_radii, turning_centres
from .routing import NoRoute, Obstacles, SearchSpent, path_hit, route
from .structures import Structure, target_structures
from .timeline import Phase, Timeline

__all__ = ["SHORTEST", "PlannerOptions", "PlanResult", "Phase", "plan_assembly", "lower_bound_s", "Obstacles", "NoRoute", "route"]


@dataclass(frozen=True)
class PlanResult:
    """A verified nominal plan and what was learnt making it."""

    plan: Plan
    structure: Structure
    analysis: ControlAnalysis
    replay: ReplayReport
    summary: dict
    notes: tuple[str, ...] = field(default=())
    phases: tuple[Phase, ...] = field(default=())


class SharedSearch:
    """Work shared by the structure variants of one ``plan_assembly`` call.

    ``used`` counts the G_1 schedules tried against :attr:`PlannerOptions.search_budget`.
    ``pair_failures`` maps what a G_1 search depends on (see :meth:`_Planner.form_pair`) to why it
    failed: variants that differ only in later slots (which side stems grow on, which tooth is first)
    would repeat the same failing search exactly, so they fail at once with the same reason.
    ``bottlenecks`` are the ranks of robots whose docking failed in a variant: later variants check first
    that those robots can reach their slots at all (:meth:`_Planner.dock_check`), before forming G_1.
    ``docking_failed`` holds the variants (by id) that failed after G_1 was formed: the extended search,
    which only widens the G_1 search, skips them.
    """

    def __init__(self, budget: int | None):
        self.budget = budget
        self.used = 0
        self.pair_failures: dict = {}
        self.bottlenecks: list[int] = []
        self.docking_failed: set[int] = set()

    @property
    def spent(self) -> bool:
        return self.budget is not None and self.used >= self.budget

    def take(self) -> None:
        self.used += 1


def robot_label(scn, i: int, rank: int) -> str:
    return f"D{rank} ({scn.names[i]!r})"


def _prechecks(scn, struct: Structure, rank: np.ndarray) -> str | None:
    """Reasons a structure cannot be planned from these starts at all (None if none found)."""
    n = scn.n
    starts = scn.starts
    L, W, R = scn.lengths_um, scn.widths_um, scn.turn_radii_um
    goals = struct.goal_poses(scn.names)
    rstar = orbit_radii(L, W, R)
    centres = turning_centres(starts, R)
    lab = [robot_label(scn, i, rank[i]) for i in range(n)]
    for i, j, d in pairwise_overlaps(starts, L, W, tol_um=1e-6):
        return f"start bodies of {lab[i]} and {lab[j]} overlap by {d:.1f} um"
    if scn.arena_um is not None:
        out = outside_arena(starts, L, W, scn.arena_um)
        for i in np.flatnonzero(out > 0).tolist():
            return f"{lab[i]} starts {out[i]:.1f} um outside the arena"
        out = outside_arena(goals, L, W, scn.arena_um)
        for i in np.flatnonzero(out > 0).tolist():
            return f"the slot of {lab[i]} is {out[i]:.1f} um outside the arena"
    orbiting = np.flatnonzero(rank <= n - 1).tolist()  # D_1..D_{n-1} orbit at their starts
    for a, b, o in disc_overlaps(centres[orbiting], rstar[orbiting]):
        i, j = orbiting[a], orbiting[b]
        return f"orbits of {lab[i]} and {lab[j]} overlap at the start by {o:.1f} um (orbit radius r* = {rstar[i]:.0f} um)"
    if scn.arena_um is not None:
        w, h = scn.arena_um
        for i in orbiting:
            c, r = centres[i], rstar[i]
            over = max(r - c[0], c[0] + r - w, r - c[1], c[1] + r - h)
            if over > 0:
                return f"the orbit of {lab[i]} leaves the arena by {over:.1f} um"
    # Robots D_j (j <= n-2) orbit until their own step: every slot filled before must stay clear.
    for i in np.flatnonzero(rank <= n - 2).tolist():
        later = np.flatnonzero(rank > rank[i])
        hit = bodies_hit_discs(goals[later], L[later], W[later], centres[i][None, :], [rstar[i]])
        for k in np.flatnonzero(hit[:, 0]):
            j = later[k]
            return f"the orbit of {lab[i]} crosses the slot of {lab[j]} (it orbits there until it docks)"
        # and every other robot's start body (they are still there while D_i orbits)
    for i in orbiting:
        others = np.array([j for j in range(n) if j != i])
        hit = bodies_hit_discs(starts[others], L[others], W[others], centres[i][None, :], [rstar[i]], tol_um=1e-6)
        for k in np.flatnonzero(hit[:, 0]):
            j = others[k]
            return f"the orbit of {lab[i]} crosses the start of {lab[j]}"
    return None


def lower_bound_s(scn, struct: Structure, rank: np.ndarray, phases: int = 90) -> float:
    """A lower bound (s) on the duration of any plan of the sequential scheme.

    G_1 cannot finish before both D_n and D_{n-1} have driven their shortest paths; each later robot
    D_i cannot dock before driving the shortest path from the best point of its orbit circle. A robot
    pre-positioned before its step (:attr:`PlannerOptions.preposition`) starts its docking off that
    circle, so a plan could in principle beat the docking part of this bound (efficiency above 1).
    """
    n = scn.n
    goals = struct.goal_poses(scn.names)
    starts = scn.starts
    v, r = scn.speeds_um_s, scn.turn_radii_um
    by_rank = {int(rank[i]): i for i in range(n)}
    pair = [by_rank[n], by_rank[n - 1]]
    t = max(pathlib.shortest_path_lengths(starts[pair], goals[pair], r[pair]) / v[pair])
    for k in range(n - 2, 0, -1):
        i = by_rank[k]
        ang = np.linspace(0.0, TWO_PI, phases, endpoint=False)
        on_orbit = advance(np.repeat(starts[i][None, :], phases, axis=0), np.ones(phases, bool), v[i], r[i], ang * r[i] / v[i])
        t += float(np.min(pathlib.shortest_path_lengths(on_orbit, np.repeat(goals[i][None, :], phases, axis=0), r[i]))) / v[i]
    return float(t)


def approach_length(struct: Structure, name: str, opts: PlannerOptions) -> float:
    return float(min(opts.approach_um, struct.slot(name).approach_um))


def pre_approach_pose(goal: np.ndarray, a: float) -> np.ndarray:
    return np.array([goal[0] - a * math.sin(goal[2]), goal[1] - a * math.cos(goal[2]), goal[2]])


class _Planner:
    def __init__(self, scn, analysis: ControlAnalysis, struct: Structure, opts: PlannerOptions, *, extended: bool = False,
                 search: SharedSearch | None = None):
        self.search = search or SharedSearch(opts.search_budget)  # shared by every variant of one plan_assembly call
        self.extended = extended  # the wider G_1 search (leg stretch, orbit first, ...): after all variants failed
        if extended:  # the wider G_1 search: more pieces (the seed's one-piece scheme stays one), more schedules
            pieces = max(opts.max_pieces, opts.extended_max_pieces) if opts.max_pieces > 1 else opts.max_pieces
            opts = replace(opts, max_pieces=pieces, pair_schedules=max(opts.pair_schedules, opts.extended_pair_schedules))
        self.scn = scn
        self.analysis = analysis
        self.struct = struct
        self.opts = opts
        self.n = scn.n
        order = analysis.order_index  # scenario indices of D_1..D_n
        assert order is not None and analysis.order is not None  # a STRING design (checked by plan_assembly)
        self.by_rank = {k + 1: int(i) for k, i in enumerate(order)}
        self.rank = np.empty(self.n, dtype=int)
        for k, i in self.by_rank.items():
            self.rank[i] = k
        self.goals = struct.goal_poses(scn.names)
        self.L, self.W = scn.lengths_um, scn.widths_um
        self.v, self.r = scn.speeds_um_s, scn.turn_radii_um
        self.rstar = orbit_radii(self.L, self.W, self.r)
        self.rng = np.random.default_rng(np.random.SeedSequence(opts.seed))
        self.tl = Timeline(scn, self.rank, [analysis.order[k] for k in range(self.n)])
        self.notes: list[str] = []
        self.route_lengths = np.zeros(self.n)
        self._timed_cache: dict = {}
        self._route_cache: dict = {}

    def lab(self, i: int) -> str:
        return robot_label(self.scn, i, self.rank[i])

    def obstacles(self, orbiting: Sequence[int], docked: Sequence[int]) -> Obstacles:
        orbiting = list(orbiting)
        docked = list(docked)
        centres = turning_centres(self.tl.poses[orbiting], self.r[orbiting]) if orbiting else np.zeros((0, 2))
        return Obstacles(
            centres,
            self.rstar[orbiting] if orbiting else np.zeros(0),
            tuple(f"the orbit of {self.lab(i)}" for i in orbiting),
            self.goals[docked] if docked else np.zeros((0, 3)),
            self.L[docked] if docked else np.zeros(0),
            self.W[docked] if docked else np.zeros(0),
            tuple(f"the docked body of {self.lab(i)}" for i in docked),
            self.scn.arena_um,
        )

    def approach_path(self, i: int, goal: np.ndarray, a: float, obst: Obstacles, who: str, a_max: float | None = None) -> pathlib.Path:
        """The final approach of robot ``i`` into its slot, ``a`` um long.

        A clockwise arc of radius ``s / phi`` (flown as an interpolated turn, seed App. 3.1) that arrives
        at the slot's heading a short straight push before the slot. Only points to a robot's right are
        reachable on one clockwise arc (seed Fig. 4): ending the nominal approach on such an arc leaves
        the fine-motion controller room to correct errors either way by changing r'. ``phi`` is the
        largest of 20, 12, 6 deg whose swept bodies clear the obstacles (touching the structure at the
        end is docking); else a straight approach, as long as the slot's clear corridor (``a_max``) if
        need be, so that it starts outside a gap between docked neighbours.
        """
        r, L, W = self.r[i], self.L[i], self.W[i]
        tail = min(20.0, 0.25 * a)
        s_f = a - tail
        p_pre = pre_approach_pose(goal, tail)
        hit = None
        options = [(20.0, a), (12.0, a), (6.0, a), (0.0, a)]
        if a_max is not None and a_max > a:
            options.append((0.0, a_max))
        for phi_deg, length in options:
            if phi_deg == 0.0:
                path = pathlib.Path(Pose(*pre_approach_pose(goal, length)), r, (("S", length),))
                if obst.first_hit(path.sample(self.opts.sample_um)[:1], L, W, self.opts.clearance_um) is not None:
                    hit = "a docked neighbour at its start"
                    continue
            else:
                radius = s_f / math.radians(phi_deg)
                if radius < 1.05 * r:
                    continue
                start = move(p_pre, -s_f, 1.0 / radius)
                path = pathlib.interpolated_arc(start, math.radians(phi_deg), radius, r, 25.0).then(("S", tail))
            hit = obst.first_hit(path.sample(self.opts.sample_um), L, W, self.opts.clearance_um, box_tol=0.5)
            if hit is None:
                return path
        raise NoRoute(f"{who}: the approach into its slot is blocked by {hit}")


    def dock_check(self, k: int) -> None:
        """Raise :class:`NoRoute` unless D_k can reach its slot from its start orbit.

        The quick test of a robot whose docking failed in an earlier variant: from any of
        ``departure_phases`` points of its start orbit, around the lower robots' orbits (they orbit at
        their starts until their own step) and the slots of the robots docked before it. Its own random
        stream, so the plan of a variant that passes is what it would be without the test.
        """
        i = self.by_rank[k]
        who = self.lab(i)
        obst = self.obstacles([self.by_rank[j] for j in range(1, k)], [self.by_rank[j] for j in range(k + 1, self.n + 1)])
        slot = float(self.struct.slot(self.scn.names[i]).approach_um)
        approach = self.approach_path(i, self.goals[i], approach_length(self.struct, self.scn.names[i], self.opts), obst, who, a_max=slot)
        m = self.opts.departure_phases
        waits = np.arange(m) * TWO_PI * self.r[i] / self.v[i] / m
        sources = advance(np.repeat(self.scn.starts[i][None, :], m, axis=0), np.ones(m, bool), self.v[i], self.r[i], waits)
        rng = np.random.default_rng(np.random.SeedSequence([self.opts.seed, k, 1]))
        route(sources, waits * self.v[i], np.array(approach.start, dtype=np.float64), self.r[i], self.L[i], self.W[i], obst, self.opts,
              rng, who)

    def dock_single(self, k: int) -> None:
        i = self.by_rank[k]
        who = self.lab(i)
        goal = self.goals[i]
        a = approach_length(self.struct, self.scn.names[i], self.opts)
        orbiting = [self.by_rank[j] for j in range(1, k)]
        docked = [self.by_rank[j] for j in range(k + 1, self.n + 1)]
        obst = self.obstacles(orbiting, docked)
        approach = self.approach_path(i, goal, a, obst, who, a_max=float(self.struct.slot(self.scn.names[i]).approach_um))
        pre = np.array(approach.start, dtype=np.float64)
        m = self.opts.departure_phases
        period = TWO_PI * self.r[i] / self.v[i]
        waits = np.arange(m) * period / m
        p0 = np.repeat(self.tl.poses[i][None, :], m, axis=0)
        sources = advance(p0, np.ones(m, bool), self.v[i], self.r[i], waits)
        s, path, waypoints = route(sources, waits * self.v[i], pre, self.r[i], self.L[i], self.W[i], obst, self.opts, self.rng, who)
        t0 = self.tl.t
        self.tl.apply(k, float(waits[s]))
        self.tl.phase("wait", i, k, k - 1, t0, sources[s])
        t0 = self.tl.t
        steps = [(k if kind == "R" else k - 1, ell / self.v[i]) for kind, ell in path.segments]
        pre_f = None
        if self.opts.preposition and k >= 2:  # after the wait: D_k's route and approach from here
            mover = pathlib.Path(Pose(*self.tl.poses[i]), self.r[i], path.segments + approach.segments)
            tail = [(k if kind == "R" else k - 1, ell / self.v[i]) for kind, ell in approach.segments]
            pre_f = self._preposition(k, steps + tail, [(i, mover)], f"{who} docked", until=path.length / self.v[i])
        if pre_f is not None:
            steps = splice_straight(steps, k, pre_f[0], pre_f[1])
        for kk, d in steps:
            self.tl.apply(kk, d, counts_for=(i,))
        self.tl.phase(
            "route", i, k, k - 1, t0, pre, waypoints=tuple(tuple(float(v) for v in w) for w in waypoints),
            path=path.then(*approach.segments).segments, path_start=tuple(float(v) for v in path.start), approach_um=approach.length,
        )
        t0 = self.tl.t
        self.tl.apply_path(i, approach, k, k - 1)
        self.tl.phase("approach", i, k, k - 1, t0, goal)
        self.route_lengths[i] = path.length + approach.length
        self.tl.dock(i, goal, who)

    def _preposition(self, k: int, steps, movers: Sequence[tuple[int, pathlib.Path]], what: str,
                     until: float = math.inf) -> tuple[float, float] | None:
        """A straight stretch ``(t0_s, dt_s)`` (from now) in which D_{k-1} drives straight with P_{k-2}
        instead of P_{k-1} (:mod:`stressbots.prepositioning`), or None when none saves time.

        ``steps`` are the coming primitive steps (P_k and above turn D_{k-1}, P_{k-1} is replaced), and
        ``movers`` the robots they move with their paths from now: D_k docking, or the G_1 pair. Candidates
        lie in the P_{k-1} steps that end by ``until`` (s), ranked by D_{k-1}'s predicted docking (best
        departure phase on its new orbit, wait plus shortest path); one is taken only if its straight and
        its new orbit clear the obstacles of D_{k-1}'s step, it keeps clear of the movers, and its
        predicted route is clear: D_{k-1}'s docking then takes no longer than predicted, which is less
        than its least docking from where it would be.
        """
        ps = self.opts.preposition_settings
        f = self.by_rank[k - 1]
        vf, rf = self.v[f], self.r[f]
        total = float(sum(d for _, d in steps))
        wins = [w for w in straight_windows(steps, k, ps.min_straight_s) if w[1] <= until + 1e-9]
        if not wins:
            return None
        obst_f = self.obstacles([self.by_rank[j] for j in range(1, k - 1)], [self.by_rank[j] for j in range(k, self.n + 1)])
        a_max = float(self.struct.slot(self.scn.names[f]).approach_um)
        try:
            app_f = self.approach_path(f, self.goals[f], approach_length(self.struct, self.scn.names[f], self.opts), obst_f, self.lab(f),
                                       a_max=a_max)
        except NoRoute:
            return None
        pre = np.array(app_f.start, dtype=np.float64)
        cand = [(a + (b - a) * q / ps.start_steps, (b - a) * (1.0 - q / ps.start_steps) * frac)
                for a, b in wins for q in range(ps.start_steps) for frac in ps.length_fractions]
        taus, dts = np.array([c[0] for c in cand]), np.array([c[1] for c in cand])
        ends = follower_ends(self.tl.poses[f], vf, rf, total, taus, dts)
        cost, wait_f = docking_costs(ends, pre, vf, rf, self.opts.departure_phases)
        base, _ = docking_costs(follower_ends(self.tl.poses[f], vf, rf, total, np.zeros(1), np.zeros(1)), pre, vf, rf,
                                self.opts.departure_phases)
        obst_s = self.obstacles([self.by_rank[j] for j in range(1, k - 1)], [self.by_rank[j] for j in range(k + 1, self.n + 1)])
        for c in np.argsort(cost, kind="stable")[: ps.checked]:
            if cost[c] > base[0] - ps.min_gain_s:
                break
            if self._preposition_clear(f, float(taus[c]), float(dts[c]), total, float(wait_f[c]), ends[c], pre, obst_s, obst_f, movers):
                self.notes.append(f"{self.lab(f)} drove {vf * dts[c]:.0f} um straight while {what} (P{k - 2})")
                return float(taus[c]), float(dts[c])
        return None

    def _preposition_clear(self, f: int, tau: float, dt: float, total: float, wait_f: float, end: np.ndarray, pre: np.ndarray,
                           obst_s: Obstacles, obst_f: Obstacles, movers: Sequence[tuple[int, pathlib.Path]]) -> bool:
        """Whether D_{k-1} (``f``) may drive straight from ``tau`` for ``dt`` s while the movers move."""
        opts = self.opts
        vf, rf, Lf, Wf = self.v[f], self.r[f], self.L[f], self.W[f]
        follower = pathlib.Path(Pose(*self.tl.poses[f]), rf, (("R", vf * tau), ("S", vf * dt), ("R", vf * (total - tau - dt))))
        if path_hit(obst_s, pathlib.sub_path(follower, vf * tau, vf * (tau + dt)), Lf, Wf, opts) is not None:
            return False
        if path_hit(obst_f, pathlib.Path(Pose(*end), rf, (("R", TWO_PI * rf),)), Lf, Wf, opts) is not None:
            return False
        for i, path in movers:
            t = np.append(np.arange(tau, total, opts.sample_um / max(vf, self.v[i])), total)
            depth = penetration_depth(follower.pose_at(vf * t), Lf, Wf, path.pose_at(self.v[i] * t), self.L[i], self.W[i])
            if (depth > -opts.clearance_um).any():
                return False
        src = advance(end[None, :], np.ones(1, bool), vf, rf, wait_f)[0]
        return path_hit(obst_f, pathlib.shortest_path(src, pre, rf), Lf, Wf, opts) is None


    def _free_run(self, pose: np.ndarray, i: int, obst: Obstacles, limit_um: float, *, backwards: bool) -> float:
        """Longest straight run (um) of robot ``i`` from ``pose`` (ahead, or behind it) clear of ``obst``."""
        h = np.array([math.sin(pose[2]), math.cos(pose[2])]) * (-1.0 if backwards else 1.0)
        probe = np.arange(0.0, limit_um, self.opts.sample_um)
        line = np.column_stack([pose[0] + probe * h[0], pose[1] + probe * h[1], np.full(probe.size, pose[2])])
        blocked = obst.hits(line, self.L[i], self.W[i], self.opts.clearance_um)
        return float(probe[np.argmax(blocked)] - self.opts.sample_um) if blocked.any() else float(probe[-1])

    def form_pair(self) -> None:
        """Step 1: D_n and D_{n-1} form G_1 (see the module docstring for the scheme).

        First without D_n orbiting before its whole-period paths (those schedules are shorter); when
        that finds no schedule, again with it (:meth:`_orbit_first`): more layouts are plannable.
        """
        # Everything the G_1 search depends on besides the scenario, which all variants share: the
        # pair's slots and approach lengths, the options and the pass (each planner starts from the
        # same start poses and the same random stream), so an equal key fails the same way.
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        key = (tuple(np.round(self.goals[[N, M]], 9).ravel()), approach_length(self.struct, self.scn.names[N], self.opts),
               approach_length(self.struct, self.scn.names[M], self.opts), self.extended, self.opts)
        if key in self.search.pair_failures:
            raise NoRoute(self.search.pair_failures[key])
        try:
            self._form_pair_search()
        except NoRoute as exc:
            self.search.pair_failures[key] = exc.reason
            raise

    def _form_pair_search(self) -> None:
        self._orbit_first_on = False
        try:
            self._form_pair_once()
        except NoRoute:
            if self.opts.orbit_phases <= 0 or not self.extended or self.search.spent:
                raise
            self._orbit_first_on = True
            self._timed_cache.clear()
            self._form_pair_once()

    def _form_pair_once(self) -> None:
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        gN, gM = self.goals[N], self.goals[M]
        vN, vM, rN, rM = self.v[N], self.v[M], self.r[N], self.r[M]
        TM = TWO_PI * rM / vM
        lower = [self.by_rank[j] for j in range(1, n - 1)]
        obst_low = self.obstacles(lower, [])
        aM = approach_length(self.struct, self.scn.names[M], self.opts)
        aN = approach_length(self.struct, self.scn.names[N], self.opts)
        whoN, whoM = self.lab(N), self.lab(M)
        opts = self.opts
        approachM = self.approach_path(M, gM, aM, obst_low, whoM)
        preM = np.array(approachM.start, dtype=np.float64)

        # D_{n-1}'s route: it may leave its orbit at any phase (D_n's first stage lasts that long).
        m = opts.departure_phases
        waits = np.arange(m) * TM / m
        sourcesM = advance(np.repeat(self.tl.poses[M][None, :], m, axis=0), np.ones(m, bool), vM, rM, waits)

        # The final corridor: how far behind its slot D_n can run straight into it.
        span = 2.0 * max(self.scn.arena_um or (5000.0, 5000.0))
        d_free = self._free_run(gN, N, obst_low, span, backwards=True)
        if d_free < aN:
            raise NoRoute(f"{whoN}: its straight approach into its slot is blocked ({max(d_free, 0.0):.0f} um free behind it)")
        # Parking tracks for D_n's runs during the earlier pieces: the final corridor itself (its runs
        # stop short of the slot) and the free line ahead of D_n's start.
        # Candidate tracks start on D_n's start orbit (at quarter turns), so reaching them is cheap.
        parks: list = [None]
        obst_park = obst_low.with_disc(turning_centres(self.tl.poses[M], rM)[0], self.rstar[M], "M")
        quarter = np.arange(4) * 0.5 * math.pi * rN / vN
        on_orbit = advance(np.repeat(self.tl.poses[N][None, :], 4, axis=0), np.ones(4, bool), vN, rN, quarter)
        tracks = [(p, self._free_run(p, N, obst_park, span, backwards=False)) for p in on_orbit]
        tracks = sorted((t for t in tracks if t[1] > 2.0 * rN), key=lambda t: -t[1])
        parks.extend(tracks[:2] if opts.max_pieces > 1 else [])
        attempts: list[str] = []
        budget = [opts.pair_schedules]  # schedule attempts per G_1: bounds the planner's time on hopeless layouts
        one_piece = [False]  # schedule only the seed's one-piece scheme
        overlap_routes = [False]  # try overlapped schedules around the routes the roadmap finds
        self._overlap_sched: PairSchedule | None = None
        self._overlap_routes_tried = 0
        if opts.overlap_pair and self._overlap_first(N, M, sourcesM, waits, preM, approachM, obst_low):
            return

        def try_route(sidx: int, routeM: pathlib.Path) -> str | None:
            """Can D_n be scheduled around this route of D_{n-1}? Records the schedule when it can."""
            if overlap_routes[0] and self._overlap_route(N, M, routeM, approachM, float(waits[sidx]), obst_low):
                return None
            fullM = routeM.then(*approachM.segments)
            T = fullM.length / vM
            for park in parks[:1] if one_piece[0] else parks:
                for durs in self._park_cuts(N, M, fullM, T, d_free, park, obst_low, aM, float(waits[sidx])):
                    if one_piece[0] and len(durs) > 1:
                        break
                    if budget[0] <= 0 or self.search.spent:  # every further route would be vetoed: end the search
                        raise SearchSpent(attempts[-1] if attempts else "no schedule")
                    budget[0] -= 1
                    self.search.take()
                    why = self._schedule_pair(N, M, fullM, float(waits[sidx]), durs, park, lower)
                    if why is None:
                        return None
                    attempts.append(why)
            return attempts[-1] if attempts else f"{whoM}'s route is too long for {whoN}'s free corridor ({d_free:.0f} um)"

        self._pair_schedule = None
        self._approach_len = approachM.length
        best = self._best_direct_pair(sourcesM, preM, rM, M, obst_low, try_route) if opts.pair_candidates > 1 else None
        if opts.pair_candidates > 1 and (best is None or len(best[4]) > 1):
            # A detour of D_{n-1} that D_n's corridor covers in one piece is often faster than pieces.
            one_piece[0], budget[0] = True, opts.pair_schedules
            light = replace(opts, roadmap_nodes=opts.roadmap_nodes[:2])
            try:
                route(sourcesM, waits * vM, preM, rM, self.L[M], self.W[M], obst_low, light, self.rng, whoM, extra_check=try_route)
                if best is None or self._pair_duration(self._pair_schedule) < self._pair_duration(best):
                    best = self._pair_schedule
            except NoRoute:
                pass
            one_piece[0] = False
        if best is not None:
            self._pair_schedule = best
            self._run_pair_schedule()
            return
        budget[0] = opts.pair_schedules
        overlap_routes[0] = opts.overlap_pair
        try:
            route(sourcesM, waits * vM, preM, rM, self.L[M], self.W[M], obst_low, opts, self.rng, whoM, extra_check=try_route)
        except NoRoute as exc:
            reason = max(set(attempts), key=attempts.count) if attempts else exc.reason
            raise NoRoute(f"cannot form G_1 with {whoN} and {whoM}: {reason}") from None
        self._run_pair_schedule()


    def _overlap_first(self, N: int, M: int, sourcesM, waits, preM, approachM: pathlib.Path, obst_low: Obstacles) -> bool:
        """Form G_1 with the best overlapped schedule over D_{n-1}'s direct routes; False if there is none."""
        sched = self._overlap_best(N, M, sourcesM, waits, preM, approachM, obst_low)
        if sched is None:
            return False
        self._run_overlap(sched)
        return True

    def _overlap_route(self, N: int, M: int, routeM: pathlib.Path, approachM: pathlib.Path, wait0: float, obst_low: Obstacles) -> bool:
        """Whether an overlapped schedule fits this (roadmap) route of D_{n-1}; records it for :meth:`_run_pair_schedule`.

        Cheaper than for the direct routes: D_n's first path is not routed, and only the first
        ``overlap.roadmap_routes`` routes of a G_1 search are tried (then only the piece scheme).
        """
        self._overlap_routes_tried += 1
        if self._overlap_routes_tried > self.opts.overlap.roadmap_routes:
            return False
        self._overlap_sched = self._overlap_try(N, M, routeM, approachM, wait0, obst_low, route_first=False)
        return self._overlap_sched is not None

    def _overlap_try(self, N: int, M: int, routeM: pathlib.Path, approachM: pathlib.Path, wait0: float, obst_low: Obstacles,
                     not_after_s: float = math.inf, route_first: bool = True) -> PairSchedule | None:
        """An overlapped G_1 schedule around this route of D_{n-1} (leaving after ``wait0`` s), or None."""
        opts = self.opts
        LN, WN, LM, WM = self.L[N], self.W[N], self.L[M], self.W[M]
        vN, vM = self.v[N], self.v[M]

        def static_ok(path: pathlib.Path) -> bool:
            return not obst_low.hits(path.sample(opts.sample_um), LN, WN, opts.clearance_um).any()

        def poses_ok(poses: np.ndarray) -> np.ndarray:
            return ~obst_low.hits(poses, LN, WN, opts.clearance_um)

        def joint_ok(path_n: pathlib.Path, path_m: pathlib.Path) -> bool:
            T = path_m.length / vM
            dt = opts.sample_um / max(vN, vM)
            t = np.append(np.arange(0.0, T, dt), T)
            depth = penetration_depth(path_n.pose_at(vN * t), LN, WN, path_m.pose_at(vM * t), LM, WM)
            limit = np.where(t > T - (opts.approach_um + opts.clearance_um) / min(vN, vM), 0.5, -opts.clearance_um)
            return not (depth > limit).any()

        TM = TWO_PI * self.r[M] / vM
        orbit = TWO_PI * self.r[M]

        # D_n's first path: D_(n-1) orbits at its start all that time (its first arc is on that orbit too)
        obst0 = obst_low.with_disc(turning_centres(self.tl.poses[M], self.r[M])[0], self.rstar[M], f"the orbit of {self.lab(M)}")

        def first_ok(path: pathlib.Path) -> bool:
            coarse = path.sample(opts.overlap.coarse_um)
            return not obst0.hits(coarse, LN, WN, opts.clearance_um).any() and not obst0.hits(path.sample(opts.sample_um), LN, WN,
                                                                                               opts.clearance_um).any()

        def first_path(s1: np.ndarray, t0: float) -> pathlib.Path | None:
            got = self._timed_path(self.tl.poses[N], s1, vN, self.r[N], LN, WN, t0, TM, obst0)
            return None if isinstance(got, str) else got
        for count in range(opts.overlap.max_inserted_orbits + 1):
            for offset in opts.overlap.split_offsets if count else (0.0,):
                routed, at = with_orbits(routeM, count, offset)
                if count and not at:
                    continue
                if any(path_hit(obst_low, pathlib.sub_path(routed, a, a + orbit), LM, WM, opts) for a in at):
                    continue  # D_(n-1)'s inserted orbit is blocked there
                sched = overlap_schedule(self.tl.poses[N], self.tl.poses[M], self.goals[N], routed, approachM, wait0, TM, vN,
                                         self.r[N], vM, self.r[M], static_ok, joint_ok, poses_ok, opts.overlap, not_after_s=not_after_s,
                                         first_path=first_path if route_first else None, first_ok=first_ok)
                if sched is not None:
                    return sched
                break  # the orbits fit: another offset would not help D_n more
        return None

    def _overlap_best(self, N: int, M: int, sourcesM, waits, preM, approachM: pathlib.Path, obst_low: Obstacles) -> PairSchedule | None:
        """The shortest overlapped schedule over D_{n-1}'s direct routes from its departure phases.

        Phases are tried by a lower bound on their schedule (the wait plus D_{n-1}'s route and approach),
        and a phase whose bound is not below the best schedule found is not searched.
        """
        vM, rM = self.v[M], self.r[M]
        lengths = pathlib.shortest_path_lengths(sourcesM, np.broadcast_to(preM, sourcesM.shape), rM)
        bound = waits + (lengths + approachM.length) / vM
        best: PairSchedule | None = None
        for s in np.argsort(bound, kind="stable"):
            if best is not None and bound[s] >= best.duration_s - 1e-9:
                break
            p = pathlib.shortest_path(sourcesM[s], preM, rM)
            if path_hit(obst_low, p, self.L[M], self.W[M], self.opts) is not None:
                continue
            sched = self._overlap_try(N, M, p, approachM, float(waits[s]), obst_low,
                                      not_after_s=math.inf if best is None else best.duration_s - 1e-9)
            if sched is not None and (best is None or sched.duration_s < best.duration_s):
                best = sched
        return best

    def _run_overlap(self, sched: PairSchedule) -> None:
        """Apply an overlapped G_1 schedule to the timeline, one phase per piece of D_n's path."""
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        vN, vM = self.v[N], self.v[M]
        last = max(t1 for _, t1, free in sched.pieces if not free)
        pre_f = None
        if self.opts.preposition and n >= 3:  # D_(n-2) drives straight while both drive straight (P_(n-3))
            steps = joint_primitives(sched.path_n, vN, sched.path_m, vM, n)
            pre_f = self._preposition(n - 1, steps, [(N, sched.path_n), (M, sched.path_m)], "G_1 formed")
        for t_a, t_b, free in sched.pieces:
            if t_b - t_a <= 0.0:
                continue
            pn = pathlib.sub_path(sched.path_n, vN * t_a, vN * t_b)
            pm = pathlib.sub_path(sched.path_m, vM * t_a, vM * t_b)
            t0 = self.tl.t
            steps = joint_primitives(pn, vN, pm, vM, n)
            if pre_f is not None and t_a - 1e-9 <= pre_f[0] and pre_f[0] + pre_f[1] <= t_b + 1e-9:
                steps = splice_straight(steps, n - 1, max(pre_f[0] - t_a, 0.0), pre_f[1])
            for k, d in steps:
                self.tl.apply(k, d, counts_for=(N,))
            if free:
                self.tl.phase("pair-A", N, n, n - 1, t0, pn.end, partner=M, partner_end=tuple(float(v) for v in self.tl.poses[M]),
                              path=pn.segments, path_start=tuple(float(v) for v in pn.start))
            else:
                self.tl.phase("pair-B", M, n - 1, n - 2, t0, pm.end, partner=N, run=(tuple(float(v) for v in pn.start), float(pn.length)),
                              last=t_b == last, path=pm.segments, path_start=tuple(float(v) for v in pm.start))
        self.route_lengths[N] = sched.path_n.length
        self.route_lengths[M] = sched.path_m.length - vM * sched.wait_s
        windows = sum(1 for _, _, free in sched.pieces[1:] if free)
        self.notes.append(
            f"G_1 overlapped: {self.lab(N)} turns while {self.lab(M)} turns ({windows} window(s) on its route), "
            f"runs straight only while it does; G_1 takes {sched.duration_s:.1f} s"
        )
        self.tl.dock(N, self.goals[N], self.lab(N))
        self.tl.dock(M, self.goals[M], self.lab(M))

    def _best_direct_pair(self, sourcesM, preM, rM, M, obst_low, try_route):
        """The shortest G_1 schedule over D_{n-1}'s direct routes from its departure phases, or None.

        ``route`` takes the first departure whose route can be scheduled, ordered by D_{n-1}'s own travel;
        but the pair's duration is set by D_n (its first path lasts a whole number of D_{n-1}'s periods
        and every extra piece adds a loop back), so up to ``pair_candidates`` schedulable departures are
        scheduled and the one that forms G_1 soonest is kept.
        """
        order = np.argsort(pathlib.shortest_path_lengths(sourcesM, np.broadcast_to(preM, sourcesM.shape), rM), kind="stable")
        found: list = []
        for s in order:
            if len(found) >= self.opts.pair_candidates:
                break
            p = pathlib.shortest_path(sourcesM[s], preM, rM)
            if path_hit(obst_low, p, self.L[M], self.W[M], self.opts) is not None:
                continue
            self._pair_schedule = None
            try:
                ok = try_route(int(s), p) is None
            except SearchSpent:
                break
            if ok and self._pair_schedule is not None:
                found.append((self._pair_duration(self._pair_schedule), len(found), self._pair_schedule))
        self._pair_schedule = None
        return min(found)[2] if found else None

    def _park_cuts(self, N: int, M: int, fullM: pathlib.Path, T: float, d_free: float, park, obst_low: Obstacles,
                   aM: float, wait0: float):
        """The cut options (:meth:`_cut_options`) for parking track ``park`` after a wait of ``wait0`` s.

        A track that starts at D_n's own start is where D_n passes D_{n-1}'s wait, driving straight
        (:meth:`_schedule_pair`), so its runs start ``v_n wait0`` um further on. Pieces cut to the whole
        track run off its end when the track ends at the arena edge (where it ends at D_{n-1}'s orbit
        they can still pass). The extended search first tries the pieces that fit in the part left.
        """
        cuts = self._cut_options(N, M, fullM, T, d_free, park, obst_low, aM)
        if not self.extended or park is None or wait0 <= 0 or not np.allclose(np.asarray(park[0]), self.tl.poses[N]):
            yield from cuts
            return
        ahead = self.v[N] * wait0
        h = np.array([math.sin(park[0][2]), math.cos(park[0][2]), 0.0])
        left = (np.asarray(park[0], float) + ahead * h, max(park[1] - ahead, 0.0))
        seen: set = set()
        for durs in self._cut_options(N, M, fullM, T, d_free, left, obst_low, aM):
            seen.add(durs)
            yield durs
        yield from (durs for durs in cuts if durs not in seen)

    def _pair_duration(self, schedule) -> float:
        """Duration (s) of a G_1 schedule: D_n's timed paths plus D_{n-1}'s pieces."""
        N, _, _, _, durs, _, a_paths = schedule
        return float(sum(p.length for p in a_paths) / self.v[N] + sum(durs))

    def _run_starts(self, N: int, durs: Sequence[float], park) -> list[np.ndarray]:
        """Start pose of D_n's straight run in every piece: the parking track, the final corridor last."""
        gN = self.goals[N]
        final = pre_approach_pose(gN, self.v[N] * durs[-1])
        if park is None:
            return [final] * len(durs)
        return [np.asarray(park[0], float)] * (len(durs) - 1) + [final]

    def _orbits_clear(self, centres: np.ndarray, M: int, obst_low: Obstacles) -> np.ndarray:
        """``(K,)`` bool: whether D_{n-1} (index ``M``) orbiting about each of ``centres`` keeps the
        clearance from the lower robots' orbit discs and from the arena edge."""
        clearance = self.opts.clearance_um
        rr = self.rstar[M] + clearance
        ok = np.ones(len(centres), dtype=bool)
        if len(obst_low.disc_radii):
            gap = np.hypot(centres[:, None, 0] - obst_low.disc_centres[None, :, 0], centres[:, None, 1] - obst_low.disc_centres[None, :, 1])
            ok &= (gap - obst_low.disc_radii[None, :] - self.rstar[M] >= clearance).all(axis=1)
        if self.scn.arena_um is not None:
            w, h = self.scn.arena_um
            ok &= (centres[:, 0] >= rr) & (centres[:, 0] <= w - rr) & (centres[:, 1] >= rr) & (centres[:, 1] <= h - rr)
        return ok

    def _cut_options(self, N: int, M: int, fullM: pathlib.Path, T: float, d_free: float, park, obst_low: Obstacles, aM: float):
        """Ways to cut D_{n-1}'s route (duration ``T`` s) into pieces for the G_1 schedule.

        The last piece is D_n's run into its slot, so it lasts at most ``d_free / v_n``; the earlier
        pieces are runs on the parking track ``park`` (``(pose, free length)``, or None for the final
        corridor, where they may not be longer than the last). D_{n-1} must be able to orbit at every
        cut. Cut points are chosen greedily from the end, each as early as the piece limit allows, among
        the positions where D_{n-1}'s orbit clears the lower orbits, the arena and D_n's run corridors.
        """
        opts = self.opts
        vN, vM, rM = self.v[N], self.v[M], self.r[M]
        t_last_max = d_free / vN
        if park is None and T <= t_last_max + 1e-9:
            yield (T,)
        total = fullM.length
        pos = np.arange(0.0, total, 10.0)
        centres = turning_centres(fullM.pose_at(pos), rM)
        rr = self.rstar[M] + opts.clearance_um
        ok = self._orbits_clear(centres, M, obst_low)
        gN = self.goals[N]
        seen = set()
        # On the final corridor D_n loops back to its right and reaches about r + L/2 past the end of
        # its run: earlier runs may stop short of the slot by that much (away from D_{n-1}'s last stops).
        short = (self.r[N] + 0.5 * self.L[N] + self.W[N] + opts.clearance_um) / vN
        if park is None:
            variants = [(f, 0.0) for f in (1.0, 0.8, 0.62, 0.48, 0.36)] + [(f, short) for f in (1.0, 0.8, 0.62, 0.48)]
        else:
            # runs that stop short of the track's end leave D_n room to loop back (the end is an obstacle)
            variants = [(f, 0.0) for f in (1.0, 0.7, 0.45, 0.3)] + ([(f, short) for f in (1.0, 0.7, 0.45)] if self.extended else [])
        for frac, margin in variants:
            tm = min(t_last_max * frac, T)
            if tm < aM / vM or tm >= T - 1e-9:
                continue
            if park is None:
                t_piece = tm - margin
                keep = [(pre_approach_pose(gN, 0.5 * vN * tm), vN * tm)]
            else:
                t_piece = park[1] / vN - margin
                keep = [(pre_approach_pose(gN, 0.5 * vN * tm), vN * tm), (pre_approach_pose(np.asarray(park[0]), -0.5 * park[1]), park[1])]
            if t_piece <= 0.2 * tm or (T - tm) / t_piece > opts.max_pieces:
                continue
            good = ok.copy()
            for centre_pose, length in keep:
                good &= point_rectangle_distance(centres, centre_pose, length + self.L[N], self.W[N])[0] >= rr
            good[0] = True  # D_{n-1}'s departure point: it orbits there anyway
            cuts = [total - vM * tm]
            while cuts[-1] > 1e-9:
                lo = cuts[-1] - vM * t_piece
                cand = np.flatnonzero(good & (pos >= lo - 1e-9) & (pos < cuts[-1] - 1e-9))
                if len(cand) == 0 or len(cuts) > opts.max_pieces:
                    cuts = []
                    break
                cuts.append(float(pos[cand[0]]))
            if not cuts:
                continue
            k_last = int(np.searchsorted(pos, cuts[0] - 1e-9))
            if k_last < pos.size and not good[k_last]:
                continue
            bounds = [0.0] + sorted(c for c in cuts if c > 1e-9) + [total]
            durs = tuple((b - a) / vM for a, b in zip(bounds[:-1], bounds[1:], strict=False))
            if len(durs) > opts.max_pieces:
                continue
            key = tuple(round(x, 6) for x in durs)
            if key not in seen:
                seen.add(key)
                yield durs

    def _schedule_pair(self, N: int, M: int, fullM: pathlib.Path, wait0: float, durs: Sequence[float], park,
                       lower: list[int]) -> str | None:
        """Plan D_n around D_{n-1}'s route cut into pieces of durations ``durs`` (s); None on success.

        During piece j D_{n-1} drives its piece (P_{n-1}/P_{n-2}) while D_n runs straight from
        ``run_starts[j]``; the last run ends in D_n's slot as D_{n-1} reaches its own. Between pieces D_n
        drives (P_n/P_{n-1}) from the end of one run to the start of the next on a path lasting a whole
        number of D_{n-1}'s orbit periods, so D_{n-1}, orbiting, is back where it stopped.
        """
        opts = self.opts
        vN, vM, rN, rM = self.v[N], self.v[M], self.r[N], self.r[M]
        LN, WN, LM, WM = self.L[N], self.W[N], self.L[M], self.W[M]
        TM = TWO_PI * rM / vM
        pieces = len(durs)
        straight_first = 0.0
        here = self.tl.poses[N]
        if park is not None and wait0 > 0 and np.allclose(np.asarray(park[0]), here):
            # Parked at its own start: D_n passes D_{n-1}'s wait for its departure driving straight along
            # its track (P_{n-1}: D_{n-1} orbits) instead of killing time on a loop.
            straight_first = vN * wait0
            if straight_first >= park[1] - 2.0 * rN:
                return f"{self.lab(N)}'s parking track is too short to wait {wait0:.1f} s on it"
            hN = np.array([math.sin(here[2]), math.cos(here[2]), 0.0])
            park = (np.asarray(park[0]) + straight_first * hN, park[1] - straight_first)
        starts = self._run_starts(N, durs, park)
        runs = [pathlib.Path(Pose(*s0), rN, (("S", vN * t),)) for s0, t in zip(starts, durs, strict=False)]
        whoN, whoM = self.lab(N), self.lab(M)
        obst_low = self.obstacles(lower, [])
        bounds_t = np.concatenate([[0.0], np.cumsum(durs)])
        cuts = [fullM.pose_at(vM * bounds_t[j]) for j in range(1, pieces)]
        # 1. Runs clear of the lower orbits and the arena.
        for j, run in enumerate(runs):
            hit = obst_low.first_hit(run.sample(opts.sample_um), LN, WN, opts.clearance_um)
            if hit is not None:
                return f"{whoN}'s straight run {j + 1} is blocked by {hit}"
        # 2. B phases: D_n's run against D_{n-1}'s piece, sampled in time (touching only at the very end).
        dt = opts.sample_um / max(vN, vM)
        for j in range(pieces):
            tp = durs[j]
            t = np.minimum(np.arange(0.0, tp + dt, dt), tp)
            pn = runs[j].pose_at(vN * t)
            pm = fullM.pose_at(np.minimum(vM * (bounds_t[j] + t), fullM.length))
            depth = penetration_depth(pn, LN, WN, pm, LM, WM)
            final = j == pieces - 1
            limit = np.where(final & (t > tp - (opts.approach_um + opts.clearance_um) / min(vN, vM)), 0.5, -opts.clearance_um)
            if (depth > limit).any():
                return f"{whoN}'s straight run meets {whoM} (piece {j + 1} of {pieces})"
        # 3. A phases: D_n's paths lasting a whole number of D_{n-1}'s periods; D_{n-1} orbits meanwhile.
        obst0 = obst_low.with_disc(turning_centres(self.tl.poses[M], rM)[0], self.rstar[M], f"the orbit of {whoM}")
        first: pathlib.Path | str
        if straight_first > 0.0:
            run = pathlib.Path(Pose(*here), rN, (("S", straight_first),))
            hit = obst0.first_hit(run.sample(opts.sample_um), LN, WN, opts.clearance_um)
            first = run if hit is None else f"blocked by {hit}"
        else:
            first = self._timed_path(self.tl.poses[N], starts[0], vN, rN, LN, WN, wait0, TM, obst0)
        if isinstance(first, str):
            return f"{whoN} cannot reach the start of its first run ({first})"
        a_paths = [first]
        for j, c in enumerate(cuts):
            disc_c = turning_centres(np.array(c), rM)[0]
            ob = obst_low.with_disc(disc_c, self.rstar[M], f"the orbit of {whoM} at its stop {j + 1}")
            end_j = np.array(runs[j].end)
            same_track = np.allclose(starts[j], starts[j + 1])
            link = self._timed_path(end_j, starts[j + 1], vN, rN, LN, WN, 0.0, TM, ob)
            if isinstance(link, str):
                what = "loop back to its run" if same_track else "move to its final corridor"
                return f"{whoN} cannot {what} ({link})"
            a_paths.append(link)
        self._pair_schedule = (N, M, fullM, wait0, tuple(durs), runs, a_paths)
        return None

    def _timed_path(self, start, goal, v, r, L, W, wait0, period, obst, *, use_route: bool = True) -> pathlib.Path | str:
        """A collision-free path of duration ``wait0 + k * period`` (k >= 0 whole) from start to goal.

        Tries the direct paths of those lengths first; with ``route`` it then routes around the
        obstacles and stretches the route to an exact length. Returns the path or the reason it failed.
        """
        start = np.asarray(start, float)
        goal = np.asarray(goal, float)
        key = (tuple(np.round(start, 4)), tuple(np.round(goal, 4)), round(wait0, 6),
               tuple(np.round(obst.disc_centres, 3).ravel()), use_route)
        if key not in self._timed_cache:
            self._timed_cache[key] = self._timed_path_uncached(start, goal, v, r, L, W, wait0, period, obst, use_route)
        return self._timed_cache[key]

    def _timed_path_uncached(self, start, goal, v, r, L, W, wait0, period, obst, use_route) -> pathlib.Path | str:
        base = pathlib.shortest_path(start, goal, r)
        kmin = max(0, math.ceil((base.length / v - wait0) / period - 1e-9))
        wants = [v * (wait0 + k * period) for k in range(kmin, kmin + 4)]
        last = "no path of a fitting length"
        for want in wants:
            try:
                p = pathlib.path_of_length(start, goal, r, want)
            except pathlib.InfeasibleLengthError:
                continue
            hit = path_hit(obst, p, L, W, self.opts)
            if hit is None:
                return p
            last = f"blocked by {hit}"
        if not use_route:
            return self._orbit_first(start, goal, v, r, L, W, wait0, period, obst) or last
        # Route around the obstacles once, then stretch the route's tail to an exact length.
        rkey = (tuple(np.round(start, 4)), tuple(np.round(goal, 4)), tuple(np.round(obst.disc_centres, 3).ravel()))
        if rkey not in self._route_cache:
            try:
                # D_n's timed legs are local manoeuvres: small roadmaps, or the G_1 search gets slow
                light = replace(self.opts, roadmap_nodes=self.opts.roadmap_nodes[:2])
                _, path, way = route(start[None, :], np.zeros(1), goal, r, L, W, obst, light, self.rng, "")
                self._route_cache[rkey] = (path, (start,) + tuple(way))
            except NoRoute as exc:
                self._route_cache[rkey] = exc.reason.lstrip(": ") or last
        cached = self._route_cache[rkey]
        if not isinstance(cached, str):
            routed, nodes = cached
            for want in wants + [v * (wait0 + k * period) for k in range(kmin + 4, kmin + 8)]:
                if routed.length > want + 1e-9:
                    continue
                stretched = self._stretch(routed, want, obst, L, W)
                if stretched is None and self.extended:
                    stretched = self._stretch_leg(nodes, r, want, obst, L, W)
                if stretched is not None:
                    return stretched
        # last resort: spend part of the time on its own orbit, then leave at a phase that clears
        return self._orbit_first(start, goal, v, r, L, W, wait0, period, obst) or (cached if isinstance(cached, str) else last)

    def _orbit_first(self, start, goal, v, r, L, W, wait0, period, obst) -> pathlib.Path | None:
        """A path of duration ``wait0 + k * period`` that first orbits at ``start`` for a while.

        The mover turns under the same primitive that keeps its partner orbiting, so it can spend part
        of the time on its own orbit and leave it at the phase from which a path of the remaining length
        is clear: :attr:`PlannerOptions.orbit_phases` phases of one orbit, the four shortest k each.
        """
        m = self.opts.orbit_phases
        if m <= 0 or not self._orbit_first_on:
            return None
        own = 2.0 * math.pi * r / v
        taus = (np.arange(1, m) / m) * own
        ring = advance(np.repeat(np.asarray(start, float)[None, :], len(taus), axis=0), np.ones(len(taus), bool), v, r, taus)
        base = pathlib.shortest_path_lengths(ring, np.broadcast_to(goal, ring.shape), r)
        cands: list = []
        for j, tau in enumerate(taus):
            kmin = max(0, math.ceil((tau + base[j] / v - wait0) / period - 1e-9))
            cands.extend((wait0 + k * period, j) for k in range(kmin, kmin + 3))
        for total, j in sorted(cands):
            want = v * (total - taus[j])
            try:
                p = pathlib.path_of_length(ring[j], goal, r, want)
            except pathlib.InfeasibleLengthError:
                continue
            full = pathlib.Path(Pose(*(float(x) for x in start)), r, (("R", v * taus[j]),) + p.segments)
            if path_hit(obst, full, L, W, self.opts) is None:
                return full
        return None

    def _stretch_leg(self, nodes, r: float, want: float, obst, L, W) -> pathlib.Path | None:
        """Lengthen a route through ``nodes`` (start, waypoints, goal) to ``want`` um in one of its legs.

        The tail stretch (:meth:`_stretch`) replaces everything after a node, so it cuts across the
        obstacles the route went around; here every other leg stays a shortest path and the one leg
        that gets the extra length is chosen, longest first (most room to bend).
        """
        legs = [pathlib.shortest_path(a, b, r) for a, b in zip(nodes[:-1], nodes[1:], strict=False)]
        extra = want - sum(p.length for p in legs)
        if extra < -1e-9:
            return None
        for j in sorted(range(len(legs)), key=lambda q: -legs[q].length):
            try:
                leg = pathlib.path_of_length(nodes[j], nodes[j + 1], r, legs[j].length + extra)
            except pathlib.InfeasibleLengthError:
                continue
            if path_hit(obst, leg, L, W, self.opts) is None:
                segs = tuple(sg for q, p in enumerate(legs) for sg in (leg.segments if q == j else p.segments))
                return pathlib.Path(Pose(*(float(x) for x in nodes[0])), r, segs)
        return None

    def _stretch(self, path: pathlib.Path, want: float, obst, L, W) -> pathlib.Path | None:
        """Lengthen a route to exactly ``want`` um by replacing its tail with a path of a set length."""
        nodes = path.nodes
        segs = path.segments
        for cut in range(len(segs) - 1, -1, -1):
            head = pathlib.Path(path.start, path.radius, segs[:cut])
            need = want - head.length
            try:
                tail = pathlib.path_of_length(nodes[cut], nodes[-1], path.radius, need)
            except pathlib.InfeasibleLengthError:
                continue
            if path_hit(obst, tail, L, W, self.opts) is None:
                return pathlib.Path(path.start, path.radius, segs[:cut] + tail.segments)
        return None

    def _run_pair_schedule(self) -> None:
        if self._overlap_sched is not None:  # the search accepted an overlapped schedule around a roadmap route
            self._run_overlap(self._overlap_sched)
            return
        assert self._pair_schedule is not None  # set by form_pair's successful search
        N, M, fullM, wait0, durs, runs, a_paths = self._pair_schedule
        n = self.n
        vM, vN = self.v[M], self.v[N]
        pieces = len(durs)
        bounds = np.concatenate([[0.0], np.cumsum(durs)]) * vM
        # A_0: D_n drives to the start of its first run (P_n / P_{n-1}); D_{n-1} orbits to its departure phase.
        t0 = self.tl.t
        self.tl.apply_path(N, a_paths[0], n, n - 1)
        self.tl.phase("pair-A", N, n, n - 1, t0, a_paths[0].end, partner=M, partner_end=tuple(float(v) for v in self.tl.poses[M]),
                      path=a_paths[0].segments, path_start=tuple(float(v) for v in a_paths[0].start))
        for j in range(pieces):
            # B_j: D_{n-1} drives its piece (P_{n-1} / P_{n-2}); D_n drives straight.
            piece = pathlib.sub_path(fullM, bounds[j], bounds[j + 1])
            before = self.tl.travel[N]
            t0 = self.tl.t
            self.tl.apply_path(M, piece, n - 1, n - 2)
            self.tl.phase(
                "pair-B", M, n - 1, n - 2, t0, piece.end, partner=N,
                run=(tuple(float(v) for v in runs[j].start), float(runs[j].length)), last=j + 1 == pieces, path=piece.segments,
                path_start=tuple(float(v) for v in piece.start),
            )
            self.tl.travel[N] = before + vN * durs[j]
            if j + 1 < pieces:
                t0 = self.tl.t
                self.tl.apply_path(N, a_paths[j + 1], n, n - 1)
                self.tl.phase("pair-A", N, n, n - 1, t0, a_paths[j + 1].end, partner=M,
                              partner_end=tuple(float(v) for v in self.tl.poses[M]), path=a_paths[j + 1].segments,
                              path_start=tuple(float(v) for v in a_paths[j + 1].start))
        self.route_lengths[M] = fullM.length
        self.route_lengths[N] = sum(p.length for p in a_paths) + vN * sum(durs)
        if pieces > 1:
            parked = not np.allclose(runs[0].start, runs[-1].start)
            self.notes.append(
                f"G_1: {self.lab(M)}'s route was cut into {pieces} pieces; {self.lab(N)} ran "
                f"{'on a parking track, then ' if parked else ''}a final corridor of {runs[-1].length:.0f} um "
                f"(the paper's two-stage scheme would need {vN * sum(durs):.0f} um)"
            )
        self.tl.dock(N, self.goals[N], self.lab(N))
        self.tl.dock(M, self.goals[M], self.lab(M))


def _plan_primitives(analysis: ControlAnalysis) -> tuple[PlanPrimitive, ...]:
    return tuple(PlanPrimitive(p.name, tuple(p.turning)) for p in analysis.primitives)


def _plan_structure(scn, analysis: ControlAnalysis, st: Structure, lb: float, candidates: int, opts: PlannerOptions, say,
                    extended: bool = False, search: SharedSearch | None = None) -> PlanResult | str:
    """Plan the assembly of one candidate structure: the replayed result, or why it failed."""
    t0 = time.perf_counter()
    planner = _Planner(scn, analysis, st, opts, extended=extended, search=search)
    try:
        for k in planner.search.bottlenecks:  # fail fast where an earlier variant failed to dock
            planner.dock_check(k)
        say(f"forming G_1 ({planner.lab(planner.by_rank[scn.n])}, {planner.lab(planner.by_rank[scn.n - 1])})")
        planner.form_pair()
    except NoRoute as exc:
        return exc.reason
    try:
        for k in range(scn.n - 2, 0, -1):
            say(f"docking {planner.lab(planner.by_rank[k])}")
            planner.dock_single(k)
    except NoRoute as exc:
        planner.search.docking_failed.add(id(st))
        if k not in planner.search.bottlenecks:
            planner.search.bottlenecks.append(k)
        return exc.reason
    steps = merge_steps(planner.tl.steps, min_duration_s=1e-12)
    from .outputs import provenance

    plan = Plan(
        robots=scn.names,
        primitives=_plan_primitives(analysis),
        steps=steps,
        goals={nm: Pose(*st.goal_poses([nm])[0]) for nm in scn.names},
        provenance=provenance(opts.seed),
    )
    accessible = {frozenset(p.turning) for p in analysis.primitives}
    rep = replay(plan, scn, accessible_turning=accessible)
    if not rep.ok:
        return "internal: the plan failed its replay: " + "; ".join(rep.problems[:3])
    duration = plan.duration_s
    summary = {
        "structure": st.shape,
        "variant": st.variant,
        "order": list(analysis.order or ()),
        "duration_s": duration,
        "steps": len(steps),
        "route_length_um": {scn.names[i]: float(planner.route_lengths[i]) for i in range(scn.n)},
        "lower_bound_s": lb,
        "efficiency": lb / duration if duration > 0 else 1.0,
        "planning_time_s": time.perf_counter() - t0,
        "candidates": candidates,
        "notes": planner.notes,
    }
    return PlanResult(plan, st, analysis, rep, summary, tuple(planner.notes), tuple(planner.tl.phases))


def plan_assembly(scenario, options: PlannerOptions | None = None, *, progress: Callable[[str], None] | None = None) -> PlanResult:
    """Plan the assembly of ``scenario``'s target structure from its start poses.

    Returns a :class:`PlanResult` whose plan has passed :func:`stressbots.replay.replay`. Raises
    :class:`~stressbots.errors.PlanningError` naming what blocks the assembly when no plan is found.
    """
    opts = options or PlannerOptions()
    say = progress or (lambda _msg: None)
    scn = scenario
    if scn.n < 2:
        raise PlanningError("a structure needs at least 2 robots (G_1 is a pair)", source=scn.source)
    _ = scn.starts  # raises a ScenarioError naming a robot without a start
    analysis = analyse_scenario(scn)
    if not analysis.is_string:
        raise PlanningError(
            "the voltage design is not STRING, so primitives P_0..P_n do not exist: " + "; ".join(analysis.reasons),
            source=scn.source,
        )
    order = analysis.order_index
    assert order is not None  # STRING, checked above
    robots_in_order = [scn.robots[i] for i in order]
    structures = target_structures(robots_in_order, scn.structure)
    rank = np.empty(scn.n, dtype=int)
    for k, i in enumerate(order):
        rank[i] = k + 1
    # Cheapest candidates first (by the lower bound); skip those the starts rule out.
    scored: list = []
    first_reason = None
    for st in structures:
        why = _prechecks(scn, st, rank)
        if why is not None:
            first_reason = first_reason or why
            continue
        scored.append((lower_bound_s(scn, st, rank), len(scored), st))
    if not scored:
        raise PlanningError(first_reason or "no structure fits", source=scn.source)
    scored.sort(key=lambda x: (x[0], x[1]))
    failures: list[str] = []
    t_start = time.perf_counter()
    search = SharedSearch(opts.search_budget)
    best = _best_variant(scn, analysis, scored, len(structures), opts, say, failures, t_start, extended=False, search=search)
    standard = len(failures)
    if best is None and opts.extended_search and not search.spent:
        best = _best_variant(scn, analysis, scored, len(structures), opts, say, failures, t_start, extended=True, search=search)
    if best is not None:
        return best
    # the extended search's reasons, when it ran: what still blocks after the wider search
    last = failures[standard:] or failures
    reason = max(set(last), key=last.count) if last else "no plan found"
    if search.spent:
        reason += f" (search budget of {opts.search_budget} G_1 schedules spent: a larger PlannerOptions.search_budget searches longer)"
    raise PlanningError(reason + advice(reason), source=scn.source)


def _best_variant(scn, analysis, scored, candidates: int, opts: PlannerOptions, say, failures: list[str], t_start: float, *,
                  extended: bool, search: SharedSearch) -> PlanResult | None:
    """The shortest plan over up to ``variants_compared`` plannable variants (cheapest bound first).

    ``extended`` turns on the wider G_1 search (one-leg stretch, orbit first); plan_assembly uses it
    only when no variant is plannable without it, so layouts the standard search solves keep its plans.
    """
    best: PlanResult | None = None
    tried = 0
    for attempt, (lb, _, st) in enumerate(scored):
        if best is None and opts.max_candidates is not None and attempt >= opts.max_candidates:
            failures.append(f"no plan within the first {opts.max_candidates} candidate structures")
            break
        if best is not None and (tried + 1 >= opts.variants_compared or lb >= best.summary["duration_s"]):
            break
        if best is None and search.spent:
            break
        if extended and id(st) in search.docking_failed:
            continue  # it formed G_1 and failed later: a wider G_1 search cannot help
        if best is None and failures and time.perf_counter() - t_start > opts.time_budget_s:
            failures.append(f"no plan within the time budget of {opts.time_budget_s:g} s")
            break
        tried += best is not None
        # Variants compared after a plan exists get a lighter search (no largest roadmap, no second G_1
        # pass): they only replace the plan when they are easy, and hard ones would dominate the time.
        light = opts if best is None else replace(opts, roadmap_nodes=opts.roadmap_nodes[:2], orbit_phases=0)
        result = _plan_structure(scn, analysis, st, lb, candidates, light, say, extended, search)
        if isinstance(result, str):
            failures.append(result)
            continue
        if best is None or result.summary["duration_s"] < best.summary["duration_s"] - 1e-9:
            best = result
    return best


_ADVICE = (
    (re.compile(r"the orbit of (D\d+ \('[^']*'\))"), "move the start of {0} (its orbit disc is in the way) or enlarge the arena"),
    (re.compile(r"too long for (D\d+ \('[^']*'\))'s free corridor"),
     "start the G_1 robots closer to their slots, or clear the line behind {0}'s slot"),
    (re.compile(r"the arena edge"), "enlarge the arena or move the structure (or the starts) away from its edge"),
    (re.compile(r"the docked body of (D\d+ \('[^']*'\))|approach into its slot is blocked"),
     "change the structure (a slot whose approach is clear of the robots docked before it)"),
    (re.compile(r"meets (D\d+ \('[^']*'\))"), "move the start of {0} away from its partner's straight runs"),
)


def advice(reason: str) -> str:
    """What would make a layout plannable, from the failure ``reason`` (``"; to make it plannable: ..."``).

    The reason names the robot and the obstacle; the advice names the change (move that start, enlarge
    the arena, change the structure). The first matching obstacle kind wins; empty when none matches.
    """
    for pattern, text in _ADVICE:
        m = pattern.search(reason)
        if m:
            return "; to make it plannable: " + text.format(*m.groups())
    return ""
