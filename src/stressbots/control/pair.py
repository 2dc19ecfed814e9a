"""G_1 (seed App. 3.3) as an orbit rendezvous: the pair phase of the closed loop.

Under P_n and P_{n-1} D_{n-1} orbits in place (its pose is a function of time only) while D_n is a free
one-way car (P_n turns it, P_{n-1} drives it straight). Under P_{n-2} both drive straight. So:

1. *transfer* (:class:`StationTransfer`): D_{n-1} turns until it heads for its station orbit, then
   drives straight onto it (P_{n-2}); D_n turns with it for a chosen fraction of the turn, then runs
   straight on a track checked to be clear (or first drives to a chosen clear track, timed to D_{n-1}'s
   departure). D_{n-1}'s heading is corrected clockwise on the way (a left bias at departure makes every
   correction clockwise, so none costs a loop);
2. *rendezvous* (:class:`Rendezvous`): D_n drives to a pose on the tangent of D_{n-1}'s orbit that leads
   to D_{n-1}'s slot, timed to arrive a little before D_{n-1} passes the tangent point, and runs straight
   on; D_{n-1} leaves its orbit at the heading that best lines it up with D_n as measured (the departure
   is timed from D_{n-1}'s measured heading and identified turn rate);
3. both drive straight into each other: self-aligning compliance forms G_1.

No step needs an exact pose: D_n's arrival may be early or late by a second (its straight run absorbs
it), D_{n-1}'s station may be tens of um off (the rendezvous is computed from the measured orbit), and
the meeting tolerates |alpha| < 60 deg and |w_y| < 80 um. The pair may form a little away from its
nominal place: the later slots follow it (:meth:`PairPhase.retarget`). When a stage has no solution,
:meth:`PairPhase.form` re-plans toward another *pair frame* (the structure turned and shifted).

The phase drives the robots only through the closed loop it is handed (:class:`PairLoop`: the
controller's ``drive``, estimates, obstacle checks and gross motion); it keeps no plant of its own.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, Protocol

import numpy as np

from .. import paths as pathlib
from .. import se2
from ..collision import arena_gap, bodies_hit_discs, penetration_depth, point_rectangle_distance
from ..kinematics import move
from ..robots import TWO_PI, angle_difference, front_midpoints, turning_centres
from .gross import path_steps
from .loopview import DockingLoop
from .queries import best_departure, pose_on_orbit
from .station import orbit_room, orbit_route

__all__ = ["PairLoop", "PairPhase", "Rendezvous", "Replan", "StationTransfer", "approach_pose", "framed_goals", "frames_apart",
           "meet_distance", "station_centre", "tight_discs"]



class Replan(Exception):
    """A stage of G_1 has no solution from here: the pair's gross motion is planned again (not a failure yet)."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class PairLoop(DockingLoop, Protocol):
    """What the pair phase uses of the closed loop (:class:`~stressbots.control.loop.PlantLoop` and the controller)."""

    n: int
    rank: np.ndarray
    t: float
    replans: int
    nominal_goals: np.ndarray

    @property
    def rstar(self) -> np.ndarray: ...


def frames_apart(a, b) -> bool:
    """Whether pair frames ``a`` and ``b`` (``(phi_rad, dx_um, dy_um)``) differ by over 10 deg or 150 um
    (a frame near one already tried would fail the same way)."""
    return abs(angle_difference(a[0], b[0])) > math.radians(10.0) or math.hypot(a[1] - b[1], a[2] - b[2]) > 150.0


def meet_distance(rstar_M: float, r_M: float, L_N: float, W_N: float) -> float:
    """Centre distance (um) of D_n from D_{n-1}'s tangent point at departure: D_n clear of the orbit disc
    (radius ``rstar_M`` plus 30 um; D_{n-1}'s turning radius ``r_M``, D_n's body ``L_N`` x ``W_N``), plus 80 um."""
    rs = rstar_M + 30.0
    lateral = r_M - 0.5 * W_N
    return 0.5 * L_N + math.sqrt(max(rs * rs - lateral * lateral, 0.0)) + 80.0


