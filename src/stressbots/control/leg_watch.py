"""Watching a straight leg of G_1's station transfer closed loop: where it may end, and whether it still moves.

Under P_{n-2} D_{n-1} and D_n both drive straight; the leg runs until D_{n-1}'s turning centre reaches the
next orbit of its station route. The track D_n drives was checked to end clear of D_{n-1}'s new orbit when
it was planned (timing within 0.6 s), but D_n's heading and timing errors accumulate over a leg of up to
900 um: on the tuning set the leg ended with D_n's orbit 170-240 um *inside* D_{n-1}'s new orbit disc, and
D_{n-1}'s body, orbiting, then swept every way out D_n had (every pair frame failed at that instant). So every
frame of the leg predicts both orbits at every instant to the leg's end (:func:`pair_gaps`) and the leg
stops where they are still apart (:func:`leg_stop_s`). A leg also stops when D_{n-1} no longer advances
(:class:`LegProgress`): one leg ran 242 s with the pair pushing each other.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["LegProgress", "leg_stop_s", "pair_gaps"]


def pair_gaps(c_n, h_n, v_n: float, rstar_n: float, c_m, h_m, v_m: float, rstar_m: float, taus) -> np.ndarray:
    """Gap (um) between the orbit discs of D_n and D_{n-1} after both drove straight ``taus`` (s, (K,)) more.

    ``c_*`` turning centres (um), ``h_*`` unit headings, ``v_*`` speeds (um/s), ``rstar_*`` orbit-disc radii (um);
    a straight moves a robot's turning centre with its body.

    >>> pair_gaps([0.0, 0.0], [0.0, 1.0], 100.0, 150.0, [500.0, 0.0], [0.0, 1.0], 100.0, 150.0, [0.0, 1.0]).tolist()
    [200.0, 200.0]
    """
    t = np.asarray(taus, float)[:, None]
    a = np.asarray(c_n, float)[None, :] + v_n * t * np.asarray(h_n, float)[None, :]
    b = np.asarray(c_m, float)[None, :] + v_m * t * np.asarray(h_m, float)[None, :]
    return np.hypot(*(a - b).T) - rstar_n - rstar_m


def leg_stop_s(gaps, taus, need_um: float) -> float | None:
    """How long the leg may still run (s), given the pair's orbit gaps ``gaps`` at the instants ``taus`` (ascending,
    from 0 to the leg's planned end): None (run on as planned) when the end keeps ``need_um`` (or the gap there is
    now, if smaller) or the orbits overlap already (stopping would not help); else the last instant that keeps it
    (0: stop now).

    >>> leg_stop_s([50.0, 30.0, 10.0, -20.0], [0.0, 1.0, 2.0, 3.0], 25.0)
    1.0
    >>> leg_stop_s([5.0, 8.0, 6.0, -20.0], [0.0, 1.0, 2.0, 3.0], 25.0)   # closer than 25 um already: not closer
    2.0
    >>> leg_stop_s([-50.0, 30.0, 40.0], [0.0, 1.0, 2.0], 25.0) is None
    True
    """
    g, t = np.asarray(gaps, float), np.asarray(taus, float)
    if g[0] < 0.0:
        return None
    need = min(need_um, float(g[0]))
    if g[-1] >= need:
        return None
    return float(t[np.flatnonzero(g >= need)[-1]])


@dataclass
class LegProgress:
    """D_{n-1}'s progress along a leg, frame by frame: stalled after ``frames`` frames in a row in which the distance
    left shrank by less than ``fraction`` of the commanded travel (pushed against D_n or another body)."""

    frames: int
    fraction: float
    _slow: int = field(default=0, init=False)
    _left: float | None = field(default=None, init=False)
    _want: float = field(default=0.0, init=False)

    def update(self, left_um: float, commanded_um: float) -> bool:
        """Record the distance left now and the travel commanded for the coming frame; True when stalled.

        >>> p = LegProgress(frames=2, fraction=0.3)
        >>> [p.update(left, 100.0) for left in (500.0, 400.0, 390.0, 385.0)]
        [False, False, False, True]
        """
        if self._left is not None:
            self._slow = self._slow + 1 if self._left - left_um < self.fraction * self._want else 0
        self._left, self._want = left_um, commanded_um
        return self._slow >= self.frames
