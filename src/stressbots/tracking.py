"""Tracking: robot poses from a microscope camera frame (SPEC 9.2).

A frame is a 2-D uint8 array, rows downward. :class:`Calibration` maps pixels to the arena frame:
``x = (col - col0) * um_per_px``, ``y = (row0 - row) * um_per_px``. The image model: a dark background
(about 30, with noise), each robot's body rectangle (L x W, about 200) and its steering arm, a bar 8 um
wide along the robot's *right* side (the side of its turning centre), from the rear edge forward over
60 % of L, 6 um away from the body. The arm is what tells front from back.

:func:`locate` works in four steps:

1. **Segment** (OpenCV, on a copy reduced to about :attr:`TrackerSettings.segment_um_per_px`): threshold
   half-way between background and body level, remove the arms by a morphological opening narrower
   than a body, label connected components. A component's area says how many robots it holds (robots
   touch each other in docked structures).
2. **Split** each component into that many known rectangles: from the previous poses that fall in it
   when there are as many, else from a k-means partition of its pixels, then by alternating
   "each pixel to the rectangle it lies deepest in" and "each rectangle to the moments of its pixels";
   the start that covers the component best wins.
3. **Refine** every rectangle on the full-resolution frame with intensity-weighted moments (sub-pixel:
   anti-aliased edge pixels count by their brightness) over its own pixels (those inside a neighbour
   are left to the neighbour), and decide front from back by the arm's signature: a bright bar behind
   a dark gap on the right side of the rear 60 %.
4. **Identify**: a Hungarian assignment (:func:`scipy.optimize.linear_sum_assignment`) of detections to
   robots on a cost of position and heading change against ``previous`` (default the scenario's start
   poses) plus size mismatch, then a last refinement with each robot's own L x W.

Angles are computed from moments with ``atan2`` and normalised here (no reliance on
``cv2.minAreaRect``'s angle convention, which changed between OpenCV releases).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from .errors import StressbotsError

__all__ = ["Calibration", "ArmGeometry", "TrackerSettings", "Detection", "locate", "detect"]


@dataclass(frozen=True)
class Calibration:
    """Pixel <-> arena mapping of a camera: ``um_per_px`` (um per pixel) and ``origin_px = (col0, row0)``,
    the pixel of the arena origin (SPEC 9.2). Rows grow downward, y upward.

    >>> c = Calibration(2.0, (10.0, 500.0))
    >>> c.to_um(np.array([10.0, 60.0]), np.array([500.0, 400.0]))
    (array([  0., 100.]), array([  0., 200.]))
    >>> c.to_px(np.array([100.0]), np.array([200.0]))
    (array([60.]), array([400.]))
    """

    um_per_px: float
    origin_px: tuple[float, float] = (0.0, 0.0)

    def __post_init__(self) -> None:
        u = float(self.um_per_px)
        if not (math.isfinite(u) and u > 0):
            raise StressbotsError(f"must be a finite number > 0, got {self.um_per_px!r}", field="um_per_px")
        c0, r0 = (float(v) for v in self.origin_px)
        if not (math.isfinite(c0) and math.isfinite(r0)):
            raise StressbotsError("must be two finite numbers (col0, row0)", field="origin_px")
        object.__setattr__(self, "um_per_px", u)
        object.__setattr__(self, "origin_px", (c0, r0))

    def to_um(self, cols, rows) -> tuple[np.ndarray, np.ndarray]:
        """Pixel (col, row) -> arena (x_um, y_um)."""
        c0, r0 = self.origin_px
        return (np.asarray(cols, np.float64) - c0) * self.um_per_px, (r0 - np.asarray(rows, np.float64)) * self.um_per_px

    def to_px(self, x_um, y_um) -> tuple[np.ndarray, np.ndarray]:
        """Arena (x_um, y_um) -> pixel (col, row), fractional."""
        c0, r0 = self.origin_px
        return c0 + np.asarray(x_um, np.float64) / self.um_per_px, r0 - np.asarray(y_um, np.float64) / self.um_per_px


@dataclass(frozen=True)
class ArmGeometry:
    """The steering arm as the camera sees it (SPEC 9.2): a bar ``width_um`` wide, ``gap_um`` off the
    body's right side, from the rear edge forward over ``length_frac`` of the body length."""

    width_um: float = 8.0
    gap_um: float = 6.0
    length_frac: float = 0.6


