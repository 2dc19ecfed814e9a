"""Recoveries of the G_1 pair phase: D_n waits on a holding orbit when it has no timed way, gets its orbit
clear of D_{n-1}'s, and the pair separates after a failed meeting (seed App. 3.3: re-plan, never give up
while the time budget lasts). Each keeps D_n where a one-way robot can still orbit.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .. import paths as pathlib
from ..collision import arena_gap
from ..robots import TWO_PI, turning_centres
from .escape_search import Orbiting, escape_manoeuvre
from .gross import arrived, path_steps
from .group_escape import Group, group_escape
from .pair_geometry import tight_discs
from .station import orbit_room

if TYPE_CHECKING:
    from .pair import PairPhase

__all__ = ["PairRecovery"]


class PairRecovery:
    """D_n's holding orbit, its escape from D_{n-1}'s orbit, and the pair's separation after a failed meeting."""

    def __init__(self, pair: PairPhase):
        self.pair = pair
        self.loop = pair.loop

    def clearance_shortfall(self, N: int, lower, disc) -> float:
        """How much (um, >= 0) D_n's own orbit, as measured, falls short of the G_1 clearances from the other
        orbits: ``Tuning.wall_clearance_um`` from the lower robots', ``Tuning.g1_clearance_um`` from D_{n-1}'s
        (``disc``). Every path starts along that orbit or straight on, so checking paths from here at the
        full clearances finds none (D_n sat still while every frame was re-planned); they are checked against
        the orbits at the clearances less this shortfall (at most ``g1_clearance_um``). Never against the
        arena edge: an orbit moves on, the edge traps a one-way robot for good (:meth:`escape` leaves it)."""
        tune = self.loop.tune
        cs = turning_centres(self.loop.est[lower], self.loop.r_hat[lower]) if lower else np.zeros((0, 2))
        rs = self.loop.rstar[lower] if lower else np.zeros(0)
        r, rstar = float(self.loop.r_hat[N]), float(self.loop.rstar[N])
        others = float(orbit_room(self.loop.est[N][None], r, rstar, None, cs, rs)[0])
        dc = np.array([c for c, _ in disc]).reshape(-1, 2)
        near = float(orbit_room(self.loop.est[N][None], r, rstar, None, dc, [float(rr) for _, rr in disc])[0])
        short = max(tune.wall_clearance_um - others, tune.g1_clearance_um - near, 0.0)
        return float(min(short, tune.g1_clearance_um))

    def hold_way_clear(self, N: int, samples: np.ndarray, lower, disc, short: float) -> bool:
        """Whether D_n's body along ``samples`` keeps the G_1 clearances less ``short`` from the orbits
        (:meth:`clearance_shortfall`) and the full ``Tuning.wall_clearance_um`` from the arena edge."""
        tune = self.loop.tune
        tight = tight_discs(disc, tune.wall_clearance_um - short, tune.g1_clearance_um - short)
        if self.loop.obstacles_hit(samples, N, lower, extra_discs=tight, clearance=tune.wall_clearance_um - short):
            return False
        arena = self.loop.scn.arena_um
        return arena is None or bool(arena_gap(samples, self.loop.L[N], self.loop.W[N], arena).min() >= tune.wall_clearance_um)

    def to_holding(self, N: int, q, lower, disc, escaped: bool = True) -> bool:
        """Take D_n (untimed) onto a free orbit near ``q``, from which any arrival time is a wait away; when
        no free orbit has a clear way there, D_n first gets clear of D_{n-1}'s orbit (:meth:`escape`, once)."""
        # the same clearances as the timed paths' checks, so that waiting there passes them
        tune = self.loop.tune
        free = self.pair.free_orbits(N, [(c, r + tune.g1_clearance_um - tune.wall_clearance_um - 5.0) for c, r in disc], lower,
                                clearance=self.loop.tune.wall_clearance_um + 5.0)
        if len(free) == 0:
            return False
        rN = self.loop.r_hat[N]
        heads = np.radians(np.arange(0.0, 360.0, 30.0))
        poses = np.concatenate([np.stack([free[:, 0] - rN * math.cos(t), free[:, 1] + rN * math.sin(t), np.full(len(free), t)],
                                         axis=1) for t in heads])
        # near the target, with a clear way on to it (the way there may be routed around obstacles)
        cost = 0.3 * pathlib.shortest_path_lengths(np.broadcast_to(self.loop.est[N], poses.shape), poses,
                                                   rN) + pathlib.shortest_path_lengths(
            poses, np.broadcast_to(np.asarray(q, float), poses.shape), rN, approach_um=60.0
        )
        # only holds D_n reaches by a clear shortest path, with a clear way on preferred: gross motion that
        # finds no way around drives on regardless, and took D_n into the arena edge or D_{n-1}'s orbit
        # (trapped for good); without a clear hold the caller re-plans G_1 instead
        # a D_n already closer than the clearances (its own orbit grazes them) may leave at what it has
        short = self.clearance_shortfall(N, lower, disc)
        hold, onward = None, False
        for j in np.argsort(cost)[:self.loop.tune.hold_candidates]:
            there = pathlib.shortest_path(self.loop.est[N], poses[j], rN)
            if not self.hold_way_clear(N, there.sample(10.0), lower, disc, short):
                continue
            on = not self.loop.obstacles_hit(pathlib.shortest_path(poses[j], q, rN, approach_um=60.0).sample(10.0), N, lower,
                                             extra_discs=tight_discs(disc, tune.wall_clearance_um, tune.g1_clearance_um),
                                             clearance=tune.wall_clearance_um)
            if hold is None or (on and not onward):
                hold, onward = poses[j], on
            if onward:
                break
        if hold is None:
            self.loop.log("hold", N, f"{self.loop.scn.names[N]} has no clear way to a free orbit near its target")
            # a way around the obstacles by the planner's roadmap: gross motion follows it (as before); no
            # such way (where gross motion "drove on" into the edge or an orbit): D_n escapes what hems it in
            if not escaped:
                return False
            if self.steer_to_hold(N, q, lower, disc):
                return True
            return self.escape(N, lower) and self.to_holding(N, q, lower, disc, escaped=False)
        self.loop.log("hold", N,
                 f"{self.loop.scn.names[N]} heads for a free orbit {np.hypot(*(hold[:2] - q[:2])):.0f} um from its target, to wait there")
        return self.drive_to_hold(N, hold, lower, disc, short)

    def steer_to_hold(self, N: int, q, lower, disc) -> bool:
        """Gross motion (the loop's ``steer``, roadmap detours) to the free orbit nearest ``q``, when the planner's
        roadmap has a route there (False, nothing driven, when it has none): the way the phase went to wait
        before it drove its own clear ways, for a D_n hemmed in so that no shortest path is clear."""
        tune = self.loop.tune
        free = self.pair.free_orbits(N, [(c, r + tune.g1_clearance_um - tune.wall_clearance_um - 5.0) for c, r in disc], lower,
                                     clearance=tune.wall_clearance_um + 5.0)
        if len(free) == 0:
            return False
        rN = self.loop.r_hat[N]
        poses = np.stack([free[:, 0] - rN, free[:, 1], np.zeros(len(free))], axis=1)
        cost = 0.3 * pathlib.shortest_path_lengths(np.broadcast_to(self.loop.est[N], poses.shape), poses, rN) + \
            pathlib.shortest_path_lengths(poses, np.broadcast_to(np.asarray(q, float), poses.shape), rN, approach_um=60.0)
        hold = poses[int(np.argmin(cost))]
        _, routed = self.loop.gross.roadmap_route(N, hold, lower, disc, max(tune.g1_clearance_um + 5.0, 20.0))
        if routed is None:
            return False
        self.loop.log("hold", N, f"{self.loop.scn.names[N]} steers around the obstacles to a free orbit "
                                 f"{np.hypot(*(hold[:2] - q[:2])):.0f} um from its target, to wait there")
        self.loop.steer(N, hold, self.loop.n, self.loop.n - 1, lower, extra_discs=disc, max_cycles=tune.hold_frames,
                        clearance=tune.g1_clearance_um)
        return not self.loop.stuck

    def drive_to_hold(self, N: int, hold, lower, disc, short: float) -> bool:
        """D_n drives its shortest path to ``hold``, re-planned every t_x while it stays clear
        (:meth:`hold_way_clear`); it stops where the way is no longer clear (the caller plans from there).
        False when D_n stalled (``Tuning.stall_count`` frames in a row under ``Tuning.stall_fraction`` of
        the commanded travel: blocked, failure region H)."""
        n, vN, rN, tune = self.loop.n, self.loop.v_hat[N], self.loop.r_hat[N], self.loop.tune
        stalls = 0
        hold_c = turning_centres(np.asarray(hold, float), rN)[0]
        for frame in range(tune.hold_frames):
            # on the holding orbit counts once D_n has driven toward it: a D_n already there drives on to the hold
            # pose as before (that time is its wait)
            if arrived(self.loop.est[N], hold, tune) or (frame > 0 and self.on_hold_orbit(N, hold_c, lower, disc)):
                return True
            path = self.way_onto_orbit(N, hold, lambda smp: self.hold_way_clear(N, smp, lower, disc, short))
            if not self.hold_way_clear(N, path.sample(10.0), lower, disc, short):
                return True
            whole = path.length / vN <= tune.whole_leg_factor * self.loop.tx
            steps = path_steps(path, vN, n, n - 1, None if whole else self.loop.tx)
            before = self.loop.est[N, :2].copy()
            self.loop.drive(steps)
            moved = float(np.hypot(*(self.loop.est[N, :2] - before)))
            stalls = stalls + 1 if moved < tune.stall_fraction * vN * sum(d for _, d in steps) else 0
            if stalls >= tune.stall_count:
                self.loop.log("stuck", N, f"{self.loop.scn.names[N]} stalled on its way to a holding orbit (failure region H)")
                return False
            if whole:
                return True
        return True

    def way_onto_orbit(self, N: int, hold, clear) -> pathlib.Path:
        """D_n's shortest clear path onto its holding orbit (the orbit through pose ``hold``), at whichever of
        ``Tuning.hold_headings`` poses on it is nearest by a path ``clear(samples)`` accepts (else the path to
        ``hold`` itself): any pose on a holding orbit will do, and a one-way robot that aims at one exact pose
        needs a whole loop each time its straight ends a little right of it (at 2x noise D_n circled 110 s
        toward a hold 2 mm away and ended 1 mm from it)."""
        rN = float(self.loop.r_hat[N])
        centre = turning_centres(np.asarray(hold, float), rN)[0]
        t = np.radians(np.arange(0.0, 360.0, 360.0 / self.loop.tune.hold_headings))
        poses = np.stack([centre[0] - rN * np.cos(t), centre[1] + rN * np.sin(t), t], axis=1)
        ell = pathlib.shortest_path_lengths(np.broadcast_to(self.loop.est[N], poses.shape), poses, rN)
        for j in np.argsort(ell)[:4]:
            path = pathlib.shortest_path(self.loop.est[N], poses[j], rN)
            if clear(path.sample(10.0)):
                return path
        return pathlib.shortest_path(self.loop.est[N], np.asarray(hold, float), rN)

    def on_hold_orbit(self, N: int, hold_c, lower, disc) -> bool:
        """Whether D_n already orbits a free centre within ``Tuning.hold_centre_tol_um`` of the holding orbit's
        centre ``hold_c``: a holding orbit is where D_n waits, any pose on it will do. Aimed at as an exact pose
        (25 um, 6 deg) at 2x noise, a one-way D_n looped after it for 110 s of a 120 t_x drive."""
        tune = self.loop.tune
        c = turning_centres(self.loop.est[N], self.loop.r_hat[N])
        if float(np.hypot(*(c[0] - hold_c))) > tune.hold_centre_tol_um:
            return False
        discs = [(cc, r + tune.g1_clearance_um - tune.wall_clearance_um - 5.0) for cc, r in disc]
        return bool(self.pair.orbits_free(N, c, discs, lower, tune.wall_clearance_um)[0])

    def escape(self, N: int, lower) -> bool:
        """D_n gets its orbit clear of the orbits around it and the arena edge: ``Tuning.g1_clearance_um`` from
        D_{n-1}'s, ``Tuning.wall_clearance_um`` from the lower robots' and the edge. It turns (P_n) until it
        heads within 60 deg of straight away from what it lacks most clearance from, then runs straight
        (P_{n-1}: the others orbit in place) while it keeps room to orbit; at most ``Tuning.separate_frames``
        t_x. True when clear.

        A D_n whose orbit overlaps another (after a failed meeting, or a transfer track ending beside a
        lower orbit at 2x noise) finds no clear path at any of G_1's clearances: every pair frame then
        failed at once, with nothing moved.
        """
        n, tune = self.loop.n, self.loop.tune
        M = self.loop.by_rank[n - 1]
        others = [M, *lower]
        need = np.array([tune.g1_clearance_um] + [tune.wall_clearance_um] * (len(lower) + 4))
        for _ in range(tune.separate_frames):
            p = self.loop.est[N]
            away_from = self.escape_gaps(N, others)
            gaps = np.array([g for g, _ in away_from])
            worst = int(np.argmax(need - gaps))
            if gaps[worst] >= need[worst]:
                return True
            away = away_from[worst][1]
            turn = float(np.mod(away - math.radians(60.0) - p[2], TWO_PI))  # clockwise to the edge of the cone
            if turn >= math.radians(240.0) or turn < 1e-9:  # heading within 60 deg of away: run straight out
                if not self.pair.transfer.keeps_room(N, self.loop.v_hat[N] * self.loop.tx, lower) or self.meets_others(N, others, 0.0,
                                                                                                                    self.loop.tx):
                    break
                self.loop.drive([(n - 1, self.loop.tx)])
            else:
                dt = min(turn + math.radians(5.0), self.loop.omega_hat[N] * self.loop.tx) / self.loop.omega_hat[N]
                if self.meets_others(N, others, 1.0 / float(self.loop.r_hat[N]), dt):
                    break  # turning here would sweep D_n into a robot orbiting beside it
                self.loop.drive([(n, dt)])
        # the direct way out is blocked (or ran out): the searched turn-then-straight, body to body in time
        return self.searched_escape(N, others)

    def searched_escape(self, N: int, others) -> bool:
        """D_n drives the quickest (straight-)turn-straight that clears its orbit
        (:func:`~stressbots.control.escape_search.escape_manoeuvre`, searched again from the measured poses every
        t_x), at most ``Tuning.escape_search_frames`` t_x. True when clear.

        The others keep orbiting meanwhile, so the search compares bodies at the same instants: D_n passes an
        orbit disc it overlaps while the body on it is elsewhere."""
        n, tune = self.loop.n, self.loop.tune
        for _ in range(tune.escape_search_frames):
            m = self.escape_plan(N, others)
            if m is None:  # no way out alone: with the robots beside it (a group manoeuvre), else none
                return self.group_escape(N)
            if m.total_s <= 1e-3:
                return m.slack_um >= 0.0
            # the first part, at most a t_x (the rest is searched again from the next frame)
            k, dt = next((k, d) for k, d in ((n - 1, m.lead_s), (n, m.turn_s), (n - 1, m.straight_s)) if d > 1e-3)
            self.loop.drive([(k, dt if dt <= 1.6 * self.loop.tx else self.loop.tx)])
        m = self.escape_plan(N, others)
        return m is not None and m.total_s <= 1e-3 and m.slack_um >= 0.0

    def group_escape(self, N: int) -> bool:
        """D_n leaves together with the robots hemming it in (:func:`~stressbots.control.group_escape.group_escape`:
        wait under P_n, then P_k drives D_(k+1) .. D_n straight), searched again from the measured poses every t_x,
        at most ``Tuning.escape_search_frames`` t_x. True when D_n's orbit is clear. D_{n-1}'s station is planned
        again from wherever its orbit ends (every pair frame plans from the measured poses)."""
        n, tune, names = self.loop.n, self.loop.tune, self.loop.scn.names
        said = False
        for _ in range(tune.escape_search_frames):
            m = self.group_plan()
            if m is None or m.total_s <= 1e-3:
                break
            if not said:
                said = True
                self.loop.log("escape", N, f"{names[N]} has no way out alone: after {m.wait_s:.1f} s, D_{m.k + 1} .. D_{n} "
                                           f"drive straight together {m.straight_s:.1f} s (P_{m.k})")
            k, dt = (n, m.wait_s) if m.wait_s > 1e-3 else (m.k, m.straight_s)
            self.loop.drive([(k, dt if dt <= 1.6 * self.loop.tx else self.loop.tx)])
        m = self.group_plan()
        if m is None or m.total_s > 1e-3:
            self.loop.log("hold", N, f"{names[N]} has no way out of the orbits around it")
            return False
        return True

    def group_plan(self):
        """D_n's group way out from the measured poses (:func:`~stressbots.control.group_escape.group_escape`), the
        gaps as in :meth:`escape_plan`; every other mover's orbit disc keeps ``Tuning.group_disc_clearance_um``."""
        L, tune = self.loop, self.loop.tune
        order = tuple(L.by_rank[r] for r in range(1, L.n + 1) if not L.docked[L.by_rank[r]])
        need = np.full(L.n, tune.wall_clearance_um)
        need[L.by_rank[L.n - 1]] = tune.g1_clearance_um
        g = Group(order, L.est, L.v_hat, L.r_hat, L.L, L.W, L.rstar, need)
        dk = np.flatnonzero(L.docked)
        return group_escape(g, L.scn.arena_um, edge_need=tune.wall_clearance_um, body_clearance=tune.escape_body_clearance_um,
                            edge_clearance=tune.wall_clearance_um, disc_clearance=tune.group_disc_clearance_um,
                            docked=(L.est[dk], L.L[dk], L.W[dk]), wait_steps=tune.group_escape_waits,
                            max_straight_um=tune.group_escape_straight_um)

    def escape_plan(self, N: int, others):
        """D_n's way out from the measured poses (:func:`~stressbots.control.escape_search.escape_manoeuvre`): gaps
        ``Tuning.g1_clearance_um`` from D_{n-1}'s orbit (``others[0]``), ``Tuning.wall_clearance_um`` from the rest,
        the arena edge and the docked bodies."""
        L, tune = self.loop, self.loop.tune
        o = list(others)
        need = np.array([tune.g1_clearance_um] + [tune.wall_clearance_um] * (len(o) - 1))
        orb = Orbiting(L.est[o], L.v_hat[o], L.r_hat[o], L.L[o], L.W[o], L.rstar[o], need)
        dk = np.flatnonzero(L.docked)
        return escape_manoeuvre(L.est[N], float(L.v_hat[N]), float(L.r_hat[N]), float(L.L[N]), float(L.W[N]), float(L.rstar[N]), orb,
                                L.scn.arena_um, edge_need=tune.wall_clearance_um, body_clearance=tune.escape_body_clearance_um,
                                edge_clearance=tune.wall_clearance_um, docked=(L.est[dk], L.L[dk], L.W[dk]),
                                turn_step_deg=tune.escape_search_step_deg, max_straight_um=tune.escape_search_straight_um,
                                lead_ins_um=(0.0, 0.25 * float(L.L[N]), 0.5 * float(L.L[N])))

    def meets_others(self, N: int, others, curvature: float, dt: float) -> bool:
        """Whether D_n, driving ``dt`` s at ``curvature`` (1/um; 0 straight) from its measured pose, would come
        within ``Tuning.g1_clearance_um`` of the body of one of ``others`` orbiting meanwhile (P_n and P_{n-1}
        turn them all): bodies compared at the same instants, not orbit discs."""
        from ..collision import penetration_depth
        from ..kinematics import move

        ts = np.linspace(0.0, dt, 12)
        mine = move(self.loop.est[N], self.loop.v_hat[N] * ts, curvature)
        for j in others:
            theirs = move(self.loop.est[j], self.loop.v_hat[j] * ts, 1.0 / float(self.loop.r_hat[j]))
            if (penetration_depth(mine, self.loop.L[N], self.loop.W[N], theirs, self.loop.L[j], self.loop.W[j])
                    > -self.loop.tune.g1_clearance_um).any():
                return True
        return False

    def escape_gaps(self, N: int, others) -> list[tuple[float, float]]:
        """``(gap_um, away_rad)`` of D_n's orbit from each of the orbits of ``others`` (the first D_{n-1},
        about its measured centre) and from the four arena edges (inf without an arena): the room it has
        (:func:`~stressbots.control.station.orbit_room`) and the heading that takes D_n's turning centre
        straight away from each."""
        p, r, rstar = self.loop.est[N], float(self.loop.r_hat[N]), float(self.loop.rstar[N])
        cs = turning_centres(self.loop.est[others], self.loop.r_hat[others])
        cs[0] = self.pair.centre(others[0])
        c = turning_centres(p, r)[0]
        # straight runs move D_n's turning centre with its body: away is from the other centre to D_n's
        out = [(float(orbit_room(p[None], r, rstar, None, o[None], [float(self.loop.rstar[j])])[0]),
                math.atan2(c[0] - o[0], c[1] - o[1])) for o, j in zip(cs, others, strict=True)]
        if self.loop.scn.arena_um is None:
            return out + [(math.inf, 0.0)] * 4
        w, h = self.loop.scn.arena_um
        # left, right, bottom, top edge; away = heading into the arena (clockwise from +y)
        return out + [(float(c[0]) - rstar, 0.5 * math.pi), (w - float(c[0]) - rstar, 1.5 * math.pi), (float(c[1]) - rstar, 0.0),
                      (h - float(c[1]) - rstar, math.pi)]

    def separate(self, N: int, M: int) -> None:
        """After a failed meeting: both turn a quarter of D_n's turn away (P_n), then drive straight apart
        (P_{n-2}) until D_n's orbit keeps ``Tuning.g1_clearance_um`` from D_{n-1}'s, at most
        ``Tuning.separate_frames`` t_x, and only while both keep room to orbit.

        Face to face, a clockwise quarter turn leaves them side by side heading opposite ways, so driving
        straight takes them apart. Without it D_n stayed inside D_{n-1}'s orbit disc: no path from there is
        clear, and every later pair frame failed at once.
        """
        n, tune = self.loop.n, self.loop.tune
        self.loop.drive([(n, 0.5 * math.pi / self.loop.omega_hat[N])])
        lower = self.loop.orbiting_below(n - 1)
        tr = self.pair.transfer
        for _ in range(tune.separate_frames):
            gap = orbit_room(self.loop.est[N][None], float(self.loop.r_hat[N]), float(self.loop.rstar[N]), None,
                             self.pair.centre(M)[None], [float(self.loop.rstar[M])])[0]
            if gap >= tune.g1_clearance_um:
                return
            tx = self.loop.tx
            if not (tr.keeps_room(N, self.loop.v_hat[N] * tx, lower) and tr.keeps_room(M, self.loop.v_hat[M] * tx, lower)):
                return
            self.loop.drive([(n - 2, self.loop.tx)])
