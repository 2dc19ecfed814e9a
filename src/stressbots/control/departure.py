"""Stage 3 of G_1 (seed App. 3.3): D_{n-1} departs its orbit toward D_n, and both drive straight into each other.

D_n has arrived on the tangent of D_{n-1}'s orbit (stage 2, :class:`~stressbots.control.rendezvous.Rendezvous`)
and runs straight on (P_{n-1}: D_{n-1} orbits in place). D_{n-1} leaves its orbit at the heading that best lines
it up with D_n as measured (:func:`~stressbots.control.queries.best_departure`, timed from its measured heading
and identified turn rate); then P_{n-2} drives both straight until they stop together, and self-aligning
compliance forms G_1 (:class:`Departure`). A miss, or a stop outside the self-alignment limits (failure
region H), separates the pair (:meth:`~stressbots.control.pair_recovery.PairRecovery.separate`) and the
rendezvous is planned again. Lengths in um, times in s.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ..robots import front_midpoints
from .queries import best_departure, meeting_cost

if TYPE_CHECKING:
    from .pair import PairPhase

__all__ = ["Departure"]


class Departure:
    """Stage 3 of G_1: D_{n-1} departs toward D_n as measured, both drive straight into each other and dock."""

    def __init__(self, pair: PairPhase):
        self.pair = pair
        self.loop = pair.loop

    def depart_and_meet(self, N: int, M: int) -> bool:
        """D_n runs straight until D_{n-1} reaches the departure heading that best lines them up; both meet."""
        if not self._await_departure(N, M):
            return False
        self.loop.log("depart", M, f"{self.loop.scn.names[M]} leaves its orbit toward {self.loop.scn.names[N]}")
        return self._drive_to_meet(N, M)

    def meet_as_they_are(self, N: int, M: int) -> bool:
        """Last resort of G_1 (every pair frame failed where the pair stands): when D_n and D_(n-1) face each other
        within the self-alignment limits (:func:`~stressbots.control.queries.meeting_cost` at most
        ``Tuning.last_meet_cost_max``), both drive straight into each other and G_1 forms where they meet (the
        later slots follow it, SPEC 6). A station-transfer leg that stopped the pair head to head, a few um apart,
        left neither robot a clear turn or straight: every pair frame failed at once and the run ended within
        25 s. True when G_1 formed."""
        L = self.loop
        cost = meeting_cost(L.est[N], float(L.v_hat[N]), float(L.L[N]), L.est[M], float(L.v_hat[M]), float(L.L[M]))
        if cost is None or cost > L.tune.last_meet_cost_max:
            return False
        L.log("depart", M, f"{L.scn.names[M]} and {L.scn.names[N]} face each other (cost {cost:.2f}): they meet where they are")
        return self._drive_to_meet(N, M)

    def _await_departure(self, N: int, M: int) -> bool:
        """D_n runs straight (P_{n-1}: D_{n-1} orbits on) until D_{n-1} reaches its best departure heading
        (:meth:`best_departure`, re-planned every t_x, at most 40 t_x). False when D_n is on no line D_{n-1}
        can leave along: D_n then turns a quarter away from the orbit (P_n)."""
        n = self.loop.n
        for _ in range(40):
            best = self.best_departure(N, M)
            if best is None:
                self.loop.log("miss", N, f"{self.loop.scn.names[N]} is not on a line {self.loop.scn.names[M]} can leave its orbit along")
                self.loop.drive([(n, 0.5 * math.pi / self.loop.omega_hat[N])])  # turn away from the orbit
                return False
            t_wait, cost = best
            if t_wait <= 1.6 * self.loop.tx:
                self.loop.drive([(n - 1, t_wait)])
                break
            self.loop.drive([(n - 1, self.loop.tx)])
        return True

    def _drive_to_meet(self, N: int, M: int) -> bool:
        """Both drive straight (P_{n-2}) into each other, at most 60 t_x, until they stop together
        (:meth:`_stopped_together`); False when they miss each other or one would lose room to orbit (then
        the rendezvous is planned again)."""
        n = self.loop.n
        closest = math.inf
        free = True
        lower = self.loop.orbiting_below(n - 1)
        for _ in range(60):
            ends = front_midpoints(self.loop.est[[N, M]], self.loop.L[[N, M]])
            gap_now = float(np.hypot(*(ends[0] - ends[1])))
            closest = min(closest, gap_now)
            tr = self.pair.transfer
            step = self.loop.v_hat[[N, M]] * self.loop.tx
            # only while both drive freely: in contact the fronts slide as compliance aligns them
            # fronts within meet_gap_um: about to touch, and compliance needs the push (stopped there at 5 um, the pair
            # orbited into a lock no escape left)
            touching = gap_now <= self.loop.tune.meet_gap_um
            if free and not touching and (gap_now > closest + self.loop.tune.meet_diverge_um
                                          or not (tr.keeps_room(N, float(step[0]), lower) and tr.keeps_room(M, float(step[1]), lower))):
                # past each other, or about to lose room to orbit (a one-way pair driven on ran into the arena
                # edges 3 mm apart at 2x noise, D_(n-1) trapped there): stop while both can still turn away
                self.loop.log("miss", N, f"{self.loop.scn.names[N]} and {self.loop.scn.names[M]} missed each other "
                                         f"(closest {closest:.0f} um); the rendezvous is planned again")
                return False
            before = self.loop.est[[N, M]].copy()
            self.loop.drive([(n - 2, self.loop.tx)])
            moved = np.hypot(*(self.loop.est[[N, M], :2] - before[:, :2]).T)
            free = bool((moved >= self.loop.tune.meet_free_fraction * self.loop.v[[N, M]] * self.loop.tx).all())
            if (moved < 0.2 * self.loop.v[[N, M]] * self.loop.tx).all():
                return self._stopped_together(N, M)
        self.loop.log("miss", N, "the pair drove past each other; both turn away and the rendezvous is planned again")
        self.pair.recovery.separate(N, M)
        return False

    def _stopped_together(self, N: int, M: int) -> bool:
        """The pair stopped moving (each under a fifth of its commanded travel in a t_x): fronts within
        ``Tuning.meet_gap_um`` form G_1 (a push of ``ControllerOptions.push_s``, both marked docked, the later
        slots retargeted); farther apart it is failure region H, and the pair separates (False)."""
        n = self.loop.n
        ends = front_midpoints(self.loop.est[[N, M]], self.loop.L[[N, M]])
        gap = float(np.hypot(*(ends[0] - ends[1])))
        if gap < self.loop.tune.meet_gap_um:
            self.loop.drive([(n - 2, self.loop.opts.push_s)])
            self.loop.docked[[N, M]] = True
            for _ in range(4):  # frames of the still pair: its pose estimate is their mean
                self.loop.drive([(n - 2, 0.5)])
            self.loop.log("G_1", N, f"formed with {self.loop.scn.names[M]} (front edges {gap:.1f} um apart)")
            self.pair.retarget(N, M)
            return True
        # outside the self-alignment limits (failure region H): both turn away, D_n approaches again
        self.loop.log("stuck", N, f"the pair stopped {gap:.0f} um apart (failure region H); both turn away and "
                                  f"{self.loop.scn.names[N]} approaches again")
        self.pair.recovery.separate(N, M)
        return False

    def best_departure(self, N: int, M: int):
        """``(wait_s, cost)`` of D_{n-1}'s best departure toward D_n as measured (:func:`~stressbots.control.queries.best_departure`)."""
        return best_departure(
            self.loop.est[N], self.loop.v_hat[N], self.loop.L[N], self.pair.centre(M), self.loop.r_hat[M], self.loop.est[M, 2],
            self.loop.omega_hat[M],
            self.loop.v_hat[M], self.loop.L[M], self.loop.rstar[M], self.loop.tune.departure_cost_max,
        )
