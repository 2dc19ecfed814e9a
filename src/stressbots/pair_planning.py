"""Step 1 of the planner: D_n and D_{n-1} form G_1 (seed App. 2.1, generalised).

The G_1 search: overlapped schedules first (:mod:`stressbots.overlapped_pair`), then the piece scheme
(:mod:`stressbots.pair_schedules`) around D_{n-1}'s direct routes and the routes its roadmap search
finds, a second pass letting D_n orbit first in the extended search, and the failures shared by
variants with the same G_1 (:class:`~stressbots.planner_state.SharedSearch`).
"""

from __future__ import annotations

import math
from dataclasses import replace
from functools import partial

import numpy as np

from . import paths as pathlib
from .kinematics import advance
from .overlapped_pair import OverlappedPair
from .pair_schedules import PieceSchedules
from .planner_state import approach_length
from .robots import TWO_PI, turning_centres
from .routing import NoRoute, Obstacles, SearchSpent, path_hit, route


class PairPlanning(PieceSchedules, OverlappedPair):
    """The G_1 search of the planner (:meth:`form_pair`) and the application of the schedule it finds."""

    def _free_run(self, pose: np.ndarray, i: int, obst: Obstacles, limit_um: float, *, backwards: bool) -> float:
        """Longest straight run (um) of robot ``i`` from ``pose`` (ahead, or behind it) clear of ``obst``."""
        h = np.array([math.sin(pose[2]), math.cos(pose[2])]) * (-1.0 if backwards else 1.0)
        probe = np.arange(0.0, limit_um, self.opts.sample_um)
        line = np.column_stack([pose[0] + probe * h[0], pose[1] + probe * h[1], np.full(probe.size, pose[2])])
        blocked = obst.hits(line, self.L[i], self.W[i], self.opts.clearance_um)
        return float(probe[np.argmax(blocked)] - self.opts.sample_um) if blocked.any() else float(probe[-1])

    def form_pair(self, stage: str = "all") -> None:
        """Step 1: D_n and D_{n-1} form G_1 (see :mod:`stressbots.planning` for the scheme).

        In the extended search D_n may orbit before its whole-period paths
        (:meth:`~stressbots.timed_paths.TimedPaths._orbit_first`): more layouts are plannable.
        ``stage`` selects part of the search: ``"overlap"`` the overlapped schedules alone (around the
        direct routes of D_{n-1}, then around the first ``overlap.roadmap_routes`` routes its roadmap
        search finds: the cheap part, which mostly succeeds), ``"pieces"`` the piece scheme alone
        (:meth:`form_pair_staged` runs them in turn).
        """
        # Everything the G_1 search depends on besides the scenario, which all variants share: the
        # pair's slots and approach lengths, the options and the pass (each planner starts from the
        # same start poses and the same random stream), so an equal key fails the same way.
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        key = (tuple(np.round(self.goals[[N, M]], 9).ravel()), approach_length(self.struct, self.scn.names[N], self.opts),
               approach_length(self.struct, self.scn.names[M], self.opts), self.extended, self.opts, stage)
        if key in self.search.pair_failures:
            raise NoRoute(self.search.pair_failures[key])
        self._pair_stage = stage
        try:
            self._form_pair_search()
        except NoRoute as exc:
            self.search.pair_failures[key] = exc.reason
            raise
        finally:
            self._pair_stage = "all"

    def form_pair_staged(self) -> None:
        """Step 1 with the clearance fallback (:meth:`~stressbots.planner_state.PlannerState.step_with_fallback`),
        cheapest search first: the overlapped G_1 at the planner's clearance, then at the fallback
        clearance, and only then the piece scheme at the planner's clearance, then at the fallback one.

        The piece scheme is the expensive part (``pair_schedules`` G_1 schedules, ~0.1 s each, before it
        gives up) and its G_1 is 2-5x longer, so an overlapped G_1 at the narrower clearance is preferred
        to the piece scheme at the wider one (bench_planner: where the overlapped G_1 needs the narrower
        clearance, the piece scheme at the wider one failed anyway, after ~1-3 s). Without a fallback
        clearance, or without overlapped schedules, this is :meth:`form_pair` with the fallback.
        """
        fallback = self.opts.fallback_clearance_um
        if not self.opts.overlap_pair or fallback is None or fallback >= self.opts.clearance_um:
            self.step_with_fallback(self.form_pair, "G_1")
            return
        try:
            self.step_with_fallback(partial(self.form_pair, "overlap"), "G_1 (overlapped)")
            return
        except NoRoute:
            pass
        self.step_with_fallback(partial(self.form_pair, "pieces"), "G_1")

    def _form_pair_search(self) -> None:
        """One G_1 search; in the extended search D_n's whole-period paths may first orbit at their start
        (:meth:`~stressbots.timed_paths.TimedPaths._orbit_first`) from the outset. The orbit is a timed
        path's last resort, so each schedule a search without it finds, this search finds too: a first
        pass without it (as before) repeated its failures in full before the pass with it (gap-16: 64
        failed schedules, 7 s, before the 18 of the pass that planned it)."""
        self._orbit_first_on = self.extended and self.opts.orbit_phases > 0
        self._form_pair_once()

    def _form_pair_once(self) -> None:
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        gN, gM = self.goals[N], self.goals[M]
        vM, rM = self.v[M], self.r[M]
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
        parks = self._parking_tracks(N, M, obst_low, span)
        self._overlap_sched = None
        self._overlap_routes_tried = 0
        if opts.overlap_pair and self._pair_stage != "pieces" and self._overlap_first(N, M, sourcesM, waits, preM, approachM, obst_low):
            return
        self._piece_search(N, M, sourcesM, waits, preM, approachM, obst_low, lower, parks, d_free, aM)

    def _parking_tracks(self, N: int, M: int, obst_low: Obstacles, span: float) -> list:
        """Parking tracks ``(pose, free length)`` for D_n's runs during the earlier pieces: None (the final
        corridor itself; its runs stop short of the slot), then up to two free lines ahead of D_n, longest first.

        Candidate tracks start on D_n's start orbit (at quarter turns), so reaching them is cheap.
        """
        vN, rN, rM = self.v[N], self.r[N], self.r[M]
        parks: list = [None]
        obst_park = obst_low.with_disc(turning_centres(self.tl.poses[M], rM)[0], self.rstar[M], "M")
        quarter = np.arange(4) * 0.5 * math.pi * rN / vN
        on_orbit = advance(np.repeat(self.tl.poses[N][None, :], 4, axis=0), np.ones(4, bool), vN, rN, quarter)
        tracks = [(p, self._free_run(p, N, obst_park, span, backwards=False)) for p in on_orbit]
        tracks = sorted((t for t in tracks if t[1] > 2.0 * rN), key=lambda t: -t[1])
        parks.extend(tracks[:2] if self.opts.max_pieces > 1 else [])
        return parks

    def _piece_search(self, N: int, M: int, sourcesM: np.ndarray, waits: np.ndarray, preM: np.ndarray, approachM: pathlib.Path,
                      obst_low: Obstacles, lower: list[int], parks: list, d_free: float, aM: float) -> None:
        """Form G_1 with the piece scheme around D_{n-1}'s routes: the best direct ones first (with
        ``pair_candidates`` > 1, and one-piece schedules around roadmap routes), then the routes its roadmap
        search finds, overlapped first when ``overlap_pair``; raise :class:`NoRoute` when none fits.
        """
        opts = self.opts
        vM, rM = self.v[M], self.r[M]
        whoN, whoM = self.lab(N), self.lab(M)
        attempts: list[str] = []
        budget = [opts.pair_schedules]  # schedule attempts per G_1: bounds the planner's time on hopeless layouts
        one_piece = [False]  # schedule only the seed's one-piece scheme
        overlap_routes = [False]  # try overlapped schedules around the routes the roadmap finds

        def try_route(sidx: int, routeM: pathlib.Path) -> str | None:
            """Can D_n be scheduled around this route of D_{n-1}? Records the schedule when it can."""
            if overlap_routes[0] and self._overlap_route(N, M, routeM, approachM, float(waits[sidx]), obst_low):
                return None
            if self._pair_stage == "overlap":  # overlapped schedules only: end once their routes are spent
                if self._overlap_routes_tried >= opts.overlap.roadmap_routes:
                    raise SearchSpent("no overlapped schedule")
                return "no overlapped schedule"
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
        pieces_first = opts.pair_candidates > 1 and self._pair_stage != "overlap"
        best = self._best_direct_pair(sourcesM, preM, rM, M, obst_low, try_route) if pieces_first else None
        if pieces_first and (best is None or len(best[4]) > 1):
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
        overlap_routes[0] = opts.overlap_pair and self._pair_stage != "pieces"  # "pieces": the overlap stage tried them
        try:
            route(sourcesM, waits * vM, preM, rM, self.L[M], self.W[M], obst_low, opts, self.rng, whoM, extra_check=try_route)
        except NoRoute as exc:
            reason = max(dict.fromkeys(attempts), key=attempts.count) if attempts else exc.reason
            raise NoRoute(f"cannot form G_1 with {whoN} and {whoM}: {reason}") from None
        self._run_pair_schedule()

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

    def _run_pair_schedule(self) -> None:
        """Apply the schedule the G_1 search accepted: an overlapped one, else the piece scheme's."""
        if self._overlap_sched is not None:  # the search accepted an overlapped schedule around a roadmap route
            self._run_overlap(self._overlap_sched)
            return
        assert self._pair_schedule is not None  # set by form_pair's successful search
        self._run_pieces(self._pair_schedule)
