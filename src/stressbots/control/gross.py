"""Gross motion sigma_1 of one robot: steering with a left bias, obstacle checks, roadmap detours.

The controller re-plans a robot's shortest path (:func:`stressbots.paths.shortest_path`) to a target
region every t_x from its measured pose. A path that would meet an orbit, the structure or the arena
edge is routed around them on the planner's roadmap: one route, followed waypoint by waypoint, so the
robot does not take a new random route every t_x. A turn into a long straight is cut short by a few
degrees (left bias): a one-way robot corrects to the right cheaply, to the left only by a full loop.

:class:`GrossMotion` is handed the closed loop (:class:`GrossLoop`: ``drive``, estimates, event log,
the routes' random stream) and drives through it; :func:`path_steps` and :func:`arrived` are pure. Its ways off
an obstacle and on (escapes from contacts, checked moves on, whether a robot is boxed in, how much of a clear
path is viable) are :class:`~stressbots.control.escapes.Escapes`, which it holds as ``escapes``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from enum import Enum
from typing import NamedTuple, Protocol

import numpy as np

from .. import paths as pathlib
from ..collision import arena_gap, bodies_hit_discs, penetration_depth
from ..kinematics import sample_arclengths
from ..robots import TWO_PI, angle_difference, turning_centres
from .escapes import Escapes
from .loopview import LoopView, Steps
from .prefixed import describe_prefix, first_clear, remaining_prefix
from .queries import shortest_into, trim_steps, waypoint_region
from .tuning import Tuning

__all__ = ["Detour", "GrossLoop", "GrossMotion", "SteerOutcome", "arrived", "circling_scale", "clear_prefix", "loop_deferred",
           "path_steps"]



_NOWHERE = np.array([np.inf, np.inf, 0.0])
"""A gross-motion target no sample is near: :meth:`GrossMotion.obstacles_hit` then keeps the docked bodies
``Tuning.gross_docked_clearance_um`` away everywhere."""


class GrossLoop(LoopView, Protocol):
    """What gross motion uses of the closed loop (:class:`~stressbots.control.loop.PlantLoop` and the controller)."""

    t: float
    replans: int
    routes_rng: np.random.Generator

    @property
    def rstar(self) -> np.ndarray: ...

    def tend_orbits(self, k: int) -> None: ...


class SteerOutcome(Enum):
    """How a gross motion (:meth:`GrossMotion.steer`) ended. Compare members with ``is``: every member is truthy."""

    ARRIVED = "arrived"
    """In the target region (or ``ready()`` became true): the next step works from here."""
    NO_WAY = "no way"
    """Short of the target without a stall: a committed route's waypoint out of reach, or the cycles ran out; the
    caller re-plans."""
    STUCK = "stuck"
    """Failure region H: the robot stalled (``Tuning.stall_count`` frames in a row and no escape), or it has no route
    and nothing clear to drive (:meth:`GrossMotion._blocked` gives up this target); the caller's recovery (backing off)
    takes over. A robot that arrives after a stall on an earlier waypoint of a roadmap route has arrived."""


def _ended(arrived: bool, stalled: bool) -> SteerOutcome:
    """The outcome of a gross motion that ended in its target region (``arrived``) or short of it, ``stalled``
    (failure region H) or not. Arriving counts first: the loop's former ``stuck`` flag kept a stall on an earlier
    waypoint of a route, and the robot that then arrived was backed off (docking) or reported stuck (holding)."""
    if arrived:
        return SteerOutcome.ARRIVED
    return SteerOutcome.STUCK if stalled else SteerOutcome.NO_WAY


class Detour(NamedTuple):
    """What gross motion around a blocked path (:meth:`GrossMotion._blocked`) did this t_x, and the state it leaves
    to the rest of the gross motion."""

    outcome: SteerOutcome | pathlib.Path | None
    """A :class:`SteerOutcome` ends the gross motion (ARRIVED: ``ready()`` became true on a roadmap route; STUCK:
    no route and nothing clear to drive); None: a route's waypoints were driven, re-plan; a path: drive it this
    t_x."""
    quiet: int
    """The t_x left before the roadmap is asked again."""
    escapes: int
    """The escapes left to this gross motion."""
    stalled: bool
    """Whether the robot is stalled (failure region H): the last waypoint steered stalled, or it gave up."""


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


def clear_prefix(path: pathlib.Path, hits: Callable[[np.ndarray], bool], step_um: float = 10.0) -> float:
    """How far (um) along ``path`` a robot drives before ``hits(samples)`` (poses (M, 3) -> bool: would
    they meet an obstacle?) first holds: the length of the longest clear beginning, at ``step_um``.

    A bisection over the path's samples (a longer beginning contains a shorter one, so clearness is
    monotone): O(log M) calls of ``hits``. The whole length when nothing is hit, 0 when the start is.
    """
    s = sample_arclengths(path.lengths, step_um)
    poses = path.pose_at(s)
    if not hits(poses):
        return float(path.length)
    lo, hi = 0, len(s)  # poses[:lo] are clear (lo = 0: nothing known), poses[:hi] are not
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if hits(poses[:mid]):
            hi = mid
        else:
            lo = mid
    return float(s[lo - 1]) if lo > 0 else 0.0


def _cut(segments, length_um: float) -> tuple[tuple[str, float], ...]:
    """The first ``length_um`` (um) of a path's ``segments``."""
    out, left = [], length_um
    for kind, ell in segments:
        if left <= 0.0:
            break
        out.append((kind, min(ell, left)))
        left -= ell
    return tuple(out)


