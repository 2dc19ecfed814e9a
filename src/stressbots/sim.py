"""The simulated plant: robots with control error, contact and compliance, seen through a noisy camera.

:class:`SimulatedPlant` implements :class:`stressbots.control.Plant`. It stands in for the lab: a
waveform is decoded by the hysteresis model (:func:`stressbots.waveform.replay`, the one source of
truth for arm states), the robots move by the closed-form kinematics (:func:`stressbots.kinematics.move`)
with the scenario's ``[noise]``, bodies never interpenetrate, and the seed's compliance (App. 3.5)
turns near misses into docked robots while larger errors leave robots stuck (failure region H).

Motion (per Drive of the waveform)
----------------------------------
Holds move nobody. During a Drive every robot drives forward at its speed on an arc of constant
curvature: ``kappa = 1/r`` with its arm down, 0 with its arm up, ``1/(2 r)`` for an arm the drive band
makes chatter (it turns every other cycle: an interpolated turn of mean radius 2r), plus its heading
drift, a curvature that is piecewise constant between the knots of the robot's odometer (below). Between
contacts and knots the motion is the closed form, so with all noise zero the simulator reproduces
:func:`stressbots.kinematics.advance` exactly (to rounding, no integration error).

Noise model (``scenario.noise``; all draws from the seed, see *Determinism*)
---------------------------------------------------------------------------
- per robot and run: speed factor ``1 + speed_rel_sd * z`` and radius factor ``1 + turn_radius_rel_sd * z``
  (z standard normal; floored at 0.1);
- per robot and Drive: the same factors jittered by :data:`SEGMENT_JITTER` times those sds
  ("small per-segment variation");
- per robot, as a function of its odometer (distance driven, :attr:`SimulatedPlant.odometer`): heading
  drift (:mod:`stressbots.drift`), a bias drawn once per run plus a random walk whose variance grows with
  the distance driven, realised as a curvature constant between odometer knots every
  :attr:`~stressbots.drift.DriftModel.knot_um` (25 um). The spread after 1 mm has sd
  ``heading_drift_deg_per_mm`` however the millimetre is cut into Drives (the same seed even gives the
  same drift, to rounding); the odometer advances only while a robot drives (not while it is held,
  slides along a face or is turned by compliance);
- camera (:meth:`SimulatedPlant.observe`): position N(0, sd) per axis, heading N(0, sd), and each robot
  missing (NaN row) with probability ``camera_dropout``.

Contact (bodies never interpenetrate)
-------------------------------------
A broad phase first checks whether any two bodies (or a body and the arena edge) could come within
:data:`NEAR_UM` during the Drive (bounding circles grown by each body's largest travel); if not, the
Drive is one closed-form step. Otherwise the first contact is found by sampling the motion every
:data:`SAMPLE_UM` of relative travel, a Lipschitz bound on the separating-axis gap between samples (so
no contact between samples is missed), finer sampling of doubtful intervals and a 16-way bisection
down to ~1e-10 um of travel. At that instant everyone stops, the rules below are applied, and the rest
of the Drive continues. A contact is interpenetration beyond :data:`CONTACT_TOL_UM` (1e-9 um); a pair
already touching whose motion does not push may graze by up to :data:`GRAZE_TOL_UM` (1e-4 um). A
robot's motion *pushes* into a touching body (or the arena edge) when moving it alone by
:data:`PROBE_UM` deepens the contact by more than :data:`PUSH_EPS_UM`. Rules, for every robot whose
motion pushes (also applied at the end of every Drive, so a contact made on its last instant counts):

1. **Self-aligning compliance (G_1).** Two robots with arms up, neither docked, meeting head-on:
   headings opposed, closing on each other (at least one pushes), every contact point in the front half
   of both bodies (front edges against each other, corner to corner, or a front corner on the other's
   long side near its front). With incidence ``alpha = theta_i - theta_j - pi`` (wrapped) and lateral
   misalignment ``w_y`` (offset of the two front-edge centres across the meeting axis, the bisector of
   the two headings), if ``|alpha| < 60 deg`` and ``|w_y| < 80 um`` they form G_1 (seed App. 3.5: also
   when ``w_y`` exceeds the width, so that only a corner meets the other's side): both turn to the mean
   axis (each by alpha/2, so the pair rotates as a whole) and slide until their front-edge midpoints
   coincide at the midpoint of the two, collinear and flush. Both are docked. A front corner that reaches
   the rear half of the other's side is a sideswipe, not a meeting: rule 5, they slide past.
   Outside those limits, or if the aligned pair would overlap a third body or leave the arena, both stop
   where they met: stuck (H).
2. **Turning robot** (arm down or chattering) whose motion pushes into anything: blocked; it stops for
   the rest of the Drive (it pivots on its stylus and cannot pivot off an obstacle). If its front edge is
   flush against a static body (it arrived in its slot on an arc), it is **docked** there: arriving flush
   against the structure is docking, with or without a straight push afterwards (SPEC 6).
3. **Arena edge**: a robot pushing out of the arena stops at the edge ("arena"; ``arena_hits``).
4. **Straight robot (arm up) against a static body** (one that does not move now: docked, stopped or
   stuck), contact on its front (its front corner on a face, the body's corner on its front edge, or
   the front edge flush). The face met is the body's face the contact lies on; at a corner of the body
   (two faces) the one the contact is not behind, and of equals the one most opposed to the robot's
   heading. ``alpha`` is the signed angle between the robot's heading and that face's inward normal.

   - ``|alpha| <= 45 deg`` (the sticking cone): **docking compliance**. It rotates about the contact
     point (the touching corner(s)) until its front edge is flush with the face, then stays there
     pushing: docked. If the rotation would sweep into another body it stops at first touch: stuck (H).
   - outside the cone with its *front corner* on the face: the corner does not stick; the robot slides
     along the face without turning, at the tangential part of its velocity ``v sin|alpha|``, until the
     corner runs :data:`SLIDE_OVERSHOOT_UM` past the face's end ("slide", then "slide_off"; it then drives
     on, e.g. onto a collinear face of the next robot) or into something else (stuck). A slide is the
     failure region H: the robot does not dock.
   - outside the cone with the body's corner on its front edge: stuck (H).
   - a body's corner touching its long side: it slides past it, straight, without turning ("graze").
   - pushing into several static bodies at once: it stops; docked if flush with one of them.
5. Any other pushing contact (e.g. into a robot that is itself moving): the pushing robot stops
   ("contact"); it is re-checked every :data:`RECHECK_S` while its partner moves.

A stopped robot is re-examined after every contact and at every later Drive: it moves again as soon as
its motion no longer pushes. ``docked`` and ``stuck`` clear when it moves. Compliance moves are
instantaneous. An event is logged when a contact's outcome changes; outcomes are remembered while the
pair stays within :data:`NEAR_UM`, so robots jostling against each other do not flood the log.

Determinism
-----------
Everything random comes from ``np.random.SeedSequence(seed)``, spawned into independent streams for
the per-run factors, the per-Drive jitter, the camera (so observing more or less often never changes
the motion) and the drift (one child stream per robot, knot values drawn in knot order). The same seed
and the same calls give bit-identical results; :meth:`SimulatedPlant.copy` continues bit-identically;
:func:`check_determinism` proves it.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .collision import arena_gap, point_rectangle_distance
from .drift import DEFAULT_DRIFT, DriftModel, HeadingDrift
from .kinematics import follow, move, wrap
from .robots import angle_difference, body_corners
from .waveform import Segment, replay

__all__ = [
    "SimEvent",
    "SimulatedPlant",
    "check_determinism",
    "plan_waveform",
    "run_plan",
    "STICKING_CONE_RAD",
    "SELF_ALIGN_MAX_INCIDENCE_RAD",
    "SELF_ALIGN_MAX_OFFSET_UM",
    "SEGMENT_JITTER",
]

STICKING_CONE_RAD = math.radians(45.0)
"""Docking compliance: largest incidence (rad) at which a front corner sticks (seed App. 3.5)."""

SELF_ALIGN_MAX_INCIDENCE_RAD = math.radians(60.0)
"""Self-aligning compliance: G_1 forms only for incidence |alpha| below this (rad)."""

SELF_ALIGN_MAX_OFFSET_UM = 80.0
"""Self-aligning compliance: G_1 forms only for lateral misalignment |w_y| below this (um)."""

SEGMENT_JITTER = 0.2
"""Per-Drive variation of speed and radius, as a fraction of the per-run sds."""

MIN_FACTOR = 0.1
SAMPLE_UM = 10.0  # coarse sampling: relative travel between samples (um)
MIN_STEP_UM = 0.5  # fine sampling of doubtful intervals (um)
BISECT_UM = 1e-10  # bisection stops at this much travel (um)
CONTACT_TOL_UM = 1e-9  # interpenetration that makes a contact event (um)
GRAZE_TOL_UM = 1e-4  # extra interpenetration allowed to a touching pair that does not push (um)
TOUCH_UM = 1e-6  # closer than this counts as touching (um)
PROBE_UM = 1e-3  # probe travel that tells whether a motion pushes into a contact (um)
PUSH_EPS_UM = 1e-9  # deeper by more than this over the probe: it pushes (um)
RECHECK_S = 0.05  # re-check a stopped robot this often while its partner moves (s)
SLIDE_OVERSHOOT_UM = 1e-4  # a slide ends this far past the face's end, clear of it (um)
FACE_TIE_UM = 1e-6  # contact faces whose lines are this close to the contact count as equally touched (um)
SWEEP_UM = 0.5  # compliance rotations are checked every this much travel of the farthest corner (um)
FLUSH_TOL_RAD = 1e-6  # front edge this parallel to a face counts as flush (rad)
NEAR_UM = 1.0  # an outcome is remembered (not logged again) while its pair stays this close (um)

ARENA = -1
_FREE, _HELD, _SLIDE = 0, 1, 2


@dataclass(frozen=True)
class SimEvent:
    """Something that happened to a robot: a contact outcome or an arm anomaly.

    ``kind`` is one of ``contact``, ``dock``, ``self_align``, ``stuck``, ``slide``, ``slide_off``, ``graze``,
    ``blocked``, ``arena``, ``arm_flip``, ``arm_chatter``. ``other`` names the robot touched, ``"arena"``,
    or is ``None``.
    """

    time_s: float
    robot: str
    kind: str
    other: str | None = None
    detail: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {"time_s": self.time_s, "robot": self.robot, "kind": self.kind, "other": self.other, "detail": self.detail}


# ----------------------------------------------------------------------------------------------------
# Geometry kernels (pure, vectorised)


def _depth(pa, pb, hla, hwa, hlb, hwb) -> np.ndarray:
    """Separating-axis penetration depth of body pairs (um; <= 0 apart), as
    :func:`stressbots.collision.penetration_depth` but for any batch shape and half sizes."""
    sa, ca = np.sin(pa[..., 2]), np.cos(pa[..., 2])
    sb, cb = np.sin(pb[..., 2]), np.cos(pb[..., 2])
    dx = pb[..., 0] - pa[..., 0]
    dy = pb[..., 1] - pa[..., 1]
    cd = np.abs(sa * sb + ca * cb)  # |cos(theta_a - theta_b)|
    sd = np.abs(sa * cb - ca * sb)  # |sin(theta_a - theta_b)|
    o1 = hla + hlb * cd + hwb * sd - np.abs(dx * sa + dy * ca)  # along a's heading
    o2 = hwa + hlb * sd + hwb * cd - np.abs(dx * ca - dy * sa)  # across a
    o3 = hlb + hla * cd + hwa * sd - np.abs(dx * sb + dy * cb)  # along b's heading
    o4 = hwb + hla * sd + hwa * cd - np.abs(dx * cb - dy * sb)  # across b
    return np.minimum(np.minimum(o1, o2), np.minimum(o3, o4))


def _arena_gap(p, hl, hw, arena) -> np.ndarray:
    """Distance (um) from each body (half lengths ``hl``, ``hw``) to the nearest arena wall; negative outside."""
    return arena_gap(p, 2.0 * hl, 2.0 * hw, arena)


def _rotate_about(pose, centre, phi) -> np.ndarray:
    """Poses after rotating clockwise (heading convention) by ``phi`` (rad, array) about ``centre``."""
    phi = np.asarray(phi, dtype=np.float64)
    c, s = np.cos(phi), np.sin(phi)
    dx, dy = pose[0] - centre[0], pose[1] - centre[1]
    out = np.empty(phi.shape + (3,))
    out[..., 0] = centre[0] + c * dx + s * dy
    out[..., 1] = centre[1] - s * dx + c * dy
    out[..., 2] = wrap(pose[2] + phi)
    return out


def _heading_of(vec) -> float:
    """Heading (rad, clockwise from +y) of a 2-vector."""
    return float(math.atan2(vec[0], vec[1]))


def _local(points, pose) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates of points along (u) and across (v, to the right) a body."""
    d = np.asarray(points, dtype=np.float64) - pose[:2]
    s, c = math.sin(pose[2]), math.cos(pose[2])
    return d[..., 0] * s + d[..., 1] * c, d[..., 0] * c - d[..., 1] * s


