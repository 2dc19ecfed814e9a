"""Where a docking robot's front corners land on the structure: the face under a slot, and where the robot aims so
that docking compliance takes it.

Docking compliance (SPEC 6, seed App. 3.5) turns a robot flush only when one of its *front corners* meets a
structure edge; a robot whose front edge meets a structure *corner* instead is stuck (failure region H), and so
is one whose rotation about its corner is blocked by a part of the structure that stands further out. Which
corner leads depends on the sign of the robot's incidence (measured on an independent plant: either sign about as
often), so a robot arriving square needs both front corners on the face the slot rests on.

A slot's face is often barely wider than the robot: the rear edge of the robot ahead of it in a string of
heterogeneous robots (0.05-8 um wider on each side), a side face ending at the slot, or the sides of a G_1 pair of
two widths, which step by half their difference. Planned slots sit on the *nominal* structure, but every docked
robot sits a few um off its own slot, so a robot aimed at its planned slot meets the end of the real face: on an
independent plant at the literature's noise, 17 of 115 claimed successes on the tuning layouts (seed 0) left a robot
stuck off flush that the controller had counted as docked.

:func:`landing_pose` profiles the face under the slot from the docked bodies as measured (:func:`face_under`: its
ends, its steps, anything standing out) and picks the cheapest aim: the slot, moved along the face so that both
corners land inside, or the robot's pose at contact turned by a chosen incidence so that a known corner leads
(:func:`contact_pose`), each with its corners' margins; where none has them, the one whose corners keep the largest
share of their margins (:func:`landing_options`).

Everything here is a pure function of the slot, the robot's body and the measured docked bodies (um, rad).
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..collision import penetration_depth
from ..generate import LITERATURE_NOISE
from ..robots import body_corners
from ..se2 import heading, points_to_frame, right
from .queries import line_pose

__all__ = ["Face", "Landing", "aligned_pair", "contact_misalignment", "contact_pose", "corner_margins", "face_profile",
           "face_under", "incidence_deg", "landing_options", "landing_pose", "nearest_distance", "nearest_shift", "noise_scale"]

GRID_UM = 0.25
"""Lateral sampling of the face and of the slot's shifts (um): under a tenth of the landing margins."""

Bodies = tuple[np.ndarray, np.ndarray, np.ndarray]
"""Docked bodies: poses ``(m, 3)``, lengths ``(m,)``, widths ``(m,)`` (um, rad)."""


def face_profile(slot, length_um: float, bodies: Bodies, xs) -> np.ndarray:
    """Depth (um) of the structure's surface ahead of the slot's face line, at lateral positions ``xs``.

    The slot's frame has its origin at the slot's front-edge midpoint, ``x`` to the slot's right and ``y``
    ahead. For every ``x`` the value is the smallest ``y`` at which a docked body meets the line at ``x``
    (clipped at ``-length_um``: a body reaching into the robot's flush place counts as standing out by the
    whole length); ``+inf`` where no body does. 0 is level with the slot's face, > 0 recessed.

    >>> bodies = (np.array([[0.0, 225.0, 0.0]]), np.array([250.0]), np.array([70.0]))   # a robot ahead, 70 um wide
    >>> slot = np.array([0.0, 0.0, 0.0])                                                 # its front edge meets the rear
    >>> face_profile(slot, 200.0, bodies, np.array([0.0, 34.0, 36.0])).tolist()
    [0.0, 0.0, inf]
    """
    slot = np.asarray(slot, dtype=np.float64)
    xs = np.asarray(xs, dtype=np.float64)
    poses, lengths, widths = bodies
    if len(poses) == 0:
        return np.full(xs.shape, np.inf)
    front = slot.copy()
    front[:2] = slot[:2] + 0.5 * length_um * heading(slot[2])
    quads = points_to_frame(front, body_corners(poses, lengths, widths))       # (m, 4, 2) in the slot frame
    a, b = quads, np.roll(quads, -1, axis=1)                                    # edges a -> b
    dx = b[..., 0] - a[..., 0]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (xs[None, None, :] - a[..., 0, None]) / dx[..., None]              # (m, 4, k)
    on = (t >= 0.0) & (t <= 1.0) & (np.abs(dx)[..., None] > 1e-12)
    y = np.where(on, a[..., 1, None] + t * (b[..., 1] - a[..., 1])[..., None], np.nan)
    hit = on.any(axis=1)                                                        # (m, k)
    y_in = np.where(hit, np.nanmin(np.where(on, y, np.inf), axis=1), np.inf)
    y_out = np.where(hit, np.nanmax(np.where(on, y, -np.inf), axis=1), -np.inf)
    reaches = hit & (y_out > -length_um)
    return np.where(reaches, np.maximum(y_in, -length_um), np.inf).min(axis=0)


