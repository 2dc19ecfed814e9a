"""G_1 in the seed's strategy (App. 2.1 and 3.3): two stages, region checks, re-planning, S_3f.

D_n and D_(n-1) move together, but only one robot's error can be corrected at a time:

- **nominal**: the pair's intermediate configurations ``a_n``, ``a_(n-1)`` lie back along the S_3f arcs
  (eqs. 2-3 corrected, S_3f(sym) first) that end in the two slots, with arc lengths in the ratio of the
  speeds (both arrive together), outside the proximity regions C_O (each partner's slot body expanded
  by ``2 r*``); the swept bodies must clear each other, the lower orbits and the arena;
- **stage 1** (sigma_1,1; ``P_n``/``P_(n-1)``): D_n is re-planned every t_x to ``A_n'`` while D_(n-1)
  orbits. ``a_n'`` is ``v_n t_2`` behind ``a_n`` on its heading, ``t_2`` the time of D_(n-1)'s stage-2
  path from a departure pose on its orbit; D_n's path is lengthened to end when D_(n-1) is back at that
  pose (``t_wait + k T_(n-1)``, App. 2.1): it orbits in place, then takes the shortest path
  (:func:`orbit_then_go`; :func:`stressbots.paths.path_of_length` as a fallback). The departure phase is
  the one (of :data:`DEPARTURE_PHASES`) with the shortest clear stage 2 that D_n can reach in time;
- **partial stage 2** (when no straight run of D_n covers the whole stage 2, SPEC 5's known limit):
  D_(n-1) moves toward ``A_(n-1)`` for as long as a clear straight run of D_n allows, then sigma_1 is
  re-planned from the measured poses (App. 3.3's re-planning used as a plan);
- **stage 2** (sigma_1,2; ``P_(n-1)``/``P_(n-2)``): D_(n-1) is re-planned every t_x to ``A_(n-1)``; D_n
  drives straight, uncorrected, to ``A_n``. When one robot enters its region and the other does not,
  sigma_1 is re-planned from the measured poses (back to stage 1, App. 3.3);
- **fine motion** (sigma_2): from ``A_n x A_(n-1)`` eq. (1) gives each robot's ``r'`` through its docking
  point, :func:`stressbots.seed_fine_motion.s3f_duty` the common duty; re-computed every t_x. Then both
  push straight (``P_(n-2)``) and self-aligning compliance forms G_1, or they stop in H.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from . import paths
from .collision import penetration_depth
from .kinematics import move
from .robots import TWO_PI, Pose, angle_difference, front_midpoints, turning_centres
from .seed_fine_motion import arc_back, s2f_duty, s3f_duty, s3f_radii, s3f_steps
from .seed_loop import SeedLoop, SeedStop, in_proximity

__all__ = ["PairNominal", "Departure", "pair_nominal", "form_pair", "DEPARTURE_PHASES"]

DEPARTURE_PHASES = 24
"""Departure headings of D_(n-1) tried on its orbit (every 15 deg): the seed's "geometric heuristics"."""

MAX_PERIODS = 8
"""Whole orbit periods of D_(n-1) D_n's stage-1 path may be lengthened by (App. 2.1)."""

PAIR_TOL_UM, PAIR_TOL_DEG = 25.0, 12.0
"""G_1 formed: front-edge midpoints this close and headings this close to opposite (measured)."""


class PairNominal(NamedTuple):
    """The pair's intermediate configurations and the S_3f duty that joins them to the slots."""

    a_n: np.ndarray
    a_m: np.ndarray
    rhos: tuple[float, float, float]
    duration_s: float


class Departure(NamedTuple):
    """Stage 2 as planned: D_(n-1) leaves its orbit at ``pose``; D_n starts its straight run at ``a_n_prime``."""

    heading: float
    pose: np.ndarray
    path: paths.Path
    t2_s: float
    a_n_prime: np.ndarray
    wait_s: float = 0.0


