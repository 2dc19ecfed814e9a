"""The seed strategy's loop and single-robot steps: settings, regions A_i and C_O, sigma_1 / sigma_2.

Shared by :mod:`stressbots.seed_strategy` (the whole assembly) and :mod:`stressbots.seed_pair` (G_1);
see :mod:`stressbots.seed_strategy` for the strategy as a whole.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import shapely

from . import paths
from .bounds import ErrorModel, cylinder
from .collision import arena_gap, bodies_hit_discs, penetration_depth
from .control.gross import path_steps
from .control.loop import PlantLoop
from .robots import TWO_PI, angle_difference, turning_centres
from .seed_fine_motion import arc_back, s2f_duty, s2f_steps

__all__ = ["SeedLoop", "SeedSettings", "SeedStop", "dock_single", "intermediate_reason", "in_proximity", "nominal_intermediate",
           "region_path"]

@dataclass(frozen=True)
class SeedSettings:
    """Numbers of the seed's strategy that the paper leaves open (um, s, deg), each with its reason.

    Attributes
    ----------
    region_um, region_deg:
        Largest radius / half-height of the regions A_i, A_n', A_n used (the cylinder C_alpha of
        :mod:`stressbots.bounds` clipped to this: beyond it the region is useless as a target).
    min_region_um, min_region_deg:
        Smallest region: the camera's error (2 um / 1 deg at the literature's level) with a margin.
    co_margin_um:
        How far outside C_O the nominal a_i is placed (the region around it must stay outside too).
    s2f_duties:
        Turning fractions rho_a tried, in order, for the nominal S_2f arc into a slot (S_2f(sym) first).
    s3f_duties:
        Duty triples tried for the pair's nominal S_3f arcs (S_3f(sym) first; App. 3.1's cones).
    sticking_cone_deg:
        Docking compliance (App. 3.5): the arrival heading must be within this of the slot's.
    self_align_deg, self_align_um:
        Self-aligning compliance limits for the pair (App. 3.5: |alpha| < 60 deg, |w_y| < 80 um).
    switch_period_s:
        Period of the primitive alternation in S_2f / S_3f (shorter = closer to the ideal arc).
    push_s:
        Straight push after a fine motion, for compliance to act.
    dock_tol_um, dock_tol_deg:
        A robot that stopped this close to its slot (measured) is docked; elsewhere it is in H.
    clearance_um:
        Clearance of re-planned paths from orbits, the structure and the arena edge in the checks.
    fine_attempts:
        How often a single robot may return from fine motion to gross motion (left the preimage).
    pair_replans:
        How often sigma_1 of the pair may be re-planned (App. 3.3) before giving up.
    partial_stages:
        How many partial stage-2 moves of D_(n-1) (when no straight run of D_n covers the whole stage 2,
        SPEC 5's known limit) are allowed before giving up.
    max_cycles:
        Re-planning cycles per gross-motion leg before it is declared stuck.
    """

    region_um: float = 60.0
    region_deg: float = 10.0
    min_region_um: float = 20.0
    min_region_deg: float = 5.0
    co_margin_um: float = 10.0
    s2f_duties: tuple[float, ...] = (0.5, 1.0 / 3.0, 0.25, 0.15)
    s3f_duties: tuple[tuple[float, float, float], ...] = (
        (1.0 / 3.0, 1.0 / 3.0, 1.0 / 3.0),
        (1.0 / 3.0, 0.5, 1.0 / 6.0),
        (1.0 / 6.0, 1.0 / 2.0, 1.0 / 3.0),
        (0.25, 0.25, 0.5),
    )
    sticking_cone_deg: float = 45.0
    self_align_deg: float = 60.0
    self_align_um: float = 80.0
    switch_period_s: float = 0.2
    push_s: float = 2.0
    dock_tol_um: float = 30.0
    dock_tol_deg: float = 15.0
    clearance_um: float = 10.0
    fine_attempts: int = 4
    pair_replans: int = 6
    partial_stages: int = 8
    max_cycles: int = 200


class SeedStop(Exception):
    """The seed's strategy ends here (goal reached elsewhere, H, budget); ``reason`` says why."""

    def __init__(self, reason: str):
        super().__init__(reason)
        self.reason = reason


# -- regions (pure) ----------------------------------------------------------------------------------


def in_proximity(co, xy) -> np.ndarray:
    """Whether points ``xy`` (..., 2) lie in the proximity region ``co`` (a shapely geometry, C_O)."""
    xy = np.asarray(xy, dtype=np.float64)
    return shapely.contains_xy(co, xy[..., 0], xy[..., 1]) | shapely.intersects_xy(co.boundary, xy[..., 0], xy[..., 1])


def intermediate_reason(pose, a_pose, goal, radius_um: float, co, *, region_um: float, region_rad: float, cone_rad: float) -> str | None:
    """Why the measured ``pose`` is not in A_i (None when it is).

    A_i (seed App. 3.2) = the ball ``region_um`` x ``+-region_rad`` around ``a_pose``, outside C_O (``co``),
    intersected with the preimage of the goal under fine motion: the eq. (1) arc from the pose through the
    goal's reference point needs ``r' >= r`` and must arrive within ``cone_rad`` of the goal heading.
    """
    pose = np.asarray(pose, dtype=np.float64)
    d = float(np.hypot(*(pose[:2] - np.asarray(a_pose)[:2])))
    if d > region_um:
        return f"{d:.0f} um from a_i"
    dth = abs(float(angle_difference(pose[2], a_pose[2])))
    if dth > region_rad:
        return f"{math.degrees(dth):.0f} deg from a_i's heading"
    if co is not None and bool(in_proximity(co, pose[:2])):
        return "inside C_O"
    fine = s2f_duty(pose, np.asarray(goal)[:2], radius_um)
    if fine is None:
        return "no clockwise arc of radius >= r through the docking point"
    miss = abs(float(angle_difference(fine.arrival_rad, goal[2])))
    if miss > cone_rad:
        return f"the arc arrives {math.degrees(miss):.0f} deg off (compliance cone {math.degrees(cone_rad):.0f} deg)"
    return None


def nominal_intermediate(goal, radius_um: float, co, rho_a: float, *, margin_um: float, step_um: float = 10.0, max_um: float = 4000.0):
    """``(a_i, s)``: the pose back along the S_2f(rho_a) arc into ``goal`` just outside C_O (+ margin).

    ``s`` is the arc length (um). None when no point of the arc within ``max_um`` leaves C_O.
    """
    r_prime = radius_um / rho_a if rho_a > 0 else math.inf
    s = np.arange(step_um, max_um, step_um)
    poses = arc_back(goal, s, r_prime)
    grown = co.buffer(margin_um) if margin_um > 0 else co
    out = np.flatnonzero(~in_proximity(grown, poses[:, :2]))  # the arc's circle may come back: first exit
    if out.size == 0:
        return None
    k = int(out[0])
    return poses[k], float(s[k])


def region_path(start, a_pose, radius_um: float, height_rad: float, turn_radius_um: float) -> paths.Path:
    """The shortest one-way path from ``start`` into the region around ``a_pose``.

    sigma_1's goal is a region, not the pose: the path goes to the nominal pose unless that needs a loop
    (a path longer by more than half a turn than into one of 26 poses at half the region's radius and
    half-height around it; then the shortest of those). A one-way robot that drifted a hair to the right
    of a straight into the exact pose would otherwise loop (2 pi r, App. 3.4) at every re-plan; the
    margin of half the region keeps the arrival inside it.
    """
    a = np.asarray(a_pose, dtype=np.float64)
    th = float(a[2])
    h, right = np.array([math.sin(th), math.cos(th)]), np.array([math.cos(th), -math.sin(th)])
    g = np.array(np.meshgrid([-0.5, 0.0, 0.5], [-0.5, 0.0, 0.5], [-0.5, 0.0, 0.5], indexing="ij")).reshape(3, -1).T
    cand = np.column_stack([
        a[0] + radius_um * (g[:, 0] * h[0] + g[:, 1] * right[0]),
        a[1] + radius_um * (g[:, 0] * h[1] + g[:, 1] * right[1]),
        th + height_rad * g[:, 2],
    ])
    start = np.asarray(start, dtype=np.float64)
    lengths = paths.shortest_path_lengths(np.broadcast_to(start, cand.shape), cand, turn_radius_um)
    best = 13 if lengths[13] <= lengths.min() + math.pi * turn_radius_um else int(np.argmin(lengths))  # 13: a_pose
    return paths.shortest_path(start, cand[best], turn_radius_um)


@lru_cache(maxsize=256)
def _cylinder(speed_um_s: float, radius_um: float, model: ErrorModel):
    """:func:`stressbots.bounds.cylinder`, cached: Monte Carlo trials of one scenario share it (~50 ms each)."""
    return cylinder(speed_um_s, radius_um, model)


# -- the plant loop --------------------------------------------------------------------------------


class SeedLoop(PlantLoop):
    """The seed strategy's loop on :class:`~stressbots.control.loop.PlantLoop` (the only code calling the
    plant), with the strategy's settings and its C_alpha cylinders.

    Holds the estimates (:class:`stressbots.estimation.Estimator`), the arm state, simulated time, the
    event log and the trace; refuses steps beyond the time budget (:class:`SeedStop`).
    """

    def __init__(self, scenario, plant, *, tx: float, budget_s: float, settings: SeedSettings):
        super().__init__(scenario, plant, budget_s=budget_s, who="the seed's strategy")
        self.tx, self.cfg = float(tx), settings
        self.v_nom, self.r_nom = scenario.speeds_um_s, scenario.turn_radii_um
        model = ErrorModel.from_noise(scenario.noise)
        self.cylinders = tuple(_cylinder(float(self.v_nom[i]), float(self.r_nom[i]), model) for i in range(self.n))

    def name(self, i: int) -> str:
        return self.scn.names[i]

    def label(self, i: int) -> str:
        """``name (D_k)``: the robot's name and its place in the voltage order."""
        return f"{self.scn.names[i]} (D_{int(self.rank[i])})"

    def over_budget(self) -> Exception:
        return SeedStop(f"not assembled within the time budget of {self.budget_s:g} s (simulated)")

    def path_steps(self, path: paths.Path, i: int, turn_k: int, straight_k: int, limit_s: float | None = None):
        """The first ``limit_s`` seconds of robot ``i``'s ``path`` as primitive steps (all when None), at its
        estimated speed (:func:`stressbots.control.gross.path_steps`)."""
        return path_steps(path, float(self.v_hat[i]), turn_k, straight_k, limit_s)

    def hit(self, samples: np.ndarray, i: int, orbiting: Sequence[int], *, discs=(), clearance: float | None = None) -> str | None:
        """What robot ``i``'s body along ``samples`` would hit (an orbit, a docked robot, the arena edge), or None."""
        c = self.cfg.clearance_um if clearance is None else clearance
        orbiting = [j for j in orbiting if j != i and not self.docked[j]]
        centres = [*turning_centres(self.est[orbiting], self.r_hat[orbiting])] if orbiting else []
        radii = list(self.rstar[orbiting]) if orbiting else []
        labels = [f"the orbit of {self.name(j)}" for j in orbiting]
        for cc, rr, lab in discs:
            centres.append(cc)
            radii.append(rr)
            labels.append(lab)
        if centres:
            hits = bodies_hit_discs(samples, self.L[i], self.W[i], np.array(centres), np.array(radii) + c).any(axis=0)
            if hits.any():
                return labels[int(np.argmax(hits))]
        for j in np.flatnonzero(self.docked).tolist():
            if (penetration_depth(samples, self.L[i], self.W[i], self.est[j], self.L[j], self.W[j]) > -c).any():
                return f"docked {self.name(j)}"
        if self.scn.arena_um is not None and (arena_gap(samples, self.L[i], self.W[i], self.scn.arena_um) < c).any():
            return "the arena edge"
        return None

    def hit_mask(self, samples: np.ndarray, i: int, orbiting: Sequence[int], *, clearance: float | None = None) -> np.ndarray:
        """Per sample of robot ``i``'s body: whether it hits an orbit, a docked robot or the arena edge, (M,)."""
        c = self.cfg.clearance_um if clearance is None else clearance
        samples = np.atleast_2d(samples)
        out = np.zeros(samples.shape[0], dtype=bool)
        orbiting = [j for j in orbiting if j != i and not self.docked[j]]
        if orbiting:
            centres = turning_centres(self.est[orbiting], self.r_hat[orbiting])
            out |= bodies_hit_discs(samples, self.L[i], self.W[i], centres, self.rstar[orbiting] + c).any(axis=1)
        for j in np.flatnonzero(self.docked):
            out |= penetration_depth(samples, self.L[i], self.W[i], self.est[j], self.L[j], self.W[j]) > -c
        if self.scn.arena_um is not None:
            out |= arena_gap(samples, self.L[i], self.W[i], self.scn.arena_um) < c
        return out

    def region(self, i: int) -> tuple[float, float]:
        """``(radius_um, half_height_rad)`` of robot ``i``'s regions: C_alpha (bounds) clipped (see module notes)."""
        cyl, cfg = self.cylinders[i], self.cfg
        rad = min(max(cyl.radius_um, cfg.min_region_um), cfg.region_um)
        hgt = min(max(cyl.height_rad, math.radians(cfg.min_region_deg)), math.radians(cfg.region_deg))
        return rad, hgt

    def cylinder_note(self, i: int) -> str:
        cyl = self.cylinders[i]
        return f"C_alpha (bounds) {cyl.radius_um:.0f} um / {math.degrees(cyl.height_rad):.0f} deg"

    def path_into_region(self, i: int, a_pose, start=None) -> paths.Path:
        """The shortest path from robot ``i``'s estimate (or ``start``) into the region around ``a_pose``
        (A_i, A_n', ...): :func:`region_path` with the robot's region and identified radius."""
        rad, hgt = self.region(i)
        return region_path(self.est[i] if start is None else start, a_pose, rad, hgt, float(self.r_hat[i]))

    def stalled(self, i: int, before: np.ndarray, duration_s: float) -> bool:
        """Whether robot ``i`` moved less than 15 % of what ``duration_s`` of driving should give."""
        return float(np.hypot(*(self.est[i, :2] - before[:2]))) < 0.15 * float(self.v_hat[i]) * duration_s


# -- single robots: sigma_1 then sigma_2 ------------------------------------------------------------


def _intermediate_for(loop: SeedLoop, i: int, goal, co, orbiting) -> tuple[np.ndarray, float]:
    """The nominal a_i and its S_2f duty: the first duty whose arc is clear (else S_2f(sym), logged)."""
    cfg = loop.cfg
    first = None
    for rho in cfg.s2f_duties:
        found = nominal_intermediate(goal, float(loop.r_nom[i]), co, rho, margin_um=cfg.co_margin_um + loop.region(i)[0])
        if found is None:
            continue
        a_pose, s = found
        first = first or (a_pose, rho)
        arc = arc_back(goal, np.linspace(0.0, s, max(8, int(s / 10.0))), float(loop.r_nom[i]) / rho)
        near = arc[:, :2] - np.asarray(goal)[:2]
        far = arc[np.hypot(*near.T) > 0.5 * loop.L[i] + 5.0]  # the slot itself touches its neighbours
        if loop.hit(far, i, orbiting) is None:
            return a_pose, rho
    if first is None:
        raise SeedStop(f"{loop.label(i)}: no intermediate configuration a_i outside C_O (App. 3.2: A_i* is empty)")
    loop.log("a_i", i, "no S_2f arc into the slot clears the obstacles; using S_2f(sym) anyway")
    return first


def gross_motion(loop: SeedLoop, i: int, turn_k: int, straight_k: int, targets: list, inside, orbiting) -> bool:
    """sigma_1: re-plan the shortest path to the next target every t_x; True once ``inside()``.

    ``targets`` are poses (route waypoints, then a_i); a waypoint within the region radius counts as
    passed. A robot that has not left its orbit yet waits (orbits) while its direct path is blocked, for
    at most one period. False when the last target was reached but ``inside()`` is not true.
    """
    targets = list(targets)
    waited, stalls = 0.0, 0
    rad, _ = loop.region(i)
    for _ in range(loop.cfg.max_cycles):
        if inside():
            return True
        p = loop.est[i]
        while len(targets) > 1 and np.hypot(*(p[:2] - targets[0][:2])) <= max(rad, 40.0):
            targets.pop(0)
        path = loop.path_into_region(i, targets[0]) if len(targets) == 1 else paths.shortest_path(p, targets[0], float(loop.r_hat[i]))
        blocked = loop.hit(path.sample(10.0), i, orbiting)
        period = TWO_PI / float(loop.omega_hat[i])
        if blocked is not None and len(targets) > 1 and waited == 0.0:
            # skip ahead if clear
            path = (loop.path_into_region(i, targets[1]) if len(targets) == 2
                    else paths.shortest_path(p, targets[1], float(loop.r_hat[i])))
            if loop.hit(path.sample(10.0), i, orbiting) is None:
                targets.pop(0)
                blocked = None
        if blocked is not None and waited < period:
            loop.log("wait", i, f"path blocked by {blocked}: orbits for t_x")
            loop.drive([(turn_k, loop.tx)])
            waited += loop.tx
            continue
        loop.replans += 1
        whole = path.length / float(loop.v_hat[i]) <= 1.6 * loop.tx
        steps = loop.path_steps(path, i, turn_k, straight_k, None if whole else loop.tx)
        before = loop.est[i].copy()
        loop.drive(steps)
        duration = math.fsum(d for _, d in steps)
        stalls = stalls + 1 if loop.stalled(i, before, duration) else 0
        if stalls >= 3:
            raise SeedStop(f"{loop.label(i)} stopped during gross motion at ({loop.est[i, 0]:.0f}, {loop.est[i, 1]:.0f}) um (failure "
                           "region H)")
        if whole:
            if len(targets) == 1:
                return bool(inside())
            targets.pop(0)
    raise SeedStop(f"{loop.label(i)}: gross motion did not reach A_i in {loop.cfg.max_cycles} re-plans")


def check_docked(loop: SeedLoop, i: int, straight_k: int, goal) -> None:
    """Push until robot ``i`` stops; docked if at its slot, else the strategy ends in H."""
    cfg = loop.cfg
    for _ in range(6):
        before = loop.est[i].copy()
        loop.drive([(straight_k, loop.tx)])
        if loop.stalled(i, before, loop.tx):
            dpos = float(np.hypot(*(loop.est[i, :2] - goal[:2])))
            dth = abs(float(angle_difference(loop.est[i, 2], goal[2])))
            if dpos <= cfg.dock_tol_um and dth <= math.radians(cfg.dock_tol_deg):
                loop.docked[i] = True
                loop.log("docked", i, f"{dpos:.1f} um, {math.degrees(dth):.1f} deg from the slot")
                return
            raise SeedStop(f"{loop.label(i)} stopped {dpos:.0f} um / {math.degrees(dth):.0f} deg from its slot (failure region H)")
    raise SeedStop(f"{loop.label(i)} kept moving after its fine motion: it missed its slot")


def fine_motion(loop: SeedLoop, i: int, turn_k: int, straight_k: int, goal) -> bool:
    """sigma_2: S_2f arcs through the docking point, ``r'`` re-computed every t_x; False if it left the preimage."""
    cfg = loop.cfg
    cone = math.radians(cfg.sticking_cone_deg)
    for _ in range(loop.cfg.max_cycles):
        fine = s2f_duty(loop.est[i], goal[:2], float(loop.r_hat[i]))
        if fine is None or abs(float(angle_difference(fine.arrival_rad, goal[2]))) > cone:
            near = float(np.hypot(*(loop.est[i, :2] - goal[:2]))) <= cfg.dock_tol_um
            if near:  # at the structure already: push and let compliance act
                check_docked(loop, i, straight_k, goal)
                return True
            why = ("no arc of radius >= r" if fine is None
                   else f"arrival {math.degrees(abs(float(angle_difference(fine.arrival_rad, goal[2])))):.0f} deg off")
            loop.log("preimage", i, f"left the fine-motion preimage ({why}): back to gross motion")
            return False
        loop.replans += 1
        t_arc = fine.length_um / float(loop.v_hat[i])
        if t_arc <= 1.6 * loop.tx:
            loop.drive(s2f_steps(fine.rho_a, t_arc, cfg.switch_period_s, turn_k, straight_k) + [(straight_k, cfg.push_s)])
            check_docked(loop, i, straight_k, goal)
            return True
        loop.drive(s2f_steps(fine.rho_a, loop.tx, cfg.switch_period_s, turn_k, straight_k))
    return False


def dock_single(loop: SeedLoop, k: int, goal, co, waypoints) -> None:
    """Dock D_k (k <= n-2): sigma_1 into A_k outside C_O, then sigma_2 (S_2f) and docking compliance."""
    i = loop.by_rank[k]
    cfg = loop.cfg
    orbiting = [loop.by_rank[j] for j in range(1, k)]
    a_pose, rho = _intermediate_for(loop, i, goal, co, orbiting)
    rad, hgt = loop.region(i)
    loop.log("a_i", i, f"a_i = ({a_pose[0]:.0f}, {a_pose[1]:.0f}, {math.degrees(a_pose[2]) % 360:.0f} deg), S_2f rho_a {rho:.2f}; A_i: "
                       f"{rad:.0f} um / {math.degrees(hgt):.0f} deg ({loop.cylinder_note(i)})")
    cone = math.radians(cfg.sticking_cone_deg)
    route = [np.asarray(w, float) for w in waypoints if not bool(in_proximity(co, np.asarray(w)[:2]))]

    def inside() -> bool:
        return intermediate_reason(loop.est[i], a_pose, goal, float(loop.r_hat[i]), co, region_um=rad, region_rad=hgt,
                                   cone_rad=cone) is None

    for _attempt in range(cfg.fine_attempts):
        if not gross_motion(loop, i, k, k - 1, route + [a_pose], inside, orbiting):
            why = intermediate_reason(loop.est[i], a_pose, goal, float(loop.r_hat[i]), co, region_um=rad, region_rad=hgt, cone_rad=cone)
            loop.log("retry", i, f"ended outside A_i ({why}): re-plans to a_i")
            route = []
            continue
        loop.log("A_i", i, "entered A_i: fine motion (S_2f)")
        if fine_motion(loop, i, k, k - 1, goal):
            return
        route = []
    raise SeedStop(f"{loop.label(i)} did not dock: {cfg.fine_attempts} times in A_i without a fine motion into its slot")
