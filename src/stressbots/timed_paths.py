"""Paths of a prescribed duration for the planner's G_1: ``wait0 + k`` whole orbit periods of a partner.

While D_n drives between two runs of the G_1 piece scheme (or to its first run), D_{n-1} orbits, so
D_n's path must last exactly the time that brings D_{n-1} back where it stopped (or to its departure
phase): a direct path of that length (:func:`stressbots.paths.path_of_length`), else a route around the
obstacles stretched to it (in its tail or one leg), else a path that first orbits at the start.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from . import paths as pathlib
from .kinematics import advance
from .planner_state import PlannerState
from .robots import Pose
from .routing import NoRoute, path_hit, route


class TimedPaths(PlannerState):
    """Collision-free paths of a whole number of a partner's orbit periods (plus a wait)."""

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
                # D_n's timed legs are local manoeuvres: the smallest roadmap (opts.timed_roadmaps), or the
                # G_1 search gets slow: most routed legs that fail fail in every roadmap, and a G_1 search
                # tries other cuts and routes of D_{n-1} instead (gap-16: 98 failed legs of ~0.1 s each)
                light = replace(self.opts, roadmap_nodes=self.opts.roadmap_nodes[:self.opts.timed_roadmaps])
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
