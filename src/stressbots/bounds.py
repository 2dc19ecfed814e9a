"""Error bounds of the EDR control strategy (seed App. 3.2-3.5, SPEC 6 and 8).

What this module computes, per robot, from a scenario's ``[noise]``:

- ``delta(t)``: how far a robot can drift from its nominal motion after driving a primitive sequence for
  time ``t`` (:func:`deviation_envelope`);
- ``t_theta = theta / omega_hat``: the longest time a turn of ``theta`` can take (:func:`turn_time`);
- the cylinder ``C_alpha,i`` that bounds the forward projection of gross motion, radius
  ``r_alpha = delta_xy(t_2pi)`` and half-height ``h_alpha = delta_theta(t_2pi)`` (:func:`cylinder`);
- the timed forward projection of D_n's uncorrected straight run over ``t_4pi`` of D_{n-1}
  (:func:`timed_forward_projection`);
- the regions ``A_i*`` of intermediate poses from which fine motion plus compliance is guaranteed to
  dock, with a per-robot verdict (:func:`intermediate_region`);
- the reachable cones of two- and three-primitive fine motion of seed Fig. 4 (:func:`fine_motion_cone`,
  :func:`s2f_cone`, :func:`s3f_cones`);
- an empirical check of ``delta(t)`` against the simulator (:func:`empirical_coverage`).

:func:`analyse_bounds` puts it all together for a scenario (``stressbots bounds``).

The error model (SPEC 8: seed eq. 5 is garbled)
-----------------------------------------------
Seed eq. 4 adds errors to the speed and turn rate, ``v_hat = v + v_e`` and ``omega_hat = omega + omega_e``.
The scenario's ``[noise]`` describes them statistically (per-robot speed and radius factors drawn once per
run, a heading drift that is a per-robot bias plus a random walk in the distance driven,
:mod:`stressbots.drift`); a *bound* needs a box. :class:`ErrorModel` takes ``k``-sigma
(default :data:`DEFAULT_K` = 3, i.e. 99.7 % of each factor's draws) of each:

- relative speed error ``|v_e| / v <= a = k sd_v (1 + J)``,
- relative radius error ``|r_e| / r <= b = k sd_r (1 + J)``,
- heading drift ``|d| <= k sd_drift`` (rad per um driven), a constant curvature that covers the per-run bias
  (whose sd is ``sqrt(f) sd_drift``, :data:`stressbots.drift.DEFAULT_DRIFT`) with room,
- plus the drift's random walk, bounded at ``k`` sigma as ``|W(s)| <= c sqrt(s)`` over ``s`` um driven with
  ``c = k sd_drift sqrt((1 - f) S)`` (``S`` = 1 mm). It is added to ``delta(t)`` after the grid: ``c sqrt(s)``
  to the heading and, since a heading error ``e(u)`` displaces the robot by at most ``int |e(u)| du``,
  ``(2/3) c s^(3/2)`` to every position component (``s`` at the fastest speed of the box),

where ``J`` = :data:`SEGMENT_JITTER` is the per-Drive variation the simulator adds on top of the per-run
factors (as a fraction of the same sds), counted at its own ``k`` sigma. Under a turning primitive the
robot then drives at ``v_hat = v (1 + e_v)`` on curvature ``1 / (r (1 + e_r)) + d``; driving straight, on
curvature ``d``. So ``omega_hat = v_hat / r_hat + d v_hat`` and, straight, ``omega_e = d v_hat``.

Each primitive is then the closed-form arc of SPEC 3 (:func:`stressbots.kinematics.move`) with those
values: no numerical integration error. ``delta(t)`` is the largest deviation ``|Delta q_e(t) -
Delta q(t)|``, component by component, over a grid of error values in the box (5 levels per axis, corners
included; errors held constant over the sequence, which is the worst case for the heading), maximised
over every time up to ``t`` (a running maximum, so ``delta`` is a non-decreasing bound valid during the
whole sequence, not only at its end). Deviations are measured in the start frame: ``across`` is to the
robot's right, ``along`` its initial heading; heading deviations are not wrapped (a bound beyond ``pi``
means any heading). ``t_theta`` uses the *slowest* turn rate of the box, so ``t_2pi`` covers every robot
in it; ``C_alpha,i`` is ``delta(t_2pi)`` maximised over pure turning, pure straight motion and S_2f mixes
(which primitives a correction uses is not known in advance).

Why k = 3, and what the bounds say
----------------------------------
A verdict "guaranteed" should mean "for all but a rare run", so the default box is 3 sigma of every
factor. The check against the simulator (:func:`empirical_coverage`, ``benchmarks/bench_bounds.py``)
agrees: with the drift as bias plus random walk (issue 11), 40 trials on the example, simulated open-loop
motion stayed inside ``delta(t)`` at every one of 14,400 checkpoints at k = 3 (error/bound median 0.13,
99th percentile 0.48, max 0.66), at 99.98 % at k = 2 and at 89 % at k = 1. The seed's construction
is conservative: at the literature's noise (speed 5 %, radius 3 %, 3.7 deg/mm) a full turn's heading
error ``delta_theta(t_2pi)`` exceeds the compliance cones, so no ``A_i*`` exists and nothing is
guaranteed; :func:`critical_noise_scales` reports the noise level up to which it would be (about 0.06 to
0.27 of the literature's on the 4-robot example). The closed-loop controller does much better than this
worst case because it measures and re-plans; Monte Carlo (:mod:`stressbots.montecarlo`) measures that.

Assumptions and simplifications (documented, not hidden)
--------------------------------------------------------
- The camera's error (``k`` sigma per axis) is added to ``C_alpha,i``: gross motion ends on a *measured*
  pose, so the true pose is uncertain by the camera error as well.
- The fine-motion trajectory is the seed's single arc from ``a_i`` through the goal's reference point
  ``p_g,i`` (eq. 1 corrected, :func:`stressbots.paths.arc_through`), realisable by interpolated turning
  when ``r' >= r (1 + b)`` (the largest radius the robot might really have). Its own heading error,
  ``turn ((1 + a)/(1 - b) - 1) + s (1 + a) d`` for a turn over arc length ``s``, is taken off the
  compliance cone; its position error is left to the iterative re-planning of ``r'`` (seed App. 3.1).
- G_i* is the goal enlarged by compliance (App. 3.5): arrival within the +-45 deg sticking cone for a
  docking robot; for the G_1 pair, incidence ``|alpha| < 60 deg`` and lateral misalignment ``|w_y| < 80
  um``, each robot against its partner's slot (the partner's own error is in its own region).
- ``A_i*`` is sampled on a grid (x, y, theta) around the slot: the nominal preimage of G_i* outside C_O
  (the docking object expanded by ``2 r*``, :meth:`stressbots.structures.Structure.proximity_region`)
  and inside the arena, with arcs that do not cross the docking object, eroded by the cylinder (radius
  ``r_alpha + spacing/2`` in the plane, ``h_alpha`` in heading). Only the docking object is an
  obstacle (orbiting robots are the planner's business). Beyond the sampled window the preimage is
  assumed to continue as at its edge.
- For D_n the erosion uses the timed forward projection of its straight run instead of ``C_alpha,n``.

Everything here is deterministic; randomness (only in :func:`empirical_coverage`) comes from an explicit
seed.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from typing import Any, NamedTuple

import numpy as np

from .kinematics import TWO_PI, follow, move
from .robots import Pose, angle_difference

__all__ = [
    "DEFAULT_K",
    "SEGMENT_JITTER",
    "STICKING_CONE_RAD",
    "SELF_ALIGN_MAX_INCIDENCE_RAD",
    "SELF_ALIGN_MAX_OFFSET_UM",
    "ErrorModel",
    "PrimitiveSequence",
    "DeltaCurve",
    "Cylinder",
    "ForwardProjection",
    "Region",
    "Cone",
    "RobotBounds",
    "Coverage",
    "BoundsReport",
    "turn_rate_range",
    "turn_time",
    "sequence_poses",
    "deviation_envelope",
    "turning_sequence",
    "straight_sequence",
    "s2f_sequence",
    "cylinder",
    "timed_forward_projection",
    "fine_motion_heading_error",
    "fine_motion_preimage",
    "intermediate_region",
    "arc_points",
    "fine_motion_cone",
    "s2f_cone",
    "s3f_cones",
    "empirical_coverage",
    "analyse_bounds",
    "critical_noise_scales",
]

DEFAULT_K = 3.0
"""Default number of standard deviations of each error factor that the bounds cover."""

SEGMENT_JITTER = 0.2
"""Per-Drive variation of speed and radius as a fraction of the per-run sds (equals
:data:`stressbots.sim.SEGMENT_JITTER`; a test keeps them equal)."""

STICKING_CONE_RAD = math.radians(45.0)
"""Docking compliance: the sticking cone's half-angle (seed App. 3.5)."""

SELF_ALIGN_MAX_INCIDENCE_RAD = math.radians(60.0)
"""Self-aligning compliance (G_1): largest incidence |alpha| (rad)."""

SELF_ALIGN_MAX_OFFSET_UM = 80.0
"""Self-aligning compliance (G_1): largest lateral misalignment |w_y| (um)."""

_MIN_FACTOR = 0.1  # the simulator floors speed and radius factors here


def _walk_scale_sqrt_um() -> float:
    """``sqrt((1 - f) S)`` (sqrt um) of the simulator's drift model: the walk's sd per unit ``sd_drift``."""
    from .drift import DEFAULT_DRIFT

    return math.sqrt((1.0 - DEFAULT_DRIFT.bias_share) * DEFAULT_DRIFT.reference_um)


# ----------------------------------------------------------------------------------------------------
# The error model


