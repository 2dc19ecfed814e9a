"""Stage 1 of G_1 (seed App. 3.3): D_{n-1} moves its orbit to its station in straight legs, D_n kept clear.

Under P_n and P_{n-1} D_{n-1} orbits in place; under P_{n-2} both D_{n-1} and D_n drive straight. Each leg:
D_{n-1} orbits until it heads along the leg, then drives straight; D_n turns with it for a chosen fraction
of the wait and runs straight, or first drives to a clear track timed to D_{n-1}'s departure (which, and
how long the leg is: :class:`~stressbots.control.transfer_legs.LegChoice`). This module drives the legs and
watches every straight frame: D_n keeps room to orbit wherever a frame leaves it
(:meth:`StationTransfer.keeps_room`), the pair's bodies stay apart (:meth:`StationTransfer.bodies_meet`)
and so do their orbits at the leg's end (:meth:`StationTransfer.leg_end_clear`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..collision import penetration_depth
from ..kinematics import move
from ..robots import TWO_PI, angle_difference, turning_centres
from .leg_watch import LegProgress, leg_stop_s, pair_gaps
from .pair_geometry import pair_can_keep_apart
from .pairloop import Replan
from .rendezvous import Tending
from .station import Body, orbit_room, orbit_route
from .transfer_legs import LegChoice

if TYPE_CHECKING:
    from .pair import PairPhase

__all__ = ["StationTransfer"]


class StationTransfer:
    """Stage 1 of G_1: D_{n-1} moves its orbit to the station orbit in straight legs, D_n kept clear."""

    def __init__(self, pair: PairPhase):
        self.pair = pair
        self.loop = pair.loop
        self.legs = LegChoice(pair)

    def _turn_together(self, N: int, M: int, t_turn: float, fraction: float) -> None:
        """D_{n-1} turns for ``t_turn`` s (its measured heading decides when it is done) while D_n turns
        ``fraction`` of that wait and then runs straight.

        D_n's turn is closed loop on its measured heading: a long open-loop turn with a turn rate not yet
        identified ends tens of degrees off, and the straight run after it goes astray."""
        n = self.loop.n
        turn = t_turn * self.loop.omega_hat[M]
        turned = 0.0
        n_turn, n_turned = fraction * t_turn * self.loop.omega_hat[N], 0.0
        stalled = 0
        while True:
            left = (turn - turned) / self.loop.omega_hat[M]
            if left <= 1e-3:
                break
            dt = left if left <= 1.6 * self.loop.tx else self.loop.tx
            a = min(dt, max((n_turn - n_turned) / self.loop.omega_hat[N], 0.0))
            run, lower = (dt - a) * self.loop.v_hat[N], self.loop.orbiting_below(n - 1)
            # D_n would run out of room to orbit, or (already short of room) run into a lower orbit: it turns with D_{n-1}
            # instead (same turn for D_{n-1}); keeps_room lets a robot short of room go on only on a clear track, and
            # unchecked here D_n ran 176 um into a waiting robot's orbit and docked against its body (held-out 33:0 at 1x)
            if dt - a > 1e-9 and not (self.keeps_room(N, run, lower) and self.track_clear(N, run + 40.0, lower)):
                a = dt
            th0, thN0 = self.loop.est[M, 2], self.loop.est[N, 2]
            self.loop.drive([(n, a), (n - 1, dt - a)])
            n_turned += float(np.mod(self.loop.est[N, 2] - thN0 + 0.5, TWO_PI)) - 0.5
            step = float(np.mod(self.loop.est[M, 2] - th0 + 0.5, TWO_PI)) - 0.5
            turned += step
            if dt == left:
                break
            stalled = stalled + 1 if step < self.loop.tune.turn_stall_fraction * dt * self.loop.omega_hat[M] else 0
            if stalled >= self.loop.tune.turn_stall_frames:
                raise Replan(f"{self.loop.scn.names[M]} does not turn toward its transfer leg (held against something)")

    def run(self, N: int, M: int, c_star: np.ndarray, D: float, lower) -> None:
        """Stage 1: move D_{n-1}'s orbit to ``c_star`` in straight legs, D_n kept clear (see :meth:`PairPhase.form`).

        Each leg: D_{n-1} orbits until it heads along the leg, then drives straight (P_{n-2}), which drives
        D_n straight too. D_n's track is either what it does anyway (it turns with D_{n-1} for a chosen
        fraction of the wait, then runs straight: :meth:`LegChoice.transfer_option`) or a track chosen for it
        (:meth:`LegChoice.transfer_run`), which D_n reaches first, timed to D_{n-1}'s departure. A leg too long for
        any clear track is shortened (900, 600, 400 um) when D_{n-1} can orbit at its end.
        """
        q_next = self.pair.approach_pose(N, M, c_star, D)
        route = self.station_route(M, c_star, lower)
        for w in route[:-1]:
            self.loop.log("transfer", M, f"{self.loop.scn.names[M]}'s way to its station is blocked: it goes via an orbit at "
                                    f"({w[0]:.0f}, {w[1]:.0f}) um")
            self.transfer_leg(N, M, w, q_next, lower, final=False)
        self.transfer_leg(N, M, c_star, q_next, lower, final=True)

    def station_route(self, M: int, c_star: np.ndarray, lower) -> list[np.ndarray]:
        """Orbit centres D_{n-1} moves through to ``c_star`` (:func:`~stressbots.control.station.orbit_route`),
        clear of the lower orbits and the arena edge; ``[c_star]`` (one straight move) when there is no route."""
        cl = self.loop.opts.clearance_um + 10.0  # LegChoice.transfer_option's check of D_{n-1}'s track
        cs = turning_centres(self.loop.est[lower], self.loop.r_hat[lower]) if lower else np.zeros((0, 2))
        rs = self.loop.rstar[lower] if lower else np.zeros(0)
        def routed(body: Body | None, via_wall_um: float) -> list[np.ndarray] | None:
            return orbit_route(self.pair.centre(M), np.asarray(c_star, float), float(self.loop.rstar[M]), cs, rs, self.loop.scn.arena_um,
                               clearance=cl, spacing_um=self.loop.tune.station_grid_um, leg_cost_um=self.loop.tune.station_leg_cost_um,
                               body=body, via_wall_um=via_wall_um)

        # no capsule route: what D_{n-1}'s body sweeps passes gaps narrower than its orbit disc
        swept = Body(float(self.loop.r_hat[M]), float(self.loop.L[M]), float(self.loop.W[M]), float(self.loop.v_hat[M]),
                     math.radians(3.0))  # th_dep's left bias in transfer_leg
        for body in (None, swept):
            # via orbits well off the arena edge first; only where there are none, at the transfer clearance
            for via_wall_um in (self.loop.tune.station_via_wall_um, 0.0):
                route = routed(body, via_wall_um)
                if route:
                    return route
        return [np.asarray(c_star, float)]

    def transfer_leg(self, N: int, M: int, c_star: np.ndarray, q_next, lower, *, final: bool) -> None:
        """Move D_{n-1}'s orbit to ``c_star`` (one stage of :meth:`run`); an intermediate orbit of a
        route (``final`` False) counts as reached within ``Tuning.station_tol_um``."""
        failed_runs = 0
        for attempt in range(8):
            cM = self.pair.centre(M)
            d_vec = c_star - cM
            d = float(np.hypot(*d_vec))
            if d <= (self.loop.tune.via_tol_um if attempt == 0 or not final else self.loop.tune.station_tol_um):
                break
            u = d_vec / d
            th_dep = float(np.mod(math.atan2(u[0], u[1]) - math.radians(3.0), TWO_PI))
            t_turn = float(np.mod(th_dep - self.loop.est[M, 2], TWO_PI)) / self.loop.omega_hat[M]
            kind, arg, leg, c_next = self.legs.choose_leg(N, M, cM, u, d, t_turn, th_dep, lower, q_next, failed_runs)
            self.loop.replans += 1
            if kind == "turn":
                self.loop.log("transfer", M,
                         f"{self.loop.scn.names[M]} moves its orbit {leg:.0f} um; {self.loop.scn.names[N]} turns {arg:.0%} of the wait, "
                         "then runs "
                         "straight")
                self._turn_together(N, M, t_turn, arg)
            else:
                self.loop.log("transfer", M, f"{self.loop.scn.names[M]} moves its orbit {leg:.0f} um; {self.loop.scn.names[N]} first takes "
                                             "a clear track")
                t0 = self.loop.t
                moves0 = self.pair.meeting.tend_moves
                tend = Tending.STOP if self.loop.tune.tend_during_transfer else Tending.OFF
                if not self.pair.meeting.arrive_timed(N, M, lambda arg=arg: arg, th_dep, lower, tend=tend):
                    if self.pair.meeting.tend_moves > moves0:
                        # a waiting orbit was moved (D_{n-1} and D_n with it): the leg is planned from the new poses
                        continue
                    # D_{n-1} still orbits where it was: choose again from where D_n is now
                    self.loop.log("retry", N, f"{self.loop.scn.names[N]} could not reach its track in time; the leg is planned again")
                    failed_runs += 1
                    # a second failure with nothing moved would repeat itself (same poses, same plan)
                    if failed_runs >= 4 or (failed_runs >= 2 and self.loop.t == t0):
                        raise Replan(f"{self.loop.scn.names[N]} cannot reach a clear track in time for {self.loop.scn.names[M]}'s move")
                    continue
                self.wait_straight(M, th_dep)
            self.straight_leg(N, M, c_next, lower)
            # a leg that stopped short may leave D_(n-1)'s orbit over a waiting one (both then turn into each other):
            # that waiting orbit is moved off it, as drifted orbits are
            self.loop.park_orbits(self.loop.n, top=self.loop.n - 2, among=[M])
        if final:
            miss = float(np.hypot(*(c_star - self.pair.centre(M))))
            self.loop.log("station", M, f"{self.loop.scn.names[M]} orbits {miss:.0f} um from its station")

    def wait_straight(self, M: int, th_dep: float) -> None:
        """D_n straight (P_{n-1}) while D_{n-1} orbits on to heading ``th_dep``."""
        n = self.loop.n
        for _ in range(40):
            left = (float(np.mod(th_dep - self.loop.est[M, 2] + 0.1, TWO_PI)) - 0.1) / self.loop.omega_hat[M]
            if left <= 1e-3:
                return
            if left <= 1.6 * self.loop.tx:
                self.loop.drive([(n - 1, left)])
                return
            self.loop.drive([(n - 1, self.loop.tx)])

    def straight_leg(self, N: int, M: int, c_next, lower) -> None:
        """D_{n-1} straight (P_{n-2}) until its turning centre reaches ``c_next``; clockwise bearing fixes."""
        n, tune = self.loop.n, self.loop.tune
        progress = LegProgress(tune.leg_stall_frames, tune.leg_stall_fraction)
        for _ in range(200):
            c = self.pair.centre(M)
            to = c_next - c
            h = np.array([math.sin(self.loop.est[M, 2]), math.cos(self.loop.est[M, 2])])
            rem = float(to @ h)
            if rem <= 5.0:
                return
            if progress.update(rem, min(rem, self.loop.v_hat[M] * self.loop.tx)):
                self.loop.log("transfer", M, f"{self.loop.scn.names[M]}'s straight leg stalled {rem:.0f} um short; it moves on from there")
                return
            if self.bodies_meet(N, M, min(rem / self.loop.v_hat[M], self.loop.tx)):
                self.loop.log("transfer", M, f"{self.loop.scn.names[N]} and {self.loop.scn.names[M]} would touch; "
                                             f"{self.loop.scn.names[M]} stops {rem:.0f} um short and moves on from there")
                return
            stop = self.leg_end_clear(N, M, rem)
            if stop is not None and stop < 0.5 * self.loop.tx:
                self.loop.log("transfer", M, f"{self.loop.scn.names[N]} would end its leg inside {self.loop.scn.names[M]}'s orbit; "
                                             f"{self.loop.scn.names[M]} stops {rem:.0f} um short, both orbits apart")
                return
            bearing = float(angle_difference(math.atan2(to[0], to[1]), self.loop.est[M, 2]))
            steps = []
            if rem > 60.0 and math.radians(0.7) < bearing < math.radians(30.0):
                steps.append((n - 1, bearing / self.loop.omega_hat[M]))
            dt = rem / self.loop.v_hat[M]
            if dt > 1.6 * self.loop.tx:
                dt = self.loop.tx
            if stop is not None:
                dt = min(dt, stop)
            steps.append((n - 2, dt))
            run = sum(d for _, d in steps) * self.loop.v_hat[N]
            if self.would_wedge(N, M, steps):
                self.loop.log("transfer", M, f"after another t_x every primitive would bring {self.loop.scn.names[N]} and "
                                             f"{self.loop.scn.names[M]} together; {self.loop.scn.names[M]} stops {rem:.0f} um short "
                                             "and moves on from there")
                return
            if not self.track_clear(N, run + 40.0, lower) or not self.keeps_room(N, run, lower):
                self.loop.log("transfer", N, f"{self.loop.scn.names[N]}'s track runs out; {self.loop.scn.names[M]} stops short and moves "
                                             "on from there")
                return
            self.loop.drive(steps)

    def bodies_meet(self, N: int, M: int, dt: float) -> bool:
        """Whether D_n's and D_{n-1}'s bodies, both driving straight ``dt`` s from the measured poses, come within
        ``Tuning.escape_body_clearance_um`` (and closer than they are): the track was checked apart when planned,
        but a pair that meets pushes itself into a lock no escape leaves."""
        L = self.loop
        ts = np.linspace(0.0, dt, 8)
        a = move(L.est[N], L.v_hat[N] * ts, 0.0)
        b = move(L.est[M], L.v_hat[M] * ts, 0.0)
        depth = penetration_depth(a, L.L[N], L.W[N], b, L.L[M], L.W[M])
        return bool(depth.max() > max(-L.tune.escape_body_clearance_um, float(depth[0])))

    def would_wedge(self, N: int, M: int, steps) -> bool:
        """Whether driving ``steps`` (``(k, seconds)`` with k = n-1: D_n straight, D_{n-1} turning; n-2: both straight)
        takes the pair from poses where some primitive keeps their bodies apart for ``Tuning.wedge_horizon_s`` to
        poses where none does (:func:`~stressbots.control.pair_geometry.pair_can_keep_apart`, floor
        ``Tuning.escape_body_clearance_um``), predicted by exact kinematics from the measured poses. Only with
        ``Tuning.transfer_stops_before_wedge``."""
        L, tune = self.loop, self.loop.tune
        if not tune.transfer_stops_before_wedge:
            return False
        body_N, body_M = self.pair.body(N), self.pair.body(M)
        pN, pM = L.est[N].copy(), L.est[M].copy()

        def apart(a, b) -> bool:
            return pair_can_keep_apart(a, body_N, b, body_M, horizon_s=tune.wedge_horizon_s, floor_um=tune.escape_body_clearance_um)

        if not apart(pN, pM):
            return False  # wedged already: stopping here changes nothing (bodies_meet still stops a meeting)
        for k, d in steps:
            pN = move(pN, np.array([L.v_hat[N] * d]), 0.0)[-1]
            pM = move(pM, np.array([L.v_hat[M] * d]), 0.0 if k <= L.n - 2 else 1.0 / float(L.r_hat[M]))[-1]
        return not apart(pN, pM)

    def leg_end_clear(self, N: int, M: int, rem: float) -> float | None:
        """How long (s) the straight leg may still run so that D_n's orbit ends ``Tuning.g1_clearance_um`` clear of
        D_{n-1}'s (:func:`~stressbots.control.leg_watch.leg_stop_s`, both predicted straight from the measured poses
        to the leg's end, ``rem`` um of D_{n-1}'s travel); None: run on as planned."""
        L = self.loop
        hd = np.stack([np.sin(L.est[[N, M], 2]), np.cos(L.est[[N, M], 2])], axis=1)
        taus = np.linspace(0.0, rem / float(L.v_hat[M]), 24)
        gaps = pair_gaps(self.pair.centre(N), hd[0], float(L.v_hat[N]), float(L.rstar[N]), self.pair.centre(M), hd[1],
                         float(L.v_hat[M]), float(L.rstar[M]), taus)
        return leg_stop_s(gaps, taus, L.tune.g1_clearance_um)

    def keeps_room(self, N: int, run_um: float, lower) -> bool:
        """Whether robot ``N`` (D_n), driving ``run_um`` straight on from its measured pose, still has room to orbit
        (:func:`~stressbots.control.station.orbit_room`) clear of the arena edge and the lower orbits.

        The end is predicted ``Tuning.track_overshoot`` long (the speed error) and must keep
        ``Tuning.orbit_room_um``; a robot with less room than that already may go on only while its room
        grows; short of that room from a lower orbit already, it may go on (stopped overlapping an orbit, D_n
        found no turn that kept it clear of the body on it: tuning 74 at 2x, 19 at 1x). Checked before every
        straight frame of the transfer, it stops D_n (and D_{n-1} with it)
        where a one-way robot can still wait or turn away, whatever the planned track assumed: at 2x the
        literature's noise D_n's tracks ended against the arena edge, and it was trapped there for good.
        """
        tune = self.loop.tune
        ends = move(self.loop.est[N], np.array([0.0, run_um * (1.0 + tune.track_overshoot)]), 0.0)
        cs = turning_centres(self.loop.est[lower], self.loop.r_hat[lower]) if lower else np.zeros((0, 2))
        rs = self.loop.rstar[lower] if lower else np.zeros(0)
        r, rstar = float(self.loop.r_hat[N]), float(self.loop.rstar[N])
        now, end = orbit_room(ends, r, rstar, self.loop.scn.arena_um, np.zeros((0, 2)), np.zeros(0))
        if not (end >= tune.orbit_room_um or (now < tune.orbit_room_um and end > now)):
            return False
        # the lower orbits: a D_n short of room from one already goes on (its body track is checked clear by the
        # caller); stopped there, its orbit overlapping another, any turn may sweep it into that robot's body
        o_now, o_end = orbit_room(ends, r, rstar, None, cs, rs)
        return bool(o_end >= tune.orbit_room_um or o_now < tune.orbit_room_um)

    def track_clear(self, N: int, length: float, lower) -> bool:
        track = move(self.loop.est[N], np.linspace(0.0, max(length, 1.0), 30), 0.0)
        return not self.legs.blocked(track, N, lower, 0.0)
