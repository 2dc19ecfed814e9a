"""Pre-positioning: the next robot to dock drives straight while the docking robot does (issue 15).

While D_k docks with P_k (it turns) and P_{k-1} (it drives straight), D_{k-1} orbits in place under both
(SPEC 4). But during any stretch where D_k drives straight, P_{k-2} drives D_k straight *and* D_{k-1}
straight, the robots below still orbit: D_k's motion is unchanged, and D_{k-1} makes progress toward its
own slot. This module holds the pure part: where D_{k-1} ends after one such straight stretch, how much
its own docking may then take (the best departure phase on its new orbit), and the step list with
P_{k-1} replaced by P_{k-2} in that stretch. The planner (:mod:`stressbots.planning`) chooses the
stretch and checks it against obstacles and the docking robot.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from . import paths as pathlib
from .kinematics import advance, move
from .plans import join_steps
from .robots import TWO_PI

__all__ = ["PrepositionSettings", "follower_ends", "docking_costs", "splice_straight", "straight_windows"]


@dataclass(frozen=True)
class PrepositionSettings:
    """Settings of the pre-positioning search.

    Attributes
    ----------
    min_straight_s:
        Shortest straight stretch of the docking robot (s) considered: shorter ones buy little.
    start_steps, length_fractions:
        Where in a stretch the next robot leaves its orbit (``start_steps`` even steps) and how much of
        the rest of the stretch it drives straight.
    min_gain_s:
        Least predicted saving (s) of the next robot's docking for which it is pre-positioned.
    checked:
        Most candidates (best predicted first) checked against obstacles and the docking robot.
    """

    min_straight_s: float = 1.0
    start_steps: int = 12
    length_fractions: tuple[float, ...] = (1.0, 0.75, 0.5, 0.25)
    min_gain_s: float = 0.5
    checked: int = 8


def straight_windows(steps: list[tuple[int, float]], k: int, min_s: float) -> list[tuple[float, float]]:
    """Time intervals ``(t0, t1)`` (s from the first step) of steps ``P_{k-1}`` lasting at least ``min_s``."""
    out = []
    t = 0.0
    for kk, d in steps:
        if kk == k - 1 and d >= min_s:
            out.append((t, t + d))
        t += d
    return out


def follower_ends(p0: np.ndarray, v: float, r: float, total_s: float, t0: np.ndarray, dt: np.ndarray) -> np.ndarray:
    """Poses ``(K, 3)`` after ``total_s`` of orbiting from ``p0`` with a straight of ``dt`` from ``t0`` (s)."""
    t0 = np.asarray(t0, float)
    dt = np.asarray(dt, float)
    m = t0.size
    on = np.ones(m, dtype=bool)
    p = advance(np.repeat(np.asarray(p0, float)[None, :], m, axis=0), on, v, r, t0)
    p = move(p, v * dt, 0.0)
    return advance(p, on, v, r, total_s - t0 - dt)


def docking_costs(poses: np.ndarray, target: np.ndarray, v: float, r: float, phases: int) -> tuple[np.ndarray, np.ndarray]:
    """For each orbit pose, the least wait plus shortest path (s) to ``target`` over ``phases`` departure
    phases, and the wait (s) that achieves it."""
    poses = np.atleast_2d(poses)
    period = TWO_PI * r / v
    waits = np.arange(phases) * period / phases
    k = poses.shape[0]
    rep = np.repeat(poses, phases, axis=0)
    w = np.tile(waits, k)
    src = advance(rep, np.ones(rep.shape[0], dtype=bool), v, r, w)
    cost = (w + pathlib.shortest_path_lengths(src, np.broadcast_to(target, src.shape), r) / v).reshape(k, phases)
    best = np.argmin(cost, axis=1)
    return cost[np.arange(k), best], waits[best]


def splice_straight(steps: list[tuple[int, float]], k: int, t0: float, dt: float) -> list[tuple[int, float]]:
    """``steps`` with ``P_{k-1}`` replaced by ``P_{k-2}`` from ``t0`` for ``dt`` s (that stretch must be P_{k-1}).

    Examples
    --------
    >>> splice_straight([(3, 1.0), (2, 4.0), (3, 1.0)], 3, 2.0, 1.5)
    [(3, 1.0), (2, 1.0), (1, 1.5), (2, 1.5), (3, 1.0)]
    """
    out: list[tuple[int, float]] = []
    t = 0.0
    t1 = t0 + dt
    for kk, d in steps:
        a, b = t, t + d
        t = b
        if b <= t0 + 1e-12 or a >= t1 - 1e-12:
            out.append((kk, d))
            continue
        if kk != k - 1:
            raise ValueError(f"the straight stretch {t0:.3g}-{t1:.3g} s overlaps P{kk}, not P{k - 1}")
        for lo, hi, kind in ((a, max(a, t0), kk), (max(a, t0), min(b, t1), k - 2), (min(b, t1), b, kk)):
            if hi - lo > 1e-12:
                out.append((kind, hi - lo))
    return list(join_steps(out))
