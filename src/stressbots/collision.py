"""Collision geometry between robot bodies, orbit discs and the arena, vectorised over poses.

Bodies are rectangles (L along the heading, W across, centred on the pose). Touching is not colliding:
every test takes a tolerance ``tol_um`` and reports a collision only when bodies interpenetrate by more.
The planner, the replay verifier and the simulator all use these functions, so they agree on what a
collision is.
"""

from __future__ import annotations

import numpy as np

from .robots import heading_vectors, right_vectors


def _as_poses(poses) -> np.ndarray:
    return np.atleast_2d(np.asarray(poses, dtype=np.float64))


def point_rectangle_distance(points, poses, length_um, width_um) -> np.ndarray:
    """Signed distance (um) from points to body rectangles; negative inside.

    ``points`` is ``(K, 2)``, ``poses`` is ``(M, 3)``; returns ``(M, K)``. ``length_um``/``width_um`` are
    scalars or ``(M,)``.
    """
    poses = _as_poses(poses)
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    half_l = 0.5 * np.broadcast_to(np.asarray(length_um, dtype=np.float64), poses.shape[:1])[:, None]
    half_w = 0.5 * np.broadcast_to(np.asarray(width_um, dtype=np.float64), poses.shape[:1])[:, None]
    h = heading_vectors(poses[:, 2])  # (M, 2)
    rt = right_vectors(poses[:, 2])
    d = pts[None, :, :] - poses[:, None, :2]  # (M, K, 2)
    u = np.abs(np.einsum("mkj,mj->mk", d, h)) - half_l  # along the body
    v = np.abs(np.einsum("mkj,mj->mk", d, rt)) - half_w  # across the body
    outside = np.hypot(np.maximum(u, 0.0), np.maximum(v, 0.0))
    inside = np.minimum(np.maximum(u, v), 0.0)
    return outside + inside


def point_rectangle_distance_rows(points, poses, length_um, width_um) -> np.ndarray:
    """Signed distance (um) from ``points[m]`` to the body at ``poses[m]``, row by row: ``(M,)``.

    The same formula as :func:`point_rectangle_distance` for matched pairs only (no ``(M, K)`` matrix):
    the collision checks of the planner evaluate just the sample-obstacle pairs that are close.
    """
    poses = _as_poses(poses)
    pts = np.atleast_2d(np.asarray(points, dtype=np.float64))
    s, c = np.sin(poses[:, 2]), np.cos(poses[:, 2])
    dx, dy = pts[:, 0] - poses[:, 0], pts[:, 1] - poses[:, 1]
    u = np.abs(dx * s + dy * c) - 0.5 * np.asarray(length_um, dtype=np.float64)
    v = np.abs(dx * c - dy * s) - 0.5 * np.asarray(width_um, dtype=np.float64)
    return np.hypot(np.maximum(u, 0.0), np.maximum(v, 0.0)) + np.minimum(np.maximum(u, v), 0.0)


def bodies_hit_discs(poses, length_um, width_um, centres, radii, *, tol_um: float = 0.0) -> np.ndarray:
    """Whether each body intersects each disc by more than ``tol_um``: ``(M, K)`` bool.

    Exact (the signed distance of :func:`point_rectangle_distance_rows`), evaluated only for the body-disc pairs
    whose centres are closer than the disc's reach plus the body's half-diagonal: a body's signed distance to a
    point is at least their centre distance less the half-diagonal, so no pair further apart can hit. Gross motion
    checks hundreds of path samples against every waiting orbit each t_x, and nearly all pairs are far apart.
    """
    poses = _as_poses(poses)
    c = np.atleast_2d(np.asarray(centres, dtype=np.float64))
    reach = np.broadcast_to(np.asarray(radii, dtype=np.float64), (c.shape[0],)) - tol_um
    out = np.zeros((poses.shape[0], c.shape[0]), dtype=bool)
    if out.size == 0:
        return out
    length = np.broadcast_to(np.asarray(length_um, dtype=np.float64), poses.shape[:1])
    width = np.broadcast_to(np.asarray(width_um, dtype=np.float64), poses.shape[:1])
    half_diag = 0.5 * np.hypot(length, width)
    dx = poses[:, None, 0] - c[None, :, 0]
    dy = poses[:, None, 1] - c[None, :, 1]
    bound = reach[None, :] + half_diag[:, None]
    near = (dx * dx + dy * dy < bound * bound) | (reach[None, :] <= 0.0)
    mi, ki = np.nonzero(near)
    if len(mi):
        out[mi, ki] = point_rectangle_distance_rows(c[ki], poses[mi], length[mi], width[mi]) < reach[ki]
    return out


