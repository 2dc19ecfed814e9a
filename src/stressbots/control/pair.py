"""G_1 (seed App. 3.3) as an orbit rendezvous: the pair phase of the closed loop.

Under P_n and P_{n-1} D_{n-1} orbits in place (its pose is a function of time only) while D_n is a free
one-way car (P_n turns it, P_{n-1} drives it straight). Under P_{n-2} both drive straight. So:

1. *transfer* (:class:`~stressbots.control.transfer.StationTransfer`): D_{n-1} turns until it heads for its station orbit, then
   drives straight onto it (P_{n-2}); D_n turns with it for a chosen fraction of the turn, then runs
   straight on a track checked to be clear (or first drives to a chosen clear track, timed to D_{n-1}'s
   departure). D_{n-1}'s heading is corrected clockwise on the way (a left bias at departure makes every
   correction clockwise, so none costs a loop);
2. *rendezvous* (:class:`~stressbots.control.rendezvous.Rendezvous`): D_n drives to a pose on the tangent of D_{n-1}'s orbit that leads
   to D_{n-1}'s slot, timed to arrive a little before D_{n-1} passes the tangent point, and runs straight
   on; D_{n-1} leaves its orbit at the heading that best lines it up with D_n as measured (the departure
   is timed from D_{n-1}'s measured heading and identified turn rate);
3. both drive straight into each other (:class:`~stressbots.control.departure.Departure`, which also times
   D_{n-1}'s departure): self-aligning compliance forms G_1.

No step needs an exact pose: D_n's arrival may be early or late by a second (its straight run absorbs
it), D_{n-1}'s station may be tens of um off (the rendezvous is computed from the measured orbit), and
the meeting tolerates |alpha| < 60 deg and |w_y| < 80 um. The pair may form a little away from its
nominal place: the later slots follow it (:meth:`PairPhase.retarget`). When a stage has no solution,
:meth:`PairPhase.form` re-plans toward another *pair frame* (the structure turned and shifted).

When D_n has no timed way, :mod:`~stressbots.control.holding` takes it to a free orbit to wait on; when its
orbit overlaps another or a meeting fails, :mod:`~stressbots.control.pair_recovery` gets it clear of D_{n-1}'s
orbit or separates the pair; then the stage is tried again. This module
holds the phase itself (:class:`PairPhase`); the pure geometry is in :mod:`~stressbots.control.pair_geometry`.

The phase drives the robots only through the closed loop it is handed (:class:`PairLoop`: the
controller's ``drive``, estimates, obstacle checks and gross motion); it keeps no plant of its own.
"""

from __future__ import annotations

import math

import numpy as np

from ..collision import arena_gap, bodies_hit_discs, point_rectangle_distance
from ..kinematics import move
from ..robots import TWO_PI, turning_centres
from .g1_failure import G1Stop, boxed_note, g1_failure, overlap_note, wedge_note
from .holding import HoldingOrbit
from .pair_geometry import (
    approach_pose,
    approach_room,
    body_gap_along,
    framed_goals,
    frames_apart,
    meet_distance,
    station_centre,
    tight_discs,
)
from .pair_recovery import PairRecovery
from .pairloop import PairLoop, Replan
from .queries import pose_on_orbit
from .rendezvous import Rendezvous
from .transfer import StationTransfer

__all__ = ["HoldingOrbit", "PairLoop", "PairPhase", "PairRecovery", "Rendezvous", "Replan", "StationTransfer", "approach_pose",
           "framed_goals", "frames_apart", "meet_distance", "station_centre", "tight_discs"]


