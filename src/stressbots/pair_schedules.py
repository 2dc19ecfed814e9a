"""The piece scheme of the planner's G_1 (seed App. 2.1, generalised): D_{n-1}'s route cut into pieces.

During each piece D_{n-1} drives while D_n runs straight on a parking track or its final corridor;
between pieces D_n drives a path lasting whole orbit periods of D_{n-1} (:mod:`stressbots.timed_paths`),
so D_{n-1}, orbiting, is back where it stopped. One piece on the final corridor is the seed's two-stage
scheme. This module chooses the cuts, checks a schedule and applies it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from . import paths as pathlib
from .collision import penetration_depth, point_rectangle_distance
from .planner_state import pre_approach_pose
from .robots import TWO_PI, Pose, turning_centres
from .routing import Obstacles
from .timed_paths import TimedPaths


class PieceSchedules(TimedPaths):
    """G_1 schedules of the piece scheme: cut options, the schedule check and its application."""

    def _park_cuts(self, N: int, M: int, fullM: pathlib.Path, T: float, d_free: float, park, obst_low: Obstacles,
                   aM: float, wait0: float):
        """The cut options (:meth:`_cut_options`) for parking track ``park`` after a wait of ``wait0`` s.

        A track that starts at D_n's own start is where D_n passes D_{n-1}'s wait, driving straight
        (:meth:`_schedule_pair`), so its runs start ``v_n wait0`` um further on. Pieces cut to the whole
        track run off its end when the track ends at the arena edge (where it ends at D_{n-1}'s orbit
        they can still pass). The extended search first tries the pieces that fit in the part left.
        """
        cuts = self._cut_options(N, M, fullM, T, d_free, park, obst_low, aM)
        if not self.extended or park is None or wait0 <= 0 or not np.allclose(np.asarray(park[0]), self.tl.poses[N]):
            yield from cuts
            return
        ahead = self.v[N] * wait0
        h = np.array([math.sin(park[0][2]), math.cos(park[0][2]), 0.0])
        left = (np.asarray(park[0], float) + ahead * h, max(park[1] - ahead, 0.0))
        seen: set = set()
        for durs in self._cut_options(N, M, fullM, T, d_free, left, obst_low, aM):
            seen.add(durs)
            yield durs
        yield from (durs for durs in cuts if durs not in seen)

    def _pair_duration(self, schedule) -> float:
        """Duration (s) of a G_1 schedule: D_n's timed paths plus D_{n-1}'s pieces."""
        N, _, _, _, durs, _, a_paths = schedule
        return float(sum(p.length for p in a_paths) / self.v[N] + sum(durs))

    def _run_starts(self, N: int, durs: Sequence[float], park) -> list[np.ndarray]:
        """Start pose of D_n's straight run in every piece: the parking track, the final corridor last."""
        gN = self.goals[N]
        final = pre_approach_pose(gN, self.v[N] * durs[-1])
        if park is None:
            return [final] * len(durs)
        return [np.asarray(park[0], float)] * (len(durs) - 1) + [final]

    def _orbits_clear(self, centres: np.ndarray, M: int, obst_low: Obstacles) -> np.ndarray:
        """``(K,)`` bool: whether D_{n-1} (index ``M``) orbiting about each of ``centres`` keeps the
        clearance from the lower robots' orbit discs and from the arena edge."""
        clearance = self.opts.clearance_um
        rr = self.rstar[M] + clearance
        ok = np.ones(len(centres), dtype=bool)
        if len(obst_low.disc_radii):
            gap = np.hypot(centres[:, None, 0] - obst_low.disc_centres[None, :, 0], centres[:, None, 1] - obst_low.disc_centres[None, :, 1])
            ok &= (gap - obst_low.disc_radii[None, :] - self.rstar[M] >= clearance).all(axis=1)
        if self.scn.arena_um is not None:
            w, h = self.scn.arena_um
            ok &= (centres[:, 0] >= rr) & (centres[:, 0] <= w - rr) & (centres[:, 1] >= rr) & (centres[:, 1] <= h - rr)
        return ok

    def _cut_options(self, N: int, M: int, fullM: pathlib.Path, T: float, d_free: float, park, obst_low: Obstacles, aM: float):
        """Ways to cut D_{n-1}'s route (duration ``T`` s) into pieces for the G_1 schedule.

        The last piece is D_n's run into its slot, so it lasts at most ``d_free / v_n``; the earlier
        pieces are runs on the parking track ``park`` (``(pose, free length)``, or None for the final
        corridor, where they may not be longer than the last). D_{n-1} must be able to orbit at every
        cut. Cut points are chosen greedily from the end, each as early as the piece limit allows, among
        the positions where D_{n-1}'s orbit clears the lower orbits, the arena and D_n's run corridors.
        """
        opts = self.opts
        vN, vM, rM = self.v[N], self.v[M], self.r[M]
        t_last_max = d_free / vN
        if park is None and T <= t_last_max + 1e-9:
            yield (T,)
        total = fullM.length
        pos = np.arange(0.0, total, 10.0)
        centres = turning_centres(fullM.pose_at(pos), rM)
        rr = self.rstar[M] + opts.clearance_um
        ok = self._orbits_clear(centres, M, obst_low)
        gN = self.goals[N]
        seen = set()
        # On the final corridor D_n loops back to its right and reaches about r + L/2 past the end of
        # its run: earlier runs may stop short of the slot by that much (away from D_{n-1}'s last stops).
        short = (self.r[N] + 0.5 * self.L[N] + self.W[N] + opts.clearance_um) / vN
        if park is None:
            variants = [(f, 0.0) for f in (1.0, 0.8, 0.62, 0.48, 0.36)] + [(f, short) for f in (1.0, 0.8, 0.62, 0.48)]
        else:
            # runs that stop short of the track's end leave D_n room to loop back (the end is an obstacle)
            variants = [(f, 0.0) for f in (1.0, 0.7, 0.45, 0.3)] + ([(f, short) for f in (1.0, 0.7, 0.45)] if self.extended else [])
        for frac, margin in variants:
            tm = min(t_last_max * frac, T)
            if tm < aM / vM or tm >= T - 1e-9:
                continue
            if park is None:
                t_piece = tm - margin
                keep = [(pre_approach_pose(gN, 0.5 * vN * tm), vN * tm)]
            else:
                t_piece = park[1] / vN - margin
                keep = [(pre_approach_pose(gN, 0.5 * vN * tm), vN * tm), (pre_approach_pose(np.asarray(park[0]), -0.5 * park[1]), park[1])]
            if t_piece <= 0.2 * tm or (T - tm) / t_piece > opts.max_pieces:
                continue
            good = ok.copy()
            for centre_pose, length in keep:
                good &= point_rectangle_distance(centres, centre_pose, length + self.L[N], self.W[N])[0] >= rr
            good[0] = True  # D_{n-1}'s departure point: it orbits there anyway
            cuts = greedy_cuts(pos, good, total - vM * tm, vM * t_piece, opts.max_pieces)
            if not cuts:
                continue
            k_last = int(np.searchsorted(pos, cuts[0] - 1e-9))
            if k_last < pos.size and not good[k_last]:
                continue
            bounds = [0.0] + sorted(c for c in cuts if c > 1e-9) + [total]
            durs = tuple((b - a) / vM for a, b in zip(bounds[:-1], bounds[1:], strict=False))
            if len(durs) > opts.max_pieces:
                continue
            key = tuple(round(x, 6) for x in durs)
            if key not in seen:
                seen.add(key)
                yield durs

    def _schedule_pair(self, N: int, M: int, fullM: pathlib.Path, wait0: float, durs: Sequence[float], park,
                       lower: list[int]) -> str | None:
        """Plan D_n around D_{n-1}'s route cut into pieces of durations ``durs`` (s); None on success.

        During piece j D_{n-1} drives its piece (P_{n-1}/P_{n-2}) while D_n runs straight from
        ``run_starts[j]``; the last run ends in D_n's slot as D_{n-1} reaches its own. Between pieces D_n
        drives (P_n/P_{n-1}) from the end of one run to the start of the next on a path lasting a whole
        number of D_{n-1}'s orbit periods, so D_{n-1}, orbiting, is back where it stopped.
        """
        opts = self.opts
        vN, vM, rN = self.v[N], self.v[M], self.r[N]
        LN, WN, LM, WM = self.L[N], self.W[N], self.L[M], self.W[M]
        pieces = len(durs)
        straight_first = 0.0
        here = self.tl.poses[N]
        if park is not None and wait0 > 0 and np.allclose(np.asarray(park[0]), here):
            # Parked at its own start: D_n passes D_{n-1}'s wait for its departure driving straight along
            # its track (P_{n-1}: D_{n-1} orbits) instead of killing time on a loop.
            straight_first = vN * wait0
            if straight_first >= park[1] - 2.0 * rN:
                return f"{self.lab(N)}'s parking track is too short to wait {wait0:.1f} s on it"
            hN = np.array([math.sin(here[2]), math.cos(here[2]), 0.0])
            park = (np.asarray(park[0]) + straight_first * hN, park[1] - straight_first)
        starts = self._run_starts(N, durs, park)
        runs = [pathlib.Path(Pose(*s0), rN, (("S", vN * t),)) for s0, t in zip(starts, durs, strict=False)]
        whoN, whoM = self.lab(N), self.lab(M)
        obst_low = self.obstacles(lower, [])
        bounds_t = np.concatenate([[0.0], np.cumsum(durs)])
        cuts = [fullM.pose_at(vM * bounds_t[j]) for j in range(1, pieces)]
        # 1. Runs clear of the lower orbits and the arena.
        for j, run in enumerate(runs):
            hit = obst_low.first_hit(run.sample(opts.sample_um), LN, WN, opts.clearance_um)
            if hit is not None:
                return f"{whoN}'s straight run {j + 1} is blocked by {hit}"
        # 2. B phases: D_n's run against D_{n-1}'s piece, sampled in time (touching only at the very end).
        dt = opts.sample_um / max(vN, vM)
        for j in range(pieces):
            tp = durs[j]
            t = np.minimum(np.arange(0.0, tp + dt, dt), tp)
            pn = runs[j].pose_at(vN * t)
            pm = fullM.pose_at(np.minimum(vM * (bounds_t[j] + t), fullM.length))
            depth = penetration_depth(pn, LN, WN, pm, LM, WM)
            final = j == pieces - 1
            limit = np.where(final & (t > tp - (opts.approach_um + opts.clearance_um) / min(vN, vM)), 0.5, -opts.clearance_um)
            if (depth > limit).any():
                return f"{whoN}'s straight run meets {whoM} (piece {j + 1} of {pieces})"
        # 3. A phases: D_n's paths lasting a whole number of D_{n-1}'s periods; D_{n-1} orbits meanwhile.
        a_paths = self._a_paths(N, M, wait0, straight_first, starts, runs, cuts, obst_low)
        if isinstance(a_paths, str):
            return a_paths
        self._pair_schedule = (N, M, fullM, wait0, tuple(durs), runs, a_paths)
        return None

    def _a_paths(self, N: int, M: int, wait0: float, straight_first: float, starts: list[np.ndarray], runs: list[pathlib.Path],
                 cuts: list, obst_low: Obstacles) -> list[pathlib.Path] | str:
        """D_n's paths of a G_1 schedule's A phases, or why one is blocked: to its first run (lasting
        ``wait0`` plus whole periods of D_{n-1}, or driven straight ``straight_first`` um along its track),
        then from the end of each run to the start of the next (whole periods), while D_{n-1} orbits.
        """
        opts = self.opts
        vN, vM, rN, rM = self.v[N], self.v[M], self.r[N], self.r[M]
        LN, WN = self.L[N], self.W[N]
        TM = TWO_PI * rM / vM
        whoN, whoM = self.lab(N), self.lab(M)
        here = self.tl.poses[N]
        obst0 = obst_low.with_disc(turning_centres(self.tl.poses[M], rM)[0], self.rstar[M], f"the orbit of {whoM}")
        first: pathlib.Path | str
        if straight_first > 0.0:
            run = pathlib.Path(Pose(*here), rN, (("S", straight_first),))
            hit = obst0.first_hit(run.sample(opts.sample_um), LN, WN, opts.clearance_um)
            first = run if hit is None else f"blocked by {hit}"
        else:
            first = self._timed_path(self.tl.poses[N], starts[0], vN, rN, LN, WN, wait0, TM, obst0)
        if isinstance(first, str):
            return f"{whoN} cannot reach the start of its first run ({first})"
        a_paths = [first]
        for j, c in enumerate(cuts):
            disc_c = turning_centres(np.array(c), rM)[0]
            ob = obst_low.with_disc(disc_c, self.rstar[M], f"the orbit of {whoM} at its stop {j + 1}")
            end_j = np.array(runs[j].end)
            same_track = np.allclose(starts[j], starts[j + 1])
            link = self._timed_path(end_j, starts[j + 1], vN, rN, LN, WN, 0.0, TM, ob)
            if isinstance(link, str):
                what = "loop back to its run" if same_track else "move to its final corridor"
                return f"{whoN} cannot {what} ({link})"
            a_paths.append(link)
        return a_paths

    def _run_pieces(self, schedule: tuple) -> None:
        """Apply a G_1 schedule of the piece scheme (:meth:`_schedule_pair`) to the timeline."""
        N, M, fullM, wait0, durs, runs, a_paths = schedule
        n = self.n
        vM, vN = self.v[M], self.v[N]
        pieces = len(durs)
        bounds = np.concatenate([[0.0], np.cumsum(durs)]) * vM
        # A_0: D_n drives to the start of its first run (P_n / P_{n-1}); D_{n-1} orbits to its departure phase.
        t0 = self.tl.t
        self.tl.apply_path(N, a_paths[0], n, n - 1)
        self.tl.phase("pair-A", N, n, n - 1, t0, a_paths[0].end, partner=M, partner_end=tuple(float(v) for v in self.tl.poses[M]),
                      path=a_paths[0].segments, path_start=tuple(float(v) for v in a_paths[0].start))
        for j in range(pieces):
            # B_j: D_{n-1} drives its piece (P_{n-1} / P_{n-2}); D_n drives straight.
            piece = pathlib.sub_path(fullM, bounds[j], bounds[j + 1])
            before = self.tl.travel[N]
            t0 = self.tl.t
            self.tl.apply_path(M, piece, n - 1, n - 2)
            self.tl.phase(
                "pair-B", M, n - 1, n - 2, t0, piece.end, partner=N,
                run=(tuple(float(v) for v in runs[j].start), float(runs[j].length)), last=j + 1 == pieces, path=piece.segments,
                path_start=tuple(float(v) for v in piece.start),
            )
            self.tl.travel[N] = before + vN * durs[j]
            if j + 1 < pieces:
                t0 = self.tl.t
                self.tl.apply_path(N, a_paths[j + 1], n, n - 1)
                self.tl.phase("pair-A", N, n, n - 1, t0, a_paths[j + 1].end, partner=M,
                              partner_end=tuple(float(v) for v in self.tl.poses[M]), path=a_paths[j + 1].segments,
                              path_start=tuple(float(v) for v in a_paths[j + 1].start))
        self.route_lengths[M] = fullM.length
        self.route_lengths[N] = sum(p.length for p in a_paths) + vN * sum(durs)
        if pieces > 1:
            parked = not np.allclose(runs[0].start, runs[-1].start)
            self.notes.append(
                f"G_1: {self.lab(M)}'s route was cut into {pieces} pieces; {self.lab(N)} ran "
                f"{'on a parking track, then ' if parked else ''}a final corridor of {runs[-1].length:.0f} um "
                f"(the paper's two-stage scheme would need {vN * sum(durs):.0f} um)"
            )
        self.tl.dock(N, self.goals[N], self.lab(N))
        self.tl.dock(M, self.goals[M], self.lab(M))


def greedy_cuts(pos: np.ndarray, good: np.ndarray, first: float, piece_um: float, max_pieces: int) -> list[float]:
    """Cut positions (um) along D_{n-1}'s route, chosen greedily from the end: ``first``, then each as early
    as a piece of at most ``piece_um`` allows among the positions ``pos`` where ``good`` (D_{n-1} may orbit
    there), down to the start; [] when no position fits or more than ``max_pieces`` pieces would be needed.
    """
    cuts = [first]
    while cuts[-1] > 1e-9:
        lo = cuts[-1] - piece_um
        cand = np.flatnonzero(good & (pos >= lo - 1e-9) & (pos < cuts[-1] - 1e-9))
        if len(cand) == 0 or len(cuts) > max_pieces:
            return []
        cuts.append(float(pos[cand[0]]))
    return cuts
