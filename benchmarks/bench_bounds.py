"""Error-bound benchmark: empirical coverage of delta(t) against the simulator, and the bounds' cost.

Run: python benchmarks/bench_bounds.py [--trials N] [--seed S]

For examples/four-robots.toml and a few generated 4-robot scenarios (heterogeneous robots, the literature's
noise), every robot alone on a :class:`stressbots.sim.SimulatedPlant` drives four open-loop sequences of
t_2pi (turning, straight, S_2f(sym), a random mix) as Drives of t_x = 1 s; after every Drive the true
pose's deviation from the nominal motion is compared with delta(t) of that sequence
(:func:`stressbots.bounds.empirical_coverage`). Printed per k: the fraction of checkpoints inside (position
*and* heading), the fraction of sequence ends inside, and quantiles of error / bound (how loose the bound
is). Then the time of a full ``analyse_bounds`` and the critical noise scales of the example.
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path

from stressbots.bounds import analyse_bounds, critical_noise_scales, empirical_coverage
from stressbots.generate import LITERATURE_NOISE, random_scenario
from stressbots.scenario import load

ROOT = Path(__file__).resolve().parents[1]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=200, help="simulated runs per robot and scenario")
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args()

    example = load(ROOT / "examples" / "four-robots.toml")
    scenarios = [("examples/four-robots.toml", example)] + [
        (f"random 4-robot tee #{s}", random_scenario(4, 100 + s, noise=LITERATURE_NOISE)) for s in range(3)
    ]
    print(f"empirical coverage of delta(t), {args.trials} simulated runs per robot, seed {args.seed}")
    print(f"{'scenario':<28} {'k':>4} {'checkpoints':>11} {'outside':>7} {'inside':>8} {'ends in':>8} {'err/bound p50':>13} {'p99':>6} "
          f"{'max':>6} {'s':>6}")
    for label, scn in scenarios:
        for k in (1.0, 2.0, 3.0):
            t = time.perf_counter()
            c = empirical_coverage(scn, trials=args.trials, seed=args.seed, k=k)
            dt = time.perf_counter() - t
            print(f"{label:<28} {k:>4g} {c.checkpoints:>11} {c.checkpoints - c.inside:>7} {100 * c.fraction:>7.3f}% "
                  f"{100 * c.end_fraction:>7.3f}% {c.ratio_p50:>13.3f} {c.ratio_p99:>6.3f} {c.ratio_max:>6.3f} {dt:>6.1f}")

    t = time.perf_counter()
    rep = analyse_bounds(example)
    dt = time.perf_counter() - t
    print(f"\nanalyse_bounds(examples/four-robots.toml): {dt:.2f} s (planner included)")
    for rb in rep.robots:
        print(f"  {rb.label:<7} t_2pi {rb.t_2pi_s:5.1f} s  r_alpha {rb.cylinder.radius_um:6.0f} um  "
              f"h_alpha {math.degrees(rb.cylinder.height_rad):6.1f} deg  {'guaranteed' if rb.guaranteed else 'not guaranteed'}")
    p = rep.projection
    print(f"  D_n timed forward projection: t_4pi {p.t_4pi_s:.1f} s, radius {p.radius_um:.0f} um, "
          f"heading +-{math.degrees(p.heading_rad):.1f} deg")
    for k in (3.0, 2.0):
        t = time.perf_counter()
        sc = critical_noise_scales(example, k=k, structure=rep.structure)
        print(f"  critical noise scales at k = {k:g}: " + ", ".join(f"{nm} {v:.3g}" for nm, v in sc.items())
              + f"  ({time.perf_counter() - t:.1f} s)")


if __name__ == "__main__":
    main()