def _sweeps_clear(loop: SeedLoop, N: int, M: int, gN, gM, rN: float, rM: float, T: float, lower) -> bool:
    t = np.linspace(0.0, T, 60)
    pN = arc_back(gN, loop.v_nom[N] * (T - t), rN)
    pM = arc_back(gM, loop.v_nom[M] * (T - t), rM)
    if (penetration_depth(pN, loop.L[N], loop.W[N], pM, loop.L[M], loop.W[M]) > 0.5).any():
        return False
    return loop.hit(pN, N, lower) is None and loop.hit(pM, M, lower) is None


def pair_nominal(loop: SeedLoop, structure, gN, gM, lower) -> PairNominal | None:
    """``a_n``, ``a_(n-1)`` outside C_O on S_3f arcs into the slots (first duty of the settings that fits)."""
    N, M = loop.by_rank[loop.n], loop.by_rank[loop.n - 1]
    cfg = loop.cfg
    co_N = structure.proximity_region(loop.name(N), float(loop.rstar[N])).buffer(cfg.co_margin_um + loop.region(N)[0])
    co_M = structure.proximity_region(loop.name(M), float(loop.rstar[M])).buffer(cfg.co_margin_um + loop.region(M)[0])
    T = np.arange(0.5, 60.0, 0.25)
    for rhos in cfg.s3f_duties:
        rN, rM = s3f_radii(rhos, float(loop.r_nom[N]), float(loop.r_nom[M]))
        aN = arc_back(gN, loop.v_nom[N] * T, rN)
        aM = arc_back(gM, loop.v_nom[M] * T, rM)
        bad = in_proximity(co_N, aN[:, :2]) | in_proximity(co_M, aM[:, :2])
        good = np.flatnonzero(~bad)  # the first exit from C_O (an arc's circle may come back into it)
        if good.size == 0:
            continue
        for k in range(int(good[0]), min(int(good[0]) + 24, T.size), 4):
            if _sweeps_clear(loop, N, M, gN, gM, rN, rM, float(T[k]), lower):
                r1, r2, r3 = (float(x) for x in rhos)
                return PairNominal(aN[k], aM[k], (r1, r2, r3), float(T[k]))
    return None


def _pose_on_orbit(centre, radius_um: float, theta: float) -> np.ndarray:
    return np.array([centre[0] - radius_um * math.cos(theta), centre[1] + radius_um * math.sin(theta), float(np.mod(theta, TWO_PI))])


def departure(loop: SeedLoop, nominal: PairNominal, lower) -> Departure | None:
    """The departure of D_(n-1) from its measured orbit with the shortest clear stage 2 that D_n can reach
    in time (the first clear one when D_n reaches none: stage 1 then says so); None if none is clear."""
    N, M = loop.by_rank[loop.n], loop.by_rank[loop.n - 1]
    c = loop.cfg.clearance_um
    rM, vM, vN = float(loop.r_hat[M]), float(loop.v_hat[M]), float(loop.v_hat[N])
    cM = turning_centres(loop.est[M], rM)[0]
    orbit_disc = [(cM, float(loop.rstar[M]), f"the orbit of {loop.name(M)}")]
    th_n = float(nominal.a_n[2])
    h = np.array([math.sin(th_n), math.cos(th_n)])
    clear = []
    for th in np.linspace(0.0, TWO_PI, DEPARTURE_PHASES, endpoint=False):
        q = _pose_on_orbit(cM, rM, float(th))
        path = loop.path_into_region(M, nominal.a_m, q)
        t2 = path.length / vM
        a_np = np.array([*(nominal.a_n[:2] - vN * t2 * h), th_n])
        run = move(a_np, np.linspace(0.0, vN * t2, max(2, int(vN * t2 / 10.0))), 0.0)
        if loop.hit(run, N, lower) is not None or loop.hit(run[:1], N, [], discs=orbit_disc) is not None:
            continue
        if not _orbit_free(loop, N, turning_centres(a_np, loop.r_hat[N])[0], lower, [cM], [float(loop.rstar[M])]):
            continue  # D_n arrives at a_n' on a turn: that circle must be free
        if loop.hit(path.sample(10.0), M, lower) is not None:
            continue
        times = np.linspace(0.0, t2, max(2, int(t2 * 10)))
        pM = path.pose_at(vM * times)
        pN = move(a_np, vN * times, 0.0)
        if (penetration_depth(pN, loop.L[N], loop.W[N], pM, loop.L[M], loop.W[M]) > -c)[:-1].any():
            continue
        clear.append(Departure(float(th), q, path, t2, a_np))
    clear.sort(key=lambda d: d.t2_s)
    for dep in clear:
        if _reachable(loop, dep, lower):
            return dep
    return clear[0] if clear else None


