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
from collections.abc import Callable, Iterator, Sequence
from enum import Enum
from typing import NamedTuple, Protocol

import numpy as np

from .. import kinematics
from .. import paths as pathlib
from ..collision import arena_gap, bodies_hit_discs, penetration_depth
from ..kinematics import sample_arclengths
from ..robots import angle_difference, turning_centres
from .loopview import LoopView, Steps
from .prefixed import describe_prefix, first_clear, remaining_prefix
from .queries import trim_steps
from .tuning import Tuning

__all__ = ["Detour", "GrossLoop", "GrossMotion", "SteerOutcome", "arrived", "clear_prefix", "contact_clearance", "escape_moves",
           "escape_sweep", "move_stops", "path_steps", "viable_prefix"]



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


def viable_prefix(path: pathlib.Path, clear_um: float, boxed_in: Callable[[np.ndarray], bool], step_um: float = 25.0,
                  checks: int = 40) -> float:
    """The longest beginning of ``path``, at most ``clear_um`` (um) long, whose end pose is not ``boxed_in`` (pose
    (3,) -> bool: can the robot not move on from there?).

    A one-way robot can neither reverse nor turn left: one that stops short of an obstacle while heading into
    it (the clear part of a blocked path usually ends so) is trapped for good once anything nudges it. Ends
    are tried back from ``clear_um`` every ``step_um``, at most ``checks`` of them; 0 when none will do (the
    robot stays where it is).
    """
    for s in np.arange(clear_um, 0.0, -step_um)[:checks]:
        if not boxed_in(np.asarray(path.pose_at(float(s)), float)):
            return float(s)
    return 0.0


def escape_moves(v: float, r: float, length: float, turn_fractions: Sequence[float],
                 straight_lengths: Sequence[float]) -> list[tuple[float, float]]:
    """Candidate escapes of a one-way robot from a contact, cheapest first: ``(turn_s, straight_s)``, turn
    clockwise for a fraction of a loop (radius ``r`` um at ``v`` um/s), then drive straight so many body
    lengths (``length`` um). A robot cannot reverse, so every way off an obstacle is one of these."""
    moves = {(2.0 * math.pi * r * f / v, length * b / v) for f in turn_fractions for b in straight_lengths}
    return sorted(moves, key=lambda m: (m[0] + m[1], m[0]))


def escape_sweep(pose: np.ndarray, move_: tuple[float, float], v: float, r: float, step_um: float = 10.0) -> np.ndarray:
    """The poses (M, 3) a robot at ``pose`` passes on the escape ``move_`` (:func:`escape_moves`), ``step_um`` apart."""
    turn = v * move_[0]
    a = kinematics.move(pose, np.linspace(0.0, turn, max(2, int(turn / step_um) + 1)), 1.0 / r)
    b = kinematics.move(a[-1], np.linspace(0.0, v * move_[1], max(2, int(v * move_[1] / step_um) + 1)), 0.0)
    return np.vstack([a, b[1:]])


def move_stops(move_: tuple[float, float], tx: float) -> list[tuple[float, float]]:
    """The parts ``(turn_s, straight_s)`` of the turn-then-straight ``move_`` driven at each of its t_x stops
    (``tx`` s apart; the whole move last): where :meth:`GrossMotion.drive_move` looks again.

    >>> move_stops((0.5, 2.0), 1.0)
    [(0.5, 0.5), (0.5, 1.5), (0.5, 2.0)]
    """
    total = move_[0] + move_[1]
    out = []
    for j in range(1, max(1, math.ceil(total / tx - 1e-9)) + 1):
        t = min(j * tx, total)
        out.append((min(move_[0], t), max(0.0, t - move_[0])))
    return out