def _faces_touched(points, pose, hl, hw, tol) -> list[tuple[np.ndarray, float]]:
    """Faces of a body that any of ``points`` lies on (within ``tol``): ``(outward unit normal, outside)``.

    ``outside`` is the largest signed distance (um) of those points from the face's line (>= 0 on or
    outside it). A point at a corner lies on both faces meeting there; with none within ``tol``, the
    nearest face.
    """
    u, v = _local(np.atleast_2d(points), pose)
    s, c = math.sin(pose[2]), math.cos(pose[2])
    h, r = np.array([s, c]), np.array([c, -s])
    faces = []
    for sign in (1.0, -1.0):
        on = (np.abs(sign * u - hl) <= tol) & (np.abs(v) <= hw + tol)
        if on.any():
            faces.append((sign * h, float(np.max(sign * u[on] - hl))))
        on = (np.abs(sign * v - hw) <= tol) & (np.abs(u) <= hl + tol)
        if on.any():
            faces.append((sign * r, float(np.max(sign * v[on] - hw))))
    if not faces:
        k = int(np.argmin(np.minimum(hl - np.abs(u), hw - np.abs(v))))
        if hl - abs(u[k]) <= hw - abs(v[k]):
            faces.append((math.copysign(1.0, u[k]) * h, float(abs(u[k]) - hl)))
        else:
            faces.append((math.copysign(1.0, v[k]) * r, float(abs(v[k]) - hw)))
    return faces


# ----------------------------------------------------------------------------------------------------
# The plant


