"""How well a run assembled its structure: placement errors, shape error after a best rigid alignment.

SPEC 6: a run succeeds when every robot is docked and the assembled shape matches the target within a
tolerance *after a best rigid alignment* (the pair may legitimately end rotated by self-alignment, and
then the whole structure with it); the absolute placement error is reported beside it.

Shape error metric: the RMS distance (um) between corresponding body corners (4 per robot) of the final
and the target poses, after the proper rigid motion (rotation + translation, no reflection) that
minimises it (2-D Kabsch). Corners rather than centres, so a robot turned in place counts (by about
its half-length times the angle), in um like everything else.

Used by ``stressbots simulate`` (open loop) and by the closed-loop controller's reports.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from .robots import Pose, angle_difference, body_corners

__all__ = ["SHAPE_TOL_UM", "ShapeError", "Assessment", "kabsch_2d", "shape_error", "placement_errors", "assess"]

SHAPE_TOL_UM = 10.0
"""Default success tolerance on the RMS shape error (um): the closed-loop target of issue 6."""


def kabsch_2d(source, target, weights=None) -> tuple[np.ndarray, np.ndarray]:
    """The proper rigid motion that best maps ``source`` points onto ``target`` (least squares).

    Parameters
    ----------
    source, target : array_like, shape (K, 2)
        Corresponding points (um).
    weights : array_like, shape (K,), optional
        Non-negative weights (default equal).

    Returns
    -------
    rotation : ndarray (2, 2)
        Proper rotation matrix (det +1).
    translation : ndarray (2,)
        So that ``source @ rotation.T + translation`` is closest to ``target``.
    """
    p = np.asarray(source, dtype=np.float64).reshape(-1, 2)
    q = np.asarray(target, dtype=np.float64).reshape(-1, 2)
    w = np.ones(len(p)) if weights is None else np.asarray(weights, dtype=np.float64).reshape(-1)
    w = w / w.sum()
    pc, qc = w @ p, w @ q
    # 2-D closed form of Kabsch: the angle maximising sum w (R p') . q'
    a, b = p - pc, q - qc
    s_cos = float(np.sum(w * (a[:, 0] * b[:, 0] + a[:, 1] * b[:, 1])))
    s_sin = float(np.sum(w * (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0])))
    phi = math.atan2(s_sin, s_cos)  # counter-clockwise (math convention)
    c, s = math.cos(phi), math.sin(phi)
    rot = np.array([[c, -s], [s, c]])
    return rot, qc - rot @ pc


@dataclass(frozen=True)
class ShapeError:
    """Shape error after the best rigid alignment of the final bodies onto the target bodies.

    Attributes
    ----------
    rms_um, max_um:
        RMS and largest corner distance (um) after alignment.
    rotation_deg:
        Rotation of that alignment, final -> target, in the heading convention (clockwise positive).
    translation_um:
        Its translation (um), applied after the rotation about the origin.
    """

    rms_um: float
    max_um: float
    rotation_deg: float
    translation_um: tuple[float, float]

    def as_dict(self) -> dict[str, Any]:
        return {
            "metric": "RMS distance of corresponding body corners after the best proper rigid alignment (2-D Kabsch)",
            "rms_um": self.rms_um,
            "max_um": self.max_um,
            "rotation_deg": self.rotation_deg,
            "translation_um": list(self.translation_um),
        }


def shape_error(final, goals, lengths_um, widths_um) -> ShapeError:
    """Shape error (see module doc) of final poses ``(n, 3)`` against target poses ``(n, 3)`` (um, rad)."""
    f = body_corners(np.asarray(final, dtype=np.float64), lengths_um, widths_um).reshape(-1, 2)
    g = body_corners(np.asarray(goals, dtype=np.float64), lengths_um, widths_um).reshape(-1, 2)
    rot, t = kabsch_2d(f, g)
    d = np.hypot(*(f @ rot.T + t - g).T)
    ccw = math.atan2(rot[1, 0], rot[0, 0])
    return ShapeError(float(np.sqrt(np.mean(d**2))), float(d.max()), -math.degrees(ccw), (float(t[0]), float(t[1])))


def placement_errors(final, goals) -> tuple[np.ndarray, np.ndarray]:
    """Absolute errors per robot: centre distance (um) and |heading difference| (deg)."""
    f = np.asarray(final, dtype=np.float64).reshape(-1, 3)
    g = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
    pos = np.hypot(f[:, 0] - g[:, 0], f[:, 1] - g[:, 1])
    head = np.degrees(np.abs(np.asarray(angle_difference(f[:, 2], g[:, 2]), dtype=np.float64)))
    return pos, head


@dataclass(frozen=True)
class Assessment:
    """Outcome of a run against its target structure (scenario order throughout)."""

    success: bool
    names: tuple[str, ...]
    final: np.ndarray
    goals: np.ndarray
    docked: np.ndarray
    position_error_um: np.ndarray
    heading_error_deg: np.ndarray
    shape: ShapeError
    shape_tol_um: float

    @property
    def all_docked(self) -> bool:
        return bool(np.all(self.docked))

    def robot_rows(self, observed=None) -> list[dict[str, Any]]:
        """Per-robot rows of result.json (SPEC 7): poses as ``[x_um, y_um, heading_deg]``."""
        rows = []
        for k, name in enumerate(self.names):
            row: dict[str, Any] = {
                "name": name,
                "final": Pose(*self.final[k]).to_degrees(),
                "goal": Pose(*self.goals[k]).to_degrees(),
                "docked": bool(self.docked[k]),
                "position_error_um": float(self.position_error_um[k]),
                "heading_error_deg": float(self.heading_error_deg[k]),
            }
            if observed is not None:
                obs = np.asarray(observed, dtype=np.float64)[k]
                row["observed"] = None if np.isnan(obs).any() else Pose(*obs).to_degrees()
            rows.append(row)
        return rows

    def summary(self) -> dict[str, Any]:
        return {
            "success": self.success,
            "all_docked": self.all_docked,
            "shape_error": {**self.shape.as_dict(), "tolerance_um": self.shape_tol_um},
            "max_position_error_um": float(np.max(self.position_error_um)),
            "max_heading_error_deg": float(np.max(self.heading_error_deg)),
        }


def assess(
    names: Sequence[str],
    final,
    goals,
    docked,
    lengths_um,
    widths_um,
    *,
    shape_tol_um: float = SHAPE_TOL_UM,
) -> Assessment:
    """Judge a run: success = every robot docked and RMS shape error <= ``shape_tol_um``."""
    final = np.asarray(final, dtype=np.float64).reshape(-1, 3)
    goals = np.asarray(goals, dtype=np.float64).reshape(-1, 3)
    docked = np.asarray(docked, dtype=bool).reshape(-1)
    if np.isnan(goals).any():
        raise ValueError("every robot needs a goal pose to be assessed")
    pos, head = placement_errors(final, goals)
    shape = shape_error(final, goals, lengths_um, widths_um)
    ok = bool(docked.all() and shape.rms_um <= shape_tol_um)
    return Assessment(ok, tuple(names), final, goals, docked, pos, head, shape, float(shape_tol_um))
