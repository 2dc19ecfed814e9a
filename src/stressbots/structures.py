"""Target structures: slots with contact geometry, named shapes and explicit per-robot goals.

SPEC section 5, seed Appendix 2. A structure is a sequence of *slots* (goal poses) in docking order.
With the robots in voltage order D_1..D_n (D_1 has the lowest snap-down voltage):

1. D_n and D_{n-1} form G_1: head-on, front edges flush and collinear (front-edge midpoints coincide,
   headings opposite, long axes on one line), a bar of length L_n + L_{n-1}.
2. D_{n-2}, ..., D_1 then dock one at a time, each *front-first* against a free side of the structure
   built so far: its front edge lies on the line of that side and within its extent, its body is outside
   the structure, and it is approachable: the straight corridor swept by its body backwards from the
   slot over ``approach_um`` crosses no robot docked before it. Docked robots keep pushing and never move.

Why the corridor: a docking robot ends its path driving straight along its heading (the fine-motion
strategy and docking compliance of seed App. 3 rely on it), so it needs a straight, free lane into its
slot that earlier robots do not block.

Two ways to get a :class:`Structure`:

- :func:`candidate_structures` for a named shape (``[structure] shape / at``): this module assigns robots
  to slots so every approach is clear and offers the planner several variants (mirror images, which
  G_1 robot takes which end, which side a stem or tooth grows on) to pick the shortest paths from.
- :func:`structure_from_goals` for explicit goals: validated against the docking order, rejected with a
  one-line :class:`~stressbots.errors.PlanningError` naming the robot, the reason and the numbers.

Named shapes live in the frame ``[structure] at = [x, y, heading]``: origin at the G_1 junction (the
common front-edge midpoint of D_n and D_{n-1}), the bar along the frame's right vector ``a``, stems and
teeth along ``+-b`` (``b`` = the frame's heading). With heading 0 a canonical tee reads as the letter T.
:data:`SHAPES` holds the exact definitions.

Tolerances: :data:`POS_TOL_UM` (0.5 um) in position and :data:`ANG_TOL_RAD` (0.1 deg) in angle.
Touching is not overlapping: bodies may interpenetrate by up to :data:`POS_TOL_UM` (floating noise in
user-computed goals), so docking into a gap exactly one robot wide between two docked neighbours is valid.

Conventions (SPEC section 2): lengths in um, angles in rad, pose = body centre and heading theta
clockwise from +y, heading vector ``h = (sin theta, cos theta)``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Literal, NamedTuple

import numpy as np
import shapely
from shapely.geometry import LineString, Polygon
from shapely.geometry.base import BaseGeometry

from .errors import PlanningError, ScenarioError
from .robots import Pose, Robot, angle_difference, body_corners, orbit_radii, wrap_angle

if TYPE_CHECKING:  # pragma: no cover - only for type hints; keeps this module free of import cycles
    from .scenario import StructureSpec

__all__ = [
    "POS_TOL_UM",
    "ANG_TOL_RAD",
    "APPROACH_MARGIN_UM",
    "SHAPES",
    "Side",
    "Slot",
    "Structure",
    "candidate_structures",
    "named_structure",
    "structure_from_goals",
    "target_structures",
]

POS_TOL_UM = 0.5
"""Position tolerance (um): flushness, coincidence, and the largest interpenetration taken as touching."""

ANG_TOL_RAD = math.radians(0.1)
"""Angle tolerance (rad): parallel front edges and opposite G_1 headings."""

APPROACH_MARGIN_UM = 50.0
"""Default straight approach of a slot is the robot's own length plus this margin (um)."""

_HALF_PI = 0.5 * math.pi
_GRID_UM = 1e-6  # snap-rounding grid for overlays: plain GEOS overlay is fragile on shared edges


# ----------------------------------------------------------------------------------------------------
# Value types


@dataclass(frozen=True)
class Side:
    """A straight free piece of the structure's outline, where a robot can rest its front edge.

    ``start -> end`` runs with the structure on its right (clockwise around the outline), so the outward
    unit ``normal`` is to the left. A robot docking on it heads along ``-normal``.

    Attributes
    ----------
    start, end:
        End points (um).
    normal:
        Outward unit normal.
    robots:
        Names of the robots whose body edges form this side, in docking order.
    """

    start: tuple[float, float]
    end: tuple[float, float]
    normal: tuple[float, float]
    robots: tuple[str, ...]
    pieces: tuple[tuple[str, float, float], ...] = field(default=(), repr=False)
    """``(robot, u0, u1)``: which robot's edge covers which stretch, as distances (um) from ``start``."""

    @property
    def segment(self) -> tuple[tuple[float, float], tuple[float, float]]:
        return (self.start, self.end)

    @property
    def length_um(self) -> float:
        return math.dist(self.start, self.end)

    @property
    def direction(self) -> np.ndarray:
        """Unit vector from ``start`` to ``end``."""
        return (np.asarray(self.end) - np.asarray(self.start)) / max(self.length_um, 1e-300)

    @property
    def midpoint(self) -> tuple[float, float]:
        return (0.5 * (self.start[0] + self.end[0]), 0.5 * (self.start[1] + self.end[1]))

    @property
    def docking_heading_rad(self) -> float:
        """Heading (rad) of a robot docked on this side: along the inward normal."""
        return wrap_angle(math.atan2(-self.normal[0], -self.normal[1]))

    def fits(self, width_um: float) -> bool:
        """Whether a front edge ``width_um`` wide fits within this side (with tolerance)."""
        return self.length_um + 2.0 * POS_TOL_UM >= width_um

    def pose_at(self, length_um: float, along_um: float) -> Pose:
        """Slot pose of a robot of length ``length_um`` whose front-edge midpoint is ``along_um`` from start.

        The caller keeps the front edge within the side: ``W/2 <= along_um <= length - W/2``.
        """
        p = np.asarray(self.start) + along_um * self.direction
        c = p + 0.5 * length_um * np.asarray(self.normal)
        return Pose(float(c[0]), float(c[1]), self.docking_heading_rad)

    def supports(self, u0: float, u1: float) -> tuple[str, ...]:
        """Robots whose edges lie under the stretch ``[u0, u1]`` (um from ``start``) of this side."""
        under = {name for name, a, b in self.pieces if min(b, u1) - max(a, u0) > POS_TOL_UM}
        return tuple(name for name in self.robots if name in under)


