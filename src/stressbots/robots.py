"""What a MicroStressBot is: its pose, its parameters and its body.

Conventions (SPEC section 2): lengths in micrometres, time in seconds, voltages in volts, angles in
radians in the Python API. A pose is ``(x, y, theta)``; the reference point is the centre of the body
rectangle and ``theta`` is measured clockwise from +y, so the heading vector is
``h(theta) = (sin theta, cos theta)`` (seed eq. 4). Arrays of poses are ``(N, 3)`` float64.

The functional layer works on raw arrays (``heading_vectors``, ``body_corners``, ``front_edges``,
``wrap_angle``); :class:`Pose` and :class:`Robot` are thin immutable values on top.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

TWO_PI = 2.0 * math.pi


class Pose(NamedTuple):
    """A planar pose: centre of the body (um) and heading (rad, clockwise from +y)."""

    x: float
    y: float
    theta: float

    def as_array(self) -> np.ndarray:
        return np.array([self.x, self.y, self.theta], dtype=np.float64)

    @classmethod
    def from_degrees(cls, x: float, y: float, heading_deg: float) -> Pose:
        """Build a pose from the file format's ``[x_um, y_um, heading_deg]``."""
        return cls(float(x), float(y), math.radians(float(heading_deg)))

    def to_degrees(self) -> list[float]:
        """The file format's ``[x_um, y_um, heading_deg]`` with the heading in [0, 360)."""
        return [float(self.x), float(self.y), math.degrees(float(wrap_angle(self.theta)))]


def wrap_angle(theta):
    """Wrap angles (rad) to ``[0, 2 pi)``. Works on scalars and arrays."""
    wrapped = np.mod(theta, TWO_PI)
    # np.mod can return exactly 2 pi for tiny negative inputs through rounding.
    wrapped = np.where(wrapped >= TWO_PI, 0.0, wrapped)
    if np.ndim(wrapped) == 0:
        return float(wrapped)
    return wrapped


def angle_difference(a, b):
    """Signed smallest difference ``a - b`` wrapped to ``(-pi, pi]`` (rad)."""
    d = np.mod(np.asarray(a, dtype=np.float64) - b + math.pi, TWO_PI) - math.pi
    d = np.where(d <= -math.pi, d + TWO_PI, d)
    if np.ndim(d) == 0:
        return float(d)
    return d


def heading_vectors(theta) -> np.ndarray:
    """Unit heading vectors ``(sin theta, cos theta)``, shape ``theta.shape + (2,)``."""
    theta = np.asarray(theta, dtype=np.float64)
    return np.stack([np.sin(theta), np.cos(theta)], axis=-1)


def right_vectors(theta) -> np.ndarray:
    """Unit vectors to the robot's right, ``(cos theta, -sin theta)``: where its turning centre lies."""
    theta = np.asarray(theta, dtype=np.float64)
    return np.stack([np.cos(theta), -np.sin(theta)], axis=-1)


def body_corners(poses, length_um, width_um) -> np.ndarray:
    """Corners of the body rectangles, shape ``(N, 4, 2)``.

    Order: front-left, front-right, rear-right, rear-left (clockwise seen from above). ``length_um`` and
    ``width_um`` are scalars or ``(N,)`` arrays (heterogeneous robots).
    """
    poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    half_l = 0.5 * np.broadcast_to(np.asarray(length_um, dtype=np.float64), poses.shape[:1])
    half_w = 0.5 * np.broadcast_to(np.asarray(width_um, dtype=np.float64), poses.shape[:1])
    h = heading_vectors(poses[:, 2])
    rt = right_vectors(poses[:, 2])
    c = poses[:, :2]
    fl = c + half_l[:, None] * h - half_w[:, None] * rt
    fr = c + half_l[:, None] * h + half_w[:, None] * rt
    rr = c - half_l[:, None] * h + half_w[:, None] * rt
    rl = c - half_l[:, None] * h - half_w[:, None] * rt
    return np.stack([fl, fr, rr, rl], axis=1)


def front_edges(poses, length_um, width_um) -> np.ndarray:
    """Front edges as segments ``(N, 2, 2)``: front-left then front-right corner."""
    return body_corners(poses, length_um, width_um)[:, :2, :]


def front_midpoints(poses, length_um) -> np.ndarray:
    """Midpoints of the front edges ``p + (L/2) h``, shape ``(N, 2)``."""
    poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    half_l = 0.5 * np.broadcast_to(np.asarray(length_um, dtype=np.float64), poses.shape[:1])
    return poses[:, :2] + half_l[:, None] * heading_vectors(poses[:, 2])


def turning_centres(poses, radius_um) -> np.ndarray:
    """Centres of the clockwise turning circles ``p + r (cos theta, -sin theta)``, shape ``(N, 2)``."""
    poses = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    r = np.broadcast_to(np.asarray(radius_um, dtype=np.float64), poses.shape[:1])
    return poses[:, :2] + r[:, None] * right_vectors(poses[:, 2])


def orbit_radii(length_um, width_um, radius_um):
    """Radius ``r* = sqrt((r + W/2)^2 + (L/2)^2)`` of the disc an orbiting robot sweeps (um)."""
    return np.hypot(np.asarray(radius_um) + 0.5 * np.asarray(width_um), 0.5 * np.asarray(length_um))


@dataclass(frozen=True)
class Robot:
    """One MicroStressBot: its name, body, motion and electrostatic parameters.

    ``start`` and ``goal`` are optional; only commands that move robots need them.
    """

    name: str
    snap_down_V: float
    release_V: float
    length_um: float = 260.0
    width_um: float = 60.0
    speed_um_s: float = 100.0
    turn_radius_um: float = 200.0
    start: Pose | None = None
    goal: Pose | None = None

    @property
    def orbit_radius_um(self) -> float:
        """Radius of the disc swept while orbiting with the arm down (um)."""
        return float(orbit_radii(self.length_um, self.width_um, self.turn_radius_um))

    @property
    def orbit_period_s(self) -> float:
        """Time for one full orbit with the arm down, ``2 pi r / v`` (s)."""
        return TWO_PI * self.turn_radius_um / self.speed_um_s

    @property
    def turn_rate_rad_s(self) -> float:
        """Angular speed with the arm down, ``v / r`` (rad/s)."""
        return self.speed_um_s / self.turn_radius_um
