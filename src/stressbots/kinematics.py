"""Closed-form motion of robots that drive straight or on a clockwise circle (SPEC section 3).

A robot moves forward at its speed ``v`` (um/s). With its arm up it drives straight; with its arm down it
drives on a clockwise circle of its turning radius ``r`` (um). Both are arcs of constant curvature
``kappa`` (1/um): ``kappa = 0`` is straight, ``kappa = 1/r`` is the turning primitive, and any
``0 < kappa < 1/r`` is an *interpolated* turn (see :mod:`stressbots.paths`). After arc length ``s`` (um):

.. math::

    \\theta_1 = \\theta_0 + \\kappa s, \\qquad
    p_1 = p_0 + s\\,\\mathrm{sinc}(\\kappa s / 2)\\; h(\\theta_0 + \\kappa s / 2)

with ``h(theta) = (sin theta, cos theta)`` (theta clockwise from +y) and ``sinc(u) = sin(u) / u``: the
displacement is the chord of the arc, pointing along the mean heading. For ``kappa = 1/r`` this is exactly
SPEC 3's ``x += r (cos theta - cos(theta + dphi))``, ``y += r (sin(theta + dphi) - sin theta)`` (use
``cos a - cos b = 2 sin((a+b)/2) sin((b-a)/2)``), written in a form that stays accurate for tiny arcs,
for huge radii and for straight lines alike, with no branch. One formula for every robot is what lets
:func:`advance` move a whole group in a handful of vectorised numpy operations.

Everything here is a pure function on arrays; angles come back wrapped to ``[0, 2 pi)``.

Functions
---------
- :func:`move` - the one primitive: constant-curvature motion, broadcast over any shapes.
- :func:`advance` - move N robots for a duration, each turning (arm down) or straight.
- :func:`follow` - compose a sequence of segments exactly (poses at every joint).
- :func:`poses_along` - poses at arbitrary arc lengths along a segment sequence.
- :func:`sample_arclengths` - a sampling grid that keeps every segment joint.
- :func:`trajectory` - replay primitive steps for N robots, sampled finely (simulator, collision checks).
- :func:`body_outlines` - body rectangles of sampled poses, for pictures and collision checks.

Examples
--------
A quarter turn on a 200 um circle, starting at the origin facing +y, ends 200 um right and 200 um up,
facing +x:

>>> import numpy as np
>>> from stressbots.kinematics import move
>>> np.round(move([0.0, 0.0, 0.0], 100 * np.pi, 1 / 200), 9)
array([200.        , 200.        ,   1.57079633])
"""

from __future__ import annotations

import math

import numpy as np

from .robots import body_corners

__all__ = [
    "TWO_PI",
    "wrap",
    "wrap_pose",
    "move",
    "advance",
    "follow",
    "follow_ends",
    "follow_joints",
    "poses_along",
    "poses_from_joints",
    "sample_arclengths",
    "trajectory",
    "body_outlines",
]

TWO_PI = 2.0 * math.pi


def wrap(theta) -> np.ndarray:
    """Wrap angles (rad) to ``[0, 2 pi)``, as an array of the input's shape."""
    t = np.mod(theta, TWO_PI)
    # np.mod returns exactly 2 pi for tiny negative inputs (rounding); that is angle 0.
    return np.where(t >= TWO_PI, 0.0, t)


