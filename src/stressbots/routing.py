"""Route search for one robot around static obstacles (seed App. 2's collision-free routes).

:class:`Obstacles` (orbit discs, docked bodies, the arena) and :func:`route`: direct shortest one-way
paths from each source first, then lazily checked roadmaps of waypoint poses (random, and tangent to
rings around the orbit discs). Public with :class:`NoRoute`: the planner and the closed-loop
controller (:mod:`stressbots.control`) both route with it.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra as csgraph_dijkstra

from . import paths as pathlib
from .collision import bodies_hit_discs, outside_arena, penetration_depth, point_rectangle_distance_rows
from .kinematics import move
from .planner_options import PlannerOptions
from .robots import TWO_PI, Pose


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


class _MaskRows(NamedTuple):
    """A segment mask ``(E, S, K)`` as the sorted obstacle indices per segment (:func:`_mask_rows`)."""

    nseg: int
    obj: np.ndarray  # obstacle indices, grouped by flat segment e * S + s
    per_segment: np.ndarray  # obstacles per flat segment
    first: np.ndarray  # offset of each flat segment's group in ``obj``


def _mask_rows(mask: np.ndarray) -> _MaskRows:
    """Group a segment mask ``(E, S, K)`` by segment, once for all the sampling passes of one check."""
    e, nseg, k = mask.shape
    fseg, obj = np.nonzero(mask.reshape(e * nseg, k))  # sorted by segment
    count = np.bincount(fseg, minlength=e * nseg)
    return _MaskRows(nseg, obj, count, np.concatenate([[0], np.cumsum(count)[:-1]]))


def _sample_pairs(rows: _MaskRows | np.ndarray, e_of: np.ndarray, seg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Expand a segment mask ``(E, S, K)`` (or its :func:`_mask_rows`) to the ``(sample, obstacle)`` pairs of
    samples on segment ``(e_of[m], seg[m])``, without a ``(samples, K)`` array (most segments reach one
    obstacle or none)."""
    if not isinstance(rows, _MaskRows):
        rows = _mask_rows(rows)
    fs = e_of * rows.nseg + seg
    rep = rows.per_segment[fs]
    si = np.repeat(np.arange(len(fs)), rep)
    j = np.arange(si.size) - np.repeat(np.cumsum(rep) - rep, rep)
    return si, rows.obj[rows.first[fs][si] + j]


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


def path_hit(obst: Obstacles, path: pathlib.Path, length: float, width: float, opts: PlannerOptions) -> str | None:
    return obst.first_hit(path.sample(opts.sample_um), length, width, opts.clearance_um)


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
    curv, joints = _segment_joints(starts, seg_lengths, words, radius)
    owner, index, seg, local = _sample_positions(seg_lengths, step_um, keep)
    if part[1] > 1:
        pick = index % part[1] == part[0]
        owner, seg, local = owner[pick], seg[pick], local[pick]
    poses = move(joints[owner, seg], local, curv[owner, seg])
    return poses, owner, seg


def _sample_positions(seg_lengths: np.ndarray, step_um: float, keep: np.ndarray | None = None) -> tuple[np.ndarray, ...]:
    """Where :func:`_batch_samples` samples paths of segments ``seg_lengths`` ``(E, S)``: per sample its path,
    its index along the path, its segment and its arc length (um) from that segment's start.

    Samples are equally spaced (at most ``step_um``) along each path, both ends included; ``keep``
    (``(E, S)`` bool) drops the samples of the segments it marks False. The poses follow by one
    :func:`~stressbots.kinematics.move` from the segment joints, for any subset of the samples.
    """
    cand = _sample_candidates(seg_lengths, step_um, keep)
    kept, owner, seg, local = _place_samples(cand, np.arange(len(cand.owner)))
    return owner, cand.position[kept], seg, local


class _SampleCandidates(NamedTuple):
    """The samples of :func:`_sample_positions` before they are placed on their segments: per candidate
    its path and index along it (``position``), and the segment it must fall in (``wanted``; None: any)."""

    owner: np.ndarray
    position: np.ndarray  # sample index along its path
    wanted: np.ndarray | None
    counts: np.ndarray  # samples per path
    cum: np.ndarray  # (E, S) arc length at each segment's start
    total: np.ndarray  # (E,) path lengths


def _sample_candidates(seg_lengths: np.ndarray, step_um: float, keep: np.ndarray | None) -> _SampleCandidates:
    e, _ = seg_lengths.shape
    total = seg_lengths.sum(axis=1)
    counts = np.maximum(2, np.ceil(total / step_um).astype(int) + 1)
    cum = np.concatenate([np.zeros((e, 1)), np.cumsum(seg_lengths, axis=1)[:, :-1]], axis=1)  # (E, S)
    if keep is None:
        owner = np.repeat(np.arange(e), counts)
        offsets = np.concatenate([[0], np.cumsum(counts)[:-1]])
        return _SampleCandidates(owner, np.arange(owner.size) - offsets[owner], None, counts, cum, total)
    owner, index, wanted = _kept_indices(keep, counts, cum, total)
    return _SampleCandidates(owner, index, wanted, counts, cum, total)


