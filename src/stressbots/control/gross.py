"""Gross motion sigma_1 of one robot: steering with a left bias, obstacle checks, roadmap detours.

The controller re-plans a robot's shortest path (:func:`stressbots.paths.shortest_path`) to a target
region every t_x from its measured pose. A path that would meet an orbit, the structure or the arena
edge is routed around them on the planner's roadmap: one route, followed waypoint by waypoint, so the
robot does not take a new random route every t_x. A turn into a long straight is cut short by a few
degrees (left bias): a one-way robot corrects to the right cheaply, to the left only by a full loop.

:class:`GrossMotion` is handed the closed loop (:class:`GrossLoop`: ``drive``, estimates, event log,
the routes' random stream) and drives through it; :func:`path_steps` and :func:`arrived` are pure.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Protocol

import numpy as np

from .. import paths as pathlib
from ..collision import arena_gap, bodies_hit_discs, penetration_depth
from ..robots import angle_difference, turning_centres
from .loopview import LoopView, Steps
from .queries import trim_steps
from .tuning import Tuning

__all__ = ["GrossLoop", "GrossMotion", "arrived", "path_steps"]



class GrossLoop(LoopView, Protocol):
    """What gross motion uses of the closed loop (:class:`~stressbots.control.loop.PlantLoop` and the controller)."""

    t: float
    replans: int
    routes_rng: np.random.Generator

    @property
    def rstar(self) -> np.ndarray: ...


def path_steps(path: pathlib.Path, v: float, turn_k: int, straight_k: int, limit_s: float | None = None) -> Steps:
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


def arrived(pose: np.ndarray, target: np.ndarray, tune: Tuning) -> bool:
    """Whether ``pose`` is inside ``target``'s region (the seed's regions instead of points): within
    ``tune.arrive_um`` (um) and ``tune.arrive_deg`` (deg)."""
    return bool(np.hypot(*(pose[:2] - target[:2])) <= tune.arrive_um
                and abs(angle_difference(pose[2], target[2])) <= math.radians(tune.arrive_deg))


class GrossMotion:
    """Gross motion for a closed loop ``loop``: drives a robot to a target region around the obstacles.

    Sets ``loop.stuck`` when the robot stalled (failure region H) during the last :meth:`steer`.
    """

    def __init__(self, loop: GrossLoop):
        self.loop = loop

    def obstacles_hit(self, samples: np.ndarray, i: int, orbiting: Sequence[int], *, extra_discs=(), clearance: float | None = None,
                      target=None) -> bool:
        """Whether robot ``i``'s body along ``samples`` hits an orbit, a docked body or the arena edge.

        With ``target`` (a gross-motion goal pose), docked bodies are kept ``Tuning.gross_docked_clearance_um``
        away except within one body length of the target: a robot that touches the structure on the way
        is turned flush against the wrong edge by docking compliance and cannot pivot off again.
        """
        c = self.loop.opts.clearance_um if clearance is None else clearance
        samples = np.asarray(samples, dtype=np.float64)
        orbiting = [j for j in orbiting if j != i]
        if orbiting or extra_discs:
            centres = [*turning_centres(self.loop.est[orbiting], self.loop.r_hat[orbiting])] if orbiting else []
            radii = list(self.loop.rstar[orbiting]) if orbiting else []
            for cc, rr in extra_discs:
                centres.append(cc)
                radii.append(rr)
            if bodies_hit_discs(samples, self.loop.L[i], self.loop.W[i], np.array(centres), np.array(radii) + c).any():
                return True
        docked = np.flatnonzero(self.loop.docked)
        if len(docked):
            need = np.full(len(samples), c)
            if target is not None:
                far = np.hypot(*(samples[:, :2] - np.asarray(target, float)[:2]).T) > self.loop.L[i]
                need[far] = max(c, self.loop.tune.gross_docked_clearance_um)
            hd = 0.5 * math.hypot(self.loop.L[i], self.loop.W[i])
            for j in docked:
                # only samples within reach of body j (bounding circles) need the exact rectangle test
                near = np.hypot(*(samples[:, :2] - self.loop.est[j, :2]).T) < hd + 0.5 * math.hypot(self.loop.L[j], self.loop.W[j]) + need
                if near.any() and (penetration_depth(samples[near], self.loop.L[i], self.loop.W[i], self.loop.est[j], self.loop.L[j],
                                                     self.loop.W[j]) > -need[near]).any():
                    return True
        if self.loop.scn.arena_um is not None and (arena_gap(samples, self.loop.L[i], self.loop.W[i], self.loop.scn.arena_um) < c).any():
            return True
        return False

    def _route_or_detour(self, i: int, target: np.ndarray, orbiting: Sequence[int], extra_discs, routed, path):
        """The roadmap route itself when there is one (it was checked at a wider clearance), else a detour at
        the controller's clearance, else ``path`` unchanged."""
        if routed is not None:
            return routed
        detour = self.roadmap_route(i, target, orbiting, extra_discs, self.loop.opts.clearance_um)[1]
        return path if detour is None else detour

    def steer(self, i: int, target: np.ndarray, turn_k: int, straight_k: int, orbiting: Sequence[int], *, extra_discs=(),
              max_cycles: int = 400, ready: Callable[[], bool] | None = None, via: bool = True, clearance: float | None = None) -> bool:
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
        self.loop.stuck = False
        for _ in range(max_cycles):
            v, r = self.loop.v_hat[i], self.loop.r_hat[i]
            p = self.loop.est[i]
            if (ready is None and arrived(p, target, self.loop.tune)) or (ready is not None and ready()):
                return True
            path = pathlib.shortest_path(p, target, r)
            if self.obstacles_hit(path.sample(10.0), i, orbiting, extra_discs=extra_discs, clearance=clearance, target=target):
                if via and quiet > 0:
                    quiet -= 1  # the roadmap found nothing a moment ago: asking every t_x only costs time
                elif via:
                    # commit to one roadmap route: steer through its waypoints (replanning every t_x
                    # between them), instead of a new random route every t_x
                    c_eff = self.loop.opts.clearance_um if clearance is None else clearance
                    points, routed = self.roadmap_route(i, target, orbiting, extra_discs, max(c_eff + 5.0, 20.0))
                    t_before = self.loop.t
                    if len(points) > 1:
                        for w in points[:-1]:
                            self.steer(i, w, turn_k, straight_k, orbiting, extra_discs=extra_discs, max_cycles=60, ready=ready, via=False,
                                       clearance=clearance)
                            if ready is not None and ready():
                                return True
                        if self.loop.t > t_before:
                            continue
                    found = self._route_or_detour(i, target, orbiting, extra_discs, routed, None)
                    if found is None:
                        quiet = self.loop.tune.no_route_quiet_cycles
                        self.loop.log("no-route", i, f"no way around the obstacles to its target; drives on, asks again in {quiet} t_x")
                    path = path if found is None else found
                else:
                    return False  # a waypoint of a committed route is out of reach: the caller re-plans
            self.loop.replans += 1
            # the last leg runs whole: a one-way robot that stops short and overshoots needs a loop
            whole = path.length / v <= self.loop.tune.whole_leg_factor * self.loop.tx
            limit = None if whole else self.loop.tx
            steps = path_steps(path, v, turn_k, straight_k, limit)
            if not whole:
                steps = self._left_biased(i, path, steps, straight_k, orbiting, extra_discs, clearance, target)
            before = self.loop.est[i].copy()
            self.loop.drive(steps)
            if float(np.hypot(*(self.loop.est[i, :2] - before[:2]))) < self.loop.tune.stall_fraction * v * sum(d for _, d in steps):
                stalls += 1
                if stalls >= self.loop.tune.stall_count:
                    self.loop.log("stuck", i, "stopped during gross motion (failure region H)")
                    self.loop.stuck = True
                    return False
            else:
                stalls = 0
            if whole:
                return True
        return False

    def _left_biased(self, i: int, path, steps, straight_k: int, orbiting, extra_discs, clearance, target):
        """``steps`` with the turn into a long straight cut short by ``Tuning.left_bias_deg`` when that path is clear
        (see :meth:`steer`)."""
        v, r = self.loop.v_hat[i], self.loop.r_hat[i]
        segs = path.segments
        if not (len(segs) > 1 and segs[0][0] == "R" and segs[1][0] == "S" and segs[1][1] > 0.5 * v * self.loop.tx):
            return steps
        cut_um = min(r * math.radians(self.loop.tune.left_bias_deg), 0.5 * segs[0][1])
        biased = pathlib.Path(self.loop.est[i], r, (("R", segs[0][1] - cut_um), ("S", segs[1][1] + cut_um)))
        if steps[0][1] > cut_um / v and not self.obstacles_hit(biased.sample(10.0), i, orbiting, extra_discs=extra_discs,
                                                               clearance=clearance, target=target):
            steps = [(steps[0][0], steps[0][1] - cut_um / v), (straight_k, cut_um / v), *steps[1:]]
            steps = trim_steps(steps, self.loop.tx)
        return steps

    def _obstacles(self, i: int, orbiting, extra_discs, box_margin: float = 0.0):
        from ..planning import Obstacles

        orbiting = [j for j in orbiting if j != i]
        centres = list(turning_centres(self.loop.est[orbiting], self.loop.r_hat[orbiting])) if orbiting else []
        radii = list(self.loop.rstar[orbiting]) if orbiting else []
        for c, rr in extra_discs:
            centres.append(c)
            radii.append(rr)
        docked = np.flatnonzero(self.loop.docked)
        return Obstacles(
            np.array(centres).reshape(-1, 2), np.array(radii, float), tuple("an orbit" for _ in radii),
            self.loop.est[docked], self.loop.L[docked] + 2.0 * box_margin, self.loop.W[docked] + 2.0 * box_margin,
            tuple("a docked robot" for _ in docked), self.loop.scn.arena_um,
        )

    def roadmap_route(self, i: int, target, orbiting, extra_discs, clearance: float):
        """``(waypoints, path)``: the planner's roadmap route from the measured pose around the orbits, the
        structure and the arena edge to ``target`` (waypoints end with it), at ``clearance``; ``([], None)``
        when there is none. Logged as a detour."""
        from ..planning import NoRoute, PlannerOptions, route

        rng = self.loop.routes_rng
        opts = PlannerOptions(clearance_um=clearance, roadmap_nodes=(60, 200))
        # around the structure with the gross-motion clearance first (see obstacles_hit), else the plain one
        margins = (max(self.loop.tune.gross_docked_clearance_um - clearance, 0.0), 0.0) if self.loop.docked.any() else (0.0,)
        for margin in margins:
            obst = self._obstacles(i, orbiting, extra_discs, margin)
            try:
                _, routed, points = route(self.loop.est[i][None, :], np.zeros(1), np.asarray(target, float), self.loop.r_hat[i],
                                          self.loop.L[i], self.loop.W[i], obst, opts, rng, "")
                break
            except NoRoute:
                continue
        else:
            return [], None
        self.loop.log("detour", i, f"route around obstacles ({routed.length:.0f} um, {len(points)} waypoints)")
        return [np.asarray(w, float) for w in points], routed