@dataclass(frozen=True)
class Slot:
    """One robot's place in a structure: goal pose and contact geometry.

    Attributes
    ----------
    robot:
        Robot name.
    index:
        Voltage index i of D_i (1 = lowest snap-down voltage).
    pose:
        Goal pose (body centre in um, heading in rad in ``[0, 2 pi)``).
    role:
        ``"pair"`` for the two robots of G_1 (D_n, D_{n-1}), ``"dock"`` for D_{n-2}..D_1.
    length_um, width_um:
        Body size L x W.
    orbit_radius_um:
        r*, the radius of the disc the robot sweeps while orbiting (``robots.orbit_radii``).
    contact:
        The structure edge its front edge rests on: for a docking robot the free side of the structure
        as it was just before it docked; for the pair, the partner's front edge.
    supports:
        Robots under its front edge (the ones it pushes against).
    neighbours:
        Robots placed before it whose bodies touch it (for the pair: the partner).
    partner:
        The other G_1 robot, for the pair; ``None`` for a docking robot.
    approach_um:
        Length of the straight final approach behind the slot that must be free (um).
    """

    robot: str
    index: int
    pose: Pose
    role: Literal["pair", "dock"]
    length_um: float
    width_um: float
    orbit_radius_um: float
    contact: tuple[tuple[float, float], tuple[float, float]]
    supports: tuple[str, ...]
    neighbours: tuple[str, ...]
    partner: str | None
    approach_um: float

    @property
    def label(self) -> str:
        """``D3 (robot 'A')``: how messages name this robot."""
        return _label(self.index, self.robot)

    @property
    def heading(self) -> np.ndarray:
        """Unit heading vector ``(sin theta, cos theta)``."""
        return np.array([math.sin(self.pose.theta), math.cos(self.pose.theta)])

    @property
    def corners(self) -> np.ndarray:
        """Body corners ``(4, 2)``: front-left, front-right, rear-right, rear-left."""
        return body_corners(self.pose.as_array(), self.length_um, self.width_um)[0]

    @property
    def front_edge(self) -> np.ndarray:
        """Front edge ``(2, 2)``: front-left then front-right corner."""
        return self.corners[:2]

    @property
    def front_midpoint(self) -> np.ndarray:
        """The docking point: midpoint of the front edge, ``p + (L/2) h``."""
        return np.array([self.pose.x, self.pose.y]) + 0.5 * self.length_um * self.heading

    @property
    def polygon(self) -> Polygon:
        """The body at the slot (shapely)."""
        return Polygon(self.corners)

    def corridor(self, approach_um: float | None = None) -> Polygon:
        """The straight lane swept by the body moving backwards from the slot by ``approach_um``.

        Includes the body at the slot itself. Defaults to :attr:`approach_um`.
        """
        a = self.approach_um if approach_um is None else float(approach_um)
        return _corridor(self.corners, self.heading, a)


@dataclass(frozen=True)
class Structure:
    """A target structure: slots in docking order, G_1 first.

    ``slots[0]`` is D_n, ``slots[1]`` is D_{n-1} (the G_1 pair), then D_{n-2}, ..., D_1. "The first k
    slots" (``k`` arguments below) is the structure as it stands before ``slots[k]`` docks.

    Build one with :func:`candidate_structures` / :func:`named_structure` (named shapes) or
    :func:`structure_from_goals` (explicit goals); both validate it.

    Attributes
    ----------
    slots:
        Slots in docking order.
    shape:
        The named shape, or ``"goals"`` for explicit per-robot goals.
    frame:
        The ``[structure] at`` pose of a named shape (the G_1 junction and the rotation), else ``None``.
    variant:
        A short description of the candidate (which robot sits where), for plans and pictures.
    """

    slots: tuple[Slot, ...]
    shape: str = "goals"
    frame: Pose | None = None
    variant: str = ""
    _sides: tuple[tuple[Side, ...], ...] = field(default=(), repr=False, compare=False)

    # -- identity and order ------------------------------------------------------------------------

    @property
    def n(self) -> int:
        return len(self.slots)

    @property
    def docking_order(self) -> tuple[str, ...]:
        """Robot names in docking order: D_n, D_{n-1}, D_{n-2}, ..., D_1."""
        return tuple(s.robot for s in self.slots)

    @property
    def order(self) -> tuple[str, ...]:
        """Robot names in voltage order D_1..D_n."""
        return tuple(reversed(self.docking_order))

    def slot(self, name: str) -> Slot:
        """The slot of the robot called ``name``."""
        return self.slots[self.step_of(name)]

    def d(self, i: int) -> Slot:
        """The slot of D_i (voltage index, 1-based)."""
        if not 1 <= i <= self.n:
            raise IndexError(f"D{i} does not exist in a structure of {self.n} robots")
        return self.slots[self.n - i]

    def step_of(self, name: str) -> int:
        """Position of ``name`` in docking order: the number of slots filled before it."""
        for k, s in enumerate(self.slots):
            if s.robot == name:
                return k
        raise KeyError(f"no robot {name!r} in this structure (robots: {', '.join(self.docking_order)})")

    def _k(self, k: int | None) -> int:
        if k is None:
            return self.n
        if not 0 <= k <= self.n:
            raise ValueError(f"k must be in 0..{self.n}, got {k}")
        return int(k)

    # -- goals ---------------------------------------------------------------------------------------

    def goal_poses(self, names: Sequence[str] | None = None) -> np.ndarray:
        """Goal poses ``(n, 3)`` ``[x_um, y_um, theta_rad]`` in the given name order (default D_1..D_n)."""
        names = self.order if names is None else tuple(names)
        rows = [self.slot(nm).pose for nm in names]
        return np.array(rows, dtype=np.float64).reshape(len(rows), 3)

    def goals(self) -> dict[str, Pose]:
        """Goal pose per robot name."""
        return {s.robot: s.pose for s in self.slots}

    # -- geometry ------------------------------------------------------------------------------------

    def body(self, name: str) -> Polygon:
        """Body polygon of ``name`` at its slot."""
        return self.slot(name).polygon

    def bodies(self, k: int | None = None) -> tuple[Polygon, ...]:
        """Body polygons of the first ``k`` slots (default all), in docking order."""
        return tuple(s.polygon for s in self.slots[: self._k(k)])

    def outline(self, k: int | None = None) -> BaseGeometry:
        """Union of the first ``k`` bodies (default all): the structure as one shapely geometry.

        Bodies that touch within tolerance are fused (no hairline slits), so this is the shape to draw
        and to treat as one obstacle.
        """
        polys = self.bodies(k)
        if not polys:
            return Polygon()
        eps = 0.5 * POS_TOL_UM
        grown = [p.buffer(eps, join_style="mitre") for p in polys]
        return shapely.union_all(grown, grid_size=_GRID_UM).buffer(-eps, join_style="mitre")

    def free_sides(self, k: int | None = None, *, min_length_um: float = 0.0) -> tuple[Side, ...]:
        """Free sides of the structure formed by the first ``k`` slots (default all).

        A free side is a maximal straight piece of outline not covered by another body: collinear edges
        of touching robots merge (the two long sides of G_1 form one side of length L_n + L_{n-1}).
        ``min_length_um`` keeps only sides at least that long (e.g. a docking robot's width).
        """
        k = self._k(k)
        if len(self._sides) == self.n + 1:
            sides = self._sides[k]
        else:  # built by hand rather than by this module's constructors
            slots = self.slots[:k]
            sides = _free_sides(np.array([s.corners for s in slots]).reshape(k, 4, 2), [s.robot for s in slots])
        if min_length_um > 0.0:
            sides = tuple(s for s in sides if s.length_um + 2.0 * POS_TOL_UM >= min_length_um)
        return sides

    def corridor(self, name: str, approach_um: float | None = None) -> Polygon:
        """Straight approach corridor of ``name``'s slot (its body swept back by ``approach_um``)."""
        return self.slot(name).corridor(approach_um)

    def docking_object(self, name: str) -> BaseGeometry:
        """O of seed App. 3.2: what ``name`` docks with.

        The partner's body for a G_1 robot, the structure built before it for a docking robot.
        """
        s = self.slot(name)
        if s.role == "pair":
            return self.body(s.partner)  # type: ignore[arg-type]
        return self.outline(self.step_of(name))

    def proximity_region(self, name: str, orbit_radius_um: float | None = None) -> BaseGeometry:
        """C_O of seed App. 3.2: the docking object expanded by ``2 r*``.

        From inside it the robot may not be able to avoid hitting O, so gross motion ends outside it.
        ``orbit_radius_um`` defaults to the slot robot's own r*.
        """
        r_star = self.slot(name).orbit_radius_um if orbit_radius_um is None else float(orbit_radius_um)
        return self.docking_object(name).buffer(2.0 * r_star)

    def moved(self, rotation_rad: float = 0.0, translation_um=(0.0, 0.0), about_um=(0.0, 0.0)) -> Structure:
        """The same structure after a rigid motion: rotate clockwise by ``rotation_rad`` about
        ``about_um`` (heading convention: theta grows clockwise), then translate. Re-validated."""
        poses = _rigid(self.goal_poses(self.docking_order), rotation_rad, translation_um, about_um)
        frame = None
        if self.frame is not None:
            frame = Pose(*_rigid(np.array([self.frame]), rotation_rad, translation_um, about_um)[0])
        return _assemble(
            [_Geom(s.robot, s.index, s.length_um, s.width_um, s.orbit_radius_um) for s in self.slots],
            poses,
            np.array([s.approach_um for s in self.slots]),
            shape=self.shape,
            frame=frame,
            variant=self.variant,
        )