def arrived(pose: np.ndarray, target: np.ndarray, tune: Tuning, scale: float = 1.0) -> bool:
    """Whether ``pose`` is inside ``target``'s region (the seed's regions instead of points): within
    ``tune.arrive_um`` (um) and ``tune.arrive_deg`` (deg), both times ``scale``."""
    return bool(np.hypot(*(pose[:2] - target[:2])) <= scale * tune.arrive_um
                and abs(angle_difference(pose[2], target[2])) <= math.radians(scale * tune.arrive_deg))


def circling_scale(elapsed_s: float, period_s: float, widen_per_loop: float) -> float:
    """How much wider a waypoint's arrival region is after ``elapsed_s`` of steering to it: ``widen_per_loop`` more per
    whole loop (period ``period_s``) spent without arriving.

    A waypoint that lies nearly on the robot's own turning circle is reached by one arc or missed by a few degrees,
    and a miss costs a whole loop that ends as close and as far (held-out 33:1 and tuning 90:0: three to four loops
    round one waypoint, 10-20 deg off each time). A waypoint only has to put the robot on its route's next leg.

    >>> circling_scale(10.0, 12.0, 1.0), circling_scale(13.0, 12.0, 1.0), circling_scale(30.0, 12.0, 1.0)
    (1.0, 2.0, 3.0)
    """
    return 1.0 + widen_per_loop * math.floor(max(elapsed_s, 0.0) / period_s) if period_s > 0 else 1.0


def loop_deferred(pose, path: pathlib.Path, r_um: float, defer_rad: float, min_straight_um: float) -> pathlib.Path | None:
    """Straight on instead of ``path``'s full loop when ``pose`` is less than ``defer_rad`` (rad) clockwise of the
    heading of a straight at least ``min_straight_um`` (um) long: that path from ``pose``, the straight run from where it
    is (as long as the one it missed), then the rest; None otherwise (turning radius ``r_um``).

    A one-way robot pointing a little clockwise of its straight needs a full loop, one a little anticlockwise a slight
    turn; at 2x the literature's noise the estimate is off by about 1 deg, and a robot on its straight looped whenever one
    frame put it past (held-out 41:0 at 2x: three loops round one roadmap waypoint, 60 s). Straight on, a robot truly past
    falls further behind the straight's heading and loops once the straight is shorter; one that was not is on its way.

    >>> import math
    >>> goal = pathlib.Path((0.0, 0.0, 0.0), 200.0, (("S", 1500.0), ("R", 200.0 * math.radians(40.0)))).end
    >>> past = pathlib.shortest_path((0.0, 0.0, math.radians(1.0)), goal, 200.0)  # 1 deg clockwise of its straight
    >>> [(k, round(ell)) for k, ell in past.segments]  # a full loop first
    [('R', 1253), ('S', 1503), ('R', 140)]
    >>> [(k, round(ell)) for k, ell in loop_deferred(past.start, past, 200.0, math.radians(2.0), 400.0).segments]
    [('S', 1500), ('R', 140)]
    >>> further = pathlib.shortest_path((0.0, 0.0, math.radians(3.0)), goal, 200.0)  # 3 deg past: the loop stands
    >>> loop_deferred(further.start, further, 200.0, math.radians(2.0), 400.0) is None
    True
    """
    segs = path.segments
    if defer_rad <= 0.0 or not (segs[0][0] == "R" and segs[0][1] >= r_um * (TWO_PI - defer_rad)):
        return None
    back = np.asarray(pose, dtype=np.float64) - np.array([0.0, 0.0, defer_rad])  # a straight within reach from here?
    alt = pathlib.shortest_path(back, path.end, r_um).segments
    if not (alt[0][0] == "R" and alt[0][1] <= r_um * defer_rad and len(alt) > 1 and alt[1][0] == "S"
            and alt[1][1] >= min_straight_um):
        return None
    return pathlib.Path(pose, r_um, (("S", alt[0][1] + alt[1][1]), *alt[2:]))