def move(poses, length_um, curvature_per_um=0.0) -> np.ndarray:
    """Poses after driving ``length_um`` along an arc of constant clockwise curvature.

    Parameters
    ----------
    poses : array_like, shape (..., 3)
        Start poses ``(x_um, y_um, theta_rad)``.
    length_um : array_like
        Arc length driven (um), broadcast against ``poses[..., 0]``. Physical motion has
        ``length_um >= 0``; a negative length runs the same arc backwards (the exact inverse).
    curvature_per_um : array_like
        ``1 / radius`` (1/um), broadcast likewise: 0 for straight motion, ``1/r`` for the turning
        primitive, anything in between for an interpolated turn. Must be finite.

    Returns
    -------
    ndarray, shape broadcast(poses[..., 0], length_um, curvature_per_um) + (3,)
        End poses, heading wrapped to ``[0, 2 pi)``.

    Notes
    -----
    Exact up to rounding, O(1) in the length (no integration): a full loop ``2 pi r`` returns to the start
    pose to ~1e-16 relative. Moving ``s1`` then ``s2`` equals moving ``s1 + s2`` to rounding.
    """
    poses = np.asarray(poses, dtype=np.float64)
    s = np.asarray(length_um, dtype=np.float64)
    kappa = np.asarray(curvature_per_um, dtype=np.float64)
    theta = poses[..., 2]
    turn = kappa * s
    # chord length s * sin(turn/2) / (turn/2): np.sinc(u) = sin(pi u) / (pi u) written out (the same operations, so
    # the same bits, without np.sinc's overhead: the escape searches call move ~300,000 times in a run)
    cycles = turn * (0.5 / math.pi)
    u = math.pi * np.where(cycles == 0.0, 1.0e-20, cycles)  # cycles, not turn: a subnormal turn scales to 0 (as np.sinc)
    chord = s * (np.sin(u) / u)
    mid = theta + 0.5 * turn
    x = poses[..., 0] + chord * np.sin(mid)
    y = poses[..., 1] + chord * np.cos(mid)
    th = wrap(theta + turn)
    out = np.empty(np.broadcast_shapes(x.shape, y.shape, th.shape) + (3,))
    out[..., 0], out[..., 1], out[..., 2] = x, y, th
    return out


def advance(poses, turning, speed_um_s, radius_um, dt_s) -> np.ndarray:
    """Move N robots for a duration, each with its arm down (turning) or up (straight).

    This is one control primitive applied to a group (SPEC 4: under ``P_k`` robots ``D_1..D_k`` turn and
    the rest drive straight): the core of plan replay and of the simulator.

    Parameters
    ----------
    poses : array_like, shape (N, 3)
        Poses ``(x_um, y_um, theta_rad)``.
    turning : array_like of bool, shape (N,)
        True where the robot's arm is down (clockwise circle of its radius), False for straight motion.
    speed_um_s : float or array_like, shape (N,)
        Forward speed of each robot (um/s).
    radius_um : float or array_like, shape (N,)
        Turning radius of each robot (um), > 0 where ``turning``.
    dt_s : float or array_like, shape (N,)
        Duration (s), common or per robot.

    Returns
    -------
    ndarray, shape (N, 3)

    Examples
    --------
    >>> import numpy as np
    >>> p = np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 0.0]])
    >>> np.round(advance(p, [True, False], 100.0, 200.0, 4 * np.pi), 9) + 0.0  # full orbit vs straight
    array([[   0.        ,    0.        ,    0.        ],
           [   0.        , 1256.63706144,    0.        ]])
    """
    turning = np.asarray(turning, dtype=bool)
    radius = np.asarray(radius_um, dtype=np.float64)
    if np.any(np.broadcast_to(radius, turning.shape)[turning] <= 0.0):
        raise ValueError("turning radius must be positive (um) for every turning robot")
    s = np.asarray(speed_um_s, dtype=np.float64) * np.asarray(dt_s, dtype=np.float64)
    with np.errstate(divide="ignore"):
        kappa = np.where(turning, 1.0 / radius, 0.0)
    return move(poses, s, kappa)


