"""Random feasible scenarios, for property tests, benchmarks and Monte Carlo studies.

A generated scenario has a STRING voltage design (from :func:`stressbots.design.design_string`), robots
of (optionally) heterogeneous size, speed and radius, a target structure placed at a random position and
rotation, and start poses whose orbit discs are separated from each other, from the structure and from
the arena edge, so that the seed's orbit-as-obstacle scheme applies. Everything is a function of the
seed (``np.random.SeedSequence``).
"""

from __future__ import annotations

import dataclasses
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
        Arena size; default grows with ``n`` (and by 10 % steps while the start orbits do not fit). A given
        arena is kept: ``RuntimeError`` when the orbits cannot be placed in it.
    gap_um:
        Least free distance between orbit discs, the structure and the arena edge.
    shuffle:
        List robots in a random file order (not the voltage order).
    """
    rng = np.random.default_rng(np.random.SeedSequence([int(seed), int(n), 7]))
    e = Electrodes(margin_V=2.0 if n > 6 else 5.0)
    robots_in_order, spec, struct, size = _draw_robots_and_structure(rng, n, e, shape, heterogeneous, arena_um, gap_um)
    names = [rb.name for rb in robots_in_order]
    goals_by_name = struct.goals()
    goal_arr = np.array([goals_by_name[nm] for nm in names])
    starts, goal_arr, spec, (w, h) = _place_starts(rng, robots_in_order, goal_arr, spec, size, gap_um=gap_um,
                                                   max_tries=max_tries, may_grow=arena_um is None)
    perm = rng.permutation(n) if shuffle else np.arange(n)
    robots = tuple(
        dataclasses.replace(robots_in_order[k], start=Pose(*starts[k]), goal=Pose(*goal_arr[k]) if explicit_goals else None) for k in perm
    )
    return Scenario(
        name=f"random-{shape}-{n}-{seed}",
        robots=robots,
        electrodes=e,
        arena_um=(float(w), float(h)),
        structure=None if explicit_goals else spec,
        noise=noise or Noise(),
        control=ControlSettings(),
        source=None,
    )


def _draw_robots_and_structure(rng: np.random.Generator, n: int, e: Electrodes, shape: str, heterogeneous: bool,
                               arena_um: tuple[float, float] | None, gap_um: float
                               ) -> tuple[list[Robot], StructureSpec, Structure, tuple[float, float]]:
    """The robots in voltage order (no starts yet) and the structure placed in the arena: redrawn (up to 50
    times) while the structure cannot be built, e.g. a wider robot that cannot dock on a narrower one's rear edge.

    With ``arena_um`` None the arena's side grows with ``n`` and the largest orbit so that the orbits fit.
    """
    des = design_string(n, e)
    for attempt in range(50):
        if heterogeneous:
            L = rng.uniform(220, 300, n)
            W = np.sort(rng.uniform(50, 70, n))  # D_1 narrowest: later robots dock on earlier ones' edges
            v = rng.uniform(80, 150, n)
            r = rng.uniform(150, 250, n)
        else:
            L, W, v, r = (np.full(n, x) for x in (260.0, 60.0, 100.0, 200.0))
        if arena_um is None:
            rstar = orbit_radii(L, W, r)
            side = max(3000.0, math.sqrt((n + 5) * (2 * rstar.max() + gap_um) ** 2 * 2.6))
            size = (side, side)
        else:
            size = arena_um
        robots_in_order = [
            Robot(f"R{k}", des.snap_down_V[k], des.release_V[k], float(L[k]), float(W[k]), float(v[k]), float(r[k]))
            for k in range(n)
        ]
        try:
            spec, struct, placed_size = _place_structure(rng, robots_in_order, shape, size, grow=arena_um is None, gap_um=gap_um)
            return robots_in_order, spec, struct, placed_size
        except PlanningError:
            if attempt == 49:
                raise
    raise AssertionError("unreachable")  # pragma: no cover


def _orbit_is_free(p: np.ndarray, k: int, starts: np.ndarray, centres: np.ndarray, L: np.ndarray, W: np.ndarray,
                   r: np.ndarray, rstar: np.ndarray, size: tuple[float, float], keep_centre: np.ndarray, keep_radius: float,
                   gap_um: float) -> bool:
    """Whether robot ``k`` may start at pose ``p``: its orbit disc (radius ``rstar[k]``) is ``gap_um`` clear of the
    arena edge, the structure's keep-out disc and the orbit discs and bodies of robots ``0 .. k-1``, and its body
    clears their orbit discs."""
    w, h = size
    c = turning_centres(p, r[k])[0]
    R = rstar[k]
    if min(c[0], w - c[0], c[1], h - c[1]) < R + gap_um:
        return False
    if np.hypot(*(c - keep_centre)) < R + keep_radius + gap_um:
        return False
    if k and (np.hypot(*(centres[:k] - c).T) < rstar[:k] + R + gap_um).any():
        return False
    if k and bodies_hit_discs(starts[:k], L[:k], W[:k], c[None, :], [R + gap_um]).any():
        return False
    return not (k and (point_rectangle_distance(centres[:k], p, L[k], W[k])[0] < rstar[:k] + gap_um).any())


def _place_starts(rng: np.random.Generator, robots_in_order: list[Robot], goal_arr: np.ndarray, spec: StructureSpec,
                  size: tuple[float, float], *, gap_um: float, max_tries: int, may_grow: bool
                  ) -> tuple[np.ndarray, np.ndarray, StructureSpec, tuple[float, float]]:
    """Start poses drawn uniformly, one robot at a time, until each passes :func:`_orbit_is_free`.

    The structure's keep-out disc covers its bodies plus 350 um for every approach. After ``max_tries`` draws
    for one set of robots the arena is crowded: with ``may_grow`` it grows by 10 % (the structure keeps its
    relative place) and placing starts over; else a ``RuntimeError`` says to make the arena larger.
    Returns ``(starts, goals, spec, arena size)``, the goals and spec moved with a grown arena.
    """
    n = len(robots_in_order)
    L = np.array([rb.length_um for rb in robots_in_order])
    W = np.array([rb.width_um for rb in robots_in_order])
    r = np.array([rb.turn_radius_um for rb in robots_in_order])
    rstar = orbit_radii(L, W, r)
    w, h = size
    keep_pts = body_corners(goal_arr, L, W).reshape(-1, 2)
    keep_centre = keep_pts.mean(axis=0)
    keep_radius = float(np.max(np.hypot(*(keep_pts - keep_centre).T))) + 350.0
    starts = np.zeros((n, 3))
    centres = np.zeros((n, 2))
    placed = tries = 0
    while placed < n:
        tries += 1
        if tries > max_tries:
            if not may_grow:
                raise RuntimeError(f"could not place {n} robots in a {w:.0f} x {h:.0f} um arena; make it larger")
            scale = 1.1
            w, h = w * scale, h * scale
            keep_centre = keep_centre * scale
            shift = keep_centre - keep_centre / scale
            goal_arr = goal_arr + np.concatenate([shift, [0.0]])
            spec = StructureSpec(spec.shape, Pose(spec.at.x + keep_centre[0] - keep_centre[0] / scale,
                                                  spec.at.y + keep_centre[1] - keep_centre[1] / scale, spec.at.theta))
            tries, placed = 0, 0
        p = np.array([rng.uniform(0, w), rng.uniform(0, h), rng.uniform(0, TWO_PI)])
        if _orbit_is_free(p, placed, starts, centres, L, W, r, rstar, (w, h), keep_centre, keep_radius, gap_um):
            starts[placed] = p
            centres[placed] = turning_centres(p, r[placed])[0]
            placed += 1
    return starts, goal_arr, spec, (w, h)


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