def _reachable(loop: SeedLoop, dep: Departure, lower) -> bool:
    """Whether D_n has a clear stage-1 path to ``dep.a_n_prime`` timed to D_(n-1)'s departure, from now."""
    N, M = loop.by_rank[loop.n], loop.by_rank[loop.n - 1]
    w = float(loop.omega_hat[M])
    t_wait = float(np.mod(dep.heading - loop.est[M, 2], TWO_PI)) / w
    durations = [t_wait + k * TWO_PI / w for k in range(MAX_PERIODS)]
    disc = [(turning_centres(loop.est[M], loop.r_hat[M])[0], float(loop.rstar[M]), "")]
    return orbit_then_go(loop, N, dep.a_n_prime, durations, lower, disc) is not None or \
        timed_path(loop, N, dep.a_n_prime, durations, lower, disc) is not None


def _clear_time(loop: SeedLoop, N: int, M: int, track: np.ndarray, path: paths.Path, t_max: float, lower) -> float:
    """How long D_n can run straight from ``track`` while D_(n-1) drives ``path`` (s), everything clear.

    The pair must keep the clearance from each other, the lower orbits and the arena, and D_(n-1)'s orbit
    where it stops must clear D_n (it orbits there during the next stage 1).
    """
    c = loop.cfg.clearance_um
    vN, vM = float(loop.v_hat[N]), float(loop.v_hat[M])
    times = np.arange(0.0, t_max + 1e-9, 0.25)
    pN = move(track, vN * times, 0.0)
    pM = path.pose_at(np.minimum(vM * times, path.length))
    bad = penetration_depth(pN, loop.L[N], loop.W[N], pM, loop.L[M], loop.W[M]) > -c
    bad |= loop.hit_mask(pN, N, lower) | loop.hit_mask(pM, M, lower)
    k = int(np.argmax(bad)) if bad.any() else times.size  # the first time something is hit
    while k > 1:
        cM = turning_centres(pM[k - 1], loop.r_hat[M])[0]
        cN = turning_centres(pN[k - 1], loop.r_hat[N])[0]
        disc = [(cM, float(loop.rstar[M]), "")]
        # D_n orbits where its run ends during the next stage 1: that orbit must be free too
        free = _orbit_free(loop, N, cN, lower, [cM], [float(loop.rstar[M])])
        if free and loop.hit(pN[k - 1 : k], N, [], discs=disc) is None and loop.hit(pM[k - 1 : k], M, lower, clearance=0.0) is None:
            return float(times[k - 1])
        k -= 2  # back in 0.5 s steps
    return 0.0


def _orbit_free(loop: SeedLoop, i: int, centre, lower, centres=(), radii=()) -> bool:
    """Whether robot ``i``'s orbit disc about ``centre`` clears the lower orbits, the given discs and the arena."""
    c = loop.cfg.clearance_um
    cs = [*turning_centres(loop.est[lower], loop.r_hat[lower])] if lower else []
    rs = list(loop.rstar[lower]) if lower else []
    cs_all, rs_all = np.array(cs + list(centres)).reshape(-1, 2), np.array(rs + list(radii))
    clear = (np.hypot(*(cs_all - centre).T) >= rs_all + loop.rstar[i] + c).all() if cs_all.size else True
    return bool(clear) and _inside_arena(loop, centre, float(loop.rstar[i]) + c)