def _place_samples(cand: _SampleCandidates, pick: np.ndarray) -> tuple[np.ndarray, ...]:
    """Place the candidates ``pick`` (indices) on their segments, dropping those outside their wanted
    segment: ``(kept, path, segment, local)``, the kept candidates' indices, paths, segments and arc
    lengths (um) from their segment's start. Placing a subset gives the same values as placing all."""
    owner, index = cand.owner[pick], cand.position[pick]
    s = index / (cand.counts[owner] - 1) * cand.total[owner]
    seg = np.sum(s[:, None] >= cand.cum[owner] - 1e-12, axis=1) - 1
    seg = np.clip(seg, 0, cand.cum.shape[1] - 1)
    if cand.wanted is not None:
        sel = seg == cand.wanted[pick]
        pick, owner, seg, s = pick[sel], owner[sel], seg[sel], s[sel]
    return pick, owner, seg, s - cand.cum[owner, seg]


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
_PASS_ORDER = (-1, 0, 2, 1, 3)  # the ends (-1), then coarse to fine: each pass halves the spacing
_END_FIRST_UM = 200.0  # samples this close to an edge's ends are tested first: a cramped source or target blocks there


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
        if len(live) == 0:
            return out
        e = idx[live]
        # the candidate samples once; each pass places, moves to and tests only its share of the live edges' samples
        cand = _sample_candidates(seg[e], step, keep=any_near[live])
        joints_e, curv_e = joints[e], curv[e]
        disc_rows, box_rows = _mask_rows(near.discs), _mask_rows(near.boxes)
        pass_of = cand.position % _SAMPLE_PASSES
        spacing = cand.total / np.maximum(cand.counts - 1, 1)  # (E,) um between samples
        near_end = np.ceil(_END_FIRST_UM / np.maximum(spacing, 1e-9))[cand.owner]
        pass_of[(cand.position < near_end) | (cand.position > cand.counts[cand.owner] - 1 - near_end)] = -1
        alive = np.ones(len(live), dtype=bool)
        for q in _PASS_ORDER:  # ends first, then interleaved passes: an edge found blocked is not sampled further
            _, o, sg, local = _place_samples(cand, np.flatnonzero((pass_of == q) & alive[cand.owner]))
            if len(o) == 0:
                continue
            poses = move(joints_e[o, sg], local, curv_e[o, sg])
            e_of = live[o]
            cand_pairs = NearPairs(_sample_pairs(disc_rows, e_of, sg), _sample_pairs(box_rows, e_of, sg), near.arena[e_of, sg])
            bad = obst.hits(poses, length, width, clearance, near=cand_pairs)
            alive[o[bad]] = False
            if not alive.any():
                break
        out[live[~alive]] = True
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
    reasons: list[str] = []
    vetoes: list[str] = []  # reasons extra_check gave for collision-free routes
    direct = _direct_route(sources, source_costs, index_of, target, radius, length, width, obst, opts, rng, extra_check, reasons, vetoes)
    if direct is not None:
        return direct
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
        common = max(dict.fromkeys(vetoes), key=vetoes.count)
        raise NoRoute(f"{who}: no usable route found ({common})")
    common = max(dict.fromkeys(reasons), key=reasons.count) if reasons else "obstacles"
    raise NoRoute(f"{who}: no collision-free route found (the direct path is blocked by {common})")


def _direct_route(sources: np.ndarray, source_costs: np.ndarray, index_of: np.ndarray, target: np.ndarray, radius: float,
                  length: float, width: float, obst: Obstacles, opts: PlannerOptions, rng: np.random.Generator,
                  extra_check: Callable[[int, pathlib.Path], str | None] | None, reasons: list[str],
                  vetoes: list[str]) -> tuple[int, pathlib.Path, tuple[np.ndarray, ...]] | None:
    """The cheapest clear direct shortest path of :func:`route` (source index in the caller's numbering,
    path, ``(target,)``), or None; the obstacles and vetoes met are appended to ``reasons``/``vetoes``."""
    direct = pathlib.shortest_path_lengths(sources, np.broadcast_to(target, sources.shape), radius) + source_costs
    for s in np.argsort(direct, kind="stable"):
        p = pathlib.shortest_path(sources[s], target, radius)
        hit = path_hit(obst, p, length, width, opts)
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
    return None


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


def _star_edges(pairs: np.ndarray, bad: np.ndarray, ns: int, stars: list[int]) -> np.ndarray:
    """Edges to check at once after the route's ``bad`` edges were found blocked (mask over ``pairs``).

    Blocked first or last legs mean the start or the approach is cramped: after :data:`_STAR_AFTER`
    such rounds (counted in ``stars``: last legs, first legs) every edge leaving a source or entering
    the target (node ``ns``) is checked, instead of one per round.
    """
    star = np.zeros(len(pairs), dtype=bool)
    if (pairs[bad, 1] == ns).any():
        stars[0] += 1
        if stars[0] >= _STAR_AFTER:
            star |= pairs[:, 1] == ns
    if (pairs[bad, 0] < ns).any():
        stars[1] += 1
        if stars[1] >= _STAR_AFTER:
            star |= pairs[:, 0] < ns
    return star


def _chain_path(nodes: np.ndarray, seq: Sequence[int], radius: float) -> pathlib.Path:
    """The path through roadmap nodes ``seq``: shortest one-way paths between consecutive nodes."""
    segs: list = []
    for a, b in zip(seq[:-1], seq[1:], strict=False):
        segs.extend(pathlib.shortest_path(nodes[a], nodes[b], radius).segments)
    return pathlib.Path(Pose(*nodes[seq[0]]), radius, tuple(segs))


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
    rounds = vetoed = 0
    stars = [0, 0]  # rounds with a blocked last leg, with a blocked first leg
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
                star = _star_edges(pairs, bad, ns, stars) & (state == 0)
                if star.any():
                    check(np.flatnonzero(star))
                continue
        path = _chain_path(nodes, seq, radius)
        why = veto(seq[0], path) if veto is not None else None
        if why is None:
            return seq[0], path, tuple(nodes[q].copy() for q in seq[1:])
        reasons.append(why)
        vetoes.append(why)
        state[on[0]] = -1  # forbid this route's first leg and look for another
        vetoed += 1
    return None