# ----------------------------------------------------------------------------------------------------
# Internal geometry


@dataclass(frozen=True)
class _Geom:
    """What validation needs of a robot: name, voltage index, body size, orbit radius."""

    name: str
    index: int
    length_um: float
    width_um: float
    orbit_radius_um: float


def _label(index: int, name: str) -> str:
    return f"D{index}" if name == f"D{index}" else f"D{index} (robot {name!r})"


def _geoms(robots_in_voltage_order: Sequence[Robot]) -> list[_Geom]:
    """Per-robot geometry in *docking* order (D_n first), after basic checks of the robot list."""
    robots = list(robots_in_voltage_order)
    n = len(robots)
    if n < 2:
        raise PlanningError(f"a structure needs at least 2 robots (G_1 is a pair), got {n}")
    seen: set[str] = set()
    for r in robots:
        if r.name in seen:
            raise PlanningError(f"robot name {r.name!r} appears twice in the voltage order")
        seen.add(r.name)
    out = []
    for i in range(n, 0, -1):
        r = robots[i - 1]
        r_star = float(orbit_radii(r.length_um, r.width_um, r.turn_radius_um))
        out.append(_Geom(r.name, i, float(r.length_um), float(r.width_um), r_star))
    return out


def _corridor(corners: np.ndarray, heading: np.ndarray, approach_um: float) -> Polygon:
    back = approach_um * heading
    return Polygon([corners[0], corners[1], corners[2] - back, corners[3] - back])


def _rigid(poses: np.ndarray, rotation_rad: float, translation_um, about_um) -> np.ndarray:
    """Rotate poses clockwise by ``rotation_rad`` about ``about_um``, then translate (um, rad)."""
    c, s = math.cos(rotation_rad), math.sin(rotation_rad)
    # Clockwise rotation keeps h(theta + phi) = R h(theta) with R = [[c, s], [-s, c]].
    rot = np.array([[c, s], [-s, c]])
    about = np.asarray(about_um, dtype=np.float64)
    xy = (poses[:, :2] - about) @ rot.T + about + np.asarray(translation_um, dtype=np.float64)
    return np.column_stack([xy, wrap_angle(poses[:, 2] + rotation_rad)])


def _overlap_area(a: Polygon, b: Polygon) -> float:
    """Area (um^2) two polygons share, robust to edges they share exactly."""
    return float(shapely.intersection(a, b, grid_size=_GRID_UM).area)


def _shrunk(p: Polygon) -> Polygon:
    """Body shrunk by half the position tolerance: two shrunk bodies meet only if they really overlap."""
    return p.buffer(-0.5 * POS_TOL_UM, join_style="mitre")


def _uncovered_spans(lo: np.ndarray, hi: np.ndarray, length: float) -> list[tuple[float, float]]:
    """The stretches ``(u0, u1)`` (um along the edge) of an edge of ``length`` um that no other body covers,
    given each body's covered interval ``[lo, hi]``; the tolerance the grown cover took at a contact is put back."""
    covered = sorted((float(a), float(b)) for a, b in zip(lo, hi, strict=True) if b - a > 0.0)
    spans = []
    cur = 0.0
    for a, b in covered + [(length, length)]:
        if a > cur:
            u0 = cur if cur <= 0.0 else max(0.0, cur - POS_TOL_UM)
            u1 = a if a >= length else min(length, a + POS_TOL_UM)
            spans.append((u0, u1))
        cur = max(cur, b)
    return spans


class _EdgeCover(NamedTuple):
    """The edges of ``k`` rectangles and the stretch of each edge every other grown body covers.

    Edge ``e`` of body ``j`` runs from corner ``e`` to corner ``e + 1`` (clockwise, front-left first);
    along it, body ``i`` grown by :data:`POS_TOL_UM` covers ``[lo[j, e, i], hi[j, e, i]]`` (um from the
    edge's start; empty when ``lo >= hi``, and always empty for ``i == j``).
    """

    starts: np.ndarray  # (k, 4, 2) um: first corner of each edge
    tangents: np.ndarray  # (k, 4, 2): unit direction of each edge
    lengths: np.ndarray  # (k, 4) um
    lo: np.ndarray  # (k, 4, k) um
    hi: np.ndarray  # (k, 4, k) um