def _inside_arena(loop: SeedLoop, centre, radius_um: float) -> bool:
    if loop.scn.arena_um is None:
        return True
    w, h = loop.scn.arena_um
    return bool(radius_um <= centre[0] <= w - radius_um and radius_um <= centre[1] <= h - radius_um)


PARTIAL_TURNS = 3
"""Extra whole turns D_n may orbit before a partial stage 2, to meet D_(n-1) at a better departure phase."""

PARTIAL_PHASES = 24
"""Run headings of D_n tried for a partial stage 2 (every 15 deg)."""


def partial_departure(loop: SeedLoop, nominal: PairNominal, lower) -> Departure | None:
    """A partial stage 2 when the whole one has no clear run: D_(n-1) gets as close to ``a_(n-1)`` as a
    clear straight run of D_n allows; sigma_1 is then re-planned from the measured poses (App. 3.3's
    re-planning used as a plan: SPEC 5's multi-phase G_1).

    D_n's run starts on its own orbit: it orbits under P_n (with D_(n-1)) for part of a turn plus up to
    :data:`PARTIAL_TURNS` whole turns, then both go (24 x 4 choices); D_(n-1) departs from wherever it
    then is on its orbit. The best choice leaves D_(n-1) the shortest path to ``a_(n-1)`` afterwards.
    Returns a :class:`Departure` whose ``heading`` is D_n's run heading, ``t2_s`` the partial duration,
    ``a_n_prime`` the run's start and ``wait_s`` D_n's orbiting before it.
    """
    N, M = loop.by_rank[loop.n], loop.by_rank[loop.n - 1]
    rM, rN, vM = float(loop.r_hat[M]), float(loop.r_hat[N]), float(loop.v_hat[M])
    wN, wM = float(loop.omega_hat[N]), float(loop.omega_hat[M])
    cM = turning_centres(loop.est[M], rM)[0]
    cN = turning_centres(loop.est[N], rN)[0]
    best, best_left = None, math.inf
    for tn in np.linspace(0.0, TWO_PI, PARTIAL_PHASES, endpoint=False):
        track = _pose_on_orbit(cN, rN, float(tn))
        for turns in range(PARTIAL_TURNS + 1):
            t_reach = (float(np.mod(tn - loop.est[N, 2], TWO_PI)) + TWO_PI * turns) / wN
            q = _pose_on_orbit(cM, rM, float(loop.est[M, 2] + wM * t_reach))
            path = loop.path_into_region(M, nominal.a_m, q)
            t_p = _clear_time(loop, N, M, track, path, path.length / vM, lower)
            if t_p < 2.0:
                continue
            left = loop.path_into_region(M, nominal.a_m, path.pose_at(vM * t_p)).length
            if left < best_left - 1.0:
                best, best_left = Departure(float(tn), q, path, t_p, track, t_reach), left
    return best


def stage1_partial(loop: SeedLoop, dep: Departure) -> None:
    """Before a partial stage 2: D_n orbits (P_n, D_(n-1) orbiting too) for ``dep.wait_s``, until it heads
    along its run."""
    n = loop.n
    N = loop.by_rank[n]
    tol = loop.region(N)[1]
    t_end = loop.t + dep.wait_s
    for _ in range(loop.cfg.max_cycles):
        w = float(loop.omega_hat[N])
        off = float(np.mod(dep.heading - loop.est[N, 2], TWO_PI))
        left = max(t_end - loop.t, off / w if off > tol and off < TWO_PI - tol else 0.0)
        if left < 0.02:
            return
        step = min(loop.tx, left)
        before = loop.est[N].copy()
        loop.drive([(n, step)])
        if step >= 0.5 and abs(float(angle_difference(loop.est[N, 2], before[2]))) < 0.15 * w * step:
            raise SeedStop(f"{loop.label(N)} stopped turning toward its run (failure region H)")
    raise SeedStop(f"G_1: {loop.label(N)} did not reach the start of its run")


def _in_ball(loop: SeedLoop, i: int, target) -> bool:
    rad, hgt = loop.region(i)
    p = loop.est[i]
    return bool(np.hypot(*(p[:2] - target[:2])) <= rad and abs(float(angle_difference(p[2], target[2]))) <= hgt)


