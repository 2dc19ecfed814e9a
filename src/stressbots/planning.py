"""The nominal n-robot assembly planner (seed Appendix 2, generalised).

Every robot receives the same signal, so the planner can only choose a sequence of control primitives
P_k (SPEC 4: under P_k the robots D_1..D_k turn, the others drive straight). The seed reduces the
parallel problem to two robots moving together followed by single robots, and this module does the same:

**Step 1 - G_1.** D_n and D_{n-1} form the initial pair while D_1..D_{n-2} orbit in place (every
primitive used, P_n, P_{n-1}, P_{n-2}, turns them). D_{n-1} follows a route to its slot using
P_{n-1}/P_{n-2} (D_n drives straight meanwhile); D_n is driven with P_n/P_{n-1} while D_{n-1} orbits.
The seed does this in two stages: D_n first goes to a pose a_n (D_{n-1} orbiting back to its start), then
D_{n-1} drives its whole route while D_n drives straight into its slot. That fails when D_{n-1}'s route
is long: D_n's straight corridor leaves the arena or crosses an orbit (SPEC 5, "a known limit"). Here
D_{n-1}'s route may be cut into *pieces*. Between two pieces D_n runs the same short straight corridor
into its slot and then loops back along a path whose length is exactly a whole number of D_{n-1}'s orbit
periods, so D_{n-1} orbits back to where it stopped. One piece is exactly the seed's scheme.

**Steps 2..n-1 - docking.** D_i (i = n-2 .. 1) docks with P_i/P_{i-1} while D_1..D_{i-1} orbit and the
docked robots push. It may first wait on its orbit (P_i): the planner tries several departure phases
and takes the fastest collision-free route.

**Routes** avoid the orbit discs (radius r*), the structure and the arena edge with a clearance, and
end with a straight approach into the slot (touching allowed). A route is first tried direct (one
shortest one-way path), then through a lazily checked roadmap of waypoint poses (random and tangent to
the discs), growing until a route is found.

Every plan is replayed by :func:`stressbots.replay.replay`, an independent integrator, before it is
returned.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field, replace
from typing import NamedTuple

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra as csgraph_dijkstra

from . import paths as pathlib
from .collision import (
    bodies_hit_discs,
    disc_overlaps,
    outside_arena,
    pairwise_overlaps,
    penetration_depth,
    point_rectangle_distance,
    point_rectangle_distance_rows,
)
from .electrostatics import ControlAnalysis, analyse_scenario
from .errors import PlanningError
from .kinematics import advance, move
from .overlap import OverlapSettings, PairSchedule, joint_primitives, overlap_schedule, with_orbits
from .plans import Plan, PlanPrimitive, PlanStep, merge_steps
from .prepositioning import (
    PrepositionSettings,
    docking_costs,
    follower_ends,
    splice_straight,
    straight_windows,
)
from .replay import ReplayReport, replay
from .robots import TWO_PI, Pose, orbit_radii, turning_centres
from .structures import Structure, target_structures

__all__ = ["SHORTEST", "PlannerOptions", "PlanResult", "Phase", "plan_assembly", "lower_bound_s", "Obstacles", "NoRoute", "route"]


SEARCH_BUDGET_DEFAULT = 128
"""Default :attr:`PlannerOptions.search_budget` (G_1 schedules, ~25-70 ms each). Of
``benchmarks/bench_planner.py``'s layouts of 2-8 robots, the ones that plan use at most 97 (cross-8, by
the extended search); tee-8 needs 232 (14 s of CPU) and is refused after 128 (~8 s) instead. Before
variants with the same G_1 slots shared their failure, tee-8 searched 288 (12 G_1 searches of 24, ~22 s
of CPU) and failed."""


@dataclass(frozen=True)
class PlannerOptions:
    """Planner settings (um, s).

    Attributes
    ----------
    clearance_um:
        Distance kept from orbit discs, the structure and the arena edge (room for control error).
    approach_um:
        Length of the final approach into every slot (capped by the slot's clear corridor): a gentle
        interpolated clockwise arc that arrives at the slot's heading, then a short straight push. The
        closed-loop controller flies the same arc as its fine motion, correcting its radius.
    sample_um:
        Spacing of the collision-check samples along routes.
    departure_phases:
        How many departure phases on its orbit a docking robot tries.
    roadmap_nodes:
        Sizes of the successive waypoint roadmaps tried when no direct route is clear.
    max_pieces:
        Largest number of pieces D_{n-1}'s route may be cut into while forming G_1.
    seed:
        Seed of the roadmap's random waypoints (the plan is a deterministic function of it).
    time_budget_s:
        Wall time after which no further structure variant is tried.
    max_candidates:
        Most structure variants tried (None: all). A deterministic budget: unlike ``time_budget_s`` it
        gives the same result on a loaded machine, so tests use it.
    pair_candidates:
        How many schedulable direct departures of D_{n-1} are compared when forming G_1 (the shortest
        schedule is kept, and one-piece schedules around roadmap routes are tried too); 1 takes the
        first schedulable route, as the seed does. Default 1 for now: see :data:`SHORTEST`.
    variants_compared:
        How many plannable structure variants (a named shape's mirror images and assignments) are
        planned in full, cheapest lower bound first; the shortest plan is returned. A variant whose
        lower bound is already longer than the best plan is skipped. 1 returns the first plan found
        (default for now: see :data:`SHORTEST`).
    orbit_phases:
        When D_n's whole-period path between two runs of G_1 is blocked, how many phases of its own
        orbit it may first orbit to before leaving (0: never, as in the seed's scheme).
    extended_search:
        When no variant is plannable, search again with the wider G_1 search: routed whole-period paths
        stretched in one leg, ``orbit_phases``, and parking-track runs that stop short of the track's end
        or fit after D_{n-1}'s wait (False: the standard search only).
    pair_schedules:
        G_1 schedules tried per G_1 search (each plans D_n around one cut of one route of D_{n-1}, the
        expensive step); when they are spent, the search ends: a hopeless pair costs at most this many.
    extended_max_pieces, extended_pair_schedules:
        ``max_pieces`` and ``pair_schedules`` of the extended search: more, shorter pieces of D_{n-1}'s
        route with D_n re-aimed between them (``max_pieces`` = 1, the seed's scheme, stays 1), and more
        schedules per G_1 search.
    overlap_pair:
        Form G_1 with overlapped schedules first (:mod:`stressbots.overlap`): D_n turns toward its slot
        while D_{n-1} turns (on its orbit and on its route's arcs), so it runs straight only while D_{n-1}
        does. Much shorter G_1 than the seed's two stages; False keeps only the seed's scheme and its
        pieces.
    overlap:
        Settings of that search.
    preposition:
        While a robot docks, let the next one drive straight during its straight stretches (P_{k-2}
        instead of P_{k-1}: :mod:`stressbots.prepositioning`) when that shortens the next one's docking.
    preposition_settings:
        Settings of that search.
    search_budget:
        G_1 schedules tried over the whole search (every structure variant, standard and extended): a
        deterministic bound on the time spent on a layout that cannot be planned (unlike
        ``time_budget_s``, the same on a loaded machine). When it is spent no further variant is tried and
        the failure names the most common obstacle. None: no bound.
    """

    clearance_um: float = 10.0
    approach_um: float = 160.0
    sample_um: float = 5.0
    departure_phases: int = 12
    roadmap_nodes: tuple[int, ...] = (80, 250, 700)
    max_pieces: int = 6
    seed: int = 0
    time_budget_s: float = 120.0
    max_candidates: int | None = None
    pair_candidates: int = 1
    variants_compared: int = 1
    orbit_phases: int = 16
    extended_search: bool = True
    pair_schedules: int = 24
    extended_max_pieces: int = 10
    extended_pair_schedules: int = 64
    search_budget: int | None = SEARCH_BUDGET_DEFAULT
    overlap_pair: bool = True
    overlap: OverlapSettings = OverlapSettings()
    preposition: bool = True
    preposition_settings: PrepositionSettings = PrepositionSettings()


SHORTEST = {"pair_candidates": 4, "variants_compared": 3}
"""PlannerOptions overrides for shorter plans (issue 15): compare G_1 schedules and structure variants.

Not the default yet. The controller now assembles these plans as often as the default ones (tests/test_edr.py
passes with them; 21/28 closed-loop trials either way on 14 tuning layouts of bench_generality.py), and
they are 12 % shorter in total on bench_planner.py's layouts of 2-8 robots, but planning takes 2-13x
longer and some plans are longer (gap-8), so the default stays the faster plan the controller was tuned on.
Those figures predate the overlapped G_1 and pre-positioning (now default), which it does not change: its
G_1 comparison only runs when no overlapped schedule is found. Not re-measured since.
"""


@dataclass(frozen=True)
class Phase:
    """One phase of a plan, as a closed-loop controller follows it.

    ``mover`` (scenario index) drives toward ``target`` with primitives ``turn_k`` (its arm down) and
    ``straight_k`` (arm up); every robot with a lower voltage index orbits, higher ones push or (for
    ``pair-B``) drive straight. Kinds: ``pair-A`` (D_n moves, D_{n-1} orbits), ``pair-B`` (D_{n-1} moves,
    D_n runs straight: ``run`` is D_n's run start and length), ``wait`` (a docking robot orbits before
    leaving), ``route`` (it drives to the start of its approach through ``waypoints``) and ``approach``
    (its final approach into the slot: an interpolated clockwise arc, then a short straight push).
    ``path``/``path_start`` give the mover's planned path; ``approach_um`` the length of its final approach.
    """

    kind: str
    mover: int
    turn_k: int
    straight_k: int
    t0_s: float
    duration_s: float
    target: tuple[float, float, float]
    waypoints: tuple[tuple[float, float, float], ...] = ()
    partner: int = -1
    run: tuple[tuple[float, float, float], float] | None = None
    last: bool = False
    partner_end: tuple[float, float, float] | None = None
    path: tuple[tuple[str, float], ...] = ()
    path_start: tuple[float, float, float] | None = None
    approach_um: float = 0.0


@dataclass(frozen=True)
class PlanResult:
    """A verified nominal plan and what was learnt making it."""

    plan: Plan
    structure: Structure
    analysis: ControlAnalysis
    replay: ReplayReport
    summary: dict
    notes: tuple[str, ...] = field(default=())
    phases: tuple[Phase, ...] = field(default=())


# ----------------------------------------------------------------------------------------------------
# Obstacles


class NearMasks(NamedTuple):
    """Which obstacles each path segment may reach: discs ``(E, S, K)``, boxes ``(E, S, B)``, arena ``(E, S)``."""

    discs: np.ndarray
    boxes: np.ndarray
    arena: np.ndarray


class NearPairs(NamedTuple):
    """Candidate ``(sample, obstacle)`` index pairs for :meth:`Obstacles.hits`: discs and boxes as
    ``(sample_indices, obstacle_indices)``, and per sample whether the arena edge may be in reach."""

    discs: tuple[np.ndarray, np.ndarray]
    boxes: tuple[np.ndarray, np.ndarray]
    arena: np.ndarray


def _sample_pairs(mask: np.ndarray, e_of: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Expand a segment mask ``(E, S, K)`` to the ``(sample, obstacle)`` pairs of samples on segment
    ``(e_of[m], seg[m])``, without a ``(samples, K)`` array (most segments reach one obstacle or none)."""
    e, nseg, k = mask.shape
    fseg, obj = np.nonzero(mask.reshape(e * nseg, k))  # sorted by segment
    count = np.bincount(fseg, minlength=e * nseg)
    first = np.concatenate([[0], np.cumsum(count)[:-1]])
    fs = e_of * nseg + seg
    rep = count[fs]
    si = np.repeat(np.arange(len(fs)), rep)
    j = np.arange(si.size) - np.repeat(np.cumsum(rep) - rep, rep)
    return si, obj[first[fs][si] + j]


def _pairs(samples: np.ndarray, centres: np.ndarray, reach: np.ndarray,
           cand: tuple[np.ndarray, np.ndarray] | None) -> tuple[np.ndarray, np.ndarray]:
    """``(sample, obstacle)`` index pairs whose centres are closer than ``reach`` (among ``cand``'s pairs)."""
    if cand is None:
        d2 = (samples[:, None, 0] - centres[None, :, 0]) ** 2 + (samples[:, None, 1] - centres[None, :, 1]) ** 2
        si, ci = np.nonzero(d2 < (reach * reach)[None, :])
        return si, ci
    si, ci = cand
    d2 = (samples[si, 0] - centres[ci, 0]) ** 2 + (samples[si, 1] - centres[ci, 1]) ** 2
    keep = d2 < reach[ci] ** 2
    return si[keep], ci[keep]


@dataclass(frozen=True)
class Obstacles:
    """Static obstacles for one robot's route: orbit discs, docked bodies (boxes) and the arena.

    Public routing API (with :func:`route` and :class:`NoRoute`): the closed-loop controller builds one
    from its estimates (orbits as measured, docked bodies where they are seen) to route around them.
    Discs are ``(K, 2)`` centres and ``(K,)`` radii (um); boxes are body poses ``(B, 3)`` with their
    lengths and widths (um); ``arena`` is ``(width_um, height_um)`` or None (no walls).
    """

    disc_centres: np.ndarray
    disc_radii: np.ndarray
    disc_labels: tuple[str, ...]
    box_poses: np.ndarray
    box_lengths: np.ndarray
    box_widths: np.ndarray
    box_labels: tuple[str, ...]
    arena: tuple[float, float] | None

    def with_disc(self, centre, radius, label) -> Obstacles:
        return Obstacles(
            np.vstack([self.disc_centres, np.reshape(centre, (1, 2))]),
            np.append(self.disc_radii, radius),
            self.disc_labels + (label,),
            self.box_poses,
            self.box_lengths,
            self.box_widths,
            self.box_labels,
            self.arena,
        )

    def hits(self, samples: np.ndarray, length: float, width: float, clearance: float, *,
             near: NearPairs | None = None) -> np.ndarray:
        """Per sample, whether the body hits any obstacle (keeping ``clearance``): ``(M,)`` bool.

        A cheap test on the body centre (half-diagonal ``hd``) first; the exact rectangle test runs only
        on the sample-obstacle pairs near each other. ``near`` (the candidate pairs, e.g. from
        :func:`_segments_near`) skips the pairs known to be out of reach; it must hold every pair within
        reach.
        """
        samples = np.asarray(samples, dtype=np.float64)
        bad = np.zeros(len(samples), dtype=bool)
        hd = 0.5 * math.hypot(length, width)
        if len(self.disc_radii):
            # squared distances against a reach enlarged by 1e-6 um: a superset of the pairs within reach
            si, ci = _pairs(samples, self.disc_centres, self.disc_radii + clearance + hd + 1e-6, None if near is None else near.discs)
            if len(si):
                dist = point_rectangle_distance_rows(self.disc_centres[ci], samples[si], length, width)
                bad[si[dist < (self.disc_radii + clearance)[ci]]] = True
        if len(self.box_lengths):
            box_reach = 0.5 * np.hypot(self.box_lengths, self.box_widths) + hd + clearance + 1e-6
            si, bi = _pairs(samples, self.box_poses[:, :2], box_reach, None if near is None else near.boxes)
            if len(si):
                depth = penetration_depth(samples[si], length, width, self.box_poses[bi], self.box_lengths[bi], self.box_widths[bi])
                bad[si[depth > -clearance]] = True
        if self.arena is not None:
            w, h = self.arena
            m = hd + clearance
            xy = samples[:, :2]
            close = (xy[:, 0] < m) | (xy[:, 0] > w - m) | (xy[:, 1] < m) | (xy[:, 1] > h - m)
            if near is not None:
                close &= near.arena
            if close.any():
                idx = np.flatnonzero(close)
                shifted = samples[idx] - np.array([clearance, clearance, 0.0])
                bad[idx] |= outside_arena(shifted, length, width, (w - 2 * clearance, h - 2 * clearance)) > 0
        return bad

    def first_hit(self, samples: np.ndarray, length: float, width: float, clearance: float, *, box_tol: float | None = None) -> str | None:
        """Label of an obstacle the body hits along ``samples`` (M, 3), or None.

        Discs and the arena keep ``clearance``; boxes keep ``clearance`` too unless ``box_tol`` is given
        (then only interpenetration deeper than ``box_tol`` counts: touching the structure is docking).
        """
        if len(samples) == 0:
            return None
        if len(self.disc_radii):
            hit = bodies_hit_discs(samples, length, width, self.disc_centres, self.disc_radii + clearance)
            if hit.any():
                return self.disc_labels[int(np.argmax(hit.any(axis=0)))]
        if len(self.box_lengths):
            m, b = len(samples), len(self.box_lengths)
            depth = penetration_depth(
                np.repeat(samples, b, axis=0),
                length,
                width,
                np.tile(self.box_poses, (m, 1)),
                np.tile(self.box_lengths, m),
                np.tile(self.box_widths, m),
            ).reshape(m, b)
            limit = -clearance if box_tol is None else box_tol
            bad = depth > limit
            if bad.any():
                return self.box_labels[int(np.argmax(bad.any(axis=0)))]
        if self.arena is not None:
            w, h = self.arena
            inner = (w - 2 * clearance, h - 2 * clearance)
            shifted = samples - np.array([clearance, clearance, 0.0])
            if (outside_arena(shifted, length, width, inner) > 0).any():
                return "the arena edge"
        return None


def _path_hit(obst: Obstacles, path: pathlib.Path, length: float, width: float, opts: PlannerOptions) -> str | None:
    return obst.first_hit(path.sample(opts.sample_um), length, width, opts.clearance_um)


# ----------------------------------------------------------------------------------------------------
# Route search: direct, then a lazily checked roadmap


_KNN = 16  # successors per roadmap node


class NoRoute(Exception):
    """No collision-free route exists (at the given clearance); ``reason`` says what blocks it."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


class SearchSpent(NoRoute):
    """Raised by an ``extra_check`` to end a route search whose search budget is spent.

    Every route the search could still find would be vetoed, so searching on only costs time (the bulk
    of a hopeless G_1 search). :func:`route` draws the random numbers the rest of its roadmaps would
    have drawn before passing it on, so the random stream, and with it every later plan, is unchanged.
    """


def _skip_roadmaps(rng: np.random.Generator, counts: Sequence[int], discs: int) -> None:
    """Draw what :func:`_sample_nodes` draws for roadmaps of ``counts`` nodes around ``discs`` discs."""
    for count in counts:
        rng.random(discs + 3 * count)


def _batch_samples(starts: np.ndarray, seg_lengths: np.ndarray, words: np.ndarray, radius: float, step_um: float,
                   keep: np.ndarray | None = None, part: tuple[int, int] = (0, 1)):
    """Sample many 3-segment paths at once: poses ``(P, 3)``, the path and segment index of every sample.

    ``seg_lengths`` is ``(E, S)``; ``words`` holds each path's kinds (e.g. ``"RSR"``). Samples are at most
    ``step_um`` apart along each path and include both ends. ``keep`` (``(E, S)`` bool) drops the samples
    of the segments it marks False (the sample positions of the others do not change). ``part = (q, Q)``
    returns only every Q-th sample of each path, from its q-th (a coarse pass first, for early exits).
    """
    e, nseg = seg_lengths.shape
    curv, joints = _segment_joints(starts, seg_lengths, words, radius)
    total = seg_lengths.sum(axis=1)
    counts = np.maximum(2, np.ceil(total / step_um).astype(int) + 1)
    cum = np.concatenate([np.zeros((e, 1)), np.cumsum(seg_lengths, axis=1)[:, :-1]], axis=1)  # (E, S)
    if keep is None:
        owner = np.repeat(np.arange(e), counts)
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
        index = np.arange(owner.size) - offsets[owner]
    else:
        owner, index, wanted = _kept_indices(keep, counts, cum, total)
    if part[1] > 1:
        pick = index % part[1] == part[0]
        owner, index = owner[pick], index[pick]
        if keep is not None:
            wanted = wanted[pick]
    s = index / (counts[owner] - 1) * total[owner]
    seg = np.sum(s[:, None] >= cum[owner] - 1e-12, axis=1) - 1
    seg = np.clip(seg, 0, nseg - 1)
    if keep is not None:
        sel = seg == wanted
        owner, seg, s = owner[sel], seg[sel], s[sel]
    local = s - cum[owner, seg]
    poses = move(joints[owner, seg], local, curv[owner, seg])
    return poses, owner, seg


def _kept_indices(keep: np.ndarray, counts: np.ndarray, cum: np.ndarray, total: np.ndarray) -> tuple[np.ndarray, ...]:
    """Path index, sample index and wanted segment ``(P,)`` of candidate samples of the kept segments: a
    superset by two samples at each end (the caller keeps those that fall in the wanted segment). Sample
    positions rise with the index, so each segment's samples are one range of indices."""
    nseg = keep.shape[1]
    ke, kj = np.nonzero(keep)
    den = (counts[ke] - 1).astype(np.float64)
    safe = np.where(total[ke] > 0, total[ke], 1.0)
    lo = np.floor(cum[ke, kj] / safe * den).astype(int) - 2
    nxt = np.where(kj + 1 < nseg, cum[ke, np.minimum(kj + 1, nseg - 1)], np.inf)
    hi = np.where(kj + 1 < nseg, np.ceil(np.minimum(nxt, total[ke]) / safe * den), den).astype(int) + 2
    lo = np.where(total[ke] > 0, np.clip(lo, 0, None), 0)
    hi = np.where(total[ke] > 0, np.minimum(hi, counts[ke] - 1), counts[ke] - 1)
    n_i = np.maximum(hi - lo + 1, 0)
    rep = np.repeat(np.arange(len(ke)), n_i)
    starts = np.concatenate([[0], np.cumsum(n_i)[:-1]])
    index = lo[rep] + (np.arange(rep.size) - starts[rep])
    return ke[rep], index, kj[rep]


def _segment_joints(starts: np.ndarray, seg_lengths: np.ndarray, words: np.ndarray, radius: float):
    """Curvatures ``(E, S)`` and the poses ``(E, S + 1, 3)`` at the ends of every segment of many paths."""
    nseg = seg_lengths.shape[1]
    kinds = np.array([[w[j] == "R" for j in range(nseg)] for w in words.tolist()], dtype=bool).reshape(seg_lengths.shape)
    curv = np.where(kinds, 1.0 / radius, 0.0)
    joint_list = [starts]
    for j in range(nseg):
        joint_list.append(move(joint_list[-1], seg_lengths[:, j], curv[:, j]))
    return curv, np.stack(joint_list, axis=1)


def _segments_near(obst: Obstacles, joints: np.ndarray, seg_lengths: np.ndarray, curv: np.ndarray, radius: float,
                   hd: float, clearance: float) -> NearMasks:
    """Which obstacles any sample of each segment could reach in :meth:`Obstacles.hits`: masks ``(E, S, .)``.

    A segment of length ``s`` lies in the disc of radius ``s / 2`` about its chord's midpoint (every point
    is at most ``s`` from both ends combined), and an arc in its turning circle; an obstacle whose near
    zone (obstacle, plus clearance and the body's half-diagonal ``hd``) keeps out of that disc cannot be
    reached by any sample of the segment. Exact pruning: ``hits`` gives the same answers with the masks.
    """
    a, b = joints[:, :-1, :2], joints[:, 1:, :2]
    centre = 0.5 * (a + b)
    rho = 0.5 * seg_lengths
    arc = curv > 0
    if arc.any():
        tc = a + radius * np.stack([np.cos(joints[:, :-1, 2]), -np.sin(joints[:, :-1, 2])], axis=-1)
        use = arc & (radius < rho)
        centre = np.where(use[..., None], tc, centre)
        rho = np.where(use, radius, rho)
    rho = rho + 1e-6 * (1.0 + rho)  # rounding of the sampled poses

    def reach(centres: np.ndarray, extent: np.ndarray) -> np.ndarray:
        d = np.hypot(centre[..., None, 0] - centres[:, 0], centre[..., None, 1] - centres[:, 1])
        return d < rho[..., None] + extent + clearance + hd

    discs = reach(obst.disc_centres, obst.disc_radii)
    boxes = reach(obst.box_poses[:, :2], 0.5 * np.hypot(obst.box_lengths, obst.box_widths))
    arena = np.zeros(rho.shape, dtype=bool)
    if obst.arena is not None:
        w, h = obst.arena
        m = hd + clearance
        x, y = centre[..., 0], centre[..., 1]
        arena = (x - rho < m) | (x + rho > w - m) | (y - rho < m) | (y + rho > h - m)
    return NearMasks(discs, boxes, arena)


_SAMPLE_PASSES = 4  # interleaved sampling passes per edge check (every 4th sample first): blocked edges exit early


def _edges_clear(obst: Obstacles, starts, goals, radius, length, width, opts: PlannerOptions, recheck=None) -> np.ndarray:
    """Whether the shortest path of every (start, goal) pair is collision-free: ``(E,)`` bool.

    Two stages: coarse samples with the clearance inflated by the most any body point moves between two
    samples (half a step, scaled by 1 + half-diagonal / radius on arcs) accept most edges cheaply and
    conservatively; the edges that fail are checked again at full resolution and the true clearance.
    Segments far from every obstacle (:func:`_segments_near`) are not sampled at all.
    """
    if len(starts) == 0:
        return np.zeros(0, dtype=bool)
    starts = np.asarray(starts, float)
    goals = np.asarray(goals, float)
    words, seg = pathlib.shortest_path_segments(starts, goals, radius)
    words = np.asarray(words)
    curv, joints = _segment_joints(starts, seg, words, radius)
    hd = 0.5 * math.hypot(length, width)

    def blocked(idx: np.ndarray, step: float, clearance: float) -> np.ndarray:
        out = np.zeros(len(idx), dtype=bool)
        near = _segments_near(obst, joints[idx], seg[idx], curv[idx], radius, hd, clearance)
        any_near = near.discs.any(axis=2) | near.boxes.any(axis=2) | near.arena  # (E, S)
        live = np.flatnonzero(any_near.any(axis=1))
        for q in range(_SAMPLE_PASSES):  # interleaved passes: an edge found blocked is not sampled further
            if len(live) == 0:
                break
            e = idx[live]
            poses, owner, sseg = _batch_samples(starts[e], seg[e], words[e], radius, step, keep=any_near[live], part=(q, _SAMPLE_PASSES))
            e_of = live[owner]
            cand = NearPairs(_sample_pairs(near.discs, e_of, sseg), _sample_pairs(near.boxes, e_of, sseg), near.arena[e_of, sseg])
            bad = obst.hits(poses, length, width, clearance, near=cand)
            hit = np.zeros(len(live), dtype=bool)
            hit[owner[bad]] = True
            out[live[hit]] = True
            live = live[~hit]
        return out

    step = 4.0 * opts.sample_um
    inflate = 0.5 * step * (1.0 + 0.5 * math.hypot(length, width) / radius)
    clear = ~blocked(np.arange(len(starts)), step, opts.clearance_um + inflate)
    again = np.flatnonzero(~clear & (True if recheck is None else np.asarray(recheck, bool)))
    if len(again):
        clear[again] = ~blocked(again, opts.sample_um, opts.clearance_um)
    return clear


def _sample_nodes(rng: np.random.Generator, count: int, region: tuple[float, float, float, float], obst: Obstacles,
                  length: float, width: float, opts: PlannerOptions) -> np.ndarray:
    """Collision-free waypoint poses: tangent to the orbit discs and uniformly random."""
    x0, y0, x1, y1 = region
    nodes = []
    # Poses tangent to rings around each disc, both travel directions: how a route skirts an orbit.
    for c, r in zip(obst.disc_centres, obst.disc_radii, strict=False):
        ring = r + opts.clearance_um + 0.5 * math.hypot(length, width) + 5.0
        ang = np.linspace(0.0, TWO_PI, 12, endpoint=False) + rng.uniform(0, TWO_PI / 12)
        px = c[0] + ring * np.sin(ang)
        py = c[1] + ring * np.cos(ang)
        for sense in (0.5 * math.pi, -0.5 * math.pi):
            nodes.append(np.stack([px, py, np.mod(ang + sense, TWO_PI)], axis=1))
    rand = np.column_stack([rng.uniform(x0, x1, count), rng.uniform(y0, y1, count), rng.uniform(0, TWO_PI, count)])
    nodes.append(rand)
    allnodes = np.vstack(nodes)
    return allnodes[~obst.hits(allnodes, length, width, opts.clearance_um)]


def _roadmap_region(sources: np.ndarray, target: np.ndarray, obst: Obstacles, radius: float, length: float):
    """``(x0, y0, x1, y1)`` (um) where roadmap waypoints are drawn: the arena, or without walls the box
    around the sources, the target and the orbit centres, padded by two turning diameters and a body."""
    if obst.arena is not None:
        return (0.0, 0.0, obst.arena[0], obst.arena[1])
    parts = [sources[:, :2], target[None, :2]] + ([obst.disc_centres] if len(obst.disc_radii) else [])
    pts = np.vstack(parts)
    pad = 4.0 * radius + length
    return (pts[:, 0].min() - pad, pts[:, 1].min() - pad, pts[:, 0].max() + pad, pts[:, 1].max() + pad)


def route(
    sources: np.ndarray,
    source_costs: np.ndarray,
    target: np.ndarray,
    radius: float,
    length: float,
    width: float,
    obst: Obstacles,
    opts: PlannerOptions,
    rng: np.random.Generator,
    who: str,
    *,
    extra_check: Callable[[int, pathlib.Path], str | None] | None = None,
) -> tuple[int, pathlib.Path, tuple[np.ndarray, ...]]:
    """Cheapest collision-free route from one of ``sources`` to ``target`` (both clear).

    ``source_costs`` (um) are added to each source's route length (waiting time times speed).
    ``extra_check(source_index, path)`` may veto a whole route (e.g. time-dependent conflicts).
    Returns ``(source_index, path, waypoints)`` (the roadmap poses the route passes, ending with the
    target: a closed-loop controller steers from one to the next); raises :class:`NoRoute`.
    """
    sources = np.atleast_2d(sources)
    blocked_by = obst.first_hit(target[None, :], length, width, opts.clearance_um)
    if blocked_by is not None:
        raise NoRoute(f"{who}: the start of its straight approach is blocked by {blocked_by}")
    free = ~obst.hits(sources, length, width, opts.clearance_um)
    if not free.any():
        first = obst.first_hit(sources[:1], length, width, opts.clearance_um)
        raise NoRoute(f"{who}: it starts within {opts.clearance_um:g} um of {first}")
    sources, source_costs = sources[free], np.asarray(source_costs)[free]
    index_of = np.flatnonzero(free)
    # 1. direct shortest paths, cheapest first
    direct = pathlib.shortest_path_lengths(sources, np.broadcast_to(target, sources.shape), radius) + source_costs
    reasons: list[str] = []
    vetoes: list[str] = []  # reasons extra_check gave for collision-free routes
    for s in np.argsort(direct, kind="stable"):
        p = pathlib.shortest_path(sources[s], target, radius)
        hit = _path_hit(obst, p, length, width, opts)
        if hit is None and extra_check is not None:
            try:
                hit = extra_check(int(index_of[s]), p)
            except SearchSpent:
                _skip_roadmaps(rng, opts.roadmap_nodes, len(obst.disc_radii))
                raise
            if hit is not None:
                vetoes.append(hit)
        if hit is None:
            return int(index_of[s]), p, (np.asarray(target, float),)
        reasons.append(hit)
    # 2. roadmaps of growing size: k-nearest edges, checked lazily along the shortest candidates
    region = _roadmap_region(sources, target, obst, radius, length)
    for q, count in enumerate(opts.roadmap_nodes):
        way = _sample_nodes(rng, count, region, obst, length, width, opts)
        nodes = np.vstack([sources, target[None, :], way])
        try:
            found = _roadmap_search(nodes, len(sources), source_costs, radius, length, width, obst, opts,
                                    None if extra_check is None else (lambda s, p: extra_check(int(index_of[s]), p)), reasons, vetoes)
        except SearchSpent:
            _skip_roadmaps(rng, opts.roadmap_nodes[q + 1:], len(obst.disc_radii))
            raise
        if found is not None:
            s, path, way_nodes = found
            return int(index_of[s]), path, way_nodes
    if extra_check is not None and vetoes:
        common = max(set(vetoes), key=vetoes.count)
        raise NoRoute(f"{who}: no usable route found ({common})")
    common = max(set(reasons), key=reasons.count) if reasons else "obstacles"
    raise NoRoute(f"{who}: no collision-free route found (the direct path is blocked by {common})")


def _roadmap_edges(nodes: np.ndarray, ns: int, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """Directed roadmap edges ``(E, 2)`` (sorted, unique) and their lengths ``(E,)`` (um).

    Nodes ``0..ns-1`` are the sources, ``ns`` the target, the rest waypoints. Every node links to its
    ``_KNN`` nearest successors (by shortest-path length); sources and target link to every waypoint,
    since near a tight goal only a few approaches are clear. No edge enters a source or leaves the target.
    """
    k = len(nodes)
    ti = ns
    ii, jj = np.meshgrid(np.arange(k), np.arange(k), indexing="ij")
    w = pathlib.shortest_path_lengths(nodes[ii.ravel()], nodes[jj.ravel()], radius).reshape(k, k)
    np.fill_diagonal(w, np.inf)
    w[:, :ns] = np.inf  # never route back into a source
    w[ti, :] = np.inf  # the target is the end
    knn = min(_KNN, k - 1)
    nbr = np.argpartition(w, knn - 1, axis=1)[:, :knn]  # each node's nearest successors
    src = np.repeat(np.arange(k), knn)
    dst = nbr.ravel()
    others = np.arange(ns + 1, k)
    src = np.concatenate([src, others, np.repeat(np.arange(ns), len(others))])
    dst = np.concatenate([dst, np.full(len(others), ti), np.tile(others, ns)])
    pairs = np.unique(np.stack([src, dst], axis=1), axis=0)
    pairs = pairs[np.isfinite(w[pairs[:, 0], pairs[:, 1]])]
    return pairs, w[pairs[:, 0], pairs[:, 1]]


_STAR_AFTER = 3  # blocked first (last) legs after which every edge leaving a source (entering the target) is checked
_LAZY_ROUNDS = 200  # Dijkstra rounds that check only the candidate route's edges; then every edge left is checked at once


def _roadmap_search(nodes, ns: int, source_costs, radius: float, length: float, width: float, obst: Obstacles,
                    opts: PlannerOptions, veto, reasons: list[str], vetoes: list[str]):
    """The shortest clear route through one roadmap: ``(source, path, waypoints)`` or None.

    Lazy collision checking: Dijkstra runs on every edge not yet known to be blocked, only the edges of
    the route it returns are checked, blocked ones are dropped and the search repeats. A route whose
    edges are all clear is the shortest among the clear edges, so the answer is the one a search over the
    fully checked roadmap gives, at a fraction of the checks. ``veto(source, path)`` may reject a clear
    route (its first leg is then dropped, at most 20 times), recorded in ``reasons`` and ``vetoes``.
    """
    k, ti = len(nodes), ns
    pairs, lengths = _roadmap_edges(nodes, ns, radius)
    ends = (pairs[:, 0] < ns) | (pairs[:, 1] == ti)  # edges at a source or the target: checked finely
    state = np.zeros(len(pairs), dtype=np.int8)  # 0 unknown, 1 clear, -1 blocked or dropped
    key = pairs[:, 0] * k + pairs[:, 1]  # sorted, since pairs are

    def check(idx: np.ndarray) -> None:
        ok = _edges_clear(obst, nodes[pairs[idx, 0]], nodes[pairs[idx, 1]], radius, length, width, opts, recheck=ends[idx])
        state[idx] = np.where(ok, 1, -1)

    vals = np.concatenate([lengths, np.asarray(source_costs, float) + 1e-9]) + 1e-9
    rows = np.concatenate([pairs[:, 0], np.full(ns, k)])
    cols = np.concatenate([pairs[:, 1], np.arange(ns)])
    rounds = vetoed = tstar = sstar = 0
    while vetoed < 20:
        keep = np.concatenate([state >= 0, np.ones(ns, dtype=bool)])
        graph = csr_matrix((vals[keep], (rows[keep], cols[keep])), shape=(k + 1, k + 1))
        dist, pred = csgraph_dijkstra(graph, directed=True, indices=k, return_predecessors=True)
        if not np.isfinite(dist[ti]):
            return None
        seq = [ti]
        while pred[seq[-1]] != k:
            seq.append(int(pred[seq[-1]]))
        seq = seq[::-1]
        on = np.searchsorted(key, np.asarray(seq[:-1]) * k + np.asarray(seq[1:]))
        unknown = on[state[on] == 0]
        if len(unknown):
            rounds += 1
            check(np.flatnonzero(state == 0) if rounds > _LAZY_ROUNDS else unknown)
            bad = on[state[on] < 0]
            if len(bad):
                # blocked first or last legs: the start or the approach is cramped, so check that whole star
                star = np.zeros(len(pairs), dtype=bool)
                if (pairs[bad, 1] == ti).any():
                    tstar += 1
                    if tstar >= _STAR_AFTER:
                        star |= pairs[:, 1] == ti
                if (pairs[bad, 0] < ns).any():
                    sstar += 1
                    if sstar >= _STAR_AFTER:
                        star |= pairs[:, 0] < ns
                star &= state == 0
                if star.any():
                    check(np.flatnonzero(star))
                continue
        segs: list = []
        for a, b in zip(seq[:-1], seq[1:], strict=False):
            segs.extend(pathlib.shortest_path(nodes[a], nodes[b], radius).segments)
        path = pathlib.Path(Pose(*nodes[seq[0]]), radius, tuple(segs))
        why = veto(seq[0], path) if veto is not None else None
        if why is None:
            return seq[0], path, tuple(nodes[q].copy() for q in seq[1:])
        reasons.append(why)
        vetoes.append(why)
        state[on[0]] = -1  # forbid this route's first leg and look for another
        vetoed += 1
    return None


# ----------------------------------------------------------------------------------------------------
# The planner


class _Search:
    """Work shared by the structure variants of one ``plan_assembly`` call.

    ``used`` counts the G_1 schedules tried against :attr:`PlannerOptions.search_budget`.
    ``pair_failures`` maps what a G_1 search depends on (see :meth:`_Planner.form_pair`) to why it
    failed: variants that differ only in later slots (which side stems grow on, which tooth is first)
    would repeat the same failing search exactly, so they fail at once with the same reason.
    ``bottlenecks`` are the ranks of robots whose docking failed in a variant: later variants check first
    that those robots can reach their slots at all (:meth:`_Planner.dock_check`), before forming G_1.
    ``docking_failed`` holds the variants (by id) that failed after G_1 was formed: the extended search,
    which only widens the G_1 search, skips them.
    """

    def __init__(self, budget: int | None):
        self.budget = budget
        self.used = 0
        self.pair_failures: dict = {}
        self.bottlenecks: list[int] = []
        self.docking_failed: set[int] = set()

    @property
    def spent(self) -> bool:
        return self.budget is not None and self.used >= self.budget

    def take(self) -> None:
        self.used += 1


class _Timeline:
    """Nominal poses of the whole group as primitives are applied (the planner's own forward model)."""

    def __init__(self, scenario, rank: np.ndarray, names_by_rank: Sequence[str]):
        self.scenario = scenario
        self.rank = rank  # rank[i] = k means robot i (scenario order) is D_k (1-based)
        self.names_by_rank = names_by_rank
        self.poses = scenario.starts.copy()
        self.poses[:, 2] = np.mod(self.poses[:, 2], TWO_PI)
        self.docked = np.zeros(scenario.n, dtype=bool)
        self.speed = scenario.speeds_um_s
        self.radius = scenario.turn_radii_um
        self.t = 0.0
        self.steps: list[PlanStep] = []
        self.travel = np.zeros(scenario.n)  # distance driven off-orbit per robot (um)
        self.phases: list[Phase] = []

    def phase(self, kind: str, mover: int, turn_k: int, straight_k: int, t0: float, target, **extra) -> None:
        """Record the phase that just ran (from ``t0`` to now)."""
        self.phases.append(
            Phase(kind, int(mover), int(turn_k), int(straight_k), float(t0), float(self.t - t0),
                  (float(target[0]), float(target[1]), float(target[2])), **extra)
        )

    def apply(self, k: int, duration: float, *, counts_for: Sequence[int] = ()) -> None:
        """Apply P_k for ``duration`` s (docked robots stay, they push against the structure)."""
        if duration <= 0:
            return
        turning = self.rank <= k
        moving = ~self.docked
        new = advance(self.poses, turning, self.speed, self.radius, duration)
        self.poses[moving] = new[moving]
        for i in counts_for:
            self.travel[i] += self.speed[i] * duration
        self.steps.append(PlanStep(f"P{k}", float(duration)))
        self.t += duration

    def apply_path(self, i: int, path: pathlib.Path, turn_k: int, straight_k: int) -> None:
        """Drive robot ``i`` along ``path`` with the two primitives that move it (R -> turn_k, S -> straight_k)."""
        v = self.speed[i]
        for kind, ell in path.segments:
            self.apply(turn_k if kind == "R" else straight_k, ell / v, counts_for=(i,))

    def dock(self, i: int, goal: np.ndarray, who: str, tol_um: float = 1e-3) -> None:
        err = float(np.hypot(*(self.poses[i, :2] - goal[:2])))
        dth = abs((self.poses[i, 2] - goal[2] + math.pi) % TWO_PI - math.pi)
        if err > tol_um or dth > 1e-6:
            raise PlanningError(f"internal: {who} ends {err:.3g} um / {math.degrees(dth):.3g} deg from its slot")
        self.poses[i] = goal
        self.docked[i] = True


def _label(scn, i: int, rank: int) -> str:
    return f"D{rank} ({scn.names[i]!r})"


def _prechecks(scn, struct: Structure, rank: np.ndarray) -> str | None:
    """Reasons a structure cannot be planned from these starts at all (None if none found)."""
    n = scn.n
    starts = scn.starts
    L, W, R = scn.lengths_um, scn.widths_um, scn.turn_radii_um
    goals = struct.goal_poses(scn.names)
    rstar = orbit_radii(L, W, R)
    centres = turning_centres(starts, R)
    lab = [_label(scn, i, rank[i]) for i in range(n)]
    for i, j, d in pairwise_overlaps(starts, L, W, tol_um=1e-6):
        return f"start bodies of {lab[i]} and {lab[j]} overlap by {d:.1f} um"
    if scn.arena_um is not None:
        out = outside_arena(starts, L, W, scn.arena_um)
        for i in np.flatnonzero(out > 0).tolist():
            return f"{lab[i]} starts {out[i]:.1f} um outside the arena"
        out = outside_arena(goals, L, W, scn.arena_um)
        for i in np.flatnonzero(out > 0).tolist():
            return f"the slot of {lab[i]} is {out[i]:.1f} um outside the arena"
    orbiting = np.flatnonzero(rank <= n - 1).tolist()  # D_1..D_{n-1} orbit at their starts
    for a, b, o in disc_overlaps(centres[orbiting], rstar[orbiting]):
        i, j = orbiting[a], orbiting[b]
        return f"orbits of {lab[i]} and {lab[j]} overlap at the start by {o:.1f} um (orbit radius r* = {rstar[i]:.0f} um)"
    if scn.arena_um is not None:
        w, h = scn.arena_um
        for i in orbiting:
            c, r = centres[i], rstar[i]
            over = max(r - c[0], c[0] + r - w, r - c[1], c[1] + r - h)
            if over > 0:
                return f"the orbit of {lab[i]} leaves the arena by {over:.1f} um"
    # Robots D_j (j <= n-2) orbit until their own step: every slot filled before must stay clear.
    for i in np.flatnonzero(rank <= n - 2).tolist():
        later = np.flatnonzero(rank > rank[i])
        hit = bodies_hit_discs(goals[later], L[later], W[later], centres[i][None, :], [rstar[i]])
        for k in np.flatnonzero(hit[:, 0]):
            j = later[k]
            return f"the orbit of {lab[i]} crosses the slot of {lab[j]} (it orbits there until it docks)"
        # and every other robot's start body (they are still there while D_i orbits)
    for i in orbiting:
        others = np.array([j for j in range(n) if j != i])
        hit = bodies_hit_discs(starts[others], L[others], W[others], centres[i][None, :], [rstar[i]], tol_um=1e-6)
        for k in np.flatnonzero(hit[:, 0]):
            j = others[k]
            return f"the orbit of {lab[i]} crosses the start of {lab[j]}"
    return None


def lower_bound_s(scn, struct: Structure, rank: np.ndarray, phases: int = 90) -> float:
    """A lower bound (s) on the duration of any plan of the sequential scheme.

    G_1 cannot finish before both D_n and D_{n-1} have driven their shortest paths; each later robot
    D_i cannot dock before driving the shortest path from the best point of its orbit circle. A robot
    pre-positioned before its step (:attr:`PlannerOptions.preposition`) starts its docking off that
    circle, so a plan could in principle beat the docking part of this bound (efficiency above 1).
    """
    n = scn.n
    goals = struct.goal_poses(scn.names)
    starts = scn.starts
    v, r = scn.speeds_um_s, scn.turn_radii_um
    by_rank = {int(rank[i]): i for i in range(n)}
    pair = [by_rank[n], by_rank[n - 1]]
    t = max(pathlib.shortest_path_lengths(starts[pair], goals[pair], r[pair]) / v[pair])
    for k in range(n - 2, 0, -1):
        i = by_rank[k]
        ang = np.linspace(0.0, TWO_PI, phases, endpoint=False)
        on_orbit = advance(np.repeat(starts[i][None, :], phases, axis=0), np.ones(phases, bool), v[i], r[i], ang * r[i] / v[i])
        t += float(np.min(pathlib.shortest_path_lengths(on_orbit, np.repeat(goals[i][None, :], phases, axis=0), r[i]))) / v[i]
    return float(t)


def _approach(struct: Structure, name: str, opts: PlannerOptions) -> float:
    return float(min(opts.approach_um, struct.slot(name).approach_um))


def _pre_approach(goal: np.ndarray, a: float) -> np.ndarray:
    return np.array([goal[0] - a * math.sin(goal[2]), goal[1] - a * math.cos(goal[2]), goal[2]])


class _Planner:
    def __init__(self, scn, analysis: ControlAnalysis, struct: Structure, opts: PlannerOptions, *, extended: bool = False,
                 search: _Search | None = None):
        self.search = search or _Search(opts.search_budget)  # shared by every variant of one plan_assembly call
        self.extended = extended  # the wider G_1 search (leg stretch, orbit first, ...): after all variants failed
        if extended:  # the wider G_1 search: more pieces (the seed's one-piece scheme stays one), more schedules
            pieces = max(opts.max_pieces, opts.extended_max_pieces) if opts.max_pieces > 1 else opts.max_pieces
            opts = replace(opts, max_pieces=pieces, pair_schedules=max(opts.pair_schedules, opts.extended_pair_schedules))
        self.scn = scn
        self.analysis = analysis
        self.struct = struct
        self.opts = opts
        self.n = scn.n
        order = analysis.order_index  # scenario indices of D_1..D_n
        assert order is not None and analysis.order is not None  # a STRING design (checked by plan_assembly)
        self.by_rank = {k + 1: int(i) for k, i in enumerate(order)}
        self.rank = np.empty(self.n, dtype=int)
        for k, i in self.by_rank.items():
            self.rank[i] = k
        self.goals = struct.goal_poses(scn.names)
        self.L, self.W = scn.lengths_um, scn.widths_um
        self.v, self.r = scn.speeds_um_s, scn.turn_radii_um
        self.rstar = orbit_radii(self.L, self.W, self.r)
        self.rng = np.random.default_rng(np.random.SeedSequence(opts.seed))
        self.tl = _Timeline(scn, self.rank, [analysis.order[k] for k in range(self.n)])
        self.notes: list[str] = []
        self.route_lengths = np.zeros(self.n)
        self._timed_cache: dict = {}
        self._route_cache: dict = {}

    def lab(self, i: int) -> str:
        return _label(self.scn, i, self.rank[i])

    def obstacles(self, orbiting: Sequence[int], docked: Sequence[int]) -> Obstacles:
        orbiting = list(orbiting)
        docked = list(docked)
        centres = turning_centres(self.tl.poses[orbiting], self.r[orbiting]) if orbiting else np.zeros((0, 2))
        return Obstacles(
            centres,
            self.rstar[orbiting] if orbiting else np.zeros(0),
            tuple(f"the orbit of {self.lab(i)}" for i in orbiting),
            self.goals[docked] if docked else np.zeros((0, 3)),
            self.L[docked] if docked else np.zeros(0),
            self.W[docked] if docked else np.zeros(0),
            tuple(f"the docked body of {self.lab(i)}" for i in docked),
            self.scn.arena_um,
        )

    def approach_path(self, i: int, goal: np.ndarray, a: float, obst: Obstacles, who: str, a_max: float | None = None) -> pathlib.Path:
        """The final approach of robot ``i`` into its slot, ``a`` um long.

        A clockwise arc of radius ``s / phi`` (flown as an interpolated turn, seed App. 3.1) that arrives
        at the slot's heading a short straight push before the slot. Only points to a robot's right are
        reachable on one clockwise arc (seed Fig. 4): ending the nominal approach on such an arc leaves
        the fine-motion controller room to correct errors either way by changing r'. ``phi`` is the
        largest of 20, 12, 6 deg whose swept bodies clear the obstacles (touching the structure at the
        end is docking); else a straight approach, as long as the slot's clear corridor (``a_max``) if
        need be, so that it starts outside a gap between docked neighbours.
        """
        r, L, W = self.r[i], self.L[i], self.W[i]
        tail = min(20.0, 0.25 * a)
        s_f = a - tail
        p_pre = _pre_approach(goal, tail)
        hit = None
        options = [(20.0, a), (12.0, a), (6.0, a), (0.0, a)]
        if a_max is not None and a_max > a:
            options.append((0.0, a_max))
        for phi_deg, length in options:
            if phi_deg == 0.0:
                path = pathlib.Path(Pose(*_pre_approach(goal, length)), r, (("S", length),))
                if obst.first_hit(path.sample(self.opts.sample_um)[:1], L, W, self.opts.clearance_um) is not None:
                    hit = "a docked neighbour at its start"
                    continue
            else:
                radius = s_f / math.radians(phi_deg)
                if radius < 1.05 * r:
                    continue
                start = move(p_pre, -s_f, 1.0 / radius)
                path = pathlib.interpolated_arc(start, math.radians(phi_deg), radius, r, 25.0).then(("S", tail))
            hit = obst.first_hit(path.sample(self.opts.sample_um), L, W, self.opts.clearance_um, box_tol=0.5)
            if hit is None:
                return path
        raise NoRoute(f"{who}: the approach into its slot is blocked by {hit}")

    # -- docking of single robots (steps 2..n-1) -------------------------------------------------

    def dock_check(self, k: int) -> None:
        """Raise :class:`NoRoute` unless D_k can reach its slot from its start orbit.

        The quick test of a robot whose docking failed in an earlier variant: from any of
        ``departure_phases`` points of its start orbit, around the lower robots' orbits (they orbit at
        their starts until their own step) and the slots of the robots docked before it. Its own random
        stream, so the plan of a variant that passes is what it would be without the test.
        """
        i = self.by_rank[k]
        who = self.lab(i)
        obst = self.obstacles([self.by_rank[j] for j in range(1, k)], [self.by_rank[j] for j in range(k + 1, self.n + 1)])
        slot = float(self.struct.slot(self.scn.names[i]).approach_um)
        approach = self.approach_path(i, self.goals[i], _approach(self.struct, self.scn.names[i], self.opts), obst, who, a_max=slot)
        m = self.opts.departure_phases
        waits = np.arange(m) * TWO_PI * self.r[i] / self.v[i] / m
        sources = advance(np.repeat(self.scn.starts[i][None, :], m, axis=0), np.ones(m, bool), self.v[i], self.r[i], waits)
        rng = np.random.default_rng(np.random.SeedSequence([self.opts.seed, k, 1]))
        route(sources, waits * self.v[i], np.array(approach.start, dtype=np.float64), self.r[i], self.L[i], self.W[i], obst, self.opts,
              rng, who)

    def dock_single(self, k: int) -> None:
        i = self.by_rank[k]
        who = self.lab(i)
        goal = self.goals[i]
        a = _approach(self.struct, self.scn.names[i], self.opts)
        orbiting = [self.by_rank[j] for j in range(1, k)]
        docked = [self.by_rank[j] for j in range(k + 1, self.n + 1)]
        obst = self.obstacles(orbiting, docked)
        approach = self.approach_path(i, goal, a, obst, who, a_max=float(self.struct.slot(self.scn.names[i]).approach_um))
        pre = np.array(approach.start, dtype=np.float64)
        m = self.opts.departure_phases
        period = TWO_PI * self.r[i] / self.v[i]
        waits = np.arange(m) * period / m
        p0 = np.repeat(self.tl.poses[i][None, :], m, axis=0)
        sources = advance(p0, np.ones(m, bool), self.v[i], self.r[i], waits)
        s, path, waypoints = route(sources, waits * self.v[i], pre, self.r[i], self.L[i], self.W[i], obst, self.opts, self.rng, who)
        t0 = self.tl.t
        self.tl.apply(k, float(waits[s]))
        self.tl.phase("wait", i, k, k - 1, t0, sources[s])
        t0 = self.tl.t
        steps = [(k if kind == "R" else k - 1, ell / self.v[i]) for kind, ell in path.segments]
        pre_f = None
        if self.opts.preposition and k >= 2:  # after the wait: D_k's route and approach from here
            mover = pathlib.Path(Pose(*self.tl.poses[i]), self.r[i], path.segments + approach.segments)
            tail = [(k if kind == "R" else k - 1, ell / self.v[i]) for kind, ell in approach.segments]
            pre_f = self._preposition(k, steps + tail, [(i, mover)], f"{who} docked", until=path.length / self.v[i])
        if pre_f is not None:
            steps = splice_straight(steps, k, pre_f[0], pre_f[1])
        for kk, d in steps:
            self.tl.apply(kk, d, counts_for=(i,))
        self.tl.phase(
            "route", i, k, k - 1, t0, pre, waypoints=tuple(tuple(float(v) for v in w) for w in waypoints),
            path=path.then(*approach.segments).segments, path_start=tuple(float(v) for v in path.start), approach_um=approach.length,
        )
        t0 = self.tl.t
        self.tl.apply_path(i, approach, k, k - 1)
        self.tl.phase("approach", i, k, k - 1, t0, goal)
        self.route_lengths[i] = path.length + approach.length
        self.tl.dock(i, goal, who)

    def _preposition(self, k: int, steps, movers: Sequence[tuple[int, pathlib.Path]], what: str,
                     until: float = math.inf) -> tuple[float, float] | None:
        """A straight stretch ``(t0_s, dt_s)`` (from now) in which D_{k-1} drives straight with P_{k-2}
        instead of P_{k-1} (:mod:`stressbots.prepositioning`), or None when none saves time.

        ``steps`` are the coming primitive steps (P_k and above turn D_{k-1}, P_{k-1} is replaced), and
        ``movers`` the robots they move with their paths from now: D_k docking, or the G_1 pair. Candidates
        lie in the P_{k-1} steps that end by ``until`` (s), ranked by D_{k-1}'s predicted docking (best
        departure phase on its new orbit, wait plus shortest path); one is taken only if its straight and
        its new orbit clear the obstacles of D_{k-1}'s step, it keeps clear of the movers, and its
        predicted route is clear: D_{k-1}'s docking then takes no longer than predicted, which is less
        than its least docking from where it would be.
        """
        ps = self.opts.preposition_settings
        f = self.by_rank[k - 1]
        vf, rf = self.v[f], self.r[f]
        total = float(sum(d for _, d in steps))
        wins = [w for w in straight_windows(steps, k, ps.min_straight_s) if w[1] <= until + 1e-9]
        if not wins:
            return None
        obst_f = self.obstacles([self.by_rank[j] for j in range(1, k - 1)], [self.by_rank[j] for j in range(k, self.n + 1)])
        a_max = float(self.struct.slot(self.scn.names[f]).approach_um)
        try:
            app_f = self.approach_path(f, self.goals[f], _approach(self.struct, self.scn.names[f], self.opts), obst_f, self.lab(f),
                                       a_max=a_max)
        except NoRoute:
            return None
        pre = np.array(app_f.start, dtype=np.float64)
        cand = [(a + (b - a) * q / ps.start_steps, (b - a) * (1.0 - q / ps.start_steps) * frac)
                for a, b in wins for q in range(ps.start_steps) for frac in ps.length_fractions]
        taus, dts = np.array([c[0] for c in cand]), np.array([c[1] for c in cand])
        ends = follower_ends(self.tl.poses[f], vf, rf, total, taus, dts)
        cost, wait_f = docking_costs(ends, pre, vf, rf, self.opts.departure_phases)
        base, _ = docking_costs(follower_ends(self.tl.poses[f], vf, rf, total, np.zeros(1), np.zeros(1)), pre, vf, rf,
                                self.opts.departure_phases)
        obst_s = self.obstacles([self.by_rank[j] for j in range(1, k - 1)], [self.by_rank[j] for j in range(k + 1, self.n + 1)])
        for c in np.argsort(cost, kind="stable")[: ps.checked]:
            if cost[c] > base[0] - ps.min_gain_s:
                break
            if self._preposition_clear(f, float(taus[c]), float(dts[c]), total, float(wait_f[c]), ends[c], pre, obst_s, obst_f, movers):
                self.notes.append(f"{self.lab(f)} drove {vf * dts[c]:.0f} um straight while {what} (P{k - 2})")
                return float(taus[c]), float(dts[c])
        return None

    def _preposition_clear(self, f: int, tau: float, dt: float, total: float, wait_f: float, end: np.ndarray, pre: np.ndarray,
                           obst_s: Obstacles, obst_f: Obstacles, movers: Sequence[tuple[int, pathlib.Path]]) -> bool:
        """Whether D_{k-1} (``f``) may drive straight from ``tau`` for ``dt`` s while the movers move."""
        opts = self.opts
        vf, rf, Lf, Wf = self.v[f], self.r[f], self.L[f], self.W[f]
        follower = pathlib.Path(Pose(*self.tl.poses[f]), rf, (("R", vf * tau), ("S", vf * dt), ("R", vf * (total - tau - dt))))
        if _path_hit(obst_s, pathlib.sub_path(follower, vf * tau, vf * (tau + dt)), Lf, Wf, opts) is not None:
            return False
        if _path_hit(obst_f, pathlib.Path(Pose(*end), rf, (("R", TWO_PI * rf),)), Lf, Wf, opts) is not None:
            return False
        for i, path in movers:
            t = np.append(np.arange(tau, total, opts.sample_um / max(vf, self.v[i])), total)
            depth = penetration_depth(follower.pose_at(vf * t), Lf, Wf, path.pose_at(self.v[i] * t), self.L[i], self.W[i])
            if (depth > -opts.clearance_um).any():
                return False
        src = advance(end[None, :], np.ones(1, bool), vf, rf, wait_f)[0]
        return _path_hit(obst_f, pathlib.shortest_path(src, pre, rf), Lf, Wf, opts) is None

    # -- G_1 (step 1) -------------------------------------------------------------------------------

    def _free_run(self, pose: np.ndarray, i: int, obst: Obstacles, limit_um: float, *, backwards: bool) -> float:
        """Longest straight run (um) of robot ``i`` from ``pose`` (ahead, or behind it) clear of ``obst``."""
        h = np.array([math.sin(pose[2]), math.cos(pose[2])]) * (-1.0 if backwards else 1.0)
        probe = np.arange(0.0, limit_um, self.opts.sample_um)
        line = np.column_stack([pose[0] + probe * h[0], pose[1] + probe * h[1], np.full(probe.size, pose[2])])
        blocked = obst.hits(line, self.L[i], self.W[i], self.opts.clearance_um)
        return float(probe[np.argmax(blocked)] - self.opts.sample_um) if blocked.any() else float(probe[-1])

    def form_pair(self) -> None:
        """Step 1: D_n and D_{n-1} form G_1 (see the module docstring for the scheme).

        First without D_n orbiting before its whole-period paths (those schedules are shorter); when
        that finds no schedule, again with it (:meth:`_orbit_first`): more layouts are plannable.
        """
        # Everything the G_1 search depends on besides the scenario, which all variants share: the
        # pair's slots and approach lengths, the options and the pass (each planner starts from the
        # same start poses and the same random stream), so an equal key fails the same way.
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        key = (tuple(np.round(self.goals[[N, M]], 9).ravel()), _approach(self.struct, self.scn.names[N], self.opts),
               _approach(self.struct, self.scn.names[M], self.opts), self.extended, self.opts)
        if key in self.search.pair_failures:
            raise NoRoute(self.search.pair_failures[key])
        try:
            self._form_pair_search()
        except NoRoute as exc:
            self.search.pair_failures[key] = exc.reason
            raise

    def _form_pair_search(self) -> None:
        self._orbit_first_on = False
        try:
            self._form_pair_once()
        except NoRoute:
            if self.opts.orbit_phases <= 0 or not self.extended or self.search.spent:
                raise
            self._orbit_first_on = True
            self._timed_cache.clear()
            self._form_pair_once()

    def _form_pair_once(self) -> None:
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        gN, gM = self.goals[N], self.goals[M]
        vN, vM, rN, rM = self.v[N], self.v[M], self.r[N], self.r[M]
        TM = TWO_PI * rM / vM
        lower = [self.by_rank[j] for j in range(1, n - 1)]
        obst_low = self.obstacles(lower, [])
        aM = _approach(self.struct, self.scn.names[M], self.opts)
        aN = _approach(self.struct, self.scn.names[N], self.opts)
        whoN, whoM = self.lab(N), self.lab(M)
        opts = self.opts
        approachM = self.approach_path(M, gM, aM, obst_low, whoM)
        preM = np.array(approachM.start, dtype=np.float64)

        # D_{n-1}'s route: it may leave its orbit at any phase (D_n's first stage lasts that long).
        m = opts.departure_phases
        waits = np.arange(m) * TM / m
        sourcesM = advance(np.repeat(self.tl.poses[M][None, :], m, axis=0), np.ones(m, bool), vM, rM, waits)

        # The final corridor: how far behind its slot D_n can run straight into it.
        span = 2.0 * max(self.scn.arena_um or (5000.0, 5000.0))
        d_free = self._free_run(gN, N, obst_low, span, backwards=True)
        if d_free < aN:
            raise NoRoute(f"{whoN}: its straight approach into its slot is blocked ({max(d_free, 0.0):.0f} um free behind it)")
        # Parking tracks for D_n's runs during the earlier pieces: the final corridor itself (its runs
        # stop short of the slot) and the free line ahead of D_n's start.
        # Candidate tracks start on D_n's start orbit (at quarter turns), so reaching them is cheap.
        parks: list = [None]
        obst_park = obst_low.with_disc(turning_centres(self.tl.poses[M], rM)[0], self.rstar[M], "M")
        quarter = np.arange(4) * 0.5 * math.pi * rN / vN
        on_orbit = advance(np.repeat(self.tl.poses[N][None, :], 4, axis=0), np.ones(4, bool), vN, rN, quarter)
        tracks = [(p, self._free_run(p, N, obst_park, span, backwards=False)) for p in on_orbit]
        tracks = sorted((t for t in tracks if t[1] > 2.0 * rN), key=lambda t: -t[1])
        parks.extend(tracks[:2] if opts.max_pieces > 1 else [])
        attempts: list[str] = []
        budget = [opts.pair_schedules]  # schedule attempts per G_1: bounds the planner's time on hopeless layouts
        one_piece = [False]  # schedule only the seed's one-piece scheme
        overlap_routes = [False]  # try overlapped schedules around the routes the roadmap finds
        self._overlap_sched: PairSchedule | None = None
        self._overlap_routes_tried = 0
        if opts.overlap_pair and self._overlap_first(N, M, sourcesM, waits, preM, approachM, obst_low):
            return

        def try_route(sidx: int, routeM: pathlib.Path) -> str | None:
            """Can D_n be scheduled around this route of D_{n-1}? Records the schedule when it can."""
            if overlap_routes[0] and self._overlap_route(N, M, routeM, approachM, float(waits[sidx]), obst_low):
                return None
            fullM = routeM.then(*approachM.segments)
            T = fullM.length / vM
            for park in parks[:1] if one_piece[0] else parks:
                for durs in self._park_cuts(N, M, fullM, T, d_free, park, obst_low, aM, float(waits[sidx])):
                    if one_piece[0] and len(durs) > 1:
                        break
                    if budget[0] <= 0 or self.search.spent:  # every further route would be vetoed: end the search
                        raise SearchSpent(attempts[-1] if attempts else "no schedule")
                    budget[0] -= 1
                    self.search.take()
                    why = self._schedule_pair(N, M, fullM, float(waits[sidx]), durs, park, lower)
                    if why is None:
                        return None
                    attempts.append(why)
            return attempts[-1] if attempts else f"{whoM}'s route is too long for {whoN}'s free corridor ({d_free:.0f} um)"

        self._pair_schedule = None
        self._approach_len = approachM.length
        best = self._best_direct_pair(sourcesM, preM, rM, M, obst_low, try_route) if opts.pair_candidates > 1 else None
        if opts.pair_candidates > 1 and (best is None or len(best[4]) > 1):
            # A detour of D_{n-1} that D_n's corridor covers in one piece is often faster than pieces.
            one_piece[0], budget[0] = True, opts.pair_schedules
            light = replace(opts, roadmap_nodes=opts.roadmap_nodes[:2])
            try:
                route(sourcesM, waits * vM, preM, rM, self.L[M], self.W[M], obst_low, light, self.rng, whoM, extra_check=try_route)
                if best is None or self._pair_duration(self._pair_schedule) < self._pair_duration(best):
                    best = self._pair_schedule
            except NoRoute:
                pass
            one_piece[0] = False
        if best is not None:
            self._pair_schedule = best
            self._run_pair_schedule()
            return
        budget[0] = opts.pair_schedules
        overlap_routes[0] = opts.overlap_pair
        try:
            route(sourcesM, waits * vM, preM, rM, self.L[M], self.W[M], obst_low, opts, self.rng, whoM, extra_check=try_route)
        except NoRoute as exc:
            reason = max(set(attempts), key=attempts.count) if attempts else exc.reason
            raise NoRoute(f"cannot form G_1 with {whoN} and {whoM}: {reason}") from None
        self._run_pair_schedule()

    # -- overlapped G_1 schedules (stressbots.overlap) ---------------------------------------------------

    def _overlap_first(self, N: int, M: int, sourcesM, waits, preM, approachM: pathlib.Path, obst_low: Obstacles) -> bool:
        """Form G_1 with the best overlapped schedule over D_{n-1}'s direct routes; False if there is none."""
        sched = self._overlap_best(N, M, sourcesM, waits, preM, approachM, obst_low)
        if sched is None:
            return False
        self._run_overlap(sched)
        return True

    def _overlap_route(self, N: int, M: int, routeM: pathlib.Path, approachM: pathlib.Path, wait0: float, obst_low: Obstacles) -> bool:
        """Whether an overlapped schedule fits this (roadmap) route of D_{n-1}; records it for :meth:`_run_pair_schedule`.

        Cheaper than for the direct routes: D_n's first path is not routed, and only the first
        ``overlap.roadmap_routes`` routes of a G_1 search are tried (then only the piece scheme).
        """
        self._overlap_routes_tried += 1
        if self._overlap_routes_tried > self.opts.overlap.roadmap_routes:
            return False
        self._overlap_sched = self._overlap_try(N, M, routeM, approachM, wait0, obst_low, route_first=False)
        return self._overlap_sched is not None

    def _overlap_try(self, N: int, M: int, routeM: pathlib.Path, approachM: pathlib.Path, wait0: float, obst_low: Obstacles,
                     not_after_s: float = math.inf, route_first: bool = True) -> PairSchedule | None:
        """An overlapped G_1 schedule around this route of D_{n-1} (leaving after ``wait0`` s), or None."""
        opts = self.opts
        LN, WN, LM, WM = self.L[N], self.W[N], self.L[M], self.W[M]
        vN, vM = self.v[N], self.v[M]

        def static_ok(path: pathlib.Path) -> bool:
            return not obst_low.hits(path.sample(opts.sample_um), LN, WN, opts.clearance_um).any()

        def poses_ok(poses: np.ndarray) -> np.ndarray:
            return ~obst_low.hits(poses, LN, WN, opts.clearance_um)

        def joint_ok(path_n: pathlib.Path, path_m: pathlib.Path) -> bool:
            T = path_m.length / vM
            dt = opts.sample_um / max(vN, vM)
            t = np.append(np.arange(0.0, T, dt), T)
            depth = penetration_depth(path_n.pose_at(vN * t), LN, WN, path_m.pose_at(vM * t), LM, WM)
            limit = np.where(t > T - (opts.approach_um + opts.clearance_um) / min(vN, vM), 0.5, -opts.clearance_um)
            return not (depth > limit).any()

        TM = TWO_PI * self.r[M] / vM
        orbit = TWO_PI * self.r[M]

        # D_n's first path: D_(n-1) orbits at its start all that time (its first arc is on that orbit too)
        obst0 = obst_low.with_disc(turning_centres(self.tl.poses[M], self.r[M])[0], self.rstar[M], f"the orbit of {self.lab(M)}")

        def first_ok(path: pathlib.Path) -> bool:
            coarse = path.sample(opts.overlap.coarse_um)
            return not obst0.hits(coarse, LN, WN, opts.clearance_um).any() and not obst0.hits(path.sample(opts.sample_um), LN, WN,
                                                                                               opts.clearance_um).any()

        def first_path(s1: np.ndarray, t0: float) -> pathlib.Path | None:
            got = self._timed_path(self.tl.poses[N], s1, vN, self.r[N], LN, WN, t0, TM, obst0)
            return None if isinstance(got, str) else got
        for count in range(opts.overlap.max_inserted_orbits + 1):
            for offset in opts.overlap.split_offsets if count else (0.0,):
                routed, at = with_orbits(routeM, count, offset)
                if count and not at:
                    continue
                if any(_path_hit(obst_low, pathlib.sub_path(routed, a, a + orbit), LM, WM, opts) for a in at):
                    continue  # D_(n-1)'s inserted orbit is blocked there
                sched = overlap_schedule(self.tl.poses[N], self.tl.poses[M], self.goals[N], routed, approachM, wait0, TM, vN,
                                         self.r[N], vM, self.r[M], static_ok, joint_ok, poses_ok, opts.overlap, not_after_s=not_after_s,
                                         first_path=first_path if route_first else None, first_ok=first_ok)
                if sched is not None:
                    return sched
                break  # the orbits fit: another offset would not help D_n more
        return None

    def _overlap_best(self, N: int, M: int, sourcesM, waits, preM, approachM: pathlib.Path, obst_low: Obstacles) -> PairSchedule | None:
        """The shortest overlapped schedule over D_{n-1}'s direct routes from its departure phases.

        Phases are tried by a lower bound on their schedule (the wait plus D_{n-1}'s route and approach),
        and a phase whose bound is not below the best schedule found is not searched.
        """
        vM, rM = self.v[M], self.r[M]
        lengths = pathlib.shortest_path_lengths(sourcesM, np.broadcast_to(preM, sourcesM.shape), rM)
        bound = waits + (lengths + approachM.length) / vM
        best: PairSchedule | None = None
        for s in np.argsort(bound, kind="stable"):
            if best is not None and bound[s] >= best.duration_s - 1e-9:
                break
            p = pathlib.shortest_path(sourcesM[s], preM, rM)
            if _path_hit(obst_low, p, self.L[M], self.W[M], self.opts) is not None:
                continue
            sched = self._overlap_try(N, M, p, approachM, float(waits[s]), obst_low,
                                      not_after_s=math.inf if best is None else best.duration_s - 1e-9)
            if sched is not None and (best is None or sched.duration_s < best.duration_s):
                best = sched
        return best

    def _run_overlap(self, sched: PairSchedule) -> None:
        """Apply an overlapped G_1 schedule to the timeline, one phase per piece of D_n's path."""
        n = self.n
        N, M = self.by_rank[n], self.by_rank[n - 1]
        vN, vM = self.v[N], self.v[M]
        last = max(t1 for _, t1, free in sched.pieces if not free)
        pre_f = None
        if self.opts.preposition and n >= 3:  # D_(n-2) drives straight while both drive straight (P_(n-3))
            steps = joint_primitives(sched.path_n, vN, sched.path_m, vM, n)
            pre_f = self._preposition(n - 1, steps, [(N, sched.path_n), (M, sched.path_m)], "G_1 formed")
        for t_a, t_b, free in sched.pieces:
            if t_b - t_a <= 0.0:
                continue
            pn = pathlib.sub_path(sched.path_n, vN * t_a, vN * t_b)
            pm = pathlib.sub_path(sched.path_m, vM * t_a, vM * t_b)
            t0 = self.tl.t
            steps = joint_primitives(pn, vN, pm, vM, n)
            if pre_f is not None and t_a - 1e-9 <= pre_f[0] and pre_f[0] + pre_f[1] <= t_b + 1e-9:
                steps = splice_straight(steps, n - 1, max(pre_f[0] - t_a, 0.0), pre_f[1])
            for k, d in steps:
                self.tl.apply(k, d, counts_for=(N,))
            if free:
                self.tl.phase("pair-A", N, n, n - 1, t0, pn.end, partner=M, partner_end=tuple(float(v) for v in self.tl.poses[M]),
                              path=pn.segments, path_start=tuple(float(v) for v in pn.start))
            else:
                self.tl.phase("pair-B", M, n - 1, n - 2, t0, pm.end, partner=N, run=(tuple(float(v) for v in pn.start), float(pn.length)),
                              last=t_b == last, path=pm.segments, path_start=tuple(float(v) for v in pm.start))
        self.route_lengths[N] = sched.path_n.length
        self.route_lengths[M] = sched.path_m.length - vM * sched.wait_s
        windows = sum(1 for _, _, free in sched.pieces[1:] if free)
        self.notes.append(
            f"G_1 overlapped: {self.lab(N)} turns while {self.lab(M)} turns ({windows} window(s) on its route), "
            f"runs straight only while it does; G_1 takes {sched.duration_s:.1f} s"
        )
        self.tl.dock(N, self.goals[N], self.lab(N))
        self.tl.dock(M, self.goals[M], self.lab(M))

    def _best_direct_pair(self, sourcesM, preM, rM, M, obst_low, try_route):
        """The shortest G_1 schedule over D_{n-1}'s direct routes from its departure phases, or None.

        ``route`` takes the first departure whose route can be scheduled, ordered by D_{n-1}'s own travel;
        but the pair's duration is set by D_n (its first path lasts a whole number of D_{n-1}'s periods
        and every extra piece adds a loop back), so up to ``pair_candidates`` schedulable departures are
        scheduled and the one that forms G_1 soonest is kept.
        """
        order = np.argsort(pathlib.shortest_path_lengths(sourcesM, np.broadcast_to(preM, sourcesM.shape), rM), kind="stable")
        found: list = []
        for s in order:
            if len(found) >= self.opts.pair_candidates:
                break
            p = pathlib.shortest_path(sourcesM[s], preM, rM)
            if _path_hit(obst_low, p, self.L[M], self.W[M], self.opts) is not None:
                continue
            self._pair_schedule = None
            try:
                ok = try_route(int(s), p) is None
            except SearchSpent:
                break
            if ok and self._pair_schedule is not None:
                found.append((self._pair_duration(self._pair_schedule), len(found), self._pair_schedule))
        self._pair_schedule = None
        return min(found)[2] if found else None

    def _park_cuts(self, N: int, M: int, fullM: pathlib.Path, T: float, d_free: float, park, obst_low: Obstacles,
                   aM: float, wait0: float):
        """The cut options (:meth:`_cut_options`) for parking track ``park`` after a wait of ``wait0`` s.

        A track that starts at D_n's own start is where D_n passes D_{n-1}'s wait, driving straight
        (:meth:`_schedule_pair`), so its runs start ``v_n wait0`` um further on. Pieces cut to the whole
        track run off its end when the track ends at the arena edge (where it ends at D_{n-1}'s orbit
        they can still pass). The extended search first tries the pieces that fit in the part left.
        """
        cuts = self._cut_options(N, M, fullM, T, d_free, park, obst_low, aM)
        if not self.extended or park is None or wait0 <= 0 or not np.allclose(np.asarray(park[0]), self.tl.poses[N]):
            yield from cuts
            return
        ahead = self.v[N] * wait0
        h = np.array([math.sin(park[0][2]), math.cos(park[0][2]), 0.0])
        left = (np.asarray(park[0], float) + ahead * h, max(park[1] - ahead, 0.0))
        seen: set = set()
        for durs in self._cut_options(N, M, fullM, T, d_free, left, obst_low, aM):
            seen.add(durs)
            yield durs
        yield from (durs for durs in cuts if durs not in seen)

    def _pair_duration(self, schedule) -> float:
        """Duration (s) of a G_1 schedule: D_n's timed paths plus D_{n-1}'s pieces."""
        N, _, _, _, durs, _, a_paths = schedule
        return float(sum(p.length for p in a_paths) / self.v[N] + sum(durs))

    def _run_starts(self, N: int, durs: Sequence[float], park) -> list[np.ndarray]:
        """Start pose of D_n's straight run in every piece: the parking track, the final corridor last."""
        gN = self.goals[N]
        final = _pre_approach(gN, self.v[N] * durs[-1])
        if park is None:
            return [final] * len(durs)
        return [np.asarray(park[0], float)] * (len(durs) - 1) + [final]

    def _orbits_clear(self, centres: np.ndarray, M: int, obst_low: Obstacles) -> np.ndarray:
        """``(K,)`` bool: whether D_{n-1} (index ``M``) orbiting about each of ``centres`` keeps the
        clearance from the lower robots' orbit discs and from the arena edge."""
        clearance = self.opts.clearance_um
        rr = self.rstar[M] + clearance
        ok = np.ones(len(centres), dtype=bool)
        if len(obst_low.disc_radii):
            gap = np.hypot(centres[:, None, 0] - obst_low.disc_centres[None, :, 0], centres[:, None, 1] - obst_low.disc_centres[None, :, 1])
            ok &= (gap - obst_low.disc_radii[None, :] - self.rstar[M] >= clearance).all(axis=1)
        if self.scn.arena_um is not None:
            w, h = self.scn.arena_um
            ok &= (centres[:, 0] >= rr) & (centres[:, 0] <= w - rr) & (centres[:, 1] >= rr) & (centres[:, 1] <= h - rr)
        return ok

    def _cut_options(self, N: int, M: int, fullM: pathlib.Path, T: float, d_free: float, park, obst_low: Obstacles, aM: float):
        """Ways to cut D_{n-1}'s route (duration ``T`` s) into pieces for the G_1 schedule.

        The last piece is D_n's run into its slot, so it lasts at most ``d_free / v_n``; the earlier
        pieces are runs on the parking track ``park`` (``(pose, free length)``, or None for the final
        corridor, where they may not be longer than the last). D_{n-1} must be able to orbit at every
        cut. Cut points are chosen greedily from the end, each as early as the piece limit allows, among
        the positions where D_{n-1}'s orbit clears the lower orbits, the arena and D_n's run corridors.
        """
        opts = self.opts
        vN, vM, rM = self.v[N], self.v[M], self.r[M]
        t_last_max = d_free / vN
        if park is None and T <= t_last_max + 1e-9:
            yield (T,)
        total = fullM.length
        pos = np.arange(0.0, total, 10.0)
        centres = turning_centres(fullM.pose_at(pos), rM)
        rr = self.rstar[M] + opts.clearance_um
        ok = self._orbits_clear(centres, M, obst_low)
        gN = self.goals[N]
        seen = set()
        # On the final corridor D_n loops back to its right and reaches about r + L/2 past the end of
        # its run: earlier runs may stop short of the slot by that much (away from D_{n-1}'s last stops).
        short = (self.r[N] + 0.5 * self.L[N] + self.W[N] + opts.clearance_um) / vN
        if park is None:
            variants = [(f, 0.0) for f in (1.0, 0.8, 0.62, 0.48, 0.36)] + [(f, short) for f in (1.0, 0.8, 0.62, 0.48)]
        else:
            # runs that stop short of the track's end leave D_n room to loop back (the end is an obstacle)
            variants = [(f, 0.0) for f in (1.0, 0.7, 0.45, 0.3)] + ([(f, short) for f in (1.0, 0.7, 0.45)] if self.extended else [])
        for frac, margin in variants:
            tm = min(t_last_max * frac, T)
            if tm < aM / vM or tm >= T - 1e-9:
                continue
            if park is None:
                t_piece = tm - margin
                keep = [(_pre_approach(gN, 0.5 * vN * tm), vN * tm)]
            else:
                t_piece = park[1] / vN - margin
                keep = [(_pre_approach(gN, 0.5 * vN * tm), vN * tm), (_pre_approach(np.asarray(park[0]), -0.5 * park[1]), park[1])]
            if t_piece <= 0.2 * tm or (T - tm) / t_piece > opts.max_pieces:
                continue
            good = ok.copy()
            for centre_pose, length in keep:
                good &= point_rectangle_distance(centres, centre_pose, length + self.L[N], self.W[N])[0] >= rr
            good[0] = True  # D_{n-1}'s departure point: it orbits there anyway
            cuts = [total - vM * tm]
            while cuts[-1] > 1e-9:
                lo = cuts[-1] - vM * t_piece
                cand = np.flatnonzero(good & (pos >= lo - 1e-9) & (pos < cuts[-1] - 1e-9))
                if len(cand) == 0 or len(cuts) > opts.max_pieces:
                    cuts = []
                    break
                cuts.append(float(pos[cand[0]]))
            if not cuts:
                continue
            k_last = int(np.searchsorted(pos, cuts[0] - 1e-9))
            if k_last < pos.size and not good[k_last]:
                continue
            bounds = [0.0] + sorted(c for c in cuts if c > 1e-9) + [total]
            durs = tuple((b - a) / vM for a, b in zip(bounds[:-1], bounds[1:], strict=False))
            if len(durs) > opts.max_pieces:
                continue
            key = tuple(round(x, 6) for x in durs)
            if key not in seen:
                seen.add(key)
                yield durs

    def _schedule_pair(self, N: int, M: int, fullM: pathlib.Path, wait0: float, durs: Sequence[float], park,
                       lower: list[int]) -> str | None:
        """Plan D_n around D_{n-1}'s route cut into pieces of durations ``durs`` (s); None on success.

        During piece j D_{n-1} drives its piece (P_{n-1}/P_{n-2}) while D_n runs straight from
        ``run_starts[j]``; the last run ends in D_n's slot as D_{n-1} reaches its own. Between pieces D_n
        drives (P_n/P_{n-1}) from the end of one run to the start of the next on a path lasting a whole
        number of D_{n-1}'s orbit periods, so D_{n-1}, orbiting, is back where it stopped.
        """
        opts = self.opts
        vN, vM, rN, rM = self.v[N], self.v[M], self.r[N], self.r[M]
        LN, WN, LM, WM = self.L[N], self.W[N], self.L[M], self.W[M]
        TM = TWO_PI * rM / vM
        pieces = len(durs)
        straight_first = 0.0
        here = self.tl.poses[N]
        if park is not None and wait0 > 0 and np.allclose(np.asarray(park[0]), here):
            # Parked at its own start: D_n passes D_{n-1}'s wait for its departure driving straight along
            # its track (P_{n-1}: D_{n-1} orbits) instead of killing time on a loop.
            straight_first = vN * wait0
            if straight_first >= park[1] - 2.0 * rN:
                return f"{self.lab(N)}'s parking track is too short to wait {wait0:.1f} s on it"
            hN = np.array([math.sin(here[2]), math.cos(here[2]), 0.0])
            park = (np.asarray(park[0]) + straight_first * hN, park[1] - straight_first)
        starts = self._run_starts(N, durs, park)
        runs = [pathlib.Path(Pose(*s0), rN, (("S", vN * t),)) for s0, t in zip(starts, durs, strict=False)]
        whoN, whoM = self.lab(N), self.lab(M)
        obst_low = self.obstacles(lower, [])
        bounds_t = np.concatenate([[0.0], np.cumsum(durs)])
        cuts = [fullM.pose_at(vM * bounds_t[j]) for j in range(1, pieces)]
        # 1. Runs clear of the lower orbits and the arena.
        for j, run in enumerate(runs):
            hit = obst_low.first_hit(run.sample(opts.sample_um), LN, WN, opts.clearance_um)
            if hit is not None:
                return f"{whoN}'s straight run {j + 1} is blocked by {hit}"
        # 2. B phases: D_n's run against D_{n-1}'s piece, sampled in time (touching only at the very end).
        dt = opts.sample_um / max(vN, vM)
        for j in range(pieces):
            tp = durs[j]
            t = np.minimum(np.arange(0.0, tp + dt, dt), tp)
            pn = runs[j].pose_at(vN * t)
            pm = fullM.pose_at(np.minimum(vM * (bounds_t[j] + t), fullM.length))
            depth = penetration_depth(pn, LN, WN, pm, LM, WM)
            final = j == pieces - 1
            limit = np.where(final & (t > tp - (opts.approach_um + opts.clearance_um) / min(vN, vM)), 0.5, -opts.clearance_um)
            if (depth > limit).any():
                return f"{whoN}'s straight run meets {whoM} (piece {j + 1} of {pieces})"
        # 3. A phases: D_n's paths lasting a whole number of D_{n-1}'s periods; D_{n-1} orbits meanwhile.
        obst0 = obst_low.with_disc(turning_centres(self.tl.poses[M], rM)[0], self.rstar[M], f"the orbit of {whoM}")
        first: pathlib.Path | str
        if straight_first > 0.0:
            run = pathlib.Path(Pose(*here), rN, (("S", straight_first),))
            hit = obst0.first_hit(run.sample(opts.sample_um), LN, WN, opts.clearance_um)
            first = run if hit is None else f"blocked by {hit}"
        else:
            first = self._timed_path(self.tl.poses[N], starts[0], vN, rN, LN, WN, wait0, TM, obst0)
        if isinstance(first, str):
            return f"{whoN} cannot reach the start of its first run ({first})"
        a_paths = [first]
        for j, c in enumerate(cuts):
            disc_c = turning_centres(np.array(c), rM)[0]
            ob = obst_low.with_disc(disc_c, self.rstar[M], f"the orbit of {whoM} at its stop {j + 1}")
            end_j = np.array(runs[j].end)
            same_track = np.allclose(starts[j], starts[j + 1])
            link = self._timed_path(end_j, starts[j + 1], vN, rN, LN, WN, 0.0, TM, ob)
            if isinstance(link, str):
                what = "loop back to its run" if same_track else "move to its final corridor"
                return f"{whoN} cannot {what} ({link})"
            a_paths.append(link)
        self._pair_schedule = (N, M, fullM, wait0, tuple(durs), runs, a_paths)
        return None

    def _timed_path(self, start, goal, v, r, L, W, wait0, period, obst, *, use_route: bool = True) -> pathlib.Path | str:
        """A collision-free path of duration ``wait0 + k * period`` (k >= 0 whole) from start to goal.

        Tries the direct paths of those lengths first; with ``route`` it then routes around the
        obstacles and stretches the route to an exact length. Returns the path or the reason it failed.
        """
        start = np.asarray(start, float)
        goal = np.asarray(goal, float)
        key = (tuple(np.round(start, 4)), tuple(np.round(goal, 4)), round(wait0, 6),
               tuple(np.round(obst.disc_centres, 3).ravel()), use_route)
        if key not in self._timed_cache:
            self._timed_cache[key] = self._timed_path_uncached(start, goal, v, r, L, W, wait0, period, obst, use_route)
        return self._timed_cache[key]

    def _timed_path_uncached(self, start, goal, v, r, L, W, wait0, period, obst, use_route) -> pathlib.Path | str:
        base = pathlib.shortest_path(start, goal, r)
        kmin = max(0, math.ceil((base.length / v - wait0) / period - 1e-9))
        wants = [v * (wait0 + k * period) for k in range(kmin, kmin + 4)]
        last = "no path of a fitting length"
        for want in wants:
            try:
                p = pathlib.path_of_length(start, goal, r, want)
            except pathlib.InfeasibleLengthError:
                continue
            hit = _path_hit(obst, p, L, W, self.opts)
            if hit is None:
                return p
            last = f"blocked by {hit}"
        if not use_route:
            return self._orbit_first(start, goal, v, r, L, W, wait0, period, obst) or last
        # Route around the obstacles once, then stretch the route's tail to an exact length.
        rkey = (tuple(np.round(start, 4)), tuple(np.round(goal, 4)), tuple(np.round(obst.disc_centres, 3).ravel()))
        if rkey not in self._route_cache:
            try:
                # D_n's timed legs are local manoeuvres: small roadmaps, or the G_1 search gets slow
                light = replace(self.opts, roadmap_nodes=self.opts.roadmap_nodes[:2])
                _, path, way = route(start[None, :], np.zeros(1), goal, r, L, W, obst, light, self.rng, "")
                self._route_cache[rkey] = (path, (start,) + tuple(way))
            except NoRoute as exc:
                self._route_cache[rkey] = exc.reason.lstrip(": ") or last
        cached = self._route_cache[rkey]
        if not isinstance(cached, str):
            routed, nodes = cached
            for want in wants + [v * (wait0 + k * period) for k in range(kmin + 4, kmin + 8)]:
                if routed.length > want + 1e-9:
                    continue
                stretched = self._stretch(routed, want, obst, L, W)
                if stretched is None and self.extended:
                    stretched = self._stretch_leg(nodes, r, want, obst, L, W)
                if stretched is not None:
                    return stretched
        # last resort: spend part of the time on its own orbit, then leave at a phase that clears
        return self._orbit_first(start, goal, v, r, L, W, wait0, period, obst) or (cached if isinstance(cached, str) else last)

    def _orbit_first(self, start, goal, v, r, L, W, wait0, period, obst) -> pathlib.Path | None:
        """A path of duration ``wait0 + k * period`` that first orbits at ``start`` for a while.

        The mover turns under the same primitive that keeps its partner orbiting, so it can spend part
        of the time on its own orbit and leave it at the phase from which a path of the remaining length
        is clear: :attr:`PlannerOptions.orbit_phases` phases of one orbit, the four shortest k each.
        """
        m = self.opts.orbit_phases
        if m <= 0 or not self._orbit_first_on:
            return None
        own = 2.0 * math.pi * r / v
        taus = (np.arange(1, m) / m) * own
        ring = advance(np.repeat(np.asarray(start, float)[None, :], len(taus), axis=0), np.ones(len(taus), bool), v, r, taus)
        base = pathlib.shortest_path_lengths(ring, np.broadcast_to(goal, ring.shape), r)
        cands: list = []
        for j, tau in enumerate(taus):
            kmin = max(0, math.ceil((tau + base[j] / v - wait0) / period - 1e-9))
            cands.extend((wait0 + k * period, j) for k in range(kmin, kmin + 3))
        for total, j in sorted(cands):
            want = v * (total - taus[j])
            try:
                p = pathlib.path_of_length(ring[j], goal, r, want)
            except pathlib.InfeasibleLengthError:
                continue
            full = pathlib.Path(Pose(*(float(x) for x in start)), r, (("R", v * taus[j]),) + p.segments)
            if _path_hit(obst, full, L, W, self.opts) is None:
                return full
        return None

    def _stretch_leg(self, nodes, r: float, want: float, obst, L, W) -> pathlib.Path | None:
        """Lengthen a route through ``nodes`` (start, waypoints, goal) to ``want`` um in one of its legs.

        The tail stretch (:meth:`_stretch`) replaces everything after a node, so it cuts across the
        obstacles the route went around; here every other leg stays a shortest path and the one leg
        that gets the extra length is chosen, longest first (most room to bend).
        """
        legs = [pathlib.shortest_path(a, b, r) for a, b in zip(nodes[:-1], nodes[1:], strict=False)]
        extra = want - sum(p.length for p in legs)
        if extra < -1e-9:
            return None
        for j in sorted(range(len(legs)), key=lambda q: -legs[q].length):
            try:
                leg = pathlib.path_of_length(nodes[j], nodes[j + 1], r, legs[j].length + extra)
            except pathlib.InfeasibleLengthError:
                continue
            if _path_hit(obst, leg, L, W, self.opts) is None:
                segs = tuple(sg for q, p in enumerate(legs) for sg in (leg.segments if q == j else p.segments))
                return pathlib.Path(Pose(*(float(x) for x in nodes[0])), r, segs)
        return None

    def _stretch(self, path: pathlib.Path, want: float, obst, L, W) -> pathlib.Path | None:
        """Lengthen a route to exactly ``want`` um by replacing its tail with a path of a set length."""
        nodes = path.nodes
        segs = path.segments
        for cut in range(len(segs) - 1, -1, -1):
            head = pathlib.Path(path.start, path.radius, segs[:cut])
            need = want - head.length
            try:
                tail = pathlib.path_of_length(nodes[cut], nodes[-1], path.radius, need)
            except pathlib.InfeasibleLengthError:
                continue
            if _path_hit(obst, tail, L, W, self.opts) is None:
                return pathlib.Path(path.start, path.radius, segs[:cut] + tail.segments)
        return None

    def _run_pair_schedule(self) -> None:
        if self._overlap_sched is not None:  # the search accepted an overlapped schedule around a roadmap route
            self._run_overlap(self._overlap_sched)
            return
        assert self._pair_schedule is not None  # set by form_pair's successful search
        N, M, fullM, wait0, durs, runs, a_paths = self._pair_schedule
        n = self.n
        vM, vN = self.v[M], self.v[N]
        pieces = len(durs)
        bounds = np.concatenate([[0.0], np.cumsum(durs)]) * vM
        # A_0: D_n drives to the start of its first run (P_n / P_{n-1}); D_{n-1} orbits to its departure phase.
        t0 = self.tl.t
        self.tl.apply_path(N, a_paths[0], n, n - 1)
        self.tl.phase("pair-A", N, n, n - 1, t0, a_paths[0].end, partner=M, partner_end=tuple(float(v) for v in self.tl.poses[M]),
                      path=a_paths[0].segments, path_start=tuple(float(v) for v in a_paths[0].start))
        for j in range(pieces):
            # B_j: D_{n-1} drives its piece (P_{n-1} / P_{n-2}); D_n drives straight.
            piece = pathlib.sub_path(fullM, bounds[j], bounds[j + 1])
            before = self.tl.travel[N]
            t0 = self.tl.t
            self.tl.apply_path(M, piece, n - 1, n - 2)
            self.tl.phase(
                "pair-B", M, n - 1, n - 2, t0, piece.end, partner=N,
                run=(tuple(float(v) for v in runs[j].start), float(runs[j].length)), last=j + 1 == pieces, path=piece.segments,
                path_start=tuple(float(v) for v in piece.start),
            )
            self.tl.travel[N] = before + vN * durs[j]
            if j + 1 < pieces:
                t0 = self.tl.t
                self.tl.apply_path(N, a_paths[j + 1], n, n - 1)
                self.tl.phase("pair-A", N, n, n - 1, t0, a_paths[j + 1].end, partner=M,
                              partner_end=tuple(float(v) for v in self.tl.poses[M]), path=a_paths[j + 1].segments,
                              path_start=tuple(float(v) for v in a_paths[j + 1].start))
        self.route_lengths[M] = fullM.length
        self.route_lengths[N] = sum(p.length for p in a_paths) + vN * sum(durs)
        if pieces > 1:
            parked = not np.allclose(runs[0].start, runs[-1].start)
            self.notes.append(
                f"G_1: {self.lab(M)}'s route was cut into {pieces} pieces; {self.lab(N)} ran "
                f"{'on a parking track, then ' if parked else ''}a final corridor of {runs[-1].length:.0f} um "
                f"(the paper's two-stage scheme would need {vN * sum(durs):.0f} um)"
            )
        self.tl.dock(N, self.goals[N], self.lab(N))
        self.tl.dock(M, self.goals[M], self.lab(M))


def _plan_primitives(analysis: ControlAnalysis) -> tuple[PlanPrimitive, ...]:
    return tuple(PlanPrimitive(p.name, tuple(p.turning)) for p in analysis.primitives)


def _plan_structure(scn, analysis: ControlAnalysis, st: Structure, lb: float, candidates: int, opts: PlannerOptions, say,
                    extended: bool = False, search: _Search | None = None) -> PlanResult | str:
    """Plan the assembly of one candidate structure: the replayed result, or why it failed."""
    t0 = time.perf_counter()
    planner = _Planner(scn, analysis, st, opts, extended=extended, search=search)
    try:
        for k in planner.search.bottlenecks:  # fail fast where an earlier variant failed to dock
            planner.dock_check(k)
        say(f"forming G_1 ({planner.lab(planner.by_rank[scn.n])}, {planner.lab(planner.by_rank[scn.n - 1])})")
        planner.form_pair()
    except NoRoute as exc:
        return exc.reason
    try:
        for k in range(scn.n - 2, 0, -1):
            say(f"docking {planner.lab(planner.by_rank[k])}")
            planner.dock_single(k)
    except NoRoute as exc:
        planner.search.docking_failed.add(id(st))
        if k not in planner.search.bottlenecks:
            planner.search.bottlenecks.append(k)
        return exc.reason
    steps = merge_steps(planner.tl.steps, min_duration_s=1e-12)
    from .outputs import provenance

    plan = Plan(
        robots=scn.names,
        primitives=_plan_primitives(analysis),
        steps=steps,
        goals={nm: Pose(*st.goal_poses([nm])[0]) for nm in scn.names},
        provenance=provenance(opts.seed),
    )
    accessible = {frozenset(p.turning) for p in analysis.primitives}
    rep = replay(plan, scn, accessible_turning=accessible)
    if not rep.ok:
        return "internal: the plan failed its replay: " + "; ".join(rep.problems[:3])
    duration = plan.duration_s
    summary = {
        "structure": st.shape,
        "variant": st.variant,
        "order": list(analysis.order or ()),
        "duration_s": duration,
        "steps": len(steps),
        "route_length_um": {scn.names[i]: float(planner.route_lengths[i]) for i in range(scn.n)},
        "lower_bound_s": lb,
        "efficiency": lb / duration if duration > 0 else 1.0,
        "planning_time_s": time.perf_counter() - t0,
        "candidates": candidates,
        "notes": planner.notes,
    }
    return PlanResult(plan, st, analysis, rep, summary, tuple(planner.notes), tuple(planner.tl.phases))


def plan_assembly(scenario, options: PlannerOptions | None = None, *, progress: Callable[[str], None] | None = None) -> PlanResult:
    """Plan the assembly of ``scenario``'s target structure from its start poses.

    Returns a :class:`PlanResult` whose plan has passed :func:`stressbots.replay.replay`. Raises
    :class:`~stressbots.errors.PlanningError` naming what blocks the assembly when no plan is found.
    """
    opts = options or PlannerOptions()
    say = progress or (lambda _msg: None)
    scn = scenario
    if scn.n < 2:
        raise PlanningError("a structure needs at least 2 robots (G_1 is a pair)", source=scn.source)
    _ = scn.starts  # raises a ScenarioError naming a robot without a start
    analysis = analyse_scenario(scn)
    if not analysis.is_string:
        raise PlanningError(
            "the voltage design is not STRING, so primitives P_0..P_n do not exist: " + "; ".join(analysis.reasons),
            source=scn.source,
        )
    order = analysis.order_index
    assert order is not None  # STRING, checked above
    robots_in_order = [scn.robots[i] for i in order]
    structures = target_structures(robots_in_order, scn.structure)
    rank = np.empty(scn.n, dtype=int)
    for k, i in enumerate(order):
        rank[i] = k + 1
    # Cheapest candidates first (by the lower bound); skip those the starts rule out.
    scored: list = []
    first_reason = None
    for st in structures:
        why = _prechecks(scn, st, rank)
        if why is not None:
            first_reason = first_reason or why
            continue
        scored.append((lower_bound_s(scn, st, rank), len(scored), st))
    if not scored:
        raise PlanningError(first_reason or "no structure fits", source=scn.source)
    scored.sort(key=lambda x: (x[0], x[1]))
    failures: list[str] = []
    t_start = time.perf_counter()
    search = _Search(opts.search_budget)
    best = _best_variant(scn, analysis, scored, len(structures), opts, say, failures, t_start, extended=False, search=search)
    standard = len(failures)
    if best is None and opts.extended_search and not search.spent:
        best = _best_variant(scn, analysis, scored, len(structures), opts, say, failures, t_start, extended=True, search=search)
    if best is not None:
        return best
    # the extended search's reasons, when it ran: what still blocks after the wider search
    last = failures[standard:] or failures
    reason = max(set(last), key=last.count) if last else "no plan found"
    if search.spent:
        reason += f" (search budget of {opts.search_budget} G_1 schedules spent: a larger PlannerOptions.search_budget searches longer)"
    raise PlanningError(reason + advice(reason), source=scn.source)


def _best_variant(scn, analysis, scored, candidates: int, opts: PlannerOptions, say, failures: list[str], t_start: float, *,
                  extended: bool, search: _Search) -> PlanResult | None:
    """The shortest plan over up to ``variants_compared`` plannable variants (cheapest bound first).

    ``extended`` turns on the wider G_1 search (one-leg stretch, orbit first); plan_assembly uses it
    only when no variant is plannable without it, so layouts the standard search solves keep its plans.
    """
    best: PlanResult | None = None
    tried = 0
    for attempt, (lb, _, st) in enumerate(scored):
        if best is None and opts.max_candidates is not None and attempt >= opts.max_candidates:
            failures.append(f"no plan within the first {opts.max_candidates} candidate structures")
            break
        if best is not None and (tried + 1 >= opts.variants_compared or lb >= best.summary["duration_s"]):
            break
        if best is None and search.spent:
            break
        if extended and id(st) in search.docking_failed:
            continue  # it formed G_1 and failed later: a wider G_1 search cannot help
        if best is None and failures and time.perf_counter() - t_start > opts.time_budget_s:
            failures.append(f"no plan within the time budget of {opts.time_budget_s:g} s")
            break
        tried += best is not None
        # Variants compared after a plan exists get a lighter search (no largest roadmap, no second G_1
        # pass): they only replace the plan when they are easy, and hard ones would dominate the time.
        light = opts if best is None else replace(opts, roadmap_nodes=opts.roadmap_nodes[:2], orbit_phases=0)
        result = _plan_structure(scn, analysis, st, lb, candidates, light, say, extended, search)
        if isinstance(result, str):
            failures.append(result)
            continue
        if best is None or result.summary["duration_s"] < best.summary["duration_s"] - 1e-9:
            best = result
    return best


_ADVICE = (
    (re.compile(r"the orbit of (D\d+ \('[^']*'\))"), "move the start of {0} (its orbit disc is in the way) or enlarge the arena"),
    (re.compile(r"too long for (D\d+ \('[^']*'\))'s free corridor"),
     "start the G_1 robots closer to their slots, or clear the line behind {0}'s slot"),
    (re.compile(r"the arena edge"), "enlarge the arena or move the structure (or the starts) away from its edge"),
    (re.compile(r"the docked body of (D\d+ \('[^']*'\))|approach into its slot is blocked"),
     "change the structure (a slot whose approach is clear of the robots docked before it)"),
    (re.compile(r"meets (D\d+ \('[^']*'\))"), "move the start of {0} away from its partner's straight runs"),
)


def advice(reason: str) -> str:
    """What would make a layout plannable, from the failure ``reason`` (``"; to make it plannable: ..."``).

    The reason names the robot and the obstacle; the advice names the change (move that start, enlarge
    the arena, change the structure). The first matching obstacle kind wins; empty when none matches.
    """
    for pattern, text in _ADVICE:
        m = pattern.search(reason)
        if m:
            return "; to make it plannable: " + text.format(*m.groups())
    return ""