def search_key(i: int, target, docked_count: int, orbiting: Sequence[int]) -> tuple:
    """What a roadmap search's answer for robot ``i`` depends on, coarsely: the robot, its target (5 um, ~3 deg), the
    structure (``docked_count`` robots docked) and the robots orbiting: the key :class:`GrossMotion` counts failed
    searches under.

    >>> search_key(3, (1002.0, 498.0, 0.1), 2, [5, 1]) == search_key(3, (1001.0, 499.0, 0.11), 2, [1, 5])
    True
    """
    t = np.asarray(target, float)
    return (i, round(float(t[0]) / 5.0), round(float(t[1]) / 5.0), round(float(t[2]) * 20.0), int(docked_count),
            tuple(sorted(orbiting)))


def _roadmap_obstacles(loop: GrossLoop, i: int, orbiting, extra_discs, box_margin: float = 0.0):
    """The planner's obstacles for robot ``i``'s roadmap route (:meth:`GrossMotion.roadmap_route`), as measured: the
    orbits but its own and ``extra_discs`` (``(centre, radius)``), the docked bodies ``box_margin`` um wider all round,
    the arena edge."""
    from ..planning import Obstacles

    orbiting = [j for j in orbiting if j != i]
    centres = list(turning_centres(loop.est[orbiting], loop.r_hat[orbiting])) if orbiting else []
    radii = list(loop.rstar[orbiting]) if orbiting else []
    for c, rr in extra_discs:
        centres.append(c)
        radii.append(rr)
    docked = np.flatnonzero(loop.docked)
    return Obstacles(
        np.array(centres).reshape(-1, 2), np.array(radii, float), tuple("an orbit" for _ in radii),
        loop.est[docked], loop.L[docked] + 2.0 * box_margin, loop.W[docked] + 2.0 * box_margin,
        tuple("a docked robot" for _ in docked), loop.scn.arena_um,
    )