def follow(start, lengths_um, curvatures_per_um) -> np.ndarray:
    """Compose a sequence of constant-curvature segments: the pose at every joint.

    Parameters
    ----------
    start : array_like, shape (..., 3)
        Start poses (one per path; leading dimensions are batched paths).
    lengths_um, curvatures_per_um : array_like, shape (..., K)
        Segment lengths (um) and curvatures (1/um) in driving order, broadcast against
        ``start[..., :1]``.

    Returns
    -------
    ndarray, shape (..., K + 1, 3)
        ``[start, after segment 1, ..., end]``. Each joint is computed from the previous one in closed
        form, so K segments cost K vectorised steps (exact composition, no integration error).
    """
    start = np.asarray(start, dtype=np.float64)
    lengths = np.asarray(lengths_um, dtype=np.float64)
    kappas = np.asarray(curvatures_per_um, dtype=np.float64)
    lengths, kappas = np.broadcast_arrays(lengths, kappas)
    if start.shape == (3,) and lengths.ndim == 1:
        return _follow_one(start, lengths, kappas)
    lead = np.broadcast_shapes(start.shape[:-1], lengths.shape[:-1])
    pose = np.broadcast_to(start, lead + (3,))
    nodes = [pose]
    for k in range(lengths.shape[-1]):
        pose = move(pose, lengths[..., k], kappas[..., k])
        nodes.append(np.broadcast_to(pose, lead + (3,)))
    return np.stack(nodes, axis=-2)


def _follow_one(start: np.ndarray, lengths: np.ndarray, kappas: np.ndarray) -> np.ndarray:
    """:func:`follow` for one path, in plain floats (:func:`follow_joints`): bit-identical joints without
    numpy's per-call overhead on 0-d arrays (~40 us per segment; a path's joints are composed each time
    it is sampled). Checked against :func:`move` by a Hypothesis property in the tests.
    """
    x, y, th = (float(v) for v in start)
    return np.array(follow_joints([(x, y, th)], [list(zip(lengths.tolist(), kappas.tolist(), strict=True))])[0]).reshape(-1, 3)


def _move_one(x: float, y: float, theta: float, s: float, kappa: float) -> tuple[float, float, float]:
    """:func:`move` of one pose in plain floats: the same operations in the same order (numpy's sin and
    cos, whose results do not depend on the array's length; Python's float remainder, which is numpy's),
    so the result is bit-identical."""
    turn = kappa * s
    u = math.pi * (turn * (0.5 / math.pi))  # np.sinc's argument times pi
    if u == 0.0:
        u = _EPS  # np.sinc(0) = sin(eps) / eps
    mid = theta + 0.5 * turn
    sines = np.sin(np.array((u, mid)))
    chord = s * (float(sines[0]) / u)
    th = (theta + turn) % TWO_PI
    return x + chord * float(sines[1]), y + chord * float(np.cos(np.array((mid,)))[0]), 0.0 if th >= TWO_PI else th


_EPS = float(np.finfo(np.float64).eps)


def follow_ends(starts: list[tuple[float, float, float]], paths: list[list[tuple[float, float]]]) -> list[tuple[float, float, float]]:
    """The end pose of each path, ``paths[r]`` a list of ``(length_um, curvature_per_um)`` from ``starts[r]``
    (um, rad), in plain floats: bit-identical to :func:`move` applied segment after segment (the operations
    of :func:`_move_one`), but with one ``np.sin`` and one ``np.cos`` call for all segments of all paths.

    Why: the simulator moves every free robot along its drift pieces once per sub-interval of a Drive
    (two to eight robots, a few pieces each), where numpy's per-call overhead on tiny arrays, not the
    arithmetic, is the cost. The headings along a path need no trigonometry, so they are chained first.
    """
    return [joints[-1] for joints in follow_joints(starts, paths)]