def _edge_cover(corners: np.ndarray) -> _EdgeCover:
    """Clip every edge of the rectangles ``corners`` ``(k, 4, 2)`` (um) against every grown body.

    A grown body is a rectangle, so the covered stretch of an edge is an exact interval: the
    intersection of the edge's line with two slabs (one per body axis), vectorised over all edges and
    bodies. Growing by the tolerance makes touching count as covering.
    """
    k = corners.shape[0]
    starts = corners
    d = np.roll(corners, -1, axis=1) - corners
    lens = np.hypot(d[..., 0], d[..., 1])  # (k, 4)
    t = d / lens[..., None]
    centre = corners.mean(axis=1)  # (k, 2)
    ax_l = corners[:, 0] - corners[:, 3]  # rear-left -> front-left: along the heading, length L
    ax_w = corners[:, 1] - corners[:, 0]  # front-left -> front-right: across, length W
    half = np.stack([np.hypot(*ax_l.T), np.hypot(*ax_w.T)], axis=1) * 0.5 + POS_TOL_UM  # (k, 2)
    axes = np.stack([ax_l, ax_w], axis=1) / (2.0 * (half - POS_TOL_UM))[..., None]  # (k, 2, 2) unit

    # Edge (j, e) point a + u t lies in grown body i iff |(a - c_i).axis + u t.axis| <= half for both axes.
    rel = starts[:, :, None, :] - centre[None, None, :, :]  # (k, 4, k, 2)
    alpha = np.einsum("jeid,iad->jeia", rel, axes)  # (k, 4, k, 2)
    beta = np.einsum("jed,iad->jeia", t, axes)
    H = half[None, None, :, :]
    with np.errstate(divide="ignore", invalid="ignore"):
        u_a = (-H - alpha) / beta
        u_b = (H - alpha) / beta
    flat = np.abs(beta) < 1e-12
    inside_flat = np.abs(alpha) <= H
    lo = np.where(flat, np.where(inside_flat, -np.inf, np.inf), np.minimum(u_a, u_b)).max(axis=-1)
    hi = np.where(flat, np.where(inside_flat, np.inf, -np.inf), np.maximum(u_a, u_b)).min(axis=-1)
    lo = np.maximum(lo, 0.0)
    hi = np.minimum(hi, lens[..., None])
    idx = np.arange(k)
    lo[idx, :, idx] = np.inf  # a body does not cover itself
    return _EdgeCover(starts, t, lens, lo, hi)


class _Piece(NamedTuple):
    """An uncovered stretch of one body edge, on the line ``normal . p = offset_um``, from ``u0_um`` to
    ``u1_um`` along ``t = (n_y, -n_x)`` measured from the origin (um)."""

    normal: np.ndarray  # outward unit normal
    offset_um: float
    u0_um: float
    u1_um: float
    robot: int
    edge: int


def _free_pieces(cover: _EdgeCover) -> list[_Piece]:
    """Every stretch of every edge that no other body covers and that is longer than twice the
    tolerance (shorter ones are rounding at a contact, not room to dock on)."""
    k = cover.lengths.shape[0]
    pieces: list[_Piece] = []
    for j in range(k):
        for e in range(4):
            spans = _uncovered_spans(cover.lo[j, e], cover.hi[j, e], float(cover.lengths[j, e]))
            tt = cover.tangents[j, e]
            nrm = np.array([-tt[1], tt[0]])  # corners run clockwise: outside is on the left
            a_t = float(np.dot(cover.starts[j, e], tt))
            off = float(np.dot(nrm, cover.starts[j, e]))
            for u0, u1 in spans:
                if u1 - u0 > 2.0 * POS_TOL_UM:
                    pieces.append(_Piece(nrm, off, a_t + u0, a_t + u1, j, e))
    return pieces


def _collinear_groups(pieces: Sequence[_Piece]) -> list[list[int]]:
    """Indices of ``pieces`` grouped by line: one outward normal (within twice :data:`ANG_TOL_RAD`) and
    one offset (within :data:`POS_TOL_UM`) as the group's first piece, in order of first appearance."""
    cos_tol = math.cos(2.0 * ANG_TOL_RAD)
    groups: list[list[int]] = []
    for piece, (nrm, off, *_rest) in enumerate(pieces):
        for grp in groups:
            n0, off0 = pieces[grp[0]].normal, pieces[grp[0]].offset_um
            if float(np.dot(nrm, n0)) >= cos_tol and abs(off - off0) <= POS_TOL_UM:
                grp.append(piece)
                break
        else:
            groups.append([piece])
    return groups


def _group_sides(pieces: Sequence[_Piece], grp: Sequence[int], names: Sequence[str]) -> list[tuple[tuple[int, int, float], Side]]:
    """The sides of one line: its touching pieces (gaps up to :data:`POS_TOL_UM`) merged into runs.

    The line is the first piece's normal at the length-weighted mean offset (um). Each side comes with
    its sort key, the smallest ``(robot, edge, u0)`` of its pieces, so sides keep the order of the
    bodies' edges.
    """
    n0 = pieces[grp[0]].normal
    t0 = np.array([n0[1], -n0[0]])
    wts = np.array([pieces[i].u1_um - pieces[i].u0_um for i in grp])
    off = float(np.average([pieces[i].offset_um for i in grp], weights=wts))
    # Coordinates along the group's own tangent (pieces' t are within tolerance of t0).
    along: list[tuple[float, float, int, int]] = []
    for i in grp:
        nrm, _, u0, u1, j, e = pieces[i]
        t = np.array([nrm[1], -nrm[0]])
        p0 = u0 * t + pieces[i].offset_um * nrm
        p1 = u1 * t + pieces[i].offset_um * nrm
        along.append((float(np.dot(p0, t0)), float(np.dot(p1, t0)), j, e))
    along.sort()
    runs: list[list] = []
    for u0, u1, j, e in along:
        if runs and u0 <= runs[-1][1] + POS_TOL_UM:
            runs[-1][1] = max(runs[-1][1], u1)
            runs[-1][2].append((j, e, u0, u1))
        else:
            runs.append([u0, u1, [(j, e, u0, u1)]])
    sides: list[tuple[tuple[int, int, float], Side]] = []
    for u0, u1, members in runs:
        start = u0 * t0 + off * n0
        end = u1 * t0 + off * n0
        order = sorted({j for j, *_ in members})
        side = Side(
            start=(float(start[0]), float(start[1])),
            end=(float(end[0]), float(end[1])),
            normal=(float(n0[0]), float(n0[1])),
            robots=tuple(names[j] for j in order),
            pieces=tuple((names[j], a - u0, b - u0) for j, _, a, b in members),
        )
        key = min((j, e, a) for j, e, a, _ in members)
        sides.append((key, side))
    return sides


def _free_sides(corners: np.ndarray, names: Sequence[str]) -> tuple[Side, ...]:
    """Free sides of the union of rectangles ``corners`` ``(k, 4, 2)`` (clockwise, front-left first).

    Every body edge minus what the other bodies cover (grown by the tolerance, so touching counts as
    covering), cut ends put back where the contact really is, then collinear adjacent pieces of
    different robots merged into one side. Each grown body is a rectangle, so the covered stretch of an
    edge is an exact interval (clipping against two slabs), vectorised over all edges and bodies.
    """
    if len(names) == 0:
        return ()
    pieces = _free_pieces(_edge_cover(np.asarray(corners, dtype=np.float64)))
    sides = [ks for grp in _collinear_groups(pieces) for ks in _group_sides(pieces, grp, names)]
    sides.sort(key=lambda ks: ks[0])
    return tuple(s for _, s in sides)


def _edge_on_side(side: Side, p0: np.ndarray, p1: np.ndarray, h: np.ndarray):
    """How a front edge ``p0 p1`` of a robot heading ``h`` sits on ``side``.

    Returns ``(angle_rad, offset_um, overhang_um, u0, u1)``: angle between h and the inward normal,
    largest perpendicular distance of the edge's ends from the side's line, how far the edge sticks out
    beyond the side's ends, and the edge's extent along the side (um from ``start``).
    """
    nrm = np.asarray(side.normal)
    start = np.asarray(side.start)
    t = side.direction
    angle = math.acos(max(-1.0, min(1.0, -float(np.dot(h, nrm)))))
    d = [float(np.dot(p - start, nrm)) for p in (p0, p1)]
    u = sorted(float(np.dot(p - start, t)) for p in (p0, p1))
    overhang = max(0.0, -u[0], u[1] - side.length_um)
    return angle, max(abs(d[0]), abs(d[1])), overhang, u[0], u[1]


