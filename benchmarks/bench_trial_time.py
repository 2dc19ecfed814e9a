"""Benchmark: wall time per simulated closed-loop assembly, and where it goes (issue 12 goal 5).

For each layout (the example, or TOML files given), the literature's noise, plant seeds ``0..S-1``: one
nominal plan (timed once, as Monte Carlo shares it), then ``control.assemble`` through a timing wrapper of
``SimulatedPlant``. Per trial: wall time, and its split into

- **simulator**: ``plant.apply`` + ``plant.observe`` (``sim.py``, ``drift.py``);
- **estimator**: :meth:`stressbots.estimation.Estimator.update`;
- **roadmap routes**: :func:`stressbots.planning.route` called by the controller (detours);
- **controller**: the rest (its geometry, timed paths, waveform synthesis).

Prints the median and the worst trial per layout (goal 5: median <= 1 s for 4 robots, <= 5 s for 8).

Run: ``python benchmarks/bench_trial_time.py [LAYOUT.toml ...] [--seeds S] [--first-seed F] [--budget-s T]``
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np

from stressbots import estimation, planning
from stressbots.control import assemble, nominal_plan
from stressbots.generate import LITERATURE_NOISE
from stressbots.scenario import load
from stressbots.sim import SimulatedPlant

ROOT = Path(__file__).resolve().parents[1]


class Clock:
    """Accumulates wall time of wrapped calls by name."""

    def __init__(self):
        self.t: dict[str, float] = {}

    def wrap(self, name, fn):
        def timed(*a, **k):
            t0 = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                self.t[name] = self.t.get(name, 0.0) + time.perf_counter() - t0

        return timed


class TimedPlant:
    def __init__(self, plant, clock: Clock):
        self.plant = plant
        self.observe = clock.wrap("simulator", plant.observe)
        self.apply = clock.wrap("simulator", plant.apply)

    def __getattr__(self, name):
        return getattr(self.plant, name)


def trial(scn, plan, seed: int, budget_s: float | None):
    clock = Clock()
    route, update = planning.route, estimation.Estimator.update
    planning.route = clock.wrap("roadmap routes", route)
    estimation.Estimator.update = clock.wrap("estimator", update)  # type: ignore[method-assign]
    try:
        t0 = time.perf_counter()
        res = assemble(scn, TimedPlant(SimulatedPlant(scn, seed=seed), clock), seed=seed, plan=plan, time_budget_s=budget_s)
        wall = time.perf_counter() - t0
    finally:
        planning.route, estimation.Estimator.update = route, update  # type: ignore[method-assign]
    parts = dict(clock.t)
    parts["controller"] = wall - sum(parts.values())
    return wall, bool(res.success), parts


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("layouts", nargs="*", type=Path, default=[ROOT / "examples" / "four-robots.toml"])
    ap.add_argument("--seeds", type=int, default=5, help="number of plant seeds")
    ap.add_argument("--first-seed", type=int, default=0, help="first plant seed")
    ap.add_argument("--budget-s", type=float, default=None, help="simulated time budget per trial (default the controller's)")
    args = ap.parse_args()
    for path in args.layouts:
        scn = load(path).with_noise(LITERATURE_NOISE)
        t0 = time.perf_counter()
        plan = nominal_plan(scn)
        t_plan = time.perf_counter() - t0
        seeds = range(args.first_seed, args.first_seed + args.seeds)
        rows = [trial(scn, plan, s, args.budget_s) for s in seeds]
        walls = np.array([r[0] for r in rows])
        keys = ("simulator", "estimator", "roadmap routes", "controller")
        share = {k: sum(r[2].get(k, 0.0) for r in rows) / walls.sum() for k in keys}
        print(f"{path.name}: {scn.n} robots, nominal plan {t_plan:.2f} s; {sum(r[1] for r in rows)}/{len(rows)} assembled; "
              f"wall per trial median {np.median(walls):.2f} s, max {walls.max():.2f} s; "
              + ", ".join(f"{k} {100 * v:.0f} %" for k, v in share.items()))
        for s, (w, ok, parts) in zip(seeds, rows, strict=True):
            print(f"  seed {s}: {w:.2f} s {'ok' if ok else 'FAILED'}  " + "  ".join(f"{k} {v:.2f}" for k, v in parts.items()))


if __name__ == "__main__":
    main()