@dataclass(frozen=True)
class TrackerSettings:
    """Tuned numbers of :func:`locate`, with units and why.

    Attributes
    ----------
    segment_um_per_px:
        Pixel size (um) segmentation works at: coarser is faster; 4.5 um still resolves the 50-70 um bodies.
    open_frac_of_width:
        Diameter of the opening that removes arms, as a fraction of the narrowest body: wider than the
        8 um arm plus its 6 um gap, narrower than a body.
    min_area_frac:
        Components smaller than this fraction of the smallest body are noise or stray arms.
    split_iterations:
        Rounds of the rectangle split of a component holding several robots.
    good_split:
        A split leaving at most this fraction of the component uncovered or doubly covered is accepted
        without trying further starts.
    kmeans_restarts:
        Extra k-means starts (deterministic first centres) when no start gives a good split.
    along_axis_weight:
        A second split from the previous poses discounts distance along each body's axis by this factor:
        robots drive along their axis, so side-by-side robots that moved far are still told apart.
    refine_iterations:
        Rounds of the sub-pixel moment refinement (neighbours' estimates improve each round).
    edge_margin_px:
        How far (px) beyond a body edge the refinement reaches to collect the anti-aliased, blurred edge;
        capped at ``gap_um - 1 um`` so that the arm stays out.
    ambiguous_arm_frac:
        Below this arm-signature difference (fraction of body contrast) front/back is undecided and the
        heading closest to the previous one is kept.
    heading_cost_um_per_rad:
        Weight of a heading change in the identity cost (um per rad).
    size_cost:
        Weight of a size mismatch (L and W, um per um) in the identity cost.
    width_weight:
        How much more a width mismatch counts than a length mismatch when matching sizes: widths are
        measured directly, lengths of robots touching end to end only through the fit.
    unseen_cost_um:
        Cost of assigning a detection to a robot with no previous pose.
    start_pose_weight:
        Weight of the position/heading cost when identities come from the scenario's start poses
        (``previous`` None): sizes decide first, start poses only break ties.
    """

    segment_um_per_px: float = 4.5
    open_frac_of_width: float = 0.4
    min_area_frac: float = 0.4
    split_iterations: int = 12
    good_split: float = 0.01
    kmeans_restarts: int = 4
    along_axis_weight: float = 0.25
    refine_iterations: int = 2
    edge_margin_px: float = 2.5
    ambiguous_arm_frac: float = 0.15
    heading_cost_um_per_rad: float = 50.0
    size_cost: float = 2.0
    width_weight: float = 3.0
    unseen_cost_um: float = 1e4
    start_pose_weight: float = 0.01
    arm: ArmGeometry = ArmGeometry()


class Detection(NamedTuple):
    """One robot found in a frame: pose ``(x_um, y_um, theta_rad)``, measured length/width (um), and
    ``arm_score`` (arm signature in units of body contrast; near 0 = front/back undecided)."""

    pose: np.ndarray
    length_um: float
    width_um: float
    arm_score: float


def _wrap(a):
    return np.mod(a, 2.0 * np.pi)


# ----------------------------------------------------------------------------------------------------
# Levels and segmentation


def _levels(frame: np.ndarray) -> tuple[float, float, float]:
    """Background level, body level and background noise sd, from a subsample of the frame."""
    sub = frame[::8, ::8].astype(np.float32).ravel()
    bg = float(np.median(sub))
    sd = max(1.4826 * float(np.median(np.abs(sub - bg))), 0.5)
    bright = sub[sub > bg + max(8.0 * sd, 20.0)]
    fg = float(np.median(bright)) if bright.size >= 8 else float(frame.max())
    return bg, max(fg, bg + 10.0), sd


