"""State estimation for closed-loop control: filtered poses and identified speeds and turn rates.

The camera gives every robot's pose with noise (literature: 2 um, 1 deg) and sometimes not at all; the
robots' true speeds and turning radii differ from nominal by a few per cent (fabrication). A one-way robot
cannot undo an error, so the controller needs better numbers than one frame gives:

- **Poses** are dead-reckoned between frames with the identified model and blended with each
  measurement (a fixed-gain complementary filter: gain 0.5 on position, 0.35 on heading). A
  measurement whose position is far from the prediction (a contact stopped or pushed the robot) replaces the
  estimate; one whose heading alone is far off is blended at a higher gain (:data:`JUMP_HEADING_GAIN`).
  A robot not seen keeps its prediction. A robot the controller holds still (docked, pushing into the
  structure) is placed at the mean of its frames since it stopped: the structure's pose sharpens with
  every frame. Frames read in the middle of a step list (the closed loop reads its last few, 0.05 s of
  driving apart: :class:`~stressbots.control.tuning.ControllerOptions` ``frames_per_step``) are blended
  the same way (:meth:`Estimator.blend`); the identification below runs on the step lists' last frames.
- **Turn rate** is identified over *runs*: maximal stretches of consecutive Drives during which a robot
  only turned (turn rate = heading change / time, unwrapped with the prediction), measured on raw frames
  at the run's two ends. The error of a run's estimate falls as 1/T with its length T, so runs are pooled
  with weights T^2: a robot that orbited for a minute knows its turn rate to ~0.1 %.
- **Straight runs curve**: a robot driving with its arm up follows an arc of its heading drift's bias
  (rad/um, + = clockwise). The estimator does not identify it (the controller's
  :class:`stressbots.control.straight_drift.StraightDrift` does, from raw frames); whoever does sets
  :attr:`Estimator.straight_curvature`, and predictions and the speed identification follow it.
- **Speed** is identified from every frame, whatever the robot did: with the turn rate fixed, a robot's
  path between two frames is the predicted one scaled by v / v_hat about its start (arc angles depend on
  the turn rate only, every length on the speed), so ``v = v_hat (dm . dp) / |dp|^2`` for measured and
  predicted displacements dm and dp. Frames are pooled with weights |dp|^2 (their error falls as 1/|dp|).

Everything is in um, s and rad; arrays are indexed like the scenario's robots.
"""

from __future__ import annotations

import math

import numpy as np

from .kinematics import follow_ends
from .robots import TWO_PI, angle_difference

__all__ = ["Estimator"]

POSITION_GAIN = 0.5
"""Weight of a frame's position against the dead-reckoned prediction (dimensionless)."""
HEADING_GAIN = 0.35
"""Weight of a frame's heading against the prediction (dimensionless). Replaying the estimator's inputs of
closed-loop tuning runs against the truth, the prediction over one t_x adds about as much heading error as
a frame carries, so the steady-state Kalman gain would be ~0.6 and gives a smaller error at the frames
(median 0.53 against 0.67 deg at 1x). In closed loop that gain assembled as often but more slowly (tuning
layouts 0-27, seed 0: the 18 trials both assembled took 17 % more simulated time in total; the example's
median duration 5 % more): the controller's decisions react to the less smoothed heading. So 0.35 stays."""
JUMP_UM = 15.0
"""A measurement this far (um) from the prediction means the robot was stopped or pushed: take it as is."""
JUMP_RAD = math.radians(5.0)
"""A heading this far (rad) from the prediction, its position not a jump, counts as a jump for identification (the
frame is not used for speed or turn rate) but is blended with :data:`JUMP_HEADING_GAIN`, not taken as is."""
JUMP_HEADING_GAIN = 0.5
"""Weight of a frame's heading that jumped (:data:`JUMP_RAD`) while its position did not (dimensionless). At twice the
literature's camera noise (2 deg per frame) 7.7 % of frames jump in heading alone, half of them the frame's own
error; taken as is, each left the estimate 3.0 deg off on average (mean against the simulator's truth over held-out
16:0, 23:0, 30:1, 46:0), blended at 0.5 1.3 deg (0.35: 1.6, 0.65: 1.4). One such frame, 5 deg off, set a heading
100 um short of the slot, and the re-aim burst it called docked the robot 16 um off its slot. At 1x they are rare
(4 in 6594 frames) and real (a robot stopped while turning): 0.5 converges on them within a step's frames."""
STEP_JUMP_UM = 30.0
STEP_JUMP_RAD = math.radians(15.0)
"""(STEP_JUMP_UM, STEP_JUMP_RAD) With frames inside a step list, a step's last frame this far from the whole step's
prediction is a contact too, and that part of it is taken as it is: a robot stopped by the structure lags only 5 um
per 0.05 s frame (under ``JUMP_UM``, within a frame's noise) but a t_x's run behind the step's prediction, one stopped
while turning ~2 deg per frame but tens of deg over the step. Twice ``JUMP_UM`` and three times ``JUMP_RAD``: at 2x
noise a t_x's prediction is off by more than those often enough to throw away what the step's frames built up
(with five frames per step: heading error 1.28 against 1.03 deg at 5 deg; held-out 2x 192/240 against 205 with 15 um
and 5 deg, inside the noise of 240 trials). The identification
keeps the frames these flag (only jumps against the last piece's prediction are left out of it)."""
MIN_RUN_S = 0.8
"""Runs shorter than this (s) are not used (their estimate is dominated by camera noise)."""
PRIOR_S = 0.5
"""The nominal values count as a run of this length (s)."""

