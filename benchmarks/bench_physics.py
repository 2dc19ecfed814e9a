"""Benchmark: the simulator's physics you can trust (issue 11).

1. **Drift spread, one Drive vs forty.** ``--robots`` identical robots (far apart, only heading drift
   at the scenario's ``--deg-per-mm``) drive 1 mm, once as one Drive and once as forty, on independent
   seeds; and again at 0.1 mm and 2 mm. Reports the sample sd of the heading change with its 99 %
   chi-square interval, next to the model's value (:func:`stressbots.drift.drift_variance`) and to what
   the old per-Drive model gave (``sd / sqrt(40)`` for forty Drives). Also: the same seed cut both ways
   gives the same headings (largest difference, rad).
2. **Zero-noise open-loop docking on generated layouts.** For every shape, robot count and seed, a
   layout from :func:`stressbots.generate.random_scenario`, the planner's nominal plan, and its whole
   waveform on a noise-free :class:`~stressbots.sim.SimulatedPlant`. Counts the layouts whose run docks
   every robot; lists the others (robots not docked, contact events). A layout the planner cannot plan
   is skipped and counted (issue 15, not the simulator's); so is one whose planning exceeds
   ``--plan-timeout-s`` (planning 7-8 robots can take minutes).

Run: ``python benchmarks/bench_physics.py [--robots 2000] [--n 2-8] [--seeds 5] [--shapes tee,cross,comb,ladder]
[--workers 2] [--plan-timeout-s 60] [--skip-drift] [--skip-docking]``. Timings on a shared machine are
indicative only.
"""

from __future__ import annotations

import argparse
import math
import multiprocessing as mp
import time

import numpy as np
from scipy import stats

from stressbots.drift import drift_variance
from stressbots.electrostatics import Electrodes
from stressbots.robots import Pose, Robot
from stressbots.scenario import Noise, Scenario
from stressbots.sim import SimulatedPlant
from stressbots.waveform import Drive

# ----------------------------------------------------------------------------------------------------
# 1. drift spread


def line_of_robots(n: int, deg_per_mm: float, speed: float = 100.0) -> Scenario:
    robots = tuple(Robot(f"R{k}", 120.0, 15.0, speed_um_s=speed, start=Pose(4000.0 * k, 0.0, 0.0)) for k in range(n))
    noise = Noise(heading_drift_rad_per_um=math.radians(deg_per_mm) / 1000.0)
    return Scenario(name="line", robots=robots, electrodes=Electrodes(), arena_um=None, noise=noise)


def spread(sc: Scenario, seed: int, distance_um: float, pieces: int) -> np.ndarray:
    plant = SimulatedPlant(sc, seed=seed)
    t = distance_um / 100.0
    plant.apply([Drive(75.0, 105.0, t / pieces)] * pieces)
    return (plant.true_poses()[:, 2] + math.pi) % (2 * math.pi) - math.pi


def bench_drift(n: int, deg_per_mm: float) -> None:
    sc = line_of_robots(n, deg_per_mm)
    sigma = math.radians(deg_per_mm) / 1000.0
    lo, hi = stats.chi2.ppf([0.005, 0.995], n - 1) / (n - 1)
    print(f"Heading drift spread, {n} robots per run, {deg_per_mm} deg/mm (sd in deg; 99 % interval of the sample sd)")
    print(f"{'distance':>9} {'cut':>10} {'sd':>7} {'model':>7} {'99% interval':>17} {'old per-Drive model':>20} {'wall s':>7}")
    for dist in (100.0, 1000.0, 2000.0):
        model = math.degrees(math.sqrt(float(drift_variance(dist, sigma))))
        for pieces, seed in ((1, 1), (40, 2)):
            t0 = time.perf_counter()
            sd = math.degrees(spread(sc, seed, dist, pieces).std(ddof=1))
            wall = time.perf_counter() - t0
            old = math.degrees(sigma * dist) / math.sqrt(pieces)
            cut = "1 Drive" if pieces == 1 else "40 Drives"
            band = f"{model * math.sqrt(lo):8.3f}-{model * math.sqrt(hi):<8.3f}"
            print(f"{dist:>7.0f}um {cut:>10} {sd:7.3f} {model:7.3f} {band} {old:20.3f} {wall:7.2f}")
    a, b = spread(sc, 3, 1000.0, 1), spread(sc, 3, 1000.0, 40)
    print(f"same seed, 1 Drive vs 40 Drives: largest heading difference {np.abs(a - b).max():.2e} rad")


# ----------------------------------------------------------------------------------------------------
# 2. zero-noise open-loop docking


def _plan_and_run(args):
    shape, n, seed = args
    from stressbots.errors import PlanningError
    from stressbots.generate import random_scenario
    from stressbots.planning import plan_assembly
    from stressbots.sim import run_plan

    sc = random_scenario(n, seed, shape=shape)
    t0 = time.perf_counter()
    try:
        res = plan_assembly(sc)
    except PlanningError as exc:
        return (shape, n, seed, "no plan", str(exc)[:80], time.perf_counter() - t0)
    t_plan = time.perf_counter() - t0
    plant = run_plan(sc, res.plan, seed=seed)
    goals = np.array([res.plan.goals[nm] for nm in sc.names])
    err = float(np.hypot(*(plant.true_poses()[:, :2] - goals[:, :2]).T).max())
    if plant.docked.all():
        return (shape, n, seed, "docked", f"max distance from slot {err:.1e} um", t_plan)
    missing = [sc.names[i] for i in np.flatnonzero(~plant.docked)]
    kinds = sorted({e.kind for e in plant.events})
    return (shape, n, seed, "NOT docked", f"{missing}; events {kinds}; max distance {err:.1e} um", t_plan)


