"""Stages 2 and 3 of G_1 (seed App. 3.3): D_n arrives on the tangent of D_{n-1}'s orbit in time, D_{n-1}
departs toward it as measured, and both drive straight into each other (self-aligning compliance).

D_n's timed arrival waits on its own orbit or loops at an interpolated radius (:meth:`Rendezvous.loiter_path`),
re-planned every t_x (:meth:`Rendezvous.arrive_timed`); D_{n-1}'s departure, timed from its measured
heading, and the meeting are stage 3 (:class:`~stressbots.control.departure.Departure`, which
:meth:`Rendezvous.rendezvous` hands on to). When no timed way exists D_n waits on a holding orbit
(:mod:`~stressbots.control.holding`); when the meeting fails, the recoveries of
:mod:`~stressbots.control.pair_recovery` take over.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from enum import Enum
from typing import TYPE_CHECKING, Any

import numpy as np

from .. import paths as pathlib
from ..kinematics import move
from ..robots import TWO_PI
from .departure import Departure
from .gross import path_steps
from .pair_geometry import tight_discs
from .pairloop import Replan
from .queries import pose_region

if TYPE_CHECKING:
    from .pair import PairPhase

__all__ = ["Rendezvous", "Tending"]


class Tending(Enum):
    """Whether D_n's timed arrival (:meth:`Rendezvous.arrive_timed`) first moves waiting orbits that drifted near trouble,
    every t_x (``park_orbits``: the group move carries D_{n-1} and D_n along). At twice the literature's noise a waiting
    orbit wanders ~90 um a minute; untended through a long timed arrival, orbits refused a park at t = 0 drifted into
    the arena edge and trapped their robots at their start."""

    OFF = "off"
    """Nothing tended (a short or a precise stage)."""
    FOLLOW = "follow"
    """Tend, then plan again from the measured poses toward the same ``target_fn()``, which must follow D_{n-1}'s
    measured orbit (the approach line does: the pair forms wherever D_{n-1} orbits and the later slots follow it)."""
    STOP = "stop"
    """Tend, and return False once an orbit was moved: the target was planned from poses that no longer hold."""


def arrival_region(target, v_um_s: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The region D_n may arrive in instead of the pose ``target``: ``(goals (K, 3), offset_s (K,), penalty (K,))``.

    Poses up to 100 um along ``target``'s line (``offset_s`` later or earlier at ``v_um_s``), up to 40 um
    right or 20 um left of it and 6 deg either way; ``penalty`` grows with each departure from ``target``
    (1 at 100 um along, 40 um aside or 6 deg).

    >>> goals, offset, penalty = arrival_region(np.array([0.0, 0.0, 0.0]), 100.0)
    >>> goals.shape, float(penalty[0]), float(offset.max())
    ((100, 3), 0.0, 1.0)
    """
    along, right, turn = [0.0, -50.0, 50.0, -100.0, 100.0], [0.0, 20.0, -20.0, 40.0], np.radians([0.0, 3.0, -3.0, 6.0, -6.0])
    goals = pose_region(target, along, right, turn)
    s, e, d = (g.ravel() for g in np.meshgrid(along, right, turn, indexing="ij"))  # each goal's offsets, in its order
    offset = s / v_um_s  # further along the line: arrive correspondingly later
    penalty = np.abs(s) / 100.0 + np.abs(e) / 40.0 + np.abs(d) / math.radians(6.0)
    return goals, offset, penalty


def _best_finite(score: np.ndarray, m: int) -> np.ndarray:
    """Flat indices of the ``m`` lowest finite entries of ``score``, lowest first. Only the finite ones are sorted: of
    the 157,000 (wait, goal) pairs of a timed-path search most miss the arrival time (inf), and sorting them all was a
    tenth of a slow G_1's wall time."""
    finite = np.flatnonzero(np.isfinite(score))
    return finite[np.argsort(score[finite])][:m]


