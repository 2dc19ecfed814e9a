"""Plants written for the tests (shared by the closed-loop test modules)."""

from __future__ import annotations

import math

import numpy as np

from stressbots.kinematics import advance


class ProtocolOnly:
    """A plant that offers nothing but ``observe`` and ``apply`` (no truth for the controller to peek at)."""

    def __init__(self, inner):
        self._inner = inner

    def observe(self):
        return self._inner.observe()

    def apply(self, waveform):
        self._inner.apply(waveform)


def replay_orbit_move(poses, move, still, speed: float, radius: float, dt: float = 0.2) -> np.ndarray:
    """Independent replay of a waiting-group move (:mod:`stressbots.control.parking`): everyone turns for
    ``move.wait_s`` (P_k), then all but the robots ``still`` (which keep turning) go straight for
    ``move.straight_s`` (P_{j-1}); every robot at ``speed`` um/s and turning ``radius`` um. Poses along the way
    ``(T, n, 3)``, at most ``dt`` s apart."""
    p = np.asarray(poses, float).copy()
    n = len(p)
    out = [p.copy()]
    for turning, total in ((np.ones(n, bool), move.wait_s), (np.isin(np.arange(n), still), move.straight_s)):
        steps = max(1, int(math.ceil(total / dt)))
        for _ in range(steps):
            p = advance(p, turning, np.full(n, speed), np.full(n, radius), total / steps)
            out.append(p.copy())
    return np.array(out)
