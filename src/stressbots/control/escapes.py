"""Ways off an obstacle and on from where a robot is, for gross motion sigma_1: escapes, checked moves on, boxed in.

A one-way robot can neither reverse nor turn left: every way off an obstacle is a clockwise turn for part of a loop,
then a straight (:func:`escape_moves`, swept by :func:`escape_sweep`). A robot is *boxed in* where none of these keeps
clear (:meth:`Escapes.boxed_in`): heading into an obstacle a few tens of um ahead, it can neither turn nor drive off,
and the next nudge pins it for good. So the gross motion (:class:`~stressbots.control.gross.GrossMotion`) drives only
a *viable* beginning of a blocked path (:func:`viable_prefix`, one whose end does not box the robot in), counts a path
whose next t_x loses the robot its loop as blocked (:meth:`Escapes.dead_end_ahead`, with ``Tuning.dead_end_guard``),
and escapes a contact by the cheapest checked way off (:meth:`Escapes.escape`, at :func:`contact_clearance`); escapes
and moves on are driven a t_x at a time, checked again from each measured pose (:meth:`Escapes.drive_move`, stops at
:func:`move_stops`).

:class:`Escapes` answers and drives for one :class:`~stressbots.control.gross.GrossMotion` (its loop and its obstacle
check); the rest is pure. D_n's ways out during G_1 are :mod:`~stressbots.control.escape_search` and
:mod:`~stressbots.control.group_escape`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Sequence
from typing import TYPE_CHECKING

import numpy as np

from .. import kinematics
from .. import paths as pathlib
from ..robots import TWO_PI
from .loopview import LoopView

if TYPE_CHECKING:
    from .gross import GrossMotion

__all__ = ["Escapes", "contact_clearance", "escape_moves", "escape_sweep", "loop_poses", "move_stops", "viable_prefix"]


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


def loop_poses(pose, r: float, samples: int = 72) -> np.ndarray:
    """The poses (``samples``, 3) of one full clockwise loop of radius ``r`` (um) from ``pose``: what a loop back or a
    loop kept in reserve sweeps (5 deg apart by default)."""
    return kinematics.move(np.asarray(pose, float), np.linspace(0.0, TWO_PI * r, samples), 1.0 / r)


def move_stops(move_: tuple[float, float], tx: float) -> list[tuple[float, float]]:
    """The parts ``(turn_s, straight_s)`` of the turn-then-straight ``move_`` driven at each of its t_x stops
    (``tx`` s apart; the whole move last): where :meth:`Escapes.drive_move` looks again.

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


class Escapes:
    """Ways off an obstacle and on for the robots of ``gross``'s closed loop, checked by its obstacle check
    (:meth:`~stressbots.control.gross.GrossMotion.obstacles_hit`): whether a robot is boxed in or a path leads into a
    dead end, how much of a clear path is viable, and the escapes and moves on it drives (through the loop)."""

    def __init__(self, gross: GrossMotion):
        self.gross = gross
        self.loop: LoopView = gross.loop

    def free_moves(self, i: int, pose: np.ndarray, orbiting: Sequence[int], extra_discs=()) -> Iterator[tuple[float, float]]:
        """The escapes of the kind :meth:`escape` drives (turn clockwise ``Tuning.escape_turns`` of a loop, none
        included, then one body length straight; ``(turn_s, straight_s)``, in that order) that keep
        ``Tuning.viable_clearance_um`` from every orbit, docked body and the arena edge from ``pose``; lazily."""
        v, r, length = float(self.loop.v_hat[i]), float(self.loop.r_hat[i]), float(self.loop.L[i])
        for f in self.loop.tune.escape_turns:
            m = (2.0 * math.pi * r * f / v, length / v)
            sweep = escape_sweep(np.asarray(pose, float), m, v, r, step_um=15.0)
            if not self.gross.obstacles_hit(sweep[1:], i, orbiting, extra_discs=extra_discs, clearance=self.loop.tune.viable_clearance_um):
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

    def viable(self, i: int, path, ahead: float, orbiting: Sequence[int], extra_discs) -> float:
        """How much of the ``ahead`` um clear beginning of ``path`` robot ``i`` may drive: all of it when it is
        :meth:`boxed_in` where it is now (it needs the way out), else the longest beginning whose end does not box
        it in (:func:`viable_prefix`): the clear part of a blocked path drove robots to a stop 10-50 um short of
        the structure, the arena edge or a waiting robot, heading into it, and the next nudge pinned them for good."""
        if ahead <= 0.0 or self.boxed_in(i, self.loop.est[i], orbiting, extra_discs):
            return ahead
        return viable_prefix(path, ahead, lambda pose: self.boxed_in(i, pose, orbiting, extra_discs), self.loop.tune.viable_step_um,
                             self.loop.tune.viable_checks_max)

    def dead_end_ahead(self, i: int, path: pathlib.Path, target, orbiting: Sequence[int], extra_discs=()) -> bool:
        """Whether one t_x along ``path`` robot ``i`` would lose the clockwise loop it has now: its loop from there would
        meet an orbit, the structure or the arena edge (``Tuning.dead_end_guard``; not within two turning radii and a
        body length of ``target``, where it is meant to come close). A one-way robot whose loop is blocked has only the
        straight ahead; a 2x drift curved a robot's long straight past the structure, and 2 s later neither its loop nor
        its straight was free (held-out 53:0 at 2x). The path then counts as blocked: a waypoint is skipped, the rest
        is routed around."""
        lp = self.loop
        if not lp.tune.dead_end_guard:
            return False
        r, v = float(lp.r_hat[i]), float(lp.v_hat[i])
        q = np.asarray(path.pose_at(min(v * lp.tx, path.length)), float)
        if np.hypot(*(q[:2] - np.asarray(target, float)[:2])) < 2.0 * r + lp.L[i]:
            return False
        if not self.gross.obstacles_hit(loop_poses(q, r), i, orbiting, extra_discs=extra_discs, clearance=0.0):
            return False  # the loop is kept (the usual case: one check per t_x)
        # lost unless it is lost already: with no loop now either, the guard keeps nothing
        return not self.gross.obstacles_hit(loop_poses(lp.est[i], r), i, orbiting, extra_discs=extra_discs, clearance=0.0)

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
            return self.gross.obstacles_hit(samples, i, orbiting, extra_discs=extra_discs, clearance=c)

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
            if self.gross.obstacles_hit(sweep[1:], i, orbiting, extra_discs=extra_discs, clearance=c) or (
                    self.boxed_in(i, sweep[-1], orbiting, extra_discs) and not self.boxed_in(i, p, orbiting, extra_discs)):
                lp.log("move-cut", i, f"stops {turn_s + straight_s:.1f} s short: the rest of its move, checked from where it "
                                      "is now, would meet an obstacle or leave it no way on")
                return