def contact_clearance(hits: Callable[[float], bool], low: float = -80.0, high: float = 0.0, tol: float = 0.5) -> float:
    """The largest clearance ``c`` (um, in ``[low, high]``) at which ``hits(c)`` is still False: how far a body
    is from its nearest obstacle (negative: overlapping, as measured). ``hits`` must be monotone in ``c``."""
    if not hits(low):
        lo, hi = low, high
        if not hits(hi):
            return high
        while hi - lo > tol:
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if not hits(mid) else (lo, mid)
        return lo
    return low


def _cut(segments, length_um: float) -> tuple[tuple[str, float], ...]:
    """The first ``length_um`` (um) of a path's ``segments``."""
    out, left = [], length_um
    for kind, ell in segments:
        if left <= 0.0:
            break
        out.append((kind, min(ell, left)))
        left -= ell
    return tuple(out)


def arrived(pose: np.ndarray, target: np.ndarray, tune: Tuning) -> bool:
    """Whether ``pose`` is inside ``target``'s region (the seed's regions instead of points): within
    ``tune.arrive_um`` (um) and ``tune.arrive_deg`` (deg)."""
    return bool(np.hypot(*(pose[:2] - target[:2])) <= tune.arrive_um
                and abs(angle_difference(pose[2], target[2])) <= math.radians(tune.arrive_deg))