def station_centre(goal_M: np.ndarray, D: float, L_M: float, L_N: float, v_M: float, v_N: float, r_M: float) -> np.ndarray:
    """Centre (um) of the orbit D_{n-1} leaves from so that, meeting D_n from ``D`` away, it ends in its slot
    ``goal_M``: the pair closes the gap at speeds ``v_M`` + ``v_N``, D_{n-1} covering its share from the
    tangent point (turning radius ``r_M``, clockwise orbit to the slot's right)."""
    g = goal_M
    th = float(g[2])
    h = np.array([math.sin(th), math.cos(th)])
    right = np.array([math.cos(th), -math.sin(th)])
    vM, vN = v_M, v_N
    s_M = max(D - 0.5 * (L_M + L_N), 0.0) * vM / (vM + vN)
    tangent = g[:2] - s_M * h
    return tangent + r_M * right


def approach_pose(centre: np.ndarray, th_dep: float, r_M: float, D: float, v_N: float, early: float) -> np.ndarray:
    """Where D_n aims: on the tangent of D_{n-1}'s orbit (about ``centre``, radius ``r_M``) at heading
    ``th_dep`` (rad, leading to D_{n-1}'s slot), facing it, ``D`` plus ``early`` seconds of driving at
    ``v_N`` (um/s) from the tangent point."""
    tangent = pose_on_orbit(centre, r_M, th_dep)
    h = np.array([math.sin(th_dep), math.cos(th_dep)])
    return np.array([*(tangent[:2] + (D + v_N * early) * h), np.mod(th_dep + math.pi, TWO_PI)])


def framed_goals(nominal_goals: np.ndarray, L: np.ndarray, N: int, M: int, phi: float, dx: float, dy: float) -> np.ndarray:
    """The slots ``nominal_goals`` (n, 3) turned clockwise by ``phi`` (rad) about the G_1 junction (midpoint of
    D_n's and D_{n-1}'s front edges) and shifted by ``(dx, dy)`` um: a *pair frame* (a rigid motion of the
    whole structure, so its shape is unchanged)."""
    g = nominal_goals
    junction = 0.5 * (front_midpoints(g[[N]], L[[N]])[0] + front_midpoints(g[[M]], L[[M]])[0])
    out = se2.rotate_about(g, junction, phi)
    out[:, :2] += np.array([dx, dy])
    return out


def tight_discs(disc, wall_clearance_um: float, clearance_um: float) -> list:
    """Discs ``(centre, radius)`` shrunk so that obstacle checks at ``wall_clearance_um`` keep ``clearance_um``
    from them."""
    return [(c, r - wall_clearance_um + clearance_um) for c, r in disc]