@dataclass(frozen=True)
class ErrorModel:
    """A box of control and sensing errors: the k-sigma bounds of a scenario's ``[noise]``.

    Attributes
    ----------
    speed_rel:
        ``a``: bound of the relative speed error ``|v_e| / v``.
    radius_rel:
        ``b``: bound of the relative turning-radius error.
    drift_rad_per_um:
        ``d``: bound of the heading drift's bias (rad per um driven, either sign), added to the curvature.
    drift_walk_rad_per_sqrt_um:
        ``c``: bound of the heading drift's random walk, ``|W(s)| <= c sqrt(s)`` over ``s`` um driven.
    camera_position_um:
        Bound of the camera's position error per axis (um).
    camera_heading_rad:
        Bound of the camera's heading error (rad).
    k:
        The number of standard deviations these bounds represent.
    """

    speed_rel: float = 0.0
    radius_rel: float = 0.0
    drift_rad_per_um: float = 0.0
    camera_position_um: float = 0.0
    camera_heading_rad: float = 0.0
    k: float = DEFAULT_K
    drift_walk_rad_per_sqrt_um: float = 0.0

    @classmethod
    def from_noise(cls, noise, k: float = DEFAULT_K, *, jitter: float = SEGMENT_JITTER) -> ErrorModel:
        """``k``-sigma bounds of a :class:`~stressbots.scenario.Noise` (see the module notes)."""
        if not (math.isfinite(k) and k >= 0):
            raise ValueError(f"k must be a finite number >= 0, got {k!r}")
        grow = 1.0 + float(jitter)
        return cls(
            speed_rel=k * noise.speed_rel_sd * grow,
            radius_rel=k * noise.turn_radius_rel_sd * grow,
            drift_rad_per_um=k * noise.heading_drift_rad_per_um,
            drift_walk_rad_per_sqrt_um=k * noise.heading_drift_rad_per_um * _walk_scale_sqrt_um(),
            camera_position_um=k * noise.camera_position_sd_um,
            camera_heading_rad=k * noise.camera_heading_sd_rad,
            k=float(k),
        )

    @property
    def is_zero(self) -> bool:
        return self.speed_rel == 0.0 and self.radius_rel == 0.0 and self.drift_rad_per_um == 0.0 and self.drift_walk_rad_per_sqrt_um == 0.0

    def walk_heading(self, s_um):
        """Bound (rad) of the drift's random walk over ``s_um`` driven: ``c sqrt(s)``."""
        return self.drift_walk_rad_per_sqrt_um * np.sqrt(np.maximum(np.asarray(s_um, dtype=np.float64), 0.0))

    def walk_displacement(self, s_um):
        """Bound (um) of the displacement the walk's heading error causes over ``s_um``: ``(2/3) c s^1.5``."""
        s = np.maximum(np.asarray(s_um, dtype=np.float64), 0.0)
        return (2.0 / 3.0) * self.drift_walk_rad_per_sqrt_um * s * np.sqrt(s)

    @property
    def speed_factors(self) -> tuple[float, float]:
        """Smallest and largest speed factor ``1 + e_v`` (floored like the simulator's)."""
        return max(1.0 - self.speed_rel, _MIN_FACTOR), 1.0 + self.speed_rel

    @property
    def radius_factors(self) -> tuple[float, float]:
        """Smallest and largest radius factor ``1 + e_r``."""
        return max(1.0 - self.radius_rel, _MIN_FACTOR), 1.0 + self.radius_rel

    def samples(self, levels: int = 5) -> np.ndarray:
        """Error values ``(G, 3)`` = ``(e_v, e_r, d)`` on a grid over the box (corners included).

        ``e_v``, ``e_r`` are relative errors (factors minus one), ``d`` curvature drift (1/um).
        Axes whose bound is zero contribute one level.
        """
        levels = max(int(levels), 2)
        (v_lo, v_hi), (r_lo, r_hi) = self.speed_factors, self.radius_factors
        ev = np.unique(np.linspace(v_lo - 1.0, v_hi - 1.0, levels))
        er = np.unique(np.linspace(r_lo - 1.0, r_hi - 1.0, levels))
        dd = np.unique(np.linspace(-self.drift_rad_per_um, self.drift_rad_per_um, levels))
        g = np.stack(np.meshgrid(ev, er, dd, indexing="ij"), axis=-1).reshape(-1, 3)
        return g

    def to_dict(self) -> dict[str, Any]:
        return {
            "k_sigma": self.k,
            "speed_rel": self.speed_rel,
            "radius_rel": self.radius_rel,
            "heading_drift_deg_per_mm": math.degrees(self.drift_rad_per_um) * 1000.0,
            "heading_drift_walk_deg_per_sqrt_mm": math.degrees(self.drift_walk_rad_per_sqrt_um) * math.sqrt(1000.0),
            "camera_position_um": self.camera_position_um,
            "camera_heading_deg": math.degrees(self.camera_heading_rad),
        }


def turn_rate_range(speed_um_s, radius_um, model: ErrorModel) -> tuple[np.ndarray, np.ndarray]:
    """Slowest and fastest turn rate ``omega_hat`` (rad/s) under a turning primitive.

    ``omega_hat = v (1 + e_v) (1 / (r (1 + e_r)) + d)``, extreme over the box. The slowest is ``<= 0``
    only for absurd drift (a turn never completes).
    """
    v = np.asarray(speed_um_s, dtype=np.float64)
    r = np.asarray(radius_um, dtype=np.float64)
    (v_lo, v_hi), (r_lo, r_hi) = model.speed_factors, model.radius_factors
    d = model.drift_rad_per_um
    w_min = v * v_lo * (1.0 / (r * r_hi) - d)
    w_max = v * v_hi * (1.0 / (r * r_lo) + d)
    return w_min, w_max


def turn_time(theta_rad, speed_um_s, radius_um, model: ErrorModel):
    """``t_theta = theta / omega_hat``: the longest time (s) a turn of ``theta`` can take (seed App. 3.4).

    Uses the slowest turn rate of :func:`turn_rate_range` so that the bound covers every robot in the
    box; ``inf`` when that rate is not positive.
    """
    w_min, _ = turn_rate_range(speed_um_s, radius_um, model)
    with np.errstate(divide="ignore"):
        t = np.where(w_min > 0, np.asarray(theta_rad, dtype=np.float64) / np.where(w_min > 0, w_min, 1.0), np.inf)
    return float(t) if np.ndim(t) == 0 else t


# ----------------------------------------------------------------------------------------------------
# Primitive sequences and delta(t)


@dataclass(frozen=True, eq=False)
class PrimitiveSequence:
    """One robot's primitive sequence: per step, arm down (turning) or up (straight), and a duration."""

    name: str
    turning: np.ndarray  # (K,) bool
    durations_s: np.ndarray  # (K,) s

    @property
    def duration_s(self) -> float:
        return float(np.sum(self.durations_s))

    @property
    def turn_fraction(self) -> float:
        d = self.duration_s
        return float(np.sum(self.durations_s[self.turning]) / d) if d > 0 else 0.0


def turning_sequence(duration_s: float, *, steps: int = 1) -> PrimitiveSequence:
    """Pure turning (S_2f(1, 0): the arm stays down) for ``duration_s``, cut into ``steps`` Drives."""
    return PrimitiveSequence("turning", np.ones(steps, bool), np.full(steps, duration_s / steps))


def straight_sequence(duration_s: float, *, steps: int = 1) -> PrimitiveSequence:
    """Pure straight motion (S_2f(0, 1)) for ``duration_s``, cut into ``steps`` Drives."""
    return PrimitiveSequence("straight", np.zeros(steps, bool), np.full(steps, duration_s / steps))


def s2f_sequence(rho_turn: float, duration_s: float, period_s: float) -> PrimitiveSequence:
    """Two-primitive fine motion S_2f: turning for ``rho_turn`` of every period, straight for the rest.

    The mean radius is ``r / rho_turn`` (SPEC 8's ``r (1 + rho_b / rho_a)``). The last period is cut
    short so the sequence lasts exactly ``duration_s``.
    """
    rho = float(rho_turn)
    if not 0.0 <= rho <= 1.0:
        raise ValueError(f"turning fraction must be in [0, 1], got {rho_turn!r}")
    if not period_s > 0:
        raise ValueError(f"switching period must be > 0 s, got {period_s!r}")
    cycles = max(1, math.ceil(duration_s / period_s - 1e-9))
    turning, durs = [], []
    left = float(duration_s)
    for _ in range(cycles):
        p = min(period_s, left)
        for is_turn, part in ((True, rho * p), (False, (1.0 - rho) * p)):
            if part > 0:
                turning.append(is_turn)
                durs.append(part)
        left -= p
    return PrimitiveSequence(f"S_2f({rho:g}, {1 - rho:g})", np.array(turning, bool), np.array(durs, float))


def sequence_poses(start, turning, durations_s, speed_um_s, radius_um, errors, times_s, *, unwrapped: bool = False) -> np.ndarray:
    """Poses along a primitive sequence for several error values, in closed form.

    Parameters
    ----------
    start : array_like, shape (3,)
        Start pose ``(x_um, y_um, theta_rad)``.
    turning : array_like of bool, shape (K,)
        Per step, arm down (turning on radius ``r``) or up (straight).
    durations_s : array_like, shape (K,)
        Step durations (s, >= 0).
    speed_um_s, radius_um : float
        Nominal speed v (um/s) and turning radius r (um).
    errors : array_like, shape (G, 3)
        ``(e_v, e_r, d)`` per error case (:meth:`ErrorModel.samples`); zeros give the nominal motion.
    times_s : array_like, shape (T,)
        Times (s) from the sequence's start; clipped to its duration.
    unwrapped : bool
        Return the heading as ``theta_0 +`` the total turn so far, not wrapped to ``[0, 2 pi)``, so that
        heading errors beyond half a turn are not folded back.

    Returns
    -------
    ndarray, shape (G, T, 3)
        Under error case ``g`` every step is the arc of SPEC 3 with speed ``v (1 + e_v)`` and curvature
        ``1 / (r (1 + e_r)) + d`` (turning) or ``d`` (straight).
    """
    turning = np.atleast_1d(np.asarray(turning, dtype=bool))
    durs = np.atleast_1d(np.asarray(durations_s, dtype=np.float64))
    err = np.atleast_2d(np.asarray(errors, dtype=np.float64))
    t = np.atleast_1d(np.asarray(times_s, dtype=np.float64))
    v_hat = float(speed_um_s) * (1.0 + err[:, 0])  # (G,)
    k_turn = 1.0 / (float(radius_um) * (1.0 + err[:, 1])) + err[:, 2]
    kappas = np.where(turning[None, :], k_turn[:, None], err[:, 2][:, None])  # (G, K)
    lengths = v_hat[:, None] * durs[None, :]
    nodes = follow(np.asarray(start, dtype=np.float64), lengths, kappas)  # (G, K + 1, 3)
    cum = np.concatenate([[0.0], np.cumsum(durs)])
    t = np.clip(t, 0.0, cum[-1])
    idx = np.clip(np.searchsorted(cum, t, side="right") - 1, 0, durs.size - 1)
    tau = t - cum[idx]
    out = move(nodes[:, idx], v_hat[:, None] * tau[None, :], kappas[:, idx])
    if unwrapped:
        cumturn = np.concatenate([np.zeros((err.shape[0], 1)), np.cumsum(kappas * lengths, axis=1)], axis=1)
        out[..., 2] = float(np.asarray(start)[2]) + cumturn[:, idx] + kappas[:, idx] * v_hat[:, None] * tau[None, :]
    return out