def _worker(job, conn) -> None:
    conn.send(_plan_and_run(job))
    conn.close()


def run_jobs(jobs, workers: int, timeout_s: float):
    """Run ``_plan_and_run`` on every job, ``workers`` processes at a time; a job running longer than
    ``timeout_s`` is killed and reported as a timeout. Yields results in completion order."""
    ctx = mp.get_context("spawn")
    queue, running = list(jobs), []
    while queue or running:
        while queue and len(running) < workers:
            job = queue.pop(0)
            here, there = ctx.Pipe(duplex=False)
            proc = ctx.Process(target=_worker, args=(job, there), daemon=True)
            proc.start()
            running.append((job, proc, here, time.perf_counter()))
        time.sleep(0.05)
        still = []
        for job, proc, conn, t0 in running:
            alive = proc.is_alive()
            if conn.poll():
                yield conn.recv()
                proc.join()
            elif not alive:
                yield (*job, "crashed", f"worker exit code {proc.exitcode}", 0.0)
            elif time.perf_counter() - t0 > timeout_s:
                proc.terminate()
                proc.join()
                yield (*job, "timeout", "planning took too long; skipped", timeout_s)
            else:
                still.append((job, proc, conn, t0))
        running = still


def bench_docking(shapes, ns, seeds: int, workers: int, timeout_s: float) -> None:
    jobs = [(shape, n, seed) for n in ns for shape in shapes for seed in range(seeds)]
    print(f"\nZero-noise open-loop docking: {len(jobs)} generated layouts ({', '.join(shapes)}; n = {ns[0]}-{ns[-1]}; "
          f"seeds 0-{seeds - 1}), {workers} workers, planning timeout {timeout_s:g} s")
    counts = {"docked": 0, "NOT docked": 0, "no plan": 0, "timeout": 0, "crashed": 0}
    by_n: dict[int, list[int]] = {}
    t0 = time.perf_counter()
    for shape, n, seed, outcome, detail, _ in run_jobs(jobs, workers, timeout_s):
        counts[outcome] += 1
        tally = by_n.setdefault(n, [0, 0])
        tally[0] += outcome == "docked"
        tally[1] += outcome in ("docked", "NOT docked")
        if outcome != "docked":
            print(f"  {shape:6} n={n} seed={seed}: {outcome}: {detail}", flush=True)
    planned = counts["docked"] + counts["NOT docked"]
    print("every robot docked, by robot count: " + ", ".join(f"n={n}: {a}/{b}" for n, (a, b) in sorted(by_n.items())))
    print(f"planned and run: {planned}; every robot docked: {counts['docked']}/{planned}; "
          f"not planned (skipped): {counts['no plan']}; planning timed out (skipped): {counts['timeout']}; "
          f"crashed: {counts['crashed']}; "
          f"wall {time.perf_counter() - t0:.0f} s")


def write_layouts(specs: str, folder: str) -> None:
    """Write generated layouts and the planner's plans as test fixtures: ``shape:n:seed,...`` ->
    ``FOLDER/shape-n-seed.toml`` and ``.plan.json`` (tests/test_sim.py replays them: planning 6-8 robots
    is too slow for the suite)."""
    from pathlib import Path

    from stressbots.generate import random_scenario
    from stressbots.planning import plan_assembly
    from stressbots.plans import save
    from stressbots.scenario import to_toml

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    for spec in specs.split(","):
        shape, n, seed = spec.split(":")
        sc = random_scenario(int(n), int(seed), shape=shape)
        res = plan_assembly(sc)
        stem = f"{shape}-{n}-{seed}"
        (out / f"{stem}.toml").write_text(to_toml(sc))
        save(res.plan, out / f"{stem}.plan.json")
        print(f"wrote {stem}: {len(res.plan.steps)} steps, {res.plan.duration_s:.1f} s")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", type=int, default=2000, help="robots per drift run")
    ap.add_argument("--deg-per-mm", type=float, default=3.7)
    ap.add_argument("--n", default="2-8", help="robot counts for the docking sweep, e.g. 2-8 or 3,5")
    ap.add_argument("--seeds", type=int, default=5)
    ap.add_argument("--shapes", default="tee,cross,comb,ladder")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--plan-timeout-s", type=float, default=60.0)
    ap.add_argument("--skip-drift", action="store_true")
    ap.add_argument("--skip-docking", action="store_true")
    ap.add_argument("--write-layouts", metavar="SPECS", help="write test fixtures shape:n:seed,... and exit")
    ap.add_argument("--layouts-dir", default="tests/data/layouts")
    a = ap.parse_args()
    if a.write_layouts:
        write_layouts(a.write_layouts, a.layouts_dir)
        return
    if "-" in a.n:
        lo, hi = (int(x) for x in a.n.split("-"))
        ns = list(range(lo, hi + 1))
    else:
        ns = [int(x) for x in a.n.split(",")]
    if not a.skip_drift:
        bench_drift(a.robots, a.deg_per_mm)
    if not a.skip_docking:
        bench_docking(a.shapes.split(","), ns, a.seeds, a.workers, a.plan_timeout_s)


if __name__ == "__main__":
    main()