def _flush_side(sides: Sequence[Side], corners: np.ndarray, h: np.ndarray):
    """The free side the front edge is flush with, or ``(None, reason)``."""
    fl, fr, rr, rl = corners
    best = None
    for side in sides:
        angle, off, over, u0, u1 = _edge_on_side(side, fl, fr, h)
        if angle <= ANG_TOL_RAD + 1e-12 and off <= POS_TOL_UM and over <= POS_TOL_UM:
            err = off + over + angle
            if best is None or err < best[0]:
                best = (err, side, u0, u1)
    if best is not None:
        return best[1], best[2], best[3]

    if not sides:
        return None, "there is no free side to dock on"
    # Diagnose against the nearest side, preferring sides the robot roughly faces.
    front = LineString([fl, fr])
    for side in sides:  # backwards: the rear edge is flush instead
        angle, off, over, *_ = _edge_on_side(side, rr, rl, -h)
        if angle <= ANG_TOL_RAD + 1e-12 and off <= POS_TOL_UM and over <= POS_TOL_UM:
            return None, "its rear edge, not its front edge, is on a free side (heading reversed? docking is front-first)"

    def score(side: Side) -> float:
        angle = _edge_on_side(side, fl, fr, h)[0]
        return front.distance(LineString(side.segment)) + (0.0 if angle < math.radians(45.0) else 1e9)

    side = min(sides, key=score)
    angle, off, over, *_ = _edge_on_side(side, fl, fr, h)
    dist = front.distance(LineString(side.segment))
    tilted = angle > ANG_TOL_RAD + 1e-12
    deg = math.degrees(angle)
    if angle > _HALF_PI:
        return None, f"front edge faces away from the nearest free side (heading {deg:.1f} deg off its inward normal)"
    if dist > POS_TOL_UM:
        also = f" and at {deg:.1f} deg to it" if tilted else ""
        return None, f"goal is not flush with the structure: front edge {dist:.1f} um from the nearest free side{also}"
    if tilted:
        return None, (
            f"front edge is at {deg:.1f} deg to the free side it touches "
            f"(must be parallel to it within {math.degrees(ANG_TOL_RAD):.1f} deg)"
        )
    if off > POS_TOL_UM:  # pragma: no cover - parallel and touching implies on the line
        return None, f"goal is not flush with the structure: front edge {off:.1f} um from the nearest free side"
    return None, (
        f"front edge overhangs the end of the free side it rests on by {over:.1f} um "
        f"(side {side.length_um:.1f} um long, front edge within it required)"
    )


def _check_pair(gn: _Geom, gm: _Geom, pn: np.ndarray, pm: np.ndarray) -> None:
    """D_n (``gn`` at ``pn``) and D_{n-1} (``gm`` at ``pm``) must form G_1."""
    who = f"{_label(gm.index, gm.name).split(' ')[0]}/{_label(gn.index, gn.name).split(' ')[0]}"
    if gm.name != f"D{gm.index}" or gn.name != f"D{gn.index}":
        who += f" (robots {gm.name!r}/{gn.name!r})"
    head = f"{who} do not form G_1"
    turn = abs(float(angle_difference(pm[2], pn[2] + math.pi)))
    if turn > ANG_TOL_RAD + 1e-12:
        apart = math.degrees(abs(float(angle_difference(pm[2], pn[2]))))
        raise PlanningError(f"{head}: headings {apart:.1f} deg apart, must be opposite (180 deg, head-on)")
    hn = np.array([math.sin(pn[2]), math.cos(pn[2])])
    rn = np.array([hn[1], -hn[0]])
    mn = pn[:2] + 0.5 * gn.length_um * hn
    hm = np.array([math.sin(pm[2]), math.cos(pm[2])])
    mm = pm[:2] + 0.5 * gm.length_um * hm
    d = mm - mn
    gap = float(np.dot(d, hn))
    side = float(np.dot(d, rn))
    if abs(side) > POS_TOL_UM:
        raise PlanningError(
            f"{head}: front edges offset by {abs(side):.1f} um sideways (long axes must be on one line)"
        )
    if gap > POS_TOL_UM:
        raise PlanningError(f"{head}: front edges {gap:.1f} um apart")
    if gap < -POS_TOL_UM:
        raise PlanningError(f"{head}: bodies overlap by {-gap:.1f} um along their axis")


class _Bodies(NamedTuple):
    """The bodies of a structure's slots in docking order, in the forms the docking rules test."""

    names: list[str]
    poses: np.ndarray  # (n, 3) um, rad (headings wrapped)
    corners: np.ndarray  # (n, 4, 2) um, clockwise from front-left
    heads: np.ndarray  # (n, 2) unit heading vectors
    polys: list[Polygon]
    shrunk: list[Polygon]  # shrunk by half the tolerance: they meet only where bodies really overlap


def _bodies(geoms: Sequence[_Geom], poses: np.ndarray) -> _Bodies:
    """The bodies at ``poses`` (docking order, um, rad); a non-finite pose is rejected naming its robot."""
    n = len(geoms)
    poses = np.asarray(poses, dtype=np.float64).reshape(n, 3)
    if not np.all(np.isfinite(poses)):
        bad = int(np.flatnonzero(~np.all(np.isfinite(poses), axis=1))[0])
        raise PlanningError(f"{_label(geoms[bad].index, geoms[bad].name)}: goal pose is not finite: {poses[bad].tolist()}")
    poses = poses.copy()
    poses[:, 2] = wrap_angle(poses[:, 2])
    lengths = np.array([g.length_um for g in geoms])
    widths = np.array([g.width_um for g in geoms])
    corners = body_corners(poses, lengths, widths)
    heads = np.stack([np.sin(poses[:, 2]), np.cos(poses[:, 2])], axis=1)
    polys = [Polygon(c) for c in corners]
    return _Bodies([g.name for g in geoms], poses, corners, heads, polys, [_shrunk(p) for p in polys])


def _slot(g: _Geom, b: _Bodies, k: int, **roles) -> Slot:
    """The slot of body ``k`` of ``b``: robot ``g``'s name, index and geometry, its pose, and the role fields
    (``role``, ``contact``, ``supports``, ``neighbours``, ``partner``, ``approach_um``) given."""
    return Slot(robot=g.name, index=g.index, pose=Pose(*map(float, b.poses[k])), length_um=g.length_um, width_um=g.width_um,
                orbit_radius_um=g.orbit_radius_um, **roles)


