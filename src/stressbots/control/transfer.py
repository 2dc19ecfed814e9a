"""Stage 1 of G_1 (seed App. 3.3): D_{n-1} moves its orbit to its station in straight legs, D_n kept clear.

Under P_n and P_{n-1} D_{n-1} orbits in place; under P_{n-2} both D_{n-1} and D_n drive straight. Each leg:
D_{n-1} orbits until it heads along the leg, then drives straight; D_n turns with it for a chosen fraction
of the wait and runs straight (:meth:`StationTransfer.transfer_option`), or first drives to a clear track
timed to D_{n-1}'s departure (:meth:`StationTransfer.transfer_run`). D_n keeps room to orbit wherever a
straight frame leaves it (:meth:`StationTransfer.keeps_room`).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .. import paths as pathlib
from ..collision import arena_gap, bodies_hit_discs, penetration_depth
from ..kinematics import move
from ..robots import TWO_PI, angle_difference, turning_centres
from .leg_watch import LegProgress, leg_stop_s, pair_gaps
from .pairloop import Replan
from .queries import pose_on_orbit
from .station import Body, orbit_room, orbit_route

if TYPE_CHECKING:
    from .pair import PairPhase

__all__ = ["StationTransfer"]


def clear_tracks(arena_um, L: float, W: float, run_len: float, buf: float, c: float, lower_c, lower_r, now_disc, new_disc):
    """Candidate straight tracks for D_n during a leg of D_{n-1}: ``(starts (K, 3), samples (K, S, 3), ok (K,))``.

    Starts on a 150 um grid of the arena ``(w, h)``, 16 headings; each track ``run_len`` um long, sampled
    every 40 um. ``ok``: the body (``L`` x ``W``) keeps ``c`` from the arena edge and stays outside the discs
    ``(lower_c, lower_r)`` (radii with their clearance) all along; outside ``now_disc`` (D_{n-1}'s current
    orbit, ``(centre, radius)``) for the first ``buf`` um (driven while D_{n-1} still orbits); its end
    outside ``new_disc`` (D_{n-1}'s new orbit).

    >>> starts, samples, ok = clear_tracks((1000.0, 1000.0), 200.0, 50.0, 300.0, 100.0, 10.0, np.zeros((0, 2)), np.zeros(0),
    ...                                    (np.array([-5000.0, 0.0]), 10.0), (np.array([-5000.0, 0.0]), 10.0))
    >>> def at(x, y): return bool(ok[(starts[:, 0] == x) & (starts[:, 1] == y) & (starts[:, 2] == 0.0)][0])
    >>> at(525.0, 225.0), at(525.0, 825.0)   # heading +y: the second runs into the far edge
    (True, False)
    """
    w, h = arena_um
    xs, ys = np.arange(75.0, w, 150.0), np.arange(75.0, h, 150.0)
    heads = np.radians(np.arange(0.0, 360.0, 22.5))
    X, Y, T = np.meshgrid(xs, ys, heads, indexing="ij")
    starts = np.stack([X.ravel(), Y.ravel(), T.ravel()], axis=1)
    s = np.arange(0.0, run_len + 1e-9, 40.0)
    K = len(s)
    hv = np.stack([np.sin(starts[:, 2]), np.cos(starts[:, 2])], axis=1)
    samples = np.empty((len(starts), K, 3))
    samples[:, :, :2] = starts[:, None, :2] + s[None, :, None] * hv[:, None, :]
    samples[:, :, 2] = starts[:, None, 2]
    flat = samples.reshape(-1, 3)
    bad = arena_gap(flat, L, W, (w, h)).reshape(len(starts), K) < c
    if len(lower_r):
        bad |= bodies_hit_discs(flat, L, W, np.asarray(lower_c), np.asarray(lower_r)).any(axis=1).reshape(len(starts), K)
    ok = ~bad.any(axis=1)
    # buffer: clear of D_{n-1}'s current orbit; end: clear of its new one
    nb = int(np.searchsorted(s, buf)) + 1
    ok &= ~bodies_hit_discs(samples[:, :nb].reshape(-1, 3), L, W, np.asarray(now_disc[0])[None, :],
                            np.array([now_disc[1]])).reshape(len(starts), nb).any(axis=1)
    ok &= ~bodies_hit_discs(samples[:, -1], L, W, np.asarray(new_disc[0])[None, :], np.array([new_disc[1]]))[:, 0]
    return starts, samples, ok


class StationTransfer:
    """Stage 1 of G_1: D_{n-1} moves its orbit to the station orbit in straight legs, D_n kept clear."""

    def __init__(self, pair: PairPhase):
        self.pair = pair
        self.loop = pair.loop

    def _turn_together(self, N: int, M: int, t_turn: float, fraction: float) -> None:
        """D_{n-1} turns for ``t_turn`` s (its measured heading decides when it is done) while D_n turns
        ``fraction`` of that wait and then runs straight.

        D_n's turn is closed loop on its measured heading: a long open-loop turn with a turn rate not yet
        identified ends tens of degrees off, and the straight run after it goes astray."""
        n = self.loop.n
        turn = t_turn * self.loop.omega_hat[M]
        turned = 0.0
        n_turn, n_turned = fraction * t_turn * self.loop.omega_hat[N], 0.0
        while True:
            left = (turn - turned) / self.loop.omega_hat[M]
            if left <= 1e-3:
                break
            dt = left if left <= 1.6 * self.loop.tx else self.loop.tx
            a = min(dt, max((n_turn - n_turned) / self.loop.omega_hat[N], 0.0))
            if dt - a > 1e-9 and not self.keeps_room(N, (dt - a) * self.loop.v_hat[N], self.loop.orbiting_below(n - 1)):
                a = dt  # D_n would run out of room to orbit: it turns with D_{n-1} instead (same turn for D_{n-1})
            th0, thN0 = self.loop.est[M, 2], self.loop.est[N, 2]
            self.loop.drive([(n, a), (n - 1, dt - a)])
            n_turned += float(np.mod(self.loop.est[N, 2] - thN0 + 0.5, TWO_PI)) - 0.5
            turned += float(np.mod(self.loop.est[M, 2] - th0 + 0.5, TWO_PI)) - 0.5
            if dt == left:
                break

    def run(self, N: int, M: int, c_star: np.ndarray, D: float, lower) -> None:
        """Stage 1: move D_{n-1}'s orbit to ``c_star`` in straight legs, D_n kept clear (see :meth:`PairPhase.form`).

        Each leg: D_{n-1} orbits until it heads along the leg, then drives straight (P_{n-2}), which drives
        D_n straight too. D_n's track is either what it does anyway (it turns with D_{n-1} for a chosen
        fraction of the wait, then runs straight: :meth:`transfer_option`) or a track chosen for it
        (:meth:`transfer_run`), which D_n reaches first, timed to D_{n-1}'s departure. A leg too long for
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
        cl = self.loop.opts.clearance_um + 10.0  # transfer_option's check of D_{n-1}'s track
        cs = turning_centres(self.loop.est[lower], self.loop.r_hat[lower]) if lower else np.zeros((0, 2))
        rs = self.loop.rstar[lower] if lower else np.zeros(0)
        def routed(body: Body | None) -> list[np.ndarray] | None:
            return orbit_route(self.pair.centre(M), np.asarray(c_star, float), float(self.loop.rstar[M]), cs, rs, self.loop.scn.arena_um,
                               clearance=cl, spacing_um=self.loop.tune.station_grid_um, leg_cost_um=self.loop.tune.station_leg_cost_um,
                               body=body)

        route = routed(None)
        if route is None:
            # no capsule route: what D_{n-1}'s body sweeps passes gaps narrower than its orbit disc
            route = routed(Body(float(self.loop.r_hat[M]), float(self.loop.L[M]), float(self.loop.W[M]), float(self.loop.v_hat[M]),
                                math.radians(3.0)))  # th_dep's left bias in transfer_leg
        return route if route else [np.asarray(c_star, float)]

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
            kind, arg, leg, c_next = self.choose_leg(N, M, cM, u, d, t_turn, th_dep, lower, q_next, failed_runs)
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
                if not self.pair.meeting.arrive_timed(N, M, lambda arg=arg: arg, th_dep, lower):
                    # D_{n-1} still orbits where it was: choose again from where D_n is now
                    self.loop.log("retry", N, f"{self.loop.scn.names[N]} could not reach its track in time; the leg is planned again")
                    failed_runs += 1
                    # a second failure with nothing moved would repeat itself (same poses, same plan)
                    if failed_runs >= 4 or (failed_runs >= 2 and self.loop.t == t0):
                        raise Replan(f"{self.loop.scn.names[N]} cannot reach a clear track in time for {self.loop.scn.names[M]}'s move")
                    continue
                self.wait_straight(M, th_dep)
            self.straight_leg(N, M, c_next, lower)
        if final:
            miss = float(np.hypot(*(c_star - self.pair.centre(M))))
            self.loop.log("station", M, f"{self.loop.scn.names[M]} orbits {miss:.0f} um from its station")

    def choose_leg(self, N: int, M: int, cM, u, d: float, t_turn: float, th_dep: float, lower, q_next, failed_runs: int):
        """``(kind, arg, leg_um, c_next)`` of the next leg of D_{n-1}'s move ``d`` um along ``u`` from ``cM``: the
        longest of ``d``, 900, 600, 400, 250 um with a clear turn-together (``"turn"``, the fraction) or timed
        run (``"run"``, D_n's track start); else the shortest tight turn-together. Raises :class:`Replan`."""
        tight = None
        why = (f"{self.loop.scn.names[N]} has no clear straight track while {self.loop.scn.names[M]} moves {d:.0f} um to its "
               "station orbit")
        for leg in sorted({d, min(d, 900.0), min(d, 600.0), min(d, 400.0), min(d, 250.0)}, reverse=True):
            c_next = cM + leg * u
            if leg < d - 1.0 and not self.pair.orbits_free(M, c_next[None, :], [], lower, 10.0)[0]:
                continue
            try:
                opt = self.transfer_option(N, M, t_turn, leg, th_dep, lower, c_next, q_next)
            except Replan as exc:  # D_{n-1}'s own track is blocked this far: a shorter leg may clear
                why = exc.reason
                continue
            if opt is not None and (opt[1] < 1e4 or failed_runs):
                # after a timed run failed, a tight turn option too: keeps_room stops D_n where it can orbit
                return ("turn", opt[0], leg, c_next)
            start = self.transfer_run(N, M, leg, th_dep, lower, c_next, q_next)
            if start is not None:
                return ("run", start, leg, c_next)
            if opt is not None:  # clear, though it leaves D_n in a tight spot: the shortest such leg
                tight = ("turn", opt[0], leg, c_next)
        if tight is None:
            raise Replan(why)
        return tight

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

    def transfer_run(self, N: int, M: int, leg: float, th_dep: float, lower, c_next, q_next) -> np.ndarray | None:
        """A start pose for D_n's straight track during a leg of D_{n-1}, reachable in time; or None.

        Candidates: starts on a 150 um grid, 16 headings. A track is a timing buffer (1.2 s, driven while
        D_{n-1} still orbits: clear of its orbit) and then the leg (synchronous with D_{n-1}'s straight:
        bodies apart), all clear of the other orbits and the arena edge, ending clear of D_{n-1}'s new
        orbit. The cheapest to reach (plus a pull toward the next target) that a timed path reaches wins.
        """
        vN, vM = float(self.loop.v_hat[N]), float(self.loop.v_hat[M])
        c = self.loop.tune.wall_clearance_um + 5.0  # the timed path's checks use Tuning.wall_clearance_um: keep the track inside them
        buf = self.loop.tune.early_s * vN
        run_len = buf + leg * vN / vM * 1.15 + 40.0
        if self.loop.scn.arena_um is None:
            return None
        lower_c = turning_centres(self.loop.est[lower], self.loop.r_hat[lower]) if lower else np.zeros((0, 2))
        lower_r = np.array([float(x) + c for x in self.loop.rstar[lower]]) if lower else np.zeros(0)
        cM = self.pair.centre(M)
        starts, samples, ok = clear_tracks(self.loop.scn.arena_um, float(self.loop.L[N]), float(self.loop.W[N]), run_len, buf, c,
                                           lower_c, lower_r, (cM, float(self.loop.rstar[M]) + c),
                                           (np.asarray(c_next), float(self.loop.rstar[M]) + 40.0))
        # room for D_n to orbit (wait, or turn away) where its track ends
        end_c = turning_centres(samples[:, -1], self.loop.r_hat[N])
        ok &= self.pair.orbits_free(N, end_c, [(np.asarray(c_next),
                                                self.loop.rstar[M] + self.loop.tune.g1_clearance_um - self.loop.tune.wall_clearance_um)],
                               lower, self.loop.tune.wall_clearance_um)
        idx = np.flatnonzero(ok)
        if len(idx) == 0:
            return None
        # cheapest first (to reach, plus a pull toward the next target); then the synchronous check
        ends = samples[idx, -1]
        cost = pathlib.shortest_path_lengths(np.broadcast_to(self.loop.est[N], (len(idx), 3)), starts[idx],
                                             self.loop.r_hat[N]) + 0.5 * np.hypot(*(ends[:, :2] - np.asarray(q_next)[:2]).T)
        idx = idx[np.argsort(cost)]
        mdep = pose_on_orbit(cM, self.loop.r_hat[M], th_dep)
        tm = np.arange(0.0, leg / vM + 1.0, 0.4)
        m_track = move(mdep, vM * tm, 0.0)
        n_s = buf + vN * tm
        keep = []
        for j in idx:
            # D_n may be up to 0.6 s early or late on its track: bodies apart for all three timings
            n_track = move(starts[j], np.maximum(np.concatenate([n_s, n_s - 0.6 * vN, n_s + 0.6 * vN]), 0.0), 0.0)
            if not (penetration_depth(n_track, self.loop.L[N], self.loop.W[N], np.tile(m_track, (3, 1)), self.loop.L[M],
                                      self.loop.W[M]) > -c).any():
                keep.append(j)
                if len(keep) >= 12:
                    break
        if not keep:
            return None
        disc = [(cM, self.loop.rstar[M])]
        t_dep = float(np.mod(th_dep - self.loop.est[M, 2], TWO_PI)) / self.loop.omega_hat[M]
        period = TWO_PI / self.loop.omega_hat[M]
        arrivals = [a for a in (t_dep + k * period - self.loop.tune.early_s for k in range(3)) if a > 0.3]
        for j in keep:
            if self.pair.meeting.loiter_path(N, starts[j], arrivals, lower, disc, tol_s=0.5) is not None:
                return starts[j]
        return starts[keep[0]]  # no timed path from here: D_n will wait on a free orbit first

    def transfer_option(self, N: int, M: int, t_turn: float, d: float, th_dep: float, lower, c_star, q_next):
        """``(fraction, cost)``: of D_{n-1}'s turn, D_n turns with it for the fraction (then runs straight); or None.

        Every fraction whose motion keeps D_n clear of the orbits, the arena edge and D_{n-1} (its orbit
        while it turns, its body while both drive straight, its new orbit afterwards) is a candidate; the
        one leaving D_n the shortest path to its next target ``q_next`` wins; the cost adds 1e5 um when that
        path is blocked and 1e4 um when D_n has no room to wait on its orbit there.
        """
        vN, rN, vM = self.loop.v_hat[N], self.loop.r_hat[N], self.loop.v_hat[M]
        c = self.loop.opts.clearance_um + 10.0
        t_straight = d / vM + 1.0
        mdep = pose_on_orbit(self.pair.centre(M), self.loop.r_hat[M], th_dep)
        s_m = np.linspace(0.0, vM * t_straight, 60)
        m_track = move(mdep, s_m, 0.0)
        if self._blocked(m_track, M, lower, c):
            raise Replan(f"{self.loop.scn.names[M]}'s straight move to its station orbit is blocked")
        m_disc = [(self.pair.centre(M), self.loop.rstar[M] + c)]
        new_disc = [(np.asarray(c_star, float), self.loop.rstar[M] + 40.0)]
        best, best_len = None, math.inf
        for f in np.linspace(0.0, 1.0, 17):
            a = vN * f * t_turn
            b = vN * (1.0 - f) * t_turn
            arc = move(self.loop.est[N], np.linspace(0.0, a, max(2, int(a / 10.0) + 2)), 1.0 / rN)
            run = move(arc[-1], np.linspace(0.0, b, max(2, int(b / 10.0) + 2)), 0.0)
            if self._blocked(np.vstack([arc, run]), N, lower, c, discs=m_disc):
                continue
            # synchronous with D_{n-1}'s straight: same times, bodies apart; then clear of its new orbit
            n_track = move(run[-1], s_m * vN / vM * 1.15, 0.0)
            if self._blocked(n_track, N, lower, c):
                continue
            if (penetration_depth(n_track, self.loop.L[N], self.loop.W[N], m_track, self.loop.L[M], self.loop.W[M]) > -c).any():
                continue
            end = move(run[-1], vN * d / vM, 0.0)
            if self._blocked(end[None, :], N, lower, c, discs=new_disc):
                continue
            nxt = pathlib.shortest_path(end, np.asarray(q_next, float), rN, approach_um=60.0)
            ell = nxt.length
            # prefer a clear way on, and room to wait on D_n's own orbit there (its timing reserve)
            if self._blocked(nxt.sample(10.0), N, lower, 0.0, discs=new_disc):
                ell += 1e5
            # room to orbit where the run ends, also if it runs long (speed error, drift): a robot that
            # meets the arena edge while turning is trapped there
            late = move(end, self.loop.tune.track_overshoot * (b + vN * d / vM) + 40.0, 0.0)
            loops = np.vstack([move(e, np.linspace(0.0, TWO_PI * rN, 40), 1.0 / rN) for e in (end, late)])
            if self._blocked(loops, N, lower, self.loop.opts.clearance_um, discs=new_disc):
                ell += 1e4
            if ell < best_len:
                best, best_len = float(f), ell
        return None if best is None else (best, best_len)

    def _blocked(self, samples: np.ndarray, i: int, lower, clearance: float, discs=()) -> bool:
        """Like the loop's ``obstacles_hit``, but ``discs`` are kept clear of by their own radius, without ``clearance``."""
        return self.loop.obstacles_hit(samples, i, lower, extra_discs=[(c, r - clearance) for c, r in discs], clearance=clearance)

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
        return not self._blocked(track, N, lower, 0.0)