class PairPhase:
    """G_1 for a closed loop ``loop``: pair frames, station geometry, and the slots' retargeting once it formed.

    ``form()`` runs the phase; :attr:`transfer` (stage 1) and :attr:`meeting` (stages 2 and 3) hold the
    motion. Raises ``loop.abort(reason)`` when G_1 cannot form.
    """

    def __init__(self, loop: PairLoop):
        self.loop = loop
        self.transfer = StationTransfer(self)
        self.meeting = Rendezvous(self)

    def centre(self, i: int) -> np.ndarray:
        """Measured turning centre of robot ``i`` (with its identified radius)."""
        return turning_centres(self.loop.est[i], self.loop.r_hat[i])[0]

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
        tried: list[tuple[float, float, float]] = [(0.0, 0.0, 0.0)]
        last = ""
        for frame_no in range(self.loop.tune.pair_frames):
            if frame_no > 0:
                frames = [f for f in self.pair_frames(N, M, D, lower) if all(frames_apart(f, t) for t in tried)]
                if not frames:
                    break
                phi, dx, dy = frames[0]
                tried.append((phi, dx, dy))
                self.set_pair_frame(phi, dx, dy)
                self.loop.replans += 1
                self.loop.log("replan", N,
                         f"G_1 re-planned from the measured poses ({last}): the structure turned {math.degrees(phi):.0f} deg and shifted "
                         f"{math.hypot(dx, dy):.0f} um")
            try:
                c_star = self.station(N, M, D)
                self.transfer.run(N, M, c_star, D, lower)
                for attempt in range(self.loop.tune.rendezvous_attempts):
                    if self.meeting.rendezvous(N, M, D, lower):
                        return
                    self.loop.log("retry", N, f"rendezvous attempt {attempt + 1} missed; {self.loop.scn.names[N]} re-plans its approach")
                raise Replan(f"G_1 of {self.loop.scn.names[N]} and {self.loop.scn.names[M]} did not form in "
                             f"{self.loop.tune.rendezvous_attempts} "
                              "rendezvous attempts")
            except Replan as exc:
                last = exc.reason
        raise self.loop.abort(f"G_1 not formed after {len(tried)} pair frame(s); last: {last}")

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

    def clearance_shortfall(self, N: int, lower, disc) -> float:
        """How much (um, >= 0) D_n's own orbit, as measured, falls short of the G_1 clearances: of
        ``Tuning.wall_clearance_um`` from the arena edge and the lower orbits, of ``Tuning.g1_clearance_um``
        from D_{n-1}'s orbit ``disc``. Every path starts along that orbit or straight on, so checking paths
        from here at the full clearances finds none (D_n sat still while every frame was re-planned); they
        are checked at the clearances less this shortfall (never below zero)."""
        tune = self.loop.tune
        cs = turning_centres(self.loop.est[lower], self.loop.r_hat[lower]) if lower else np.zeros((0, 2))
        rs = self.loop.rstar[lower] if lower else np.zeros(0)
        r, rstar, arena = float(self.loop.r_hat[N]), float(self.loop.rstar[N]), self.loop.scn.arena_um
        walls = float(orbit_room(self.loop.est[N][None], r, rstar, arena, cs, rs)[0])
        dc = np.array([c for c, _ in disc]).reshape(-1, 2)
        near = float(orbit_room(self.loop.est[N][None], r, rstar, None, dc, [float(rr) for _, rr in disc])[0])
        short = max(tune.wall_clearance_um - walls, tune.g1_clearance_um - near, 0.0)
        return float(min(short, tune.g1_clearance_um))

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
        route = orbit_route(self.pair.centre(M), np.asarray(c_star, float), float(self.loop.rstar[M]), cs, rs, self.loop.scn.arena_um,
                            clearance=cl, spacing_um=self.loop.tune.station_grid_um, leg_cost_um=self.loop.tune.station_leg_cost_um)
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
            plan = tight = None
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
                    plan = ("turn", opt[0], leg, c_next)
                    break
                start = self.transfer_run(N, M, leg, th_dep, lower, c_next, q_next)
                if start is not None:
                    plan = ("run", start, leg, c_next)
                    break
                if opt is not None:  # clear, though it leaves D_n in a tight spot: the shortest such leg
                    tight = ("turn", opt[0], leg, c_next)
            plan = plan or tight
            if plan is None:
                raise Replan(why)
            kind, arg, leg, c_next = plan
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
        n = self.loop.n
        for _ in range(200):
            c = self.pair.centre(M)
            to = c_next - c
            h = np.array([math.sin(self.loop.est[M, 2]), math.cos(self.loop.est[M, 2])])
            rem = float(to @ h)
            if rem <= 5.0:
                return
            bearing = float(angle_difference(math.atan2(to[0], to[1]), self.loop.est[M, 2]))
            steps = []
            if rem > 60.0 and math.radians(0.7) < bearing < math.radians(30.0):
                steps.append((n - 1, bearing / self.loop.omega_hat[M]))
            dt = rem / self.loop.v_hat[M]
            if dt > 1.6 * self.loop.tx:
                dt = self.loop.tx
            steps.append((n - 2, dt))
            run = sum(d for _, d in steps) * self.loop.v_hat[N]
            if not self.track_clear(N, run + 40.0, lower) or not self.keeps_room(N, run, lower):
                self.loop.log("transfer", N, f"{self.loop.scn.names[N]}'s track runs out; {self.loop.scn.names[M]} stops short and moves "
                                             "on from there")
                return
            self.loop.drive(steps)

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
        w, h = self.loop.scn.arena_um
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
        bad = arena_gap(flat, self.loop.L[N], self.loop.W[N], (w, h)).reshape(len(starts), K) < c
        centres = [*turning_centres(self.loop.est[lower], self.loop.r_hat[lower])] if lower else []
        radii = [float(x) + c for x in self.loop.rstar[lower]] if lower else []
        if centres:
            bad |= bodies_hit_discs(flat, self.loop.L[N], self.loop.W[N], np.array(centres),
                                    np.array(radii)).any(axis=1).reshape(len(starts), K)
        ok = ~bad.any(axis=1)
        cM = self.pair.centre(M)
        # buffer: clear of D_{n-1}'s current orbit; end: clear of its new one
        nb = int(np.searchsorted(s, buf)) + 1
        ok &= ~bodies_hit_discs(samples[:, :nb].reshape(-1, 3), self.loop.L[N], self.loop.W[N], cM[None, :],
                                np.array([self.loop.rstar[M] + c])).reshape(len(starts), nb).any(axis=1)
        ok &= ~bodies_hit_discs(samples[:, -1], self.loop.L[N], self.loop.W[N], np.asarray(c_next)[None, :],
                                np.array([self.loop.rstar[M] + 40.0]))[:, 0]
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
        grows. Checked before every straight frame of the transfer, it stops D_n (and D_{n-1} with it)
        where a one-way robot can still wait or turn away, whatever the planned track assumed: at 2x the
        literature's noise D_n's tracks ended against the arena edge, and it was trapped there for good.
        """
        tune = self.loop.tune
        ends = move(self.loop.est[N], np.array([0.0, run_um * (1.0 + tune.track_overshoot)]), 0.0)
        cs = turning_centres(self.loop.est[lower], self.loop.r_hat[lower]) if lower else np.zeros((0, 2))
        rs = self.loop.rstar[lower] if lower else np.zeros(0)
        now, end = orbit_room(ends, float(self.loop.r_hat[N]), float(self.loop.rstar[N]), self.loop.scn.arena_um, cs, rs)
        return bool(end >= tune.orbit_room_um or (now < tune.orbit_room_um and end > now))

    def track_clear(self, N: int, length: float, lower) -> bool:
        track = move(self.loop.est[N], np.linspace(0.0, max(length, 1.0), 30), 0.0)
        return not self._blocked(track, N, lower, 0.0)


class Rendezvous:
    """Stages 2 and 3 of G_1: D_n arrives on D_{n-1}'s tangent in time, D_{n-1} departs, both meet."""

    def __init__(self, pair: PairPhase):
        self.pair = pair
        self.loop = pair.loop
        self._plan: tuple[Any, Any, float] | None = None

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
        vN, rN = self.loop.v_hat[N], self.loop.r_hat[N]
        q = np.asarray(target, float)
        hq = np.array([math.sin(q[2]), math.cos(q[2])])
        rq = np.array([math.cos(q[2]), -math.sin(q[2])])
        grid = np.meshgrid([0.0, -50.0, 50.0, -100.0, 100.0], [0.0, 20.0, -20.0, 40.0], np.radians([0.0, 3.0, -3.0, 6.0, -6.0]),
                           indexing="ij")
        s, e, d = (g.ravel() for g in grid)
        goals = np.stack([q[0] + s * hq[0] + e * rq[0], q[1] + s * hq[1] + e * rq[1], np.mod(q[2] + d, TWO_PI)], axis=1)
        offset = s / vN  # further along the line: arrive correspondingly later
        penalty = np.abs(s) / 100.0 + np.abs(e) / 40.0 + np.abs(d) / math.radians(6.0)
        period = TWO_PI * rN / vN
        # a straight of a um first, then a wait of tw s on the orbit: the shortest path's length jumps by a
        # loop as the wait passes its first turn, and the straights fill those gaps in arrival time
        pre = np.array([0.0, 100.0, 200.0, 350.0, 500.0])
        tw = np.arange(0.0, period, 0.05)
        A, Tw = np.meshgrid(pre, tw, indexing="ij")
        A, Tw = A.ravel(), Tw.ravel()
        waits = move(move(self.loop.est[N], A, 0.0), vN * Tw, 1.0 / rN)
        W, K = len(Tw), len(goals)
        ell = pathlib.shortest_path_lengths(np.repeat(waits, K, axis=0), np.tile(goals, (W, 1)), rN, approach_um=60.0).reshape(W, K)
        arr = (A / vN + Tw)[:, None] + ell / vN - offset[None, :]
        for want in arrivals:
            err = np.abs(arr - want)
            score = np.where(err <= tol_s, err + 0.1 * penalty[None, :] + 0.002 * A[:, None] / vN, np.inf).ravel()
            for flat in np.argsort(score)[:10]:
                if not np.isfinite(score[flat]):
                    break
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
        # Waiting on the orbit only shifts arrival times in steps (it eats into the path's first turn, then
        # costs a whole loop). One or two interpolated loops of radius R in [r, 1.6 r] (P_n / P_{n-1}
        # alternating) end where they began after 2 pi R / v: every arrival time in a window wider than
        # D_{n-1}'s period, continuously.
        ell0 = pathlib.shortest_path_lengths(np.broadcast_to(self.loop.est[N], goals.shape), goals, rN, approach_um=60.0)
        radii = np.linspace(rN, 1.6 * rN, 61)
        for want in arrivals:
            for m in (1, 2):
                arr = m * TWO_PI * radii[:, None] / vN + ell0[None, :] / vN - offset[None, :]
                err = np.abs(arr - want)
                score = np.where(err <= tol_s, err + 0.1 * penalty[None, :] + 0.01 * radii[:, None] / rN, np.inf).ravel()
                for flat in np.argsort(score)[:6]:
                    if not np.isfinite(score[flat]):
                        break
                    jr, kk = divmod(int(flat), K)
                    R = float(radii[jr])
                    loop = move(self.loop.est[N], np.linspace(0.0, TWO_PI * R, 72), 1.0 / R)
                    tail = pathlib.shortest_path(self.loop.est[N], goals[kk], rN, approach_um=60.0)
                    if self.loop.obstacles_hit(np.vstack([loop, tail.sample(10.0)]), N, lower, extra_discs=self._tight(disc),
                                          clearance=self.loop.tune.wall_clearance_um):
                        continue
                    return tail, goals[kk], float(offset[kk]), float(want), (R, m)
        return None

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
        if not self.arrive_timed(N, M, lambda: self.pair.approach_pose(N, M, self.pair.centre(M), D), th_dep, lower):
            raise Replan(f"{self.loop.scn.names[N]} found no timed path to its approach line")
        return self.depart_and_meet(N, M)

    def arrive_timed(self, N: int, M: int, target_fn, th_dep: float, lower, early: float | None = None) -> bool:
        """D_n drives to ``target_fn()`` (a pose on a line it then runs straight along), arriving ``early``
        seconds before D_{n-1}, orbiting, reaches heading ``th_dep``. Replanned every t_x; the last leg
        runs whole. False if no timed way exists even from a holding orbit.
        """
        early = self.loop.tune.early_s if early is None else early
        n = self.loop.n
        self._plan = None
        holds = 0
        prev = None
        for _ in range(600):
            vN = self.loop.v_hat[N]
            q = target_fn()
            disc = [(self.pair.centre(M), self.loop.rstar[M])]
            t_dep = float(np.mod(th_dep - self.loop.est[M, 2], TWO_PI)) / self.loop.omega_hat[M]
            period = TWO_PI / self.loop.omega_hat[M]
            arrivals = [a for a in (t_dep + k * period - early for k in range(4)) if a > 0.3]
            path = self.continued(N, arrivals, lower, disc)
            if path is None and prev is not None and prev.length - vN * self.loop.tx <= self.loop.tune.final_leg_s * vN:
                # the final seconds: a small error can make the replanned path a loop (one-way robot);
                # the rest of the plan, driven open loop, misses by a few um at most
                rest = pathlib.sub_path(prev, min(vN * self.loop.tx, prev.length), prev.length)
                self.loop.log("final", N, f"{self.loop.scn.names[N]} drives the last {rest.length:.0f} um of its plan open loop")
                self.loop.drive(path_steps(rest, vN, n, n - 1, None))
                return True
            loop = None
            for tol in (0.3, 0.7):
                if path is not None:
                    break
                found = self.loiter_path(N, q, arrivals, lower, disc, tol_s=tol)
                path = None if found is None else found[0]
                self._plan = None if found is None else (found[1], found[2], self.loop.t + found[3])
                loop = None if found is None else found[4]
            if loop is not None:
                R, m = loop
                self.loop.log("loop", N, f"{self.loop.scn.names[N]} circles {m} time(s) at radius {R:.0f} um to arrive on time")
                self.loop.replans += 1
                total = m * TWO_PI * R / vN
                while total > 1e-6:  # the loop, a t_x at a time (it ends where it began)
                    d = min(self.loop.tx, total)
                    self.loop.drive(self.loop.interpolated_steps(float(self.loop.r_hat[N] / R), d, n, n - 1))
                    total -= d
                prev = None
                continue
            prev = path
            if path is None:
                # no timed way from here: go where D_n can wait on its orbit near the target, then retry
                holds += 1
                if holds > 3 or not self.to_holding(N, q, lower, disc):
                    return False
                continue
            self.loop.replans += 1
            whole = path.length / vN <= 1.6 * self.loop.tx
            self.loop.drive(path_steps(path, vN, n, n - 1, None if whole else self.loop.tx))
            if whole:
                return True
        return False

    def to_holding(self, N: int, q, lower, disc, escaped: bool = True) -> bool:
        """Take D_n (untimed) onto a free orbit near ``q``, from which any arrival time is a wait away; when
        no free orbit has a clear way there, D_n first gets clear of D_{n-1}'s orbit (:meth:`escape`, once)."""
        n = self.loop.n
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
        short = self.pair.clearance_shortfall(N, lower, disc)
        tight = tight_discs(disc, tune.wall_clearance_um - short, tune.g1_clearance_um - short)
        hold, onward = None, False
        for j in np.argsort(cost)[:self.loop.tune.hold_candidates]:
            there = pathlib.shortest_path(self.loop.est[N], poses[j], rN)
            if self.loop.obstacles_hit(there.sample(10.0), N, lower, extra_discs=tight, clearance=tune.wall_clearance_um - short):
                continue
            on = not self.loop.obstacles_hit(pathlib.shortest_path(poses[j], q, rN, approach_um=60.0).sample(10.0), N, lower,
                                             extra_discs=self._tight(disc), clearance=tune.wall_clearance_um)
            if hold is None or (on and not onward):
                hold, onward = poses[j], on
            if onward:
                break
        if hold is None:
            self.loop.log("hold", N, f"{self.loop.scn.names[N]} has no clear way to a free orbit near its target")
            return escaped and self.escape(N, lower) and self.to_holding(N, q, lower, disc, escaped=False)
        self.loop.log("hold", N,
                 f"{self.loop.scn.names[N]} heads for a free orbit {np.hypot(*(hold[:2] - q[:2])):.0f} um from its target, to wait there")
        self.loop.steer(N, hold, n, n - 1, lower, extra_discs=disc, max_cycles=120, clearance=tune.g1_clearance_um - short, via=False)
        return not self.loop.stuck

    def depart_and_meet(self, N: int, M: int) -> bool:
        """D_n runs straight until D_{n-1} reaches the departure heading that best lines them up; both meet."""
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
        self.loop.log("depart", M, f"{self.loop.scn.names[M]} leaves its orbit toward {self.loop.scn.names[N]}")
        for _ in range(60):
            before = self.loop.est[[N, M]].copy()
            self.loop.drive([(n - 2, self.loop.tx)])
            moved = np.hypot(*(self.loop.est[[N, M], :2] - before[:, :2]).T)
            if (moved < 0.2 * self.loop.v[[N, M]] * self.loop.tx).all():
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
                self.separate(N, M)
                return False
        self.loop.log("miss", N, "the pair drove past each other; both turn away and the rendezvous is planned again")
        self.separate(N, M)
        return False

    def escape(self, N: int, lower) -> bool:
        """D_n gets its orbit ``Tuning.g1_clearance_um`` clear of D_{n-1}'s: it turns (P_n) until it heads
        within 60 deg of straight away from D_{n-1}'s turning centre, then runs straight (P_{n-1}, D_{n-1}
        orbiting in place) while it keeps room to orbit; at most ``Tuning.separate_frames`` t_x. True when clear.

        A D_n whose orbit overlaps D_{n-1}'s (after a failed meeting, or a hold path cut short) finds no
        clear path at any of G_1's clearances: every pair frame then failed at once, with nothing moved.
        """
        n, tune = self.loop.n, self.loop.tune
        M = self.loop.by_rank[n - 1]
        for _ in range(tune.separate_frames):
            p, cM = self.loop.est[N], self.pair.centre(M)
            gap = orbit_room(p[None], float(self.loop.r_hat[N]), float(self.loop.rstar[N]), None, cM[None], [float(self.loop.rstar[M])])[0]
            if gap >= tune.g1_clearance_um:
                return True
            away = math.atan2(p[0] - cM[0], p[1] - cM[1])
            turn = float(np.mod(away - math.radians(60.0) - p[2], TWO_PI))  # clockwise to the edge of the cone
            if turn > math.radians(120.0):  # heading within 60 deg of away: run straight out
                if not self.pair.transfer.keeps_room(N, self.loop.v_hat[N] * self.loop.tx, lower):
                    return False
                self.loop.drive([(n - 1, self.loop.tx)])
            else:
                self.loop.drive([(n, min(turn + math.radians(5.0), self.loop.omega_hat[N] * self.loop.tx) / self.loop.omega_hat[N])])
        return False

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

    def best_departure(self, N: int, M: int):
        """``(wait_s, cost)`` of D_{n-1}'s best departure toward D_n as measured (:func:`~stressbots.control.queries.best_departure`)."""
        return best_departure(
            self.loop.est[N], self.loop.v_hat[N], self.loop.L[N], self.pair.centre(M), self.loop.r_hat[M], self.loop.est[M, 2],
            self.loop.omega_hat[M],
            self.loop.v_hat[M], self.loop.L[M], self.loop.rstar[M], self.loop.tune.departure_cost_max,
        )