class Face(NamedTuple):
    """The face a slot rests on, sampled on an even lateral grid ``xs`` (um) of the slot's frame."""

    xs: np.ndarray
    depth: np.ndarray
    """:func:`face_profile` on ``xs``."""
    on: np.ndarray
    """Grid points on the face: within the level tolerance of its highest point under the slot's front edge (bool)."""
    proud: np.ndarray
    """Grid points where something stands further out than the face (bool)."""
    level: float
    """The face's depth (um): the highest point under the slot's front edge."""
    step_right: np.ndarray
    """Grid points after which the face steps *out* (toward the robot) going right by more than the step tolerance:
    a corner landing left of such a step and turning flush meets it (the side of the wider robot of a G_1 pair)."""
    step_left: np.ndarray
    """Grid points after which the face steps out going left."""

    def steps(self, lead: int) -> np.ndarray:
        """The steps a robot's rotation to flush may meet (bool per grid point): every step for a robot that may arrive
        turned either way (``lead`` 0), those beyond its leading corner for one whose left (+1) or right (-1) leads."""
        return self.step_right if lead > 0 else self.step_left if lead < 0 else self.step_right | self.step_left

    @property
    def half_step(self) -> float:
        """Half the grid's spacing (um): where a step between two samples lies."""
        return 0.5 * float(self.xs[1] - self.xs[0]) if len(self.xs) > 1 else 0.0

    def signed(self, lead: int) -> np.ndarray:
        """Signed distance (um) of each grid point to the nearest end of the face a corner may land on: + on it, - off
        it. The steps its rotation may meet (:meth:`steps`) are ends too."""
        ends = np.sort(np.concatenate([self.xs[~self.on], self.xs[self.steps(lead)] + self.half_step]))
        return np.where(self.on, nearest_distance(self.xs, ends), -nearest_distance(self.xs, self.xs[self.on]))


