"""Benchmark: one-way shortest path lengths, batch, against OMPL's Dubins distance in a Python loop.

Run ``python benchmarks/bench_paths.py [--pairs N] [--radius R] [--seed S]`` (OMPL from the ``bench``
extra: ``pip install -e ".[bench]"``; without it the OMPL figures are skipped with a message).

Prints, on the same random pairs (positions uniform on a 3 mm square, headings uniform):

- ns/pair of :func:`stressbots.paths.shortest_path_lengths` on the whole batch (best of several runs);
- us/call of :func:`stressbots.paths.shortest_path` for one query (the scalar fast path, a Path value);
- ns/pair of ``ompl.base.DubinsStateSpace.distance`` called in a Python loop, setting the two states
  each time (what a Python caller must do), and with all states built beforehand (OMPL's best case);
- the speed-up (target: at least 2x the loop);
- the price of turning one way: the mean ratio of the one-way length to the ordinary (two-way) Dubins
  length, from OMPL, or from the vectorised ordinary Dubins below when OMPL is absent. The two are
  cross-checked when both are there, and one-way >= two-way is checked on every pair.

Conventions: stressbots headings are clockwise from +y; OMPL's yaw is counter-clockwise from +x, so
``yaw = pi/2 - theta`` (the heading vector ``(sin theta, cos theta) = (cos yaw, sin yaw)``).
"""

from __future__ import annotations

import argparse
import math
import sys
import time

import numpy as np

from stressbots.paths import shortest_path, shortest_path_lengths

TWO_PI = 2.0 * math.pi


def random_pairs(n: int, seed: int, side_um: float = 3000.0):
    rng = np.random.default_rng(seed)
    starts = np.column_stack([rng.uniform(0, side_um, (n, 2)), rng.uniform(0, TWO_PI, n)])
    goals = np.column_stack([rng.uniform(0, side_um, (n, 2)), rng.uniform(0, TWO_PI, n)])
    return starts, goals


def dubins_two_way_lengths(starts, goals, radius):
    """Ordinary Dubins (both turning directions) shortest lengths, vectorised (Shkel & Lumelsky words).

    Poses in stressbots' convention; converted to yaw counter-clockwise from +x.
    """
    yaw1 = 0.5 * math.pi - starts[:, 2]
    yaw2 = 0.5 * math.pi - goals[:, 2]
    dx = (goals[:, 0] - starts[:, 0]) / radius
    dy = (goals[:, 1] - starts[:, 1]) / radius
    d = np.hypot(dx, dy)
    phi = np.arctan2(dy, dx)
    a = np.mod(yaw1 - phi, TWO_PI)
    b = np.mod(yaw2 - phi, TWO_PI)
    sa, sb, ca, cb = np.sin(a), np.sin(b), np.cos(a), np.cos(b)
    cab = np.cos(a - b)
    m = lambda x: np.mod(x, TWO_PI)  # noqa: E731
    out = np.full(starts.shape[0], np.inf)
    with np.errstate(invalid="ignore"):
        # LSL
        p2 = 2 + d * d - 2 * cab + 2 * d * (sa - sb)
        tmp = np.arctan2(cb - ca, d + sa - sb)
        L = m(tmp - a) + np.sqrt(p2) + m(b - tmp)
        out = np.where(p2 >= 0, np.minimum(out, L), out)
        # RSR
        p2 = 2 + d * d - 2 * cab + 2 * d * (sb - sa)
        tmp = np.arctan2(ca - cb, d - sa + sb)
        L = m(a - tmp) + np.sqrt(p2) + m(tmp - b)
        out = np.where(p2 >= 0, np.minimum(out, L), out)
        # LSR
        p2 = -2 + d * d + 2 * cab + 2 * d * (sa + sb)
        p = np.sqrt(p2)
        tmp = np.arctan2(-ca - cb, d + sa + sb) - np.arctan2(-2.0, p)
        L = m(tmp - a) + p + m(tmp - b)
        out = np.where(p2 >= 0, np.minimum(out, L), out)
        # RSL
        p2 = d * d - 2 + 2 * cab - 2 * d * (sa + sb)
        p = np.sqrt(p2)
        tmp = np.arctan2(ca + cb, d - sa - sb) - np.arctan2(2.0, p)
        L = m(a - tmp) + p + m(b - tmp)
        out = np.where(p2 >= 0, np.minimum(out, L), out)
        # RLR
        c = (6 - d * d + 2 * cab + 2 * d * (sa - sb)) / 8
        p = m(TWO_PI - np.arccos(c))
        t = m(a - np.arctan2(ca - cb, d - sa + sb) + 0.5 * p)
        L = t + p + m(a - b - t + p)
        out = np.where(np.abs(c) <= 1, np.minimum(out, L), out)
        # LRL
        c = (6 - d * d + 2 * cab + 2 * d * (sb - sa)) / 8
        p = m(TWO_PI - np.arccos(c))
        t = m(-a - np.arctan2(ca - cb, d + sa - sb) + 0.5 * p)
        L = t + p + m(b - a - t + p)
        out = np.where(np.abs(c) <= 1, np.minimum(out, L), out)
    return out * radius