def _pair_slots(geoms: Sequence[_Geom], b: _Bodies, approach: np.ndarray) -> list[Slot]:
    """The slots of G_1 (D_n, D_{n-1}), once checked head-on: each one's contact is its partner's front edge."""
    _check_pair(geoms[0], geoms[1], b.poses[0], b.poses[1])
    slots: list[Slot] = []
    for k, partner in ((0, 1), (1, 0)):
        g = geoms[k]
        slots.append(
            _slot(g, b, k, role="pair", contact=tuple(map(tuple, b.corners[partner, :2].tolist())),
                  supports=(b.names[partner],), neighbours=(b.names[partner],), partner=b.names[partner],
                  approach_um=float(approach[k]))
        )
    return slots


def _check_outside(geoms: Sequence[_Geom], b: _Bodies, k: int) -> None:
    """Docking rule 1 for slot ``k``: its body lies outside the structure built so far (touching allowed)."""
    for j in range(k):
        if b.shrunk[k].intersects(b.shrunk[j]):
            area = _overlap_area(b.polys[k], b.polys[j])
            raise PlanningError(
                f"{_label(geoms[k].index, geoms[k].name)}: body overlaps {_label(geoms[j].index, geoms[j].name)} by {area:.0f} um^2"
            )


def _check_corridor(geoms: Sequence[_Geom], b: _Bodies, k: int, approach_um: float) -> None:
    """Docking rule 3 for slot ``k``: the straight corridor ``approach_um`` (um) back along its heading,
    the way the robot drives in, crosses no body docked before it."""
    lane = _shrunk(_corridor(b.corners[k], b.heads[k], approach_um))
    for j in range(k):
        if lane.intersects(b.shrunk[j]):
            area = _overlap_area(_corridor(b.corners[k], b.heads[k], approach_um), b.polys[j])
            raise PlanningError(
                f"{_label(geoms[k].index, geoms[k].name)}: approach corridor ({approach_um:.0f} um straight back along "
                f"its heading) crosses {_label(geoms[j].index, geoms[j].name)}'s body ({area:.0f} um^2)"
            )


def _dock_slot(geoms: Sequence[_Geom], b: _Bodies, k: int, sides: Sequence[Side], approach_um: float) -> Slot:
    """The slot of the ``k``-th robot to dock (k >= 2) on the structure of the first ``k`` slots, whose free
    sides are ``sides``, once it meets the docking rules: body outside the structure, front edge flush with
    a free side (its contact), approach corridor clear. Its neighbours are the bodies it touches."""
    _check_outside(geoms, b, k)
    found = _flush_side(sides, b.corners[k], b.heads[k])
    if found[0] is None:
        raise PlanningError(f"{_label(geoms[k].index, geoms[k].name)}: {found[1]}")
    side, u0, u1 = found
    _check_corridor(geoms, b, k, approach_um)
    g = geoms[k]
    return _slot(g, b, k, role="dock", contact=side.segment, supports=side.supports(u0, u1),
                 neighbours=tuple(b.names[j] for j in range(k) if b.polys[k].distance(b.polys[j]) <= POS_TOL_UM),
                 partner=None, approach_um=approach_um)


def _assemble(
    geoms: Sequence[_Geom],
    poses: np.ndarray,
    approach: np.ndarray,
    *,
    shape: str,
    frame: Pose | None,
    variant: str,
) -> Structure:
    """Validate poses (docking order) against the docking rules and build the :class:`Structure`.

    ``approach`` holds each slot's straight approach (um). The free sides of every partial structure
    (the first k slots, k = 0..n) are kept in the structure for the planner and the controller.
    """
    b = _bodies(geoms, poses)
    slots = _pair_slots(geoms, b, approach)
    sides_by_k: list[tuple[Side, ...]] = [(), _free_sides(b.corners[:1], b.names[:1]), _free_sides(b.corners[:2], b.names[:2])]
    for k in range(2, len(geoms)):
        slots.append(_dock_slot(geoms, b, k, sides_by_k[k], float(approach[k])))
        sides_by_k.append(_free_sides(b.corners[: k + 1], b.names[: k + 1]))
    return Structure(slots=tuple(slots), shape=shape, frame=frame, variant=variant, _sides=tuple(sides_by_k))


# ----------------------------------------------------------------------------------------------------
# Explicit goals


def structure_from_goals(
    robots_in_voltage_order: Sequence[Robot],
    goals: Mapping[str, Pose | Sequence[float]] | np.ndarray | Sequence | None = None,
    *,
    approach_margin_um: float = APPROACH_MARGIN_UM,
) -> Structure:
    """Validate explicit per-robot goals against the docking order and build the structure.

    Parameters
    ----------
    robots_in_voltage_order:
        Robots D_1..D_n (D_1: lowest snap-down voltage).
    goals:
        Goal poses ``(x_um, y_um, theta_rad)``: a mapping name -> pose, or an ``(n, 3)`` array / sequence
        aligned with ``robots_in_voltage_order``. ``None`` uses each robot's ``goal``.
    approach_margin_um:
        Each slot's straight approach is its robot's length plus this margin (um).

    Returns
    -------
    Structure
        Slots in docking order, G_1 (D_n, D_{n-1}) first.

    Raises
    ------
    PlanningError
        One line naming the robot and what is wrong, with numbers: D_n/D_{n-1} not head-on with
        coincident front-edge midpoints; a body overlapping an earlier one; a front edge not flush with
        (on the line of, parallel to, and within) a free side of the structure built so far; an approach
        corridor crossing an earlier robot.
    """
    geoms = _geoms(robots_in_voltage_order)  # docking order
    robots = list(robots_in_voltage_order)
    n = len(robots)
    rows: list[Sequence[float]] = []
    if goals is None:
        for g in geoms:
            p = robots[g.index - 1].goal
            if p is None:
                raise PlanningError(f"{_label(g.index, g.name)}: no goal pose (give per-robot goals or a [structure])")
            rows.append(p)
    elif isinstance(goals, Mapping):
        for g in geoms:
            if g.name not in goals:
                raise PlanningError(f"{_label(g.index, g.name)}: no goal pose given")
            rows.append(goals[g.name])
        extra = sorted(set(goals) - {g.name for g in geoms})
        if extra:
            raise PlanningError(f"goal given for unknown robot {extra[0]!r}")
    else:
        arr = np.asarray(goals, dtype=np.float64)
        if arr.shape != (n, 3):
            raise PlanningError(f"goals must be an ({n}, 3) array in voltage order, got shape {arr.shape}")
        rows = [arr[g.index - 1] for g in geoms]
    poses = np.array([[float(v) for v in r] for r in rows], dtype=np.float64).reshape(n, 3)
    approach = np.array([g.length_um + approach_margin_um for g in geoms])
    return _assemble(geoms, poses, approach, shape="goals", frame=None, variant="explicit goals")


# ----------------------------------------------------------------------------------------------------
# Named shapes


class _Local:
    """A structure frame: origin at the G_1 junction, bar along ``a`` (the frame's right vector),
    ``b`` = the frame's heading. Local point ``(s, t)`` is ``origin + s a + t b``."""

    def __init__(self, at: Pose):
        self.at = at
        self.o = np.array([at.x, at.y], dtype=np.float64)
        self.a = np.array([math.cos(at.theta), -math.sin(at.theta)])
        self.b = np.array([math.sin(at.theta), math.cos(at.theta)])

    def pose(self, s: float, t: float, direction: str) -> list[float]:
        """World pose of a body centred at local ``(s, t)`` heading along ``+a``, ``-a``, ``+b`` or ``-b``."""
        xy = self.o + s * self.a + t * self.b
        off = {"+a": _HALF_PI, "-a": -_HALF_PI, "+b": 0.0, "-b": math.pi}[direction]
        return [float(xy[0]), float(xy[1]), wrap_angle(self.at.theta + off)]