@dataclass(frozen=True, eq=False)
class DeltaCurve:
    """``delta(t)`` of one sequence: the largest deviation from nominal motion up to time ``t``.

    All arrays have the shape of ``times_s`` and are non-decreasing. ``across_um`` is to the robot's
    right at the start, ``along_um`` along its start heading; ``xy_um`` is the Euclidean position error
    (``<= hypot(across, along)``), ``theta_rad`` the heading error.
    """

    sequence: str
    times_s: np.ndarray
    across_um: np.ndarray
    along_um: np.ndarray
    xy_um: np.ndarray
    theta_rad: np.ndarray

    def at(self, t_s) -> tuple[np.ndarray, np.ndarray]:
        """``(delta_xy, delta_theta)`` at times ``t_s``: the value at the first sample not before ``t``."""
        t = np.asarray(t_s, dtype=np.float64)
        k = np.clip(np.searchsorted(self.times_s, t - 1e-12, side="left"), 0, self.times_s.size - 1)
        return self.xy_um[k], self.theta_rad[k]

    @property
    def end(self) -> tuple[float, float]:
        return float(self.xy_um[-1]), float(self.theta_rad[-1])

    def to_dict(self, points: int = 25) -> dict[str, Any]:
        k = np.unique(np.round(np.linspace(0, self.times_s.size - 1, min(points, self.times_s.size))).astype(int))
        return {
            "sequence": self.sequence,
            "times_s": self.times_s[k],
            "xy_um": self.xy_um[k],
            "across_um": self.across_um[k],
            "along_um": self.along_um[k],
            "theta_deg": np.degrees(self.theta_rad[k]),
        }


def _sample_times(durations_s: np.ndarray, samples: int) -> np.ndarray:
    total = float(np.sum(durations_s))
    ends = np.cumsum(durations_s)
    return np.unique(np.concatenate([np.linspace(0.0, total, samples), ends]))


def deviation_envelope(
    sequence: PrimitiveSequence,
    speed_um_s: float,
    radius_um: float,
    model: ErrorModel,
    *,
    times_s=None,
    samples: int = 241,
    levels: int = 5,
    start_heading_offsets_rad=(0.0,),
) -> DeltaCurve:
    """``delta(t)`` for one robot driving ``sequence`` (the integration of seed eq. 4/5 over S).

    Parameters
    ----------
    sequence:
        The primitive sequence (:func:`turning_sequence`, :func:`straight_sequence`,
        :func:`s2f_sequence`, or any :class:`PrimitiveSequence`).
    speed_um_s, radius_um:
        Nominal speed v and radius r.
    model:
        The error box.
    times_s:
        Sample times; default ``samples`` points plus every step end.
    levels:
        Grid levels per error axis (:meth:`ErrorModel.samples`).
    start_heading_offsets_rad:
        Offsets of the true start heading from the nominal one (an uncertain start, e.g. a cylinder's
        ``+-h``); the start position's uncertainty adds to ``delta_xy`` separately since motion is
        translation-invariant.

    Returns
    -------
    DeltaCurve
        Running maxima over the error grid and the heading offsets.
    """
    durs = np.asarray(sequence.durations_s, dtype=np.float64)
    t = _sample_times(durs, samples) if times_s is None else np.asarray(times_s, dtype=np.float64)
    nominal = sequence_poses((0.0, 0.0, 0.0), sequence.turning, durs, speed_um_s, radius_um, np.zeros((1, 3)), t, unwrapped=True)[0]
    err = model.samples(levels)
    offsets = np.atleast_1d(np.asarray(start_heading_offsets_rad, dtype=np.float64))
    across = np.zeros(t.size)
    along = np.zeros(t.size)
    xy = np.zeros(t.size)
    th = np.zeros(t.size)
    for off in offsets:
        p = sequence_poses((0.0, 0.0, off), sequence.turning, durs, speed_um_s, radius_um, err, t, unwrapped=True)
        dx = p[..., 0] - nominal[None, :, 0]
        dy = p[..., 1] - nominal[None, :, 1]
        dth = np.abs(p[..., 2] - nominal[None, :, 2])
        across = np.maximum(across, np.abs(dx).max(axis=0))
        along = np.maximum(along, np.abs(dy).max(axis=0))
        xy = np.maximum(xy, np.hypot(dx, dy).max(axis=0))
        th = np.maximum(th, dth.max(axis=0))
    # The drift's random walk, on top of the grid (module notes): distance at the box's fastest speed.
    s = speed_um_s * model.speed_factors[1] * t
    walk = model.walk_displacement(s)
    across, along, xy, th = across + walk, along + walk, xy + walk, th + model.walk_heading(s)
    acc = np.maximum.accumulate
    return DeltaCurve(sequence.name, t, acc(across), acc(along), acc(xy), acc(th))


# ----------------------------------------------------------------------------------------------------
# C_alpha,i and the timed forward projection


@dataclass(frozen=True)
class Cylinder:
    """``C_alpha,i = B(r_alpha) x [theta - h_alpha, theta + h_alpha]``: where gross motion leaves D_i.

    ``radius_um = motion_radius_um + camera_radius_um`` and ``height_rad = motion_height_rad +
    camera_height_rad``; the motion parts are ``delta(t_2pi)`` maximised over :attr:`sequences`.
    """

    robot: str
    radius_um: float
    height_rad: float
    t_2pi_s: float
    motion_radius_um: float
    motion_height_rad: float
    camera_radius_um: float
    camera_height_rad: float
    worst_xy: str
    worst_theta: str

    def to_dict(self) -> dict[str, Any]:
        return {
            "robot": self.robot,
            "radius_um": self.radius_um,
            "height_deg": math.degrees(self.height_rad),
            "t_2pi_s": self.t_2pi_s,
            "motion_radius_um": self.motion_radius_um,
            "motion_height_deg": math.degrees(self.motion_height_rad),
            "camera_radius_um": self.camera_radius_um,
            "camera_height_deg": math.degrees(self.camera_height_rad),
            "worst_sequence_xy": self.worst_xy,
            "worst_sequence_theta": self.worst_theta,
        }


CYLINDER_DUTIES = (1.0, 0.75, 0.5, 0.25, 0.0)
"""Turning fractions of the sequences of duration ``t_2pi`` over which ``C_alpha,i`` is maximised."""


def cylinder(speed_um_s: float, radius_um: float, model: ErrorModel, *, robot: str = "", levels: int = 5) -> Cylinder:
    """``C_alpha,i`` of seed App. 3.4: ``r_alpha = delta_xy(t_2pi)``, ``h_alpha = delta_theta(t_2pi)``.

    Gross motion can only correct an error by driving up to a full turn (robots turn one way), so what
    it leaves is the error accumulated over ``t_2pi`` (:func:`turn_time` of ``2 pi``). Which primitives
    that correction uses is unknown, so ``delta(t_2pi)`` is maximised over pure turning, pure straight
    motion and S_2f mixes in between (:data:`CYLINDER_DUTIES`, switching every ``t_2pi / 32``). The
    camera's bound is added (``sqrt(2)`` times the per-axis bound in position).
    """
    t2 = turn_time(TWO_PI, speed_um_s, radius_um, model)
    cam_r = math.sqrt(2.0) * model.camera_position_um
    cam_h = model.camera_heading_rad
    if not math.isfinite(t2):
        return Cylinder(robot, math.inf, math.inf, t2, math.inf, math.inf, cam_r, cam_h, "-", "-")
    best_xy, best_th = (-1.0, ""), (-1.0, "")
    for rho in CYLINDER_DUTIES:
        if rho == 1.0:
            seq = turning_sequence(t2)
        elif rho == 0.0:
            seq = straight_sequence(t2)
        else:
            seq = s2f_sequence(rho, t2, t2 / 32.0)
        curve = deviation_envelope(seq, speed_um_s, radius_um, model, levels=levels)
        xy, th = curve.end
        if xy > best_xy[0]:
            best_xy = (xy, seq.name)
        if th > best_th[0]:
            best_th = (th, seq.name)
    return Cylinder(robot, best_xy[0] + cam_r, best_th[0] + cam_h, t2, best_xy[0], best_th[0], cam_r, cam_h, best_xy[1], best_th[1])


@dataclass(frozen=True)
class ForwardProjection:
    """The timed forward projection ``F(A'_n, t_4pi)`` of D_n's uncorrected straight run (App. 3.4).

    D_n starts in ``C'_alpha,n`` (:attr:`start`) and drives straight for ``t_4pi_s``, the longest time
    D_{n-1} needs to turn ``4 pi``. ``radius_um`` bounds its position error, ``heading_rad`` its heading
    error; ``across_um`` and ``along_um`` split the position error across and along the nominal line
    (each including the start cylinder's radius).
    """

    robot: str
    partner: str
    t_4pi_s: float
    straight_um: float
    start: Cylinder
    radius_um: float
    heading_rad: float
    across_um: float
    along_um: float

    def to_dict(self) -> dict[str, Any]:
        return {
            "robot": self.robot,
            "partner": self.partner,
            "t_4pi_s": self.t_4pi_s,
            "straight_um": self.straight_um,
            "start_radius_um": self.start.radius_um,
            "start_height_deg": math.degrees(self.start.height_rad),
            "radius_um": self.radius_um,
            "heading_deg": math.degrees(self.heading_rad),
            "across_um": self.across_um,
            "along_um": self.along_um,
            "self_align_limits": {
                "incidence_deg": math.degrees(SELF_ALIGN_MAX_INCIDENCE_RAD),
                "offset_um": SELF_ALIGN_MAX_OFFSET_UM,
            },
        }


