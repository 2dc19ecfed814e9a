"""The simulated plant: the Plant protocol over the bodies, the noise streams and one Drive at a time.

See :mod:`stressbots.sim` for the model. This module holds :class:`SimulatedPlant`: it draws the
per-run and per-Drive noise, decodes waveforms into Drives (:func:`stressbots.waveform.replay`), advances
the bodies between contacts (:mod:`.search`), applies the contact rules at every contact
(:mod:`.contact`) and answers the camera.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Sequence

import numpy as np

from ..drift import DEFAULT_DRIFT, DriftModel, HeadingDrift
from ..kinematics import wrap
from ..waveform import Segment, replay
from .bodies import NEAR_UM, RECHECK_S, Bodies, SimEvent
from .contact import ContactRules
from .search import FREE, HELD, DriveRates, Motion, first_contact, poses_at

SEGMENT_JITTER = 0.2
"""Per-Drive variation of speed and radius, as a fraction of the per-run sds."""

MIN_FACTOR = 0.1
"""Floor of every speed and radius factor (a robot never stops or turns on the spot by noise)."""

STALL_EVALUATIONS = 50
"""Contact instants in a row without progress after which the robots touching are frozen (stuck)
rather than evaluated again: a safeguard against rules that undo each other."""


class SimulatedPlant:
    """A simulated group of MicroStressBots behind the :class:`~stressbots.control.Plant` protocol.

    Parameters
    ----------
    scenario : stressbots.scenario.Scenario
        Robots (bodies, speeds, radii, thresholds, start poses), arena and ``[noise]``.
    seed : int, optional
        Seed of every random draw (recorded as :attr:`seed`). ``None`` draws fresh entropy.
    poses : array_like (n, 3), optional
        Start poses (um, rad) instead of the scenario's, e.g. for constructed contacts.
    record : bool
        Keep a sampled trajectory (:meth:`trace`) for pictures; off by default (it costs time).
    log_drives : bool
        Keep the true poses at the end of every Drive and the arm states it ran with
        (:meth:`drive_log`), for analyses of moments inside a waveform (:mod:`stressbots.coverage`). Cheap;
        it changes nothing of the motion.
    drift : stressbots.drift.DriftModel, optional
        Knot spacing and bias/walk split of the heading drift (default
        :data:`stressbots.drift.DEFAULT_DRIFT`); its size is the scenario's ``heading_drift_deg_per_mm``.

    Notes
    -----
    Only :meth:`observe` and :meth:`apply` form the protocol. :meth:`true_poses`, :attr:`events`,
    :attr:`docked`, :attr:`stuck`, :attr:`time_s` and :meth:`copy` are for reports and tests; a controller
    must not use them (hardware has no such thing). See :mod:`stressbots.sim` for the model.
    """

    def __init__(
        self, scenario, seed: int | None = None, *, poses=None, record: bool = False, drift: DriftModel | None = None,
        log_drives: bool = False,
    ):
        self.scenario = scenario
        n = scenario.n
        ss = np.random.SeedSequence(seed)
        self.seed = int(ss.entropy)  # type: ignore[arg-type]
        run_ss, motion_ss, camera_ss, drift_ss = ss.spawn(4)
        z = np.random.default_rng(run_ss).standard_normal((2, n))
        nz = scenario.noise
        self._drift = HeadingDrift(n, nz.heading_drift_rad_per_um, drift_ss, DEFAULT_DRIFT if drift is None else drift)
        self._speed_factor = np.maximum(1.0 + nz.speed_rel_sd * z[0], MIN_FACTOR)
        self._radius_factor = np.maximum(1.0 + nz.turn_radius_rel_sd * z[1], MIN_FACTOR)
        self._motion_rng = np.random.default_rng(motion_ss)
        self._camera_rng = np.random.default_rng(camera_ss)
        self._v = scenario.speeds_um_s
        self._r = scenario.turn_radii_um
        p = scenario.starts if poses is None else np.asarray(poses, dtype=np.float64).reshape(n, 3)
        self._bodies = Bodies(scenario, p)
        self._rules = ContactRules(self._bodies, self._drift)
        self._arms = np.zeros(n, dtype=np.uint8)
        self._t = 0.0
        self._record = bool(record)
        self._trace_t: list[np.ndarray] = [np.zeros(1)]
        self._trace_p: list[np.ndarray] = [self._bodies.pose[None].copy()]
        self._drive_log: list[tuple[float, np.ndarray, np.ndarray]] | None = [] if log_drives else None

    # -- the Plant protocol ------------------------------------------------------------------------

    def observe(self) -> np.ndarray:
        """One camera frame ``(n, 3)``: true poses plus camera noise; NaN rows for dropped robots."""
        nz = self.scenario.noise
        n = self.n
        drop = self._camera_rng.random(n) < nz.camera_dropout
        e = self._camera_rng.standard_normal((n, 3))
        obs = self._bodies.pose.copy()
        obs[:, :2] += nz.camera_position_sd_um * e[:, :2]
        obs[:, 2] = wrap(obs[:, 2] + nz.camera_heading_sd_rad * e[:, 2])
        obs[drop] = np.nan
        return obs

    def apply(self, waveform: Sequence[Segment]) -> None:
        """Play a waveform: decode the arm states, then move the robots through every Drive."""
        segs = tuple(waveform)
        dec = replay(segs, self.scenario.snap_down_V, self.scenario.release_V, initial=self._arms)
        t0 = self._t
        for d in dec.drives:
            t_start = t0 + d.t_start_s
            for i in np.flatnonzero(d.flipped):
                self._bodies.log(t_start, int(i), "arm_flip", None, f"the drive band [{d.low_V:g}, {d.high_V:g}] V flips its arm")
            for i in np.flatnonzero(d.chatter):
                self._bodies.log(t_start, int(i), "arm_chatter", None, f"its arm chatters in the drive band [{d.low_V:g}, {d.high_V:g}] V")
            self._drive(d.states.astype(bool), d.chatter, d.duration_s, t_start)
            if self._drive_log is not None:
                self._drive_log.append((t_start + d.duration_s, d.states.astype(bool) | d.chatter, self._bodies.pose.copy()))
        self._arms = np.asarray(dec.final, dtype=np.uint8).copy()
        self._t = t0 + dec.duration_s

    # -- for reports and tests (outside the protocol) -----------------------------------------------

    @property
    def n(self) -> int:
        return self.scenario.n

    @property
    def names(self) -> tuple[str, ...]:
        return self._bodies.names

    @property
    def time_s(self) -> float:
        """Simulated time (s) of every segment applied so far, Holds included."""
        return self._t

    @property
    def events(self) -> tuple[SimEvent, ...]:
        return tuple(self._bodies.events)

    @property
    def docked(self) -> np.ndarray:
        """``(n,)`` bool: resting flush against a body and pushing (docking compliance or G_1)."""
        return self._bodies.docked.copy()

    @property
    def stuck(self) -> np.ndarray:
        """``(n,)`` bool: stopped in the failure region H (outside a compliance limit, or obstructed)."""
        return self._bodies.stuck.copy()

    @property
    def arena_hits(self) -> np.ndarray:
        """``(n,)`` bool: the robot has been stopped at the arena edge at some point."""
        return self._bodies.arena_hit.copy()

    @property
    def arm_states(self) -> np.ndarray:
        """``(n,)`` uint8 arm states now (1 = down)."""
        return self._arms.copy()

    @property
    def speed_factors(self) -> np.ndarray:
        """Per-run speed factors drawn from the seed (the plant's hidden truth)."""
        return self._speed_factor.copy()

    @property
    def radius_factors(self) -> np.ndarray:
        """Per-run turning-radius factors drawn from the seed."""
        return self._radius_factor.copy()

    @property
    def odometer(self) -> np.ndarray:
        """``(n,)`` distance (um) each robot has driven so far (arcs and straight runs; not slides or
        compliance moves): the variable its heading drift is a function of."""
        return self._bodies.odo.copy()

    @property
    def drift_bias(self) -> np.ndarray:
        """Per-run heading-drift bias (rad per um driven) of each robot (the plant's hidden truth)."""
        return self._drift.bias.copy()

    def true_poses(self) -> np.ndarray:
        """True poses ``(n, 3)`` (um, rad in [0, 2 pi))."""
        return self._bodies.pose.copy()

    def trace(self) -> tuple[np.ndarray, np.ndarray]:
        """Recorded trajectory: times ``(M,)`` (s) and poses ``(M, n, 3)``; start and end only unless
        the plant was made with ``record=True``."""
        t = np.concatenate(self._trace_t)
        p = np.concatenate(self._trace_p)
        pose = self._bodies.pose
        if t[-1] != self._t or not np.array_equal(p[-1], pose):
            t = np.append(t, self._t)
            p = np.concatenate([p, pose[None]])
        return t, p

    def drive_log(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """With ``log_drives=True``: the end time ``(K,)`` (s) of every Drive so far, which robots turned in
        it ``(K, n)`` (arm down or chattering) and the true poses at its end ``(K, n, 3)``.

        Raises
        ------
        RuntimeError
            The plant was made without ``log_drives=True``.
        """
        if self._drive_log is None:
            raise RuntimeError("make the plant with log_drives=True to keep its drive log")
        n = self.n
        if not self._drive_log:
            return np.zeros(0), np.zeros((0, n), dtype=bool), np.zeros((0, n, 3))
        t, turning, poses = zip(*self._drive_log, strict=True)
        return np.array(t), np.stack(turning), np.stack(poses)

    def copy(self) -> SimulatedPlant:
        """An independent copy that continues bit-identically (random streams included).

        One deep copy of the whole state, so the parts that share the bodies still share the copy's; the
        scenario (immutable) is shared.
        """
        new = object.__new__(type(self))
        new.__dict__ = copy.deepcopy(self.__dict__, memo={id(self.scenario): self.scenario})
        return new

    # -- one Drive -----------------------------------------------------------------------------------

    def _rates(self, turning: np.ndarray, chatter: np.ndarray, duration_s: float) -> DriveRates:
        """This Drive's speeds and curvatures (per-run factors jittered per Drive) and each body's
        fastest point (um/s, heading drift included)."""
        nz = self.scenario.noise
        z = self._motion_rng.standard_normal((2, self.n))
        speed = self._v * self._speed_factor * np.maximum(1.0 + SEGMENT_JITTER * nz.speed_rel_sd * z[0], MIN_FACTOR)
        radius = self._r * self._radius_factor * np.maximum(1.0 + SEGMENT_JITTER * nz.turn_radius_rel_sd * z[1], MIN_FACTOR)
        kappa = np.where(chatter, 0.5 / radius, np.where(turning, 1.0 / radius, 0.0))  # drift comes on top
        straight = ~turning & ~chatter
        reach = speed * duration_s
        odo = self._bodies.odo
        kmax = np.abs(kappa) + self._drift.max_abs_all(odo, reach)
        bound = speed * (1.0 + kmax * self._bodies.hd)  # fastest point of each body (um/s)
        return DriveRates(speed, kappa, straight, bound)

    def _drive(self, turning: np.ndarray, chatter: np.ndarray, duration_s: float, t_start: float) -> None:
        b = self._bodies
        ctx = self._rates(turning, chatter, duration_s)
        if self._quiet(ctx.bound, duration_s):
            # Broad phase: nobody can come near anybody or the wall during this Drive; closed form only.
            p0 = b.pose.copy()
            free = Motion(np.full(self.n, FREE), np.zeros((self.n, 2)), np.full(self.n, math.inf), set(), False)
            b.pose = poses_at(b, self._drift, p0, free, ctx, np.array([duration_s]))[0]
            if self._record:
                self._record_segment(p0, free, ctx, duration_s, t_start)
            b.odo += ctx.speed * duration_s
            self._rules.contacts = {}
            b.docked[:] = False
            b.stuck[:] = False
            return
        tau = 0.0
        stalls = 0
        forced: set[int] = set()
        while duration_s - tau > 1e-12:
            motion = self._rules.evaluate(ctx, t_start + tau, forced)
            dt, hit = self._advance(motion, ctx, duration_s - tau, t_start + tau)
            tau += dt
            if dt <= 1e-12:
                stalls += 1
                if stalls > STALL_EVALUATIONS:  # no progress: freeze whoever is touching, rather than loop
                    self._freeze(hit, forced, t_start + tau)
                    stalls = 0
            else:
                stalls = 0
        # Contacts made at the very end still act: the last push of the Drive docks (or blocks) them.
        self._rules.evaluate(ctx, t_start + duration_s, forced)

    def _advance(self, motion: Motion, ctx: DriveRates, left_s: float, t_abs: float):
        """Move everyone by ``motion`` until the first contact, the end of a slide, a re-check or the end
        of the Drive (``left_s`` s away); returns ``(dt, hit)`` (``hit`` as :func:`.search.first_contact`)."""
        b = self._bodies
        horizon = left_s
        if motion.recheck:
            horizon = min(horizon, RECHECK_S)
        slide_ends = float(motion.slide_end.min()) if self.n else math.inf
        horizon = min(horizon, slide_ends)
        p0 = b.pose.copy()
        hit = first_contact(b, self._drift, p0, motion, ctx, horizon)
        dt = horizon if hit is None else hit[0]
        if dt > 0.0:
            b.pose = poses_at(b, self._drift, p0, motion, ctx, np.array([dt]))[0]
            moved = (motion.mode != HELD) & (ctx.speed > 0)
            b.docked &= ~moved
            b.stuck &= ~moved
            if self._record:
                self._record_segment(p0, motion, ctx, dt, t_abs)
            b.odo += np.where(motion.mode == FREE, ctx.speed * dt, 0.0)  # slides and holds drive nowhere
        if hit is None and dt == slide_ends:
            for i in np.flatnonzero(motion.slide_end == slide_ends):
                b.log(t_abs + dt, int(i), "slide_off", None, "its corner ran off the face it slid along")
        return dt, hit

    def _freeze(self, hit, forced: set[int], t_abs: float) -> None:
        """Stop (stuck) every robot of the contact that made no progress, so the Drive can go on."""
        for pair in hit[1] if hit is not None else []:
            for k in pair:
                if k >= 0 and k not in forced:
                    forced.add(k)
                    self._bodies.stuck[k] = True
                    self._bodies.log(t_abs, k, "stuck", None, "contact could not be resolved; stopped")

    def _quiet(self, bound: np.ndarray, duration_s: float) -> bool:
        """Whether no body can come within :data:`~.bodies.NEAR_UM` of another or of the arena edge in
        ``duration_s`` (bounding circles grown by each body's largest travel)."""
        b = self._bodies
        ii, jj = b.I, b.J
        travel = bound * duration_s
        if ii.size:
            centre = b.centre_distances()
            if (centre - b.hd[ii] - b.hd[jj] - travel[ii] - travel[jj] <= NEAR_UM).any():
                return False
        if b.arena is not None:
            if (b.wall_gaps() - travel <= NEAR_UM).any():
                return False
        return bool((self._v > 0).all())

    def _record_segment(self, p0, motion, ctx, dt, t0) -> None:
        vmax = float(np.max(ctx[3])) if self.n else 0.0
        m = max(1, math.ceil(vmax * dt / 10.0))
        taus = dt * np.arange(1, m + 1) / m
        self._trace_t.append(t0 + taus)
        self._trace_p.append(poses_at(self._bodies, self._drift, p0, motion, ctx, taus))
