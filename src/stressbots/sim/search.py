"""Motion between contacts and the search for the first contact (the simulator's continuous-time core).

During a sub-interval of a Drive every robot either drives freely on its arc (closed form, plus its
heading drift: exact arcs between odometer knots), slides along a face at a constant velocity, or is
held. :func:`poses_at` gives the poses at any times of the sub-interval; :func:`first_contact` finds the
first time two bodies (or a body and the arena edge) interpenetrate beyond the tolerance, by sampling
every :data:`~.bodies.SAMPLE_UM` of relative travel, a Lipschitz bound between samples (so no contact
between samples is missed), finer sampling of doubtful intervals and a 16-way bisection.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..drift import HeadingDrift
from ..kinematics import follow_ends, follow_joints, move
from .bodies import (
    ARENA,
    BISECT_UM,
    CONTACT_TOL_UM,
    GRAZE_TOL_UM,
    MIN_STEP_UM,
    SAMPLE_UM,
    TOUCH_UM,
    Bodies,
)

FREE, HELD, SLIDE = 0, 1, 2
"""How a robot moves during a sub-interval: on its arc, not at all, or sliding along a face."""


class DriveRates(NamedTuple):
    """What every robot does during one Drive (all ``(n,)``)."""

    speed: np.ndarray  # um/s, this Drive's (per-run factor and per-Drive jitter)
    kappa: np.ndarray  # 1/um, base curvature (arm down 1/r, chattering 1/(2r), up 0); drift comes on top
    straight: np.ndarray  # bool: arm up and not chattering
    bound: np.ndarray  # um/s, fastest point of each body (turning and drift included)


@dataclass
class Motion:
    """How each robot moves during one sub-interval of a Drive."""

    mode: np.ndarray  # (n,) FREE / HELD / SLIDE
    slide_v: np.ndarray  # (n, 2) um/s, for sliding robots
    slide_end: np.ndarray  # (n,) s from the sub-interval start; inf when not sliding
    excluded: set  # pairs (i, j), i < j, not checked (a slide along j's face)
    recheck: bool  # a stopped robot touches a moving one


def poses_at(b: Bodies, drift: HeadingDrift, p0, motion: Motion, ctx: DriveRates, taus) -> np.ndarray:
    """Poses ``(K, n, 3)`` at times ``taus`` (s) after the sub-interval start (poses ``p0`` then)."""
    speed, kappa = ctx[0], ctx[1]
    taus = np.asarray(taus, dtype=np.float64)
    out = np.repeat(p0[None], taus.size, axis=0)
    f = np.flatnonzero(motion.mode == FREE)
    if f.size and not drift.active:
        out[:, f] = move(p0[f][None], speed[f][None, :] * taus[:, None], kappa[f][None, :])
    elif f.size:
        out[:, f] = drift_poses(b, drift, p0[f], f, speed[f], kappa[f], taus)
    s = np.flatnonzero(motion.mode == SLIDE)
    if s.size:
        out[:, s, :2] = p0[s, :2][None] + taus[:, None, None] * motion.slide_v[s][None]
    return out


def drift_poses(b: Bodies, drift: HeadingDrift, p0, idx, speed, kappa, taus) -> np.ndarray:
    """Poses ``(K, m, 3)`` of robots ``idx`` driving freely for ``taus`` s from ``p0`` on their base
    curvature plus the drift's, which is piecewise constant between odometer knots: exact arcs,
    composed (the joints in plain floats, :func:`~stressbots.kinematics.follow_joints`; then all times
    at once, pieces padded to a common count)."""
    if taus.size == 1:
        return drift_poses_one(b, drift, p0, idx, speed, kappa, float(taus[0]))[None]
    tmax = float(taus.max())
    pieces = [drift.pieces(i, o, sp * tmax) for i, o, sp in zip(idx.tolist(), b.odo[idx].tolist(), speed.tolist(), strict=True)]
    m, k = len(pieces), max(len(p[0]) for p in pieces)
    lengths = np.zeros((m, k))
    kd = np.zeros((m, k))
    for r, (ln, kv) in enumerate(pieces):
        lengths[r, : len(ln)] = ln
        kd[r, : len(kv)] = kv
    curv = kappa[:, None] + kd
    joints = follow_joints([tuple(p) for p in p0.tolist()],
                           [list(zip(ln, c[: len(ln)], strict=True)) for (ln, _), c in zip(pieces, curv.tolist(), strict=True)])
    nodes = np.array([jt + jt[-1:] * (k + 1 - len(jt)) for jt in joints])  # (m, k + 1, 3); padding never read
    cum = np.concatenate([np.zeros((m, 1)), np.cumsum(lengths, axis=1)], axis=1)
    s = np.minimum(speed[None, :] * taus[:, None], cum[None, :, -1])  # (K, m)
    last = np.array([len(p[0]) - 1 for p in pieces])  # each robot's own last piece (not the padding)
    j = np.minimum((s[..., None] >= cum[None, :, 1:]).sum(axis=-1), last[None, :])  # piece each s lies in
    rows = np.arange(m)[None, :]
    return move(nodes[rows, j], s - cum[rows, j], curv[rows, j])


def drift_poses_one(b: Bodies, drift: HeadingDrift, p0, idx, speed, kappa, tau: float) -> np.ndarray:
    """:func:`drift_poses` at one time ``tau`` (s): poses ``(m, 3)``, bit-identical, in plain floats.

    The end of every sub-interval of a Drive asks for exactly this, ~20,000 times in a 4-robot assembly:
    each robot's drift pieces up to ``tau``, the piece its arc length ``s`` lies in (as the array form
    picks it: the first whose end ``s`` has not reached, else its last), composed by
    :func:`~stressbots.kinematics.follow_ends` with one sine and one cosine call for all robots.
    """
    starts, paths = [], []
    odo = b.odo
    for r, (i, sp, k) in enumerate(zip(idx.tolist(), speed.tolist(), kappa.tolist(), strict=True)):
        lengths, kd = drift.pieces(i, float(odo[i]), sp * tau)
        total = 0.0
        ends = []
        for ln in lengths:  # running sum: np.cumsum's order
            total += ln
            ends.append(total)
        s = min(sp * tau, total)
        j = next((q for q, e in enumerate(ends) if not s >= e), len(lengths) - 1)
        before = ends[j - 1] if j else 0.0
        path = [(lengths[q], k + kd[q]) for q in range(j)]
        path.append((s - before, k + kd[j]))
        starts.append(tuple(p0[r].tolist()))
        paths.append(path)
    return np.array(follow_ends(starts, paths)).reshape(len(paths), 3)


def _candidates(b: Bodies, motion: Motion, U: np.ndarray, horizon: float) -> tuple[np.ndarray, np.ndarray]:
    """Pairs ``(ci, cj)`` that could touch within ``horizon`` s (``cj = -1``: the arena edge), given each
    body's fastest speed ``U`` (um/s): bounding circles grown by their travel, from the poses now (the
    sub-interval's start; their centre distances and wall gaps are remembered on the bodies)."""
    moving = motion.mode != HELD
    ii, jj = b.I, b.J
    keep = moving[ii] | moving[jj]
    if keep.any():
        ii, jj = ii[keep], jj[keep]
        reach = (U[ii] + U[jj]) * horizon + 1.0
        centre = b.centre_distances()[keep]
        near = centre - b.hd[ii] - b.hd[jj] < reach
        ii, jj = ii[near], jj[near]
        if motion.excluded and ii.size:
            ok = np.array([(int(a), int(c)) not in motion.excluded for a, c in zip(ii, jj, strict=True)], dtype=bool)
            ii, jj = ii[ok], jj[ok]
    else:
        ii, jj = ii[:0], jj[:0]
    ci, cj = ii, jj
    if b.arena is not None:
        m = np.flatnonzero(moving)
        g0a = b.wall_gaps()[m]
        m = m[g0a - U[m] * horizon < 1.0]
        ci = np.concatenate([ci, m])
        cj = np.concatenate([cj, np.full(m.size, ARENA)])
    return ci, cj


