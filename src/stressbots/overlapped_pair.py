"""The planner's overlapped G_1: finding and applying schedules of :mod:`stressbots.overlap` for one variant.

D_n turns toward its slot while D_{n-1} turns (on its orbit and its route's arcs) and runs straight only
while D_{n-1} does. This module binds that search to the planner's obstacles, timed paths and timeline.
"""

from __future__ import annotations

import math

import numpy as np

from . import paths as pathlib
from .collision import penetration_depth
from .dock_planning import DockPlanning
from .overlap import PairSchedule, joint_primitives, overlap_schedule, with_orbits
from .prepositioning import splice_straight
from .robots import TWO_PI, turning_centres
from .routing import Obstacles, path_hit
from .timed_paths import TimedPaths


class OverlappedPair(DockPlanning, TimedPaths):
    """Overlapped G_1 schedules around D_{n-1}'s direct and roadmap routes, and their application."""

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
