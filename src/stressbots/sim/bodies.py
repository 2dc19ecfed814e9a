"""The bodies the simulator moves: their state during a run, the geometry kernels over it, the event log.

:class:`Bodies` is the one mutable state the plant's parts share (:mod:`.search` reads it, :mod:`.contact`
and :mod:`.compliance` move robots by compliance and set ``docked`` / ``stuck``); the plant
(:class:`~stressbots.sim.SimulatedPlant`) owns it. The kernels are pure and vectorised over any batch
shape of poses ``(..., 3)`` (um, rad; heading clockwise from +y).

The tolerances below are the contact model's (see :mod:`stressbots.sim`): lengths in um of travel or of
interpenetration, far below the camera's 2 um, so that they decide nothing a controller could see.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..collision import arena_gap
from ..kinematics import wrap

STICKING_CONE_RAD = math.radians(45.0)
"""Docking compliance: largest incidence (rad) at which a front corner sticks (seed App. 3.5)."""

SELF_ALIGN_MAX_INCIDENCE_RAD = math.radians(60.0)
"""Self-aligning compliance: G_1 forms only for incidence |alpha| below this (rad)."""

SELF_ALIGN_MAX_OFFSET_UM = 80.0
"""Self-aligning compliance: G_1 forms only for lateral misalignment |w_y| below this (um)."""

SAMPLE_UM = 10.0  # coarse sampling: relative travel between samples (um)
MIN_STEP_UM = 0.5  # fine sampling of doubtful intervals (um)
BISECT_UM = 1e-10  # bisection stops at this much travel (um)
CONTACT_TOL_UM = 1e-9  # interpenetration that makes a contact event (um)
GRAZE_TOL_UM = 1e-4  # extra interpenetration allowed to a touching pair that does not push (um)
TOUCH_UM = 1e-6  # closer than this counts as touching (um)
PROBE_UM = 1e-3  # probe travel that tells whether a motion pushes into a contact (um)
PUSH_EPS_UM = 1e-9  # deeper by more than this over the probe: it pushes (um)
RECHECK_S = 0.05  # re-check a stopped robot this often while its partner moves (s)
SLIDE_OVERSHOOT_UM = 1e-4  # a slide ends this far past the face's end, clear of it (um)
FACE_TIE_UM = 1e-6  # contact faces whose lines are this close to the contact count as equally touched (um)
SWEEP_UM = 0.5  # compliance rotations are checked every this much travel of the farthest corner (um)
FLUSH_TOL_RAD = 1e-6  # front edge this parallel to a face counts as flush (rad)
ARRIVE_FLUSH_RAD = math.radians(0.5)  # a front edge this near flush on the structure's corner still docks (rad):
# SPEC 6 names no tolerance; the independent plant's choice. At zero noise a robot arrives 0.01 deg off, its corner
# 0.03 um past the end of a face as wide as itself.
NEAR_UM = 1.0  # an outcome is remembered (not logged again) while its pair stays this close (um)

ARENA = -1
"""Index standing for the arena edge where a robot index is expected (contact partners, blockers)."""


@dataclass(frozen=True)
class SimEvent:
    """Something that happened to a robot: a contact outcome or an arm anomaly.

    ``kind`` is one of ``contact``, ``dock``, ``self_align``, ``stuck``, ``graze``, ``slide_off``,
    ``blocked``, ``arena``, ``arm_flip``, ``arm_chatter``. ``other`` names the robot touched, ``"arena"``,
    or is ``None``.
    """

    time_s: float
    robot: str
    kind: str
    other: str | None = None
    detail: str = ""

    def as_dict(self) -> dict[str, Any]:
        return {"time_s": self.time_s, "robot": self.robot, "kind": self.kind, "other": self.other, "detail": self.detail}


# ----------------------------------------------------------------------------------------------------
# Geometry kernels (pure, vectorised)


def depth(pa, pb, hla, hwa, hlb, hwb) -> np.ndarray:
    """Separating-axis penetration depth of body pairs (um; <= 0 apart), as
    :func:`stressbots.collision.penetration_depth` but for any batch shape and half sizes."""
    sa, ca = np.sin(pa[..., 2]), np.cos(pa[..., 2])
    sb, cb = np.sin(pb[..., 2]), np.cos(pb[..., 2])
    dx = pb[..., 0] - pa[..., 0]
    dy = pb[..., 1] - pa[..., 1]
    cd = np.abs(sa * sb + ca * cb)  # |cos(theta_a - theta_b)|
    sd = np.abs(sa * cb - ca * sb)  # |sin(theta_a - theta_b)|
    o1 = hla + hlb * cd + hwb * sd - np.abs(dx * sa + dy * ca)  # along a's heading
    o2 = hwa + hlb * sd + hwb * cd - np.abs(dx * ca - dy * sa)  # across a
    o3 = hlb + hla * cd + hwa * sd - np.abs(dx * sb + dy * cb)  # along b's heading
    o4 = hwb + hla * sd + hwa * cd - np.abs(dx * cb - dy * sb)  # across b
    return np.minimum(np.minimum(o1, o2), np.minimum(o3, o4))


Trig = tuple[float, float, float, float]
"""A pose in plain floats with its heading's sine and cosine: ``(x_um, y_um, sin, cos)``."""