def _stem_start(shape: str, P: _Geom, Q: _Geom, sigma: int, w: float, who: str) -> tuple[float, float]:
    """Where the first stem robot's front-edge midpoint goes on the bar face ``sigma`` (local s, t).

    The bar middle, moved the least so the front edge lies on one flat stretch of that face (when the
    two G_1 robots differ in width the face has a step at the junction).
    """
    s_mid = 0.5 * (Q.length_um - P.length_um)  # bar spans [-L_P, L_Q]
    if abs(P.width_um - Q.width_um) <= 1e-9 * max(P.width_um, Q.width_um):  # named shapes are exact
        segs = [(-P.length_um, Q.length_um, 0.5 * max(P.width_um, Q.width_um))]
    else:
        segs = [(-P.length_um, 0.0, 0.5 * P.width_um), (0.0, Q.length_um, 0.5 * Q.width_um)]
        # The stretch containing the middle; at the junction itself, the wider robot's.
        if s_mid == 0.0:
            segs.sort(key=lambda sg: -sg[2])
        else:
            segs.sort(key=lambda sg: 0 if sg[0] <= s_mid <= sg[1] else 1)
    lo, hi, half_w = segs[0]
    if hi - lo < w * (1.0 - 1e-12):
        raise PlanningError(
            f"{shape}: {who} ({w:.1f} um wide) does not fit on the G_1 bar's face ({hi - lo:.1f} um long)"
        )
    s = min(max(s_mid, lo + 0.5 * w), hi - 0.5 * w)
    return s, sigma * half_w


@dataclass
class _Tooth:
    """A column of robots growing straight out of one bar face (a stem or a comb tooth)."""

    s: float  # local position along the bar (um)
    sigma: int  # face: +1 = +b side, -1 = -b side
    face_t: float  # local t of the face the first robot docks on
    end_t: float | None = None  # local t of the free rear edge of the last robot
    end_w: float | None = None  # width of that rear edge (um)
    end_name: str = ""


def _dock_on_tooth(frame: _Local, tooth: _Tooth, g: _Geom, shape: str) -> list[float]:
    """Pose of ``g`` docking onto ``tooth``: on the bar face, or on the rear edge of its last robot."""
    if tooth.end_t is None:
        face = tooth.face_t
    else:
        if g.width_um > tooth.end_w * (1.0 + 1e-9):  # type: ignore[operator]  # named shapes are exact
            raise PlanningError(
                f"{shape}: {_label(g.index, g.name)} ({g.width_um:.1f} um wide) is wider than the rear edge "
                f"of {tooth.end_name} ({tooth.end_w:.1f} um) it must dock on; a front edge must lie within "
                f"the side it rests on"
            )
        face = tooth.end_t
    centre_t = face + tooth.sigma * 0.5 * g.length_um
    tooth.end_t = face + tooth.sigma * g.length_um
    tooth.end_w = g.width_um
    tooth.end_name = _label(g.index, g.name)
    return frame.pose(tooth.s, centre_t, "-b" if tooth.sigma > 0 else "+b")


def _tooth_positions(P: _Geom, Q: _Geom, pitch: float, w_max: float, start: str) -> list[tuple[float, float]]:
    """Comb/ladder tooth positions ``(s, face half-width)``, centre-out, alternating sides of the junction.

    Teeth sit at ``s = +-(j - 1/2) pitch`` (j = 1, 2, ...) so each lies on one G_1 robot, never across
    the junction, and the widest docker's front edge fits on that robot.
    """

    def one_side(g: _Geom, sign: float) -> list[tuple[float, float]]:
        out = []
        j = 1
        while (j - 0.5) * pitch + 0.5 * w_max <= g.length_um * (1.0 + 1e-12):
            out.append((sign * (j - 0.5) * pitch, 0.5 * g.width_um))
            j += 1
        return out

    right, left = one_side(Q, 1.0), one_side(P, -1.0)
    first, second = (right, left) if start == "right" else (left, right)
    out = []
    for j in range(max(len(first), len(second))):
        out += first[j : j + 1] + second[j : j + 1]
    return out


def _shape_poses(shape: str, geoms: Sequence[_Geom], at: Pose, flip: bool, sigma: int, start: str) -> np.ndarray:
    """Goal poses (docking order) of a named shape in the frame ``at``; see :data:`SHAPES`."""
    n = len(geoms)
    frame = _Local(at)
    gn, gm = geoms[0], geoms[1]
    P, Q = (gm, gn) if flip else (gn, gm)  # P on the -a end heading +a, Q on the +a end heading -a
    poses: dict[str, list[float]] = {
        P.name: frame.pose(-0.5 * P.length_um, 0.0, "+a"),
        Q.name: frame.pose(0.5 * Q.length_um, 0.0, "-a"),
    }
    dockers = list(geoms[2:])
    if shape == "pair":
        if n != 2:
            raise PlanningError(f"shape 'pair' holds exactly 2 robots (G_1), got {n}")
    elif shape in ("tee", "cross") and dockers:
        faces = [sigma] if shape == "tee" else [sigma, -sigma]
        teeth: dict[int, _Tooth] = {}
        for m, g in enumerate(dockers):
            f = faces[m % len(faces)]
            if f not in teeth:
                s, t = _stem_start(shape, P, Q, f, g.width_um, _label(g.index, g.name))
                teeth[f] = _Tooth(s=s, sigma=f, face_t=t)
            poses[g.name] = _dock_on_tooth(frame, teeth[f], g, shape)
    elif shape in ("comb", "ladder") and dockers:
        w_max = max(g.width_um for g in dockers)
        positions = _tooth_positions(P, Q, 2.0 * w_max, w_max, start)
        if not positions:
            raise PlanningError(
                f"{shape}: no room for a tooth on the G_1 bar (robots {P.length_um:.0f} and "
                f"{Q.length_um:.0f} um long, teeth {w_max:.0f} um wide)"
            )
        faces = [sigma] if shape == "comb" else [sigma, -sigma]
        sites = [(s, hw, f) for s, hw in positions for f in faces]
        teeth_by_site: dict[int, _Tooth] = {}
        for m, g in enumerate(dockers):
            site = m % len(sites)  # level by level: all teeth get their first robot, then the second ...
            if site not in teeth_by_site:
                s, hw, f = sites[site]
                teeth_by_site[site] = _Tooth(s=s, sigma=f, face_t=f * hw)
            poses[g.name] = _dock_on_tooth(frame, teeth_by_site[site], g, shape)
    elif shape not in SHAPES:
        raise ScenarioError(f"unknown shape {shape!r}; known shapes: {', '.join(SHAPES)}", field="structure.shape")
    return np.array([poses[g.name] for g in geoms], dtype=np.float64)


