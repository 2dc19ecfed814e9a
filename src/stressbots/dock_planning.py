"""Docking of single robots (steps 2..n-1 of the planner, seed App. 2) and their final approaches.

D_k docks with P_k/P_{k-1} while D_1..D_{k-1} orbit and the docked robots push, after waiting on its
orbit for the best of several departure phases. While it drives straight, the next robot may be
pre-positioned (:mod:`stressbots.prepositioning`). :meth:`DockPlanning.approach_path` is every robot's final
approach into its slot (G_1's pair too).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from . import paths as pathlib
from .collision import penetration_depth
from .kinematics import advance, move
from .planner_state import PlannerState, approach_length, pre_approach_pose
from .prepositioning import docking_costs, follower_ends, splice_straight, straight_windows
from .robots import TWO_PI, Pose
from .routing import NoRoute, Obstacles, path_hit, route


class DockPlanning(PlannerState):
    """Single-robot docking, pre-positioning and final approaches of the planner."""

    def approach_path(self, i: int, goal: np.ndarray, a: float, obst: Obstacles, who: str, a_max: float | None = None,
                      tight: bool = False) -> pathlib.Path:
        """The final approach of robot ``i`` into its slot, ``a`` um long.

        A clockwise arc of radius ``s / phi`` (flown as an interpolated turn, seed App. 3.1) that arrives
        at the slot's heading a short straight push before the slot. Only points to a robot's right are
        reachable on one clockwise arc (seed Fig. 4): ending the nominal approach on such an arc leaves
        the fine-motion controller room to correct errors either way by changing r'. ``phi`` is the
        largest of 20, 12, 6 deg whose swept bodies clear the obstacles (touching the structure at the
        end is docking); else a straight approach, as long as the slot's clear corridor (``a_max``) if
        need be, so that it starts outside a gap between docked neighbours.

        ``tight``: instead, arcs of :attr:`PlannerOptions.tight_approach_deg` at
        :attr:`PlannerOptions.tight_approach_radius` times the turning radius, which start off to the
        side of the slot rather than behind it: for a slot whose rear lies near the arena edge (a long
        stem's tip), where a route cannot reach the start of the gentle approach (:meth:`dock_route`).
        """
        r, L, W = self.r[i], self.L[i], self.W[i]
        tail = min(20.0, 0.25 * a)
        p_pre = pre_approach_pose(goal, tail)
        hit = None
        options = [(20.0, a), (12.0, a), (6.0, a), (0.0, a)]
        if tight:
            rho = self.opts.tight_approach_radius * r
            options = [(phi, tail + rho * math.radians(phi)) for phi in self.opts.tight_approach_deg]
        elif a_max is not None and a_max > a:
            options.append((0.0, a_max))
        for phi_deg, length in options:
            s_f = length - tail
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
        obst = self.obstacles([self.by_rank[j] for j in range(1, k)], [self.by_rank[j] for j in range(k + 1, self.n + 1)])
        m = self.opts.departure_phases
        waits = np.arange(m) * TWO_PI * self.r[i] / self.v[i] / m
        sources = advance(np.repeat(self.scn.starts[i][None, :], m, axis=0), np.ones(m, bool), self.v[i], self.r[i], waits)
        rng = np.random.default_rng(np.random.SeedSequence([self.opts.seed, k, 1]))
        self.dock_route(i, obst, sources, waits * self.v[i], rng, note=False)

    def dock_route(self, i: int, obst: Obstacles, sources: np.ndarray, costs: np.ndarray, rng: np.random.Generator, *,
                   note: bool = True):
        """Robot ``i``'s final approach and its route from one of ``sources`` to the approach's start:
        ``(approach, (source_index, path, waypoints))``; raises :class:`NoRoute`.

        The gentle approach first (:meth:`approach_path`); when no route reaches its start (or it is
        blocked), the tight approaches, which start beside the slot instead of behind it. The first
        failure's reason is the one raised: it names what blocks the usual approach. ``note``: say in
        the plan's notes when the tight approach is taken (not for :meth:`dock_check`'s test).
        """
        who = self.lab(i)
        name = self.scn.names[i]
        a, slot = approach_length(self.struct, name, self.opts), float(self.struct.slot(name).approach_um)
        try:
            approach = self.approach_path(i, self.goals[i], a, obst, who, a_max=slot)
            return approach, self._route_to(i, approach, obst, sources, costs, rng)
        except NoRoute as exc:
            if not self.opts.tight_approach_deg:
                raise
            first = exc
        try:
            approach = self.approach_path(i, self.goals[i], a, obst, who, tight=True)
            found = self._route_to(i, approach, obst, sources, costs, rng)
        except NoRoute:
            raise first from None
        if note:
            self.notes.append(f"{who} docks by a tight approach arc ({approach.length:.0f} um): no route reaches the gentle one")
        return approach, found

    def _route_to(self, i: int, approach: pathlib.Path, obst: Obstacles, sources: np.ndarray, costs: np.ndarray,
                  rng: np.random.Generator):
        pre = np.array(approach.start, dtype=np.float64)
        return route(sources, costs, pre, self.r[i], self.L[i], self.W[i], obst, self.opts, rng, self.lab(i))

    def dock_single(self, k: int) -> None:
        i = self.by_rank[k]
        who = self.lab(i)
        goal = self.goals[i]
        orbiting = [self.by_rank[j] for j in range(1, k)]
        docked = [self.by_rank[j] for j in range(k + 1, self.n + 1)]
        obst = self.obstacles(orbiting, docked)
        m = self.opts.departure_phases
        period = TWO_PI * self.r[i] / self.v[i]
        waits = np.arange(m) * period / m
        p0 = np.repeat(self.tl.poses[i][None, :], m, axis=0)
        sources = advance(p0, np.ones(m, bool), self.v[i], self.r[i], waits)
        approach, (s, path, waypoints) = self.dock_route(i, obst, sources, waits * self.v[i], self.rng)
        pre = np.array(approach.start, dtype=np.float64)
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