def orbit_then_go(loop: SeedLoop, N: int, target, durations, lower, disc) -> tuple[float, paths.Path] | None:
    """``(wait_s, path)``: D_n orbits in place for ``wait_s``, then takes the shortest path to ``target``,
    arriving after one of ``durations`` (s, tried in order); None when no such path is clear.

    This is App. 2.1's lengthening of D_n's path (so that D_(n-1), orbiting, is back at its departure pose
    when D_n arrives) in a form that re-planning keeps stable: the wait shrinks by t_x every cycle and
    the shortest path after it is the one already planned. The wait phase psi solves
    ``r psi + |shortest(q(psi), target)| = v d`` (5 deg grid, then secant steps).
    """
    r, v = float(loop.r_hat[N]), float(loop.v_hat[N])
    start = loop.est[N]
    psi = np.linspace(0.0, TWO_PI, 73)
    ends = move(start, r * psi, 1.0 / r)
    lengths = paths.shortest_path_lengths(ends, np.broadcast_to(target, ends.shape), r)

    def total(wait_um: float) -> float:
        return wait_um + paths.shortest_path(move(start, wait_um, 1.0 / r), target, r).length

    for d in durations:
        for m in range(3):
            f = r * (psi + TWO_PI * m) + lengths - v * d
            for j in np.flatnonzero(np.sign(f[:-1]) != np.sign(f[1:])):
                w0, w1 = r * (psi[j] + TWO_PI * m), r * (psi[j + 1] + TWO_PI * m)
                lo, hi = w0, w1
                f0, f1 = float(f[j]), float(f[j + 1])
                for _ in range(6):  # secant steps on a smooth stretch (a jump in the family is rejected below)
                    w = w0 - f0 * (w1 - w0) / (f1 - f0) if f1 != f0 else w0
                    fw = total(w) - v * d
                    if abs(fw) < 1e-3:
                        break
                    w0, f0, w1, f1 = w1, f1, w, fw
                if abs(total(w) - v * d) > 0.1 * v:  # more than 0.1 s off: a discontinuity, not a root
                    continue
                if not lo <= w <= hi:  # the secant ran out of its bracket (once to a negative wait): not this root
                    continue
                rest = paths.shortest_path(move(start, w, 1.0 / r), target, r)
                path = paths.Path(Pose(*start), r, (("R", w),) + rest.segments)
                if loop.hit(path.sample(10.0), N, lower, discs=disc) is None:
                    return w / v, path
    return None


def timed_path(loop: SeedLoop, N: int, target, durations, lower, disc) -> paths.Path | None:
    """The fallback of :func:`orbit_then_go`: a clear path of exactly one of ``durations`` (s) from
    :func:`stressbots.paths.path_of_length`, after orbiting for part of a turn (24 choices); None if none."""
    r, v = float(loop.r_hat[N]), float(loop.v_hat[N])
    start = loop.est[N]
    for duration in durations:
        for j in range(DEPARTURE_PHASES):
            wait_um = TWO_PI * r * j / DEPARTURE_PHASES
            if v * duration - wait_um <= 0.0:
                continue
            try:
                rest = paths.path_of_length(move(start, wait_um, 1.0 / r), target, r, v * duration - wait_um)
            except ValueError:
                continue
            cand = paths.Path(Pose(*start), r, (("R", wait_um),) + rest.segments)
            if loop.hit(cand.sample(10.0), N, lower, discs=disc) is None:
                return cand
    return None


