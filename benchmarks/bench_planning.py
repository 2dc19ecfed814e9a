"""Planner benchmark: speed (4 and 12 robots), success rate and plan efficiency on generated layouts.

Run: python benchmarks/bench_planning.py [--trials N]
Targets (issue 4): a 4-robot plan in under 1 s, a 12-robot plan in under 30 s on the 2-core machine.
"""

from __future__ import annotations

import argparse
import statistics
import time
from pathlib import Path

from stressbots.errors import PlanningError
from stressbots.generate import random_scenario
from stressbots.planning import PlannerOptions, plan_assembly
from stressbots.scenario import load

ROOT = Path(__file__).resolve().parents[1]


def timed(scn, budget=60.0):
    t = time.perf_counter()
    try:
        r = plan_assembly(scn, PlannerOptions(time_budget_s=budget))
        return time.perf_counter() - t, r
    except PlanningError as exc:
        return time.perf_counter() - t, exc


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--trials", type=int, default=6, help="generated layouts per (n, shape)")
    args = ap.parse_args()

    scn = load(ROOT / "examples" / "four-robots.toml")
    times = [timed(scn)[0] for _ in range(3)]
    dt, r = timed(scn)
    print(f"examples/four-robots.toml: best {min(times):.2f} s, duration {r.summary['duration_s']:.1f} s, "
          f"efficiency {r.summary['efficiency']:.2f}")

    print(f"\n{'n':>3} {'shape':>7} {'solved':>7} {'median s':>9} {'max s':>7} {'efficiency':>11}")
    for n, shapes in [(3, ("tee",)), (4, ("tee", "cross")), (5, ("comb",)), (6, ("ladder", "tee")), (12, ("comb", "cross"))]:
        for shape in shapes:
            ok, secs, effs = 0, [], []
            for seed in range(args.trials if n < 12 else max(2, args.trials // 3)):
                s = random_scenario(n, 1000 + seed, shape=shape, explicit_goals=bool(seed % 2))
                dt, res = timed(s)
                secs.append(dt)
                if not isinstance(res, PlanningError):
                    ok += 1
                    effs.append(res.summary["efficiency"])
            eff = f"{statistics.mean(effs):.2f}" if effs else "-"
            print(f"{n:>3} {shape:>7} {ok:>3}/{len(secs):<3} {statistics.median(secs):>9.2f} {max(secs):>7.2f} {eff:>11}")


if __name__ == "__main__":
    main()