def first_contact(b: Bodies, drift: HeadingDrift, p0, motion: Motion, ctx: DriveRates, horizon: float):
    """First contact within ``horizon`` s: ``(tau_lo, pairs)`` or ``None``.

    ``tau_lo`` is the last time (to ~1e-10 um of travel) with no new interpenetration beyond
    :data:`~.bodies.CONTACT_TOL_UM`; ``pairs`` are the candidate pairs that interpenetrate just after it.
    ``p0`` holds the bodies' poses now (a copy: the plant moves them after the search); the broad phase
    reads their centre distances and wall gaps from the bodies.
    """
    moving = motion.mode != HELD
    if horizon <= 0.0 or not moving.any():
        return None
    U = np.where(moving, np.where(motion.mode == SLIDE, np.hypot(*motion.slide_v.T), ctx[3]), 0.0)
    ci, cj = _candidates(b, motion, U, horizon)
    if ci.size == 0:
        return None
    Uq = U[ci] + np.where(cj >= 0, U[np.maximum(cj, 0)], 0.0)
    g0 = b.gaps(p0[None], ci, cj)[0]
    # A contact is interpenetration beyond the tolerance; pairs touching now (that do not push, or
    # they would be stopped) get the graze allowance, absolute so that it never accumulates.
    thr = np.where(g0 < TOUCH_UM, -GRAZE_TOL_UM, -CONTACT_TOL_UM)
    thr = np.minimum(thr, g0 - CONTACT_TOL_UM)
    kc = max(2, math.ceil(float(Uq.max()) * horizon / SAMPLE_UM) + 1)
    taus = np.linspace(0.0, horizon, kc)
    G = b.gaps(poses_at(b, drift, p0, motion, ctx, taus), ci, cj)
    dtau = taus[1] - taus[0]
    bad = G[1:] < thr
    lower = 0.5 * (G[:-1] + G[1:] - Uq * dtau)  # Lipschitz lower bound of the true gap between samples
    unsafe = bad | (lower < thr)
    for k in np.flatnonzero(unsafe.any(axis=1)):
        qs = np.flatnonzero(unsafe[k])
        found = _refine(b, drift, p0, motion, ctx, taus[k], taus[k + 1], ci[qs], cj[qs], thr[qs], Uq[qs])
        if found is not None:
            return found
    return None


