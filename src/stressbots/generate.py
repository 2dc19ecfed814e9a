"""Random feasible scenarios, for property tests, benchmarks and Monte Carlo studies.

A generated scenario has a STRING voltage design (from :func:`stressbots.design.design_string`), robots
of (optionally) heterogeneous size, speed and radius, a target structure placed at a random position and
rotation, and start poses whose orbit discs are separated from each other, from the structure and from
the arena edge, so that the seed's orbit-as-obstacle scheme applies. Everything is a function of the
seed (``np.random.SeedSequence``).
"""

from __future__ import annotations

import math

import numpy as np

from .collision import bodies_hit_discs, point_rectangle_distance
from .design import design_string
from .electrostatics import Electrodes
from .errors import PlanningError
from .robots import TWO_PI, Pose, Robot, body_corners, orbit_radii, turning_centres
from .scenario import ControlSettings, Noise, Scenario, StructureSpec
from .structures import Structure, candidate_structures

LITERATURE_NOISE = Noise(
    speed_rel_sd=0.05,
    turn_radius_rel_sd=0.03,
    heading_drift_rad_per_um=math.radians(3.7) / 1000.0,
    camera_position_sd_um=2.0,
    camera_heading_sd_rad=math.radians(1.0),
    camera_dropout=0.02,
)
"""The literature's error levels (IJRR abstract): speed 5 %, radius 3 %, drift 3.7 deg/mm, camera 2 um / 1 deg."""


