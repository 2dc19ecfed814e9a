"""Rigid motions of the plane (SE(2)) in the project's pose convention, on plain arrays.

A pose ``(x, y, theta)`` (um, um, rad) has heading ``h = (sin theta, cos theta)``: theta is measured
clockwise from +y (SPEC 2). Its *frame* has the robot's right ``a = (cos theta, -sin theta)`` as first
axis and its heading ``h`` as second, so a local point ``(u, w)`` (u to the right, w ahead) lies at

.. math::

    p + u\\,a + w\\,h = p + R(\\theta) (u, w)^T,
    \\qquad R(\\theta) = \\begin{pmatrix} \\cos\\theta & \\sin\\theta \\\\ -\\sin\\theta & \\cos\\theta \\end{pmatrix},

the clockwise rotation by theta, and local headings add: ``theta_world = theta + theta_local``. With
theta = 0 the frame is the arena's. Every transform the controller needs is one of the functions below
(composition, inverse, to/from a pose's frame, rotation about a point); they broadcast over ``(..., 3)``
pose arrays and ``(..., 2)`` point arrays. Headings come out wrapped to ``[0, 2 pi)``.

Examples
--------
>>> import numpy as np
>>> slot = np.array([100.0, 50.0, np.pi / 2])          # heading +x
>>> behind = from_frame(slot, np.array([0.0, -30.0, 0.0]))  # 30 um behind it on its approach line
>>> np.round(behind, 6).tolist()
[70.0, 50.0, 1.570796]
>>> (np.round(to_frame(slot, behind), 6) + 0.0).tolist()
[0.0, -30.0, 0.0]
>>> p = np.array([1.0, 2.0, 0.3])
>>> np.allclose(compose(p, inverse(p)), 0.0)
True
"""

from __future__ import annotations

import numpy as np

TWO_PI = 2.0 * np.pi

__all__ = ["heading", "right", "rotate", "compose", "inverse", "to_frame", "from_frame", "rotate_about", "points_to_frame"]


def heading(theta) -> np.ndarray:
    """Unit heading vectors ``(sin theta, cos theta)``, shape ``theta.shape + (2,)``.

    >>> heading(0.0).tolist()
    [0.0, 1.0]
    """
    t = np.asarray(theta, dtype=np.float64)
    return np.stack([np.sin(t), np.cos(t)], axis=-1)


def right(theta) -> np.ndarray:
    """Unit vectors to the robot's right ``(cos theta, -sin theta)`` (its turning centre lies this way).

    >>> right(0.0).tolist()
    [1.0, -0.0]
    """
    t = np.asarray(theta, dtype=np.float64)
    return np.stack([np.cos(t), -np.sin(t)], axis=-1)


def rotate(vectors, theta) -> np.ndarray:
    """Vectors ``(..., 2)`` rotated clockwise by ``theta``: ``R(theta) v``.

    >>> np.round(rotate(np.array([0.0, 1.0]), np.pi / 2), 12).tolist()
    [1.0, 0.0]
    """
    v = np.asarray(vectors, dtype=np.float64)
    t = np.asarray(theta, dtype=np.float64)
    c, s = np.cos(t), np.sin(t)
    return np.stack([v[..., 0] * c + v[..., 1] * s, -v[..., 0] * s + v[..., 1] * c], axis=-1)


def compose(a, b) -> np.ndarray:
    """``a * b``: the pose ``b`` given in ``a``'s frame, expressed in the world frame."""
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    xy = a[..., :2] + rotate(b[..., :2], a[..., 2])
    return np.concatenate([xy, np.mod(a[..., 2] + b[..., 2], TWO_PI)[..., None]], axis=-1)


def inverse(a) -> np.ndarray:
    """The inverse motion: ``compose(a, inverse(a))`` is the identity (up to the heading's wrap)."""
    a = np.asarray(a, dtype=np.float64)
    xy = -rotate(a[..., :2], -a[..., 2])
    return np.concatenate([xy, np.mod(-a[..., 2], TWO_PI)[..., None]], axis=-1)


def from_frame(frame, local) -> np.ndarray:
    """Poses given in ``frame``'s coordinates (right, ahead, relative heading) in world coordinates."""
    return compose(frame, local)


def to_frame(frame, poses) -> np.ndarray:
    """World poses in ``frame``'s coordinates: ``(right_um, ahead_um, relative heading)``; the relative
    heading is wrapped to ``(-pi, pi]`` (a signed angle: positive = clockwise of the frame's heading)."""
    frame = np.asarray(frame, dtype=np.float64)
    poses = np.asarray(poses, dtype=np.float64)
    xy = rotate(poses[..., :2] - frame[..., :2], -frame[..., 2])
    d = np.mod(poses[..., 2] - frame[..., 2] + np.pi, TWO_PI) - np.pi
    d = np.where(d <= -np.pi, d + TWO_PI, d)
    return np.concatenate([xy, d[..., None]], axis=-1)


def points_to_frame(frame, points) -> np.ndarray:
    """World points ``(..., 2)`` in ``frame``'s coordinates ``(right_um, ahead_um)``."""
    frame = np.asarray(frame, dtype=np.float64)
    return rotate(np.asarray(points, dtype=np.float64) - frame[..., :2], -frame[..., 2])


def rotate_about(poses, centre, phi) -> np.ndarray:
    """Poses turned clockwise by ``phi`` about the point ``centre`` (a rigid motion of the whole set).

    >>> np.round(rotate_about(np.array([1.0, 0.0, 0.0]), np.zeros(2), np.pi / 2), 12).tolist()
    [0.0, -1.0, 1.570796326795]
    """
    poses = np.asarray(poses, dtype=np.float64)
    c = np.asarray(centre, dtype=np.float64)
    xy = c + rotate(poses[..., :2] - c, phi)
    return np.concatenate([xy, np.mod(poses[..., 2] + phi, TWO_PI)[..., None]], axis=-1)