def _components(frame, bg, fg, cal: Calibration, settings: TrackerSettings, min_w_um: float):
    """Reduced-resolution body components: list of ``(points_um (m, 2), pixel_area_um2)``."""
    import cv2

    f = max(1, int(settings.segment_um_per_px / cal.um_per_px))
    small = frame if f == 1 else cv2.resize(frame, (frame.shape[1] // f, frame.shape[0] // f), interpolation=cv2.INTER_AREA)
    upx = cal.um_per_px * f
    mask = (small > 0.5 * (bg + fg)).astype(np.uint8)
    d = max(3, int(round(settings.open_frac_of_width * min_w_um / upx)) | 1)
    mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, cv2.getStructuringElement(cv2.MORPH_ELLIPSE, (d, d)))
    count, labels, stats, _ = cv2.connectedComponentsWithStats(mask, connectivity=8)
    out = []
    for k in range(1, count):
        x0, y0, w, h, area = stats[k]
        sub = labels[y0:y0 + h, x0:x0 + w] == k
        rr, cc = np.nonzero(sub)
        cols = (cc + x0 + 0.5) * f - 0.5
        rows = (rr + y0 + 0.5) * f - 0.5
        x, y = cal.to_um(cols, rows)
        out.append((np.stack([x, y], axis=1), upx * upx))
    return out


# ----------------------------------------------------------------------------------------------------
# Splitting a component into known rectangles


def _local(pts: np.ndarray, pose) -> tuple[np.ndarray, np.ndarray]:
    """Points in a robot's frame: ``u`` along its heading, ``w`` to its right (um)."""
    dx, dy = pts[:, 0] - pose[0], pts[:, 1] - pose[1]
    s, c = math.sin(pose[2]), math.cos(pose[2])
    return dx * s + dy * c, dx * c - dy * s


def _moment_pose(pts: np.ndarray, w: np.ndarray | None = None) -> tuple[np.ndarray, float, float]:
    """Centroid and axis heading (theta mod pi) of weighted points; also sqrt(12 var) along/across (um)."""
    if w is None:
        w = np.ones(len(pts))
    m0 = float(w.sum())
    cx, cy = (w @ pts) / m0
    dx, dy = pts[:, 0] - cx, pts[:, 1] - cy
    mxx, myy, mxy = (w @ (dx * dx)) / m0, (w @ (dy * dy)) / m0, (w @ (dx * dy)) / m0
    alpha = 0.5 * math.atan2(2.0 * mxy, mxx - myy)  # major axis, from +x counter-clockwise
    theta = math.pi / 2.0 - alpha  # clockwise from +y (SPEC 2)
    tr, det = mxx + myy, mxx * myy - mxy * mxy
    disc = math.sqrt(max(tr * tr / 4.0 - det, 0.0))
    return np.array([cx, cy, theta % math.pi]), math.sqrt(12.0 * max(tr / 2 + disc, 0.0)), math.sqrt(12.0 * max(tr / 2 - disc, 0.0))


def _depth(pts: np.ndarray, poses: np.ndarray, hl: np.ndarray, hw: np.ndarray, along: float = 1.0) -> np.ndarray:
    """``(k, m)`` box distance of each point to each rectangle: negative inside (how deep), positive outside.
    ``along`` < 1 discounts distance along a body's axis (robots mostly move along it between frames)."""
    out = np.empty((len(poses), len(pts)))
    for j, p in enumerate(poses):
        u, w = _local(pts, p)
        out[j] = np.maximum(along * (np.abs(u) - hl[j]), np.abs(w) - hw[j])
    return out


def _fit_rectangles(pts, init: np.ndarray, hl, hw, iterations: int, size_range=None, along: float = 1.0
                    ) -> tuple[np.ndarray, np.ndarray, float]:
    """Alternate pixel -> deepest rectangle and rectangle -> moments; returns poses and the uncovered
    fraction plus the overlap fraction of the component (lower is better). With ``size_range``
    ``((hl_min, hl_max), (hw_min, hw_max))`` each rectangle's size follows its pixels' moments too."""
    poses = init.copy()
    hl, hw = np.array(hl, np.float64), np.array(hw, np.float64)
    k = len(poses)
    for _ in range(iterations):
        owner = np.argmin(_depth(pts, poses, hl, hw, along), axis=0)
        new = poses.copy()
        for j in range(k):
            mine = pts[owner == j]
            if len(mine) >= 3:
                p, length, width = _moment_pose(mine)
                if size_range is not None:
                    hl[j] = np.clip(length / 2, *size_range[0])
                    hw[j] = np.clip(width / 2, *size_range[1])
                # keep the previous direction of the axis (moments give it mod pi)
                d = (p[2] - poses[j, 2] + np.pi / 2) % np.pi - np.pi / 2
                new[j] = (p[0], p[1], poses[j, 2] + d)
        if np.allclose(new, poses, atol=1e-3):
            poses = new
            break
        poses = new
    depth = _depth(pts, poses, hl, hw)
    inside = depth <= 1.0
    uncovered = float(np.mean(~inside.any(axis=0)))
    overlap = float(np.mean(inside.sum(axis=0) > 1))
    return poses, np.stack([hl, hw], axis=1), uncovered + overlap


def _kmeans_init(pts: np.ndarray, k: int, first: int | None = None) -> np.ndarray:
    """k-means (farthest-point start from point ``first``, default the one farthest from the centroid;
    10 Lloyd rounds) -> one axis pose per cluster."""
    c = pts.mean(axis=0)
    centres = [pts[np.argmax(np.sum((pts - c) ** 2, axis=1)) if first is None else first]]
    for _ in range(1, k):
        d = np.min([np.sum((pts - q) ** 2, axis=1) for q in centres], axis=0)
        centres.append(pts[np.argmax(d)])
    cen = np.array(centres)
    for _ in range(10):
        lab = np.argmin(((pts[:, None, :] - cen[None]) ** 2).sum(axis=2), axis=1)
        cen = np.array([pts[lab == j].mean(axis=0) if np.any(lab == j) else cen[j] for j in range(k)])
    poses = []
    for j in range(k):
        mine = pts[lab == j]
        poses.append(_moment_pose(mine)[0] if len(mine) >= 3 else np.array([*cen[j], 0.0]))
    return np.array(poses)


def _split(pts, area_px: float, hl0: float, hw0: float, previous: np.ndarray | None, prev_hl, prev_hw,
           settings: TrackerSettings) -> tuple[np.ndarray, np.ndarray]:
    """Axis poses ``(k, 3)`` and half sizes ``(k, 2)`` of the robots in one component (k from its area)."""
    k = max(1, int(round(len(pts) * area_px / (4.0 * hl0 * hw0))))
    if k == 1:
        pose, length, width = _moment_pose(pts)
        return pose[None], np.array([[length / 2, width / 2]])
    starts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
    if previous is not None and len(previous):
        lo, hi = pts.min(axis=0) - hw0, pts.max(axis=0) + hw0
        ok = np.all(np.isfinite(previous), axis=1) & np.all((previous[:, :2] >= lo) & (previous[:, :2] <= hi), axis=1)
        if ok.any():
            d = np.min(np.hypot(previous[ok, 0, None] - pts[None, :, 0], previous[ok, 1, None] - pts[None, :, 1]), axis=1)
            idx = np.flatnonzero(ok)[d <= 2.0 * hw0]
            if len(idx) == k:
                starts.append((previous[idx].copy(), prev_hl[idx], prev_hw[idx]))
    varied = np.ptp(prev_hl) > 0 or np.ptp(prev_hw) > 0
    adapt = ((prev_hl.min(), prev_hl.max()), (prev_hw.min(), prev_hw.max())) if varied else None
    best, best_score = None, np.inf
    for init, a, b in starts:  # from the previous poses: as they are, and discounting motion along the axis
        for along in (1.0, settings.along_axis_weight):
            poses, half, score = _fit_rectangles(pts, init, a, b, settings.split_iterations, None, along)
            if score < best_score - 1e-9:
                best, best_score = (poses, half), score
    from_previous = best is not None
    # from the pixels alone: a k-means partition, and from a few more deterministic first centres while
    # no start splits the component well
    firsts = [None] + list(np.random.default_rng(k).choice(len(pts), size=min(settings.kmeans_restarts, len(pts)), replace=False))
    for m, first in enumerate(firsts):
        if m > 0 and best_score <= settings.good_split:
            break
        init = _kmeans_init(pts, k, first)
        poses, half, score = _fit_rectangles(pts, init, np.full(k, hl0), np.full(k, hw0), settings.split_iterations, adapt)
        if adapt is not None:
            snapped = _snap_sizes(pts, poses, half, prev_hl, prev_hw, settings)
            if snapped[2] <= score:
                poses, half, score = snapped
        # a start from the previous poses (right sizes in the right places) wins unless clearly worse:
        # coverage alone cannot see where robots touching end to end meet
        if score < best_score - (settings.good_split if from_previous else 1e-9):
            best, best_score, from_previous = (poses, half), score, False
    assert best is not None  # the first finite score always wins
    return best


def _snap_sizes(pts, poses, half, all_hl, all_hw, settings: TrackerSettings):
    """Robots of different sizes: give each fitted rectangle the size of the robot whose body it matches
    best (widths weigh more: a width is seen directly, a length only where a seam or an end shows), then
    fit again with those sizes."""
    from scipy.optimize import linear_sum_assignment

    cost = (settings.width_weight * np.abs(half[:, None, 1] - all_hw[None, :]) + np.abs(half[:, None, 0] - all_hl[None, :]))
    rows, cols = linear_sum_assignment(cost)
    hl, hw = all_hl[cols[np.argsort(rows)]], all_hw[cols[np.argsort(rows)]]
    return _fit_rectangles(pts, poses, hl, hw, settings.split_iterations)


# ----------------------------------------------------------------------------------------------------
# Sub-pixel refinement and front/back


def _roi(frame_shape, cal: Calibration, pose, hl, hw, margin_um):
    """Row/col slices of the frame around a rectangle grown by ``margin_um``."""
    r = math.hypot(hl + margin_um, hw + margin_um)
    c, rw = cal.to_px(np.array([pose[0]]), np.array([pose[1]]))
    rad = r / cal.um_per_px + 1.0
    c0, c1 = max(0, int(c[0] - rad)), min(frame_shape[1], int(math.ceil(c[0] + rad)) + 1)
    r0, r1 = max(0, int(rw[0] - rad)), min(frame_shape[0], int(math.ceil(rw[0] + rad)) + 1)
    return slice(r0, r1), slice(c0, c1)


def _refine(frame, cal, bg, fg, poses, hl, hw, settings: TrackerSettings) -> tuple[np.ndarray, np.ndarray]:
    """Intensity-weighted moments of each rectangle's own pixels on the full frame; returns axis poses
    (heading kept within +-90 deg of the input) and the measured (length, width) per robot."""
    arm = settings.arm
    margin = min(settings.edge_margin_px * cal.um_per_px, arm.gap_um - 1.0)
    out = poses.copy()
    sizes = np.zeros((len(poses), 2))
    for _ in range(settings.refine_iterations):
        current = out.copy()
        for j, p in enumerate(current):
            rs, cs = _roi(frame.shape, cal, p, hl[j], hw[j], margin)
            if rs.stop <= rs.start or cs.stop <= cs.start:
                continue
            rows = np.arange(rs.start, rs.stop, dtype=np.float64)
            cols = np.arange(cs.start, cs.stop, dtype=np.float64)
            X, Y = cal.to_um(cols[None, :], rows[:, None])
            pts = np.stack(np.broadcast_arrays(X, Y), axis=-1).reshape(-1, 2)
            u, w = _local(pts, p)
            keep = (np.abs(u) <= hl[j] + margin) & (np.abs(w) <= hw[j] + margin)
            for i, q in enumerate(current):
                if i != j and math.hypot(q[0] - p[0], q[1] - p[1]) < hl[i] + hl[j] + hw[i] + hw[j] + 2 * margin:
                    ui, wi = _local(pts, q)
                    keep &= ~((np.abs(ui) < hl[i]) & (np.abs(wi) < hw[i]))
            if keep.sum() < 10:
                continue
            wts = (frame[rs, cs].astype(np.float64).reshape(-1)[keep] - bg) / (fg - bg)
            pose, length, width = _moment_pose(pts[keep], wts)
            d = (pose[2] - p[2] + np.pi / 2) % np.pi - np.pi / 2
            out[j] = (pose[0], pose[1], p[2] + d)
            sizes[j] = (length, width)
    return out, sizes


def _bilinear(frame, cal: Calibration, x, y) -> np.ndarray:
    c, r = cal.to_px(x, y)
    c = np.clip(c, 0, frame.shape[1] - 1.001)
    r = np.clip(r, 0, frame.shape[0] - 1.001)
    c0, r0 = np.floor(c).astype(int), np.floor(r).astype(int)
    fc, fr = c - c0, r - r0
    def at(r, c):
        return frame[r, c].astype(np.float64)

    return (1 - fr) * ((1 - fc) * at(r0, c0) + fc * at(r0, c0 + 1)) + fr * ((1 - fc) * at(r0 + 1, c0) + fc * at(r0 + 1, c0 + 1))


def _arm_signature(frame, cal, pose, hl, hw, arm: ArmGeometry) -> float:
    """Mean brightness on the arm's centre line minus that on the gap's, on the right side of the rear
    ``length_frac`` (in raw grey levels; large and positive when ``pose`` faces the right way)."""
    arm_len = 2.0 * hl * arm.length_frac
    u = np.linspace(-hl + 0.1 * arm_len, -hl + 0.9 * arm_len, 24)
    s, c = math.sin(pose[2]), math.cos(pose[2])

    def line(w_off: float) -> np.ndarray:
        return _bilinear(frame, cal, pose[0] + u * s + w_off * c, pose[1] + u * c - w_off * s)

    return float(np.mean(line(hw + arm.gap_um + 0.5 * arm.width_um)) - np.mean(line(hw + 0.5 * arm.gap_um)))


def _as_uint8(frame) -> np.ndarray:
    img = np.asarray(frame)
    if img.ndim != 2:
        raise StressbotsError(f"a frame must be a 2-D grey image, got shape {img.shape}", field="frame")
    return img if img.dtype == np.uint8 else np.clip(np.asarray(img, np.float64), 0, 255).astype(np.uint8)


def _axes(img, calibration, L, W, prev, st: TrackerSettings) -> tuple[np.ndarray, np.ndarray, float, float]:
    """Refined axis poses ``(k, 3)`` (theta mod pi), their measured sizes ``(k, 2)``, background and body level."""
    hl0, hw0 = float(np.median(L)) / 2, float(np.median(W)) / 2
    bg, fg, _ = _levels(img)
    axes: list[np.ndarray] = []
    halves: list[np.ndarray] = []
    for pts, area in _components(img, bg, fg, calibration, st, float(W.min())):
        if len(pts) * area < st.min_area_frac * float((L * W).min()):
            continue
        poses, half = _split(pts, area, hl0, hw0, prev, L / 2, W / 2, st)
        axes.extend(poses)
        halves.extend(half)
    if not axes:
        return np.zeros((0, 3)), np.zeros((0, 2)), bg, fg
    half = np.array(halves)
    hl = np.clip(half[:, 0], L.min() / 2, L.max() / 2)
    hw = np.clip(half[:, 1], W.min() / 2, W.max() / 2)
    poses, _ = _refine(img, calibration, bg, fg, np.array(axes), hl, hw, st)
    return poses, 2.0 * half, bg, fg


def _orient(img, cal, pose, hl, hw, contrast, arm: ArmGeometry) -> tuple[np.ndarray, float]:
    """The heading of an axis pose that puts the arm on the right of the rear, and how clearly (fraction
    of the body contrast)."""
    p = np.array(pose, np.float64)
    fwd = _arm_signature(img, cal, p, hl, hw, arm)
    back = _arm_signature(img, cal, (p[0], p[1], p[2] + np.pi), hl, hw, arm)
    if back > fwd:
        p[2] += np.pi
    p[2] = _wrap(p[2])
    return p, abs(fwd - back) / contrast


def detect(frame, calibration: Calibration, lengths_um, widths_um, *, previous=None,
           settings: TrackerSettings | None = None) -> list[Detection]:
    """All robots in a frame, without identities (see :func:`locate`). ``lengths_um``/``widths_um``
    are the robots' body sizes (their median is used); ``previous`` (poses of those robots) seeds splits."""
    st = settings or TrackerSettings()
    img = _as_uint8(frame)
    L, W = np.asarray(lengths_um, np.float64), np.asarray(widths_um, np.float64)
    prev = None if previous is None else np.asarray(previous, np.float64).reshape(-1, 3)
    poses, sizes, bg, fg = _axes(img, calibration, L, W, prev, st)
    out = []
    for p, (length, width) in zip(poses, sizes, strict=False):
        q, score = _orient(img, calibration, p, float(np.median(L)) / 2, float(np.median(W)) / 2, fg - bg, st.arm)
        out.append(Detection(q, float(length), float(width), score))
    return out


def _angle_diff(a, b):
    return np.abs((np.asarray(a) - np.asarray(b) + np.pi) % (2 * np.pi) - np.pi)


def _identity_cost(ref, P, clear, sizes, L, W, st: TrackerSettings, position_weight: float = 1.0) -> np.ndarray:
    """``(n, k)`` cost of calling detection k robot i: distance plus heading turn against ``ref`` (the
    axis turn, heading mod pi, where the arm left front/back undecided: ``clear`` False), plus size
    mismatch when the robots' sizes differ."""
    n = len(L)
    cost = np.zeros((n, len(P)))
    if ref is not None:
        seen = np.all(np.isfinite(ref), axis=1)
        dist = np.hypot(ref[:, None, 0] - P[None, :, 0], ref[:, None, 1] - P[None, :, 1])
        d = _angle_diff(ref[:, None, 2], P[None, :, 2])
        dax = np.where(clear[None, :], d, np.minimum(d, np.pi - d))
        cost = position_weight * np.where(
            seen[:, None], np.nan_to_num(dist + st.heading_cost_um_per_rad * dax, nan=st.unseen_cost_um), st.unseen_cost_um)
    if np.ptp(L) > 0 or np.ptp(W) > 0:
        cost = cost + st.size_cost * (np.abs(L[:, None] - sizes[None, :, 0]) + st.width_weight * np.abs(W[:, None] - sizes[None, :, 1]))
    return cost


def locate(frame, scenario, calibration: Calibration, previous=None, *, settings: TrackerSettings | None = None) -> np.ndarray:
    """Poses ``(n, 3)`` (x_um, y_um, theta_rad in [0, 2 pi)) of the scenario's robots in a frame, in
    scenario order; a NaN row for a robot not found (SPEC 9.2).

    Parameters
    ----------
    frame:
        2-D grey image (uint8), rows downward.
    scenario:
        Gives the robots' body sizes (and their start poses, the identity reference when ``previous``
        is None).
    calibration:
        :class:`Calibration` of the camera.
    previous:
        The last poses ``(n, 3)`` (NaN rows allowed): identities are the Hungarian assignment closest
        to them, and a robot whose front/back the frame leaves undecided keeps the heading nearest to it.
        Without it the scenario's start poses break ties between robots of the same size.
    """
    st = settings or TrackerSettings()
    n = scenario.n
    L, W = scenario.lengths_um, scenario.widths_um
    img = _as_uint8(frame)
    if previous is not None:
        return _locate(img, L, W, calibration, np.asarray(previous, np.float64).reshape(n, 3), 1.0, st)
    return _locate(img, L, W, calibration, scenario.starts if scenario.has_starts else None, st.start_pose_weight, st)


def _locate(img, L, W, calibration, ref, weight: float, st: TrackerSettings) -> np.ndarray:
    from scipy.optimize import linear_sum_assignment

    n = len(L)
    P, sizes, bg, fg = _axes(img, calibration, L, W, ref, st)
    out = np.full((n, 3), np.nan)
    if not len(P):
        return out
    oriented = [_orient(img, calibration, p, float(np.median(L)) / 2, float(np.median(W)) / 2, fg - bg, st.arm) for p in P]
    P = np.array([q for q, _ in oriented])
    clear = np.array([score >= st.ambiguous_arm_frac for _, score in oriented])
    rows, cols = linear_sum_assignment(_identity_cost(ref, P, clear, sizes, L, W, st, weight))
    # refine with each robot's own size, then front/back from its arm
    refined, _ = _refine(img, calibration, bg, fg, P[cols], L[rows] / 2, W[rows] / 2, st)
    for i, p in zip(rows, refined, strict=True):
        q, score = _orient(img, calibration, p, L[i] / 2, W[i] / 2, fg - bg, st.arm)
        if score < st.ambiguous_arm_frac and ref is not None and np.all(np.isfinite(ref[i])):
            if _angle_diff(q[2], ref[i, 2]) > np.pi / 2:
                q[2] = _wrap(q[2] + np.pi)
        out[i] = q
    return out


def describe(poses: np.ndarray, names) -> list[dict[str, Any]]:
    """Rows for a poses table (file units: degrees)."""
    return [{"robot": nm, "x_um": float(p[0]), "y_um": float(p[1]), "heading_deg": float(np.degrees(p[2]))}
            for nm, p in zip(names, poses, strict=False)]
