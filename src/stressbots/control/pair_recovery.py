"""Recoveries of the G_1 pair phase: D_n gets its orbit clear of D_{n-1}'s and the others' (alone, or with
the robots hemming it in), and the pair separates after a failed meeting (seed App. 3.3: re-plan, never give
up while the time budget lasts). Each keeps D_n where a one-way robot can still orbit. Waiting on a holding
orbit when D_n has no timed way is :mod:`~stressbots.control.holding`, which falls back on :meth:`PairRecovery.escape`.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..collision import bodies_hit_discs, penetration_depth
from ..kinematics import move
from ..robots import TWO_PI, turning_centres
from .escape_search import Orbiting, escape_manoeuvre
from .group_escape import EscapeSequence, Group, group_escape_sequence
from .station import orbit_room

if TYPE_CHECKING:
    from .pair import PairPhase

__all__ = ["PairRecovery"]


class PairRecovery:
    """D_n's escape from D_{n-1}'s orbit (and the others'), and the pair's separation after a failed meeting."""

    def __init__(self, pair: PairPhase):
        self.pair = pair
        self.loop = pair.loop

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
                if self.meets_others(N, others, 1.0 / float(self.loop.r_hat[N]), dt) or self.enters_discs(N, lower, dt):
                    break  # turning here would sweep D_n into a robot orbiting beside it, or onto its orbit
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
        wait under P_n, then P_k drives D_(k+1) .. D_n straight), or by two such manoeuvres in turn
        (:func:`~stressbots.control.group_escape.group_escape_sequence`, with ``Tuning.group_escape_sequences``),
        searched again from the measured poses every t_x, at most ``Tuning.escape_search_frames`` t_x. True when D_n's
        orbit is clear. D_{n-1}'s station is planned again from wherever its orbit ends (every pair frame plans from
        the measured poses)."""
        tune, names = self.loop.tune, self.loop.scn.names
        said = False
        tight = False  # no way out with the body margin: one without it (bodies still kept apart) is taken
        rest: tuple[tuple[int, float], ...] = ()  # what is left of the sequence being driven
        for _ in range(tune.escape_search_frames):
            m = self.group_plan(tight)
            if m is None and not tight:
                tight = True
                m = self.group_plan(tight)
            if m is not None and m.total_s <= 1e-3:
                return True
            if m is not None:
                rest = m.steps
            elif not rest:
                break  # nothing from here, nothing begun
            # else: no way from the new measured poses (a plan without margin misses by the prediction error of a
            # t_x): the sequence already begun is driven on, as planned
            if not said:
                said = True
                margin = " (no body margin)" if tight else ""
                how = ", then ".join(self._step_words(N, k, d) for k, d in rest)
                self.loop.log("escape", N, f"{names[N]} has no searched turn-and-straight of its own; way out: {how}{margin}")
            k, d = rest[0]
            dt = d if d <= 1.6 * self.loop.tx else self.loop.tx
            self.loop.drive([(k, dt)])
            rest = ((k, d - dt), *rest[1:]) if d - dt > 1e-9 else rest[1:]
        else:  # the frames ran out while driving: clear by now?
            m = self.group_plan(tight)
            if m is not None and m.total_s <= 1e-3:
                return True
        self.loop.log("hold", N, f"{names[N]} has no way out of the orbits around it")
        return False

    def _step_words(self, N: int, k: int, d: float) -> str:
        """One step of a group way out in words: 'everyone orbits 1.0 s (P_8)', 'R7 straight alone 2.5 s (P_7)',
        'D_6 .. D_8 straight 0.6 s (P_5)'."""
        n = self.loop.n
        if k >= n:
            return f"everyone orbits {d:.1f} s (P_{k})"
        if k == n - 1:
            return f"{self.loop.scn.names[N]} straight alone {d:.1f} s (P_{k})"
        return f"D_{k + 1} .. D_{n} straight {d:.1f} s (P_{k})"

    def group_plan(self, tight: bool = False) -> EscapeSequence | None:
        """D_n's group way out from the measured poses as steps ``(k, seconds)`` of P_k: one group manoeuvre
        (:func:`~stressbots.control.group_escape.group_escape`), or with ``Tuning.group_escape_sequences`` the quickest
        of at most two (:func:`~stressbots.control.group_escape.group_escape_sequence`); the gaps as in
        :meth:`escape_plan`; every other mover's orbit disc keeps ``Tuning.group_disc_clearance_um``. D_n's body keeps
        ``Tuning.escape_body_clearance_um`` from the others, or ``Tuning.group_tight_body_um`` when ``tight``."""
        L, tune = self.loop, self.loop.tune
        order = tuple(L.by_rank[r] for r in range(1, L.n + 1) if not L.docked[L.by_rank[r]])
        need = np.full(L.n, tune.wall_clearance_um)
        need[L.by_rank[L.n - 1]] = tune.g1_clearance_um
        g = Group(order, L.est, L.v_hat, L.r_hat, L.L, L.W, L.rstar, need)
        dk = np.flatnonzero(L.docked)
        body = tune.group_tight_body_um if tight else tune.escape_body_clearance_um
        return group_escape_sequence(g, L.scn.arena_um, edge_need=tune.wall_clearance_um, body_clearance=body,
                                     edge_clearance=tune.wall_clearance_um, disc_clearance=tune.group_disc_clearance_um,
                                     docked=(L.est[dk], L.L[dk], L.W[dk]), wait_steps=tune.group_escape_waits,
                                     max_straight_um=tune.group_escape_straight_um, cut_um=tune.group_sequence_cut_um,
                                     two_step=tune.group_escape_sequences)

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

    def enters_discs(self, N: int, others, dt: float) -> bool:
        """Whether D_n, turning ``dt`` s in place (P_n) from its measured pose, would carry its body into the orbit
        disc (radius ``r*``) of one of ``others`` (the lower robots: D_{n-1} is the one it is to meet) that it is not
        in now. :meth:`meets_others` compares bodies at the same instants, so the turn itself is safe while the other
        body is elsewhere on its orbit; but D_n is then left where that body comes round, and every way out meets it
        (held-out 20:4: D_n's recovery turn at t = 2-5 s carried it into a lower robot's disc, and G_1 gave up at
        6 s). Only with ``Tuning.recovery_keeps_off_discs`` (off by default)."""
        if not self.loop.tune.recovery_keeps_off_discs:
            return False
        ts = np.linspace(0.0, dt, 12)
        mine = move(self.loop.est[N], self.loop.v_hat[N] * ts, 1.0 / float(self.loop.r_hat[N]))
        o = list(others)
        hits = bodies_hit_discs(mine, self.loop.L[N], self.loop.W[N], turning_centres(self.loop.est[o], self.loop.r_hat[o]),
                                self.loop.rstar[o])
        return bool((hits[1:] & ~hits[0]).any())

    def meets_others(self, N: int, others, curvature: float, dt: float) -> bool:
        """Whether D_n, driving ``dt`` s at ``curvature`` (1/um; 0 straight) from its measured pose, would come
        within ``Tuning.g1_clearance_um`` of the body of one of ``others`` orbiting meanwhile (P_n and P_{n-1}
        turn them all): bodies compared at the same instants, not orbit discs."""
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
