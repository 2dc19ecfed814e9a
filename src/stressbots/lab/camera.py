"""The synthetic camera: renders robot poses by the image model of SPEC 9.2.

Background about 30 with Gaussian pixel noise; each body rectangle (L x W) about 200; its steering arm a
bar 8 um wide along the robot's right side (the side of its turning centre), from the rear edge forward
over 60 % of L, 6 um off the body; optical blur; robots missing from a frame with a dropout
probability. Edges are anti-aliased (each pixel is lit by the fraction of it a shape covers, to first
order), so a tracker can be judged to a fraction of a pixel.

>>> import numpy as np
>>> from stressbots.tracking import Calibration
>>> cam = Camera(Calibration(2.0, (0.0, 300.0)), (300, 400), ImageModel(noise_sd=0.0))
>>> f = cam.render(np.array([[300.0, 300.0, 0.0]]), [260.0], [60.0], np.random.default_rng(0))
>>> f.shape, f.dtype, int(f[150, 150]), int(f[5, 5])
((300, 400), dtype('uint8'), 200, 30)
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from ..tracking import ArmGeometry, Calibration

__all__ = ["ImageModel", "Camera", "frame_for_scenario", "shape_for"]


@dataclass(frozen=True)
class ImageModel:
    """Grey levels (0-255), noise and optics of the rendered frames (SPEC 9.2).

    Attributes
    ----------
    background, body, arm:
        Grey level of the substrate, a robot's body and its steering arm.
    noise_sd:
        Gaussian pixel noise (grey levels, sd).
    blur_um:
        Optical blur, Gaussian sd (um).
    dropout:
        Probability that a robot is missing from a frame (glare, out of focus).
    arm_geometry:
        Where the arm is drawn.
    """

    background: float = 30.0
    body: float = 200.0
    arm: float = 200.0
    noise_sd: float = 6.0
    blur_um: float = 1.5
    dropout: float = 0.0
    arm_geometry: ArmGeometry = field(default_factory=ArmGeometry)


def _ramp(d: np.ndarray, width_px: float, um_per_px: float) -> np.ndarray:
    """Fraction of a pixel inside an edge at signed distance ``d`` (um, positive inside)."""
    return np.clip(d / (width_px * um_per_px) + 0.5, 0.0, 1.0)


@dataclass(frozen=True)
class Camera:
    """Renders frames of ``shape = (rows, cols)`` through ``calibration`` with ``model``."""

    calibration: Calibration
    shape: tuple[int, int]
    model: ImageModel = field(default_factory=ImageModel)

    def coverage(self, poses, lengths_um, widths_um) -> tuple[np.ndarray, np.ndarray]:
        """Anti-aliased coverage ``(rows, cols)`` float32 of the bodies and of the arms (no blur, no noise)."""
        cal, arm = self.calibration, self.model.arm_geometry
        body_c = np.zeros(self.shape, np.float32)
        arm_c = np.zeros(self.shape, np.float32)
        upx = cal.um_per_px
        for p, L, W in zip(np.asarray(poses, np.float64), np.asarray(lengths_um, np.float64), np.asarray(widths_um, np.float64),
                           strict=True):
            if not np.all(np.isfinite(p)):
                continue
            hl, hw = L / 2, W / 2
            reach = math.hypot(hl, hw + arm.gap_um + arm.width_um) + 2 * upx
            c, r = cal.to_px(p[0], p[1])
            c0, c1 = max(0, int(c - reach / upx)), min(self.shape[1], int(c + reach / upx) + 2)
            r0, r1 = max(0, int(r - reach / upx)), min(self.shape[0], int(r + reach / upx) + 2)
            if c0 >= c1 or r0 >= r1:
                continue
            X, Y = cal.to_um(np.arange(c0, c1)[None, :], np.arange(r0, r1)[:, None])
            s, co = math.sin(p[2]), math.cos(p[2])
            u = (X - p[0]) * s + (Y - p[1]) * co  # along the heading
            w = (X - p[0]) * co - (Y - p[1]) * s  # to the right
            foot = abs(s) + abs(co)  # pixel footprint across a rotated edge (px)
            body = _ramp(hl - np.abs(u), foot, upx) * _ramp(hw - np.abs(w), foot, upx)
            a_len = arm.length_frac * L
            a_mid_u, a_mid_w = -hl + a_len / 2, hw + arm.gap_um + arm.width_um / 2
            bar = _ramp(a_len / 2 - np.abs(u - a_mid_u), foot, upx) * _ramp(arm.width_um / 2 - np.abs(w - a_mid_w), foot, upx)
            np.maximum(body_c[r0:r1, c0:c1], body, out=body_c[r0:r1, c0:c1])
            np.maximum(arm_c[r0:r1, c0:c1], bar, out=arm_c[r0:r1, c0:c1])
        return body_c, arm_c

    def render(self, poses, lengths_um, widths_um, rng: np.random.Generator) -> np.ndarray:
        """A uint8 frame of the robots at ``poses`` (um, rad); dropouts, blur and noise from ``rng``."""
        import cv2

        m = self.model
        poses = np.array(poses, np.float64).reshape(-1, 3)
        drop = rng.random(len(poses)) < m.dropout
        poses[drop] = np.nan
        body_c, arm_c = self.coverage(poses, lengths_um, widths_um)
        img: np.ndarray = np.float32(m.background) + np.float32(m.arm - m.background) * arm_c
        np.maximum(img, np.float32(m.background) + np.float32(m.body - m.background) * body_c, out=img)
        sigma_px = m.blur_um / self.calibration.um_per_px
        if sigma_px > 0.05:
            img = cv2.GaussianBlur(img, (0, 0), sigma_px)
        if m.noise_sd > 0:
            img += np.float32(m.noise_sd) * rng.standard_normal(self.shape, dtype=np.float32)
        return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _extent(scenario) -> tuple[float, float, float, float]:
    """``(x0, y0, x1, y1)`` (um) a camera should show: the arena, or every start and goal with 600 um around."""
    if scenario.arena_um is not None:
        return 0.0, 0.0, float(scenario.arena_um[0]), float(scenario.arena_um[1])
    pts = [scenario.starts[:, :2]] if scenario.has_starts else []
    try:
        pts.append(scenario.goals[:, :2])
    except Exception:  # noqa: BLE001 - no explicit goals: the starts frame the view
        pass
    allp = np.concatenate(pts) if pts else np.zeros((1, 2))
    (x0, y0), (x1, y1) = allp.min(axis=0) - 600.0, allp.max(axis=0) + 600.0
    return float(x0), float(y0), float(x1), float(y1)


def frame_for_scenario(scenario, um_per_px: float = 2.0, margin_um: float = 100.0) -> tuple[Calibration, tuple[int, int]]:
    """A calibration and frame shape that show the whole arena (or, without one, every start and goal
    with 600 um around them), ``margin_um`` beyond it on each side."""
    x0, y0, x1, y1 = _extent(scenario)
    cols = int(math.ceil((x1 - x0 + 2 * margin_um) / um_per_px))
    rows = int(math.ceil((y1 - y0 + 2 * margin_um) / um_per_px))
    origin = ((margin_um - x0) / um_per_px, rows - (margin_um - y0) / um_per_px)
    return Calibration(um_per_px, origin), (rows, cols)


def shape_for(scenario, calibration: Calibration, margin_um: float = 100.0) -> tuple[int, int]:
    """The frame shape ``(rows, cols)`` that reaches past the scenario's extent by ``margin_um`` in a
    given calibration (pixels before the origin are cut off: the calibration decides them)."""
    x0, y0, x1, y1 = _extent(scenario)
    cols, rows = calibration.to_px(np.array([x1 + margin_um]), np.array([y0 - margin_um]))
    return max(int(math.ceil(float(rows[0]))), 1), max(int(math.ceil(float(cols[0]))), 1)