@dataclass
class _Motion:
    """How each robot moves during one sub-interval of a Drive."""

    mode: np.ndarray  # (n,) _FREE / _HELD / _SLIDE
    slide_v: np.ndarray  # (n, 2) um/s, for sliding robots
    slide_end: np.ndarray  # (n,) s from the sub-interval start; inf when not sliding
    excluded: set  # pairs (i, j), i < j, not checked (a slide along j's face)
    recheck: bool  # a stopped robot touches a moving one


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
    must not use them (hardware has no such thing). See the module docstring for the model.
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
        self._odo = np.zeros(n)
        self._speed_factor = np.maximum(1.0 + nz.speed_rel_sd * z[0], MIN_FACTOR)
        self._radius_factor = np.maximum(1.0 + nz.turn_radius_rel_sd * z[1], MIN_FACTOR)
        self._motion_rng = np.random.default_rng(motion_ss)
        self._camera_rng = np.random.default_rng(camera_ss)
        self._v = scenario.speeds_um_s
        self._r = scenario.turn_radii_um
        self._hl = 0.5 * scenario.lengths_um
        self._hw = 0.5 * scenario.widths_um
        self._hd = np.hypot(self._hl, self._hw)
        self._vd = scenario.snap_down_V
        self._vu = scenario.release_V
        self._names = scenario.names
        p = scenario.starts if poses is None else np.asarray(poses, dtype=np.float64).reshape(n, 3)
        self._pose = np.array(p, dtype=np.float64)
        self._pose[:, 2] = wrap(self._pose[:, 2])
        self._arms = np.zeros(n, dtype=np.uint8)
        self._t = 0.0
        self._docked = np.zeros(n, dtype=bool)
        self._stuck = np.zeros(n, dtype=bool)
        self._arena_hit = np.zeros(n, dtype=bool)
        self._contacts: dict[tuple[int, int], str] = {}
        self._rule_cache: dict[tuple[int, int], tuple[bytes, tuple[str, str]]] = {}
        self._flush_cache: dict[tuple[int, int], tuple[bytes, bool]] = {}
        self._events: list[SimEvent] = []
        self._I, self._J = np.triu_indices(n, k=1)
        self._record = bool(record)
        self._trace_t: list[np.ndarray] = [np.zeros(1)]
        self._trace_p: list[np.ndarray] = [self._pose[None].copy()]
        self._drive_log: list[tuple[float, np.ndarray, np.ndarray]] | None = [] if log_drives else None

    # -- the Plant protocol ------------------------------------------------------------------------

    def observe(self) -> np.ndarray:
        """One camera frame ``(n, 3)``: true poses plus camera noise; NaN rows for dropped robots."""
        nz = self.scenario.noise
        n = self.n
        drop = self._camera_rng.random(n) < nz.camera_dropout
        e = self._camera_rng.standard_normal((n, 3))
        obs = self._pose.copy()
        obs[:, :2] += nz.camera_position_sd_um * e[:, :2]
        obs[:, 2] = wrap(obs[:, 2] + nz.camera_heading_sd_rad * e[:, 2])
        obs[drop] = np.nan
        return obs

    def apply(self, waveform: Sequence[Segment]) -> None:
        """Play a waveform: decode the arm states, then move the robots through every Drive."""
        segs = tuple(waveform)
        dec = replay(segs, self._vd, self._vu, initial=self._arms)
        t0 = self._t
        for d in dec.drives:
            t_start = t0 + d.t_start_s
            for i in np.flatnonzero(d.flipped):
                self._log(t_start, int(i), "arm_flip", None, f"the drive band [{d.low_V:g}, {d.high_V:g}] V flips its arm")
            for i in np.flatnonzero(d.chatter):
                self._log(t_start, int(i), "arm_chatter", None, f"its arm chatters in the drive band [{d.low_V:g}, {d.high_V:g}] V")
            self._drive(d.states.astype(bool), d.chatter, d.duration_s, t_start)
            if self._drive_log is not None:
                self._drive_log.append((t_start + d.duration_s, d.states.astype(bool) | d.chatter, self._pose.copy()))
        self._arms = np.asarray(dec.final, dtype=np.uint8).copy()
        self._t = t0 + dec.duration_s

    # -- for reports and tests (outside the protocol) -----------------------------------------------

    @property
    def n(self) -> int:
        return self.scenario.n

    @property
    def names(self) -> tuple[str, ...]:
        return self._names

    @property
    def time_s(self) -> float:
        """Simulated time (s) of every segment applied so far, Holds included."""
        return self._t

    @property
    def events(self) -> tuple[SimEvent, ...]:
        return tuple(self._events)

    @property
    def docked(self) -> np.ndarray:
        """``(n,)`` bool: resting flush against a body and pushing (docking compliance or G_1)."""
        return self._docked.copy()

    @property
    def stuck(self) -> np.ndarray:
        """``(n,)`` bool: stopped in the failure region H (outside a compliance limit, or obstructed)."""
        return self._stuck.copy()

    @property
    def arena_hits(self) -> np.ndarray:
        """``(n,)`` bool: the robot has been stopped at the arena edge at some point."""
        return self._arena_hit.copy()

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
        return self._odo.copy()

    @property
    def drift_bias(self) -> np.ndarray:
        """Per-run heading-drift bias (rad per um driven) of each robot (the plant's hidden truth)."""
        return self._drift.bias.copy()

    def true_poses(self) -> np.ndarray:
        """True poses ``(n, 3)`` (um, rad in [0, 2 pi))."""
        return self._pose.copy()

    def trace(self) -> tuple[np.ndarray, np.ndarray]:
        """Recorded trajectory: times ``(M,)`` (s) and poses ``(M, n, 3)``; start and end only unless
        the plant was made with ``record=True``."""
        t = np.concatenate(self._trace_t)
        p = np.concatenate(self._trace_p)
        if t[-1] != self._t or not np.array_equal(p[-1], self._pose):
            t = np.append(t, self._t)
            p = np.concatenate([p, self._pose[None]])
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
        """An independent copy that continues bit-identically (random streams included)."""
        new = object.__new__(type(self))
        new.__dict__ = {k: (v if k == "scenario" else copy.deepcopy(v)) for k, v in self.__dict__.items()}
        return new

    # -- one Drive -----------------------------------------------------------------------------------

    def _drive(self, turning: np.ndarray, chatter: np.ndarray, duration_s: float, t_start: float) -> None:
        nz = self.scenario.noise
        z = self._motion_rng.standard_normal((2, self.n))
        speed = self._v * self._speed_factor * np.maximum(1.0 + SEGMENT_JITTER * nz.speed_rel_sd * z[0], MIN_FACTOR)
        radius = self._r * self._radius_factor * np.maximum(1.0 + SEGMENT_JITTER * nz.turn_radius_rel_sd * z[1], MIN_FACTOR)
        kappa = np.where(chatter, 0.5 / radius, np.where(turning, 1.0 / radius, 0.0))  # drift comes on top
        straight = ~turning & ~chatter
        reach = speed * duration_s
        kmax = np.abs(kappa) + np.array([self._drift.max_abs(i, self._odo[i], reach[i]) for i in range(self.n)])
        bound = speed * (1.0 + kmax * self._hd)  # fastest point of each body (um/s)
        ctx = (speed, kappa, straight, bound)
        if self._quiet(bound, duration_s):
            # Broad phase: nobody can come near anybody or the wall during this Drive; closed form only.
            p0 = self._pose.copy()
            free = _Motion(np.full(self.n, _FREE), np.zeros((self.n, 2)), np.full(self.n, math.inf), set(), False)
            self._pose = self._poses_at(p0, free, ctx, np.array([duration_s]))[0]
            if self._record:
                self._record_segment(p0, free, ctx, duration_s, t_start)
            self._odo += reach
            self._contacts = {}
            self._docked[:] = False
            self._stuck[:] = False
            return
        tau = 0.0
        stalls = 0
        forced: set[int] = set()
        while duration_s - tau > 1e-12:
            motion = self._evaluate(ctx, t_start + tau, forced)
            horizon = duration_s - tau
            if motion.recheck:
                horizon = min(horizon, RECHECK_S)
            slide_ends = float(motion.slide_end.min()) if self.n else math.inf
            horizon = min(horizon, slide_ends)
            p0 = self._pose.copy()
            hit = self._search(p0, motion, ctx, horizon)
            dt = horizon if hit is None else hit[0]
            if dt > 0.0:
                self._pose = self._poses_at(p0, motion, ctx, np.array([dt]))[0]
                moved = (motion.mode != _HELD) & (speed > 0)
                self._docked &= ~moved
                self._stuck &= ~moved
                if self._record:
                    self._record_segment(p0, motion, ctx, dt, t_start + tau)
                self._odo += np.where(motion.mode == _FREE, speed * dt, 0.0)  # slides and holds drive nowhere
            if hit is None and dt == slide_ends:
                for i in np.flatnonzero(motion.slide_end == slide_ends):
                    self._log(t_start + tau + dt, int(i), "slide_off", None, "its corner ran off the face it slid along")
            tau += dt
            if dt <= 1e-12:
                stalls += 1
                if stalls > 50:  # no progress: freeze whoever is touching, rather than loop
                    for pair in hit[1] if hit is not None else []:
                        for k in pair:
                            if k >= 0 and k not in forced:
                                forced.add(k)
                                self._stuck[k] = True
                                self._log(t_start + tau, k, "stuck", None, "contact could not be resolved; stopped")
                    stalls = 0
            else:
                stalls = 0
        # Contacts made at the very end still act: the last push of the Drive docks (or blocks) them.
        self._evaluate(ctx, t_start + duration_s, forced)

    def _quiet(self, bound: np.ndarray, duration_s: float) -> bool:
        """Whether no body can come within :data:`NEAR_UM` of another or of the arena edge in
        ``duration_s`` (bounding circles grown by each body's largest travel)."""
        P, ii, jj = self._pose, self._I, self._J
        travel = bound * duration_s
        if ii.size:
            centre = np.hypot(P[ii, 0] - P[jj, 0], P[ii, 1] - P[jj, 1])
            if (centre - self._hd[ii] - self._hd[jj] - travel[ii] - travel[jj] <= NEAR_UM).any():
                return False
        if self.scenario.arena_um is not None:
            if (_arena_gap(P, self._hl, self._hw, self.scenario.arena_um) - travel <= NEAR_UM).any():
                return False
        return bool((self._v > 0).all())

    def _record_segment(self, p0, motion, ctx, dt, t0) -> None:
        vmax = float(np.max(ctx[3])) if self.n else 0.0
        m = max(1, math.ceil(vmax * dt / 10.0))
        taus = dt * np.arange(1, m + 1) / m
        self._trace_t.append(t0 + taus)
        self._trace_p.append(self._poses_at(p0, motion, ctx, taus))

    def _poses_at(self, p0, motion: _Motion, ctx, taus) -> np.ndarray:
        """Poses ``(K, n, 3)`` at times ``taus`` (s) after the sub-interval start."""
        speed, kappa = ctx[0], ctx[1]
        taus = np.asarray(taus, dtype=np.float64)
        out = np.repeat(p0[None], taus.size, axis=0)
        f = np.flatnonzero(motion.mode == _FREE)
        if f.size and not self._drift.active:
            out[:, f] = move(p0[f][None], speed[f][None, :] * taus[:, None], kappa[f][None, :])
        elif f.size:
            out[:, f] = self._drift_poses(p0[f], f, speed[f], kappa[f], taus)
        s = np.flatnonzero(motion.mode == _SLIDE)
        if s.size:
            out[:, s, :2] = p0[s, :2][None] + taus[:, None, None] * motion.slide_v[s][None]
        return out

    def _drift_poses(self, p0, idx, speed, kappa, taus) -> np.ndarray:
        """Poses ``(K, m, 3)`` of robots ``idx`` driving freely for ``taus`` s from ``p0`` on their base
        curvature plus the drift's, which is piecewise constant between odometer knots: exact arcs,
        composed (all robots at once, pieces padded to a common count)."""
        tmax = float(taus.max())
        pieces = [self._drift.segments(int(i), self._odo[i], sp * tmax) for i, sp in zip(idx, speed, strict=False)]
        k = max(len(p[0]) for p in pieces)
        lengths = np.zeros((len(pieces), k))
        kd = np.zeros((len(pieces), k))
        for r, (ln, kv) in enumerate(pieces):
            lengths[r, : ln.size] = ln
            kd[r, : ln.size] = kv
        curv = kappa[:, None] + kd
        nodes = follow(p0, lengths, curv)  # (m, k + 1, 3): the pose at every knot
        cum = np.concatenate([np.zeros((len(pieces), 1)), np.cumsum(lengths, axis=1)], axis=1)
        s = np.minimum(speed[None, :] * taus[:, None], cum[None, :, -1])  # (K, m)
        last = np.array([p[0].size - 1 for p in pieces])  # each robot's own last piece (not the padding)
        j = np.minimum((s[..., None] >= cum[None, :, 1:]).sum(axis=-1), last[None, :])  # piece each s lies in
        rows = np.arange(len(pieces))[None, :]
        return move(nodes[rows, j], s - cum[rows, j], curv[rows, j])

    # -- contact search ------------------------------------------------------------------------------

    def _gaps(self, poses, ci, cj) -> np.ndarray:
        """Gaps ``(K, Q)`` (um, negative = interpenetration) of candidate pairs ``(ci, cj)``; ``cj = -1``
        is the arena edge."""
        out = np.empty(poses.shape[:1] + ci.shape)
        pm = cj >= 0
        if pm.any():
            a, b = ci[pm], cj[pm]
            out[:, pm] = -_depth(poses[:, a], poses[:, b], self._hl[a], self._hw[a], self._hl[b], self._hw[b])
        if (~pm).any():
            a = ci[~pm]
            out[:, ~pm] = _arena_gap(poses[:, a], self._hl[a], self._hw[a], self.scenario.arena_um)
        return out

    def _search(self, p0, motion: _Motion, ctx, horizon: float):
        """First contact within ``horizon`` s: ``(tau_lo, pairs)`` or ``None``.

        ``tau_lo`` is the last time (to ~1e-10 um of travel) with no new interpenetration beyond
        :data:`CONTACT_TOL_UM`; ``pairs`` are the candidate pairs that interpenetrate just after it.
        """
        moving = motion.mode != _HELD
        if horizon <= 0.0 or not moving.any():
            return None
        U = np.where(moving, np.where(motion.mode == _SLIDE, np.hypot(*motion.slide_v.T), ctx[3]), 0.0)
        ii, jj = self._I, self._J
        keep = moving[ii] | moving[jj]
        if keep.any():
            ii, jj = ii[keep], jj[keep]
            reach = (U[ii] + U[jj]) * horizon + 1.0
            centre = np.hypot(p0[ii, 0] - p0[jj, 0], p0[ii, 1] - p0[jj, 1])
            near = centre - self._hd[ii] - self._hd[jj] < reach
            ii, jj = ii[near], jj[near]
            if motion.excluded and ii.size:
                ok = np.array([(int(a), int(b)) not in motion.excluded for a, b in zip(ii, jj, strict=True)], dtype=bool)
                ii, jj = ii[ok], jj[ok]
        else:
            ii, jj = ii[:0], jj[:0]
        ci, cj = ii, jj
        if self.scenario.arena_um is not None:
            m = np.flatnonzero(moving)
            g0a = _arena_gap(p0[m], self._hl[m], self._hw[m], self.scenario.arena_um)
            m = m[g0a - U[m] * horizon < 1.0]
            ci = np.concatenate([ci, m])
            cj = np.concatenate([cj, np.full(m.size, ARENA)])
        if ci.size == 0:
            return None
        Uq = U[ci] + np.where(cj >= 0, U[np.maximum(cj, 0)], 0.0)
        g0 = self._gaps(p0[None], ci, cj)[0]
        # A contact is interpenetration beyond the tolerance; pairs touching now (that do not push, or
        # they would be stopped) get the graze allowance, absolute so that it never accumulates.
        thr = np.where(g0 < TOUCH_UM, -GRAZE_TOL_UM, -CONTACT_TOL_UM)
        thr = np.minimum(thr, g0 - CONTACT_TOL_UM)
        kc = max(2, math.ceil(float(Uq.max()) * horizon / SAMPLE_UM) + 1)
        taus = np.linspace(0.0, horizon, kc)
        G = self._gaps(self._poses_at(p0, motion, ctx, taus), ci, cj)
        dtau = taus[1] - taus[0]
        bad = G[1:] < thr
        lower = 0.5 * (G[:-1] + G[1:] - Uq * dtau)  # Lipschitz lower bound of the true gap between samples
        unsafe = bad | (lower < thr)
        for k in np.flatnonzero(unsafe.any(axis=1)):
            qs = np.flatnonzero(unsafe[k])
            found = self._refine(p0, motion, ctx, taus[k], taus[k + 1], ci[qs], cj[qs], thr[qs], Uq[qs])
            if found is not None:
                return found
        return None

    def _refine(self, p0, motion, ctx, a, b, ci, cj, thr, Uq):
        kf = max(2, math.ceil(float(Uq.max()) * (b - a) / MIN_STEP_UM) + 1)
        taus = np.linspace(a, b, kf)
        G = self._gaps(self._poses_at(p0, motion, ctx, taus), ci, cj)
        bad = (G < thr).any(axis=1)
        if not bad[1:].any():
            return None
        f = int(np.argmax(bad[1:])) + 1
        lo, hi = taus[f - 1], taus[f]
        umax = float(Uq.max())
        for _ in range(24):
            if (hi - lo) * umax <= BISECT_UM:
                break
            mid = lo + (hi - lo) * np.arange(1, 16) / 16.0
            Gm = self._gaps(self._poses_at(p0, motion, ctx, mid), ci, cj)
            badm = (Gm < thr).any(axis=1)
            if badm.any():
                k = int(np.argmax(badm))
                hi = mid[k]
                lo = mid[k - 1] if k > 0 else lo
            else:
                lo = mid[-1]
        Gh = self._gaps(self._poses_at(p0, motion, ctx, np.array([hi])), ci, cj)[0]
        pairs = [(int(x), int(y)) for x, y, g, t in zip(ci, cj, Gh, thr, strict=False) if g < t]
        return lo, pairs

    # -- contact rules -------------------------------------------------------------------------------

    def _evaluate(self, ctx, t_abs: float, forced: set[int]) -> _Motion:
        """Apply the contact rules at the current poses; return how everyone moves next."""
        speed, kappa, straight, _ = ctx
        n = self.n
        P = self._pose
        hl, hw = self._hl, self._hw
        mode = np.full(n, _FREE)
        mode[speed <= 0] = _HELD
        for k in forced:
            mode[k] = _HELD
        slide_v = np.zeros((n, 2))
        slide_end = np.full(n, math.inf)
        excluded: set = set()
        ii, jj = self._I, self._J
        arena = self.scenario.arena_um
        d0 = _depth(P[ii], P[jj], hl[ii], hw[ii], hl[jj], hw[jj]) if ii.size else np.zeros(0)
        g0 = _arena_gap(P, hl, hw, arena) if arena is not None else np.full(n, np.inf)
        if not ((d0 > -NEAR_UM).any() or (g0 < NEAR_UM).any()):  # nothing near anything: all free
            self._contacts = {}
            return _Motion(mode, slide_v, slide_end, excluded, False)
        kappa = kappa + self._drift.curvature_at(self._odo)
        probe = move(P, PROBE_UM, kappa)  # each robot alone, a hair further along its own motion
        # Touching pairs and whether each side's motion pushes into the other.
        push, approach, touching = self._touch_graph(probe, d0)
        if arena is not None:
            gp = _arena_gap(probe, hl, hw, arena)
            for i in np.flatnonzero((g0 < TOUCH_UM) & (g0 - gp > PUSH_EPS_UM)).tolist():
                push.setdefault(i, []).append(ARENA)
        close = np.flatnonzero(d0 > -NEAR_UM)
        near_pairs = {(int(a), int(b)) for a, b in zip(ii[close], jj[close], strict=True)}
        arena_near = set(np.flatnonzero(g0 < NEAR_UM).tolist())

        def near(a: int, b: int) -> bool:
            return a in arena_near if b == ARENA else (min(a, b), max(a, b)) in near_pairs

        pushers = set(push)
        static = pushers | set(np.flatnonzero(speed <= 0).tolist()) | forced
        outcomes: dict[tuple[int, int], tuple[str, str]] = {}
        done: set[int] = set(forced)
        slide_partner: dict[int, int] = {}

        # 1. Self-aligning compliance: two free straight robots meeting head-on.
        for i, j in sorted({(min(a, b), max(a, b)) for a in pushers for b in push[a] if b != ARENA}):
            if i in done or j in done or not self._head_on(i, j, straight, speed, approach):
                continue
            outcomes[(i, j)] = outcomes[(j, i)] = self._self_align_cached(i, j, straight)
            mode[i] = mode[j] = _HELD
            done |= {i, j}

        # 2. Each remaining robot that pushes into something.
        for i in sorted(pushers - done):
            mode[i] = _HELD
            slide = self._push_outcome(i, push[i], static, ctx, touching.get(i, []), outcomes)
            if slide is not None:
                j, (slide_v[i], slide_end[i]) = slide
                mode[i] = _SLIDE
                slide_partner[i] = j
                excluded.add((min(i, j), max(i, j)))

        # A slide is along a body that stays put; if the partner moves after all, stop instead.
        for i in np.flatnonzero(mode == _SLIDE).tolist():
            j = slide_partner[i]
            if mode[j] != _HELD:
                mode[i] = _HELD
                slide_end[i] = math.inf
                excluded.discard((min(i, j), max(i, j)))
                outcomes[(i, j)] = ("contact", "stopped against a moving robot")
        self._remember_contacts(outcomes, t_abs, near)
        recheck = any(
            mode[i] == _HELD and j >= 0 and mode[j] != _HELD for (i, j) in outcomes
        )
        return _Motion(mode, slide_v, slide_end, excluded, recheck)

    def _touch_graph(self, probe: np.ndarray, d0: np.ndarray):
        """``(push, approach, touching)`` of the touching pairs: whom each robot's own motion pushes into,
        the approach rate of each ordered pair (um per um driven) and whom each robot touches."""
        P, hl, hw = self._pose, self._hl, self._hw
        ii, jj = self._I, self._J
        push: dict[int, list[int]] = {}
        approach: dict[tuple[int, int], float] = {}
        touching: dict[int, list[int]] = {}
        if not ii.size:
            return push, approach, touching
        t = np.flatnonzero(d0 > -TOUCH_UM)
        if not t.size:
            return push, approach, touching
        a, b = ii[t], jj[t]
        da = _depth(probe[a], P[b], hl[a], hw[a], hl[b], hw[b]) - d0[t]
        db = _depth(P[a], probe[b], hl[a], hw[a], hl[b], hw[b]) - d0[t]
        for x, y, rx, ry in zip(a.tolist(), b.tolist(), da.tolist(), db.tolist(), strict=False):
            touching.setdefault(x, []).append(y)
            touching.setdefault(y, []).append(x)
            approach[(x, y)] = rx / PROBE_UM
            approach[(y, x)] = ry / PROBE_UM
            if rx > PUSH_EPS_UM:
                push.setdefault(x, []).append(y)
            if ry > PUSH_EPS_UM:
                push.setdefault(y, []).append(x)
        return push, approach, touching

    def _self_align_cached(self, i: int, j: int, straight) -> tuple[str, str]:
        """``(kind, detail)`` of self-aligning compliance between i and j, remembered while nothing moves."""
        key = self._rule_key(i, j, straight)
        hit = self._rule_cache.get((i, j))
        if hit is not None and hit[0] == key:
            return hit[1]
        kind, detail = self._self_align(i, j)
        self._rule_cache[(i, j)] = (self._rule_key(i, j, straight), (kind, detail))
        return kind, detail

    def _push_outcome(self, i: int, cs: list[int], static: set[int], ctx, touching_i: list[int],
                      outcomes: dict[tuple[int, int], tuple[str, str]]):
        """The outcome of robot i pushing into the bodies ``cs`` (written to ``outcomes``); ``(j, (slide
        velocity, slide end))`` when i slides along body j, else None (i is held)."""
        straight = ctx[2]
        if not straight[i]:
            # Arriving flush in its slot is docking, whatever the arm does (SPEC 6): a robot that turns
            # into its slot on an arc is docked there, and stays docked while it keeps pushing.
            flush = [j for j in cs if j != ARENA and j in static and self._flush_cached(i, j, straight)]
            for j in cs:
                outcomes[(i, j)] = (
                    ("dock", "arrived flush against the structure") if j in flush
                    else ("blocked", "a turning robot cannot pivot off an obstacle")
                )
            if flush:
                self._docked[i] = True
                self._stuck[i] = False
            return None
        if ARENA in cs:
            self._arena_hit[i] = True
            for j in cs:
                outcomes[(i, j)] = ("arena", "stopped at the arena edge") if j == ARENA else ("contact", "stopped")
            return None
        fronts = [j for j in cs if j in static]
        if len(cs) == 1 and fronts:
            j = cs[0]
            key = self._rule_key(i, j, straight)
            hit = self._rule_cache.get((i, j))
            if hit is not None and hit[0] == key:
                (kind, detail), slide = hit[1], None
            else:
                kind, detail, slide = self._dock_rule(i, j, ctx, touching_i)
                if slide is None:  # held outcomes repeat while nothing moves; slides are recomputed
                    self._rule_cache[(i, j)] = (self._rule_key(i, j, straight), (kind, detail))
            outcomes[(i, j)] = (kind, detail)
            return None if slide is None else (j, slide)
        if len(cs) > 1 and len(fronts) == len(cs):
            flush = [j for j in cs if self._flush_cached(i, j, straight)]
            for j in cs:
                outcomes[(i, j)] = ("dock", "flush against the structure") if flush else ("stuck", "pushing into several bodies")
            self._docked[i] = bool(flush)
            self._stuck[i] = not flush
            return None
        for j in cs:
            outcomes[(i, j)] = ("contact", "stopped against a moving robot" if j not in static else "stopped")
        return None

    def _remember_contacts(self, outcomes: dict[tuple[int, int], tuple[str, str]], t_abs: float, near) -> None:
        """Log changes of outcome. Outcomes are remembered while the pair stays within NEAR_UM, so two
        robots jostling against each other do not log every touch."""
        for pair in sorted(outcomes):
            kind, detail = outcomes[pair]
            if self._contacts.get(pair) != kind:
                self._log(t_abs, pair[0], kind, pair[1], detail)
        memory = {k: v[0] for k, v in outcomes.items()}
        for pair, kind in self._contacts.items():
            if pair not in memory and near(*pair):
                memory[pair] = kind
        self._contacts = memory

    def _head_on(self, i: int, j: int, straight, speed, approach) -> bool:
        """Whether touching robots i and j meet head-on (the situation of self-aligning compliance).

        Both drive straight and neither is docked (a structure's member is a static body: rule 4), their
        headings are opposed, the pair closes (at least one pushes, and together they approach), and
        every contact point lies in the front half of both bodies: front edge on front edge, a front
        corner on a front corner, or a front corner on the other's long side near its front. Whether
        they then form G_1 is decided by the seed's limits (:meth:`_self_align`), not here.
        """
        if not (straight[i] and straight[j]) or speed[i] <= 0 or speed[j] <= 0:
            return False
        if self._docked[i] or self._docked[j]:
            return False
        P = self._pose
        if math.cos(P[i, 2] - P[j, 2]) >= 0.0 or approach[(i, j)] + approach[(j, i)] <= 0.0:
            return False
        pts, _ = self._contact_points(i, j)
        return bool((_local(pts, P[i])[0] >= 0.0).all() and (_local(pts, P[j])[0] >= 0.0).all())

    def _rule_key(self, i: int, j: int, straight) -> bytes:
        """What a contact rule's outcome depends on: the arm kinds of i and j and, bit for bit, the poses
        of every robot a compliance move of i or j could reach (itself included)."""
        P = self._pose
        reach = 2.0 * self._hd[[i, j]][:, None] + self._hd[None, :] + 1.0
        d = np.hypot(P[None, :, 0] - P[[i, j], 0][:, None], P[None, :, 1] - P[[i, j], 1][:, None])
        near = np.flatnonzero((d < reach).any(axis=0))
        return bytes([bool(straight[i]), bool(straight[j])]) + near.tobytes() + P[near].tobytes()

    def _contact_points(self, i: int, j: int):
        """Touching corners: ``(points (k, 2), is_corner_of_i (k,))`` of bodies i and j."""
        P = self._pose
        ci = body_corners(P[i], 2 * self._hl[i], 2 * self._hw[i])[0]
        cj = body_corners(P[j], 2 * self._hl[j], 2 * self._hw[j])[0]
        depth = float(_depth(P[i], P[j], self._hl[i], self._hw[i], self._hl[j], self._hw[j]))
        eps = max(TOUCH_UM, 2.0 * depth) + 1e-9
        di = point_rectangle_distance(ci, P[j], 2 * self._hl[j], 2 * self._hw[j])[0]
        dj = point_rectangle_distance(cj, P[i], 2 * self._hl[i], 2 * self._hw[i])[0]
        pts = np.vstack([ci[di <= eps], cj[dj <= eps]])
        own = np.concatenate([np.ones(int((di <= eps).sum()), bool), np.zeros(int((dj <= eps).sum()), bool)])
        if pts.shape[0] == 0:  # degenerate crossing: fall back to the nearest corners
            pts = np.vstack([ci[[int(np.argmin(di))]], cj[[int(np.argmin(dj))]]])
            own = np.array([True, False])
        return pts, own

    def _front_face(self, i: int, j: int, pts):
        """For robot i pressing its front on body j: ``(contact point, outward normal of j's face, alpha)``,
        or ``None`` when the contact is not on i's front edge."""
        P = self._pose
        u, v = _local(pts, P[i])
        tol = 1e-3 + max(0.0, float(_depth(P[i], P[j], self._hl[i], self._hw[i], self._hl[j], self._hw[j])))
        if not np.all((np.abs(u - self._hl[i]) <= tol) & (np.abs(v) <= self._hw[i] + tol)):
            return None
        c = pts.mean(axis=0)
        h = np.array([math.sin(P[i, 2]), math.cos(P[i, 2])])
        # The face of j that i's front meets. A contact at a corner of j lies on two faces: keep those
        # it is not behind (e.g. a corner sliding along one face onto a collinear one is already past
        # the other), then take the one most opposed to i's heading.
        faces = _faces_touched(pts, P[j], self._hl[j], self._hw[j], tol)
        best = max(out for _, out in faces)
        nrm = max((m for m, out in faces if out >= best - FACE_TIE_UM), key=lambda m: float(-(m @ h)))
        alpha = angle_difference(P[i, 2], _heading_of(-nrm))
        return c, nrm, float(alpha)

    def _flush_cached(self, i: int, j: int, straight) -> bool:
        """:meth:`_flush`, remembered while nothing near the pair moves (a blocked robot is asked every
        evaluation); headings not square to each other are not flush (cheap test first)."""
        d = (self._pose[i, 2] - self._pose[j, 2]) % (0.5 * math.pi)
        if min(d, 0.5 * math.pi - d) > FLUSH_TOL_RAD:
            return False
        key = self._rule_key(i, j, straight)
        hit = self._flush_cache.get((i, j))
        if hit is None or hit[0] != key:
            hit = (key, self._flush(i, j))
            self._flush_cache[(i, j)] = hit
        return hit[1]

    def _flush(self, i: int, j: int) -> bool:
        pts, own = self._contact_points(i, j)
        ff = self._front_face(i, j, pts)
        return ff is not None and abs(ff[2]) <= FLUSH_TOL_RAD

    def _dock_rule(self, i: int, j: int, ctx, touching: Iterable[int]):
        """Straight robot i pushing into static body j: docking compliance, slide or stuck.

        Returns ``(kind, detail, slide)`` with ``slide = (velocity (2,), duration_s)`` for a slide.
        """
        P = self._pose
        speed = ctx[0]
        pts, own = self._contact_points(i, j)
        ff = self._front_face(i, j, pts)
        name_j = self._names[j]
        if ff is None:
            u, v = _local(pts, P[i])
            if np.all(np.abs(np.abs(v) - self._hw[i]) <= 1e-3) and not own.any():
                # j's corner on i's long side: i slides past it, straight on.
                h = np.array([math.sin(P[i, 2]), math.cos(P[i, 2])])
                dist = float(np.max(u) + self._hl[i]) + SLIDE_OVERSHOOT_UM
                return "graze", f"slides past a corner of {name_j}", (speed[i] * h, dist / speed[i])
            self._stuck[i] = False
            return "contact", "stopped (contact not on its front)", None
        c, nrm, alpha = ff
        deg = math.degrees(alpha)
        if abs(alpha) <= STICKING_CONE_RAD:
            phi, blocker = self._sweep(i, c, -alpha)
            self._pose[i] = _rotate_about(P[i], c, phi)
            if blocker is None:
                self._docked[i] = True
                self._stuck[i] = False
                return "dock", f"docking compliance: incidence {deg:.2f} deg inside the sticking cone, now flush", None
            self._stuck[i] = True
            self._docked[i] = False
            return "stuck", f"docking compliance ({deg:.2f} deg) obstructed by {self._label(blocker)}", None
        if own.any():
            h = np.array([math.sin(P[i, 2]), math.cos(P[i, 2])])
            t = h - float(h @ nrm) * nrm
            t /= np.linalg.norm(t)
            vel = speed[i] * float(h @ t) * t
            # The face of j with normal nrm: its corners; the slide ends past the one ahead.
            cj = body_corners(P[j], 2 * self._hl[j], 2 * self._hw[j])[0]
            on_face = cj[np.argsort(-(cj - P[j, :2]) @ nrm)[:2]]
            dist = float(np.max((on_face - c) @ t)) + SLIDE_OVERSHOOT_UM
            if dist > 0.0 and not self._slide_blocked(i, vel, [k for k in touching if k != j]):
                self._stuck[i] = False
                return ("slide", f"incidence {deg:.1f} deg outside the sticking cone: slides along {name_j} (H)",
                        (vel, dist / float(np.linalg.norm(vel))))
            self._stuck[i] = True
            return "stuck", f"incidence {deg:.1f} deg outside the sticking cone and cannot slide (H)", None
        self._stuck[i] = True
        return "stuck", f"incidence {deg:.1f} deg outside the sticking cone on a corner of {name_j} (H)", None

    def _slide_blocked(self, i: int, vel, others: list[int]) -> bool:
        """Whether sliding with ``vel`` pushes robot i into another body it touches (or the arena)."""
        P = self._pose
        step = PROBE_UM / max(float(np.linalg.norm(vel)), 1e-300)
        q = P[i].copy()
        q[:2] += vel * step
        for k in others:
            d0 = _depth(P[i], P[k], self._hl[i], self._hw[i], self._hl[k], self._hw[k])
            d1 = _depth(q, P[k], self._hl[i], self._hw[i], self._hl[k], self._hw[k])
            if d1 - d0 > PUSH_EPS_UM:
                return True
        if self.scenario.arena_um is not None:
            a = self.scenario.arena_um
            g0 = _arena_gap(P[i], self._hl[i], self._hw[i], a)
            if g0 < TOUCH_UM and g0 - _arena_gap(q, self._hl[i], self._hw[i], a) > PUSH_EPS_UM:
                return True
        return False

    def _sweep(self, i: int, c, phi: float):
        """Rotate robot i about ``c`` by up to ``phi`` (rad); stop at first touch of another body.

        Returns ``(phi_reached, blocker)``; ``blocker`` is a robot index, ``ARENA`` or ``None``.
        """
        if abs(phi) < 1e-12:
            return phi, None
        P = self._pose
        corners = body_corners(P[i], 2 * self._hl[i], 2 * self._hw[i])[0]
        reach = float(np.max(np.hypot(*(corners - c).T)))
        m = int(min(max(2, math.ceil(abs(phi) * reach / SWEEP_UM)), 4000))
        others = np.array([k for k in range(self.n) if k != i], dtype=int)
        ci = np.full(others.size, i)
        cj = others
        if self.scenario.arena_um is not None:
            ci = np.append(ci, i)
            cj = np.append(cj, ARENA)
        if ci.size == 0:
            return phi, None

        def gaps(phis):
            poses = np.repeat(P[None], np.size(phis), axis=0)
            poses[:, i] = _rotate_about(P[i], c, phis)
            return self._gaps(poses, ci, cj)

        g0 = gaps(np.zeros(1))[0]
        thr = np.minimum(-GRAZE_TOL_UM, g0 - CONTACT_TOL_UM)
        phis = phi * np.arange(1, m + 1) / m
        bad = gaps(phis) < thr
        rows = bad.any(axis=1)
        if not rows.any():
            return phi, None
        k = int(np.argmax(rows))
        lo, hi = (phis[k - 1] if k else 0.0), phis[k]
        for _ in range(60):
            mid = 0.5 * (lo + hi)
            if (gaps(np.array([mid]))[0] < thr).any():
                hi = mid
            else:
                lo = mid
            if abs(hi - lo) * reach < BISECT_UM:
                break
        col = int(np.argmax(bad[k]))
        return lo, int(cj[col])

    def _self_align(self, i: int, j: int) -> tuple[str, str]:
        """Two straight robots meeting head-on: form G_1 within the seed's limits, else stuck."""
        P = self._pose
        alpha = float(angle_difference(P[i, 2], P[j, 2] + math.pi))
        hi_ = np.array([math.sin(P[i, 2]), math.cos(P[i, 2])])
        hj_ = np.array([math.sin(P[j, 2]), math.cos(P[j, 2])])
        axis = hi_ - hj_
        axis /= np.linalg.norm(axis)
        th = _heading_of(axis)
        mi = P[i, :2] + self._hl[i] * hi_
        mj = P[j, :2] + self._hl[j] * hj_
        across = np.array([math.cos(th), -math.sin(th)])
        w_y = float((mj - mi) @ across)
        nums = f"alpha {math.degrees(alpha):.1f} deg, w_y {w_y:.1f} um"
        if abs(alpha) >= SELF_ALIGN_MAX_INCIDENCE_RAD or abs(w_y) >= SELF_ALIGN_MAX_OFFSET_UM:
            self._stuck[[i, j]] = True
            self._docked[[i, j]] = False
            return "stuck", f"head-on outside the self-alignment limits ({nums}) (H)"
        junction = 0.5 * (mi + mj)
        new_i = np.array([*(junction - self._hl[i] * axis), wrap(th)])
        new_j = np.array([*(junction + self._hl[j] * axis), wrap(th + math.pi)])
        others = np.array([k for k in range(self.n) if k not in (i, j)], dtype=int)
        if others.size or self.scenario.arena_um is not None:
            ci = np.concatenate([np.full(others.size, i), np.full(others.size, j)])
            cj = np.concatenate([others, others])
            if self.scenario.arena_um is not None:
                ci = np.append(ci, [i, j])
                cj = np.append(cj, [ARENA, ARENA])
            before = self._gaps(P[None], ci, cj)[0]
            moved = P.copy()
            moved[i], moved[j] = new_i, new_j
            after = self._gaps(moved[None], ci, cj)[0]
            if (after < np.minimum(-GRAZE_TOL_UM, before - CONTACT_TOL_UM)).any():
                self._stuck[[i, j]] = True
                self._docked[[i, j]] = False
                return "stuck", f"self-alignment ({nums}) obstructed by a third body (H)"
        self._pose[i], self._pose[j] = new_i, new_j
        self._docked[[i, j]] = True
        self._stuck[[i, j]] = False
        return "self_align", f"G_1 formed ({nums})"

    # -- bookkeeping ---------------------------------------------------------------------------------

    def _label(self, k: int) -> str:
        return "the arena edge" if k == ARENA else self._names[k]

    def _log(self, t: float, i: int, kind: str, other: int | None, detail: str) -> None:
        who = None if other is None else ("arena" if other == ARENA else self._names[other])
        self._events.append(SimEvent(float(t), self._names[i], kind, who, detail))