def _refine(b: Bodies, drift: HeadingDrift, p0, motion, ctx, a, c, ci, cj, thr, Uq):
    """The first contact in the doubtful interval ``[a, c]`` (s): sampled every
    :data:`~.bodies.MIN_STEP_UM`, then bisected 16 ways at a time down to :data:`~.bodies.BISECT_UM`."""

    def gaps_at(taus):
        return b.gaps(poses_at(b, drift, p0, motion, ctx, taus), ci, cj)

    kf = max(2, math.ceil(float(Uq.max()) * (c - a) / MIN_STEP_UM) + 1)
    taus = np.linspace(a, c, kf)
    bad = (gaps_at(taus) < thr).any(axis=1)
    if not bad[1:].any():
        return None
    f = int(np.argmax(bad[1:])) + 1
    lo, hi = taus[f - 1], taus[f]
    umax = float(Uq.max())
    for _ in range(24):
        if (hi - lo) * umax <= BISECT_UM:
            break
        mid = lo + (hi - lo) * np.arange(1, 16) / 16.0
        badm = (gaps_at(mid) < thr).any(axis=1)
        if badm.any():
            k = int(np.argmax(badm))
            hi = mid[k]
            lo = mid[k - 1] if k > 0 else lo
        else:
            lo = mid[-1]
    Gh = gaps_at(np.array([hi]))[0]
    pairs = [(int(x), int(y)) for x, y, g, t in zip(ci, cj, Gh, thr, strict=False) if g < t]
    return lo, pairs
