"""Leg choice of G_1's station transfer (stage 1, seed App. 3.3): how D_n gets through one straight leg of D_{n-1}.

Before each leg of D_{n-1}'s move to its station orbit (:class:`~stressbots.control.transfer.StationTransfer`
drives it), :class:`LegChoice` picks the leg's length (the whole way, else 900, 600, 400, 250 um) and what
D_n does meanwhile, both checked on the measured poses: it turns with D_{n-1} for a fraction of the wait
and then runs straight (:meth:`LegChoice.transfer_option`), or it first drives to a clear straight track
(:func:`clear_tracks`) timed to D_{n-1}'s departure (:meth:`LegChoice.transfer_run`). Lengths in um,
times in s.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from .. import paths as pathlib
from ..collision import arena_gap, bodies_hit_discs, penetration_depth
from ..kinematics import move
from ..robots import TWO_PI, turning_centres
from .pairloop import Replan
from .queries import pose_on_orbit

if TYPE_CHECKING:
    from .pair import PairPhase

__all__ = ["LegChoice", "clear_tracks", "tracks_apart"]


def tracks_apart(track_a: np.ndarray, track_b: np.ndarray, gap_um: float) -> bool:
    """Whether two straight tracks (poses ``(S, 3)`` along each, um) keep their centre lines ``gap_um`` apart anywhere,
    whatever the timing: the segments from each track's first to its last pose.

    >>> a = np.array([[0.0, 0.0, 0.0], [0.0, 1000.0, 0.0]])            # along +y
    >>> b = np.array([[-500.0, 500.0, 1.5708], [500.0, 500.0, 1.5708]])  # along +x, across a
    >>> tracks_apart(a, b, 10.0), tracks_apart(a, b + [0.0, 600.0, 0.0], 10.0)
    (False, True)
    """
    from shapely.geometry import LineString

    la = LineString([tuple(track_a[0, :2]), tuple(track_a[-1, :2])])
    lb = LineString([tuple(track_b[0, :2]), tuple(track_b[-1, :2])])
    return bool(la.distance(lb) >= gap_um)


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


class LegChoice:
    """The next leg of D_{n-1}'s straight move to its station orbit, and D_n's motion during it (stage 1 of G_1)."""

    def __init__(self, pair: PairPhase):
        self.pair = pair
        self.loop = pair.loop

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

    def transfer_option(self, N: int, M: int, t_turn: float, d: float, th_dep: float, lower, c_star, q_next):
        """``(fraction, cost)``: of D_{n-1}'s turn, D_n turns with it for the fraction (then runs straight); or None.

        Every fraction whose motion keeps D_n clear of the orbits, the arena edge and D_{n-1} (its orbit
        while it turns, its body while both drive straight, with ``Tuning.transfer_tracks_apart`` the whole of its
        straight track whatever the timing: :func:`tracks_apart`; its new orbit afterwards) is a candidate; the
        one leaving D_n the shortest path to its next target ``q_next`` wins; the cost adds 1e5 um when that
        path is blocked and 1e4 um when D_n has no room to wait on its orbit there.
        """
        vN, rN, vM = self.loop.v_hat[N], self.loop.r_hat[N], self.loop.v_hat[M]
        c = self.loop.opts.clearance_um + 10.0
        t_straight = d / vM + 1.0
        mdep = pose_on_orbit(self.pair.centre(M), self.loop.r_hat[M], th_dep)
        s_m = np.linspace(0.0, vM * t_straight, 60)
        m_track = move(mdep, s_m, 0.0)
        own = move(mdep, np.linspace(0.0, d + vM * self.loop.tune.leg_overrun_s, 60), 0.0)
        if self.blocked(own, M, lower, c):
            raise Replan(f"{self.loop.scn.names[M]}'s straight move to its station orbit is blocked")
        m_disc = [(self.pair.centre(M), self.loop.rstar[M] + c)]
        new_disc = [(np.asarray(c_star, float), self.loop.rstar[M] + 40.0)]
        best, best_len = None, math.inf
        for f in np.linspace(0.0, 1.0, 17):
            a = vN * f * t_turn
            b = vN * (1.0 - f) * t_turn
            arc = move(self.loop.est[N], np.linspace(0.0, a, max(2, int(a / 10.0) + 2)), 1.0 / rN)
            run = move(arc[-1], np.linspace(0.0, b, max(2, int(b / 10.0) + 2)), 0.0)
            if self.blocked(np.vstack([arc, run]), N, lower, c, discs=m_disc):
                continue
            # synchronous with D_{n-1}'s straight: same times, bodies apart; then clear of its new orbit
            n_track = move(run[-1], s_m * vN / vM * 1.15, 0.0)
            if self.blocked(n_track, N, lower, c):
                continue
            if (penetration_depth(n_track, self.loop.L[N], self.loop.W[N], m_track, self.loop.L[M], self.loop.W[M]) > -c).any():
                continue
            # ... and (Tuning.transfer_tracks_apart) never across D_{n-1}'s track: timed to pass in front of it, the pair
            # met there under noise (D_n's heading error over a straight of a mm and more) and locked
            if self.loop.tune.transfer_tracks_apart and not tracks_apart(n_track, m_track,
                                                                         0.5 * float(self.loop.L[N] + self.loop.L[M]) + c):
                continue
            end = move(run[-1], vN * d / vM, 0.0)
            if self.blocked(end[None, :], N, lower, c, discs=new_disc):
                continue
            nxt = pathlib.shortest_path(end, np.asarray(q_next, float), rN, approach_um=60.0)
            ell = nxt.length
            # prefer a clear way on, and room to wait on D_n's own orbit there (its timing reserve)
            if self.blocked(nxt.sample(10.0), N, lower, 0.0, discs=new_disc):
                ell += 1e5
            # room to orbit where the run ends, also if it runs long (speed error, drift): a robot that
            # meets the arena edge while turning is trapped there
            late = move(end, self.loop.tune.track_overshoot * (b + vN * d / vM) + 40.0, 0.0)
            loops = np.vstack([move(e, np.linspace(0.0, TWO_PI * rN, 40), 1.0 / rN) for e in (end, late)])
            if self.blocked(loops, N, lower, self.loop.opts.clearance_um, discs=new_disc):
                ell += 1e4
            if ell < best_len:
                best, best_len = float(f), ell
        return None if best is None else (best, best_len)

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

    def blocked(self, samples: np.ndarray, i: int, lower, clearance: float, discs=()) -> bool:
        """Like the loop's ``obstacles_hit``, but ``discs`` are kept clear of by their own radius, without ``clearance``."""
        return self.loop.obstacles_hit(samples, i, lower, extra_discs=[(c, r - clearance) for c, r in discs], clearance=clearance)
