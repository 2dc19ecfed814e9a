"""An independent plant: SPEC.md's robot model written again, without the project's simulator.

Outside checkers run :func:`stressbots.control.assemble` through the Plant protocol (SPEC 6) on a plant
of their own. Our controller was tuned against our simulator (``stressbots.sim``), so a second plant,
written from SPEC 3, 4 and 6 alone, tells how much of the closed loop's success is the controller and how
much is a flattering plant. This module imports neither ``stressbots.sim`` nor ``stressbots.collision``,
``stressbots.kinematics`` or the controller: only the scenario's value types and the waveform segments.

What it models (SPEC 3, 4, 6), with the choices SPEC leaves open marked *choice*:

- **Arms**: hysteresis per level (``s = 1`` if ``V >= V_d``, ``s = 0`` if ``V <= V_u``, else kept). A
  ``Hold`` applies its level and moves nothing. A ``Drive`` applies ``high_V`` then ``low_V`` (the square
  wave's half periods); *choice*: an arm the band itself flips both ways (chatter) keeps the state of
  the last half period (``low_V``).
- **Motion**: arm up straight at the robot's speed, arm down a clockwise arc of its radius, both in
  closed form per sub-step. *choice*: sub-steps of at most :attr:`PlantSettings.substep_um` of travel;
  within a sub-step the robots move one after the other in a random order (a fresh permutation per
  sub-step from its own stream), each against the others' current bodies (Gauss-Seidel, not a
  simultaneous update).
- **Control error**: per-run speed and radius factors ``1 + N(0, sd)``; heading drift per robot = a
  bias ``b ~ N(0, sigma_b)`` (rad/um) drawn once plus a random walk with variance ``sigma_w^2`` per um
  of distance actually travelled; *choice*: half of the SPEC's variance over 1 mm in each part, so
  ``Var(dtheta over s) = sigma_b^2 s^2 + sigma_w^2 s`` equals ``drift^2`` at ``s`` = 1 mm whatever the
  cut. Drift acts on every travelled um (straight and arc). Camera: Gaussian position and heading
  noise, dropouts as NaN rows; *choice*: headings reported wrapped to ``[0, 2 pi)`` (SPEC 2 allows it).
- **Contact**: bodies are L x W rectangles (separating-axis test, own code). A moving body whose
  sub-step would overlap another body or leave the arena stops at contact (bisection on the fraction of
  the sub-step); it stays while the command pushes into the obstacle and leaves when the motion takes
  it away. *choice*: nobody pushes anybody (bodies are immovable to each other).
- **Docking compliance**: a robot driving straight whose front corner meets an edge of a *structure*
  body (a G_1 member or a docked robot) with its heading within +-45 deg of that edge's inward normal
  rotates about the contact point until flush; *choice*: gradually, the free corner advancing at the
  drive, ``dtheta/ds = 1 / W`` (45 deg in ~47 um of drive for W = 60), not instantly. A robot whose
  front edge rests flush on a structure edge joins the structure (it is docked), also one that arrives
  flush while turning (SPEC 6); a turning robot is otherwise just blocked (it pivots on its stylus).
  *choice*: no slides or grazes: a corner outside the cone, or on a long side, is stuck until the
  motion takes it away; compliance acts only against the structure, not against stopped free robots.
- **G_1**: two free robots meeting front to front (the contact point, the corner of either body nearest
  the other, in the front half of both: front edges, corner to corner, or a corner on the other's long
  side near its front; any arm states) with incidence ``|alpha| < 60 deg`` and lateral offset
  ``|w_y| < 80 um`` (between the front-edge centres, across the meeting axis ``u = h_a - h_b``) snap
  collinear and flush about the midpoint of their front-edge centres (instantly) and then move as one
  bar: *choice*: their pushes along the bar cancel (scratch drives stall head-on), the bar turns about
  its centre at the mean of the members' turn rates and translates by the mean of their sideways motion.

Everything random comes from ``np.random.SeedSequence(seed)`` split into named streams: the same seed
gives a bit-identical run.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from stressbots.waveform import Drive, Hold

__all__ = ["PlantSettings", "IndependentPlant", "corners", "penetration", "settle_arms", "arc_or_line", "rigid_rms"]

TWO_PI = 2.0 * math.pi
WALL = -1
"""Obstacle index of the arena boundary."""


@dataclass(frozen=True)
class PlantSettings:
    """The independent plant's own modelling choices (um, rad).

    Attributes
    ----------
    substep_um:
        Largest travel of any robot in one sub-step (contacts are then found by bisection).
    contact_tol_um:
        Penetration depth below which two bodies are touching, not overlapping.
    bisect_steps:
        Bisection steps locating a contact within a sub-step (4 um / 2^14 ~ 0.2 nm).
    probe_um:
        A body blocked within this much travel does not move in that sub-step (no bisection): a robot
        pushing against an obstacle costs two contact tests, not sixteen. While neither it nor the
        obstacle moves and its arm keeps its state, it is not tested again (it stays blocked).
    touch_um:
        Largest gap between two front edges that counts as front-to-front contact (G_1).
    flush_rad:
        A docking robot this close to flush joins the structure (0.5 deg).
    dock_cone_rad, g1_alpha_rad, g1_wy_um:
        SPEC 6 limits: sticking cone +-45 deg; G_1 incidence 60 deg and lateral 80 um.
    drift_bias_share:
        Share of the heading drift's variance over 1 mm carried by the per-run bias (rest: random walk).
    """

    substep_um: float = 4.0
    contact_tol_um: float = 0.01
    bisect_steps: int = 14
    probe_um: float = 0.05
    touch_um: float = 1.0
    flush_rad: float = math.radians(0.5)
    dock_cone_rad: float = math.radians(45.0)
    g1_alpha_rad: float = math.radians(60.0)
    g1_wy_um: float = 80.0
    drift_bias_share: float = 0.5


# ---------------------------------------------------------------------------------------------- geometry
def heading(theta) -> np.ndarray:
    """Heading vectors ``(sin theta, cos theta)`` (theta clockwise from +y), shape ``(..., 2)``."""
    theta = np.asarray(theta, dtype=np.float64)
    return np.stack([np.sin(theta), np.cos(theta)], axis=-1)


def corners(poses, L, W) -> np.ndarray:
    """Body corners ``(m, 4, 2)``: front-left, front-right, rear-right, rear-left (um)."""
    p = np.atleast_2d(np.asarray(poses, dtype=np.float64))
    h = heading(p[:, 2])
    rt = np.stack([h[:, 1], -h[:, 0]], axis=-1)  # unit vector to the robot's right
    a = (np.asarray(L, dtype=np.float64).reshape(-1) / 2.0)[:, None] * h
    b = (np.asarray(W, dtype=np.float64).reshape(-1) / 2.0)[:, None] * rt
    c = p[:, None, :2]
    return np.stack([c[:, 0] + a - b, c[:, 0] + a + b, c[:, 0] - a + b, c[:, 0] - a - b], axis=1)


def one_body(pose, L: float, W: float) -> np.ndarray:
    """:func:`corners` of one body ``(4, 2)``, in scalar arithmetic (the plant's inner loop calls it most)."""
    x, y, t = float(pose[0]), float(pose[1]), float(pose[2])
    hx, hy = math.sin(t) * L / 2, math.cos(t) * L / 2
    rx, ry = math.cos(t) * W / 2, -math.sin(t) * W / 2
    return np.array([[x + hx - rx, y + hy - ry], [x + hx + rx, y + hy + ry],
                     [x - hx + rx, y - hy + ry], [x - hx - rx, y - hy - ry]])


def penetration(one: np.ndarray, many: np.ndarray) -> np.ndarray:
    """Separating-axis penetration depth (um) of rectangle ``one`` (4, 2) into each of ``many`` (m, 4, 2).

    Positive: the bodies overlap that deep; zero or negative: they are apart (minus the gap along the
    best separating axis of the four edge normals).
    """
    if many.shape[0] == 0:
        return np.zeros(0)
    ax1 = one[[1, 0]] - one[[2, 1]]  # the body's own two axes (along h, across)
    ax1 = ax1 / np.linalg.norm(ax1, axis=1, keepdims=True)
    ax2 = np.stack([many[:, 1] - many[:, 2], many[:, 0] - many[:, 1]], axis=1)
    ax2 = ax2 / np.linalg.norm(ax2, axis=2, keepdims=True)
    axes = np.concatenate([np.broadcast_to(ax1, (many.shape[0], 2, 2)), ax2], axis=1)  # (m, 4, 2)
    pa = np.einsum("mkd,cd->mkc", axes, one)
    pb = np.einsum("mkd,mcd->mkc", axes, many)
    overlap = np.minimum(pa.max(2), pb.max(2)) - np.maximum(pa.min(2), pb.min(2))
    return overlap.min(axis=1)


def wall_penetration(body: np.ndarray, arena) -> float:
    """How far (um) body corners ``(4, 2)`` stick out of the arena (0 inside; always 0 without walls)."""
    if arena is None:
        return 0.0
    out = np.maximum(np.maximum(-body, body - np.asarray(arena, dtype=np.float64)), 0.0)
    return float(out.max())


def rotate_cw(vec: np.ndarray, dtheta: float) -> np.ndarray:
    """Vectors ``(..., 2)`` turned clockwise by ``dtheta`` (so ``heading(t)`` becomes ``heading(t + dtheta)``)."""
    c, s = math.cos(dtheta), math.sin(dtheta)
    return np.stack([c * vec[..., 0] + s * vec[..., 1], -s * vec[..., 0] + c * vec[..., 1]], axis=-1)


def arc_or_line(pose, s_um: float, radius_um: float | None, extra_dtheta: float = 0.0) -> np.ndarray:
    """Pose after travelling ``s_um``: straight (``radius_um`` None) or clockwise arc, SPEC 3's closed forms.

    ``extra_dtheta`` (heading drift over this travel) turns the straight path at its midpoint and adds to
    the arc's turn, so a zero drift gives the exact SPEC formulas.
    """
    x, y, t = (float(v) for v in pose)
    if radius_um is None:
        tm = t + 0.5 * extra_dtheta
        return np.array([x + s_um * math.sin(tm), y + s_um * math.cos(tm), t + extra_dtheta])
    dphi = s_um / radius_um
    return np.array([x + radius_um * (math.cos(t) - math.cos(t + dphi)),
                     y + radius_um * (math.sin(t + dphi) - math.sin(t)), t + dphi + extra_dtheta])


def rect_distance(q: np.ndarray, pose: np.ndarray, L: float, W: float) -> np.ndarray:
    """Distances (um) of points ``q`` (k, 2) to a body (0 inside)."""
    h = heading(pose[2])
    rel = q - pose[:2]
    a, b = rel @ h, rel @ np.array([h[1], -h[0]])
    return np.hypot(np.maximum(np.abs(a) - L / 2, 0.0), np.maximum(np.abs(b) - W / 2, 0.0))


def contact_point(ca, pb, Lb, Wb, cb, pa, La, Wa) -> np.ndarray:
    """Where two touching bodies meet: the corner of either (corners ``ca``/``cb``) nearest to the other.

    Two convex polygons are nearest at a vertex of one against the other, so this is exact up to the
    choice between equally near vertices (flush edges: either end of the shared stretch).
    """
    da, db = rect_distance(ca, pb, Lb, Wb), rect_distance(cb, pa, La, Wa)
    if da.min() <= db.min():
        return ca[int(np.argmin(da))]
    return cb[int(np.argmin(db))]


def wrap_pi(a):
    """Angle(s) wrapped to ``(-pi, pi]``."""
    return np.pi - np.mod(np.pi - np.asarray(a, dtype=np.float64), TWO_PI)


def settle_arms(states: np.ndarray, volts: float, snap_down_V: np.ndarray, release_V: np.ndarray) -> np.ndarray:
    """Arm states after one level (SPEC 4 hysteresis): down at ``>= V_d``, up at ``<= V_u``, else kept."""
    s = states.copy()
    s[volts >= snap_down_V] = 1
    s[volts <= release_V] = 0
    return s


def rigid_rms(final, goals, L, W) -> tuple[float, float]:
    """RMS corner distance (um) after the best proper rigid motion (2-D Kabsch, own code) and its angle (deg)."""
    a = corners(final, L, W).reshape(-1, 2)
    b = corners(goals, L, W).reshape(-1, 2)
    ac, bc = a - a.mean(0), b - b.mean(0)
    hmat = ac.T @ bc
    ang = math.atan2(hmat[0, 1] - hmat[1, 0], hmat[0, 0] + hmat[1, 1])
    c, s = math.cos(ang), math.sin(ang)
    rot = np.array([[c, -s], [s, c]])
    err = ac @ rot.T - bc
    return float(np.sqrt((err ** 2).sum(1).mean())), math.degrees(ang)


def touched_edge(q: np.ndarray, pose: np.ndarray, L: float, W: float, h_robot: np.ndarray, touch_um: float):
    """Depth of point ``q`` in a body (um, negative outside) and the outward normal of the edge it touches.

    Near a corner of the body two edges are within ``touch_um``: the one a robot heading ``h_robot``
    drives into most squarely is taken (the other is only grazed).
    """
    h = heading(pose[2])
    rt = np.array([h[1], -h[0]])
    a, b = float(np.dot(q - pose[:2], h)), float(np.dot(q - pose[:2], rt))
    gaps = np.array([L / 2 - a, L / 2 + a, W / 2 - b, W / 2 + b])  # front, rear, right, left edge
    normals = np.stack([h, -h, rt, -rt])
    near = np.flatnonzero(gaps < touch_um)
    if near.size == 0:
        return float(gaps.min()), normals[int(np.argmin(gaps))]
    k = near[int(np.argmin(normals[near] @ h_robot))]  # most opposed to the motion
    return float(gaps.min()), normals[k]


class IndependentPlant:
    """A Plant (SPEC 6: ``observe``/``apply``) built from SPEC 3, 4 and 6 alone; see the module docstring.

    Parameters
    ----------
    scenario:
        Robots (body, speed, radius, thresholds, starts), arena and ``[noise]``.
    seed:
        Plant seed: speed and radius factors, drift biases and walks, camera noise, move order.
    settings:
        The plant's own modelling choices (:class:`PlantSettings`).
    """

    def __init__(self, scenario, seed: int = 0, settings: PlantSettings | None = None):
        self.cfg = settings or PlantSettings()
        self.n = scenario.n
        self.names = scenario.names
        self.L, self.W = scenario.lengths_um, scenario.widths_um
        self.vd, self.vu = scenario.snap_down_V, scenario.release_V
        self.arena = scenario.arena_um
        self.noise = scenario.noise
        self.seed = seed
        par, walk, cam, order = (np.random.default_rng(s) for s in np.random.SeedSequence(seed).spawn(4))
        self._walk, self._cam, self._order = walk, cam, order
        nz = scenario.noise
        self.speed = scenario.speeds_um_s * (1.0 + nz.speed_rel_sd * par.standard_normal(self.n))
        self.radius = scenario.turn_radii_um * (1.0 + nz.turn_radius_rel_sd * par.standard_normal(self.n))
        share = self.cfg.drift_bias_share
        self.bias = nz.heading_drift_rad_per_um * math.sqrt(share) * par.standard_normal(self.n)  # rad/um
        self.walk_sd = nz.heading_drift_rad_per_um * math.sqrt((1.0 - share) * 1000.0)  # rad/sqrt(um)
        self.poses = np.array(scenario.starts, dtype=np.float64)
        self.arms = np.zeros(self.n, dtype=np.int8)
        self.partner = np.full(self.n, -1)
        self.member = np.zeros(self.n, dtype=bool)
        self.travel_um = np.zeros(self.n)
        self.t = 0.0
        self.events: list[dict] = []
        self._last_contact: dict[int, tuple] = {}
        self._stall: dict[int, tuple] = {}
        self._hd = 0.5 * np.hypot(self.L, self.W)
        self._c = corners(self.poses, self.L, self.W)

    # ------------------------------------------------------------------------------------ protocol
    def observe(self) -> np.ndarray:
        """Camera: true poses plus Gaussian noise, headings in ``[0, 2 pi)``, NaN rows for dropouts."""
        nz = self.noise
        e = self._cam.standard_normal((self.n, 3))
        obs = self.poses.copy()
        obs[:, :2] += nz.camera_position_sd_um * e[:, :2]
        obs[:, 2] = np.mod(obs[:, 2] + nz.camera_heading_sd_rad * e[:, 2], TWO_PI)
        obs[self._cam.random(self.n) < nz.camera_dropout] = np.nan
        return obs

    def apply(self, waveform) -> None:
        """Run a waveform: a Hold sets arms, a Drive sets arms from its band then moves every robot."""
        for seg in waveform:
            if isinstance(seg, Hold):
                self.arms = settle_arms(self.arms, seg.volts, self.vd, self.vu)
            elif isinstance(seg, Drive):
                self.arms = settle_arms(self.arms, seg.high_V, self.vd, self.vu)
                self.arms = settle_arms(self.arms, seg.low_V, self.vd, self.vu)
                self._drive(float(seg.duration_s))
            else:
                raise TypeError(f"waveform segment must be Hold or Drive, got {type(seg).__name__}")

    def true_poses(self) -> np.ndarray:
        """The true poses (for the benchmark's own judgement; never handed to the controller)."""
        return self.poses.copy()

    # ------------------------------------------------------------------------------------ motion
    def _drive(self, duration_s: float) -> None:
        if duration_s <= 0.0:
            return
        nsub = max(1, math.ceil(float(self.speed.max()) * duration_s / self.cfg.substep_um))
        dt = duration_s / nsub
        for _ in range(nsub):
            z = self._walk.standard_normal(self.n)
            done = np.zeros(self.n, dtype=bool)
            for i in self._order.permutation(self.n):
                if done[i]:
                    continue
                j = int(self.partner[i])
                if j >= 0:
                    done[[i, j]] = True
                    self._move_bar(int(i), j, dt)
                else:
                    done[i] = True
                    self._move_single(int(i), dt, float(z[i]))
            self.t += dt

    def _move_single(self, i: int, dt: float, z: float) -> None:
        if i in self._stall and self._stall[i] == self._stall_key(i, self._stall[i][0]):
            return  # still pushing against the same unmoved obstacle with the same arm state
        self._stall.pop(i, None)
        s = float(self.speed[i]) * dt
        rad = float(self.radius[i]) if self.arms[i] else None
        start = self.poses[i].copy()

        def pose_at(f: float) -> np.ndarray:
            ds = f * s
            drift = float(self.bias[i]) * ds + self.walk_sd * math.sqrt(ds) * z
            return arc_or_line(start, ds, rad, drift)[None]

        f, who = self._advance([i], pose_at)
        self.travel_um[i] += f * s
        if who is None:
            self._last_contact.pop(i, None)
            return
        before = self.poses[i].copy()
        self._on_contact(i, who, (1.0 - f) * s)
        if f == 0.0 and np.array_equal(before, self.poses[i]) and self.partner[i] < 0:
            self._stall[i] = self._stall_key(i, who)

    def _stall_key(self, i: int, j: int) -> tuple:
        """What a blocked robot's next sub-step depends on: obstacle, arm state, both poses."""
        other = () if j == WALL else tuple(self.poses[j])
        return (j, int(self.arms[i]), tuple(self.poses[i]), other)

    def _move_bar(self, a: int, b: int, dt: float) -> None:
        """One sub-step of a G_1 bar: pushes along the bar cancel, turns and sideways motion average."""
        if not (self.arms[a] or self.arms[b]):
            return  # both push straight into each other: stalled
        start = self.poses[[a, b]].copy()
        u = heading(start[0, 2])
        moves = []
        for k, i in enumerate((a, b)):
            rad = float(self.radius[i]) if self.arms[i] else None
            nxt = arc_or_line(start[k], float(self.speed[i]) * dt, rad)
            d = nxt[:2] - start[k, :2]
            moves.append((d - np.dot(d, u) * u, nxt[2] - start[k, 2]))
        shift = 0.5 * (moves[0][0] + moves[1][0])
        turn = 0.5 * (moves[0][1] + moves[1][1])
        ends = (start[0, :2] - u * self.L[a] / 2, start[1, :2] + u * self.L[b] / 2)
        centre = 0.5 * (ends[0] + ends[1])

        def pose_at(f: float) -> np.ndarray:
            out = start.copy()
            out[:, :2] = centre + rotate_cw(start[:, :2] - centre, f * turn) + f * shift
            out[:, 2] += f * turn
            return out

        self._advance([a, b], pose_at)

    def _advance(self, ids: list[int], pose_at) -> tuple[float, int | None]:
        """Move bodies ``ids`` along ``pose_at(f)``, f in [0, 1], up to the first contact.

        Returns the fraction reached and the obstacle (robot index, :data:`WALL`) met, or None when free.
        """
        full = pose_at(1.0)
        depth, who = self._blocking(ids, full)
        if depth <= self.cfg.contact_tol_um:
            self._set(ids, full)
            return 1.0, None
        lo, hi = 0.0, 1.0
        reach = float(np.abs(full[:, :2] - pose_at(0.0)[:, :2]).max())
        tiny = min(1.0, self.cfg.probe_um / max(reach, 1e-12))
        if self._blocking(ids, pose_at(tiny))[0] > self.cfg.contact_tol_um:
            hi = tiny  # already pushing against it: no need to bisect
        else:
            lo = tiny
            for _ in range(self.cfg.bisect_steps):
                mid = 0.5 * (lo + hi)
                if self._blocking(ids, pose_at(mid))[0] > self.cfg.contact_tol_um:
                    hi = mid
                else:
                    lo = mid
        if lo > 0.0:
            self._set(ids, pose_at(lo))
        return lo, self._blocking(ids, pose_at(hi))[1]

    def _blocking(self, ids: list[int], new: np.ndarray) -> tuple[float, int]:
        """Deepest penetration (um) of bodies ``ids`` at poses ``new`` into any other body or the walls."""
        best, who = -np.inf, WALL
        others = np.ones(self.n, dtype=bool)
        others[ids] = False
        for k, i in enumerate(ids):
            body = one_body(new[k], float(self.L[i]), float(self.W[i]))
            wall = wall_penetration(body, self.arena)
            if wall > 0.0 and wall > best:
                best, who = wall, WALL
            dist = np.hypot(self.poses[:, 0] - new[k, 0], self.poses[:, 1] - new[k, 1])
            near = np.flatnonzero(others & (dist < self._hd[i] + self._hd + 1.0))
            if near.size:
                d = penetration(body, self._c[near])
                m = int(np.argmax(d))
                if d[m] > best:
                    best, who = float(d[m]), int(near[m])
        return best, who

    def _set(self, ids: list[int], new: np.ndarray) -> None:
        self.poses[ids] = new
        for k, i in enumerate(ids):
            self._c[i] = one_body(new[k], float(self.L[i]), float(self.W[i]))

    # ------------------------------------------------------------------------------------ contact
    def _on_contact(self, i: int, j: int, remaining_um: float) -> None:
        """Robot ``i`` stopped against ``j``: docking compliance, G_1, or stuck (logged once per contact)."""
        if j == WALL:
            self._note(i, "wall", j, "stopped at the arena edge")
        elif self.member[j] and not self.member[i]:
            self._dock(i, j, remaining_um)
        elif not self.member[i] and not self.member[j] and self.partner[i] < 0 and self.partner[j] < 0:
            self._g1(i, j)
        elif self.member[i]:
            self._note(i, "pushing", j, "docked, pushing against a body")
        else:
            self._note(i, "stuck", j, "stopped against a body")

    def _dock(self, i: int, j: int, remaining_um: float) -> None:
        """Docking compliance: rotate about the touching front corner toward flush, then join the structure."""
        p = self.poses[i]
        h = heading(p[2])
        found = [touched_edge(q, self.poses[j], self.L[j], self.W[j], h, self.cfg.touch_um) for q in self._c[i, :2]]
        k = int(np.argmax([d for d, _ in found]))
        depth, normal = found[k]
        if depth < -self.cfg.touch_um:
            self._note(i, "stuck", j, "front edge on a structure corner (no corner contact)")
            return
        err = float(wrap_pi(math.atan2(-normal[0], -normal[1]) - p[2]))
        if abs(err) > self.cfg.dock_cone_rad:
            self._note(i, "stuck", j, f"outside the sticking cone ({math.degrees(err):.0f} deg)")
            return
        if self.arms[i] and abs(err) > self.cfg.flush_rad:
            self._note(i, "stuck", j, "turning robot blocked by the structure (pivots on its stylus)")
            return
        if abs(err) > self.cfg.flush_rad:
            turn = math.copysign(min(abs(err), remaining_um / float(self.W[i])), err)
            pivot = self._c[i, k]
            new = p.copy()
            new[:2] = pivot + rotate_cw(p[:2] - pivot, turn)
            new[2] += turn
            depth2, who = self._blocking([i], new[None])
            if depth2 > self.cfg.contact_tol_um and not (who == j and depth2 < 10 * self.cfg.contact_tol_um):
                self._note(i, "stuck", who, "docking rotation blocked")
                return
            self._set([i], new[None])
            err -= turn
        if abs(err) <= self.cfg.flush_rad:
            self.member[i] = True
            self._note(i, "docked", j, "flush against the structure")
        else:
            self._note(i, "docking", j, "rotating about its front corner")

    def _g1(self, a: int, b: int) -> None:
        """Self-aligning compliance: front to front within the limits -> collinear, flush, one bar."""
        pa, pb = self.poses[a], self.poses[b]
        ca, cb = self._c[a], self._c[b]
        q = contact_point(ca, pb, float(self.L[b]), float(self.W[b]), cb, pa, float(self.L[a]), float(self.W[a]))
        if min(float(np.dot(q - pa[:2], heading(pa[2]))), float(np.dot(q - pb[:2], heading(pb[2])))) < 0.0:
            self._note(a, "stuck", b, "met a free robot, not front to front (contact in a rear half)")
            return
        alpha = float(wrap_pi(pa[2] - pb[2] - math.pi))
        u = heading(pa[2]) - heading(pb[2])
        u = u / np.linalg.norm(u)
        fa, fb = 0.5 * (ca[0] + ca[1]), 0.5 * (cb[0] + cb[1])
        d = fb - fa
        wy = abs(u[0] * d[1] - u[1] * d[0])
        if abs(alpha) >= self.cfg.g1_alpha_rad or wy >= self.cfg.g1_wy_um:
            self._note(a, "stuck", b, f"front to front outside G_1's limits (alpha {math.degrees(alpha):.0f} deg, w_y {wy:.0f} um)")
            return
        mid = 0.5 * (fa + fb)
        th = math.atan2(u[0], u[1])
        new = np.array([[*(mid - u * self.L[a] / 2), th], [*(mid + u * self.L[b] / 2), th + math.pi]])
        new[:, 2] = np.mod(new[:, 2], TWO_PI)
        depth, who = self._blocking([a, b], new)
        if depth > self.cfg.contact_tol_um:
            self._note(a, "stuck", who, "G_1 alignment blocked by another body")
            return
        self._set([a, b], new)
        self.partner[a], self.partner[b] = b, a
        self.member[[a, b]] = True
        self._note(a, "G1", b, f"formed (alpha {math.degrees(alpha):.0f} deg, w_y {wy:.0f} um)")

    def _note(self, i: int, kind: str, j: int, detail: str) -> None:
        """Log a contact event once per (robot, kind, obstacle) change (a pushing robot meets it every sub-step)."""
        key = (kind, j)
        if self._last_contact.get(i) == key:
            return
        self._last_contact[i] = key
        other = "arena" if j == WALL else self.names[j]
        self.events.append({"t_s": round(self.t, 3), "kind": kind, "robot": self.names[i], "other": other, "detail": detail})