# ----------------------------------------------------------------------------------------------------
# Plans, determinism


def plan_waveform(scenario, plan, *, source: str | None = None) -> tuple[Segment, ...]:
    """The voltage waveform of a plan on this scenario's design (synthesised from all-up)."""
    from .electrostatics import analyse_scenario
    from .waveform import steps_from_plan, synthesize

    analysis = analyse_scenario(scenario)
    return synthesize(analysis, steps_from_plan(plan, analysis, source=source))


def run_plan(scenario, plan, *, seed: int | None = 0, record: bool = False, source: str | None = None) -> SimulatedPlant:
    """Execute a plan open loop: its whole waveform on a fresh plant from the start poses."""
    plant = SimulatedPlant(scenario, seed=seed, record=record)
    plant.apply(plan_waveform(scenario, plan, source=source))
    return plant


def _state(plant: SimulatedPlant, obs) -> dict[str, Any]:
    return {
        "true poses": plant.true_poses(),
        "observation": obs,
        "time_s": np.array([plant.time_s]),
        "docked": plant.docked,
        "stuck": plant.stuck,
        "arm states": plant.arm_states,
        "events": plant.events,
    }


def _first_difference(a: dict[str, Any], b: dict[str, Any], names: Sequence[str]) -> str | None:
    """The first quantity that differs between two states, bit for bit (NaN equals NaN)."""
    for key in a:
        x, y = a[key], b[key]
        if key == "events":
            if x != y:
                k = next((m for m, (p, q) in enumerate(zip(x, y, strict=False)) if p != q), min(len(x), len(y)))
                px = x[k] if k < len(x) else "nothing"
                py = y[k] if k < len(y) else "nothing"
                return f"event {k} differs: {px} vs {py}"
            continue
        if x is None and y is None:
            continue
        xa, ya = np.atleast_1d(np.asarray(x)), np.atleast_1d(np.asarray(y))
        if xa.shape != ya.shape:
            return f"{key}: shapes {xa.shape} vs {ya.shape}"
        for r in range(xa.shape[0]):
            if xa[r].tobytes() != ya[r].tobytes():
                who = f" of robot {names[r]}" if key != "time_s" else ""
                return f"{key}{who}: {xa[r].tolist()} vs {ya[r].tolist()}"
    return None