def stage1(loop: SeedLoop, dep: Departure, lower) -> None:
    """sigma_1,1: D_n to A_n' (re-planned every t_x) while D_(n-1) orbits; the arrival is timed to
    D_(n-1)'s departure pose (:func:`orbit_then_go`). Residual timing errors are left to stage 2's region
    checks, as in the seed."""
    n = loop.n
    N, M = loop.by_rank[n], loop.by_rank[n - 1]
    stalls, departed = 0, False
    for _ in range(loop.cfg.max_cycles):
        if _in_ball(loop, N, dep.a_n_prime):
            return
        if departed:
            path = loop.path_into_region(N, dep.a_n_prime)
        else:
            w = float(loop.omega_hat[M])
            t_wait = float(np.mod(dep.heading - loop.est[M, 2], TWO_PI)) / w
            cM = turning_centres(loop.est[M], loop.r_hat[M])[0]
            disc = [(cM, float(loop.rstar[M]), f"the orbit of {loop.name(M)}")]
            durations = [t_wait + k * TWO_PI / w for k in range(MAX_PERIODS)]
            plan = orbit_then_go(loop, N, dep.a_n_prime, durations, lower, disc)
            if plan is None:
                committed = timed_path(loop, N, dep.a_n_prime, durations, lower, disc)
                if committed is None:
                    raise SeedStop(f"G_1 stage 1: {loop.label(N)} has no clear path to A_n' timed to {loop.label(M)}'s departure (within "
                                   f"{MAX_PERIODS} orbit periods)")
                loop.log("timed", N, f"follows a lengthened path of {committed.length:.0f} um (open loop until its last {2 * loop.tx:g} s)")
                _follow(loop, N, committed, n, n - 1)
                departed = True
                continue
            wait_s, path = plan
            if wait_s >= loop.tx:
                loop.drive([(n, loop.tx)])  # D_n orbits in place (P_n), so does D_(n-1)
                continue
            departed = True
        loop.replans += 1
        whole = path.length / float(loop.v_hat[N]) <= 1.6 * loop.tx
        steps = loop.path_steps(path, N, n, n - 1, None if whole else loop.tx)
        before = loop.est[N].copy()
        loop.drive(steps)
        stalls = stalls + 1 if loop.stalled(N, before, math.fsum(d for _, d in steps)) else 0
        if stalls >= 3:
            raise SeedStop(f"{loop.label(N)} stopped during G_1 stage 1 (failure region H)")
        if whole and not _in_ball(loop, N, dep.a_n_prime):
            loop.log("retry", N, "ended outside A_n': re-plans its timed path")
            departed = False
    raise SeedStop(f"G_1 stage 1: {loop.label(N)} did not reach A_n' in {loop.cfg.max_cycles} re-plans")


def _follow(loop: SeedLoop, N: int, path: paths.Path, turn_k: int, straight_k: int) -> None:
    """Drive ``path`` in t_x pieces, open loop, up to its last 2 t_x (re-planned from there on)."""
    v = float(loop.v_hat[N])
    s = 0.0
    while path.length - s > 2.0 * loop.tx * v:
        piece = paths.sub_path(path, s, s + loop.tx * v)
        loop.drive(loop.path_steps(piece, N, turn_k, straight_k))
        s += loop.tx * v


def stage2(loop: SeedLoop, nominal: PairNominal) -> bool:
    """sigma_1,2: D_(n-1) re-planned to A_(n-1), D_n straight; True when both are in their regions.

    False when one robot enters its region and the other does not (App. 3.3: re-plan sigma_1).
    """
    n = loop.n
    N, M = loop.by_rank[n], loop.by_rank[n - 1]
    h = np.array([math.sin(nominal.a_n[2]), math.cos(nominal.a_n[2])])
    rad_N = loop.region(N)[0]
    stalls = 0
    for _ in range(loop.cfg.max_cycles):
        path = loop.path_into_region(M, nominal.a_m)
        loop.replans += 1
        whole = path.length / float(loop.v_hat[M]) <= 1.6 * loop.tx
        steps = loop.path_steps(path, M, n - 1, n - 2, None if whole else loop.tx)
        before = loop.est.copy()
        loop.drive(steps)
        duration = math.fsum(d for _, d in steps)
        stuck = [i for i in (N, M) if loop.stalled(i, before[i], duration)]
        stalls = stalls + 1 if stuck else 0
        if stalls >= 3:
            raise SeedStop(f"{loop.label(stuck[0])} stopped during G_1 stage 2 (failure region H)")
        in_N, in_M = _in_ball(loop, N, nominal.a_n), _in_ball(loop, M, nominal.a_m)
        passed = float((loop.est[N, :2] - nominal.a_n[:2]) @ h) > rad_N
        if in_N and in_M:
            return True
        if in_M:
            loop.log("replan", M,
                     f"{loop.label(M)} entered A_(n-1) before {loop.label(N)} entered A_n (its path was shorter than nominal): re-plans "
                     "sigma_1")
            return False
        if in_N or passed:
            loop.log("replan", N,
                     f"{loop.label(N)} reached A_n before {loop.label(M)} entered A_(n-1) (its path was longer than nominal): re-plans "
                     "sigma_1")
            return False
    raise SeedStop(f"G_1 stage 2: {loop.label(M)} did not reach A_(n-1) in {loop.cfg.max_cycles} re-plans")