def follow_joints(starts: list[tuple[float, float, float]],
                  paths: list[list[tuple[float, float]]]) -> list[list[tuple[float, float, float]]]:
    """Every joint of each path (its start, then the pose after each segment), as :func:`follow_ends`."""
    us: list[float] = []
    mids: list[float] = []
    headings: list[list[float]] = []
    for (_, _, theta), path in zip(starts, paths, strict=True):
        th = [theta]
        for s, kappa in path:
            turn = kappa * s
            u = math.pi * (turn * (0.5 / math.pi))  # np.sinc's argument times pi
            us.append(_EPS if u == 0.0 else u)  # np.sinc(0) = sin(eps) / eps
            mids.append(theta + 0.5 * turn)
            theta = (theta + turn) % TWO_PI
            if theta >= TWO_PI:
                theta = 0.0
            th.append(theta)
        headings.append(th)
    m = len(us)
    sines = np.sin(np.array(us + mids)).tolist()
    cosines = np.cos(np.array(mids)).tolist()
    out = []
    q = 0
    for (x, y, _), path, th in zip(starts, paths, headings, strict=True):
        joints = [(x, y, th[0])]
        for k, (s, _) in enumerate(path):
            chord = s * (sines[q] / us[q])
            x, y = x + chord * sines[m + q], y + chord * cosines[q]
            joints.append((x, y, th[k + 1]))
            q += 1
        out.append(joints)
    return out


def poses_along(start, lengths_um, curvatures_per_um, s_um) -> np.ndarray:
    """Poses at arc lengths ``s_um`` along one segment sequence from ``start``.

    Parameters
    ----------
    start : array_like, shape (3,)
    lengths_um, curvatures_per_um : array_like, shape (K,)
        Segments in driving order (lengths >= 0).
    s_um : array_like
        Arc lengths (um) from the start; clipped to ``[0, total]``.

    Returns
    -------
    ndarray, shape ``np.shape(s_um) + (3,)``
    """
    lengths = np.atleast_1d(np.asarray(lengths_um, dtype=np.float64))
    kappas = np.broadcast_to(np.asarray(curvatures_per_um, dtype=np.float64), lengths.shape)
    s = np.asarray(s_um, dtype=np.float64)
    start = np.asarray(start, dtype=np.float64)
    if lengths.size == 0:
        return np.broadcast_to(wrap_pose(start), s.shape + (3,)).copy()
    return poses_from_joints(follow(start, lengths, kappas), np.concatenate([[0.0], np.cumsum(lengths)]), kappas, s)


def poses_from_joints(nodes: np.ndarray, cum_um: np.ndarray, curvatures_per_um: np.ndarray, s_um) -> np.ndarray:
    """:func:`poses_along` from its segment sequence's joints, already composed: ``nodes`` ``(K + 1, 3)``
    (:func:`follow`), ``cum_um`` ``(K + 1,)`` the arc lengths (um) at the joints, from 0, and the curvatures
    ``(K,)`` (K >= 1). A path sampled many times composes its joints once (:attr:`stressbots.paths.Path.nodes`).
    """
    s = np.clip(np.asarray(s_um, dtype=np.float64), 0.0, cum_um[-1])
    idx = np.clip(np.searchsorted(cum_um, s, side="right") - 1, 0, len(curvatures_per_um) - 1)
    if s.ndim == 0:  # one pose: plain floats, bit-identical to move
        j = int(idx)
        node = nodes[j]
        return np.array(_move_one(float(node[0]), float(node[1]), float(node[2]), float(s) - float(cum_um[j]),
                                  float(curvatures_per_um[j])))
    return move(nodes[idx], s - cum_um[idx], curvatures_per_um[idx])


def wrap_pose(pose) -> np.ndarray:
    """A copy of poses ``(..., 3)`` with headings wrapped to ``[0, 2 pi)``."""
    pose = np.array(pose, dtype=np.float64)
    pose[..., 2] = wrap(pose[..., 2])
    return pose


def sample_arclengths(lengths_um, step_um) -> np.ndarray:
    """Arc lengths from 0 to the total at spacing at most ``step_um``, keeping every segment joint.

    Each segment is cut into equal pieces no longer than ``step_um``, so a sample falls on every joint
    (where the curvature switches) and on both ends.
    """
    if not step_um > 0:
        raise ValueError(f"sampling step must be positive (um), got {step_um!r}")
    lengths = np.atleast_1d(np.asarray(lengths_um, dtype=np.float64))
    parts = [np.zeros(1)]
    offset = 0.0
    for length in lengths:
        n = max(1, math.ceil(length / step_um))
        parts.append(offset + length * np.arange(1, n + 1) / n)
        offset += length
    return np.concatenate(parts)