def nearest_distance(xs: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Distance from each of ``xs`` to the nearest of the sorted ``points`` (``inf`` when there are none).

    >>> nearest_distance(np.array([0.0, 2.0, 9.0]), np.array([1.0, 5.0])).tolist()
    [1.0, 1.0, 4.0]
    """
    if points.size == 0:
        return np.full(xs.shape, np.inf)
    k = np.clip(np.searchsorted(points, xs), 1, len(points) - 1) if len(points) > 1 else np.zeros(xs.shape, dtype=int)
    below = np.abs(xs - points[k - 1]) if len(points) > 1 else np.full(xs.shape, np.inf)
    return np.minimum(below, np.abs(xs - points[k]))


def face_under(slot, length_um: float, width_um: float, bodies: Bodies, tune, reach_um: float,
               grid_um: float = GRID_UM) -> Face | None:
    """The face under a slot (:class:`Face`) out to ``reach_um`` either side of its centre line; None when no docked
    body is ahead of the slot's front edge. ``tune``: ``landing_level_tol_um``, ``landing_step_um``."""
    xs = np.arange(-reach_um, reach_um + 0.5 * grid_um, grid_um)
    depth = face_profile(slot, length_um, bodies, xs)
    span = np.abs(xs) <= 0.5 * width_um + 1e-9
    level = float(depth[span].min()) if span.any() else math.inf
    if not math.isfinite(level):
        return None
    on = np.abs(depth - level) <= tune.landing_level_tol_um
    both = on[:-1] & on[1:]
    with np.errstate(invalid="ignore"):
        rise = np.append(np.where(both, depth[:-1] - depth[1:], 0.0), 0.0)   # > 0: the next point stands further out
    return Face(xs, depth, on, depth < level - tune.landing_level_tol_um, level,
                rise > tune.landing_step_um, rise < -tune.landing_step_um)


def corner_margins(face: Face, width_um: float, shifts, lead: int = 0,
                   incidence_rad: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """For each candidate shift ``o`` (um, + = right) of the slot: how far (um) inside the face its left and its right
    front corner land, ``(left (k,), right (k,))``; negative where a corner misses the face (:meth:`Face.signed`).
    Arriving turned (``lead`` +-1), the trailing corner's value is instead its room to the nearest part of the
    structure standing out beyond it (a neighbour beside the slot, or a step of the face such as the side of the wider
    member of a G_1 pair): where the leading corner lands decides where the trailing one ends, and a landing error
    toward that neighbour or step blocks the rotation to flush.

    ``lead`` 0: the robot may arrive turned either way, so either corner may lead; +1: it arrives turned clockwise by
    ``incidence_rad``, its left corner first; -1: anticlockwise, its right corner first. Both are ``-inf`` where the
    shifted slot cannot be docked in that way: something in the robot's flush span stands further out than the face
    (it would not fit), a step its rotation would meet lies in the span, or, arriving turned, its trailing long side
    would meet a body on the way in (its rear is ``L sin(incidence)`` to that side).
    """
    xs, shifts = face.xs, np.asarray(shifts, dtype=np.float64)
    signed, steps, half = face.signed(lead), face.steps(lead), face.half_step
    left, right_ = shifts - 0.5 * width_um, shifts + 0.5 * width_um          # (k,) corners
    x = xs[None, :]
    blocked = (np.any(face.proud & (x >= left[:, None] - 1e-9) & (x <= right_[:, None] + 1e-9), axis=1)
               | np.any(steps & (x + half > left[:, None]) & (x + half < right_[:, None]), axis=1))
    tan = math.tan(incidence_rad)
    if lead and tan > 0.0:  # the trailing side: behind the leading corner by (distance beyond it) / tan
        beyond = (left[:, None] - x) if lead > 0 else (x - right_[:, None])
        blocked |= np.any((beyond > 0.0) & (face.depth[None, :] < face.level - beyond / tan), axis=1)
    lm, rm = np.interp(left, xs, signed), np.interp(right_, xs, signed)
    if lead:  # the trailing corner ends where the leading one puts it: its room is to whatever stands out beyond it,
        # a step the rotation to flush would meet included (the side of the wider member of a G_1 pair)
        proud = np.sort(np.concatenate([xs[face.proud], xs[steps] + half]))
        if lead > 0:
            k = np.searchsorted(proud, right_)
            rm = np.where(k < len(proud), proud[np.minimum(k, len(proud) - 1)] - right_, np.inf) if len(proud) else np.full(k.shape, np.inf)
        else:
            k = np.searchsorted(proud, left, side="right") - 1
            lm = np.where(k >= 0, left - proud[np.maximum(k, 0)], np.inf) if len(proud) else np.full(k.shape, np.inf)
    return np.where(blocked, -np.inf, lm), np.where(blocked, -np.inf, rm)


def nearest_shift(shifts: np.ndarray, ok: np.ndarray) -> float | None:
    """The least shift (um) where ``ok``; None if nowhere."""
    order = np.argsort(np.abs(shifts), kind="stable")
    good = order[ok[order]]
    return float(shifts[good[0]]) if good.size else None


class Landing(NamedTuple):
    """Where a docking robot aims (:func:`landing_pose`) and where it then ends."""

    aim: np.ndarray
    """The pose (3,) it steers to: its slot, moved along the face, or its pose at contact turned by a chosen incidence."""
    slot: np.ndarray
    """Where docking compliance leaves it (3,): ``aim`` but for a chosen incidence, flush on the face."""
    note: str
    """What was chosen, for the event log; empty when the slot stays as it is."""


def landing_pose(slot, length_um: float, width_um: float, bodies: Bodies, tune, scale: float = 1.0) -> Landing:
    """Where a docking robot should aim so that docking compliance takes it (:class:`Landing`).

    The choices (:func:`landing_options`; ``tune``: :class:`~stressbots.control.tuning.DockingTuning` ``landing_*``
    fields, margins times ``scale`` (:func:`noise_scale`), shifts at most ``landing_max_shift_um``):

    - the slot moved along its face (not at all where it can stay), the least that lands both front corners
      ``landing_left_margin_um`` / ``landing_right_margin_um`` inside it, whichever way the robot arrives turned;
    - a *chosen incidence*: the robot arrives turned by ``landing_incidence_deg`` clockwise, its left corner first,
      or by ``landing_incidence_anticlockwise_deg`` anticlockwise, its right corner first, its leading corner its own
      margin (``landing_lead_*_margin_um``) inside the face, the least shift from the slot. The pose returned is the
      robot's at contact: heading turned by the incidence, leading front corner on the face. The line approach,
      aiming at it, brings the robot in on that heading; compliance turns it flush about that corner. The rear edge
      of a robot of the same width has room for one corner, not for both, and a face that steps out (the sides of a
      G_1 pair of two widths) takes a corner on its outer part only. It counts as ``landing_incidence_cost_um`` of
      shift;

    the cheapest wins. Where no choice has its margins (a narrow face, or margins doubled at twice the noise), the
    *safest* does: the option and shift whose corners keep the largest share of their margins (:func:`landing_options`'
    safety); a corner given half its margin misses the face far less often than a centred robot, either of whose
    corners may lead with none. With no corner on the face at all, the slot.
    """
    slot = np.asarray(slot, dtype=np.float64)
    turned = max(incidence_deg(tune, +1), incidence_deg(tune, -1))
    reach = tune.landing_max_shift_um + width_um + length_um * math.sin(math.radians(turned)) + 5.0
    face = face_under(slot, length_um, width_um, bodies, tune, reach)
    if face is None or tune.landing_max_shift_um <= 0.0:
        return Landing(slot, slot, "")
    shifts = np.arange(-tune.landing_max_shift_um, tune.landing_max_shift_um + 0.5 * GRID_UM, GRID_UM)
    options = landing_options(face, width_um, shifts, tune, scale)
    choices = [(abs(o) + (tune.landing_incidence_cost_um if lead else 0.0), lead, o)
               for lead, meets, _ in options for o in [nearest_shift(shifts, meets)] if o is not None]
    why = "room for that corner, not for both (or steps out)"
    if choices:
        _, lead, o = min(choices, key=lambda c: c[0])
    else:
        lead, _, safe = max(options, key=lambda opt: float(opt[2].max()))
        safety = float(safe.max())
        best = nearest_shift(shifts, safe >= safety)
        if safety <= 0.0 or best is None:
            return Landing(slot, slot, "")
        o = best
        why = f"too little room for its margins: the safest landing keeps {safety:.0%} of them"
    moved = line_pose(slot, 0.0, o, 0.0)  # the slot moved o um along its face
    if lead == 0:
        return Landing(slot, slot, "") if o == 0.0 else Landing(
            moved, moved, f"moves {abs(o):.1f} um {'right' if o > 0 else 'left'} along its face: both front corners then land on it"
            + ("" if choices else f" ({why})"))
    deg = incidence_deg(tune, lead)
    return Landing(contact_pose(slot, length_um, width_um, o, face.level, lead, math.radians(deg)), moved,
                   f"is reached turned {deg:g} deg {'clockwise' if lead > 0 else 'anticlockwise'}, "
                   f"{'left' if lead > 0 else 'right'} front corner first, {o:+.1f} um along its face: its face has {why}")


def incidence_deg(tune, lead: int) -> float:
    """The chosen incidence (deg) of a robot whose left (``lead`` +1: turned clockwise) or right (-1: anticlockwise)
    front corner is to lead (``Tuning.landing_incidence_deg`` / ``landing_incidence_anticlockwise_deg``)."""
    return tune.landing_incidence_deg if lead > 0 else tune.landing_incidence_anticlockwise_deg


def landing_options(face: Face, width_um: float, shifts: np.ndarray, tune, scale: float):
    """For both corners on the face (lead 0) and each chosen incidence (+1 left corner first, -1 right), over the
    candidate ``shifts``: ``(lead, meets (k,), safety (k,))``. ``meets``: both corners have their margins (times
    ``scale``, at least ``landing_min_margin_um``; one grid step of slack: the face's ends are known to the grid);
    ``safety``: the least share of its margin a corner
    keeps (1 = all of it, <= 0: a corner off the face). A corner leading alone has its own margin
    (``landing_lead_*_margin_um``); a trailing one, its room to what stands out beyond it."""
    need = {0: (tune.landing_left_margin_um, tune.landing_right_margin_um),
            +1: (tune.landing_lead_left_margin_um, tune.landing_right_margin_um),
            -1: (tune.landing_left_margin_um, tune.landing_lead_right_margin_um)}
    out = []
    for lead in (0, +1, -1):
        psi = math.radians(incidence_deg(tune, lead)) if lead else 0.0
        lm, rm = corner_margins(face, width_um, shifts, lead, psi)
        ml, mr = (max(m * scale, tune.landing_min_margin_um) for m in need[lead])
        meets = (lm >= ml - GRID_UM) & (rm >= mr - GRID_UM)
        with np.errstate(invalid="ignore"):
            safe = np.minimum(lm / max(ml, GRID_UM), rm / max(mr, GRID_UM))
        out.append((lead, meets, np.nan_to_num(safe, nan=-np.inf)))
    return out


def contact_pose(slot, length_um: float, width_um: float, shift_um: float, level_um: float, lead: int,
                 incidence_rad: float) -> np.ndarray:
    """The pose (3,) of a robot turned by ``lead * incidence_rad`` (+ = clockwise) from the slot's heading whose leading
    front corner (left for ``lead`` +1, right for -1) touches the face ``level_um`` ahead of the slot's front edge where
    the slot moved ``shift_um`` along it has that corner; compliance turns it flush about that corner into that slot.

    >>> p = contact_pose(np.array([0.0, 0.0, 0.0]), 200.0, 60.0, 0.0, 0.0, +1, math.radians(4.0))
    >>> from stressbots.robots import body_corners
    >>> np.round(body_corners(p, 200.0, 60.0)[0, 0], 9).tolist()     # its front-left corner: the slot's
    [-30.0, 100.0]
    """
    slot = np.asarray(slot, dtype=np.float64)
    h, r = heading(slot[2]), right(slot[2])
    corner = slot[:2] + (0.5 * length_um + level_um) * h + (shift_um - lead * 0.5 * width_um) * r
    th = slot[2] + lead * incidence_rad
    centre = corner - 0.5 * length_um * heading(th) + lead * 0.5 * width_um * right(th)
    return np.array([centre[0], centre[1], np.mod(th, 2.0 * math.pi)])


def aligned_pair(pose_a, pose_b, length_a_um: float, length_b_um: float) -> np.ndarray:
    """The G_1 pair ``(2, 3)`` as self-aligning compliance leaves it (SPEC 6): collinear, front edges flush, about the
    measured pair (the mean of both axes, the midpoint of both front-edge midpoints). The camera's independent errors
    on the two members would otherwise make a step of a few tenths of a um between their sides, or hide a real one.

    >>> a, b = np.array([0.0, -100.0, 0.01]), np.array([0.5, 100.0, math.pi - 0.01])   # slightly off, 200 um long
    >>> p = aligned_pair(a, b, 200.0, 200.0)
    >>> np.round(p[:, :2], 4).tolist()                  # on one axis, front edges meeting at the midpoint
    [[1.25, -100.0], [1.25, 100.0]]
    >>> round(math.degrees(abs(math.sin(p[0, 2] - p[1, 2]))), 9)   # opposed headings
    0.0
    """
    a, b = np.asarray(pose_a, dtype=np.float64), np.asarray(pose_b, dtype=np.float64)
    fa, fb = a[:2] + 0.5 * length_a_um * heading(a[2]), b[:2] + 0.5 * length_b_um * heading(b[2])
    axis = heading(a[2]) + heading(b[2] + math.pi)
    th = math.atan2(axis[0], axis[1])
    mid = 0.5 * (fa + fb)
    u = heading(th)
    return np.array([[*(mid - 0.5 * length_a_um * u), np.mod(th, 2.0 * math.pi)],
                     [*(mid + 0.5 * length_b_um * u), np.mod(th + math.pi, 2.0 * math.pi)]])


def contact_misalignment(pose, length_um: float, width_um: float, bodies: Bodies, reach_um: float) -> tuple[float, int] | None:
    """How far (rad) a stopped robot is turned from flush: its heading against the edges of the docked bodies its front
    edge touches, modulo a quarter turn (any edge of a body can be a face), the smallest over those bodies, with that
    body's index in ``bodies``; None when no body comes within ``reach_um`` of its front edge.

    Docking compliance leaves a docked robot exactly parallel to the edge it docked on (SPEC 6); one whose front edge
    met a corner of the structure instead stops turned by its incidence (failure region H), within the docking
    tolerances of its slot all the same. A still robot's mean heading tells the two apart where its position cannot.

    >>> bodies = (np.array([[0.0, 250.0, 0.0]]), np.array([250.0]), np.array([70.0]))   # a robot's rear edge at y = 125
    >>> contact_misalignment(np.array([0.0, 0.0, 0.0]), 250.0, 70.0, bodies, 5.0)
    (0.0, 0)
    >>> round(contact_misalignment(np.array([3.0, -2.0, 0.03]), 250.0, 70.0, bodies, 5.0)[0], 6)
    0.03
    >>> contact_misalignment(np.array([0.0, -50.0, 0.0]), 250.0, 70.0, bodies, 5.0) is None   # 50 um short of the face
    True
    """
    pose = np.asarray(pose, dtype=np.float64)
    poses, lengths, widths = bodies
    if len(poses) == 0:
        return None
    probe = pose.copy()  # a strip reach_um deep on either side of the front edge
    probe[:2] = pose[:2] + 0.5 * length_um * heading(pose[2])
    touch = penetration_depth(probe, 2.0 * reach_um, width_um, poses, lengths, widths) > 0.0
    if not touch.any():
        return None
    quarter = 0.5 * math.pi
    off = np.mod(pose[2] - np.asarray(poses)[:, 2] + 0.5 * quarter, quarter) - 0.5 * quarter
    j = int(np.flatnonzero(touch)[np.argmin(np.abs(off[touch]))])
    return float(off[j]), j


def noise_scale(noise) -> float:
    """How many times the literature's error levels a scenario's declared ``[noise]`` is, for what decides where a
    docking robot lands (heading drift, camera position and heading): the largest of the three ratios. The landing
    margins (``Tuning.landing_*_margin_um``, measured at the literature's noise) scale with it: with no declared noise
    a docked robot sits exactly in its slot, and a margin would only move slots for nothing.

    >>> noise_scale(LITERATURE_NOISE)
    1.0
    """
    ref = LITERATURE_NOISE
    return max(noise.heading_drift_rad_per_um / ref.heading_drift_rad_per_um,
               noise.camera_position_sd_um / ref.camera_position_sd_um,
               noise.camera_heading_sd_rad / ref.camera_heading_sd_rad)