def partial_stage2(loop: SeedLoop, nominal: PairNominal, duration_s: float) -> None:
    """A planned part of stage 2: D_(n-1) re-planned toward ``a_(n-1)`` for ``duration_s``, D_n straight."""
    n = loop.n
    N, M = loop.by_rank[n], loop.by_rank[n - 1]
    left = duration_s
    while left > 1e-9:
        path = loop.path_into_region(M, nominal.a_m)
        loop.replans += 1
        steps = loop.path_steps(path, M, n - 1, n - 2, min(loop.tx, left))
        before = loop.est.copy()
        loop.drive(steps)
        d = math.fsum(x for _, x in steps)
        left -= d
        for i in (N, M):
            if loop.stalled(i, before[i], d):
                raise SeedStop(f"{loop.label(i)} stopped during a partial G_1 stage 2 (failure region H)")
        if d < 1e-9:
            break


def check_pair(loop: SeedLoop, _gN, _gM) -> None:
    """Push both straight until they stop: G_1 formed (both docked) or the strategy ends in H."""
    n = loop.n
    N, M = loop.by_rank[n], loop.by_rank[n - 1]
    for _ in range(4):
        before = loop.est.copy()
        loop.drive([(n - 2, loop.tx)])
        if loop.stalled(N, before[N], loop.tx) and loop.stalled(M, before[M], loop.tx):
            f = front_midpoints(loop.est[[N, M]], loop.L[[N, M]])
            gap = float(np.hypot(*(f[0] - f[1])))
            off = abs(float(angle_difference(loop.est[N, 2], loop.est[M, 2] + math.pi)))
            if gap <= PAIR_TOL_UM and off <= math.radians(PAIR_TOL_DEG):
                loop.docked[[N, M]] = True
                loop.log("G_1", None,
                         f"{loop.label(N)} and {loop.label(M)} formed G_1 (front edges {gap:.1f} um apart, {math.degrees(off):.1f} deg "
                         "from head-on)")
                return
            raise SeedStop(f"G_1 did not form: {loop.label(N)} and {loop.label(M)} stopped with front edges {gap:.0f} um apart, "
                           f"{math.degrees(off):.0f} deg from head-on (failure region H)")
    raise SeedStop(f"G_1 did not form: {loop.label(N)} and {loop.label(M)} kept moving after their S_3f arcs (they missed each other)")