def with_trig(poses: list[tuple[float, float, float]]) -> list[Trig]:
    """``(x, y, sin theta, cos theta)`` of poses (um, rad): one ``np.sin`` and one ``np.cos`` call for all,
    so the sines are numpy's, the same bits as :func:`depth` and :func:`wall_gap` compute on arrays."""
    th = np.array([p[2] for p in poses])
    return list(zip([p[0] for p in poses], [p[1] for p in poses], np.sin(th).tolist(), np.cos(th).tolist(), strict=True))


def depth_one(a: Trig, b: Trig, hla: float, hwa: float, hlb: float, hwb: float) -> float:
    """:func:`depth` of one pair in plain floats, bit-identical (the same operations in the same order):
    the contact rules probe a few touching pairs per evaluation, where numpy's per-call cost dominates."""
    sa, ca, sb, cb = a[2], a[3], b[2], b[3]
    dx, dy = b[0] - a[0], b[1] - a[1]
    cd = abs(sa * sb + ca * cb)
    sd = abs(sa * cb - ca * sb)
    o1 = hla + hlb * cd + hwb * sd - abs(dx * sa + dy * ca)
    o2 = hwa + hlb * sd + hwb * cd - abs(dx * ca - dy * sa)
    o3 = hlb + hla * cd + hwa * sd - abs(dx * sb + dy * cb)
    o4 = hwb + hla * sd + hwa * cd - abs(dx * cb - dy * sb)
    return min(min(o1, o2), min(o3, o4))


def wall_gap_one(p: Trig, hl: float, hw: float, arena) -> float:
    """:func:`wall_gap` of one body in plain floats, bit-identical (:func:`stressbots.collision.arena_gap`'s
    operations; its half sizes ``0.5 * (2 hl)`` are ``hl`` exactly)."""
    s, c = abs(p[2]), abs(p[3])
    ex = hl * s + hw * c
    ey = hl * c + hw * s
    w, h = float(arena[0]), float(arena[1])
    x, y = p[0], p[1]
    return min(min(x - ex, w - x - ex), min(y - ey, h - y - ey))


def wall_gap(p, hl, hw, arena) -> np.ndarray:
    """Distance (um) from each body (half lengths ``hl``, ``hw``) to the nearest arena wall; negative outside."""
    return arena_gap(p, 2.0 * hl, 2.0 * hw, arena)