def timed_forward_projection(
    speed_n_um_s: float,
    radius_n_um: float,
    speed_partner_um_s: float,
    radius_partner_um: float,
    model: ErrorModel,
    start: Cylinder,
    *,
    robot: str = "",
    partner: str = "",
    levels: int = 5,
    heading_levels: int = 9,
) -> ForwardProjection:
    """``F(A'_n, t_4pi)``: D_n from its start cylinder, straight for the time D_{n-1} needs to turn 4 pi.

    Integrates the straight-motion error (speed error and drift) from every start heading in
    ``+-start.height_rad`` (``heading_levels`` samples) and adds the start radius.
    """
    t4 = turn_time(2.0 * TWO_PI, speed_partner_um_s, radius_partner_um, model)
    if not (math.isfinite(t4) and math.isfinite(start.radius_um)):
        return ForwardProjection(robot, partner, t4, math.inf, start, math.inf, math.inf, math.inf, math.inf)
    h = start.height_rad
    offsets = np.linspace(-h, h, heading_levels) if h > 0 else np.zeros(1)
    curve = deviation_envelope(
        straight_sequence(t4), speed_n_um_s, radius_n_um, model, levels=levels, start_heading_offsets_rad=offsets
    )
    xy, th = curve.end
    return ForwardProjection(
        robot,
        partner,
        float(t4),
        float(speed_n_um_s * t4),
        start,
        float(xy + start.radius_um),
        float(th),
        float(curve.across_um[-1] + start.radius_um),
        float(curve.along_um[-1] + start.radius_um),
    )


# ----------------------------------------------------------------------------------------------------
# Fine motion: preimage of G_i* and the regions A_i*


def fine_motion_heading_error(turn_rad, length_um, model: ErrorModel):
    """Heading error (rad) a fine-motion arc can accumulate: ``turn g + s (1 + a) d + c sqrt(s (1 + a))``.

    ``g = (1 + a) / (1 - b) - 1`` is the largest relative error of the turn (speed and radius factors),
    ``s (1 + a) d`` the drift's bias and ``c sqrt(s (1 + a))`` its random walk over the arc length ``s``.
    Vectorised.
    """
    (_, v_hi), (r_lo, _) = model.speed_factors, model.radius_factors
    g = v_hi / r_lo - 1.0
    s = np.abs(length_um) * v_hi
    return np.abs(turn_rad) * g + s * model.drift_rad_per_um + model.walk_heading(s)


class _ArcsThrough(NamedTuple):
    """The clockwise arcs from poses ``a`` (positions x headings) through one target point ``q`` (seed eq. 1
    corrected, as :func:`stressbots.paths.arc_through`); every array has shape ``(P, H)``."""

    exists: np.ndarray  # bool: q lies to the right of a (or straight ahead), so a clockwise arc reaches it
    radius_um: np.ndarray  # r' = d^2 / (2 right); inf straight ahead
    turn_rad: np.ndarray  # 2 atan2(right, ahead); 0 straight ahead
    length_um: np.ndarray  # r' turn, or the distance straight ahead


def _arcs_through(pos: np.ndarray, sin_h: np.ndarray, cos_h: np.ndarray, q: np.ndarray) -> _ArcsThrough:
    """The arcs from every position ``pos`` ``(P, 2)`` and heading (``sin_h``, ``cos_h`` ``(1, H)``) through ``q``."""
    dx = (q[0] - pos[:, 0])[:, None]
    dy = (q[1] - pos[:, 1])[:, None]
    right = dx * cos_h - dy * sin_h  # offset of q to the robot's right
    ahead = dx * sin_h + dy * cos_h
    dist2 = dx * dx + dy * dy
    with np.errstate(divide="ignore", invalid="ignore"):
        # eq. 1: r' = d^2 / (2 right); the arc turns 2 atan2(right, ahead); straight ahead: r' = inf
        straight = (right == 0) & (ahead > 0)
        exists = (right > 0) | straight
        radius = np.where(right > 0, dist2 / (2.0 * right), np.inf)
        turn = np.where(right > 0, 2.0 * np.arctan2(right, ahead), 0.0)
        length = np.where(right > 0, radius * turn, np.maximum(ahead, 0.0))
    return _ArcsThrough(exists, radius, turn, length)


def _arcs_clear(pos: np.ndarray, hd: np.ndarray, arcs: _ArcsThrough, ok: np.ndarray, fractions: np.ndarray, obstacle,
                arena_um) -> np.ndarray:
    """For the arcs where ``ok`` ``(P, H)`` holds, whether the reference point stays out of ``obstacle`` and
    inside the arena ``(w, h)`` (um) at the ``fractions`` of the arc's length; one bool per True of ``ok``
    (in :func:`numpy.nonzero` order)."""
    ip, ih = np.nonzero(ok)
    p = np.stack([pos[ip, 0], pos[ip, 1], hd[ih]], axis=-1)
    rr = arcs.radius_um[ip, ih]
    kappa = np.where(np.isinf(rr), 0.0, 1.0 / rr)
    pts = move(p[:, None, :], arcs.length_um[ip, ih][:, None] * fractions[None, :], kappa[:, None])
    clear = np.ones(ip.size, dtype=bool)
    if obstacle is not None:
        import shapely

        clear &= ~shapely.contains_xy(obstacle, pts[..., 0], pts[..., 1]).any(axis=1)
    if arena_um is not None:
        w, h = arena_um
        clear &= ((pts[..., 0] >= 0) & (pts[..., 0] <= w) & (pts[..., 1] >= 0) & (pts[..., 1] <= h)).all(axis=1)
    return clear


def fine_motion_preimage(
    positions,
    headings,
    targets,
    goal_heading_rad: float,
    cone_rad: float,
    min_radius_um: float,
    model: ErrorModel,
    *,
    obstacle=None,
    arena_um=None,
    clearance_samples: int = 8,
) -> np.ndarray:
    """Whether fine motion from each pose reaches G_i* (the compliance-enlarged goal), nominally.

    A pose ``a`` is in the preimage when, for some target point ``q`` (the goal's reference point, or
    points along the partner's front for G_1), the clockwise arc from ``a`` through ``q`` (seed eq. 1
    corrected, as :func:`stressbots.paths.arc_through`) has ``r' >= min_radius_um`` (realisable by
    interpolated turning), arrives with incidence ``|alpha| = |theta_a + turn - theta_g|`` below
    ``cone_rad`` minus the arc's own heading error (:func:`fine_motion_heading_error`), and its reference
    point stays out of ``obstacle`` (a shapely geometry: the docking object grown by half a body width)
    and inside the arena on the way (``clearance_samples`` points up to 90 % of the arc).

    Parameters
    ----------
    positions : array_like, shape (P, 2)
        Positions of ``a`` (um).
    headings : array_like, shape (H,)
        Headings of ``a`` (rad); every position is tried with every heading.
    targets : array_like, shape (M, 2)
        Points the arc may pass through (um).

    Returns
    -------
    ndarray of bool, shape (P, H)
    """
    pos = np.atleast_2d(np.asarray(positions, dtype=np.float64))
    hd = np.atleast_1d(np.asarray(headings, dtype=np.float64))
    targets = np.atleast_2d(np.asarray(targets, dtype=np.float64))
    sin_h, cos_h = np.sin(hd)[None, :], np.cos(hd)[None, :]
    out = np.zeros((pos.shape[0], hd.size), dtype=bool)
    fr = np.linspace(0.0, 0.9, clearance_samples)
    for q in targets:
        arcs = _arcs_through(pos, sin_h, cos_h, q)
        ok = arcs.exists & (arcs.radius_um >= min_radius_um) & (arcs.length_um > 0) & ~out
        alpha = np.abs(np.mod(hd[None, :] + arcs.turn_rad - goal_heading_rad + math.pi, TWO_PI) - math.pi)
        ok &= alpha < cone_rad - fine_motion_heading_error(arcs.turn_rad, arcs.length_um, model)
        if (obstacle is not None or arena_um is not None) and ok.any():
            ok[np.nonzero(ok)] = _arcs_clear(pos, hd, arcs, ok, fr, obstacle, arena_um)
        out |= ok
    return out