def penetration_depth(poses_a, length_a, width_a, poses_b, length_b, width_b) -> np.ndarray:
    """Separating-axis penetration depth (um) of body pairs, row by row; <= 0 means apart or touching.

    The depth is the smallest overlap of the two rectangles' projections over the four candidate axes
    (both bodies' heading and right vectors): the distance one body must move to separate them.
    """
    pa, pb = _as_poses(poses_a), _as_poses(poses_b)
    m = max(pa.shape[0], pb.shape[0])
    # one pose or size against many: numpy's broadcasting in the arithmetic below, not copies
    la = 0.5 * np.asarray(length_a, dtype=np.float64)
    wa = 0.5 * np.asarray(width_a, dtype=np.float64)
    lb = 0.5 * np.asarray(length_b, dtype=np.float64)
    wb = 0.5 * np.asarray(width_b, dtype=np.float64)
    # components written out (heading (sin, cos), right (cos, -sin)): the same products and sums as the vector
    # form, so the same bits, without its per-call overhead (escape searches call this 10^5 times a run)
    sa, ca, sb, cb = np.sin(pa[:, 2]), np.cos(pa[:, 2]), np.sin(pb[:, 2]), np.cos(pb[:, 2])
    ha, ra, hb, rb = (sa, ca), (ca, -sa), (sb, cb), (cb, -sb)
    dx, dy = pb[:, 0] - pa[:, 0], pb[:, 1] - pa[:, 1]
    depth = np.full(m, np.inf)
    for ax, ay in (ha, ra, hb, rb):
        ext_a = la * np.abs(ha[0] * ax + ha[1] * ay) + wa * np.abs(ra[0] * ax + ra[1] * ay)
        ext_b = lb * np.abs(hb[0] * ax + hb[1] * ay) + wb * np.abs(rb[0] * ax + rb[1] * ay)
        overlap = ext_a + ext_b - np.abs(dx * ax + dy * ay)
        depth = np.minimum(depth, overlap)
    return depth


def bodies_overlap(poses_a, length_a, width_a, poses_b, length_b, width_b, *, tol_um: float = 1e-6) -> np.ndarray:
    """Whether body pairs interpenetrate by more than ``tol_um`` (row by row): ``(M,)`` bool."""
    return penetration_depth(poses_a, length_a, width_a, poses_b, length_b, width_b) > tol_um


def pairwise_overlaps(poses, lengths_um, widths_um, *, tol_um: float = 1e-6) -> list[tuple[int, int, float]]:
    """All pairs ``(i, j, depth_um)`` of the ``N`` bodies that interpenetrate by more than ``tol_um``."""
    poses = _as_poses(poses)
    n = poses.shape[0]
    if n < 2:
        return []
    i, j = np.triu_indices(n, k=1)
    lengths = np.broadcast_to(np.asarray(lengths_um, dtype=np.float64), (n,))
    widths = np.broadcast_to(np.asarray(widths_um, dtype=np.float64), (n,))
    depth = penetration_depth(poses[i], lengths[i], widths[i], poses[j], lengths[j], widths[j])
    hit = depth > tol_um
    return [(int(a), int(b), float(dd)) for a, b, dd in zip(i[hit], j[hit], depth[hit], strict=True)]


def arena_gap(poses, length_um, width_um, arena_um) -> np.ndarray:
    """Distance (um) from each body to the nearest wall of the arena ``[0, w] x [0, h]``; negative when it
    sticks out. Closed form: a rectangle's half extents along x and y are ``L/2 |sin| + W/2 |cos|`` and
    ``L/2 |cos| + W/2 |sin|``. Broadcasts like ``poses[..., 0]``."""
    p = np.asarray(poses, dtype=np.float64)
    hl, hw = 0.5 * np.asarray(length_um, dtype=np.float64), 0.5 * np.asarray(width_um, dtype=np.float64)
    s, c = np.abs(np.sin(p[..., 2])), np.abs(np.cos(p[..., 2]))
    ex = hl * s + hw * c
    ey = hl * c + hw * s
    w, h = arena_um
    x, y = p[..., 0], p[..., 1]
    return np.minimum(np.minimum(x - ex, w - x - ex), np.minimum(y - ey, h - y - ey))


def outside_arena(poses, length_um, width_um, arena_um, *, tol_um: float = 1e-6) -> np.ndarray:
    """How far (um) each body sticks out of the arena ``[0, w] x [0, h]``; 0 when inside. ``(M,)``."""
    over = -arena_gap(_as_poses(poses), length_um, width_um, arena_um)
    return np.where(over > tol_um, over, 0.0)


def disc_overlaps(centres, radii, *, tol_um: float = 0.0) -> list[tuple[int, int, float]]:
    """Pairs ``(i, j, overlap_um)`` of discs that overlap by more than ``tol_um``."""
    c = np.atleast_2d(np.asarray(centres, dtype=np.float64))
    r = np.broadcast_to(np.asarray(radii, dtype=np.float64), (c.shape[0],))
    if c.shape[0] < 2:
        return []
    i, j = np.triu_indices(c.shape[0], k=1)
    overlap = r[i] + r[j] - np.hypot(*(c[i] - c[j]).T)
    hit = overlap > tol_um
    return [(int(a), int(b), float(o)) for a, b, o in zip(i[hit], j[hit], overlap[hit], strict=True)]