_NONE, _TURN = 0, 2


class Estimator:
    """Pose filter and speed/turn-rate identification for ``n`` robots.

    Parameters
    ----------
    first : ndarray (n, 3)
        The first camera frame (NaN rows for robots not seen).
    fallback : ndarray (n, 3)
        Poses to assume for robots not seen in the first frame (the scenario's starts).
    speed_um_s, turn_radius_um : ndarray (n,)
        Nominal values: the starting point of the identification.

    Examples
    --------
    >>> import numpy as np
    >>> est = Estimator(np.array([[0.0, 0.0, 0.0]]), np.zeros((1, 3)), np.array([100.0]), np.array([200.0]))
    >>> est.update([(np.array([False]), 1.0)], np.array([False]), np.array([[0.0, 102.0, 0.0]]))
    >>> round(float(est.pose[0, 1]), 1)  # halfway between the prediction (100) and the frame (102)
    101.0
    """

    def __init__(self, first, fallback, speed_um_s, turn_radius_um):
        first = np.asarray(first, dtype=np.float64)
        self.n = first.shape[0]
        seen = ~np.isnan(first).any(axis=1)
        self.pose = np.where(seen[:, None], first, np.asarray(fallback, dtype=np.float64))
        self.pose[:, 2] = np.mod(self.pose[:, 2], TWO_PI)
        self.v_nom = np.asarray(speed_um_s, dtype=np.float64).copy()
        self.omega_nom = self.v_nom / np.asarray(turn_radius_um, dtype=np.float64)
        self.speed = self.v_nom.copy()
        self.turn_rate = self.omega_nom.copy()
        # pooled estimates (value, weight) of finished runs
        self._v_pool = self.v_nom.copy()
        self._v_w = np.full(self.n, PRIOR_S**2)  # in (um / (um/s))^2 = s^2: displacement^2 / v_nom^2
        self._w_pool = self.omega_nom.copy()
        self._w_w = np.full(self.n, PRIOR_S**2)
        # the current run of each robot
        self._mode = np.full(self.n, _NONE)
        self._ref = np.where(seen[:, None], first, np.nan)
        self._T = np.zeros(self.n)
        self._dth = np.zeros(self.n)
        self._last = np.where(seen[:, None], first, np.nan)
        self._run_est: dict[int, float] = {}
        self._was_frozen = np.zeros(self.n, dtype=bool)
        self._still_sum = np.zeros((self.n, 3))
        self._still_n = np.zeros(self.n, dtype=int)
        self.unseen = np.where(seen, 0, 1)
        self._step_start: np.ndarray | None = None  # the poses before a step list's first blended frame
        self.straight_curvature = np.zeros(self.n)
        """Curvature (rad/um, + = clockwise) of each robot's straight drives, used by the predictions."""

    @property
    def radius(self) -> np.ndarray:
        """Identified turning radii (um): speed / turn rate."""
        return self.speed / self.turn_rate

    def predict(self, steps, frozen, start=None) -> np.ndarray:
        """Dead-reckoned poses after ``steps`` = [(turning mask (n,), duration_s), ...] from ``start`` (default the
        estimates); ``frozen`` robots stay."""
        p = self._advance(self.pose if start is None else np.asarray(start, dtype=np.float64), steps, frozen)
        p[:, 2] = np.mod(p[:, 2], TWO_PI)
        return p

    def _advance(self, p, steps, frozen=None) -> np.ndarray:
        """``p`` (a new array) moved through ``steps`` at the identified speeds, ``frozen`` robots not at all:
        turning robots on their identified circles, the others along arcs of :attr:`straight_curvature`.

        In plain floats (:func:`~stressbots.kinematics.follow_ends`), bit-identical to :func:`move` step
        after step on the arrays: the loop predicts a few robots over a few steps several times per
        step list, where numpy's per-call cost, not the arithmetic, was the time.
        """
        speed, circle, straight = self.speed.tolist(), (self.turn_rate / self.speed).tolist(), self.straight_curvature.tolist()
        turns = [(np.asarray(turning, dtype=bool).tolist(), d) for turning, d in steps]
        still = [False] * self.n if frozen is None else np.asarray(frozen, dtype=bool).tolist()
        paths = [[] if still[i] else [(speed[i] * d, circle[i] if t[i] else straight[i]) for t, d in turns]
                 for i in range(self.n)]
        return np.array(follow_ends([tuple(r) for r in np.asarray(p, dtype=np.float64).tolist()], paths)).reshape(self.n, 3)

    def update(self, steps, frozen, frame, *, tail=None) -> None:
        """Advance through ``steps`` (as in :meth:`predict`) and take the camera ``frame`` (n, 3): blend it into the
        poses and identify speeds and turn rates over ``steps``.

        ``tail``: when frames in between were taken in by :meth:`blend`, the steps since the last of them (the poses
        advance through these only); the identification still spans all of ``steps``, from the last update's frame.
        """
        frame = np.asarray(frame, dtype=np.float64)
        start, self._step_start = self._step_start, None
        whole = (None if start is None or tail is None
                 else self._jumps(self._innovations(self.predict(steps, frozen, start), frame), STEP_JUMP_UM, STEP_JUMP_RAD))
        jump = self._blend(steps if tail is None else tail, frozen, frame, last=True, jumped=whole)
        seen = ~np.isnan(frame).any(axis=1)
        self._identify(steps, frozen, frame, seen, jump)
        self.unseen = np.where(seen, 0, self.unseen + 1)

    def blend(self, steps, frozen, frame) -> None:
        """Advance the poses through ``steps`` and blend in the camera ``frame`` (n, 3), without identification:
        a frame taken in the middle of a step list (:class:`~stressbots.control.loop.PlantLoop` reads its last
        few). ``frozen`` robots keep their estimate: a held robot's is the mean of the step lists' last frames
        since it stopped, and frames inside the step in which it settles into its slot would pull that mean off.

        >>> import numpy as np
        >>> est = Estimator(np.array([[0.0, 0.0, 0.0]]), np.zeros((1, 3)), np.array([100.0]), np.array([200.0]))
        >>> _ = est.blend([(np.array([False]), 0.5)], np.array([False]), np.array([[0.0, 52.0, 0.0]]))
        >>> round(float(est.pose[0, 1]), 1), float(est.speed[0])  # halfway to the frame; speed not identified
        (51.0, 100.0)
        """
        self._blend(steps, frozen, frame, last=False)

    def look(self, frames, frozen, prior_frames: float) -> None:
        """Take in camera ``frames`` ``(m, n, 3)`` read while nobody moved (Holds only, no Drive): each robot's pose
        becomes the mean of its frames, weighted against the estimate as ``prior_frames`` frames' worth.

        A still robot's frames differ by camera noise alone, so their mean is ``sqrt(m)`` times sharper than one frame,
        where the fixed-gain filter, tuned for robots that move (and whose heading drifts) between frames, keeps about
        a quarter of a frame's heading variance. ``frozen`` robots add the frames to the mean of their frames since
        they stopped; the raw reference of the identification becomes the mean, so the next frame's displacement is
        measured from it. Robots seen in no frame keep their estimate.

        >>> import numpy as np
        >>> est = Estimator(np.array([[0.0, 0.0, 0.0]]), np.zeros((1, 3)), np.array([100.0]), np.array([200.0]))
        >>> est.look(np.array([[[4.0, 0.0, 0.0]], [[2.0, 0.0, 0.0]]]), np.array([False]), prior_frames=2.0)
        >>> round(float(est.pose[0, 0]), 6)   # (2 x 0 + 2 x 3) / 4
        1.5
        """
        frames = np.asarray(frames, dtype=np.float64)
        frozen = np.asarray(frozen, dtype=bool)
        seen = ~np.isnan(frames).any(axis=2)                                           # (m, n)
        count = seen.sum(axis=0)
        ok = count > 0
        if not ok.any():
            return
        dth = np.where(seen, angle_difference(np.nan_to_num(frames[..., 2]), self.pose[None, :, 2]), 0.0)
        dxy = np.where(seen[..., None], np.nan_to_num(frames[..., :2]) - self.pose[None, :, :2], 0.0)
        mean = self.pose.copy()
        mean[:, :2] += dxy.sum(axis=0) / np.maximum(count, 1)[:, None]
        mean[:, 2] += dth.sum(axis=0) / np.maximum(count, 1)
        held = ok & frozen & self._was_frozen
        if held.any():  # a held robot: its frames join the mean of its frames since it stopped
            ref = self._still_sum[held, 2] / np.maximum(self._still_n[held], 1)
            total = mean[held].copy() * count[held][:, None]
            total[:, 2] = np.where(self._still_n[held] > 0, ref + angle_difference(mean[held, 2], ref), mean[held, 2]) * count[held]
            self._still_sum[held] += total
            self._still_n[held] += count[held]
            self.pose[held] = self._still_sum[held] / self._still_n[held][:, None]
        free = ok & ~frozen
        w = count[free] / (count[free] + max(prior_frames, 0.0))  # free robots were seen: count > 0
        self.pose[free] += w[:, None] * (mean[free] - self.pose[free])
        self.pose[:, 2] = np.mod(self.pose[:, 2], TWO_PI)
        self._last[free] = mean[free]
        self._last[free, 2] = np.mod(mean[free, 2], TWO_PI)
        self.unseen = np.where(ok, 0, self.unseen)

    @staticmethod
    def _innovations(pred, frame) -> np.ndarray:
        """``frame - pred`` (n, 3), headings wrapped to (-pi, pi]; zero for robots not seen."""
        innov = np.nan_to_num(np.asarray(frame, dtype=np.float64) - pred)
        innov[:, 2] = angle_difference(innov[:, 2], 0.0)
        return innov

    @staticmethod
    def _jumps(innov, jump_um: float = JUMP_UM, jump_rad: float = JUMP_RAD) -> tuple[np.ndarray, np.ndarray]:
        """Robots whose innovation (:meth:`_innovations`) is over ``jump_um`` in position, and over ``jump_rad`` in
        heading."""
        return np.hypot(innov[:, 0], innov[:, 1]) > jump_um, np.abs(innov[:, 2]) > jump_rad

    def _blend(self, steps, frozen, frame, *, last: bool, jumped: tuple[np.ndarray, np.ndarray] | None = None) -> np.ndarray:
        """The pose update of :meth:`update` (``last``) and :meth:`blend`; returns which robots' frames were jumps.
        ``jumped``: robots whose frame is a jump against the whole step list's prediction, in position and in heading
        (a robot stopped by a contact is 5 um behind a 0.05 s prediction, within a frame's noise, but a t_x behind
        the step's); only the part that jumped is taken from the frame, the other keeps what the step's frames
        built up."""
        frame = np.asarray(frame, dtype=np.float64)
        if not last:  # held robots keep their estimate until the step list's last frame
            frame = np.where(np.asarray(frozen, dtype=bool)[:, None], np.nan, frame)
            if self._step_start is None:
                self._step_start = self.pose.copy()
        pred = self.predict(steps, frozen)
        seen = ~np.isnan(frame).any(axis=1)
        innov = self._innovations(pred, frame)
        jump_xy, jump_th = self._jumps(innov)
        jump = (jump_xy | jump_th) & seen
        new = pred.copy()
        blend = seen & ~jump_xy
        new[blend, :2] += POSITION_GAIN * innov[blend, :2]
        new[blend, 2] += np.where(jump_th[blend], JUMP_HEADING_GAIN, HEADING_GAIN) * innov[blend, 2]
        new[seen & jump_xy] = frame[seen & jump_xy]
        if jumped is not None:  # against the whole step: position and heading each taken from the frame if it jumped
            whole_xy, whole_th = jumped[0] & seen & ~jump_xy, jumped[1] & seen & ~jump_xy
            new[whole_xy, :2] = frame[whole_xy, :2]
            new[whole_th, 2] = frame[whole_th, 2]
        if not last:
            new[:, 2] = np.mod(new[:, 2], TWO_PI)
            self.pose = new
            return jump
        # a robot held still (docked) is where the mean of its frames since it stopped says
        start = frozen & ~self._was_frozen
        self._still_sum[start] = 0.0
        self._still_n[start] = 0
        self._was_frozen = frozen.copy()
        hold = frozen & seen
        if hold.any():
            ref = self._still_sum[hold, 2] / np.maximum(self._still_n[hold], 1)
            unwrapped = frame[hold].copy()
            unwrapped[:, 2] = np.where(self._still_n[hold] > 0, ref + angle_difference(frame[hold, 2], ref), frame[hold, 2])
            self._still_sum[hold] += unwrapped
            self._still_n[hold] += 1
            new[hold] = self._still_sum[hold] / self._still_n[hold][:, None]
        new[:, 2] = np.mod(new[:, 2], TWO_PI)
        self.pose = new
        return jump

    # -- identification ------------------------------------------------------------------------------

    def _identify(self, steps, frozen, frame, seen, jump) -> None:
        total = sum(d for _, d in steps)
        turn_time = sum(np.where(t, d, 0.0) for t, d in steps) if steps else np.zeros(self.n)
        mode = np.where(turn_time >= total - 1e-9, _TURN, _NONE)
        valid = seen & ~jump & ~frozen & ~np.isnan(self._last[:, 0]) & (total > 0)
        # speed: the measured displacement against the one predicted from the last raw frame
        if valid.any():
            start = np.where(valid[:, None], self._last, 0.0)
            p = self._advance(start, steps)
            dp = p[:, :2] - start[:, :2]
            dm = frame[:, :2] - start[:, :2]
            dp2 = (dp * dp).sum(axis=1)
            for i in np.flatnonzero(valid & (dp2 >= 30.0**2)).tolist():
                value = self.speed[i] * float(dm[i] @ dp[i]) / float(dp2[i])
                if 0.6 * self.v_nom[i] < value < 1.4 * self.v_nom[i]:
                    self._v_pool[i] = ((self._v_w[i] * self._v_pool[i] + dp2[i] / self.v_nom[i] ** 2 * value)
                                       / (self._v_w[i] + dp2[i] / self.v_nom[i] ** 2))
                    self._v_w[i] += dp2[i] / self.v_nom[i] ** 2
                    self.speed[i] = self._v_pool[i]
        # turn rate: runs of pure turning
        for i in range(self.n):
            ok = bool(valid[i])
            if not ok or mode[i] == _NONE or self._mode[i] != _TURN or np.isnan(self._ref[i, 0]):
                self._commit(i)
                if ok and mode[i] == _TURN:
                    self._mode[i] = _TURN
                    self._ref[i] = self._last[i]
                    self._T[i] = total
                    self._dth[i] = self.turn_rate[i] * total
            else:
                self._T[i] += total
                self._dth[i] += self.turn_rate[i] * total
            if self._mode[i] == _TURN and self._T[i] >= MIN_RUN_S:
                self._provisional(i, frame[i])
        self._last = np.where(seen[:, None], frame, np.nan)

    def _run_value(self, i: int, end) -> float | None:
        raw = float(end[2] - self._ref[i, 2])
        dth = self._dth[i] + float(angle_difference(raw - self._dth[i], 0.0))
        value = dth / self._T[i]
        return value if 0.6 * self.omega_nom[i] < value < 1.4 * self.omega_nom[i] else None

    def _provisional(self, i: int, end) -> None:
        value = self._run_value(i, end)
        if value is None:
            self._run_est.pop(i, None)
            return
        self._run_est[i] = value
        w = self._T[i] ** 2
        self.turn_rate[i] = (self._w_w[i] * self._w_pool[i] + w * value) / (self._w_w[i] + w)

    def _commit(self, i: int) -> None:
        run = self._run_est
        if i in run and self._mode[i] == _TURN and self._T[i] >= MIN_RUN_S:
            w = self._T[i] ** 2
            self._w_pool[i] = (self._w_w[i] * self._w_pool[i] + w * run[i]) / (self._w_w[i] + w)
            self._w_w[i] += w
            self.turn_rate[i] = self._w_pool[i]
        run.pop(i, None)
        self._T[i] = 0.0
        self._mode[i] = _NONE
