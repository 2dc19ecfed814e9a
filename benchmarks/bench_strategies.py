"""Benchmark: the two closed-loop strategies (``rendezvous``, ours; ``seed``, the paper's as written) on the
same plants and layouts.

Run ``python benchmarks/bench_strategies.py [--seeds 3] [--layouts 2] [--json out.json]``. Layouts: the
example ``examples/four-robots.toml`` and generated layouts of 2-6 robots
(:func:`stressbots.generate.random_scenario`, heterogeneous robots, layout seeds 300.., shapes pair for 2
and tee/cross/comb otherwise), all at the literature's noise (:data:`stressbots.generate.LITERATURE_NOISE`).
Every layout is planned once (:func:`stressbots.control.nominal_plan`, shared by both strategies); plant
seeds 1..S are the same for both. Prints per strategy: success (Wilson 95 % interval), RMS shape error
after best rigid alignment and largest absolute placement error (medians over successes), simulated
duration (median over successes) and wall time per assembly (median over all), then the failure reasons.
Runs sequentially in one process; meant to be run with ``nice`` on a shared machine.
"""

from __future__ import annotations

import argparse
import collections
import json
import sys
import time
from pathlib import Path

import numpy as np

from stressbots.control import nominal_plan
from stressbots.errors import StressbotsError
from stressbots.generate import LITERATURE_NOISE, random_scenario
from stressbots.montecarlo import wilson_interval
from stressbots.scenario import load
from stressbots.sim import SimulatedPlant
from stressbots.strategies import STRATEGIES, assemble_with

ROOT = Path(__file__).resolve().parents[1]


def layouts(count: int):
    """(label, scenario) pairs: the example, then ``count`` generated layouts per robot count 2..6."""
    yield "example", load(ROOT / "examples" / "four-robots.toml").with_noise(LITERATURE_NOISE)
    shapes = ("tee", "cross", "comb")
    for n in range(2, 7):
        for j in range(count):
            seed = 300 + 10 * n + j
            shape = "pair" if n == 2 else shapes[(seed + j) % 3]
            if shape == "cross" and n < 4:
                shape = "tee"
            yield f"{shape}-{n}-{seed}", random_scenario(n, seed, shape=shape, noise=LITERATURE_NOISE)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=3, help="plant seeds per layout (1..S)")
    ap.add_argument("--layouts", type=int, default=2, help="generated layouts per robot count (2..6 robots)")
    ap.add_argument("--json", type=Path, default=None, help="write every trial here")
    args = ap.parse_args(argv)
    rows = []
    for label, scn in layouts(args.layouts):
        t0 = time.perf_counter()
        try:
            plan = nominal_plan(scn)
        except StressbotsError as exc:
            print(f"{label}: not planned ({exc}); skipped for both strategies", flush=True)
            continue
        print(f"{label}: {scn.n} robots, planned in {time.perf_counter() - t0:.1f} s", flush=True)
        for seed in range(1, args.seeds + 1):
            for strategy in STRATEGIES:
                t1 = time.perf_counter()
                res = assemble_with(strategy, scn, SimulatedPlant(scn, seed=seed), seed=seed, plan=plan)
                wall = time.perf_counter() - t1
                rows.append({
                    "layout": label, "n": scn.n, "seed": seed, "strategy": strategy, "success": bool(res.success),
                    "shape_error_um": float(res.shape_error_rms_um), "placement_error_um": float(np.max(res.placement_error_um)),
                    "duration_s": float(res.duration_s), "wall_s": wall, "failure": res.failure,
                })
                print(f"  seed {seed} {strategy:10s} {'ok ' if res.success else 'FAIL'} {res.duration_s:7.1f} s sim "
                      f"{wall:5.2f} s wall {'' if res.success else res.failure}", flush=True)
    if args.json:
        args.json.write_text(json.dumps(rows, indent=1))
    print()
    print("| strategy | success | Wilson 95 % | shape error RMS (um, median) | placement error (um, median) | duration (s sim, median) "
          "| wall per assembly (s, median) |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for strategy in STRATEGIES:
        mine = [r for r in rows if r["strategy"] == strategy]
        ok = [r for r in mine if r["success"]]
        lo, hi = wilson_interval(len(ok), len(mine)) if mine else (float("nan"), float("nan"))

        def med(key, rs=ok):
            return f"{np.median([r[key] for r in rs]):.1f}" if rs else "-"

        print(f"| {strategy} | {len(ok)}/{len(mine)} | {lo:.2f}-{hi:.2f} | {med('shape_error_um')} | {med('placement_error_um')} | "
              f"{med('duration_s')} | {med('wall_s', mine)} |")
    for strategy in STRATEGIES:
        reasons = collections.Counter(_kind(r["failure"]) for r in rows if r["strategy"] == strategy and not r["success"])
        if reasons:
            print(f"\n{strategy} failures:")
            for why, count in reasons.most_common():
                print(f"  {count:3d}  {why}")
    return 0


def _kind(reason: str | None) -> str:
    """A failure reason with robot names and numbers blurred, for counting."""
    import re

    text = re.sub(r"\b[A-Z]\w* \(D_\d+\)", "<robot>", reason or "")
    text = re.sub(r"(?<![\w.-])-?\d+(?:\.\d+)?", "#", text)  # numbers, not the digits of G_1 or D_(n-1)
    return text


if __name__ == "__main__":
    sys.exit(main())
