"""Prefixed shortest paths: a turn and a straight first, then the shortest path to the target.

Gross motion sigma_1 re-plans a robot's shortest one-way path (:func:`stressbots.paths.shortest_path`) every
t_x. Near the structure, the arena edge or a waiting orbit that path is often blocked where a slightly
different one is not: the shortest path's first clockwise turn sweeps into the structure beside the robot,
while driving on a little first (or turning a little first) leaves room for it. A one-way robot's paths
from a pose form a small family: any turn ``phi`` (clockwise, 0 to a full loop), then any straight ``s``, then
the shortest path from there. :func:`prefixed_paths` lists that family on a grid, shortest first; the
controller drives the first clear one instead of a random roadmap route (which wandered for 5-9 mm and
drove robots into dead ends beside the structure), re-planning every t_x as before.

Pure functions of poses (um, rad); the obstacle check is the caller's.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator

import numpy as np

from .. import paths as pathlib
from ..kinematics import move, sample_arclengths
from ..robots import Pose

__all__ = ["describe_prefix", "first_clear", "prefixed_paths", "remaining_prefix"]


def prefixed_paths(start, target, radius_um: float, *, turn_step_deg: float = 15.0, straight_step_um: float = 50.0,
                   straight_max_um: float = 1500.0, limit: int | None = None,
                   first: tuple[float, float] | None = None) -> Iterator[pathlib.Path]:
    """The paths "turn ``phi``, straight ``s``, then the shortest path to ``target``" from ``start``, shortest first
    (lazily: the lengths of all are computed at once, each path only when asked for).

    ``phi`` runs over ``[0, 2 pi)`` every ``turn_step_deg`` (deg) and ``s`` over ``[0, straight_max_um]`` every
    ``straight_step_um`` (um); ``(0, 0)`` is the shortest path itself. Every path ends at ``target`` (its last
    segments are a shortest path to it), and each comes once (segments equal to the um). ``limit``: at most this
    many paths. ``first``: a ``(turn_um, straight_um)`` prefix whose path comes before all others (the rest of a path
    chosen a t_x ago, :func:`remaining_prefix`).

    >>> ps = list(prefixed_paths((0.0, 0.0, 0.0), (0.0, 1000.0, 0.0), 100.0, limit=3))
    >>> [round(p.length) for p in ps], ps[0].word   # straight; then a full loop (628 um) first
    ([1000, 1628, 1630], 'S')
    >>> end = ps[-1].end
    >>> round(end.x, 6) + 0.0, round(end.y, 6), round(end.theta, 6) + 0.0
    (0.0, 1000.0, 0.0)
    """
    p0 = np.asarray(start, float)
    q = np.asarray(target, float)
    r = float(radius_um)
    phi = np.radians(np.arange(0.0, 360.0, turn_step_deg))
    s = np.arange(0.0, straight_max_um + 1e-9, straight_step_um)
    turn_um, straight_um = (g.ravel() for g in np.meshgrid(r * phi, s, indexing="ij"))
    if first is not None:
        turn_um, straight_um = np.r_[first[0], turn_um], np.r_[first[1], straight_um]
    turned = move(p0[None, :], turn_um, 1.0 / r)
    ends = move(turned, straight_um, 0.0)
    total = turn_um + straight_um + pathlib.shortest_path_lengths(ends, q[None, :], r)
    order = np.argsort(total, kind="stable")
    if first is not None:
        order = np.r_[0, order[order != 0]]
    seen: set[tuple] = set()
    for k in order:
        if limit is not None and len(seen) >= limit:
            return
        rest = pathlib.shortest_path(ends[k], q, r)
        path = pathlib.Path(Pose(*(float(v) for v in p0)), r, (("R", float(turn_um[k])), ("S", float(straight_um[k])), *rest.segments))
        key = tuple((kind, round(ell)) for kind, ell in path.segments)
        if key not in seen:  # a turn along the shortest path's own first turn is that path again
            seen.add(key)
            yield path


def remaining_prefix(path: pathlib.Path, pose, *, off_um: float = 30.0) -> tuple[float, float] | None:
    """What is left of the prefix (a turn, then a straight: :func:`prefixed_paths`) of ``path`` for a robot now at
    ``pose``: ``(turn_um, straight_um)`` from the point of ``path`` nearest to ``pose`` (um); None when the robot is
    more than ``off_um`` from ``path`` or past its prefix.

    >>> p = pathlib.Path((0.0, 0.0, 0.0), 100.0, (("R", 0.0), ("S", 500.0), ("R", 157.08)))
    >>> remaining_prefix(p, (0.0, 200.0, 0.0)), remaining_prefix(p, (300.0, 200.0, 0.0))
    ((0.0, 300.0), None)
    """
    segs = path.segments
    turn = segs[0][1] if segs and segs[0][0] == "R" else 0.0
    rest = segs[1:] if turn > 0.0 else segs
    straight = rest[0][1] if rest and rest[0][0] == "S" else 0.0
    s = sample_arclengths(path.lengths, 10.0)
    xy = path.pose_at(s)[:, :2]
    d = np.hypot(*(xy - np.asarray(pose, float)[:2]).T)
    k = int(np.argmin(d))
    if d[k] > off_um or s[k] >= turn + straight:
        return None
    done = float(s[k])
    return max(turn - done, 0.0), straight - max(done - turn, 0.0)


def first_clear(start, target, radius_um: float, hits: Callable[[pathlib.Path], bool], *, checks: int, max_length_um: float,
                rest: tuple[float, float] | None = None) -> tuple[pathlib.Path, int] | None:
    """The shortest of :func:`prefixed_paths` (at most ``checks`` of them, none longer than ``max_length_um``) for which
    ``hits(path)`` is False, and how many were checked before it; None when none. ``rest`` (a prefix,
    :func:`remaining_prefix`) is checked first whatever its length: the way a robot already chose.

    >>> far = lambda p: bool((p.sample(10.0)[:, 0] > 50.0).any())   # nothing may pass x = 50 um
    >>> path, k = first_clear((0.0, 0.0, 0.0), (0.0, 1000.0, 0.0), 100.0, far, checks=5, max_length_um=3000.0)
    >>> path.word, k
    ('S', 0)
    """
    for k, cand in enumerate(prefixed_paths(start, target, radius_um, limit=checks, first=rest)):
        if cand.length > max_length_um and not (k == 0 and rest is not None):
            return None
        if not hits(cand):
            return cand, k
    return None


def describe_prefix(path: pathlib.Path) -> str:
    """How a prefixed path begins, in words.

    >>> describe_prefix(pathlib.Path((0.0, 0.0, 0.0), 100.0, (("R", 50.0 * math.pi), ("S", 300.0), ("R", 10.0))))
    'turns 90 deg, drives 300 um straight'
    """
    segs = list(path.segments)
    words = []
    if segs and segs[0][0] == "R":
        words.append(f"turns {math.degrees(segs.pop(0)[1] / path.radius):.0f} deg")
    if segs and segs[0][0] == "S":
        words.append(f"drives {segs[0][1]:.0f} um straight")
    return ", ".join(words) or "takes its shortest path"