def random_scenario(
    n: int,
    seed: int,
    *,
    shape: str = "tee",
    explicit_goals: bool = False,
    heterogeneous: bool = True,
    arena_um: tuple[float, float] | None = None,
    gap_um: float = 60.0,
    shuffle: bool = True,
    noise: Noise | None = None,
    max_tries: int = 4000,
) -> Scenario:
    """A random scenario of ``n`` robots assembling ``shape``.

    Parameters
    ----------
    explicit_goals:
        Write the structure's slots as per-robot ``goal`` poses instead of a ``[structure]``.
    heterogeneous:
        Draw L, W, v, r per robot (L 220-300 um, W 50-70 um, v 80-150 um/s, r 150-250 um).
    arena_um:
        Arena size; default grows with ``n`` so that the orbits fit.
    gap_um:
        Least free distance between orbit discs, the structure and the arena edge.
    shuffle:
        List robots in a random file order (not the voltage order).
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(n), 7]))
    e = Electrodes(margin_V=2.0 if n > 6 else 5.0)
    des = design_string(n, e)
    names = [f"R{k}" for k in range(n)]
    for attempt in range(50):
        if heterogeneous:
            L = rng.uniform(220, 300, n)
            W = np.sort(rng.uniform(50, 70, n))  # D_1 narrowest: later robots dock on earlier ones' edges
            v = rng.uniform(80, 150, n)
            r = rng.uniform(150, 250, n)
        else:
            L, W, v, r = (np.full(n, x) for x in (260.0, 60.0, 100.0, 200.0))
        rstar = orbit_radii(L, W, r)
        if arena_um is None:
            side = max(3000.0, math.sqrt((n + 5) * (2 * rstar.max() + gap_um) ** 2 * 2.6))
            size = (side, side)
        else:
            size = arena_um
        robots_in_order = [
            Robot(names[k], des.snap_down_V[k], des.release_V[k], float(L[k]), float(W[k]), float(v[k]), float(r[k]))
            for k in range(n)
        ]
        try:
            spec, struct, (w, h) = _place_structure(rng, robots_in_order, shape, size, grow=arena_um is None, gap_um=gap_um)
            break
        except PlanningError:  # e.g. a wider robot cannot dock on a narrower one's rear edge: redraw
            if attempt == 49:
                raise
    arena_um = (w, h)
    goals_by_name = struct.goals()
    goal_arr = np.array([goals_by_name[nm] for nm in names])
    # Keep-out for orbits: the structure's bodies plus a margin for every approach.
    keep_pts = body_corners(goal_arr, L, W).reshape(-1, 2)
    keep_centre = keep_pts.mean(axis=0)
    keep_radius = float(np.max(np.hypot(*(keep_pts - keep_centre).T))) + 350.0
    starts = np.zeros((n, 3))
    centres = np.zeros((n, 2))
    placed = 0
    tries = 0
    while placed < n:
        tries += 1
        if tries > max_tries:
            if arena_um is not None and tries > 4 * max_tries:
                raise RuntimeError(f"could not place {n} robots in a {w:.0f} x {h:.0f} um arena; make it larger")
            # crowded: grow the arena by 10 % (the structure stays at its relative place) and retry
            scale = 1.1
            w, h = w * scale, h * scale
            keep_centre = keep_centre * scale
            goal_arr = goal_arr + np.concatenate([keep_centre - keep_centre / scale, [0.0]])
            keep_pts = keep_pts + (keep_centre - keep_centre / scale)
            spec = StructureSpec(shape, Pose(spec.at.x + keep_centre[0] - keep_centre[0] / scale,
                                             spec.at.y + keep_centre[1] - keep_centre[1] / scale, spec.at.theta))
            tries, placed = 0, 0
        p = np.array([rng.uniform(0, w), rng.uniform(0, h), rng.uniform(0, TWO_PI)])
        c = turning_centres(p, r[placed])[0]
        R = rstar[placed]
        if min(c[0], w - c[0], c[1], h - c[1]) < R + gap_um:
            continue
        if np.hypot(*(c - keep_centre)) < R + keep_radius + gap_um:
            continue
        if placed and (np.hypot(*(centres[:placed] - c).T) < rstar[:placed] + R + gap_um).any():
            continue
        # every robot's orbit disc must also clear the bodies of robots already placed and vice versa
        if placed and bodies_hit_discs(starts[:placed], L[:placed], W[:placed], c[None, :], [R + gap_um]).any():
            continue
        if placed and (point_rectangle_distance(centres[:placed], p, L[placed], W[placed])[0] < rstar[:placed] + gap_um).any():
            continue
        starts[placed] = p
        centres[placed] = c
        placed += 1
    perm = rng.permutation(n) if shuffle else np.arange(n)
    robots = []
    for k in perm:
        rb = robots_in_order[k]
        robots.append(
            Robot(
                rb.name,
                rb.snap_down_V,
                rb.release_V,
                rb.length_um,
                rb.width_um,
                rb.speed_um_s,
                rb.turn_radius_um,
                start=Pose(*starts[k]),
                goal=Pose(*goal_arr[k]) if explicit_goals else None,
            )
        )
    return Scenario(
        name=f"random-{shape}-{n}-{seed}",
        robots=tuple(robots),
        electrodes=e,
        arena_um=(float(w), float(h)),
        structure=None if explicit_goals else spec,
        noise=noise or Noise(),
        control=ControlSettings(),
        source=None,
    )


def _place_structure(rng: np.random.Generator, robots_in_order: list[Robot], shape: str, size: tuple[float, float], *,
                     grow: bool, gap_um: float) -> tuple[StructureSpec, Structure, tuple[float, float]]:
    """The target structure at a random place (0.4-0.6 of the arena) and rotation, inside the arena.

    Long structures (a tee of 12 robots) can reach past the edge of the default arena: then the arena
    grows by 10 % at a time (``grow``, the structure keeping its relative place) until every slot is at
    least ``gap_um`` inside; with a given arena the draw is refused (:class:`PlanningError`, redrawn).
    """
    w, h = size
    fx, fy, th = rng.uniform(0.4, 0.6), rng.uniform(0.4, 0.6), rng.uniform(0, TWO_PI)
    names = [rb.name for rb in robots_in_order]
    L = np.array([rb.length_um for rb in robots_in_order])
    W = np.array([rb.width_um for rb in robots_in_order])
    for _ in range(40):
        spec = StructureSpec(shape, Pose(float(fx * w), float(fy * h), float(th)))
        struct = candidate_structures(robots_in_order, spec)[0]
        corners = body_corners(struct.goal_poses(names), L, W).reshape(-1, 2)
        if corners.min() >= gap_um and (corners[:, 0] <= w - gap_um).all() and (corners[:, 1] <= h - gap_um).all():
            return spec, struct, (w, h)
        if not grow:
            break
        w, h = w * 1.1, h * 1.1
    raise PlanningError(f"the {shape} of {len(names)} robots does not fit in the {w:.0f} x {h:.0f} um arena")