def best_time(fn, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def ompl_loop(starts, goals, radius):
    """OMPL's DubinsStateSpace.distance in a Python loop; returns (lengths, seconds set+distance, seconds distance-only)."""
    from ompl import base as ob

    space = ob.DubinsStateSpace(radius)
    a, b = space.allocState(), space.allocState()
    n = starts.shape[0]
    sx, sy, syaw = starts[:, 0].tolist(), starts[:, 1].tolist(), (0.5 * math.pi - starts[:, 2]).tolist()
    gx, gy, gyaw = goals[:, 0].tolist(), goals[:, 1].tolist(), (0.5 * math.pi - goals[:, 2]).tolist()
    out = [0.0] * n
    dist = space.distance
    t0 = time.perf_counter()
    for i in range(n):
        a.setXY(sx[i], sy[i])
        a.setYaw(syaw[i])
        b.setXY(gx[i], gy[i])
        b.setYaw(gyaw[i])
        out[i] = dist(a, b)
    t_set = time.perf_counter() - t0
    # OMPL's best case: states already built
    sa, sb = [], []
    for i in range(n):
        u, v = space.allocState(), space.allocState()
        u.setXY(sx[i], sy[i])
        u.setYaw(syaw[i])
        v.setXY(gx[i], gy[i])
        v.setYaw(gyaw[i])
        sa.append(u)
        sb.append(v)
    t0 = time.perf_counter()
    for u, v in zip(sa, sb, strict=True):
        dist(u, v)
    t_only = time.perf_counter() - t0
    return np.array(out), t_set, t_only


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--pairs", type=int, default=100_000)
    ap.add_argument("--radius", type=float, default=200.0, help="turning radius (um)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--repeat", type=int, default=7, help="timing runs of the batch (best counts)")
    ap.add_argument("--ompl-repeat", type=int, default=3, help="timing runs of the OMPL loop (best counts)")
    args = ap.parse_args(argv)
    n, r = args.pairs, args.radius
    starts, goals = random_pairs(n, args.seed)
    print(f"pairs: {n}, turning radius {r:g} um, positions on a 3000 um square, headings uniform")

    shortest_path_lengths(starts[:1000], goals[:1000], r)  # warm up
    t_ours = best_time(lambda: shortest_path_lengths(starts, goals, r), args.repeat)
    one_way = shortest_path_lengths(starts, goals, r)
    ns_ours = t_ours / n * 1e9
    print(f"stressbots shortest_path_lengths (batch, one-way): {ns_ours:8.1f} ns/pair (best of {args.repeat})")
    single = [(tuple(map(float, s)), tuple(map(float, g))) for s, g in zip(starts[:5000], goals[:5000], strict=True)]
    t_single = best_time(lambda: [shortest_path(s, g, r) for s, g in single], args.repeat)
    print(f"stressbots shortest_path (one query, Path value, scalar fast path): {t_single / len(single) * 1e6:8.2f} us/call")

    two_way_own = dubins_two_way_lengths(starts, goals, r)
    try:
        import ompl.base  # noqa: F401
    except ImportError:
        print("OMPL not installed (pip install ompl, or the project's [bench] extra): skipping the OMPL timing;")
        print("the two-way lengths below come from this script's own vectorised ordinary Dubins.")
        two_way, source = two_way_own, "own ordinary Dubins"
    else:
        runs = [ompl_loop(starts, goals, r) for _ in range(args.ompl_repeat)]
        two_way = runs[0][0]
        t_set = min(run[1] for run in runs)
        t_only = min(run[2] for run in runs)
        ns_set, ns_only = t_set / n * 1e9, t_only / n * 1e9
        print(f"OMPL DubinsStateSpace.distance, Python loop, set states + distance: {ns_set:8.1f} ns/pair "
              f"(best of {args.ompl_repeat})")
        print(f"OMPL DubinsStateSpace.distance, Python loop, states pre-built:      {ns_only:8.1f} ns/pair")
        print(f"speed-up: {ns_set / ns_ours:.2f}x the loop ({ns_only / ns_ours:.2f}x the pre-built loop); "
              f"target >= 2x: {'met' if ns_set / ns_ours >= 2 else 'NOT met'}")
        diff = np.max(np.abs(two_way - two_way_own) / (r + two_way))
        print(f"cross-check own ordinary Dubins vs OMPL: max relative difference {diff:.2e}")
        source = "OMPL"
    ratio = one_way / two_way
    bad = np.sum(one_way < two_way * (1 - 1e-9))
    print(f"price of turning one way (one-way / two-way Dubins, two-way from {source}): "
          f"mean {ratio.mean():.4f}, median {np.median(ratio):.4f}, p90 {np.percentile(ratio, 90):.4f}, "
          f"max {ratio.max():.4f}, min {ratio.min():.6f}")
    print(f"pairs where the one-way path is shorter than the two-way optimum (must be 0): {bad}")
    return 0 if bad == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
