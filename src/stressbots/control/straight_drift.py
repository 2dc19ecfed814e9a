"""Identifying each robot's heading drift while it drives straight (the bias part of the drift).

Heading drift is a per-robot process: a bias drawn once per run plus a random walk (SPEC 6). Over a
docking run of a few hundred um a bias of 2 sigma (about 7 deg/mm at the literature's noise) moves the
docking point by 10-20 um, more than the shape tolerance, and a one-way robot cannot undo a drift to the
right without a loop. The bias can be known, though: every straight drive shows it.

:class:`StraightDrift` accumulates *runs*: maximal stretches of consecutive frames during which a robot
drove straight (arm up) and moved. A run of length ``s`` whose raw camera headings at its two ends differ
by ``d`` measures the curvature ``kappa = d / s`` with an error ``sqrt(2) sigma_cam / s`` (the frames in
between cancel). Runs pool by least squares (weights ``s^2``) with a zero-mean prior worth a run of
``prior_um`` (the camera's heading noise over the prior spread of the bias). Positive = clockwise (the
heading grows), rad per um.
"""

from __future__ import annotations

import numpy as np

from ..robots import angle_difference

__all__ = ["StraightDrift"]


class StraightDrift:
    """Per-robot straight-line curvature (rad/um, + = clockwise) identified from camera frames.

    Parameters
    ----------
    n:
        Number of robots.
    prior_um:
        The zero prior counts as a run this long (um).
    stop_fraction:
        A frame in which a robot moved less than this fraction of its commanded travel ends its run
        (it touched something).

    Examples
    --------
    >>> import numpy as np
    >>> d = StraightDrift(1, prior_um=0.0)
    >>> for k in range(5):   # 100 um per frame, heading +0.01 rad per frame: 1e-4 rad/um
    ...     d.frame(np.array([[0.0, 100.0 * k, 0.01 * k]]), np.array([True]), np.array([100.0]))
    >>> d.frame(np.array([[0.0, 400.0, 0.04]]), np.array([False]), np.array([0.0]))   # it turns: the run ends
    >>> round(float(d.kappa[0]), 8)
    0.0001
    """

    def __init__(self, n: int, *, prior_um: float = 380.0, stop_fraction: float = 0.5):
        self.n = n
        self.prior_um = float(prior_um)
        self.stop_fraction = float(stop_fraction)
        self._num = np.zeros(n)
        self._den = np.full(n, self.prior_um**2)
        self._start = np.full((n, 3), np.nan)  # raw frame at the start of the current run
        self._len = np.zeros(n)  # commanded length of the current run (um)
        self._last = np.full((n, 3), np.nan)
        self._open_dtheta = np.zeros(n)

    @property
    def kappa(self) -> np.ndarray:
        """Identified curvature (rad/um) per robot, the current run included."""
        num = self._num + self._open_dtheta * self._len**2
        den = self._den + self._len**2
        return num / den

    def frame(self, raw, straight, travel_um) -> None:
        """Take the next raw camera ``frame`` (n, 3) (NaN rows unseen) after a drive in which robots with
        ``straight`` True drove only straight, by ``travel_um`` (commanded, um)."""
        raw = np.asarray(raw, float)
        seen = ~np.isnan(raw).any(axis=1)
        straight = np.asarray(straight, bool)
        travel = np.asarray(travel_um, float)
        moved = np.hypot(*(raw[:, :2] - self._last[:, :2]).T)
        cont = straight & seen & ~np.isnan(self._last).any(axis=1) & (travel > 0) & (moved >= self.stop_fraction * travel)
        for i in range(self.n):
            if cont[i]:
                if np.isnan(self._start[i]).any():
                    self._start[i] = self._last[i]
                    self._len[i] = 0.0
                self._len[i] += travel[i]
                self._open_dtheta[i] = float(angle_difference(raw[i, 2], self._start[i, 2])) / self._len[i]
            else:
                self._close(i)
        self._last = np.where(seen[:, None], raw, np.nan)

    def _close(self, i: int) -> None:
        if self._len[i] > 0:
            self._num[i] += self._open_dtheta[i] * self._len[i] ** 2
            self._den[i] += self._len[i] ** 2
        self._start[i] = np.nan
        self._len[i] = 0.0
        self._open_dtheta[i] = 0.0
