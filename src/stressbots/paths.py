"""Exact shortest paths for a robot that drives forward only and turns clockwise only.

A MicroStressBot drives forward at unit rate along its path, with clockwise curvature ``u`` anywhere in
``[0, 1/r]`` (0 = arm up, ``1/r`` = arm down; values in between are reached by interpolated turning). It
can never turn counter-clockwise nor reverse, so ordinary Dubins solvers (OMPL, pydubins), which turn
both ways, answer the wrong question. Conventions as in SPEC section 2: poses ``(x_um, y_um, theta)``,
heading ``h(theta) = (sin theta, cos theta)`` with theta clockwise from +y, turning centre on the right at
``c = p + r (cos theta, -sin theta)``.

Derivation (why RSR and SRS, and nothing else)
----------------------------------------------
Pontryagin's principle for ``x' = sin theta, y' = cos theta, theta' = u`` gives constant ``lambda_x,
lambda_y`` and ``lambda_theta' = lambda_y x' - lambda_x y'``, so ``lambda_theta = lambda_y x - lambda_x y
+ c`` is affine in position. ``u`` minimises ``lambda_theta u``: the robot turns at full rate on one side
of the fixed line ``lambda_theta = 0``, drives straight on the other side, and can drive *along* the line
(a singular arc, ``u = 0``). A straight on the straight side never comes back to the line and a circle
meets a line twice, which leaves RSR (straight along the line, tangent arcs) and SRS (line crossed
transversally); ``H = 0`` with ``lambda_0 >= 0`` forces the arc of an SRS to be the *major* part of its
circle, turn >= pi. The same answer, with a global-optimality proof and no extremal bookkeeping, comes
from a convexity argument that this module implements directly:

Along any admissible path the heading only increases; write the total turn ``T = Delta + 2 pi k``
(``Delta`` = the goal heading minus the start heading, wrapped to ``[0, 2 pi)``, ``k >= 0`` whole loops).
Split each piece of path ``ds`` into a full-rate turning part ``r dtheta`` and a straight part
``ds - r dtheta >= 0``. The turning parts displace the robot by ``D(T) = r (right(theta_1) -
right(theta_2))`` whatever the order, and the straight parts form a non-negative measure ``mu`` over the
headings ``[theta_1, theta_1 + T]`` visited. With ``w = c_goal - c_start`` (the two turning centres)::

    every path  <=>  T and mu >= 0 on [theta_1, theta_1 + T] with  integral h dmu = w,
    length      =    r T + |mu|.

So the shortest path is ``min over k`` of ``r T + (least mass representing w by directions in the
heading window)``, a tiny linear programme whose optima sit on at most two directions:

- if the heading of ``w`` lies in the window ``[theta_1, theta_1 + Delta]``: one straight along ``w``,
  the path **R S R** with turns adding up to ``Delta`` (length ``r Delta + |w|``);
- else if ``Delta > pi``: straights along the window's two end headings, the path **S R S** with a
  turn of ``Delta > pi`` (for ``Delta <= pi`` the window cannot represent ``w`` at all);
- always available: one extra loop, ``k = 1``, whose window holds every direction: **R S R** with turns
  adding up to ``Delta + 2 pi`` (length ``r (Delta + 2 pi) + |w|``). Larger ``k`` only costs more.

RSR alone is not always optimal: when the goal lies ahead and to the left and faces more than half a turn
round, SRS wins (e.g. start ``(0, 0, 0)``, goal ``(-400, 400, 3 pi / 2)``, ``r = 200``: SRS
``1200 + 300 pi`` against RSR ``849 + 700 pi``). Every sub-word (``S``, ``R``, ``RS``, ``SR``, the
empty path) is a degenerate member of these two families. The measure picture also gives every length a
path can have (:func:`feasible_lengths`): for ``T >= pi`` a pair of opposite straights ``e h(psi) + e
h(psi + pi) = 0`` lengthens the path by any ``2 e``; for ``T < pi`` the mass is bounded above by the SRS
through the window's ends, so short turns admit only an interval of lengths, and e.g. ``start = goal``
admits length 0 or any length ``>= 2 pi r``.

Degenerate geometry and tolerance
---------------------------------
The true optimum is discontinuous: a goal a hair to the side of straight ahead needs a whole loop. Goal
poses computed in floating point sit on such edges constantly (a goal on the turning circle, straight
ahead, heading ``2 pi - 1e-16``). Where a path ending within ``REL_TOL = 1e-12`` of the goal (relative to
``r + |goal - start|``; ``ANGLE_TOL = 1e-12`` rad in heading) avoids a loop, that path is returned, and an
SRS near a half turn, whose straights rounding would inflate, is shortened within the same tolerance.
So every path ends at its goal to that tolerance and is never longer than the exact optimum. Of two
families of equal length (a tie) RSR is returned, unless rounding makes the SRS shorter.

Public API
----------
- :class:`Path` - a frozen path value: start, radius, ``segments`` ``(("R", um), ("S", um), ...)``.
- :func:`shortest_path`, :func:`shortest_path_lengths`, :func:`shortest_path_segments` (SPEC 7).
- :func:`feasible_lengths`, :func:`path_of_length` - paths of a prescribed length (orbit matching).
- ``approach_um=`` on the above - paths that end with a straight approach (docking).
- :func:`interpolation_duty`, :func:`interpolated_radius`, :func:`interpolated_arc`,
  :func:`interpolation_deviation` - interpolated turning to a radius ``r' >= r`` (SPEC 8).
- :func:`arc_through` - the single clockwise arc from a pose through a point (seed eq. 1, corrected).

Examples
--------
>>> from stressbots.paths import shortest_path
>>> p = shortest_path((0, 0, 0), (-400, 400, 4.71238898038469), 200)
>>> p.word, [(k, round(v, 6)) for k, v in p.segments]
('SRS', [('S', 600.0), ('R', 942.477796), ('S', 600.0)])
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

from .kinematics import TWO_PI, follow, poses_along, poses_from_joints, sample_arclengths, wrap
from .robots import Pose

__all__ = [
    "sub_path",
    "Path",
    "InfeasibleLengthError",
    "shortest_path",
    "shortest_path_lengths",
    "shortest_path_segments",
    "feasible_lengths",
    "path_of_length",
    "interpolation_duty",
    "interpolated_radius",
    "interpolated_arc",
    "interpolation_deviation",
    "ArcThrough",
    "arc_through",
    "REL_TOL",
    "ANGLE_TOL",
]

#: Relative position tolerance (of ``r + |goal - start|``) within which a path counts as reaching its goal
#: when that avoids a loop (see the module notes).
REL_TOL = 1e-12
#: Heading tolerance (rad) for the same purpose: a turn this short of a full circle counts as none.
ANGLE_TOL = 1e-12
_EPS = np.finfo(np.float64).eps
_PI = math.pi


# --------------------------------------------------------------------------------------------------
# the path value
# --------------------------------------------------------------------------------------------------


def _normalise_segments(segments) -> tuple[tuple[str, float], ...]:
    out: list[list] = []
    for item in segments:
        kind, length = item
        kind = str(kind)
        length = float(length)
        if kind not in ("R", "S"):
            raise ValueError(f"segment kind must be 'R' (clockwise arc) or 'S' (straight), got {kind!r}")
        if not (math.isfinite(length) and length >= 0.0):
            raise ValueError(f"segment length must be finite and >= 0 um, got {length!r}")
        if length == 0.0:
            continue
        if out and out[-1][0] == kind:
            out[-1][1] += length
        else:
            out.append([kind, length])
    return tuple((k, v) for k, v in out)


def _check_radius(radius):
    r = np.asarray(radius, dtype=np.float64)
    if not np.all(r > 0.0) or not np.all(np.isfinite(r)):
        bad = r[~((r > 0.0) & np.isfinite(r))] if r.ndim else r
        raise ValueError(
            f"turning radius must be positive and finite (um), got {np.ravel(bad)[0]!r}"
        )
    return r


@dataclass(frozen=True)
class Path:
    """A path of the one-way car: clockwise arcs of one radius and straights, from a start pose.

    Parameters
    ----------
    start : Pose or (x_um, y_um, theta_rad)
        Start pose; the heading is stored wrapped to ``[0, 2 pi)``.
    radius : float
        Radius of every ``"R"`` segment (um), > 0.
    segments : sequence of (kind, length_um)
        ``kind`` is ``"R"`` (clockwise arc of ``radius``) or ``"S"`` (straight); lengths are arc
        lengths in um, >= 0. Stored normalised: zero-length segments dropped, neighbours of one kind
        merged, so ``word`` is the path's true shape (``""`` for the empty path).

    Examples
    --------
    >>> p = Path((0, 0, 0), 200.0, (("S", 100.0), ("R", 0.0), ("S", 50.0)))
    >>> p.segments, p.word, p.length
    ((('S', 150.0),), 'S', 150.0)
    """

    start: Pose
    radius: float
    segments: tuple[tuple[str, float], ...] = ()

    def __post_init__(self):
        r = float(_check_radius(float(self.radius)))
        x, y, t = (float(v) for v in self.start)
        object.__setattr__(self, "start", Pose(x, y, float(wrap(t))))
        object.__setattr__(self, "radius", r)
        object.__setattr__(self, "segments", _normalise_segments(self.segments))

    @property
    def length(self) -> float:
        """Total length (um)."""
        return math.fsum(v for _, v in self.segments)

    @property
    def word(self) -> str:
        """The segment kinds in order, e.g. ``"RSR"``."""
        return "".join(k for k, _ in self.segments)

    @property
    def turn(self) -> float:
        """Total clockwise turn (rad), not wrapped."""
        return math.fsum(v for k, v in self.segments if k == "R") / self.radius

    @property
    def lengths(self) -> np.ndarray:
        """Segment lengths (um), shape (K,)."""
        return np.array([v for _, v in self.segments], dtype=np.float64)

    @property
    def curvatures(self) -> np.ndarray:
        """Segment curvatures (1/um): ``1/radius`` for R, 0 for S, shape (K,)."""
        return np.array([1.0 / self.radius if k == "R" else 0.0 for k, _ in self.segments])

    @cached_property
    def nodes(self) -> np.ndarray:
        """Poses at the start, every joint and the end, shape (K + 1, 3)."""
        return follow(np.array(self.start), self.lengths, self.curvatures)

    @property
    def end(self) -> Pose:
        """End pose (heading in ``[0, 2 pi)``)."""
        return Pose(*(float(v) for v in self.nodes[-1]))

    @cached_property
    def _joints(self) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
        """:attr:`nodes`, the arc lengths at them (um) and the segment curvatures (1/um), for
        :meth:`pose_at` (a path is sampled many times: its joints are composed once); None if empty."""
        if not self.segments:
            return None
        return self.nodes, np.concatenate([[0.0], np.cumsum(self.lengths)]), self.curvatures

    def pose_at(self, s_um):
        """Pose(s) after driving ``s_um`` (clipped to ``[0, length]``): a Pose, or (M, 3) for arrays."""
        joints = self._joints
        if joints is None:
            out = poses_along(np.array(self.start), self.lengths, self.curvatures, s_um)
        else:
            out = poses_from_joints(*joints, s_um)
        return Pose(*(float(v) for v in out)) if np.ndim(s_um) == 0 else out

    def sample(self, step_um: float) -> np.ndarray:
        """Poses at spacing at most ``step_um`` along the path, including every joint, shape (M, 3)."""
        return self.pose_at(sample_arclengths(self.lengths, step_um))

    def primitives(self, speed_um_s: float) -> tuple[tuple[bool, float], ...]:
        """The path as primitive steps ``(turning, duration_s)`` for a robot of this speed (um/s)."""
        if not speed_um_s > 0:
            raise ValueError(f"speed must be positive (um/s), got {speed_um_s!r}")
        return tuple((k == "R", v / speed_um_s) for k, v in self.segments)

    @classmethod
    def _trusted(cls, x: float, y: float, theta: float, radius: float, segments) -> Path:
        """A path from values already checked (finite floats, radius > 0, lengths >= 0): no numpy."""
        t = theta % TWO_PI
        path = object.__new__(cls)
        object.__setattr__(path, "start", Pose(x, y, 0.0 if t >= TWO_PI else t))
        object.__setattr__(path, "radius", radius)
        object.__setattr__(path, "segments", _normalise_segments(segments))
        return path

    def then(self, *segments) -> Path:
        """This path followed by more ``(kind, length_um)`` segments."""
        return Path(self.start, self.radius, self.segments + tuple(segments))


def sub_path(path: Path, s0_um: float, s1_um: float) -> Path:
    """The part of ``path`` between arc lengths ``s0_um`` and ``s1_um`` (um), as a path of its own.

    Used to cut a planned route into the pieces a robot drives between two measurements or phases.
    """
    segs = []
    acc = 0.0
    for kind, ell in path.segments:
        a, b = max(s0_um, acc), min(s1_um, acc + ell)
        if b > a:
            segs.append((kind, b - a))
        acc += ell
    return Path(Pose(*path.pose_at(s0_um)), path.radius, tuple(segs))


class InfeasibleLengthError(ValueError):
    """No path of the requested length exists; ``feasible`` holds the achievable intervals (um)."""

    def __init__(self, message: str, feasible: tuple[tuple[float, float], ...]):
        super().__init__(message)
        self.feasible = feasible


# --------------------------------------------------------------------------------------------------
# the vectorised core
# --------------------------------------------------------------------------------------------------


class _Geometry(NamedTuple):
    delta: np.ndarray  # goal heading - start heading in [0, 2 pi), snapped
    d: np.ndarray  # |w|, distance between the turning centres (um), snapped
    off: np.ndarray  # heading of w minus the start heading in [0, 2 pi), snapped
    r: np.ndarray
    tol: np.ndarray  # position tolerance (um)
    d_sin_off: np.ndarray  # w . right(t1) = |w| sin(off) (unsnapped; used where off is not snapped)
    d_cos_off: np.ndarray  # w . h(t1) = |w| cos(off)
    sin_delta: np.ndarray
    cos_delta: np.ndarray


def _as_poses(a, name):
    a = np.asarray(a, dtype=np.float64)
    if a.shape[-1:] != (3,):
        raise ValueError(f"{name} must have shape (..., 3) = (x_um, y_um, theta_rad), got {a.shape}")
    if not np.all(np.isfinite(a)):
        raise ValueError(f"{name} must be finite")
    return a


def _mod2pi(x):
    """``x mod 2 pi`` in ``[0, 2 pi]`` (np.mod is 7x slower); a rounding 2 pi is snapped by the caller."""
    return np.maximum(x - TWO_PI * np.floor(x * (1.0 / TWO_PI)), 0.0)


def _geometry(starts, goals, r) -> _Geometry:
    """Turning-centre offset w = c_goal - c_start in the start's frame, heading change, snapping.

    Five transcendental calls per pair (sin, cos of both headings, one arctan2); everything else is
    arithmetic, because this is the whole cost of the batch solver.
    """
    x1, y1, t1 = starts[..., 0], starts[..., 1], starts[..., 2]
    x2, y2, t2 = goals[..., 0], goals[..., 1], goals[..., 2]
    s1, c1, s2, c2 = np.sin(t1), np.cos(t1), np.sin(t2), np.cos(t2)
    delta = _mod2pi(t2 - t1)
    # a turn within ANGLE_TOL of a full circle is none (goal heading 2 pi - 1e-16 = start heading)
    full = delta > TWO_PI - ANGLE_TOL
    if np.any(full):
        delta = np.where(full, 0.0, delta)
        s2 = np.where(full, s1, s2)
        c2 = np.where(full, c1, c2)
    dx = x2 - x1
    dy = y2 - y1
    # w = c2 - c1 with c = p + r (cos theta, -sin theta)
    wx = dx + r * (c2 - c1)
    wy = dy - r * (s2 - s1)
    d = np.hypot(wx, wy)
    off = _mod2pi(np.arctan2(wx, wy) - t1)
    tol = REL_TOL * (r + np.abs(dx) + np.abs(dy)) + (64 * _EPS) * (
        np.abs(x1) + np.abs(y1) + np.abs(x2) + np.abs(y2) + r
    )
    # Snap: a straight that misses the heading window by less than tol of sideways error is taken to
    # lie on the window's nearer edge (otherwise a whole extra loop would be needed).
    d = np.where(d <= tol, 0.0, d)
    off = np.where((d == 0.0) | (off >= TWO_PI) | ((TWO_PI - off) * d <= tol), 0.0, off)
    off = np.where((off > delta) & ((off - delta) * d <= tol), delta, off)
    return _Geometry(
        delta, d, off, r, tol,
        wx * c1 - wy * s1, wy * c1 + wx * s1,
        s2 * c1 - c2 * s1, c2 * c1 + s2 * s1,
    )


_SRS_ILL = 0.1  # delta - pi below which the SRS is ill-conditioned


def _srs_masses(g: _Geometry, can_srs):
    """Straights ``a``, ``b`` of the SRS ``w = a h(t1) + b h(t1 + delta)`` (um), where ``can_srs``.

    Near ``delta = pi`` the two headings are almost opposite and ``a + b`` is ill-conditioned (it divides
    a sideways offset by ``sin delta``): rounding in the goal alone would make the path longer than
    the exact optimum. Shortening both straights by ``e`` moves the end by ``e |h1 + h2| <= e (delta -
    pi)``, so ``e = tol / (delta - pi)`` keeps the end within tolerance and the length never above the
    optimum. Only done where the rounding is amplified more than ``1 / _SRS_ILL`` times; elsewhere the
    SRS is exact.
    """
    with np.errstate(divide="ignore", invalid="ignore"):
        b = np.maximum(g.d_sin_off / np.where(can_srs, g.sin_delta, -1.0), 0.0)
        a = np.maximum(g.d_cos_off - b * g.cos_delta, 0.0)
        e = np.minimum(np.minimum(a, b), g.tol / np.where(can_srs, g.delta - _PI, 1.0))
    e = np.where(can_srs & (g.delta - _PI < _SRS_ILL), e, 0.0)
    return a - e, b - e


_CHUNK = 4096  # pairs per vectorised pass: keeps the temporaries in cache


def _solve_chunk(starts, goals, r, segments: bool):
    g = _geometry(starts, goals, r)
    delta, d, off = g.delta, g.d, g.off
    outside = off > delta
    l_rsr = r * (delta + TWO_PI * outside) + d
    # SRS: w = a h(t1) + b h(t1 + delta), only possible (and useful) for delta > pi, w outside the window
    can_srs = outside & (delta > _PI)
    a, b = _srs_masses(g, can_srs)
    l_srs = a + b + r * delta
    use_srs = can_srs & (l_srs < l_rsr)
    if not segments:
        return use_srs, np.where(use_srs, l_srs, l_rsr)
    arc2 = delta - off + TWO_PI * outside
    seg = np.stack(
        [
            np.where(use_srs, a, r * off),
            np.where(use_srs, r * delta, d),
            np.where(use_srs, b, r * arc2),
        ],
        axis=-1,
    )
    return use_srs, seg


def _rows(a, i: int, j: int, ndim: int, trailing: int):
    """Rows ``i:j`` along the first of ``ndim`` broadcast (lead) axes of ``a`` (``trailing`` axes after them); ``a``
    itself where it broadcasts along that axis."""
    a = np.asarray(a)
    own = a.ndim - trailing
    return a[i:j] if own == ndim and a.shape[0] != 1 else a


def _solve(starts, goals, radius, segments: bool):
    """Shortest one-way paths, vectorised. Returns (use_srs, lengths) or (use_srs, seg (..., 3)).

    ``starts``, ``goals`` and ``radius`` broadcast against each other and are not expanded first: a grid of ``W``
    starts ``(W, 1, 3)`` by ``K`` goals ``(1, K, 3)`` takes the sines and cosines of ``W + K`` headings, not ``2 W K``
    (every pair's arithmetic is the same, so are its bits). Large batches are cut into chunks of about ``_CHUNK``
    pairs along the first axis (a loop over chunks, not over pairs).
    """
    lead = np.broadcast_shapes(starts.shape[:-1], goals.shape[:-1], np.shape(radius))
    n = int(np.prod(lead))
    if n <= _CHUNK:
        return _solve_chunk(starts, goals, radius, segments)
    if n // lead[0] > _CHUNK:  # one row is longer than a chunk ((1, 100000), say): chunk the expanded flat batch
        s, g, r = (np.broadcast_to(a, lead + tail).reshape((n,) + tail) for a, tail in ((starts, (3,)), (goals, (3,)), (radius, ())))
        use, out = _solve(s, g, r, segments)
        return use.reshape(lead), out.reshape(lead + out.shape[1:])
    rows = _CHUNK // (n // lead[0])
    use = np.empty(lead, dtype=bool)
    out = np.empty(lead + (3,) if segments else lead)
    k = len(lead)
    for i in range(0, lead[0], rows):
        j = min(i + rows, lead[0])
        use[i:j], out[i:j] = _solve_chunk(_rows(starts, i, j, k, 1), _rows(goals, i, j, k, 1), _rows(radius, i, j, k, 0), segments)
    return use, out


def _prepare(starts, goals, radius, approach_um):
    starts = _as_poses(starts, "starts")
    goals = _as_poses(goals, "goals")
    r = _check_radius(radius)
    np.broadcast_shapes(starts.shape[:-1], goals.shape[:-1], r.shape)  # the shapes must fit (ValueError)
    ell = np.asarray(approach_um, dtype=np.float64)
    if np.any(ell < 0) or not np.all(np.isfinite(ell)):
        raise ValueError(f"approach_um must be finite and >= 0 um, got {approach_um!r}")
    if np.any(ell > 0):
        # goals moved back along their headings in their own shape (broadcast against ``ell``), not expanded to ``lead``
        t = goals[..., 2]
        goals = np.stack(np.broadcast_arrays(goals[..., 0] - ell * np.sin(t), goals[..., 1] - ell * np.cos(t), t), -1)
    return starts, goals, r, ell


def shortest_path_lengths(starts, goals, radius, *, approach_um=0.0) -> np.ndarray:
    """Lengths (um) of the shortest one-way paths for many pose pairs at once.

    Parameters
    ----------
    starts, goals : array_like, shape (N, 3) (or any (..., 3), broadcast)
        Poses ``(x_um, y_um, theta_rad)``; headings may be any real (wrapped internally).
    radius : float or array_like, shape (N,)
        Turning radius (um), > 0.
    approach_um : float or array_like, optional
        Require the path to end with a straight of at least this length into the goal (docking).

    Returns
    -------
    ndarray, shape (N,)

    Raises
    ------
    ValueError
        If a radius is zero, negative or not finite, or the shapes do not fit.

    Notes
    -----
    A fixed number of numpy operations per call (no Python loop per pair): about 100-200 ns per pair
    for large batches on one core. The inputs are not expanded before the work: a grid of every start by
    every goal is cheapest as ``starts[:, None]`` by ``goals[None, :]`` (same results, bit for bit, as the
    flat batch of all pairs).
    """
    starts, goals, r, ell = _prepare(starts, goals, radius, approach_um)
    _, lengths = _solve(starts, goals, r, segments=False)
    return lengths + ell


def shortest_path_segments(starts, goals, radius, *, approach_um=0.0):
    """The shortest paths of many pairs as arrays, for batch replay.

    Returns
    -------
    words : ndarray of str, shape (N,)
        ``"RSR"`` or ``"SRS"`` (the family; some lengths may be 0).
    lengths : ndarray, shape (N, 3)
        The three segment lengths (um) in driving order. With ``approach_um > 0`` the shape is
        ``(N, 4)``: a final ``"S"`` of the approach length follows (words ``"RSRS"``/``"SRSS"``).
    """
    starts, goals, r, ell = _prepare(starts, goals, radius, approach_um)
    use_srs, seg = _solve(starts, goals, r, segments=True)
    words = np.where(use_srs, "SRS", "RSR")
    if np.any(ell > 0):
        seg = np.concatenate([seg, np.broadcast_to(ell, seg.shape[:-1])[..., None]], axis=-1)
        words = np.char.add(words, "S")
    return words, seg


def _pose_tuple(p, name) -> np.ndarray:
    a = _as_poses(p, name)
    if a.shape != (3,):
        raise ValueError(f"{name} must be one pose (x_um, y_um, theta_rad), got shape {a.shape}")
    return a


def _ieee_div(a: float, b: float) -> float:
    """``a / b`` with numpy's IEEE semantics (inf or nan instead of ZeroDivisionError)."""
    if b != 0.0:
        return a / b
    return math.nan if a == 0.0 or a != a else math.copysign(math.inf, a) * math.copysign(1.0, b)


def _nanmax0(x: float) -> float:
    """``np.maximum(x, 0.0)`` for a scalar (NaN propagates)."""
    return x if x != x else (x if x > 0.0 else 0.0)


def _mod2pi_scalar(x: float) -> float:
    return max(x - TWO_PI * math.floor(x * (1.0 / TWO_PI)), 0.0)


def _SINCOS(t: np.ndarray) -> tuple[float, float, float, float]:
    s, c = np.sin(t), np.cos(t)
    return s[0], c[0], s[1], c[1]


def _solve_scalar(x1: float, y1: float, t1: float, x2: float, y2: float, t2: float, r: float) -> tuple[str, tuple[float, float, float]]:
    """One pair of :func:`_solve_chunk` in plain floats: ``(word, three segment lengths)``.

    The same operations in the same order as the vectorised core (snapping, tolerance, the SRS
    conditioning), so single queries skip numpy's per-call overhead (~100 us) and agree with the batch to
    rounding (checked by a Hypothesis property in the tests).
    """
    # numpy's transcendental functions (not math's, which may differ in the last bit): bit-identical to the batch
    s1, c1, s2, c2 = (float(v) for v in _SINCOS(np.array((t1, t2))))
    delta = _mod2pi_scalar(t2 - t1)
    if delta > TWO_PI - ANGLE_TOL:
        delta, s2, c2 = 0.0, s1, c1
    dx, dy = x2 - x1, y2 - y1
    wx = dx + r * (c2 - c1)
    wy = dy - r * (s2 - s1)
    d = float(np.hypot(wx, wy))
    off = _mod2pi_scalar(float(np.arctan2(wx, wy)) - t1)
    tol = REL_TOL * (r + abs(dx) + abs(dy)) + (64 * _EPS) * (abs(x1) + abs(y1) + abs(x2) + abs(y2) + r)
    if d <= tol:
        d = 0.0
    if d == 0.0 or off >= TWO_PI or (TWO_PI - off) * d <= tol:
        off = 0.0
    if off > delta and (off - delta) * d <= tol:
        off = delta
    outside = off > delta
    l_rsr = r * (delta + (TWO_PI if outside else 0.0)) + d
    if outside and delta > _PI:
        sin_delta, cos_delta = s2 * c1 - c2 * s1, c2 * c1 + s2 * s1
        b = _nanmax0(_ieee_div(wx * c1 - wy * s1, sin_delta))
        a = _nanmax0((wy * c1 + wx * s1) - b * cos_delta)
        if delta - _PI < _SRS_ILL:
            e = min(min(a, b), tol / (delta - _PI)) if a == a and b == b else math.nan
            a, b = a - e, b - e
        l_srs = a + b + r * delta
        if l_srs < l_rsr:
            return "SRS", (a, r * delta, b)
    arc2 = delta - off + (TWO_PI if outside else 0.0)
    return "RSR", (r * off, d, r * arc2)


def _float_pose(p, name) -> tuple[float, float, float]:
    """A finite pose as three floats (the checks of :func:`_pose_tuple` without numpy)."""
    try:
        x, y, t = p
        out = (float(x), float(y), float(t))
    except (TypeError, ValueError):
        x, y, t = (float(v) for v in _pose_tuple(p, name))  # the array path raises the usual errors
        return (x, y, t)
    if not all(math.isfinite(v) for v in out):
        raise ValueError(f"{name} must be finite")
    return out


def shortest_path(start, goal, radius, *, approach_um=0.0) -> Path:
    """The shortest path from ``start`` to ``goal`` for a robot that turns clockwise only.

    Parameters
    ----------
    start, goal : Pose or (x_um, y_um, theta_rad)
    radius : float
        Turning radius (um), > 0.
    approach_um : float, optional
        The path must end with a straight approach of at least this length (um) into the goal, as a
        robot docking front-first needs. 0 (default) means no requirement.

    Returns
    -------
    Path
        ``.length`` (um), ``.segments`` (``("R" | "S", um)`` in driving order), ``.word``, ``.end``...

    Raises
    ------
    ValueError
        If ``radius`` is zero, negative or not finite.

    Examples
    --------
    >>> p = shortest_path((0, 0, 0), (0, -1, 0), 200.0)   # goal just behind: a full loop
    >>> p.word, round(p.length / (2 * 3.141592653589793 * 200.0), 6)
    ('RSR', 1.000796)
    """
    x1, y1, t1 = _float_pose(start, "start")
    x2, y2, t2 = _float_pose(goal, "goal")
    r = float(radius)
    if not (r > 0.0 and math.isfinite(r)):
        _check_radius(r)
    ell = float(approach_um)
    if not (ell >= 0.0 and math.isfinite(ell)):
        raise ValueError(f"approach_um must be finite and >= 0 um, got {approach_um!r}")
    if ell > 0.0:
        x2, y2 = x2 - ell * math.sin(t2), y2 - ell * math.cos(t2)
    word, seg = _solve_scalar(x1, y1, t1, x2, y2, t2, r)
    segments = tuple(zip(word, seg, strict=False)) + ((("S", ell),) if ell > 0.0 else ())
    return Path._trusted(x1, y1, t1, r, segments)


# --------------------------------------------------------------------------------------------------
# paths of a prescribed length
# --------------------------------------------------------------------------------------------------


class _Classes(NamedTuple):
    g: _Geometry
    lo0: float  # class k = 0 (turn delta): lengths [lo0, hi0], lo0 = inf if empty
    hi0: float
    lo1: float  # class k = 1 (turn delta + 2 pi): lengths [lo1, inf)
    srs: tuple[float, float]  # masses (a, b) on the window's ends (valid when delta > 0 and finite)


def _classes(start, goal, radius) -> _Classes:
    g = _geometry(start, goal, np.float64(radius))
    delta, d, off, r = (float(v) for v in (g.delta, g.d, g.off, g.r))
    inside = off <= delta
    sd = math.sin(delta)
    if delta > _PI and not inside:
        a, b = (float(v) for v in _srs_masses(g, np.bool_(True)))
    elif delta > 0.0 and sd != 0.0:
        b = d * math.sin(off) / sd
        a = d * math.cos(off) - b * math.cos(delta)
    else:
        a, b = math.inf, math.inf
    if delta >= _PI:
        lo0 = r * delta + (d if inside else (a + b if delta > _PI else math.inf))
        hi0 = math.inf if math.isfinite(lo0) else -math.inf
    elif inside:
        lo0 = r * delta + d
        # the most mass: the SRS through both window ends (stable form of a + b)
        hi0 = r * delta + (d * math.cos(0.5 * delta - off) / math.cos(0.5 * delta))
        hi0 = max(hi0, lo0)
    else:
        lo0, hi0 = math.inf, -math.inf
    lo1 = r * (delta + TWO_PI) + d
    return _Classes(g, lo0, hi0, lo1, (a, b))


def _intervals(c: _Classes, shift: float = 0.0) -> tuple[tuple[float, float], ...]:
    parts = sorted(([c.lo0, c.hi0], [c.lo1, math.inf]) if c.lo0 <= c.hi0 else ([c.lo1, math.inf],))
    out = [parts[0]]
    for lo, hi in parts[1:]:
        if lo <= out[-1][1]:
            out[-1][1] = max(out[-1][1], hi)
        else:
            out.append([lo, hi])
    return tuple((lo + shift, hi + shift) for lo, hi in out)


def feasible_lengths(start, goal, radius, *, approach_um=0.0) -> tuple[tuple[float, float], ...]:
    """Every length (um) a path from ``start`` to ``goal`` can have, as disjoint closed intervals.

    The union is ``[L_min, inf)`` when the heading change is at least pi (lengthen by opposite
    straights). Otherwise it is ``[L_min, L_max]`` (paths without an extra loop, bounded by the SRS
    through the heading window's ends) and ``[L_loop, inf)`` (with one loop), which may overlap.
    The last interval always ends at ``inf``.

    Examples
    --------
    >>> import math
    >>> feasible_lengths((0, 0, 0), (0, 0, 0), 1.0) == ((0.0, 0.0), (2 * math.pi, math.inf))
    True
    """
    start = _pose_tuple(start, "start")
    goal = _pose_tuple(goal, "goal")
    r = float(_check_radius(float(radius)))
    s, g, _, ell = _prepare(start, goal, r, float(approach_um))
    return _intervals(_classes(s, g, r), float(ell))


def _from_atoms(start, radius, turn, atoms) -> Path:
    """Path with straights of mass m at heading offsets o (rad from the start heading), total turn."""
    segs = []
    cur = 0.0
    for o, m in sorted(atoms):
        o = min(max(o, cur), turn)
        segs.append(("R", radius * (o - cur)))
        segs.append(("S", max(m, 0.0)))
        cur = o
    segs.append(("R", radius * (turn - cur)))
    return Path(Pose(*start), radius, tuple(segs))


def _fmt_intervals(iv) -> str:
    return " U ".join(f"[{lo:.9g}, {hi:.9g}]" if math.isfinite(hi) else f"[{lo:.9g}, inf)" for lo, hi in iv)


def _atoms_without_loop(c: _Classes, want: float) -> tuple[float, list[tuple[float, float]]]:
    """``(turn, atoms)`` of a path of class k = 0 (turning only ``delta``) of length ``want`` (um, within the
    class's lengths): straights as ``(heading offset rad, mass um)``.

    Below a half turn the class is bounded: blend the one-straight path (the straight at the offset of
    the line to the goal) with the two-straight SRS through the heading window's ends. From a half turn
    on, add two opposite straights of equal mass (at 0 and pi), which lengthen without moving the end.
    """
    delta, d, off = float(c.g.delta), float(c.g.d), float(c.g.off)
    if delta < _PI:
        a, b = c.srs
        t = 0.0 if c.hi0 - c.lo0 <= 0.0 else (want - c.lo0) / (c.hi0 - c.lo0)
        if not (math.isfinite(a) and math.isfinite(b)):
            t, a, b = 0.0, 0.0, 0.0
        return delta, [(0.0, t * a), (off, (1.0 - t) * d), (delta, t * b)]
    if off <= delta:
        atoms = [(off, d)]
    else:
        a, b = c.srs
        atoms = [(0.0, max(a, 0.0)), (delta, max(b, 0.0))]
    e = 0.5 * (want - c.lo0)
    return delta, atoms + [(0.0, e), (_PI, e)]


def _atoms_with_loop(c: _Classes, want: float) -> tuple[float, list[tuple[float, float]]]:
    """``(turn, atoms)`` of a path of class k = 1 (turning ``delta + 2 pi``) of length ``want`` (um): the
    straight to the goal plus two opposite straights of equal mass for the extra length."""
    e = 0.5 * (want - c.lo1)
    return float(c.g.delta) + TWO_PI, [(float(c.g.off), float(c.g.d)), (0.0, e), (_PI, e)]


def path_of_length(start, goal, radius, length_um, *, approach_um=0.0) -> Path:
    """A path from ``start`` to ``goal`` of exactly ``length_um`` (um), when one exists.

    The nominal planner (seed App. 2) lengthens a robot's path so that another robot, orbiting during
    the same primitives, comes back to its start: this gives the path for any achievable length.

    Parameters
    ----------
    start, goal : Pose or (x_um, y_um, theta_rad)
    radius : float
        Turning radius (um), > 0.
    length_um : float
        Wanted length (um). Lengths within the module tolerance below the shortest are accepted.
    approach_um : float, optional
        The path ends with a straight of at least this length (um) into the goal.

    Returns
    -------
    Path
        At most seven segments (a path of the measure form: straights at up to three headings).

    Raises
    ------
    InfeasibleLengthError
        (a ``ValueError``) if no path has that length; its ``feasible`` attribute and message give the
        achievable intervals (see :func:`feasible_lengths`).
    """
    start = _pose_tuple(start, "start")
    goal = _pose_tuple(goal, "goal")
    r = float(_check_radius(float(radius)))
    s, g, _, ell = _prepare(start, goal, r, float(approach_um))
    ell = float(ell)
    want = float(length_um) - ell
    c = _classes(s, g, r)
    slack = float(c.g.tol) * 4 + 1e-12 * abs(want)
    if c.lo0 - slack <= want <= c.hi0 + slack:
        turn, atoms = _atoms_without_loop(c, min(max(want, c.lo0), c.hi0))
    elif want >= c.lo1 - slack:
        turn, atoms = _atoms_with_loop(c, max(want, c.lo1))
    else:
        iv = _intervals(c, ell)
        raise InfeasibleLengthError(
            f"no one-way path of length {float(length_um):.9g} um from {tuple(start)} to "
            f"{tuple(goal)} with turning radius {r:.9g} um: achievable lengths are "
            f"{_fmt_intervals(iv)} um",
            iv,
        )
    path = _from_atoms(s, r, turn, atoms)
    return path.then(("S", ell)) if ell > 0 else path


# --------------------------------------------------------------------------------------------------
# interpolated turning (seed App. 3.1, SPEC 8)
# --------------------------------------------------------------------------------------------------


def interpolated_radius(rho_turn, radius):
    """Mean radius (um) of a robot that turns a fraction ``rho_turn`` of the time and drives straight
    the rest: ``r' = r / rho_turn``.

    With two primitives (P_i turning for rho_a, P_{i-1} straight for rho_b, rho_a + rho_b = 1) this is
    SPEC 8's corrected ``r' = r (1 + rho_b / rho_a)``; with three (P_n, P_{n-1}, P_{n-2}) it gives
    ``r'_n = r (1 + (rho_b + rho_c) / rho_a)`` for D_n (``rho_turn = rho_a``) and SPEC 8's corrected
    eq. 3 ``r'_{n-1} = r (1 + rho_c / (rho_a + rho_b))`` for D_{n-1} (``rho_turn = rho_a + rho_b``).
    Fractions are of time, equal to fractions of distance because the speed is the same in both.
    """
    rho = np.asarray(rho_turn, dtype=np.float64)
    if np.any(rho <= 0) or np.any(rho > 1):
        raise ValueError(f"turning fraction must be in (0, 1], got {rho_turn!r}")
    out = np.asarray(radius, dtype=np.float64) / rho
    return float(out) if out.ndim == 0 else out


def interpolation_duty(r_prime, radius, period_um=None):
    """Fractions ``(rho_a, rho_b)`` of turning and straight driving that make a mean radius ``r'``.

    Parameters
    ----------
    r_prime : float
        Wanted radius (um), ``>= radius``.
    radius : float
        The robot's turning radius r (um).
    period_um : float, optional
        Switching period as distance driven per turning + straight cycle (um; ``= v x period_s``).
        ``None`` gives SPEC 8's mean relation ``rho_a = r / r'``, ``rho_b = 1 - r / r'``. With a period,
        the duty that puts the end of every cycle exactly on the circle of radius ``r'``, which is what
        :func:`interpolated_arc` uses: per cycle the robot turns ``beta`` on its own circle and drives
        ``2 (r' - r) sin(beta / 2)`` straight, with ``r beta + 2 (r' - r) sin(beta / 2) = period``;
        it tends to ``r / r'`` as the period shrinks.

    Returns
    -------
    (rho_a, rho_b) : tuple of float
    """
    r_prime = float(r_prime)
    r = float(_check_radius(float(radius)))
    if not r_prime >= r:
        raise ValueError(f"interpolated radius must be >= the turning radius {r} um, got {r_prime}")
    if period_um is None or r_prime == r:
        return r / r_prime, 1.0 - r / r_prime
    lam = float(period_um)
    if not lam > 0:
        raise ValueError(f"switching period must be positive (um), got {period_um!r}")
    if not lam <= _PI * r_prime:
        raise ValueError(f"switching period must be at most pi r' = {_PI * r_prime:.9g} um")
    f = lambda beta: r * beta + 2.0 * (r_prime - r) * math.sin(0.5 * beta) - lam  # noqa: E731
    lo, hi = 0.0, _PI
    for _ in range(200):  # bisection: f is increasing on [0, pi]
        mid = 0.5 * (lo + hi)
        if f(mid) < 0:
            lo = mid
        else:
            hi = mid
    beta = 0.5 * (lo + hi)
    rho_a = r * beta / lam
    return rho_a, 1.0 - rho_a


def interpolated_arc(start, turn_rad, r_prime, radius, max_period_um) -> Path:
    """Expand the ideal clockwise arc of radius ``r' >= r`` into explicit R/S segments.

    The ideal arc starts at ``start`` and turns ``turn_rad``. It is cut into ``n`` equal cycles, each
    turning ``beta = turn_rad / n`` with ``n`` the fewest cycles no longer than ``max_period_um`` (and
    ``beta <= pi``). Each cycle is ``R(r beta / 2) S(2 (r' - r) sin(beta / 2)) R(r beta / 2)``: the
    primitive sequence turning / straight / turning ... of seed App. 3.1 with the first and last turning
    steps halved. Then every cycle ends *exactly* on the ideal arc with the ideal heading, so the path
    ends at the ideal arc's end pose, and in between it stays inside the ideal circle, at most
    :func:`interpolation_deviation` ``(r', r, max_period_um)`` from it.

    Parameters
    ----------
    start : Pose or (x_um, y_um, theta_rad)
    turn_rad : float
        Clockwise turn of the ideal arc (rad, >= 0); its length is ``r' turn_rad``.
    r_prime : float
        Ideal radius (um), ``>= radius``.
    radius : float
        The robot's turning radius r (um).
    max_period_um : float
        Longest switching period, as distance driven per cycle (um; ``v x period_s``).

    Returns
    -------
    Path
        Radius ``radius``; ``path.primitives(v)`` gives the switching durations.
    """
    start = _pose_tuple(start, "start")
    r = float(_check_radius(float(radius)))
    r_prime = float(r_prime)
    turn = float(turn_rad)
    lam = float(max_period_um)
    if not r_prime >= r or not math.isfinite(r_prime):
        raise ValueError(f"interpolated radius must be finite and >= the turning radius {r} um, got {r_prime}")
    if not (turn >= 0 and math.isfinite(turn)):
        raise ValueError(f"turn must be finite and >= 0 rad, got {turn_rad!r}")
    if not lam > 0:
        raise ValueError(f"switching period must be positive (um), got {max_period_um!r}")
    if turn == 0.0:
        return Path(Pose(*start), r, ())
    n = max(1, math.ceil(r_prime * turn / lam), math.ceil(turn / _PI))
    beta = turn / n
    a = r * beta
    b = 2.0 * (r_prime - r) * math.sin(0.5 * beta)
    segs = [("R", 0.5 * a)]
    for _ in range(n - 1):
        segs += [("S", b), ("R", a)]
    segs += [("S", b), ("R", 0.5 * a)]
    return Path(Pose(*start), r, tuple(segs))


def interpolation_deviation(r_prime, radius, period_um):
    """Largest distance (um) between :func:`interpolated_arc`'s path and its ideal arc.

    Closed form, for cycles of at most ``period_um`` driven (``beta = min(period_um / r', pi)``)::

        delta = (r' - r) (1 - cos(beta / 2)) = 2 (r' - r) sin^2(beta / 4)  <=  (r' - r) period^2 / (8 r'^2)

    Proof: within a cycle, the two half turns lie on circles of radius r internally tangent to the ideal
    circle (centre O, radius r') at the cycle's ends, and the straight joins them symmetrically; the
    point nearest O is the straight's midpoint, at ``r + (r' - r) cos(beta / 2)`` from O (the distance
    from O of a point on a half turn decreases monotonically towards the straight). Every point stays in
    the cycle's angular sector, so its distance to the arc is its distance to the circle. The bound is
    attained when the period divides the arc exactly; it is increasing in the period.
    """
    r_prime = np.asarray(r_prime, dtype=np.float64)
    r = np.asarray(radius, dtype=np.float64)
    beta = np.minimum(np.asarray(period_um, dtype=np.float64) / r_prime, _PI)
    out = (r_prime - r) * 2.0 * np.sin(0.25 * beta) ** 2
    return float(out) if out.ndim == 0 else out


class ArcThrough(NamedTuple):
    """The single clockwise arc from a pose through a point."""

    radius_um: np.ndarray | float  #: r' (um); inf for a point straight ahead; nan if unreachable
    turn_rad: np.ndarray | float  #: clockwise turn to the point (rad), in [0, 2 pi); nan if unreachable
    length_um: np.ndarray | float  #: arc length to the point (um); nan if unreachable


def arc_through(pose, point) -> ArcThrough:
    """The clockwise arc from ``pose`` through ``point``: seed App. 3.1 eq. 1, corrected (SPEC 8).

    ``r' = (dx^2 + dy^2) / (2 (dx cos theta - dy sin theta))`` with ``dx = x_p - x_a``,
    ``dy = y_p - y_a``: the point lies on the circle of centre ``a + r' (cos theta, -sin theta)``. The
    denominator is twice the point's offset to the robot's right; when it is negative (point on the
    left) no clockwise arc reaches the point and the result is nan; when zero, the point straight ahead
    is reached by a straight (``r' = inf``, turn 0), and a point behind or at the pose is unreachable.
    Compare ``r'`` with the robot's ``r``: only ``r' >= r`` is reachable by interpolated turning.

    Vectorised over ``pose`` ``(..., 3)`` and ``point`` ``(..., 2)``.

    Examples
    --------
    >>> arc_through((0.0, 0.0, 0.0), (200.0, 200.0))   # quarter turn on a 200 um circle
    ArcThrough(radius_um=200.0, turn_rad=1.5707963267948966, length_um=314.1592653589793)
    """
    pose = np.asarray(pose, dtype=np.float64)
    point = np.asarray(point, dtype=np.float64)
    dx = point[..., 0] - pose[..., 0]
    dy = point[..., 1] - pose[..., 1]
    t = pose[..., 2]
    right = dx * np.cos(t) - dy * np.sin(t)
    ahead = dx * np.sin(t) + dy * np.cos(t)
    dist2 = dx * dx + dy * dy
    with np.errstate(divide="ignore", invalid="ignore"):
        radius = np.where(right > 0, dist2 / (2.0 * right), np.where((right == 0) & (ahead > 0), np.inf, np.nan))
        turn = np.where(right > 0, 2.0 * np.arctan2(right, ahead), np.where(np.isinf(radius), 0.0, np.nan))
        length = np.where(np.isinf(radius), ahead, radius * turn)
    if radius.ndim == 0:
        return ArcThrough(float(radius), float(turn), float(length))
    return ArcThrough(radius, turn, length)
