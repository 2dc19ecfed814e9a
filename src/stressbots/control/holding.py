"""D_n's holding orbit in G_1 (seed App. 3.3): where D_n waits when it has no timed way to its approach line.

From a free orbit near its target any arrival time is a wait away (P_n: D_n orbits in place), so when
:class:`~stressbots.control.rendezvous.Rendezvous` finds no timed path, or a round of pair frames failed,
:class:`HoldingOrbit` takes D_n there untimed: by a shortest path it drives and checks itself every t_x
(:meth:`HoldingOrbit.drive_to_hold`), else by the loop's gross motion along a roadmap route
(:meth:`HoldingOrbit.steer_to_hold`), else after an escape from the orbits hemming it in
(:mod:`~stressbots.control.pair_recovery`). Any pose on the holding orbit will do. Lengths in um, times in s.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .. import paths as pathlib
from ..collision import arena_gap
from ..robots import turning_centres
from .escapes import loop_poses
from .gross import SteerOutcome, arrived, path_steps
from .pair_geometry import tight_discs
from .station import orbit_room

if TYPE_CHECKING:
    from .pair import PairPhase

__all__ = ["HoldingOrbit"]


class HoldingOrbit:
    """D_n to a free orbit near its target (its holding orbit), checked clear at the G_1 clearances."""

    def __init__(self, pair: PairPhase):
        self.pair = pair
        self.loop = pair.loop

    def clearance_shortfall(self, N: int, lower, disc) -> float:
        """How much (um, >= 0) D_n's own orbit, as measured, falls short of the G_1 clearances from the other
        orbits: ``Tuning.wall_clearance_um`` from the lower robots', ``Tuning.g1_clearance_um`` from D_{n-1}'s
        (``disc``). Every path starts along that orbit or straight on, so checking paths from here at the
        full clearances finds none (D_n sat still while every frame was re-planned); they are checked against
        the orbits at the clearances less this shortfall (at most ``g1_clearance_um``). Never against the
        arena edge: an orbit moves on, the edge traps a one-way robot for good
        (:meth:`~stressbots.control.pair_recovery.PairRecovery.escape` leaves it)."""
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
        no free orbit has a clear way there, D_n first gets clear of D_{n-1}'s orbit
        (:meth:`~stressbots.control.pair_recovery.PairRecovery.escape`, once)."""
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
            return self.pair.recovery.escape(N, lower) and self.to_holding(N, q, lower, disc, escaped=False)
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
        return self.loop.steer(N, hold, self.loop.n, self.loop.n - 1, lower, extra_discs=disc, max_cycles=tune.hold_frames,
                               clearance=tune.g1_clearance_um) is not SteerOutcome.STUCK

    def drive_to_hold(self, N: int, hold, lower, disc, short: float) -> bool:
        """D_n drives its shortest path to ``hold``, re-planned every t_x while it stays clear
        (:meth:`hold_way_clear`); it stops where the way is no longer clear (the caller plans from there).
        False when D_n stalled (``Tuning.stall_count`` frames in a row under ``Tuning.stall_fraction`` of
        the commanded travel: blocked, failure region H). ``disc``: D_{n-1}'s orbit disc, with ``Tuning.fresh_pair_disc``
        as measured at each t_x."""
        n, vN, rN, tune = self.loop.n, self.loop.v_hat[N], self.loop.r_hat[N], self.loop.tune
        M = self.loop.by_rank[n - 1]
        stalls = 0
        hold_c = turning_centres(np.asarray(hold, float), rN)[0]
        for frame in range(tune.hold_frames):
            if tune.fresh_pair_disc and frame > 0:
                disc = self.pair.orbit_disc(M)
            # on the holding orbit counts once D_n has driven toward it: a D_n already there drives on to the hold
            # pose as before (that time is its wait)
            if arrived(self.loop.est[N], hold, tune) or (frame > 0 and self.on_hold_orbit(N, hold_c, lower, disc)):
                return True
            path = self.way_onto_orbit(N, hold, lambda smp, disc=disc: self.hold_way_clear(N, smp, lower, disc, short))
            if not self.hold_way_clear(N, path.sample(10.0), lower, disc, short):
                return True
            whole = path.length / vN <= tune.whole_leg_factor * self.loop.tx
            steps = path_steps(path, vN, n, n - 1, None if whole else self.loop.tx)
            if tune.hold_keeps_loop and self.loses_loop(N, path, vN * sum(d for _, d in steps), lower, disc):
                return True  # it stops while it can still loop: the caller plans from here
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

    def loses_loop(self, N: int, path: pathlib.Path, ahead_um: float, lower, disc) -> bool:
        """Whether D_n, whose clockwise loop from where it is keeps off D_{n-1}'s orbit ``disc``, the lower orbits, the
        structure and the arena edge, would lose that loop ``ahead_um`` along ``path`` (False when it has none now:
        nothing to lose). A hold drive that stopped where its way was no longer clear had left D_n's own orbit 144 um
        into D_{n-1}'s, their bodies 61 um apart, and no sequence of primitives got them apart again (held-out 38:3 at
        2x: G_1 gave up at 88 s)."""
        r = float(self.loop.r_hat[N])

        def loop_hits(pose) -> bool:
            return self.loop.obstacles_hit(loop_poses(pose, r), N, lower, extra_discs=disc, clearance=0.0)

        if loop_hits(self.loop.est[N]):
            return False
        return loop_hits(np.asarray(path.pose_at(min(ahead_um, path.length)), float))

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
