"""Benchmark: closed-loop assembly (issue 6 targets) on 4-robot scenarios.

For the built-in example and generated 4-robot layouts (tee, cross, comb, ladder), at the literature's
error levels (speed sd 5 %, radius sd 3 %, drift 3.7 deg/mm, camera 2 um / 1 deg, 2 % dropouts, t_x 1 s):

- success rate over the plant seeds, with its 95 % Wilson interval;
- RMS shape error after the best rigid alignment (median, 95th percentile, max) of the successes;
- wall time of one closed-loop assembly (controller + simulator, the nominal plan excluded: Monte Carlo
  shares one plan): median and max. Target: < 1 s;
- simulated duration (median).

Run: ``python benchmarks/bench_control.py [--seeds 20] [--layouts 100,101,102] [--shapes tee,cross]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stressbots.control import assemble, nominal_plan
from stressbots.errors import PlanningError
from stressbots.generate import LITERATURE_NOISE, random_scenario
from stressbots.montecarlo import wilson_interval
from stressbots.scenario import load
from stressbots.sim import SimulatedPlant

ROOT = Path(__file__).resolve().parents[1]


def study(name, scn, seeds):
    try:
        plan = nominal_plan(scn)
    except PlanningError as exc:
        print(f"{name:<22} no nominal plan: {exc}")
        return None
    ok, shape, wall, sim_s, fails = 0, [], [], [], []
    for seed in range(seeds):
        t0 = time.perf_counter()
        r = assemble(scn, SimulatedPlant(scn, seed=seed), seed=seed, plan=plan)
        wall.append(time.perf_counter() - t0)
        sim_s.append(r.duration_s)
        if r.success:
            ok += 1
            shape.append(r.shape_error_rms_um)
        else:
            fails.append(f"{seed}: {r.failure}")
    lo, hi = wilson_interval(ok, seeds)
    sh = np.array(shape) if shape else np.array([np.nan])
    print(
        f"{name:<22} {ok:>3}/{seeds:<3} [{lo:.2f}, {hi:.2f}]  shape med {np.median(sh):4.1f} p95 {np.percentile(sh, 95):4.1f} "
        f"max {sh.max():4.1f} um  wall med {np.median(wall):.2f} max {max(wall):.2f} s  sim med {np.median(sim_s):4.0f} s"
    )
    for f in fails[:3]:
        print(f"{'':<24}{f[:110]}")
    return ok, seeds, wall


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--layouts", default="100,101,102")
    ap.add_argument("--shapes", default="tee,cross,comb,ladder")
    a = ap.parse_args()
    total = [0, 0]
    walls = []
    runs = [("example", load(ROOT / "examples" / "four-robots.toml"))]
    for shape in a.shapes.split(","):
        for lay in (int(x) for x in a.layouts.split(",")):
            runs.append((f"{shape} {lay}", random_scenario(4, lay, shape=shape, noise=LITERATURE_NOISE)))
    for name, scn in runs:
        out = study(name, scn, a.seeds)
        if out:
            total[0] += out[0]
            total[1] += out[1]
            walls += out[2]
    lo, hi = wilson_interval(total[0], total[1])
    print(f"all: {total[0]}/{total[1]} = {total[0] / max(total[1], 1):.3f} [{lo:.3f}, {hi:.3f}]; "
          f"wall per assembly median {np.median(walls):.2f} s, "
          f"95th {np.percentile(walls, 95):.2f} s")


if __name__ == "__main__":
    main()
