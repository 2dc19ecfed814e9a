"""Identifying each robot's heading drift while it drives straight (the bias part of the drift).

Heading drift is a per-robot process: a bias drawn once per run plus a random walk in the distance driven
(SPEC 6, :mod:`stressbots.drift`). Over a docking run of a few hundred um a bias of 2 sigma (about 7 deg/mm
at the literature's noise) moves the docking point by 10-20 um, more than the shape tolerance, and a
one-way robot cannot undo a drift to the right without a loop. The bias can be known, though: every
straight drive shows it.

:class:`StraightDrift` accumulates *runs*: maximal chains of frames during which a robot drove straight
(arm up), moved as commanded and was not pushed. A run of commanded length ``s`` whose raw camera headings
at its two ends differ by ``d`` measures the curvature ``kappa_r = d / s``; its error has two independent
parts, the camera's at the two ends and the walk's over ``s`` (the frames in between cancel)::

    Var[kappa_r] = 2 sigma_cam^2 / s^2 + (1 - f) sigma^2 S / s

with ``sigma`` the scenario's drift (rad/um), ``S`` its reference distance (1 mm) and ``f`` the bias share
of :data:`stressbots.drift.DEFAULT_DRIFT`. Runs pool with inverse-variance weights against a zero-mean
prior of variance ``f sigma^2`` (the bias's spread): the posterior mean is the identified curvature, and the
posterior variance says how well it is known. Positive = clockwise (the heading grows), rad per um, like
the curvature of :func:`stressbots.kinematics.move`.

Robust to the camera:

- **dropouts**: a frame in which a robot is not seen does not end its run; the travel of the unseen frames
  is carried to the next frame that sees it (up to ``max_bridge_um``);
- **contacts**: a frame whose heading change, forward travel or sideways displacement does not fit a
  straight drive with the identified curvature (``gate_sigmas`` standard deviations of camera noise, walk
  and the bias's own uncertainty) ends the run *before* that frame: a robot pushed or turned by another
  contributes nothing from the contact on. A frame in which it moved less than ``stop_fraction`` of its
  commanded travel (it touched something) does the same.

Frames with a short turn count too (*turn-corrected* runs): gross motion re-plans every t_x, and nearly
every frame of it starts with a few degrees of turn before its straight (so does a re-aim burst on an
approach line). Counting only all-straight frames, a robot that waited on its orbit and then steered to its
slot reached the structure with its bias still at the prior's zero: at twice the literature's noise, robots
with a bias of 9-11 deg/mm were identified at under 1 deg/mm and docked 20-45 um right of their slots. A
frame whose turn is at most ``max_turn_rad`` (predicted from the identified turn rate) adds its straight
travel to the run and its heading change less that turn; the turn rate's own error enters the turn as
``turn_rel_sd`` of it. The turn rate is identified on the orbit, drift included, so the bias acts only on
the straight part. Off unless ``max_turn_rad`` is set (the closed loop's ``Tuning.drift_turn_max_deg``, 0:
measured, the success rates did not follow the identification).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..drift import DEFAULT_DRIFT, DriftModel
from ..robots import angle_difference

__all__ = ["StraightDrift", "StraightDriftSettings"]


@dataclass(frozen=True)
class StraightDriftSettings:
    """Thresholds of the straight-drift identification (see the module docstring).

    Attributes
    ----------
    stop_fraction:
        A frame in which a robot moved forward less than this fraction of its commanded travel ends its
        run (it touched something, or was held).
    over_fraction:
        ... or more than ``1 + over_fraction`` times it (pushed from behind); 0.3 is six times the
        literature's speed spread, so an unidentified speed never trips it.
    gate_sigmas:
        A frame's heading change and sideways displacement must lie within this many standard deviations
        of a straight drive with the identified curvature (3.5: a clean frame is cut once in ~2000).
    min_camera_heading_rad, min_camera_position_um:
        Floors of the camera's noise in the gates (an exact camera still rounds; 0.05 deg, 0.2 um).
    max_bridge_um:
        Longest commanded travel (um) a run may bridge over frames that did not see the robot.
    max_turn_rad:
        Largest predicted turn (rad) of a frame that still counts, corrected (0: all-straight frames only; 6 deg takes
        gross motion's per-t_x corrections and the approach's re-aim bursts, not the arcs of a merge or a loop).
    turn_rel_sd:
        Relative error (sd) of a frame's predicted turn: the identified turn rate's (a few % before an orbit is
        seen) and the per-drive jitter of the radius.
    """

    stop_fraction: float = 0.5
    over_fraction: float = 0.3
    gate_sigmas: float = 3.5
    min_camera_heading_rad: float = math.radians(0.05)
    min_camera_position_um: float = 0.2
    max_bridge_um: float = 400.0
    max_turn_rad: float = 0.0
    turn_rel_sd: float = 0.05


class StraightDrift:
    """Per-robot straight-line curvature (rad/um, + = clockwise) identified from camera frames.

    Parameters
    ----------
    n:
        Number of robots.
    drift_rad_per_um:
        The scenario's heading drift (sd over the reference distance, divided by it; rad/um). Zero: no
        drift, and the curvature stays 0.
    camera_heading_rad, camera_position_um:
        The camera's noise (sd; rad, um).
    settings:
        Gates and limits (:class:`StraightDriftSettings`).
    model:
        The drift's bias/walk split and reference distance (the simulator's, :data:`stressbots.drift.DEFAULT_DRIFT`).

    Examples
    --------
    >>> import math
    >>> import numpy as np
    >>> d = StraightDrift(1, drift_rad_per_um=math.radians(3.7) / 1000.0, camera_heading_rad=math.radians(1.0),
    ...                   camera_position_um=2.0)
    >>> for k in range(5):   # 100 um per frame, heading +0.01 rad per frame: 1e-4 rad/um (5.7 deg/mm)
    ...     d.frame(np.array([[100.0 * math.sin(0.01 * k), 100.0 * k, 0.01 * k]]), np.array([True]), np.array([100.0]))
    >>> round(math.degrees(float(d.kappa[0])) * 1000.0, 2)   # one 400-um run: 19 % of the information, the prior the rest
    1.08
    """

    def __init__(
        self, n: int, *, drift_rad_per_um: float, camera_heading_rad: float, camera_position_um: float,
        settings: StraightDriftSettings | None = None, model: DriftModel = DEFAULT_DRIFT,
    ):
        self.n = n
        self.settings = StraightDriftSettings() if settings is None else settings
        cfg = self.settings
        self.sigma = max(float(drift_rad_per_um), 0.0)
        self.cam_h = max(float(camera_heading_rad), cfg.min_camera_heading_rad)
        self.cam_p = max(float(camera_position_um), cfg.min_camera_position_um)
        self.walk_var_per_um = (1.0 - model.bias_share) * self.sigma**2 * model.reference_um  # rad^2 per um
        self.prior_var = model.bias_share * self.sigma**2  # (rad/um)^2
        self._num = np.zeros(n)  # sum of w_r kappa_r over closed runs
        self._den = np.full(n, 1.0 / self.prior_var if self.prior_var > 0 else math.inf)  # prior + sum of w_r
        self._len = np.zeros(n)  # commanded length of the current run (um)
        self._dth = np.zeros(n)  # unwrapped heading change over the current run (rad)
        self._last = np.full((n, 3), np.nan)  # last raw frame of the current chain
        self._pending = np.zeros(n)  # straight travel since that frame, over unseen frames (um)
        self._pending_turn = np.zeros(n)  # predicted turn since that frame, over unseen frames (rad)
        self._turn_var = np.zeros(n)  # variance (rad^2) the current run's corrected turns add to its heading change

    def run_weight(self, s_um, turn_var=0.0) -> np.ndarray:
        """Inverse variance ((um/rad)^2) of one run's curvature over ``s_um`` of straight drive whose corrected turns
        add ``turn_var`` (rad^2) to its heading change."""
        s = np.asarray(s_um, dtype=np.float64)
        with np.errstate(divide="ignore", invalid="ignore"):
            var = (2.0 * self.cam_h**2 + turn_var) / s**2 + self.walk_var_per_um / s
            return np.where(s > 0, 1.0 / var, 0.0)

    def _open(self) -> tuple[np.ndarray, np.ndarray]:
        w = self.run_weight(self._len, self._turn_var)
        with np.errstate(invalid="ignore", divide="ignore"):
            k = np.where(self._len > 0, self._dth / np.where(self._len > 0, self._len, 1.0), 0.0)
        return w, k

    @property
    def kappa(self) -> np.ndarray:
        """Identified curvature (rad/um) per robot, the current run included (posterior mean)."""
        if self.prior_var <= 0:
            return np.zeros(self.n)
        w, k = self._open()
        return (self._num + w * k) / (self._den + w)

    @property
    def kappa_sd(self) -> np.ndarray:
        """Posterior standard deviation (rad/um) of :attr:`kappa`."""
        if self.prior_var <= 0:
            return np.zeros(self.n)
        w, _ = self._open()
        return 1.0 / np.sqrt(self._den + w)

    def fits(self, last, raw, seg_um, kappa, kappa_sd, turn_rad: float = 0.0) -> bool:
        """Whether a robot seen at ``last`` then ``raw`` (raw frames) after ``seg_um`` of commanded straight
        travel and a turn predicted at ``turn_rad`` moved like a straight drive of curvature ``kappa`` (rad/um,
        known to ``kappa_sd``) that turned so much. Where in the frame the turn fell is not known here: its
        sideways effect, up to half the turn over the travel, widens the sideways gate."""
        cfg = self.settings
        dth = float(angle_difference(raw[2], last[2]))
        var_h = (2.0 * self.cam_h**2 + self.walk_var_per_um * seg_um + (kappa_sd * seg_um) ** 2
                 + (cfg.turn_rel_sd * turn_rad) ** 2)
        if abs(dth - turn_rad - kappa * seg_um) > cfg.gate_sigmas * math.sqrt(var_h):
            return False
        mid = last[2] + 0.5 * (turn_rad + kappa * seg_um)
        dx, dy = raw[0] - last[0], raw[1] - last[1]
        along = dx * math.sin(mid) + dy * math.cos(mid)
        side = dx * math.cos(mid) - dy * math.sin(mid)
        # the start heading's camera error swings the whole displacement; the curvature's error bends it
        var_p = 2.0 * self.cam_p**2 + (self.cam_h * seg_um) ** 2 + (0.5 * kappa_sd * seg_um**2) ** 2
        var_p += self.walk_var_per_um * seg_um**3 / 3.0 + (0.5 * turn_rad * seg_um) ** 2
        if abs(side) > cfg.gate_sigmas * math.sqrt(var_p):
            return False
        slack = cfg.gate_sigmas * math.sqrt(2.0) * self.cam_p
        return cfg.stop_fraction * seg_um - slack <= along <= (1.0 + cfg.over_fraction) * seg_um + slack

    def frame(self, raw, straight, travel_um, turn_rad=None) -> None:
        """Take the next raw camera ``frame`` (n, 3) (NaN rows unseen) after a drive in which robots with
        ``straight`` True drove straight by ``travel_um`` (commanded, um) and turned by ``turn_rad`` (predicted,
        rad; default none) besides: a frame whose turn exceeds ``max_turn_rad`` ends the run."""
        raw = np.asarray(raw, float)
        seen = ~np.isnan(raw).any(axis=1)
        travel = np.broadcast_to(np.asarray(travel_um, float), (self.n,))
        turn = np.zeros(self.n) if turn_rad is None else np.broadcast_to(np.asarray(turn_rad, float), (self.n,))
        straight = np.asarray(straight, bool) & (np.abs(turn) <= self.settings.max_turn_rad)
        kappa, kappa_sd = self.kappa, self.kappa_sd
        for i in range(self.n):
            chain = not np.isnan(self._last[i, 0])
            if not (straight[i] and travel[i] > 0):
                self._close(i)
                self._restart(i, raw[i] if seen[i] else None)
            elif not seen[i]:
                self._pending[i] += travel[i]
                self._pending_turn[i] += turn[i]
                if self._pending[i] > self.settings.max_bridge_um:
                    self._close(i)
                    self._restart(i, None)
            else:
                self._take(i, raw[i], chain, self._pending[i] + travel[i], self._pending_turn[i] + turn[i],
                           float(kappa[i]), float(kappa_sd[i]))

    def _take(self, i: int, raw, chain: bool, seg: float, turn: float, kappa: float, kappa_sd: float) -> None:
        """Robot ``i`` seen at ``raw`` after ``seg`` um straight and a predicted ``turn`` (rad) since its last frame."""
        if chain and self.fits(self._last[i], raw, seg, kappa, kappa_sd, turn):
            self._len[i] += seg
            self._dth[i] += float(angle_difference(raw[2], self._last[i, 2])) - turn
            self._turn_var[i] += (self.settings.turn_rel_sd * turn) ** 2
            self._last[i] = raw
            self._pending[i] = 0.0
            self._pending_turn[i] = 0.0
        else:  # a contact (or no chain): the run ends before this frame, a new chain starts at it
            self._close(i)
            self._restart(i, raw)

    def _restart(self, i: int, pose) -> None:
        self._last[i] = np.nan if pose is None else pose
        self._pending[i] = 0.0
        self._pending_turn[i] = 0.0

    def _close(self, i: int) -> None:
        if self._len[i] > 0:
            w = float(self.run_weight(self._len[i], self._turn_var[i]))
            self._num[i] += w * self._dth[i] / self._len[i]
            self._den[i] += w
        self._len[i] = 0.0
        self._dth[i] = 0.0
        self._turn_var[i] = 0.0