@dataclass(frozen=True, eq=False)
class Region:
    """``A_i*`` sampled on a grid: the intermediate poses from which D_i is guaranteed to reach G_i.

    Attributes
    ----------
    robot:
        Robot name.
    goal:
        The slot pose ``g_i``.
    xs_um, ys_um, headings_rad:
        The grid axes (world frame).
    mask:
        ``(nx, ny, nh)`` bool, the poses of A_i*.
    preimage:
        ``(nx, ny, nh)`` bool, the nominal preimage of G_i* outside C_O (before erosion).
    erosion_radius_um, erosion_height_rad:
        The cylinder the preimage was eroded by (``C_alpha,i``, or D_n's forward projection).
    cone_rad, min_radius_um:
        The compliance cone and the smallest realisable fine-motion radius used.
    reason:
        Why A_i* is empty, or ``""``.
    """

    robot: str
    goal: np.ndarray
    xs_um: np.ndarray
    ys_um: np.ndarray
    headings_rad: np.ndarray
    mask: np.ndarray
    preimage: np.ndarray
    erosion_radius_um: float
    erosion_height_rad: float
    cone_rad: float
    min_radius_um: float
    reason: str = ""

    @property
    def spacing_um(self) -> float:
        return float(self.xs_um[1] - self.xs_um[0]) if self.xs_um.size > 1 else 0.0

    @property
    def heading_step_rad(self) -> float:
        return TWO_PI / self.headings_rad.size

    @property
    def empty(self) -> bool:
        return not bool(self.mask.any())

    @property
    def count(self) -> int:
        return int(self.mask.sum())

    @property
    def area_um2(self) -> float:
        """Area of A_i*'s projection on the plane (um^2)."""
        return float(self.mask.any(axis=2).sum()) * self.spacing_um**2

    @property
    def preimage_area_um2(self) -> float:
        return float(self.preimage.any(axis=2).sum()) * self.spacing_um**2

    @property
    def heading_span_rad(self) -> float:
        """Widest contiguous heading interval of A_i* at one position (rad)."""
        if self.empty:
            return 0.0
        return float(_longest_circular_run(self.mask).max()) * self.heading_step_rad

    @property
    def preimage_heading_span_rad(self) -> float:
        if not self.preimage.any():
            return 0.0
        return float(_longest_circular_run(self.preimage).max()) * self.heading_step_rad

    @property
    def volume(self) -> float:
        """Measure of A_i* (um^2 rad)."""
        return self.count * self.spacing_um**2 * self.heading_step_rad

    def example(self) -> np.ndarray | None:
        """The pose of A_i* nearest to the slot (where gross motion would aim), or ``None``.

        Of the headings A_i* allows there, the middle of the widest run.
        """
        if self.empty:
            return None
        inside = self.mask.any(axis=2)
        X, Y = np.meshgrid(self.xs_um, self.ys_um, indexing="ij")
        d = np.where(inside, np.hypot(X - self.goal[0], Y - self.goal[1]), np.inf)
        i, j = np.unravel_index(int(np.argmin(d)), d.shape)
        row = self.mask[i, j]
        n = row.size
        if row.all():
            k = 0
        else:
            start = int(np.flatnonzero(~row)[0])  # walk the circle from a gap: runs never wrap
            best, best_k, cnt = 0, 0, 0
            for m in range(1, n + 1):
                kk = (start + m) % n
                cnt = cnt + 1 if row[kk] else 0
                if cnt > best:
                    best, best_k = cnt, kk
            k = (best_k - (best - 1) // 2) % n
        return np.array([self.xs_um[i], self.ys_um[j], self.headings_rad[k]])

    def to_dict(self) -> dict[str, Any]:
        ex = self.example()
        return {
            "empty": self.empty,
            "reason": self.reason or None,
            "area_um2": self.area_um2,
            "heading_span_deg": math.degrees(self.heading_span_rad),
            "volume_um2_rad": self.volume,
            "poses": self.count,
            "nearest_pose": None if ex is None else Pose(*ex).to_degrees(),
            "preimage_area_um2": self.preimage_area_um2,
            "preimage_heading_span_deg": math.degrees(self.preimage_heading_span_rad),
            "erosion_radius_um": self.erosion_radius_um,
            "erosion_height_deg": math.degrees(self.erosion_height_rad),
            "cone_deg": math.degrees(self.cone_rad),
            "min_fine_radius_um": self.min_radius_um,
            "grid": {
                "spacing_um": self.spacing_um,
                "heading_step_deg": math.degrees(self.heading_step_rad),
                "x_um": [float(self.xs_um[0]), float(self.xs_um[-1])],
                "y_um": [float(self.ys_um[0]), float(self.ys_um[-1])],
            },
        }


def _longest_circular_run(mask: np.ndarray) -> np.ndarray:
    """Longest circular run of True along the last axis, shape ``mask.shape[:-1]``."""
    m = np.asarray(mask, dtype=bool)
    n = m.shape[-1]
    out = np.zeros(m.shape[:-1], dtype=np.int32)
    anyt = m.any(axis=-1)
    rows = m[anyt]  # (P, n): only positions with some True
    best = np.zeros(rows.shape[0], dtype=np.int32)
    cnt = np.zeros(rows.shape[0], dtype=np.int32)
    for k in range(2 * n):
        cnt = (cnt + 1) * rows[:, k % n]
        np.maximum(best, cnt, out=best)
    out[anyt] = np.minimum(best, n)
    return out


def erode(preimage: np.ndarray, spacing_um: float, heading_step_rad: float, radius_um: float, height_rad: float) -> np.ndarray:
    """Poses whose whole cylinder (radius in the plane, +-height in heading) lies in ``preimage``.

    ``preimage`` is ``(nx, ny, nh)`` on a regular grid, headings periodic. Erosion by the cylinder is
    erosion by the heading interval followed by erosion by the disc (the cylinder is their Minkowski
    sum). In heading every sample within ``ceil(height / step)`` steps must qualify. In the plane a
    cell is kept when the nearest cell outside lies farther than ``radius_um + spacing_um / 2`` (the half
    cell covers the boundary's position between samples); beyond the grid's edge the preimage is
    continued as at the edge.
    """
    from scipy.ndimage import distance_transform_edt, minimum_filter1d

    s = np.asarray(preimage, dtype=bool)
    if not s.any():
        return s.copy()
    nh = s.shape[2]
    m = int(math.ceil(height_rad / heading_step_rad - 1e-9)) if height_rad > 0 else 0
    if m == 0:
        ok = s.copy()
    elif 2 * m + 1 >= nh:
        ok = np.broadcast_to(s.all(axis=2, keepdims=True), s.shape).copy()
    else:
        ok = minimum_filter1d(s.view(np.uint8), size=2 * m + 1, axis=2, mode="wrap").astype(bool)
    if radius_um <= 0 or not ok.any():
        return ok
    pad = int(math.ceil(radius_um / spacing_um)) + 2
    out = np.zeros_like(ok)
    done: dict[bytes, np.ndarray] = {}
    for k in np.flatnonzero(ok.any(axis=(0, 1))):
        sl = ok[:, :, k]
        key = sl.tobytes()
        if key not in done:  # slices repeat when the heading erosion covers every heading
            sp = np.pad(sl, pad, mode="edge")
            if sp.all():
                done[key] = sl.copy()
            else:
                dist = distance_transform_edt(sp, sampling=spacing_um)
                done[key] = (dist >= radius_um + 0.5 * spacing_um)[pad:-pad, pad:-pad]
        out[:, :, k] = done[key]
    return out


class _Grid(NamedTuple):
    """The regular pose grid A_i* is sampled on (world frame): positions (um) and periodic headings (rad)."""

    xs_um: np.ndarray
    ys_um: np.ndarray
    headings_rad: np.ndarray
    spacing_um: float

    @property
    def heading_step_rad(self) -> float:
        return TWO_PI / self.headings_rad.size


def _region_grid(proximity, grow_um: float, arena_um, spacing_um: float | None, heading_step_rad: float,
                 max_cells: int) -> _Grid:
    """The grid over C_O's bounding box grown by ``grow_um`` and clipped to the arena ``(w, h)`` (um).

    The default spacing keeps at most ``max_cells`` cells per side (and is at least 10 um); headings
    split the full turn evenly, at least 4 of them, as close to ``heading_step_rad`` as that allows.
    """
    x0, y0, x1, y1 = proximity.bounds
    x0, y0, x1, y1 = x0 - grow_um, y0 - grow_um, x1 + grow_um, y1 + grow_um
    if arena_um is not None:
        x0, y0 = max(x0, 0.0), max(y0, 0.0)
        x1, y1 = min(x1, float(arena_um[0])), min(y1, float(arena_um[1]))
    if spacing_um is None:
        spacing_um = max(10.0, max(x1 - x0, y1 - y0) / max_cells)
    nh = max(4, int(round(TWO_PI / heading_step_rad)))
    xs = np.arange(x0, x1 + 0.5 * spacing_um, spacing_um)
    ys = np.arange(y0, y1 + 0.5 * spacing_um, spacing_um)
    return _Grid(xs, ys, np.arange(nh) * (TWO_PI / nh), spacing_um)


def _sampled_preimage(grid: _Grid, proximity, arena_um, half_diagonal_um: float, aim: Callable[[np.ndarray], np.ndarray]) -> np.ndarray:
    """The fine-motion preimage on ``grid``, ``(nx, ny, nh)`` bool, at the positions outside C_O (and with the
    body's ``half_diagonal_um`` inside the arena): ``aim`` maps positions ``(P, 2)`` to their ``(P, nh)``
    preimage (:func:`fine_motion_preimage`), called on chunks of at most 400,000 poses to bound memory."""
    import shapely

    X, Y = np.meshgrid(grid.xs_um, grid.ys_um, indexing="ij")
    free = ~shapely.contains_xy(proximity, X, Y)
    if arena_um is not None:
        hd = half_diagonal_um
        free &= (X >= hd) & (X <= arena_um[0] - hd) & (Y >= hd) & (Y <= arena_um[1] - hd)
    nh = grid.headings_rad.size
    pre = np.zeros(X.shape + (nh,), dtype=bool)
    ii, jj = np.nonzero(free)
    chunk = max(1, 400_000 // nh)
    for s in range(0, ii.size, chunk):
        a, b = ii[s : s + chunk], jj[s : s + chunk]
        pre[a, b] = aim(np.stack([grid.xs_um[a], grid.ys_um[b]], axis=-1))
    return pre


def _empty_region_reason(pre: np.ndarray, grid: _Grid, erosion_radius_um: float, erosion_height_rad: float) -> str:
    """Why A_i* came out empty: no preimage at all, a heading window (2 h_alpha) wider than the preimage
    offers at any position, or no position with the clearance r_alpha (um) from the boundary."""
    if not pre.any():
        return "no pose outside C_O can reach the goal by fine motion within the compliance cone"
    span = float(_longest_circular_run(pre).max()) * grid.heading_step_rad
    heading_only = erode(pre, grid.spacing_um, grid.heading_step_rad, 0.0, erosion_height_rad)
    if not heading_only.any():
        return (
            f"h_alpha = {math.degrees(erosion_height_rad):.1f} deg: the cylinder needs a heading window of "
            f"{2 * math.degrees(erosion_height_rad):.0f} deg but the preimage of G* offers at most "
            f"{math.degrees(span):.0f} deg at any position"
        )
    return (
        f"r_alpha = {erosion_radius_um:.0f} um: no pose of the preimage of G* outside C_O keeps that "
        f"clearance from its boundary (heading margin {math.degrees(erosion_height_rad):.1f} deg)"
    )


def intermediate_region(
    goal,
    targets,
    cone_rad: float,
    min_radius_um: float,
    model: ErrorModel,
    proximity,
    docking_object,
    *,
    erosion_radius_um: float,
    erosion_height_rad: float,
    body_width_um: float,
    body_length_um: float,
    arena_um=None,
    robot: str = "",
    spacing_um: float | None = None,
    heading_step_rad: float = math.radians(5.0),
    margin_um: float = 400.0,
    max_grow_um: float = 1000.0,
    max_cells: int = 180,
) -> Region:
    """``A_i*`` (seed App. 3.2), sampled: poses at least ``r_alpha`` (plane) and ``h_alpha`` (heading) away
    from the boundary of the fine-motion preimage of G_i* and of C_O.

    Parameters
    ----------
    goal : (3,)
        The slot pose ``g_i``.
    targets : (M, 2)
        Points fine motion may aim at (:func:`fine_motion_preimage`).
    cone_rad, min_radius_um:
        Compliance cone and smallest realisable fine-motion radius.
    proximity:
        C_O (shapely geometry).
    docking_object:
        O (shapely geometry); fine-motion arcs keep ``body_width_um / 2`` from it.
    erosion_radius_um, erosion_height_rad:
        The cylinder (``r_alpha``, ``h_alpha``).
    arena_um:
        ``(w, h)``: poses keep the body's half-diagonal inside it.
    spacing_um, heading_step_rad:
        Grid resolution; the default spacing keeps at most ``max_cells`` cells per side.
    margin_um, max_grow_um:
        The window is C_O's bounding box grown by twice the erosion radius (at most ``max_grow_um``)
        plus ``margin_um``, clipped to the arena.
    """
    goal = np.asarray(goal, dtype=np.float64)
    if not (math.isfinite(erosion_radius_um) and math.isfinite(erosion_height_rad)):
        raise ValueError("the erosion cylinder must be finite")
    grow = min(2.0 * erosion_radius_um, max_grow_um) + margin_um
    grid = _region_grid(proximity, grow, arena_um, spacing_um, heading_step_rad, max_cells)
    obstacle = docking_object.buffer(0.5 * body_width_um)

    def aim(xy: np.ndarray) -> np.ndarray:
        return fine_motion_preimage(xy, grid.headings_rad, targets, float(goal[2]), cone_rad, min_radius_um, model,
                                    obstacle=obstacle, arena_um=arena_um)

    pre = _sampled_preimage(grid, proximity, arena_um, 0.5 * math.hypot(body_length_um, body_width_um), aim)
    mask = erode(pre, grid.spacing_um, grid.heading_step_rad, erosion_radius_um, erosion_height_rad)
    reason = "" if mask.any() else _empty_region_reason(pre, grid, erosion_radius_um, erosion_height_rad)
    return Region(robot, goal, grid.xs_um, grid.ys_um, grid.headings_rad, mask, pre, float(erosion_radius_um),
                  float(erosion_height_rad), float(cone_rad), float(min_radius_um), reason)


# ----------------------------------------------------------------------------------------------------
# Reachable cones of fine motion (seed Fig. 4)


def arc_points(radius_um: float, length_um: float, n: int = 65, start=(0.0, 0.0, 0.0)) -> np.ndarray:
    """``(n, 2)`` points of the clockwise arc of radius ``radius_um`` (``inf``: straight) from ``start``."""
    kappa = 0.0 if math.isinf(radius_um) else 1.0 / radius_um
    s = np.linspace(0.0, length_um, n)
    return move(np.asarray(start, dtype=np.float64), s, kappa)[:, :2]


@dataclass(frozen=True, eq=False)
class Cone:
    """A reachable cone of fine motion: positions swept by arcs of radius in ``[r_min, r_max]``.

    Drawn in the robot's frame: start at the origin heading +y (turning clockwise, to the right).
    ``polygon`` is ``(M, 2)``: the inner arc (``r_min``) out, the end curve (arc length ``length_um``)
    across, the outer arc (``r_max``, ``inf`` = straight) back. ``duties`` names the two extreme
    duty cycles that span it.
    """

    label: str
    robot: str
    radius_min_um: float
    radius_max_um: float
    length_um: float
    duties: tuple[str, str]
    polygon: np.ndarray

    def contains(self, points, tol_um: float = 0.1) -> np.ndarray:
        """Whether points ``(..., 2)`` lie in the cone (within ``tol_um`` of it: the polygon's sampled
        curves are chords of the true ones, off by well under 0.1 um at the default sampling)."""
        import shapely
        from shapely.geometry import Polygon

        pts = np.asarray(points, dtype=np.float64)
        poly = Polygon(self.polygon).buffer(tol_um)
        return shapely.contains_xy(poly, pts[..., 0], pts[..., 1])

    def to_dict(self) -> dict[str, Any]:
        return {
            "label": self.label,
            "robot": self.robot,
            "radius_min_um": self.radius_min_um,
            "radius_max_um": self.radius_max_um if math.isfinite(self.radius_max_um) else None,
            "length_um": self.length_um,
            "duties": list(self.duties),
        }


def fine_motion_cone(radius_min_um: float, radius_max_um: float, length_um: float, *, n: int = 65, label: str = "", robot: str = "",
                     duties=("", "")) -> Cone:
    """The cone of positions reachable by arcs of radius ``r_min <= r' <= r_max`` up to ``length_um``.

    Arcs from one pose with one tangent are nested circles touching only at the start, so up to half a
    turn of the tightest (``length_um <= pi r_min``) the region they sweep is bounded by the two
    extreme arcs and the curve of their end points.
    """
    if not (radius_min_um > 0 and radius_max_um >= radius_min_um):
        raise ValueError(f"need 0 < r_min <= r_max, got {radius_min_um!r}, {radius_max_um!r}")
    if not (0 < length_um <= math.pi * radius_min_um + 1e-9):
        raise ValueError(f"cone length must be in (0, pi r_min] = (0, {math.pi * radius_min_um:.6g}] um, got {length_um!r}")
    k_in = 1.0 / radius_min_um
    k_out = 0.0 if math.isinf(radius_max_um) else 1.0 / radius_max_um
    inner = arc_points(radius_min_um, length_um, n)
    ks = np.linspace(k_in, k_out, 2 * n - 1)
    ends = move(np.zeros(3), length_um, ks)[:, :2]
    outer = arc_points(radius_max_um, length_um, n)[::-1]
    poly = np.vstack([inner, ends[1:], outer[1:]])
    return Cone(label, robot, float(radius_min_um), float(radius_max_um), float(length_um), tuple(duties), poly)


def s2f_cone(radius_um: float, length_um: float | None = None, *, robot: str = "") -> Cone:
    """Seed Fig. 4(a): S_2f spans pure turning (``rho_a = 1``, ``r' = r``) to straight (``rho_a = 0``)."""
    length = 0.5 * math.pi * radius_um if length_um is None else length_um
    return fine_motion_cone(radius_um, math.inf, length, label="S_2f", robot=robot, duties=("S_2f(1, 0)", "S_2f(0, 1)"))


def s3f_cones(radius_n_um: float, radius_nm1_um: float, length_um: float | None = None, *, robots=("D_n", "D_n-1")) -> tuple[Cone, Cone]:
    """Seed Fig. 4(b) with SPEC 8's radii ``r'_n = r / rho_a``, ``r'_{n-1} = r / (rho_a + rho_b)``.

    Each robot's cone is what S_3f reaches *without changing the other robot's arc*:

    - D_{n-1} between S_3f(1/3, 2/3, 0) (``r'_{n-1} = r``) and S_3f(sym) (``1.5 r``), with ``rho_a = 1/3``
      fixed so D_n keeps ``r'_n = 3 r``;
    - D_n between S_3f(sym) (``r'_n = 3 r``) and S_3f(0, 2/3, 1/3) (straight), with ``rho_a + rho_b =
      2/3`` fixed so D_{n-1} keeps ``r'_{n-1} = 1.5 r``.

    Returns ``(cone of D_n, cone of D_{n-1})``.
    """
    ln = 0.5 * math.pi * radius_n_um if length_um is None else length_um
    lm = 0.5 * math.pi * radius_nm1_um if length_um is None else length_um
    cone_n = fine_motion_cone(3.0 * radius_n_um, math.inf, min(ln, 3.0 * math.pi * radius_n_um), label="S_3f D_n", robot=robots[0],
                              duties=("S_3f(1/3, 1/3, 1/3)", "S_3f(0, 2/3, 1/3)"))
    cone_m = fine_motion_cone(radius_nm1_um, 1.5 * radius_nm1_um, lm, label="S_3f D_n-1", robot=robots[1],
                              duties=("S_3f(1/3, 2/3, 0)", "S_3f(1/3, 1/3, 1/3)"))
    return cone_n, cone_m


# ----------------------------------------------------------------------------------------------------
# Empirical coverage (the bounds against the simulator)


@dataclass(frozen=True)
class Coverage:
    """How often simulated open-loop motion stays inside ``delta(t)``.

    ``fraction`` counts checkpoints (the end of every Drive of every sequence of every robot and trial)
    whose position error is ``<= delta_xy(t)`` *and* heading error ``<= delta_theta(t)``;
    ``end_fraction`` only the sequences' ends. ``by_sequence`` splits ``fraction`` by sequence name;
    ``ratio_p50`` / ``ratio_max`` are quantiles of ``max(err_xy / delta_xy, err_theta / delta_theta)``
    (how tight the bound is: < 1 inside).
    """

    trials: int
    seed: int
    k: float
    checkpoints: int
    inside: int
    fraction: float
    end_fraction: float
    by_sequence: dict
    ratio_p50: float
    ratio_p99: float
    ratio_max: float
    plant: str

    def to_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


def _coverage_sequences(speed: float, radius: float, model: ErrorModel, step_s: float, rng: np.random.Generator):
    t2 = turn_time(TWO_PI, speed, radius, model)
    steps = max(1, math.ceil(t2 / step_s))
    seqs = [
        turning_sequence(t2, steps=steps),
        straight_sequence(t2, steps=steps),
        replace(s2f_sequence(0.5, t2, step_s), name="S_2f(sym)"),
    ]
    k = steps
    durs = rng.uniform(0.2, 1.0, k) * step_s
    durs *= t2 / durs.sum()
    seqs.append(PrimitiveSequence("random", rng.random(k) < 0.5, durs))
    return seqs


class _Checkpoint(NamedTuple):
    """The true pose at the end of one Drive against ``delta(t)`` of its sequence."""

    sequence: str
    inside: bool  # position error <= delta_xy and heading error <= delta_theta
    ratio: float  # max(err_xy / delta_xy, err_theta / delta_theta): < 1 inside
    last: bool  # the sequence's last Drive


def _bound_ratio(err_xy_um: float, err_theta_rad: float, delta_xy_um: float, delta_theta_rad: float) -> float:
    """``max(err_xy / delta_xy, err_theta / delta_theta)``; against a zero bound an error within rounding
    (1e-9 um, 1e-12 rad) counts 0 and a larger one infinity."""
    return max(err_xy_um / delta_xy_um if delta_xy_um > 0 else (0.0 if err_xy_um <= 1e-9 else math.inf),
               err_theta_rad / delta_theta_rad if delta_theta_rad > 0 else (0.0 if err_theta_rad <= 1e-12 else math.inf))


def _drive_checked(plant, analysis, seq: PrimitiveSequence, curve: DeltaCurve, speed_um_s: float, radius_um: float,
                   state: np.ndarray | None, checks: list[_Checkpoint]) -> np.ndarray | None:
    """Drive ``seq`` on a one-robot ``plant`` from where it stands, appending one :class:`_Checkpoint` per
    Drive to ``checks``: the true pose against the nominal motion from the sequence's start, within
    ``curve`` at the Drive's end. ``state`` is the arm state the plant was left in (``None``: all arms
    up); returns the state the sequence leaves."""
    from .waveform import synthesize

    p0 = np.asarray(plant.true_poses(), dtype=np.float64)[0]
    ends_t = np.cumsum(seq.durations_s)
    nominal = sequence_poses(p0, seq.turning, seq.durations_s, speed_um_s, radius_um, np.zeros((1, 3)), ends_t)[0]
    bxy, bth = curve.at(ends_t)
    for kk, (turn, dur) in enumerate(zip(seq.turning, seq.durations_s, strict=True)):
        prim = analysis.primitive("P1" if turn else "P0")
        plant.apply(synthesize(analysis, [(prim, float(dur))], initial=state))
        state = np.array(prim.state, dtype=np.uint8)
        p = np.asarray(plant.true_poses(), dtype=np.float64)[0]
        exy = math.hypot(p[0] - nominal[kk, 0], p[1] - nominal[kk, 1])
        eth = abs(float(angle_difference(p[2], nominal[kk, 2])))
        ok = exy <= bxy[kk] + 1e-9 and eth <= bth[kk] + 1e-12
        checks.append(_Checkpoint(seq.name, ok, _bound_ratio(exy, eth, bxy[kk], bth[kk]), kk == len(seq.durations_s) - 1))
    return state


def _coverage_of(checks: Sequence[_Checkpoint], *, trials: int, seed: int, k: float, plant: str) -> Coverage:
    """The :class:`Coverage` of all checkpoints (every fraction 1.0 when there are none)."""
    inside = checks_n = end_in = ends = 0
    per: dict[str, list[int]] = {}
    for c in checks:
        checks_n += 1
        inside += c.inside
        tally = per.setdefault(c.sequence, [0, 0])
        tally[0] += c.inside
        tally[1] += 1
        if c.last:
            ends += 1
            end_in += c.inside
    rq = np.asarray([c.ratio for c in checks]) if checks else np.zeros(1)
    return Coverage(
        trials=int(trials),
        seed=int(seed),
        k=float(k),
        checkpoints=int(checks_n),
        inside=int(inside),
        fraction=float(inside / checks_n) if checks_n else 1.0,
        end_fraction=float(end_in / ends) if ends else 1.0,
        by_sequence={name: float(a / b) for name, (a, b) in per.items()},
        ratio_p50=float(np.quantile(rq, 0.5, method="inverted_cdf")),  # no interpolation: ratios may be inf
        ratio_p99=float(np.quantile(rq, 0.99, method="inverted_cdf")),
        ratio_max=float(rq.max()),
        plant=plant,
    )


def empirical_coverage(
    scenario,
    *,
    trials: int = 200,
    seed: int = 0,
    k: float = DEFAULT_K,
    step_s: float | None = None,
    plant_factory: Callable | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> Coverage:
    """Simulate open-loop primitive sequences with the scenario's noise; count outcomes inside ``delta(t)``.

    For every trial and robot, a fresh plant (default :class:`stressbots.sim.SimulatedPlant`) holding
    that robot alone (no contacts, no arena) drives four sequences of ``t_2pi`` back to back: pure
    turning, pure straight, S_2f(sym) and a random mix, as Drives of about ``step_s`` (default the
    scenario's ``replan_interval_s``, the controller's open-loop stretch). After every Drive the true
    pose's deviation from the nominal motion (from the sequence's start) is compared with ``delta(t)``
    of that sequence under ``ErrorModel.from_noise(scenario.noise, k)``. Trial ``t`` uses seed
    ``SeedSequence(seed).spawn(trials)[t]``, the same for every robot.
    """
    from .electrostatics import analyse_scenario

    if plant_factory is None:
        from .sim import SimulatedPlant

        plant_factory = SimulatedPlant
    model = ErrorModel.from_noise(scenario.noise, k)
    step = float(step_s if step_s is not None else scenario.control.replan_interval_s)
    children = np.random.SeedSequence(int(seed)).spawn(int(trials))
    checks: list[_Checkpoint] = []
    total = trials * scenario.n
    done = 0
    for i, rob in enumerate(scenario.robots):
        solo = replace(
            scenario, robots=(replace(rob, start=Pose(0.0, 0.0, 0.0), goal=None),), arena_um=None, structure=None
        )
        analysis = analyse_scenario(solo)
        v, r = rob.speed_um_s, rob.turn_radius_um
        seqs = _coverage_sequences(v, r, model, step, np.random.default_rng(np.random.SeedSequence([int(seed), i, 1])))
        curves = [deviation_envelope(s, v, r, model) for s in seqs]
        for t in range(trials):
            plant = plant_factory(solo, seed=int(children[t].generate_state(1, np.uint64)[0] >> np.uint64(11)))
            state = None
            for seq, curve in zip(seqs, curves, strict=True):
                state = _drive_checked(plant, analysis, seq, curve, v, r, state, checks)
            done += 1
            if progress is not None:
                progress(done, total)
    return _coverage_of(checks, trials=trials, seed=seed, k=k, plant=f"{plant_factory.__module__}.{plant_factory.__qualname__}")


# ----------------------------------------------------------------------------------------------------
# The whole analysis for a scenario


@dataclass(frozen=True, eq=False)
class RobotBounds:
    """Everything the bounds say about one robot D_i."""

    name: str
    index: int
    role: str
    goal: np.ndarray
    speed_um_s: float
    radius_um: float
    omega_min_rad_s: float
    omega_max_rad_s: float
    t_2pi_s: float
    t_4pi_s: float
    delta_turning: DeltaCurve
    delta_straight: DeltaCurve
    cylinder: Cylinder
    region: Region | None
    guaranteed: bool
    reason: str
    replan_interval_s: float = math.nan
    delta_replan: tuple[float, float] = (math.nan, math.nan)
    """``(delta_xy, delta_theta)`` over one replanning interval t_x (worst of turning and straight): the
    error that accumulates between two measurements of the closed-loop controller."""

    @property
    def label(self) -> str:
        return f"D{self.index}" if self.name == f"D{self.index}" else f"D{self.index} ({self.name})"

    def to_dict(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "D": self.index,
            "role": self.role,
            "goal": Pose(*self.goal).to_degrees(),
            "speed_um_s": self.speed_um_s,
            "turn_radius_um": self.radius_um,
            "omega_hat_rad_s": [self.omega_min_rad_s, self.omega_max_rad_s],
            "t_2pi_s": self.t_2pi_s,
            "t_4pi_s": self.t_4pi_s,
            "delta": {"turning": self.delta_turning.to_dict(), "straight": self.delta_straight.to_dict()},
            "cylinder": self.cylinder.to_dict(),
            "delta_replan_interval": {
                "t_x_s": self.replan_interval_s,
                "xy_um": self.delta_replan[0],
                "theta_deg": math.degrees(self.delta_replan[1]),
            },
            "region": None if self.region is None else self.region.to_dict(),
            "verdict": "guaranteed" if self.guaranteed else "not guaranteed",
            "reason": self.reason,
        }


@dataclass(frozen=True, eq=False)
class BoundsReport:
    """The bounds of a scenario (``stressbots bounds``): robots in voltage order D_1..D_n."""

    scenario: str
    model: ErrorModel
    robots: tuple[RobotBounds, ...]
    projection: ForwardProjection
    cones: tuple[Cone, ...]
    structure: Any
    arena_um: tuple[float, float] | None
    notes: tuple[str, ...] = ()
    coverage: Coverage | None = None

    def robot(self, name: str) -> RobotBounds:
        for r in self.robots:
            if r.name == name:
                return r
        raise KeyError(name)

    @property
    def guaranteed(self) -> bool:
        return all(r.guaranteed for r in self.robots)

    def to_dict(self) -> dict[str, Any]:
        from .outputs import provenance

        return {
            "format": "stressbots.bounds/1",
            "scenario": self.scenario,
            "error_model": self.model.to_dict(),
            "model": (
                "delta(t): worst deviation from nominal motion over a grid of constant speed, radius and drift "
                "errors in the k-sigma box, closed-form straight runs and clockwise arcs, running maximum; C_alpha,i = delta(t_2pi) "
                "over turning/straight/S_2f sequences plus the camera bound; A_i*: nominal fine-motion preimage of "
                "G_i* outside C_O, eroded by the cylinder (D_n: by its timed forward projection)"
            ),
            "guaranteed": self.guaranteed,
            "robots": [r.to_dict() for r in self.robots],
            "forward_projection": self.projection.to_dict(),
            "cones": [c.to_dict() for c in self.cones],
            "structure": {"shape": getattr(self.structure, "shape", None), "variant": getattr(self.structure, "variant", None)},
            "coverage": None if self.coverage is None else self.coverage.to_dict(),
            "notes": list(self.notes),
            "provenance": provenance(None),
        }

    def with_coverage(self, coverage: Coverage) -> BoundsReport:
        return replace(self, coverage=coverage)


def _resolve_structure(scenario, analysis, notes: list[str]):
    """The target structure: the variant the nominal plan of a closed-loop run uses (the planner's choice,
    :func:`stressbots.control.nominal_plan`), else the canonical one."""
    from .errors import PlanningError
    from .structures import target_structures

    robots = [scenario.robots[i] for i in analysis.order_index]
    if scenario.structure is not None and scenario.has_starts:
        from .control import nominal_plan  # the controller's planner: the same variant as a closed-loop run

        try:
            return nominal_plan(scenario).structure
        except PlanningError as exc:
            notes.append(f"the planner found no plan ({exc.problem}); bounds use the canonical {scenario.structure.shape}")
    return target_structures(robots, scenario.structure)[0]


def _goal_region_spec(slot) -> tuple[np.ndarray, np.ndarray, float]:
    """Goal pose, target points and compliance cone of G_i* for a slot (App. 3.5)."""
    goal = slot.pose.as_array()
    if slot.role == "pair":
        lat = np.array([math.cos(goal[2]), -math.sin(goal[2])])
        w = SELF_ALIGN_MAX_OFFSET_UM * (1.0 - 1e-6)
        return goal, goal[:2][None, :] + np.linspace(-w, w, 5)[:, None] * lat[None, :], SELF_ALIGN_MAX_INCIDENCE_RAD
    return goal, goal[:2][None, :], STICKING_CONE_RAD


def _verdict(scenario, structure, model, order, nm, cyl, proj, *, spacing_um, heading_step_deg) -> tuple[Region | None, bool, str]:
    """A_i* of robot ``nm`` and its verdict (``D_n`` is eroded by the forward projection)."""
    r = scenario.robot(nm)
    idx = order.index(nm) + 1
    slot = structure.slot(nm)
    goal, targets, cone = _goal_region_spec(slot)
    is_n = nm == order[-1]
    er_r, er_h = (proj.radius_um, proj.heading_rad) if is_n else (cyl.radius_um, cyl.height_rad)
    if not (math.isfinite(er_r) and math.isfinite(er_h)):
        return None, False, "the turn-rate bound is not positive: a full turn may never complete"
    region = intermediate_region(
        goal,
        targets,
        cone,
        r.turn_radius_um * model.radius_factors[1],
        model,
        structure.proximity_region(nm),
        structure.docking_object(nm),
        erosion_radius_um=er_r,
        erosion_height_rad=er_h,
        body_width_um=r.width_um,
        body_length_um=r.length_um,
        arena_um=scenario.arena_um,
        robot=nm,
        spacing_um=spacing_um,
        heading_step_rad=math.radians(heading_step_deg),
    )
    if region.empty:
        reason = f"A_{idx}* is empty: {region.reason}"
    else:
        reason = (
            f"A_{idx}* is {region.area_um2 / 1e6:.3g} mm^2 in the plane with headings up to "
            f"{math.degrees(region.heading_span_rad):.0f} deg wide"
        )
    if is_n:
        reason += f" (eroded by D_n's timed forward projection over t_4pi = {proj.t_4pi_s:.1f} s)"
    return region, not region.empty, reason


def _prepare(scenario, structure, notes: list[str], say):
    from .electrostatics import analyse_scenario
    from .errors import PlanningError

    if scenario.n < 2:
        raise PlanningError("bounds need at least 2 robots (G_1 is a pair)", source=scenario.source)
    analysis = analyse_scenario(scenario)
    if not analysis.is_string:
        raise PlanningError(
            "the voltage design is not STRING, so the primitives of the EDR strategy do not exist: " + "; ".join(analysis.reasons),
            source=scenario.source,
        )
    if structure is None:
        say("resolving the target structure")
        structure = _resolve_structure(scenario, analysis, notes)
    assert analysis.order is not None  # a STRING design always has its order
    return list(analysis.order), structure


def _cylinders(scenario, order, model, levels):
    cyl = {nm: cylinder(scenario.robot(nm).speed_um_s, scenario.robot(nm).turn_radius_um, model, robot=nm, levels=levels) for nm in order}
    rn, rm = scenario.robot(order[-1]), scenario.robot(order[-2])
    proj = timed_forward_projection(
        rn.speed_um_s, rn.turn_radius_um, rm.speed_um_s, rm.turn_radius_um, model, cyl[order[-1]],
        robot=order[-1], partner=order[-2], levels=levels,
    )
    return cyl, proj


class _MotionBounds(NamedTuple):
    """The open-loop motion bounds of one robot under the error model."""

    omega_min_rad_s: float  # turn-rate range
    omega_max_rad_s: float
    t_2pi_s: float  # longest time a full turn (2 pi) and two full turns (4 pi) can take
    t_4pi_s: float
    delta_turning: DeltaCurve  # delta(t) of pure turning and pure straight motion up to t_4pi
    delta_straight: DeltaCurve
    delta_replan: tuple[float, float]  # (um, rad) over one replanning interval, worst of turning and straight


def _motion_bounds(r, model: ErrorModel, levels: int, replan_interval_s: float) -> _MotionBounds:
    """Turn rates, full-turn times and ``delta(t)`` of robot ``r``. The curves run to ``t_4pi`` (two full
    turns at the slowest turn rate), or to 4 pi at the nominal turn rate when a turn may never complete."""
    v, rad = r.speed_um_s, r.turn_radius_um
    t2 = turn_time(TWO_PI, v, rad, model)
    t4 = turn_time(2 * TWO_PI, v, rad, model)
    w_lo, w_hi = turn_rate_range(v, rad, model)
    horizon = t4 if math.isfinite(t4) else 4 * TWO_PI / r.turn_rate_rad_s
    d_turn = deviation_envelope(turning_sequence(horizon), v, rad, model, levels=levels)
    d_str = deviation_envelope(straight_sequence(horizon), v, rad, model, levels=levels)
    short = [deviation_envelope(q(replan_interval_s), v, rad, model, levels=levels).end for q in (turning_sequence,
                                                                                               straight_sequence)]
    d_tx = (max(a for a, _ in short), max(b for _, b in short))
    return _MotionBounds(float(w_lo), float(w_hi), float(t2), float(t4), d_turn, d_str, d_tx)


def _fine_motion_cones(scenario, order: Sequence[str]) -> tuple[Cone, ...]:
    """The reachable cones of fine motion: S_2f of every single robot D_1..D_(n-2) (of D_(n-1) when there
    are none, as an example), then S_3f of D_n and D_(n-1)."""
    name_n, name_m = order[-1], order[-2]
    cones = [s2f_cone(scenario.robot(nm).turn_radius_um, robot=nm) for nm in order[:-2]]
    if not cones:
        cones = [s2f_cone(scenario.robot(name_m).turn_radius_um, robot=name_m)]
    cones.extend(s3f_cones(scenario.robot(name_n).turn_radius_um, scenario.robot(name_m).turn_radius_um, robots=(name_n, name_m)))
    return tuple(cones)


def analyse_bounds(
    scenario,
    *,
    k: float = DEFAULT_K,
    structure=None,
    spacing_um: float | None = None,
    heading_step_deg: float = 5.0,
    levels: int = 5,
    progress: Callable[[str], None] | None = None,
) -> BoundsReport:
    """Error bounds, C_alpha,i, the forward projection of D_n, A_i* and verdicts for a scenario.

    Parameters
    ----------
    scenario:
        A scenario with goals or a ``[structure]`` and a STRING design.
    k:
        Sigmas of each noise factor the bounds cover (:class:`ErrorModel`).
    structure:
        The target :class:`~stressbots.structures.Structure`; default the planner's choice (when the
        scenario has start poses and a named shape) or the scenario's structure.
    spacing_um, heading_step_deg:
        Grid of the A_i* sampling.
    levels:
        Error-grid levels per axis for ``delta(t)``.

    Raises
    ------
    PlanningError
        Fewer than 2 robots, not STRING, or no valid target structure.
    """
    say = progress or (lambda _m: None)
    model = ErrorModel.from_noise(scenario.noise, k)
    notes: list[str] = []
    order, structure = _prepare(scenario, structure, notes, say)
    cyl, proj = _cylinders(scenario, order, model, levels)
    tx = float(scenario.control.replan_interval_s)
    robots_out = []
    for idx, nm in enumerate(order, start=1):
        r = scenario.robot(nm)
        slot = structure.slot(nm)
        mb = _motion_bounds(r, model, levels, tx)
        say(f"sampling A_{idx}* ({nm})")
        region, ok, reason = _verdict(
            scenario, structure, model, order, nm, cyl[nm], proj, spacing_um=spacing_um, heading_step_deg=heading_step_deg
        )
        robots_out.append(
            RobotBounds(
                nm, idx, slot.role, slot.pose.as_array(), r.speed_um_s, r.turn_radius_um, mb.omega_min_rad_s, mb.omega_max_rad_s,
                mb.t_2pi_s, mb.t_4pi_s, mb.delta_turning, mb.delta_straight, cyl[nm], region, ok, reason, tx, mb.delta_replan,
            )
        )
    return BoundsReport(
        scenario=scenario.name,
        model=model,
        robots=tuple(robots_out),
        projection=proj,
        cones=_fine_motion_cones(scenario, order),
        structure=structure,
        arena_um=scenario.arena_um,
        notes=tuple(notes),
    )


def critical_noise_scales(
    scenario,
    *,
    k: float = DEFAULT_K,
    structure=None,
    upper: float = 1.0,
    iterations: int = 7,
    spacing_um: float = 30.0,
    heading_step_deg: float = 7.5,
    levels: int = 3,
    progress: Callable[[str], None] | None = None,
) -> dict[str, float]:
    """Per robot, the largest multiple of the scenario's ``[noise]`` (``Noise.scaled``) at which its
    verdict is still "guaranteed", to ``upper / 2^iterations``, by bisection on ``[0, upper]``.

    Bounds grow and the preimage shrinks with the noise, so the verdict is monotone in the scale. A
    coarser grid than :func:`analyse_bounds`' keeps it quick. ``0.0`` means not guaranteed even without
    noise (the geometry forbids it); ``upper`` means guaranteed at least up to ``upper``.
    """
    say = progress or (lambda _m: None)
    notes: list[str] = []
    order, structure = _prepare(scenario, structure, notes, say)
    base = scenario.noise

    def ok(nm: str, scale: float) -> bool:
        model = ErrorModel.from_noise(base.scaled(scale), k)
        cyl, proj = _cylinders(scenario, order, model, levels)
        return _verdict(scenario, structure, model, order, nm, cyl[nm], proj, spacing_um=spacing_um, heading_step_deg=heading_step_deg)[1]

    out: dict[str, float] = {}
    for nm in order:
        say(f"critical noise scale of {nm}")
        if not ok(nm, 0.0):
            out[nm] = 0.0
            continue
        if ok(nm, upper):
            out[nm] = float(upper)
            continue
        lo, hi = 0.0, float(upper)
        for _ in range(iterations):
            mid = 0.5 * (lo + hi)
            lo, hi = (mid, hi) if ok(nm, mid) else (lo, mid)
        out[nm] = lo
    return out