def fine_pair(loop: SeedLoop, gN, gM) -> bool:
    """sigma_2 for the pair: S_3f arcs through both docking points; False if they left the preimage."""
    n, cfg = loop.n, loop.cfg
    N, M = loop.by_rank[n], loop.by_rank[n - 1]
    cone = math.radians(cfg.self_align_deg)
    for _ in range(cfg.max_cycles):
        fN = s2f_duty(loop.est[N], gN[:2], float(loop.r_hat[N]))
        fM = s2f_duty(loop.est[M], gM[:2], float(loop.r_hat[M]))
        why = None
        if fN is None or fM is None:
            why = "no arc of radius >= r through a docking point"
        elif max(abs(float(angle_difference(fN.arrival_rad, gN[2]))), abs(float(angle_difference(fM.arrival_rad, gM[2])))) > cone:
            why = "an arc arrives outside the self-alignment limit"
        rhos = None if why or fN is None or fM is None else s3f_duty(float(loop.r_hat[N]), fN.radius_um, float(loop.r_hat[M]), fM.radius_um)
        if why is None and rhos is None:
            why = f"outside the S_3f cones ({loop.label(N)} would have to turn more than {loop.label(M)})"
        if why is not None or fN is None or fM is None:
            loop.log("preimage", None, f"the pair left the S_3f preimage: {why}")
            return False
        loop.replans += 1
        T = 0.5 * (fN.length_um / float(loop.v_hat[N]) + fM.length_um / float(loop.v_hat[M]))
        if T <= 1.6 * loop.tx:
            loop.drive(s3f_steps(rhos, T, cfg.switch_period_s, n) + [(n - 2, cfg.push_s)])
            check_pair(loop, gN, gM)
            return True
        loop.drive(s3f_steps(rhos, loop.tx, cfg.switch_period_s, n))
    return False


def form_pair(loop: SeedLoop, structure, nominal_goals: np.ndarray) -> None:
    """Form G_1 with the seed's two stages, re-planning sigma_1 as App. 3.3 says (see module notes)."""
    n, cfg = loop.n, loop.cfg
    N, M = loop.by_rank[n], loop.by_rank[n - 1]
    lower = [loop.by_rank[k] for k in range(1, n - 1)]
    gN, gM = nominal_goals[N], nominal_goals[M]
    nominal = pair_nominal(loop, structure, gN, gM, lower)
    if nominal is None:
        raise SeedStop(f"G_1: no S_3f arcs into the slots of {loop.label(N)} and {loop.label(M)} start outside C_O and clear of the other "
                       "robots (A_n* empty)")
    loop.log("a_n", None,
             f"S_3f{tuple(round(r, 2) for r in nominal.rhos)}, {nominal.duration_s:.1f} s; a_n = ({nominal.a_n[0]:.0f}, "
             f"{nominal.a_n[1]:.0f}), a_(n-1) = ({nominal.a_m[0]:.0f}, {nominal.a_m[1]:.0f}); {loop.cylinder_note(N)}")
    replans = partials = 0
    while True:
        dep = departure(loop, nominal, lower)
        if dep is None:
            if partials >= cfg.partial_stages:
                raise SeedStop(f"G_1 did not form: no clear straight stage-2 run for {loop.label(N)} after {partials} partial stages (the "
                               "seed's two-stage scheme; SPEC 5's known limit)")
            dep = partial_departure(loop, nominal, lower)
            if dep is None:
                raise SeedStop(f"G_1: no departure of {loop.label(M)} from its orbit gives {loop.label(N)} a clear straight stage-2 run "
                               "(the seed's two-stage scheme; SPEC 5's known limit)")
            partials += 1
            loop.log("sigma_1", N,
                     f"no clear straight run to A_n: partial stage 2 ({dep.t2_s:.1f} s of {loop.label(M)}'s path) from a run at "
                     f"({dep.a_n_prime[0]:.0f}, {dep.a_n_prime[1]:.0f})")
            stage1_partial(loop, dep)
            partial_stage2(loop, nominal, dep.t2_s)
            continue
        loop.log("sigma_1", N,
                 f"stage 1 to A_n' ({dep.a_n_prime[0]:.0f}, {dep.a_n_prime[1]:.0f}); stage 2 {dep.t2_s:.1f} s from heading "
                 f"{math.degrees(dep.heading):.0f} deg")
        stage1(loop, dep, lower)
        if stage2(loop, nominal):
            loop.log("A_n", None, "both in A_n x A_(n-1): fine motion (S_3f)")
            if fine_pair(loop, gN, gM):
                return
        replans += 1
        if replans > cfg.pair_replans:
            raise SeedStop(f"G_1 did not form: {cfg.pair_replans} re-plans of sigma_1 without both robots in A_n x A_(n-1) and a fine "
                           "motion")