def trajectory(poses, turning, durations_s, speed_um_s, radius_um, *, step_um=None):
    """Replay a sequence of primitive steps for N robots, sampled for pictures and collision checks.

    Parameters
    ----------
    poses : array_like, shape (N, 3)
        Start poses.
    turning : array_like of bool, shape (K, N)
        Per step, which robots have their arm down.
    durations_s : array_like, shape (K,)
        Duration of each step (s), >= 0.
    speed_um_s, radius_um : float or array_like, shape (N,)
        Per-robot speed (um/s) and turning radius (um).
    step_um : float, optional
        Largest distance any robot travels between two samples (um). ``None`` samples only the step
        ends. Every step end is always a sample.

    Returns
    -------
    times_s : ndarray, shape (M,)
        Sample times from 0, non-decreasing (a zero-duration step repeats a time).
    poses : ndarray, shape (M, N, 3)
        Poses at those times; ``poses[-1]`` equals chaining :func:`advance` over the steps.

    Notes
    -----
    Samples within a step are computed in closed form from the pose at the step's start, so sampling
    finer never changes where the robots end up.
    """
    poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    n = poses.shape[0]
    turning = np.asarray(turning, dtype=bool).reshape(-1, n)
    durations = np.atleast_1d(np.asarray(durations_s, dtype=np.float64))
    if durations.shape != (turning.shape[0],):
        raise ValueError("durations_s must have one entry per step (row of turning)")
    if np.any(durations < 0):
        raise ValueError("step durations must be >= 0 s")
    speed = np.broadcast_to(np.asarray(speed_um_s, dtype=np.float64), (n,))
    radius = np.broadcast_to(np.asarray(radius_um, dtype=np.float64), (n,))
    if np.any(radius[turning.any(axis=0)] <= 0):
        raise ValueError("turning radius must be positive (um) for every turning robot")
    vmax = float(np.max(np.abs(speed))) if n else 0.0
    times = [np.zeros(1)]
    out = [wrap_pose(poses)[None]]
    t0 = 0.0
    current = out[0][0]
    for k in range(turning.shape[0]):
        dur = durations[k]
        m = 1
        if step_um is not None and dur > 0 and vmax > 0:
            m = max(1, math.ceil(vmax * dur / step_um))
        tau = dur * np.arange(1, m + 1) / m
        with np.errstate(divide="ignore"):
            kappa = np.where(turning[k], 1.0 / radius, 0.0)
        seg = move(current[None], speed[None] * tau[:, None], kappa[None])
        times.append(t0 + tau)
        out.append(seg)
        current = seg[-1]
        t0 += dur
    return np.concatenate(times), np.concatenate(out, axis=0)


def body_outlines(poses, length_um, width_um) -> np.ndarray:
    """Body rectangles of poses of any batch shape, via :func:`stressbots.robots.body_corners`.

    Parameters
    ----------
    poses : array_like, shape (..., N, 3)
        E.g. the ``(M, N, 3)`` output of :func:`trajectory`.
    length_um, width_um : float or array_like, shape (N,)
        Per-robot body length along the heading and width across it (um).

    Returns
    -------
    ndarray, shape (..., N, 4, 2)
        Corners front-left, front-right, rear-right, rear-left.
    """
    poses = np.asarray(poses, dtype=np.float64)
    lead = poses.shape[:-1]
    length = np.broadcast_to(np.asarray(length_um, dtype=np.float64), lead)
    width = np.broadcast_to(np.asarray(width_um, dtype=np.float64), lead)
    corners = body_corners(poses.reshape(-1, 3), length.reshape(-1), width.reshape(-1))
    return corners.reshape(lead + (4, 2))