class GrossMotion:
    """Gross motion for a closed loop ``loop``: drives a robot to a target region around the obstacles.

    :meth:`steer` returns a :class:`SteerOutcome` (STUCK when the robot stalled: failure region H).
    """

    def __init__(self, loop: GrossLoop):
        self.loop = loop
        self.escapes = Escapes(self)  # ways off an obstacle and on, checked by obstacles_hit
        # failed roadmap searches per (robot, target, structure, orbits) (:func:`search_key`): each costs a full
        # roadmap build, and failing runs spent most of their wall time asking again and again
        self._failed: dict[tuple, int] = {}
        # per robot: (target, path) of the last prefixed detour (prefixed_detour): its rest is tried first next t_x
        self._prefixed: dict[int, tuple[np.ndarray, pathlib.Path]] = {}

    def obstacles_hit(self, samples: np.ndarray, i: int, orbiting: Sequence[int], *, extra_discs=(), clearance: float | None = None,
                      target=None, start=None) -> bool:
        """Whether robot ``i``'s body along ``samples`` hits an orbit, a docked body or the arena edge.

        With ``target`` (a gross-motion goal pose), docked bodies are kept ``Tuning.gross_docked_clearance_um``
        away except within one body length of the target: a robot that touches the structure on the way
        is turned flush against the wrong edge by docking compliance and cannot pivot off again. With ``start``
        (the pose the path leaves from) and ``Tuning.gross_start_relief``, also not within its first loop's reach
        (two turning radii and one body length) of the start: a robot that missed its approach line near the
        structure has only that loop back, which its line approach checked at ``Tuning.loop_back_clearance_um``.
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
                if start is not None and self.loop.tune.gross_start_relief:
                    reach = 2.0 * self.loop.r_hat[i] + self.loop.L[i]
                    far &= np.hypot(*(samples[:, :2] - np.asarray(start, float)[:2]).T) > reach
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

    def _searches_left(self, i: int, target, orbiting: Sequence[int]) -> int:
        """Roadmap searches robot ``i`` may still spend on ``target`` (``Tuning.route_searches_max`` failed ones in all)."""
        return self.loop.tune.route_searches_max - self._failed.get(search_key(i, target, int(self.loop.docked.sum()), orbiting), 0)

    def _blocked(self, i: int, target: np.ndarray, turn_k: int, straight_k: int, orbiting: Sequence[int], extra_discs, ready,
                 clearance, path, quiet: int, escapes: int, stalled: bool) -> Detour:
        """Gross motion around a blocked ``path``: a :class:`Detour` (``quiet``, ``escapes`` and ``stalled`` as the
        gross motion had them before, updated).

        Its ``outcome`` is ARRIVED (``ready()`` became true on a roadmap route), None (a route's waypoints were
        driven: re-plan), a path to drive this t_x, or STUCK: no route and nothing clear to drive (give up
        this target; failure region H) after an :meth:`~stressbots.control.escapes.Escapes.escape` was tried. With no
        route, only the clear beginning of ``path`` (:func:`clear_prefix`, at the full clearance, else at
        ``Tuning.escape_clearance_um``, else short of contact) is driven, never the blocked part: robots that drove on along blocked paths
        ran into the arena edge or the structure and were trapped there (a one-way robot against an
        obstacle can neither turn nor drive off it).
        """
        if self.loop.tune.prefixed_checks_max > 0:
            prefixed = self.prefixed_detour(i, target, path, orbiting, extra_discs, clearance)
            if prefixed is not None:
                return Detour(prefixed, quiet, escapes, stalled)
        if quiet <= 0 and self._searches_left(i, target, orbiting) > 0:
            c_eff = self.loop.opts.clearance_um if clearance is None else clearance
            # widest clearance first; the last, Tuning.escape_clearance_um, gets a robot in a tight spot (its loop
            # 12 um from the arena edge, say) out of it, where no route at the full clearance starts
            for c in (max(c_eff + 5.0, 20.0), self.loop.opts.clearance_um, self.loop.tune.escape_clearance_um):
                points, routed = self.roadmap_route(i, target, orbiting, extra_discs, c)
                if routed is None:
                    continue
                # commit to one roadmap route: steer through its waypoints (replanning every t_x between
                # them, at the clearance it was found at), instead of a new random route every t_x
                t_before = self.loop.t
                for w in points[:-1]:
                    stalled = self.steer(i, w, turn_k, straight_k, orbiting, extra_discs=extra_discs, max_cycles=60, ready=ready,
                                         via=False, clearance=min(c, c_eff),
                                         region=waypoint_region(w, self.loop.tune)) is SteerOutcome.STUCK
                    if ready is not None and ready():
                        return Detour(SteerOutcome.ARRIVED, quiet, escapes, stalled)
                return Detour(None if self.loop.t > t_before else routed, quiet, escapes, stalled)
            key = search_key(i, target, int(self.loop.docked.sum()), orbiting)
            self._failed[key] = self._failed.get(key, 0) + 1
            quiet = self.loop.tune.no_route_quiet_cycles
            self.loop.log("no-route", i, f"no way around the obstacles to its target; drives the clear part of its path, asks again "
                                         f"in {quiet} t_x")
        quiet -= 1
        ahead = 0.0
        # full clearance, else the escape one, else (a robot already that close) no contact
        for c, tgt in ((clearance, target), (self.loop.tune.escape_clearance_um, None), (0.0, None)):
            def hit(s: np.ndarray, c=c, tgt=tgt) -> bool:
                return self.obstacles_hit(s, i, orbiting, extra_discs=extra_discs, clearance=c, target=tgt, start=path.start)

            ahead = clear_prefix(path, hit, 10.0)
            if ahead >= self.loop.tune.min_clear_run_s * self.loop.v_hat[i]:
                break
        ahead = self.escapes.viable(i, path, ahead, orbiting, extra_discs)
        if ahead < self.loop.tune.min_clear_run_s * self.loop.v_hat[i]:
            if escapes > 0 and self.escapes.escape(i, turn_k, straight_k, orbiting, extra_discs):
                return Detour(None, quiet, escapes - 1, stalled)  # off the obstacle: re-plan from there
            self.loop.log("blocked", i, f"no route to its target and only {ahead:.0f} um of its path clear: gives up this target")
            # failure region H: the caller's recovery (backing off) takes over
            return Detour(SteerOutcome.STUCK, quiet, escapes, True)
        return Detour(pathlib.Path(path.start, path.radius, _cut(path.segments, ahead)), quiet, escapes, stalled)

    def prefixed_detour(self, i: int, target: np.ndarray, path: pathlib.Path, orbiting: Sequence[int], extra_discs,
                        clearance) -> pathlib.Path | None:
        """Robot ``i``'s :func:`~stressbots.control.prefixed.first_clear` prefixed path to ``target`` from its measured pose
        instead of the blocked shortest ``path`` (checked as that is: the docked bodies' clearance relaxed near
        ``target``), the rest of its last choice tried first; None when none is clear. A new choice is logged."""
        last = self._prefixed.get(i)
        rest = remaining_prefix(last[1], self.loop.est[i]) if last is not None and np.allclose(last[0], target) else None

        def hits(cand: pathlib.Path) -> bool:
            # only its arrival (the last body length) may come closer to the structure than the gross-motion clearance: a
            # longer way round passes near the target more than once, and robots stopped against the structure there
            s = sample_arclengths(cand.lengths, 10.0)
            samples = cand.pose_at(s)
            tail = s >= cand.length - float(self.loop.L[i])
            return (self.obstacles_hit(samples[~tail], i, orbiting, extra_discs=extra_discs, clearance=clearance, target=_NOWHERE,
                                       start=self.loop.est[i])
                    or self.obstacles_hit(samples[tail], i, orbiting, extra_discs=extra_discs, clearance=clearance, target=target))

        found = first_clear(self.loop.est[i], target, float(self.loop.r_hat[i]), hits, checks=self.loop.tune.prefixed_checks_max,
                            max_length_um=path.length + self.loop.tune.prefixed_extra_um, rest=rest)
        if found is None:
            self._prefixed.pop(i, None)
            return None
        cand, k = found
        self._prefixed[i] = (np.asarray(target, float).copy(), cand)
        if k > 0 or rest is None:  # a new choice (its continuation is not logged again)
            self.loop.log("detour", i, f"its shortest path is blocked: it takes a {cand.length:.0f} um path that first "
                                       f"{describe_prefix(cand)} (checked {k + 1})")
        return cand

    def steer(self, i: int, target: np.ndarray, turn_k: int, straight_k: int, orbiting: Sequence[int], *, extra_discs=(),
              max_cycles: int = 400, ready: Callable[[], bool] | None = None, via: bool = True,
              clearance: float | None = None, ready_if_blocked: Callable[[], tuple[str, str] | None] | None = None,
              waypoint: bool = False, region: np.ndarray | None = None) -> SteerOutcome:
        """Gross motion: drive robot ``i`` to ``target`` (or a goal of ``region``, :meth:`_into`) by replanning every t_x.

        ARRIVED when there. ``ready()`` True ends the gross motion early (the robot is already in the region from which the next step works:
        the seed's regions A_i instead of a point); so does arriving at a ``waypoint`` of a route (waiting for the final
        aim's ``ready`` alone, a robot circled a nominal waypoint for 57 s); so does ``ready_if_blocked()`` (``(event,
        reason)``, logged) when the path to ``target`` is blocked (a wider region the next step also works from, or a
        waypoint the caller can do without). A blocked path is routed around the obstacles (:meth:`_blocked`); NO_WAY
        when there is no way (the caller re-plans), STUCK when the robot stalled or has no route and nothing clear to
        drive (failure region H; see :class:`SteerOutcome`).

        Left bias: a turn that leads into a long straight is cut short by up to 3 deg (:meth:`_left_biased`), so the
        straight points a little left of where it must. Clockwise is the only correction a one-way robot makes cheaply:
        a turn overdone (speed or radius misidentified, drift) would cost a full loop at the next replan, a turn cut short
        costs a slight turn.
        """
        stalls = 0
        escapes = self.loop.tune.escapes_per_steer
        quiet = 0  # cycles left before the roadmap is asked again after it found no way around
        stalled = False  # failure region H (see SteerOutcome.STUCK)
        t0, leg_of_route = self.loop.t, not via or waypoint
        for _ in range(max_cycles):
            v = self.loop.v_hat[i]
            p = self.loop.est[i]
            # a route's waypoint (via False) ends on arrival too: waiting for ready() alone, robots circled it 60 t_x
            if (ready is not None and ready()) or ((ready is None or leg_of_route) and self._on_target(i, target, t0, leg_of_route)):
                return _ended(True, stalled)
            path = self._into(i, target, region)
            # a route's waypoint legs at the route's own clearance (the docked one blocked them: a new route every t_x)
            if (self.obstacles_hit(path.sample(10.0), i, orbiting, extra_discs=extra_discs, clearance=clearance,
                                   target=target if via else None, start=p)
                    or self.escapes.dead_end_ahead(i, path, target, orbiting, extra_discs)):
                if not via:
                    return _ended(False, stalled)  # a waypoint of a committed route is out of reach: the caller re-plans
                why = ready_if_blocked() if ready_if_blocked is not None else None
                if why is not None:
                    self.loop.log(why[0], i, why[1])
                    return _ended(True, stalled)
                outcome, quiet, escapes, stalled = self._blocked(i, target, turn_k, straight_k, orbiting, extra_discs, ready, clearance,
                                                                 path, quiet, escapes, stalled)
                if outcome is None:
                    continue
                if isinstance(outcome, SteerOutcome):
                    return outcome
                path = outcome
            whole, slow = self._drive_leg(i, path, v, turn_k, straight_k, orbiting, extra_discs, clearance, target)
            if slow:
                stalls += 1
                if stalls >= self.loop.tune.stall_count:
                    self.loop.log("stuck", i, "stopped during gross motion (failure region H)")
                    if not (escapes > 0 and self.escapes.escape(i, turn_k, straight_k, orbiting, extra_discs)):
                        return SteerOutcome.STUCK
                    stalls, escapes = 0, escapes - 1
            else:
                stalls = 0
            if whole:
                return _ended(True, stalled)
            self.loop.tend_orbits(turn_k)  # waiting orbits drift meanwhile: move one away before it is trapped
        return _ended(False, stalled)

    def _on_target(self, i: int, target: np.ndarray, t0: float, leg_of_route: bool) -> bool:
        """Whether robot ``i`` is in ``target``'s arrival region (:func:`arrived`), on a route's leg widened for every loop
        spent on it since ``t0`` (:func:`circling_scale`)."""
        lp = self.loop
        if not leg_of_route or lp.tune.circling_widen <= 0.0:
            return arrived(lp.est[i], target, lp.tune)
        period = TWO_PI * float(lp.r_hat[i]) / float(lp.v_hat[i])
        return arrived(lp.est[i], target, lp.tune, circling_scale(lp.t - t0, period, lp.tune.circling_widen))

    def _into(self, i: int, target: np.ndarray, region: np.ndarray | None) -> pathlib.Path:
        """Robot ``i``'s shortest path from its measured pose to ``target``, or to the goal of ``region`` that saves
        ``Tuning.region_min_saving_loops`` loops on it (:func:`~stressbots.control.queries.shortest_into`); straight on
        instead of a loop it is measured just past (:func:`loop_deferred`, ``Tuning.loop_defer_deg``)."""
        p, r, tune = self.loop.est[i], float(self.loop.r_hat[i]), self.loop.tune
        if region is not None and tune.region_targets:
            target = region[shortest_into(p, region, r, tune.region_min_saving_loops * 2.0 * math.pi * r)]
        path = pathlib.shortest_path(p, target, r)
        min_straight_um = tune.loop_defer_min_straight_tx * float(self.loop.v_hat[i]) * self.loop.tx
        return loop_deferred(p, path, r, math.radians(tune.loop_defer_deg), min_straight_um) or path

    def _drive_leg(self, i: int, path: pathlib.Path, v: float, turn_k: int, straight_k: int, orbiting, extra_discs, clearance,
                   target) -> tuple[bool, bool]:
        """Drive robot ``i`` one t_x along ``path`` at ``v`` (um/s; all of it when little more is left): ``(whole, slow)``,
        whether that was all of it, and whether it moved less than ``Tuning.stall_fraction`` of that (see :meth:`steer`)."""
        self.loop.replans += 1
        # the last leg runs whole: a one-way robot that stops short and overshoots needs a loop
        whole = path.length / v <= self.loop.tune.whole_leg_factor * self.loop.tx
        limit = None if whole else self.loop.tx
        steps = path_steps(path, v, turn_k, straight_k, limit)
        if not whole:
            steps = self._left_biased(i, path, steps, straight_k, orbiting, extra_discs, clearance, target)
        before = self.loop.est[i].copy()
        self.loop.drive(steps)
        return whole, float(np.hypot(*(self.loop.est[i, :2] - before[:2]))) < self.loop.tune.stall_fraction * v * sum(d for _, d in steps)

    def _left_biased(self, i: int, path, steps, straight_k: int, orbiting, extra_discs, clearance, target):
        """``steps`` with the turn into a long straight cut short by ``Tuning.left_bias_deg`` when that path is clear
        (see :meth:`steer`). The cut applies to every t_x of a turn longer than one t_x, not only its end: each such
        t_x turns a little less, so a long turn runs wide (a loop's circle drifted 58 um in 3 t_x on held-out 6:2).
        Cutting only the turn's end was measured in session 15 and lost as many trials as it won (tuning 1x 227/240
        against 229): the wide turn is a standing margin, and the next re-plan corrects it clockwise, cheaply. A turn
        within the bias is not driven at all (``Tuning.left_bias_hold``), and a bias whose straight would pass too near
        an obstacle is tried smaller before none (``Tuning.left_bias_shrink``)."""
        v, r = self.loop.v_hat[i], self.loop.r_hat[i]
        segs = path.segments
        if not (len(segs) > 1 and segs[0][0] == "R" and segs[1][0] == "S" and segs[1][1] > 0.5 * v * self.loop.tx):
            return steps
        full_cut_um = r * math.radians(self.loop.tune.left_bias_deg)
        # held: a turn within the bias is not driven (halving it every t_x converged on the straight's heading, and
        # one noisy frame past it cost a loop); else cut by the bias, at most half the turn (the whole bias, kept for
        # turns up to twice it, entered the approach funnels further left: more docks off the line at 2x)
        hold = self.loop.tune.left_bias_hold and segs[0][1] <= full_cut_um
        first = segs[0][1] if hold else min(full_cut_um, 0.5 * segs[0][1])
        # a cut whose straight passes too near an obstacle gives way to a smaller one (Tuning.left_bias_shrink)
        for cut_um in (first, 0.5 * first, 0.25 * first) if self.loop.tune.left_bias_shrink else (first,):
            if cut_um < segs[0][1] - 1e-9 and steps[0][1] <= cut_um / v:
                continue  # a part of the turn is cut only from a first step longer than the cut
            biased = pathlib.Path(self.loop.est[i], r, (("R", segs[0][1] - cut_um), ("S", segs[1][1] + cut_um)))
            if not self.obstacles_hit(biased.sample(10.0), i, orbiting, extra_discs=extra_discs, clearance=clearance, target=target):
                turn = [(steps[0][0], steps[0][1] - cut_um / v)] if steps[0][1] - cut_um / v > 1e-12 else []
                return trim_steps([*turn, (straight_k, cut_um / v), *steps[1:]], self.loop.tx)
        return steps

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
            obst = _roadmap_obstacles(self.loop, i, orbiting, extra_discs, margin)
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