class GrossMotion:
    """Gross motion for a closed loop ``loop``: drives a robot to a target region around the obstacles.

    :meth:`steer` returns a :class:`SteerOutcome` (STUCK when the robot stalled: failure region H).
    """

    def __init__(self, loop: GrossLoop):
        self.loop = loop
        # failed roadmap searches per (robot, target, structure, orbits) (:meth:`_search_key`): each costs a full
        # roadmap build, and failing runs spent most of their wall time asking again and again
        self._failed: dict[tuple, int] = {}
        # per robot: (target, path) of the last prefixed detour (prefixed_detour): its rest is tried first next t_x
        self._prefixed: dict[int, tuple[np.ndarray, pathlib.Path]] = {}

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

    def _search_key(self, i: int, target, orbiting: Sequence[int]) -> tuple:
        """What a roadmap search's answer depends on, coarsely: robot, target (5 um, ~3 deg), structure, orbits."""
        t = np.asarray(target, float)
        return (i, round(float(t[0]) / 5.0), round(float(t[1]) / 5.0), round(float(t[2]) * 20.0), int(self.loop.docked.sum()),
                tuple(sorted(orbiting)))

    def _searches_left(self, i: int, target, orbiting: Sequence[int]) -> int:
        """Roadmap searches robot ``i`` may still spend on ``target`` (``Tuning.route_searches_max`` failed ones in all)."""
        return self.loop.tune.route_searches_max - self._failed.get(self._search_key(i, target, orbiting), 0)

    def _blocked(self, i: int, target: np.ndarray, turn_k: int, straight_k: int, orbiting: Sequence[int], extra_discs, ready,
                 clearance, path, quiet: int, escapes: int, stalled: bool) -> Detour:
        """Gross motion around a blocked ``path``: a :class:`Detour` (``quiet``, ``escapes`` and ``stalled`` as the
        gross motion had them before, updated).

        Its ``outcome`` is ARRIVED (``ready()`` became true on a roadmap route), None (a route's waypoints were
        driven: re-plan), a path to drive this t_x, or STUCK: no route and nothing clear to drive (give up
        this target; failure region H) after an :meth:`escape` was tried. With no route, only the clear beginning of ``path``
        (:func:`clear_prefix`, at the full clearance, else at ``Tuning.escape_clearance_um``, else short of contact) is driven,
        never the blocked part: robots that drove on along blocked paths
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
                                         via=False, clearance=min(c, c_eff)) is SteerOutcome.STUCK
                    if ready is not None and ready():
                        return Detour(SteerOutcome.ARRIVED, quiet, escapes, stalled)
                return Detour(None if self.loop.t > t_before else routed, quiet, escapes, stalled)
            key = self._search_key(i, target, orbiting)
            self._failed[key] = self._failed.get(key, 0) + 1
            quiet = self.loop.tune.no_route_quiet_cycles
            self.loop.log("no-route", i, f"no way around the obstacles to its target; drives the clear part of its path, asks again "
                                         f"in {quiet} t_x")
        quiet -= 1
        ahead = 0.0
        # full clearance, else the escape one, else (a robot already that close) no contact
        for c, tgt in ((clearance, target), (self.loop.tune.escape_clearance_um, None), (0.0, None)):
            def hit(s: np.ndarray, c=c, tgt=tgt) -> bool:
                return self.obstacles_hit(s, i, orbiting, extra_discs=extra_discs, clearance=c, target=tgt)

            ahead = clear_prefix(path, hit, 10.0)
            if ahead >= self.loop.tune.min_clear_run_s * self.loop.v_hat[i]:
                break
        ahead = self._viable(i, path, ahead, orbiting, extra_discs)
        if ahead < self.loop.tune.min_clear_run_s * self.loop.v_hat[i]:
            if escapes > 0 and self.escape(i, turn_k, straight_k, orbiting, extra_discs):
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
            return (self.obstacles_hit(samples[~tail], i, orbiting, extra_discs=extra_discs, clearance=clearance, target=_NOWHERE)
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

    def free_moves(self, i: int, pose: np.ndarray, orbiting: Sequence[int], extra_discs=()) -> Iterator[tuple[float, float]]:
        """The escapes of the kind :meth:`escape` drives (turn clockwise ``Tuning.escape_turns`` of a loop, none
        included, then one body length straight; ``(turn_s, straight_s)``, in that order) that keep
        ``Tuning.viable_clearance_um`` from every orbit, docked body and the arena edge from ``pose``; lazily."""
        v, r, length = float(self.loop.v_hat[i]), float(self.loop.r_hat[i]), float(self.loop.L[i])
        for f in self.loop.tune.escape_turns:
            m = (2.0 * math.pi * r * f / v, length / v)
            sweep = escape_sweep(np.asarray(pose, float), m, v, r, step_um=15.0)
            if not self.obstacles_hit(sweep[1:], i, orbiting, extra_discs=extra_discs, clearance=self.loop.tune.viable_clearance_um):
                yield m

    def free_move(self, i: int, orbiting: Sequence[int]) -> tuple[float, float] | None:
        """A checked move on for robot ``i`` from where it is, ``(turn_s, straight_s)``: of its :meth:`free_moves`, the
        cheapest that boxes it in at none of the t_x stops :meth:`drive_move` makes (its end included), else the cheapest
        that does not at its end, else the cheapest; None when it is boxed in. Checked at the end only, a robot beside
        the structure took a body-length straight whose first t_x already left it no way on."""
        lp = self.loop
        p = lp.est[i]
        moves = list(self.free_moves(i, p, orbiting))
        v, r = float(lp.v_hat[i]), float(lp.r_hat[i])

        def boxed_at(m: tuple[float, float]) -> bool:
            return self.boxed_in(i, escape_sweep(p, m, v, r)[-1], orbiting)

        free_ends = [m for m in moves if not boxed_at(m)]
        for m in free_ends:
            if not any(boxed_at(s) for s in move_stops(m, lp.tx)[:-1]):
                return m
        return free_ends[0] if free_ends else (moves[0] if moves else None)

    def boxed_in(self, i: int, pose: np.ndarray, orbiting: Sequence[int], extra_discs=()) -> bool:
        """Whether robot ``i`` at ``pose`` cannot move on: it has no :meth:`free_moves`. A robot heading into an
        obstacle a few tens of um ahead is boxed in (it can neither turn nor drive off); one driving along the
        structure is not."""
        return next(self.free_moves(i, pose, orbiting, extra_discs), None) is None

    def _viable(self, i: int, path, ahead: float, orbiting: Sequence[int], extra_discs) -> float:
        """How much of the ``ahead`` um clear beginning of ``path`` robot ``i`` may drive: all of it when it is
        :meth:`boxed_in` where it is now (it needs the way out), else the longest beginning whose end does not box
        it in (:func:`viable_prefix`): the clear part of a blocked path drove robots to a stop 10-50 um short of
        the structure, the arena edge or a waiting robot, heading into it, and the next nudge pinned them for good."""
        if ahead <= 0.0 or self.boxed_in(i, self.loop.est[i], orbiting, extra_discs):
            return ahead
        return viable_prefix(path, ahead, lambda pose: self.boxed_in(i, pose, orbiting, extra_discs), self.loop.tune.viable_step_um,
                             self.loop.tune.viable_checks_max)

    def steer(self, i: int, target: np.ndarray, turn_k: int, straight_k: int, orbiting: Sequence[int], *, extra_discs=(),
              max_cycles: int = 400, ready: Callable[[], bool] | None = None, via: bool = True,
              clearance: float | None = None, ready_if_blocked: Callable[[], tuple[str, str] | None] | None = None) -> SteerOutcome:
        """Gross motion: drive robot ``i`` to ``target`` by replanning every t_x; ARRIVED when there.

        ``ready()`` True ends the gross motion early (the robot is already in the region from which the
        next step works: the seed's regions A_i instead of a point); so does ``ready_if_blocked()`` (``(event, reason)``,
        logged) when the path to ``target`` is blocked (a wider region the next step also works from, or a waypoint
        the caller can do without). A blocked path is routed around the
        obstacles (:meth:`_blocked`); NO_WAY when there is no way (the caller re-plans), STUCK when the robot
        stalled or has no route and nothing clear to drive (failure region H; see :class:`SteerOutcome`).

        Left bias: a turn that leads into a long straight is cut short by up to 3 deg, so the straight
        points a little left of where it must. Clockwise is the only correction a one-way robot makes
        cheaply: a turn overdone (speed or radius misidentified, drift) would cost a full loop at the
        next replan, a turn cut short costs a slight turn.
        """
        stalls = 0
        escapes = self.loop.tune.escapes_per_steer
        quiet = 0  # cycles left before the roadmap is asked again after it found no way around
        stalled = False  # failure region H (see SteerOutcome.STUCK)
        for _ in range(max_cycles):
            v = self.loop.v_hat[i]
            p = self.loop.est[i]
            # a route's waypoint (via False) ends on arrival too: waiting for ready() alone, robots circled it 60 t_x
            if (ready is not None and ready()) or ((ready is None or not via) and arrived(p, target, self.loop.tune)):
                return _ended(True, stalled)
            path = pathlib.shortest_path(p, target, self.loop.r_hat[i])
            # a route's waypoint legs at the route's own clearance (the docked one blocked them: a new route every t_x)
            if self.obstacles_hit(path.sample(10.0), i, orbiting, extra_discs=extra_discs, clearance=clearance,
                                  target=target if via else None):
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
                    if not (escapes > 0 and self.escape(i, turn_k, straight_k, orbiting, extra_discs)):
                        return SteerOutcome.STUCK
                    stalls, escapes = 0, escapes - 1
            else:
                stalls = 0
            if whole:
                return _ended(True, stalled)
            self.loop.tend_orbits(turn_k)  # waiting orbits drift meanwhile: move one away before it is trapped
        return _ended(False, stalled)

    def escape(self, i: int, turn_k: int, straight_k: int, orbiting: Sequence[int], extra_discs=()) -> bool:
        """Recovery from a contact (or a pose that close): drive robot ``i`` off what blocks it; True if it moved.

        How close it is to its nearest obstacle is measured (:func:`contact_clearance`, the orbits, the
        structure and the arena edge as obstacles); the cheapest escape (:func:`escape_moves`) that never
        goes deeper than that and ends ``Tuning.escape_clearance_um`` clear is driven. Backing off blindly
        (a quarter turn, then straight) turned into the obstacle as often as away from it.
        """
        lp = self.loop
        v, r = float(lp.v_hat[i]), float(lp.r_hat[i])
        p = lp.est[i].copy()

        def hit(samples: np.ndarray, c: float) -> bool:
            return self.obstacles_hit(samples, i, orbiting, extra_discs=extra_discs, clearance=c)

        now = contact_clearance(lambda c: hit(p[None, :], c), high=lp.tune.escape_clearance_um)
        free = not self.boxed_in(i, p, orbiting, extra_discs)  # a robot that can move on escapes only to where it still can
        for m in escape_moves(v, r, float(lp.L[i]), lp.tune.escape_turns, lp.tune.escape_straights):
            sweep = escape_sweep(p, m, v, r)
            if not hit(sweep[1:], now - 0.5) and not hit(sweep[-1:], lp.tune.escape_clearance_um) and \
                    not (free and self.boxed_in(i, sweep[-1], orbiting, extra_discs)):
                lp.log("escape", i, f"{now:.0f} um from an obstacle: turns {m[0]:.1f} s, then {m[1]:.1f} s straight off it")
                self.drive_move(i, turn_k, straight_k, m, orbiting, extra_discs, clearance=min(now - 0.5, lp.tune.viable_clearance_um))
                return True
        return False

    def drive_move(self, i: int, turn_k: int, straight_k: int, move_: tuple[float, float], orbiting: Sequence[int],
                   extra_discs=(), clearance: float | None = None) -> None:
        """Drive robot ``i``'s turn-then-straight ``move_`` (``(turn_s, straight_s)``, an escape or a move on) one t_x
        at a time, checked again from each measured pose: the rest must keep ``clearance`` (um; default
        ``Tuning.viable_clearance_um``) and, for a robot that can move on now, end where it still can; else it stops
        where it is. Driven whole on one frame, a body-length straight checked 5 um clear ran a 1 deg heading error
        (4 um over 250 um) and drift into the structure or the arena edge, and pinned the robot for good."""
        lp = self.loop
        c = lp.tune.viable_clearance_um if clearance is None else clearance
        done = (0.0, 0.0)
        for stop in move_stops(move_, lp.tx):  # the stops free_move checked
            lp.drive([(k, d) for k, d in ((turn_k, stop[0] - done[0]), (straight_k, stop[1] - done[1])) if d > 0.0])
            done = stop
            turn_s, straight_s = move_[0] - stop[0], move_[1] - stop[1]
            if turn_s + straight_s <= 1e-9:
                return
            v, r, p = float(lp.v_hat[i]), float(lp.r_hat[i]), lp.est[i].copy()
            sweep = escape_sweep(p, (turn_s, straight_s), v, r)
            if self.obstacles_hit(sweep[1:], i, orbiting, extra_discs=extra_discs, clearance=c) or (
                    self.boxed_in(i, sweep[-1], orbiting, extra_discs) and not self.boxed_in(i, p, orbiting, extra_discs)):
                lp.log("move-cut", i, f"stops {turn_s + straight_s:.1f} s short: the rest of its move, checked from where it "
                                      "is now, would meet an obstacle or leave it no way on")
                return

    def _left_biased(self, i: int, path, steps, straight_k: int, orbiting, extra_discs, clearance, target):
        """``steps`` with the turn into a long straight cut short by ``Tuning.left_bias_deg`` when that path is clear
        (see :meth:`steer`). The cut applies to every t_x of a turn longer than one t_x, not only its end: each such
        t_x turns a little less, so a long turn runs wide (a loop's circle drifted 58 um in 3 t_x on held-out 6:2).
        Cutting only the turn's end was measured in session 15 and lost as many trials as it won (tuning 1x 227/240
        against 229): the wide turn is a standing margin, and the next re-plan corrects it clockwise, cheaply."""
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