class Rendezvous:
    """Stages 2 and 3 of G_1: D_n arrives on D_{n-1}'s tangent in time, D_{n-1} departs, both meet."""

    def __init__(self, pair: PairPhase):
        self.pair = pair
        self.loop = pair.loop
        self._plan: tuple[Any, Any, float] | None = None
        self.departure = Departure(pair)
        self.tend_moves = 0
        """Waiting-orbit moves made while tending (:class:`Tending`) so far."""

    def loiter_path(self, N: int, target, arrivals: Sequence[float], lower, disc, tol_s: float = 0.3):
        """D_n waits on its own orbit, then takes its shortest path into the region around ``target``.

        Waiting on its own orbit (P_n: D_{n-1} orbits too) is the compact way for a one-way robot to
        arrive later: every arrival time from the shortest path's on to a period later is (almost always)
        available, and the path stays near where the robot is. The goal is a region, not a pose: any
        pose up to 100 um along D_n's approach line (timed accordingly), up to 40 um right or 20 um left
        of it and 6 deg either way will do, because D_{n-1}'s departure is fitted to the line D_n really
        ends on. A pose target would turn a small error to the left into a full loop. The first of
        ``arrivals`` (s from now, for ``target`` itself) that some wait meets within ``tol_s`` with a
        clear path wins; of those, the one nearest ``target``. Returns ``(path, goal, offset_s, arrival_s,
        loop)`` (``loop`` = (radius_um, count) of interpolated loops to drive first, or None) or None.
        """
        vN = self.loop.v_hat[N]
        goals, offset, penalty = arrival_region(target, vN)
        found = self._wait_then_go(N, goals, offset, penalty, arrivals, lower, disc, tol_s)
        return found if found is not None else self._loop_then_go(N, goals, offset, penalty, arrivals, lower, disc, tol_s)

    def _wait_then_go(self, N: int, goals, offset, penalty, arrivals: Sequence[float], lower, disc, tol_s: float):
        """:meth:`loiter_path` by a straight of 0-500 um and a wait on D_n's own orbit, then the shortest path."""
        vN, rN = self.loop.v_hat[N], self.loop.r_hat[N]
        period = TWO_PI * rN / vN
        # a straight of a um first, then a wait of tw s on the orbit: the shortest path's length jumps by a
        # loop as the wait passes its first turn, and the straights fill those gaps in arrival time
        pre = np.array([0.0, 100.0, 200.0, 350.0, 500.0])
        tw = np.arange(0.0, period, 0.05)
        A, Tw = np.meshgrid(pre, tw, indexing="ij")
        A, Tw = A.ravel(), Tw.ravel()
        waits = move(move(self.loop.est[N], A, 0.0), vN * Tw, 1.0 / rN)
        K = len(goals)
        ell = pathlib.shortest_path_lengths(waits[:, None, :], goals[None, :, :], rN, approach_um=60.0)  # (W, K): a grid, not W K copies
        arr = (A / vN + Tw)[:, None] + ell / vN - offset[None, :]
        for want in arrivals:
            err = np.abs(arr - want)
            score = np.where(err <= tol_s, err + 0.1 * penalty[None, :] + 0.002 * A[:, None] / vN, np.inf).ravel()
            for flat in _best_finite(score, 10):
                j, kk = divmod(int(flat), K)
                tail = pathlib.shortest_path(waits[j], goals[kk], rN, approach_um=60.0)
                segs = tuple(tail.segments)
                if Tw[j] > 0:
                    if segs and segs[0][0] == "R":
                        segs = (("R", segs[0][1] + vN * Tw[j]),) + segs[1:]
                    else:
                        segs = (("R", vN * Tw[j]),) + segs
                if A[j] > 0:
                    segs = (("S", float(A[j])),) + segs
                path = pathlib.Path(self.loop.est[N], rN, segs)
                if not self.loop.obstacles_hit(path.sample(10.0), N, lower, extra_discs=self._tight(disc),
                                          clearance=self.loop.tune.wall_clearance_um):
                    return path, goals[kk], float(offset[kk]), float(want), None
        return None

    def _loop_then_go(self, N: int, goals, offset, penalty, arrivals: Sequence[float], lower, disc, tol_s: float):
        """:meth:`loiter_path` by one or two interpolated loops first, then the shortest path.

        Waiting on the orbit only shifts arrival times in steps (it eats into the path's first turn, then
        costs a whole loop). One or two interpolated loops of radius R in [r, 1.6 r] (P_n / P_{n-1}
        alternating) end where they began after 2 pi R / v: every arrival time in a window wider than
        D_{n-1}'s period, continuously.
        """
        vN, rN = self.loop.v_hat[N], self.loop.r_hat[N]
        K = len(goals)
        ell0 = pathlib.shortest_path_lengths(np.broadcast_to(self.loop.est[N], goals.shape), goals, rN, approach_um=60.0)
        radii = np.linspace(rN, 1.6 * rN, 61)
        for want in arrivals:
            for m in (1, 2):
                arr = m * TWO_PI * radii[:, None] / vN + ell0[None, :] / vN - offset[None, :]
                err = np.abs(arr - want)
                score = np.where(err <= tol_s, err + 0.1 * penalty[None, :] + 0.01 * radii[:, None] / rN, np.inf).ravel()
                for flat in _best_finite(score, 6):
                    jr, kk = divmod(int(flat), K)
                    R = float(radii[jr])
                    loop = move(self.loop.est[N], np.linspace(0.0, TWO_PI * R, 72), 1.0 / R)
                    tail = pathlib.shortest_path(self.loop.est[N], goals[kk], rN, approach_um=60.0)
                    if self.loop.obstacles_hit(np.vstack([loop, tail.sample(10.0)]), N, lower, extra_discs=self._tight(disc),
                                          clearance=self.loop.tune.wall_clearance_um):
                        continue
                    return tail, goals[kk], float(offset[kk]), float(want), (R, m)
        return None

    def loop_clear(self, N: int, R: float, left_s: float, lower, disc) -> bool:
        """Whether the rest of D_n's timing loop (radius ``R``, ``left_s`` seconds), from its measured pose, keeps
        ``Tuning.loop_clearance_um`` from the arena edge, the orbits and the structure (D_{n-1}'s orbit at
        ``Tuning.g1_clearance_um`` less the same shortfall). Checked every t_x: a loop is driven open loop by
        interpolation, and at 2x noise two loops drifted 300 um and ended with D_n against the arena edge,
        where a one-way robot cannot turn."""
        s = np.linspace(0.0, float(self.loop.v_hat[N]) * left_s, max(2, int(left_s * 4) + 2))
        return self._open_loop_clear(N, move(self.loop.est[N], s, 1.0 / R), lower, disc)

    def _open_loop_clear(self, N: int, poses: np.ndarray, lower, disc) -> bool:
        """Whether D_n's ``poses`` (M, 3), driven open loop, keep ``Tuning.loop_clearance_um`` from the arena edge, the
        orbits and the structure, and D_{n-1}'s orbit ``disc`` at ``Tuning.g1_clearance_um`` less the same shortfall
        from ``Tuning.wall_clearance_um``."""
        tune = self.loop.tune
        short = tune.wall_clearance_um - tune.loop_clearance_um
        tight = tight_discs(disc, tune.loop_clearance_um, tune.g1_clearance_um - short)
        return not self.loop.obstacles_hit(poses, N, lower, extra_discs=tight, clearance=tune.loop_clearance_um)

    def _tight(self, disc, clearance: float | None = None):
        """D_{n-1}'s orbit disc(s) shrunk so that checks at ``Tuning.wall_clearance_um`` keep ``clearance``
        (default ``Tuning.g1_clearance_um``) from them."""
        clearance = self.loop.tune.g1_clearance_um if clearance is None else clearance
        return tight_discs(disc, self.loop.tune.wall_clearance_um, clearance)

    def continued(self, N: int, arrivals: Sequence[float], lower, disc) -> pathlib.Path | None:
        """The last plan's goal, re-planned from the measured pose, if its timing still holds (plans persist).

        Without this, a plan that becomes marginally infeasible (a graze with an orbit, an arrival just
        outside the tolerance) would be replaced by a different one every t_x.
        """
        if self._plan is None:
            return None
        goal, offset, t_abs = self._plan
        vN, rN = self.loop.v_hat[N], self.loop.r_hat[N]
        want = min(arrivals, key=lambda a: abs(self.loop.t + a - t_abs)) if arrivals else None
        if want is None or abs(self.loop.t + want - t_abs) > 1.0:
            return None
        path = pathlib.shortest_path(self.loop.est[N], goal, rN, approach_um=60.0)
        if abs(path.length / vN - offset - want) > 0.5:
            return None
        if self.loop.obstacles_hit(path.sample(10.0), N, lower, extra_discs=self._tight(disc, 0.0),
                                   clearance=self.loop.tune.wall_clearance_um - 5.0):
            return None
        self._plan = (goal, offset, self.loop.t + want)
        return path

    def rendezvous(self, N: int, M: int, D: float, lower) -> bool:
        th_dep = float(self.loop.goals[M, 2])
        tend = Tending.FOLLOW if self.loop.tune.tend_during_rendezvous else Tending.OFF
        if not self.arrive_timed(N, M, lambda: self.pair.approach_pose(N, M, self.pair.centre(M), D), th_dep, lower, tend=tend):
            raise Replan(f"{self.loop.scn.names[N]} found no timed path to its approach line")
        return self.departure.depart_and_meet(N, M)

    def arrive_timed(self, N: int, M: int, target_fn, th_dep: float, lower, early: float | None = None,
                     tend: Tending = Tending.OFF) -> bool:
        """D_n drives to ``target_fn()`` (a pose on a line it then runs straight along), arriving ``early``
        seconds before D_{n-1}, orbiting, reaches heading ``th_dep``. Replanned every t_x; the last leg
        runs whole. False if no timed way exists even from a holding orbit, or (``tend`` STOP) when a waiting orbit
        was moved (:class:`Tending`; :attr:`tend_moves` counts those moves).
        """
        early = self.loop.tune.early_s if early is None else early
        n = self.loop.n
        self._plan = None
        holds = loops = 0
        prev = None
        moves0 = self.tend_moves
        for _ in range(600):
            if tend is not Tending.OFF:
                self._tended(n)
                if self.tend_moves > moves0:
                    if tend is Tending.STOP:
                        return False
                    self._plan, prev, moves0 = None, None, self.tend_moves
            vN = self.loop.v_hat[N]
            q = target_fn()
            disc = self.pair.orbit_disc(M)
            arrivals = self._arrivals(M, th_dep, early)
            path = self.continued(N, arrivals, lower, disc)
            if path is None and prev is not None and prev.length - vN * self.loop.tx <= self.loop.tune.final_leg_s * vN:
                return self._drive_rest_open_loop(N, prev, vN, lower, disc)
            path, loop = self._timed_path(N, q, arrivals, lower, disc, path)
            if loop is not None:
                loops += 1
                if loops > self.loop.tune.timing_loops_max:
                    # each loop came back off time (at 2x noise an interpolated loop's period is seconds off):
                    # another would too; the caller falls back (another leg option, a holding orbit, a new frame)
                    self.loop.log("retry", N, f"{self.loop.scn.names[N]} missed its time after {loops - 1} timing loops")
                    return False
                self._drive_timing_loop(N, M, loop, vN, lower, disc, tend)
                prev = None
                continue
            prev = path
            if path is None:
                # no timed way from here: go where D_n can wait on its orbit near the target, then retry
                holds += 1
                if holds > 3 or not self.pair.holding.to_holding(N, q, lower, disc):
                    return False
                continue
            self.loop.replans += 1
            whole = path.length / vN <= 1.6 * self.loop.tx
            self.loop.drive(path_steps(path, vN, n, n - 1, None if whole else self.loop.tx))
            if whole:
                return True
        return False

    def _tended(self, n: int) -> bool:
        """Move the waiting orbits (D_1 .. D_(n-2)) that drifted near trouble, D_{n-1}'s orbit disc counting as trouble
        (:class:`Tending`); True when anything moved (time passed)."""
        t0 = self.loop.t
        self.loop.park_orbits(n, top=n - 2, among=[self.loop.by_rank[n - 1]])
        if self.loop.t > t0:
            self.tend_moves += 1
            return True
        return False

    def _arrivals(self, M: int, th_dep: float, early: float) -> list[float]:
        """When D_n should arrive (s from now): ``early`` s before each of D_{n-1}'s next four passes through
        heading ``th_dep`` on its orbit (as measured, at its identified turn rate), those more than 0.3 s away."""
        t_dep = float(np.mod(th_dep - self.loop.est[M, 2], TWO_PI)) / self.loop.omega_hat[M]
        period = TWO_PI / self.loop.omega_hat[M]
        return [a for a in (t_dep + k * period - early for k in range(4)) if a > 0.3]

    def _drive_rest_open_loop(self, N: int, prev: pathlib.Path, vN: float, lower, disc) -> bool:
        """The final seconds of :meth:`arrive_timed`: D_n drives the rest of its last plan ``prev`` (less the
        t_x already driven) open loop at ``vN`` um/s. A small error can make a replanned path a loop (one-way
        robot); the rest of the plan misses by a few um at most. False (nothing driven) when that rest, driven from
        the measured pose, would not keep ``Tuning.loop_clearance_um`` from the arena edge, the orbits and the
        structure (as :meth:`loop_clear`): at 2x noise it drove D_n into the arena edge, pinned for good."""
        n = self.loop.n
        rest = pathlib.sub_path(prev, min(vN * self.loop.tx, prev.length), prev.length)
        from_here = pathlib.Path(self.loop.est[N].copy(), rest.radius, rest.segments)
        if not self._open_loop_clear(N, from_here.sample(10.0), lower, disc):
            self.loop.log("final", N, f"{self.loop.scn.names[N]}'s last {rest.length:.0f} um, driven from where it is, would meet "
                                      "an obstacle: it plans again")
            return False
        self.loop.log("final", N, f"{self.loop.scn.names[N]} drives the last {rest.length:.0f} um of its plan open loop")
        self.loop.drive(path_steps(rest, vN, n, n - 1, None))
        return True

    def _timed_path(self, N: int, q, arrivals: Sequence[float], lower, disc, path: pathlib.Path | None):
        """``(path, loop)``: the continued plan ``path`` if there is one, else a new :meth:`loiter_path` to ``q``
        (arrival tolerance 0.3 s, then 0.7 s), remembered as the plan to continue; ``loop`` = (radius_um, count)
        of timing loops to drive first, or None. ``(None, None)``: no timed way from here."""
        loop = None
        for tol in (0.3, 0.7):
            if path is not None:
                break
            found = self.loiter_path(N, q, arrivals, lower, disc, tol_s=tol)
            path = None if found is None else found[0]
            self._plan = None if found is None else (found[1], found[2], self.loop.t + found[3])
            loop = None if found is None else found[4]
        return path, loop

    def _drive_timing_loop(self, N: int, M: int, loop: tuple[float, int], vN: float, lower, disc,
                           tend: Tending = Tending.OFF) -> None:
        """D_n circles ``loop`` = (radius_um, count) interpolated loops (P_n / P_{n-1} alternating) at ``vN``
        um/s, a t_x at a time; it stops early where the rest is no longer clear (:meth:`loop_clear`; against D_{n-1}'s
        (``M``'s) orbit ``disc``, or with ``Tuning.fresh_pair_disc`` its disc as measured at each t_x; and the next t_x
        against D_{n-1}'s body at the same instants, ``Tuning.loop_body_clearance_um``), or (``tend``)
        where a waiting orbit had to be moved (:meth:`_tended`: the timing is then planned again)."""
        n = self.loop.n
        R, m = loop
        self.loop.log("loop", N, f"{self.loop.scn.names[N]} circles {m} time(s) at radius {R:.0f} um to arrive on time")
        self.loop.replans += 1
        total = m * TWO_PI * R / vN
        while total > 1e-6:  # the loop, a t_x at a time (it ends where it began)
            if tend is not Tending.OFF and self._tended(n):
                break
            if self.loop.tune.fresh_pair_disc:
                disc = self.pair.orbit_disc(M)
            if not self.loop_clear(N, R, total, lower, disc):
                self.loop.log("loop", N, f"{self.loop.scn.names[N]}'s timing loop has drifted toward an obstacle; "
                                         "it plans again from here")
                break
            d = min(self.loop.tx, total)
            steps = self.loop.interpolated_steps(float(self.loop.r_hat[N] / R), d, n, n - 1)
            gap = self.pair.body_gap(N, M, steps)
            if gap < self.loop.tune.loop_body_clearance_um:
                names = self.loop.scn.names
                self.loop.log("loop", N, f"{names[N]}'s timing loop would pass {gap:.0f} um from {names[M]}'s body; "
                                         "it plans again from here")
                break
            self.loop.drive(steps)
            total -= d