class PairPhase:
    """G_1 for a closed loop ``loop``: pair frames, station geometry, and the slots' retargeting once it formed.

    ``form()`` runs the phase; :attr:`transfer` (stage 1) and :attr:`meeting` (stages 2 and 3) hold the
    motion, :attr:`holding` (D_n waiting on a free orbit) and :attr:`recovery` (escapes, separation) the
    fallbacks. Raises ``loop.abort(reason)`` when G_1 cannot form.
    """

    def __init__(self, loop: PairLoop):
        self.loop = loop
        self.transfer = StationTransfer(self)
        self.meeting = Rendezvous(self)
        self.holding = HoldingOrbit(self)
        self.recovery = PairRecovery(self)

    def centre(self, i: int) -> np.ndarray:
        """Measured turning centre of robot ``i`` (with its identified radius)."""
        return turning_centres(self.loop.est[i], self.loop.r_hat[i])[0]

    def orbit_disc(self, M: int) -> list[tuple[np.ndarray, float]]:
        """D_{n-1}'s (robot ``M``'s) orbit disc as measured now: ``[(centre, r*)]`` (um), its turning centre and swept
        radius with the identified radius (what D_n's paths keep clear of while G_1 forms)."""
        return [(self.centre(M), float(self.loop.rstar[M]))]

    def body_gap(self, N: int, M: int, steps) -> float:
        """The least gap (um; < 0: overlap) between D_n's and D_{n-1}'s (``M``'s) bodies along ``steps`` as predicted at
        the same instants (:func:`~stressbots.control.pair_geometry.body_gap_along`); inf with
        ``Tuning.loop_body_clearance_um`` off."""
        if self.loop.tune.loop_body_clearance_um <= 0.0:
            return math.inf
        return body_gap_along(self.loop.predicted_track(steps), N, M, self.loop.L, self.loop.W)

    def meet_distance(self, N: int, M: int) -> float:
        """D_n's centre distance from D_{n-1}'s tangent point at departure (:func:`meet_distance`)."""
        return meet_distance(self.loop.rstar[M], self.loop.r[M], self.loop.L[N], self.loop.W[N])

    def station(self, N: int, M: int, D: float) -> np.ndarray:
        """Centre of the orbit D_{n-1} leaves from so that, meeting D_n from ``D`` away, it ends in its slot
        (:func:`station_centre` with the current goals and the identified speeds and radius)."""
        return station_centre(self.loop.goals[M], D, self.loop.L[M], self.loop.L[N], self.loop.v_hat[M], self.loop.v_hat[N],
                              self.loop.r_hat[M])

    def form(self) -> None:
        """G_1 (App. 3.3), re-planned from the measured poses whenever a stage has no solution.

        The first attempt aims at the nominal G_1 slots. When the transfer has no clear way, D_n finds no
        timed path to its approach line, or the rendezvous keeps missing, the gross motion sigma_1 of
        the pair is planned again from where the robots are (seed App. 3.3: re-plan when D_{n-1} is early
        or late), toward another *pair frame*: the whole target structure turned and shifted as a rigid
        body (success is judged on the shape after a best rigid alignment, SPEC 6). Frames are tried
        nearest the nominal one first, and only those whose station orbit, approach line, departure
        track and later slots are clear of the orbits as measured (:meth:`pair_frames`).
        """
        n = self.loop.n
        N, M = self.loop.by_rank[n], self.loop.by_rank[n - 1]
        lower = self.loop.orbiting_below(n - 1)
        D = self.meet_distance(N, M)
        frames = 0
        last = ""
        first = self.room_frame(N, M, D, lower)
        if first != (0.0, 0.0, 0.0):
            self.set_pair_frame(*first)
            phi, dx, dy = first
            self.loop.log("replan", N, f"G_1 planned with room for the later robots' approaches: the structure turned "
                                       f"{math.degrees(phi):.0f} deg and shifted {math.hypot(dx, dy):.0f} um")
        stop, rounds = G1Stop.ROUNDS, 0
        for round_no in range(self.loop.tune.pair_rounds):
            if round_no > 0 and self.loop.tune.give_up_boxed_in and self.boxed_note(N):
                stop = G1Stop.BOXED
                break
            if round_no > 0 and not self.between_rounds(N, M, D, lower, last):
                stop = G1Stop.UNMOVED
                break
            most = self.loop.tune.pair_frames if round_no == 0 else self.loop.tune.round_frames
            done, tried, last = self.form_round(N, M, D, lower, last, most, first)
            frames, rounds = frames + tried, rounds + 1
            if done:
                return
            if tried < most:  # the round stopped early: D_n boxed in, or no frame left
                stop = G1Stop.BOXED if self.loop.tune.give_up_boxed_in and self.boxed_note(N) else G1Stop.NO_FRAMES
                break
        if self.meeting.departure.meet_as_they_are(N, M):
            return
        lp = self.loop
        wedged = wedge_note(lp.scn.names, N, M, (lp.est[N], self.body(N)), (lp.est[M], self.body(M)), lp.tune.escape_body_clearance_um)
        raise lp.abort(g1_failure(lp.scn.names[N], stop, frames, rounds, f"{wedged}{self.boxed_note(N)}{overlap_note(lp, N)}", last))

    def boxed_note(self, N: int) -> str:
        """D_n's note when it is boxed in against the arena edge (:func:`~stressbots.control.g1_failure.boxed_note`)."""
        return boxed_note(self.loop, N)

    def room_frame(self, N: int, M: int, D: float, lower) -> tuple[float, float, float]:
        """The pair frame G_1 first aims at: the nominal one, unless a later robot's approach has less than
        ``Tuning.approach_room_um`` of room in the arena there (:func:`~stressbots.control.pair_geometry.approach_room`);
        then the cheapest frame of :meth:`pair_frames` with that room, else the roomiest if it gains
        ``Tuning.approach_room_gain_um``. Only with ``Tuning.frame_for_approach_room``. Success is judged on the shape
        after a best rigid alignment (SPEC 6), and every later slot follows the pair wherever G_1 forms."""
        lp, tune = self.loop, self.loop.tune
        nominal = (0.0, 0.0, 0.0)
        later = [i for i in range(lp.n) if i not in (N, M) and not lp.docked[i]]
        if not tune.frame_for_approach_room or not later:
            return nominal

        def room(g) -> float:
            return approach_room(g, lp.r_hat, lp.rstar, lp.scn.arena_um, lp.opts.fine_distance_um, later, tune.approach_room_behind_radii)

        now = room(lp.goals)
        if now >= tune.approach_room_um:
            return nominal
        best = (now + tune.approach_room_gain_um, nominal)
        for f in self.pair_frames(N, M, D, lower):  # cheapest first
            r = room(self.framed_goals(*f))
            if r >= tune.approach_room_um:
                return f
            if r >= best[0]:
                best = (r, f)
        return best[1]

    def body(self, i: int) -> tuple[float, float, float, float]:
        """Robot ``i`` as the pair's body queries take it (:func:`pressed_together`,
        :func:`~stressbots.control.pair_geometry.pair_can_keep_apart`):
        ``(length_um, width_um, speed_um_s, radius_um)``, speed and radius as identified."""
        lp = self.loop
        return float(lp.L[i]), float(lp.W[i]), float(lp.v_hat[i]), float(lp.r_hat[i])

    def form_round(self, N: int, M: int, D: float, lower, last: str, frames_max: int,
                   first: tuple[float, float, float] = (0.0, 0.0, 0.0)) -> tuple[bool, int, str]:
        """One round of at most ``frames_max`` pair frames from where the robots are (:meth:`form`): ``(formed,
        frames tried, last reason)``; the first round starts in the frame ``first`` (:meth:`room_frame`)."""
        tried: list[tuple[float, float, float]] = [first] if not last else []
        for frame_no in range(frames_max):
            if (frame_no > 0 or last) and self.loop.tune.give_up_boxed_in and self.boxed_note(N):
                break  # nothing a re-plan does frees it (boxed_note): the pair phase gives up now
            if frame_no > 0 or last:
                # a re-plan costs the pair its timing anyway: the waiting orbits, untended while G_1 runs (one phase
                # took 500 s and two orbits drifted into each other), are moved off trouble first
                self.loop.park_orbits(self.loop.n, top=self.loop.n - 2)
                frames = [f for f in self.pair_frames(N, M, D, lower) if all(frames_apart(f, t) for t in tried)]
                if not frames:
                    break
                phi, dx, dy = frames[0]
                tried.append((phi, dx, dy))
                self.set_pair_frame(phi, dx, dy)
                self.loop.replans += 1
                self.loop.log("replan", N,
                              f"G_1 re-planned from the measured poses ({last}): the structure turned {math.degrees(phi):.0f} deg and "
                              f"shifted {math.hypot(dx, dy):.0f} um")
            try:
                c_star = self.station(N, M, D)
                self.transfer.run(N, M, c_star, D, lower)
                for attempt in range(self.loop.tune.rendezvous_attempts):
                    if self.meeting.rendezvous(N, M, D, lower):
                        return True, len(tried), last
                    self.loop.log("retry", N, f"rendezvous attempt {attempt + 1} missed; {self.loop.scn.names[N]} re-plans its approach")
                raise Replan(f"G_1 of {self.loop.scn.names[N]} and {self.loop.scn.names[M]} did not form in "
                             f"{self.loop.tune.rendezvous_attempts} rendezvous attempts")
            except Replan as exc:
                last = exc.reason
        return False, len(tried), last

    def between_rounds(self, N: int, M: int, D: float, lower, last: str) -> bool:
        """Before another round of pair frames: D_n waits on a free orbit near its approach (or first gets its
        orbit clear of the others), so that the next round plans from somewhere else. False (no new round) when
        D_n moved less than ``Tuning.round_moved_um``: the same poses would fail the same way."""
        before = self.loop.est[N, :2].copy()
        self.loop.log("hold", N, f"every pair frame failed ({last}); {self.loop.scn.names[N]} waits on a free orbit and G_1 "
                                 "is planned again")
        q = self.approach_pose(N, M, self.centre(M), D)
        disc = self.orbit_disc(M)
        if not self.holding.to_holding(N, q, lower, disc):
            self.recovery.escape(N, lower)
        return bool(np.hypot(*(self.loop.est[N, :2] - before)) >= self.loop.tune.round_moved_um)

    def set_pair_frame(self, phi: float, dx: float, dy: float) -> None:
        """Aim at the nominal structure turned clockwise by ``phi`` about the G_1 junction and shifted by (dx, dy)."""
        self.loop.goals = self.framed_goals(phi, dx, dy)

    def framed_goals(self, phi: float, dx: float, dy: float) -> np.ndarray:
        """The nominal slots in the pair frame ``(phi, dx, dy)`` (:func:`framed_goals`)."""
        N, M = self.loop.by_rank[self.loop.n], self.loop.by_rank[self.loop.n - 1]
        return framed_goals(self.loop.nominal_goals, self.loop.L, N, M, phi, dx, dy)

    def pair_frames(self, N: int, M: int, D: float, lower) -> list[tuple[float, float, float]]:
        """Candidate pair frames ``(phi_rad, dx_um, dy_um)`` that look feasible from the measured poses, best first.

        A frame passes when, with the structure there: every slot lies inside the arena and clear of the
        orbit of every robot that docks after it; D_{n-1}'s station orbit is clear of the lower orbits and
        the arena edge; D_n's approach run (from its approach pose to its slot) and D_{n-1}'s departure
        track (tangent point to slot) are clear of the lower orbits and the arena edge, with the steering
        clearance. Cost: turning angle (1 um per 0.1 deg) plus shift plus how far D_{n-1} must move.
        """
        saved = self.loop.goals.copy()
        out = []
        rank = self.loop.rank
        orbit_c = turning_centres(self.loop.est, self.loop.r_hat)
        rs = self.loop.rstar
        try:
            for phi_deg in self.loop.tune.frame_turns_deg:
                for dist in self.loop.tune.frame_shifts_um:
                    for ang in (np.arange(0.0, 360.0, 45.0) if dist > 0 else [0.0]):
                        dx, dy = dist * math.sin(math.radians(ang)), dist * math.cos(math.radians(ang))
                        phi = math.radians(phi_deg)
                        g = self.framed_goals(phi, dx, dy)
                        self.loop.goals = g
                        if not self._frame_ok(N, M, D, lower, g, orbit_c, rs, rank):
                            continue
                        c_star = self.station(N, M, D)
                        cost = 10.0 * abs(phi_deg) + dist + 0.3 * float(np.hypot(*(c_star - self.centre(M))))
                        out.append((cost, (phi, dx, dy)))
        finally:
            self.loop.goals = saved
        out.sort(key=lambda t: t[0])
        return [f for _, f in out]

    def _frame_ok(self, N, M, D, lower, g, orbit_c, rs, rank) -> bool:
        n = self.loop.n
        arena = self.loop.scn.arena_um
        if arena is not None and (arena_gap(g, self.loop.L, self.loop.W, arena) < self.loop.tune.frame_slot_clearance_um).any():
            return False
        for a in range(n):
            later = [b for b in range(n) if rank[b] < rank[a]]
            if later and bodies_hit_discs(g[a][None, :], self.loop.L[a], self.loop.W[a], orbit_c[later],
                                          rs[later] + self.loop.tune.frame_slot_clearance_um).any():
                return False
        c_star = self.station(N, M, D)
        if not self.orbits_free(M, c_star[None, :], [], lower, self.loop.tune.frame_slot_clearance_um)[0]:
            return False
        q = self.approach_pose(N, M, c_star, D)
        run = move(q, np.linspace(0.0, float(np.hypot(*(q[:2] - g[N, :2]))), 24), 0.0)
        if self.loop.obstacles_hit(run, N, lower, clearance=self.loop.tune.wall_clearance_um):
            return False
        tangent = pose_on_orbit(c_star, self.loop.r_hat[M], float(g[M, 2]))
        dep = move(tangent, np.linspace(0.0, float(np.hypot(*(tangent[:2] - g[M, :2]))), 16), 0.0)
        return not self.loop.obstacles_hit(dep, M, lower, clearance=self.loop.opts.clearance_um)

    def approach_pose(self, N: int, M: int, centre, D: float, early: float | None = None) -> np.ndarray:
        """Where D_n aims: on the tangent of D_{n-1}'s orbit (about ``centre``) leading to D_{n-1}'s slot,
        facing it, ``D`` plus ``early`` seconds (default ``Tuning.early_s``) of driving from the tangent point."""
        early = self.loop.tune.early_s if early is None else early
        return approach_pose(centre, float(self.loop.goals[M, 2]), self.loop.r_hat[M], D, self.loop.v_hat[N], early)

    def orbits_free(self, i: int, centres, discs, lower, clearance: float) -> np.ndarray:
        """Mask (K,): robot ``i`` could orbit about each of ``centres`` (K, 2) without meeting the arena edge,
        a lower robot's orbit, ``discs`` or a docked body (with ``clearance``)."""
        c = np.atleast_2d(np.asarray(centres, dtype=np.float64))
        rs = float(self.loop.rstar[i])
        ok = np.ones(len(c), dtype=bool)
        if self.loop.scn.arena_um is not None:
            w, h = self.loop.scn.arena_um
            ok &= (c[:, 0] >= rs + clearance) & (c[:, 0] <= w - rs - clearance)
            ok &= (c[:, 1] >= rs + clearance) & (c[:, 1] <= h - rs - clearance)
        others = [*zip(turning_centres(self.loop.est[lower], self.loop.r_hat[lower]), self.loop.rstar[lower], strict=True)] if lower else []
        for cc, rr in [*others, *discs]:
            ok &= np.hypot(*(c - cc).T) >= rs + float(rr) + clearance
        for j in np.flatnonzero(self.loop.docked):
            ok &= point_rectangle_distance(c, self.loop.est[j][None, :], self.loop.L[j], self.loop.W[j])[0] >= rs + clearance
        return ok

    def free_orbits(self, i: int, discs, lower, clearance: float = 15.0) -> np.ndarray:
        """Centres (K, 2) on a 100 um grid where robot ``i`` can orbit without meeting anything."""
        rs = float(self.loop.rstar[i])
        if self.loop.scn.arena_um is not None:
            lo, (w, h) = np.zeros(2), self.loop.scn.arena_um
        else:
            lo = self.loop.est[:, :2].min(axis=0) - 1500.0
            w, h = self.loop.est[:, :2].max(axis=0) - lo + 1500.0
        xs = lo[0] + np.arange(rs + clearance, w - rs - clearance + 1e-9, 100.0)
        ys = lo[1] + np.arange(rs + clearance, h - rs - clearance + 1e-9, 100.0)
        if len(xs) == 0 or len(ys) == 0:
            return np.zeros((0, 2))
        cx, cy = np.meshgrid(xs, ys)
        c = np.stack([cx.ravel(), cy.ravel()], axis=1)
        return c[self.orbits_free(i, c, discs, lower, clearance)]

    def retarget(self, N: int, M: int) -> None:
        """Move the remaining slots with the rigid motion the pair actually took (SPEC 6)."""
        g = self.loop.nominal_goals
        nom_axis = g[M, :2] - g[N, :2]
        meas_axis = self.loop.est[M, :2] - self.loop.est[N, :2]
        phi = math.atan2(meas_axis[0], meas_axis[1]) - math.atan2(nom_axis[0], nom_axis[1])  # clockwise angle
        c_nom = 0.5 * (g[M, :2] + g[N, :2])
        c_meas = 0.5 * (self.loop.est[M, :2] + self.loop.est[N, :2])
        cph, sph = math.cos(phi), math.sin(phi)
        self.loop.motion = (phi, c_nom, c_meas)
        rest = [i for i in range(self.loop.n) if not self.loop.docked[i]]
        for i in rest:
            d = g[i, :2] - c_nom
            # clockwise rotation by phi (theta is clockwise from +y)
            rot = np.array([d[0] * cph + d[1] * sph, -d[0] * sph + d[1] * cph])
            self.loop.goals[i, :2] = c_meas + rot
            self.loop.goals[i, 2] = np.mod(g[i, 2] + phi, TWO_PI)
        self.loop.goals[N] = self.loop.est[N]
        self.loop.goals[M] = self.loop.est[M]
        if abs(math.degrees(phi)) > 0.5 or np.hypot(*(c_meas - c_nom)) > 5.0:
            self.loop.log("retarget", None,
                     f"G_1 formed {np.hypot(*(c_meas - c_nom)):.1f} um / {math.degrees(phi):.1f} deg from nominal; later slots follow it")