def rotate_about(pose, centre, phi) -> np.ndarray:
    """Poses after rotating clockwise (heading convention) by ``phi`` (rad, array) about ``centre``."""
    phi = np.asarray(phi, dtype=np.float64)
    c, s = np.cos(phi), np.sin(phi)
    dx, dy = pose[0] - centre[0], pose[1] - centre[1]
    out = np.empty(phi.shape + (3,))
    out[..., 0] = centre[0] + c * dx + s * dy
    out[..., 1] = centre[1] - s * dx + c * dy
    out[..., 2] = wrap(pose[2] + phi)
    return out


def heading_of(vec) -> float:
    """Heading (rad, clockwise from +y) of a 2-vector."""
    return float(math.atan2(vec[0], vec[1]))


def local(points, pose) -> tuple[np.ndarray, np.ndarray]:
    """Coordinates of points along (u) and across (v, to the right) a body."""
    d = np.asarray(points, dtype=np.float64) - pose[:2]
    s, c = math.sin(pose[2]), math.cos(pose[2])
    return d[..., 0] * s + d[..., 1] * c, d[..., 0] * c - d[..., 1] * s


def faces_touched(points, pose, hl, hw, tol) -> list[tuple[np.ndarray, float]]:
    """Faces of a body that any of ``points`` lies on (within ``tol``): ``(outward unit normal, outside)``.

    ``outside`` is the largest signed distance (um) of those points from the face's line (>= 0 on or
    outside it). A point at a corner lies on both faces meeting there; with none within ``tol``, the
    nearest face.
    """
    u, v = local(np.atleast_2d(points), pose)
    s, c = math.sin(pose[2]), math.cos(pose[2])
    h, r = np.array([s, c]), np.array([c, -s])
    faces = []
    for sign in (1.0, -1.0):
        on = (np.abs(sign * u - hl) <= tol) & (np.abs(v) <= hw + tol)
        if on.any():
            faces.append((sign * h, float(np.max(sign * u[on] - hl))))
        on = (np.abs(sign * v - hw) <= tol) & (np.abs(u) <= hl + tol)
        if on.any():
            faces.append((sign * r, float(np.max(sign * v[on] - hw))))
    if not faces:
        k = int(np.argmin(np.minimum(hl - np.abs(u), hw - np.abs(v))))
        if hl - abs(u[k]) <= hw - abs(v[k]):
            faces.append((math.copysign(1.0, u[k]) * h, float(abs(u[k]) - hl)))
        else:
            faces.append((math.copysign(1.0, v[k]) * r, float(abs(v[k]) - hw)))
    return faces


# ----------------------------------------------------------------------------------------------------
# The shared state