def check_determinism(
    scenario,
    waveforms: Sequence[Sequence[Segment]],
    seed: int,
    *,
    observe: bool = True,
    plant_factory=None,
) -> None:
    """Prove that a seed fixes a run bit for bit (in the spirit of Gymnasium's ``check_env``).

    Two plants with the same seed receive the same waveforms (and, with ``observe``, a camera frame after
    each); after every step their true poses, observations, time, flags, arm states and event logs must
    be bit-identical. A :meth:`SimulatedPlant.copy` taken halfway must then replay the second half
    bit-identically too.

    ``plant_factory(scenario, seed=...)`` builds the plants (default :class:`SimulatedPlant`; a subclass
    must keep its methods and ``copy``).

    Raises
    ------
    AssertionError
        Naming the first step and quantity that differ.
    """
    make = SimulatedPlant if plant_factory is None else plant_factory
    wfs = [tuple(w) for w in waveforms]
    a = make(scenario, seed=seed)
    b = make(scenario, seed=seed)
    half = len(wfs) // 2
    snapshot: list[dict[str, Any]] = []
    twin = None
    for k, wf in enumerate(wfs):
        if k == half:
            twin = a.copy()
        sa: list[Any] = []
        sb: list[Any] = []
        for plant, out in ((a, sa), (b, sb)):
            plant.apply(wf)
            out.append(_state(plant, plant.observe() if observe else None))
        diff = _first_difference(sa[0], sb[0], a.names)
        if diff is not None:
            raise AssertionError(f"seed {seed}, waveform {k}: two runs differ: {diff}")
        snapshot.append(sa[0])
    if twin is None:
        return
    for k in range(half, len(wfs)):
        twin.apply(wfs[k])
        st = _state(twin, twin.observe() if observe else None)
        diff = _first_difference(snapshot[k], st, a.names)
        if diff is not None:
            raise AssertionError(f"seed {seed}, waveform {k}: a copy taken before waveform {half} diverges: {diff}")

