"""Benchmark: the simulated plant on 4-robot assemblies (issue 5; the budget of issue 6).

For the built-in example and generated 4-robot tee scenarios (nominal plans from the planner):

- **open loop**: the plan's whole waveform in one ``apply``: simulated seconds per wall second, with no
  noise (every robot must end docked in its slot) and with the literature's noise
  (``stressbots.generate.LITERATURE_NOISE``); also the open-loop drift, the largest distance of a robot
  from its slot at the end;
- **1-s applies**: the same plan cut into 1-s waveforms (from each window's arm state, as a controller
  replanning every second sends them), one ``apply`` plus one ``observe`` per second: ms per apply
  (mean, 95th percentile, worst). Issue 6 needs a whole closed-loop assembly in < 1 s, so this should
  be well under 5 ms.

Run: ``python benchmarks/bench_sim.py [--scenarios K] [--seeds S]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stressbots.electrostatics import analyse_scenario
from stressbots.errors import PlanningError
from stressbots.generate import LITERATURE_NOISE, random_scenario
from stressbots.planning import plan_assembly
from stressbots.scenario import Noise, load
from stressbots.sim import SimulatedPlant, plan_waveform
from stressbots.waveform import steps_from_plan, synthesize

ROOT = Path(__file__).resolve().parents[1]


def windows(steps, dt=1.0):
    """Cut ``[(arm state, duration_s), ...]`` into consecutive windows of ``dt`` seconds of driving."""
    out, cur, left = [], [], dt
    for state, d in steps:
        while d > 1e-12:
            take = min(d, left)
            cur.append((state, take))
            d -= take
            left -= take
            if left <= 1e-12:
                out.append(cur)
                cur, left = [], dt
    if cur:
        out.append(cur)
    return out


def one_second_waveforms(scn, plan):
    analysis = analyse_scenario(scn)
    wfs, state = [], None
    for win in windows(steps_from_plan(plan, analysis)):
        wfs.append(synthesize(analysis, win, initial=state))
        state = win[-1][0]
    return wfs


def drift_um(plant, scn, plan) -> float:
    goals = np.array([plan.goals[name] for name in scn.names])
    return float(np.hypot(*(plant.true_poses()[:, :2] - goals[:, :2]).T).max())


def bench(name, scn, plan, seeds: int) -> dict:
    row = {"name": name, "plan_s": plan.duration_s}
    for label, noise in (("zero", Noise()), ("literature", LITERATURE_NOISE)):
        s = scn.with_noise(noise)
        wf = plan_waveform(s, plan)
        sim_s = wall = 0.0
        drifts = []
        for seed in range(seeds):
            t = time.perf_counter()
            plant = SimulatedPlant(s, seed=seed)
            plant.apply(wf)
            wall += time.perf_counter() - t
            sim_s += plant.time_s
            drifts.append(drift_um(plant, s, plan))
            if label == "zero" and not (plant.docked.all() and drifts[-1] < 1e-6):
                raise AssertionError(f"{name}: zero-noise open loop did not end docked in the slots ({drifts[-1]:.3g} um)")
        row[f"{label}_rate"] = sim_s / wall
        row[f"{label}_drift"] = float(np.median(drifts))
        per = []
        for seed in range(seeds):
            plant = SimulatedPlant(s, seed=seed)
            for w in one_second_waveforms(s, plan):
                t = time.perf_counter()
                plant.apply(w)
                plant.observe()
                per.append(time.perf_counter() - t)
        per_ms = 1000.0 * np.array(per)
        row[f"{label}_apply_ms"] = (float(per_ms.mean()), float(np.percentile(per_ms, 95)), float(per_ms.max()))
    return row


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--scenarios", type=int, default=4, help="generated 4-robot scenarios (besides the example)")
    ap.add_argument("--seeds", type=int, default=5, help="plant seeds per scenario and noise level")
    args = ap.parse_args()

    cases = [("example four-robots", load(ROOT / "examples" / "four-robots.toml"))]
    seed = 0
    while len(cases) < args.scenarios + 1 and seed < 50:
        cases.append((f"random tee n=4 seed {seed}", random_scenario(4, seed, shape="tee")))
        seed += 1
    rows = []
    for name, scn in cases:
        try:
            plan = plan_assembly(scn.with_noise(Noise())).plan
        except PlanningError as exc:
            print(f"{name}: no plan ({exc}); skipped")
            continue
        rows.append(bench(name, scn, plan, args.seeds))

    print(f"\nsimulated plant, 4 robots, {args.seeds} plant seeds each (wall times on this machine)\n")
    head = (f"{'scenario':<24} {'plan s':>7} | {'sim s / wall s':>15} {'zero: ms per 1-s apply':>26} | {'sim s / wall s':>15} "
            f"{'literature: ms per 1-s apply':>30} {'open-loop drift um':>19}")
    print(head)
    print("-" * len(head))
    for r in rows:
        z, n = r["zero_apply_ms"], r["literature_apply_ms"]
        print(
            f"{r['name']:<24} {r['plan_s']:7.1f} | {r['zero_rate']:15.0f} {z[0]:8.2f} mean {z[1]:5.2f} p95 {z[2]:5.1f} max"
            f" | {r['literature_rate']:15.0f} {n[0]:10.2f} mean {n[1]:5.2f} p95 {n[2]:5.1f} max {r['literature_drift']:19.0f}"
        )
    if rows:
        zr = np.median([r["zero_rate"] for r in rows])
        lr = np.median([r["literature_rate"] for r in rows])
        za = np.mean([r["zero_apply_ms"][0] for r in rows])
        la = np.mean([r["literature_apply_ms"][0] for r in rows])
        print(
            f"\nmedian: {zr:.0f} (no noise) and {lr:.0f} (literature noise) simulated s per wall s open loop; "
            f"{za:.2f} / {la:.2f} ms per 1-s apply (+ observe). Zero-noise runs all ended docked in their slots."
        )


if __name__ == "__main__":
    main()