class Bodies:
    """The robots' bodies during a run: true poses, odometers, contact flags and the event log.

    Parameters
    ----------
    scenario : stressbots.scenario.Scenario
        Body sizes, names and the arena.
    poses : array_like (n, 3)
        Start poses (um, rad); headings are wrapped into [0, 2 pi).

    Notes
    -----
    Mutable on purpose: one Drive moves everybody and the contact rules move robots by compliance, in
    place, thousands of times per run. Only the plant and its parts hold a reference; the plant's public
    accessors hand out copies.
    """

    def __init__(self, scenario, poses):
        n = scenario.n
        self.names: tuple[str, ...] = scenario.names
        self.arena = scenario.arena_um
        self.hl = 0.5 * scenario.lengths_um
        self.hw = 0.5 * scenario.widths_um
        self.hd = np.hypot(self.hl, self.hw)  # half diagonal: bounding-circle radius (um)
        # reach[i, k]: centre distance (um) within which a compliance move of i could touch k (ContactRules.rule_key)
        self.reach = 2.0 * self.hd[:, None] + self.hd[None, :] + 1.0
        self.pose = np.array(poses, dtype=np.float64)
        self.pose[:, 2] = wrap(self.pose[:, 2])
        self.odo = np.zeros(n)
        self.docked = np.zeros(n, dtype=bool)
        self.stuck = np.zeros(n, dtype=bool)
        self.arena_hit = np.zeros(n, dtype=bool)
        self.events: list[SimEvent] = []
        self.I, self.J = np.triu_indices(n, k=1)  # every pair once
        self._at_key = b""  # the pose bytes the geometry in _at was computed for
        self._at: dict[str, np.ndarray] = {}

    @property
    def n(self) -> int:
        return self.pose.shape[0]

    def _now(self, name: str, compute) -> np.ndarray:
        """``compute()`` at the current poses, remembered while they stay the same bit for bit.

        The contact rules evaluate at the end of every Drive and again at the start of the next, at the
        same poses (and :meth:`~stressbots.sim.SimulatedPlant._quiet` reads the wall gaps in between);
        keyed on the pose bytes, so any move, in place or not, forgets it. Callers must not modify it.
        """
        key = self.pose.tobytes()
        if key != self._at_key:
            self._at_key, self._at = key, {}
        out = self._at.get(name)
        if out is None:
            out = self._at[name] = compute()
        return out

    def pair_depths(self) -> np.ndarray:
        """Penetration depth (um; <= 0 apart) of every pair ``(I, J)`` now."""
        P, hl, hw, ii, jj = self.pose, self.hl, self.hw, self.I, self.J
        return self._now("depth", lambda: depth(P[ii], P[jj], hl[ii], hw[ii], hl[jj], hw[jj]) if ii.size else np.zeros(0))

    def wall_gaps(self) -> np.ndarray:
        """Gap (um) of every body to the arena edge now; +inf without an arena."""
        return self._now("wall", lambda: wall_gap(self.pose, self.hl, self.hw, self.arena) if self.arena is not None
                         else np.full(self.n, np.inf))

    def centre_distances(self) -> np.ndarray:
        """Distance (um) between the centres of every pair ``(I, J)`` now."""
        P, ii, jj = self.pose, self.I, self.J
        return self._now("centre", lambda: np.hypot(P[ii, 0] - P[jj, 0], P[ii, 1] - P[jj, 1]))

    def within_reach(self) -> np.ndarray:
        """``(n, n)`` bool: body k's centre is within ``reach[i, k]`` of body i's now (the poses a compliance move
        of i could change: :meth:`~.contact.ContactRules.rule_key`)."""
        def compute():
            x, y = self.pose[:, 0], self.pose[:, 1]
            return np.hypot(x[None, :] - x[:, None], y[None, :] - y[:, None]) < self.reach
        return self._now("reach", compute)

    def gaps(self, poses, ci, cj) -> np.ndarray:
        """Gaps ``(K, Q)`` (um, negative = interpenetration) of candidate pairs ``(ci, cj)`` at poses
        ``(K, n, 3)``; ``cj = -1`` is the arena edge."""
        out = np.empty(poses.shape[:1] + ci.shape)
        pm = cj >= 0
        if pm.any():
            a, b = ci[pm], cj[pm]
            out[:, pm] = -depth(poses[:, a], poses[:, b], self.hl[a], self.hw[a], self.hl[b], self.hw[b])
        if (~pm).any():
            a = ci[~pm]
            out[:, ~pm] = wall_gap(poses[:, a], self.hl[a], self.hw[a], self.arena)
        return out

    def pair_depth(self, i: int, j: int) -> float:
        """Penetration depth (um; <= 0 apart) of bodies i and j now."""
        P = self.pose
        return float(depth(P[i], P[j], self.hl[i], self.hw[i], self.hl[j], self.hw[j]))

    def label(self, k: int) -> str:
        return "the arena edge" if k == ARENA else self.names[k]

    def log(self, t: float, i: int, kind: str, other: int | None, detail: str) -> None:
        who = None if other is None else ("arena" if other == ARENA else self.names[other])
        self.events.append(SimEvent(float(t), self.names[i], kind, who, detail))