SHAPES: dict[str, str] = {
    "pair": (
        "G_1 alone (n = 2): D_n and D_{n-1} head-on along the frame's right vector a, front edges flush "
        "and centred on each other at the frame origin."
    ),
    "tee": (
        "G_1 bar plus one stem: D_{n-2} docks perpendicular on one long face of the bar at the bar's "
        "middle (shifted the least needed to lie on one flat stretch when the G_1 widths differ); each "
        "later robot docks front-first on the rear edge of the previous stem robot. Canonically the "
        "stem hangs on the -b side, so with the frame heading up it reads as the letter T."
    ),
    "cross": (
        "G_1 bar plus two stems at the bar's middle, one on each long face, grown alternately: D_{n-2} "
        "on the first face (canonically -b), D_{n-3} on the other, D_{n-4} on the rear of D_{n-2}, ..."
    ),
    "comb": (
        "G_1 bar plus teeth on one long face (canonically -b): tooth sites at s = +-(j - 1/2) p, "
        "j = 1, 2, ..., p = 2 W_max (W_max the widest docking robot), so neighbouring teeth leave a gap "
        "of at least one robot width and no tooth straddles the G_1 junction; as many sites as fit "
        "on each G_1 robot. Sites fill centre-out, alternating sides of the junction (canonically +a "
        "first). With more robots than sites the teeth grow level by level: the next robot docks on the "
        "rear edge of the tooth's last robot."
    ),
    "ladder": (
        "A double-sided comb: the G_1 bar is the rail, rungs (teeth) stand on both long faces at the "
        "comb's sites; robots fill site by site, first face then the other (canonically -b then +b), "
        "centre-out, then level by level like the comb."
    ),
}
"""Named shapes and their exact definitions.

Frame (``[structure] at = [x, y, heading]``): the origin is the G_1 junction (the common front-edge
midpoint of D_n and D_{n-1}); ``b = h(heading)`` and ``a = (cos heading, -sin heading)`` (the frame's
right). Local coordinates ``(s, t)`` mean ``origin + s a + t b``. The G_1 bar lies along ``a``: the robot
on the -a end (canonically D_n) spans ``s in [-L, 0]``. Robots dock in the order D_{n-2}, ..., D_1. For
n = 2 every shape is the pair.
"""

_SIDE_WORD = {1: "+b", -1: "-b"}


def named_structure(
    shape: str,
    robots_in_voltage_order: Sequence[Robot],
    at: Pose,
    *,
    flip: bool = False,
    side: int = -1,
    start: Literal["right", "left"] = "right",
    approach_margin_um: float = APPROACH_MARGIN_UM,
) -> Structure:
    """One variant of a named shape (see :data:`SHAPES`), validated.

    Parameters
    ----------
    shape:
        ``pair``, ``tee``, ``cross``, ``comb`` or ``ladder``.
    robots_in_voltage_order:
        Robots D_1..D_n.
    at:
        The structure frame (um, rad): origin = G_1 junction, heading = the frame's b axis.
    flip:
        ``False``: D_n on the -a end of the bar; ``True``: D_n on the +a end.
    side:
        Face the first stem/tooth grows on: -1 = -b (canonical), +1 = +b.
    start:
        Comb/ladder: which end of the bar (from the junction) gets the first tooth: ``right`` = +a.
    approach_margin_um:
        Each slot's straight approach is its robot's length plus this margin (um).

    Raises
    ------
    PlanningError
        When the shape cannot hold these robots (with the reason).
    ScenarioError
        For an unknown shape name.
    """
    if shape not in SHAPES:
        raise ScenarioError(f"unknown shape {shape!r}; known shapes: {', '.join(SHAPES)}", field="structure.shape")
    if side not in (1, -1):
        raise ValueError(f"side must be +1 or -1, got {side!r}")
    geoms = _geoms(robots_in_voltage_order)
    at = Pose(float(at[0]), float(at[1]), float(at[2]))
    poses = _shape_poses(shape, geoms, at, flip, side, start)
    approach = np.array([g.length_um + approach_margin_um for g in geoms])
    ends = (geoms[1].name, geoms[0].name) if flip else (geoms[0].name, geoms[1].name)
    words = [f"{ends[0]!r} on -a, {ends[1]!r} on +a"]
    if len(geoms) > 2 and shape != "pair":
        words.append(f"first {'stem' if shape in ('tee', 'cross') else 'tooth'} on {_SIDE_WORD[side]}")
        if shape in ("comb", "ladder"):
            words.append(f"teeth from {'+a' if start == 'right' else '-a'} first")
    return _assemble(geoms, poses, approach, shape=shape, frame=at, variant=f"{shape}: " + ", ".join(words))


def candidate_structures(
    robots_in_voltage_order: Sequence[Robot],
    spec: StructureSpec,
    *,
    approach_margin_um: float = APPROACH_MARGIN_UM,
) -> list[Structure]:
    """Every variant of the named shape ``spec.shape`` placed at ``spec.at``, canonical first.

    Variants: which G_1 robot takes which end of the bar, which face the (first) stem or tooth grows on
    (mirror images), and for comb/ladder which end of the bar fills first. All are congruent to the
    canonical shape up to mirroring; the planner picks the one with the shortest paths.

    Raises
    ------
    PlanningError
        When no variant can hold these robots; the message is the canonical variant's reason.
    ScenarioError
        For an unknown shape name (field ``structure.shape``).
    """
    shape, at = spec.shape, spec.at
    if shape not in SHAPES:
        raise ScenarioError(f"unknown shape {shape!r}; known shapes: {', '.join(SHAPES)}", field="structure.shape")
    n = len(robots_in_voltage_order)
    sides = (-1, 1) if n > 2 and shape != "pair" else (-1,)
    starts = ("right", "left") if n > 2 and shape in ("comb", "ladder") else ("right",)
    out: list[Structure] = []
    seen: set[tuple] = set()
    first_error: PlanningError | None = None
    for side in sides:
        for flip in (False, True):
            for start in starts:
                try:
                    st = named_structure(
                        shape,
                        robots_in_voltage_order,
                        at,
                        flip=flip,
                        side=side,
                        start=start,  # type: ignore[arg-type]
                        approach_margin_um=approach_margin_um,
                    )
                except PlanningError as exc:
                    first_error = first_error or exc
                    continue
                key = tuple(np.round(st.goal_poses(st.docking_order), 6).ravel())
                if key not in seen:
                    seen.add(key)
                    out.append(st)
    if not out:
        assert first_error is not None
        raise first_error
    return out


def target_structures(
    robots_in_voltage_order: Sequence[Robot],
    spec: StructureSpec | None = None,
    *,
    approach_margin_um: float = APPROACH_MARGIN_UM,
) -> list[Structure]:
    """The planner's entry point: named-shape candidates when ``spec`` is given, else the single
    structure of the robots' explicit ``goal`` poses (validated)."""
    if spec is not None:
        return candidate_structures(robots_in_voltage_order, spec, approach_margin_um=approach_margin_um)
    return [structure_from_goals(robots_in_voltage_order, None, approach_margin_um=approach_margin_um)]
