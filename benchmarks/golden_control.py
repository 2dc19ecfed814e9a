"""Golden runs of the closed loop: record a fingerprint of several runs, check a refactor left them bit-identical.

A behaviour-preserving change of the controller (moving code between modules, renaming) must give the
same runs to the last bit: same success, shape error, simulated duration, final poses (true and
observed) and event list. This script runs a fixed set of closed-loop assemblies and stores the
``repr`` of those values per run (``--record FILE``), or compares a fresh set of runs against a stored
file (``--check FILE``: exit status 1 and the first differing field per run on a mismatch).

The runs: the example ``examples/four-robots.toml`` with the literature's noise
(:data:`stressbots.generate.LITERATURE_NOISE`), plant seeds 0-3; and two generated layouts of
``benchmarks/bench_generality.py``'s tuning set (a 5- and a 6-robot one), plant seeds 0-1, built the
same way as there (:func:`stressbots.generate.random_scenario` with the layout seed, shape and noise).

Run (a few minutes; use ``nice``)::

    nice python benchmarks/golden_control.py --record golden.json
    nice python benchmarks/golden_control.py --check golden.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

TUNING_LAYOUTS = ((3, 5, "tee"), (4, 6, "tee"))
"""``(index j, robots, shape)`` of the tuning-set layouts used (layout seed 1000 + j, as bench_generality)."""


def runs():
    """``(name, scenario, plant seed, plan)`` of every golden run."""
    from stressbots.control import nominal_plan
    from stressbots.generate import LITERATURE_NOISE, random_scenario
    from stressbots.scenario import load

    ex = load(ROOT / "examples" / "four-robots.toml").with_noise(LITERATURE_NOISE)
    plan = nominal_plan(ex)
    for s in range(4):
        yield f"four-robots/seed{s}", ex, s, plan
    for j, n, shape in TUNING_LAYOUTS:
        scn = random_scenario(n, 1000 + j, shape=shape, noise=LITERATURE_NOISE)
        plan = nominal_plan(scn)
        for s in range(2):
            yield f"tuning{j}-n{n}-{shape}/seed{s}", scn, s, plan


def fingerprint(result) -> dict[str, str]:
    """The ``repr`` of what a run achieved: compared as strings, so equal means bit-identical floats."""
    final_true = None if result.final_true is None else result.final_true.tolist()
    return {
        "success": repr(bool(result.success)),
        "failure": repr(result.failure),
        "shape_error_rms_um": repr(float(result.shape_error_rms_um)),
        "duration_s": repr(float(result.duration_s)),
        "final_true": repr(final_true),
        "final_observed": repr(result.final_observed.tolist()),
        "events": repr(list(result.events)),
    }


def collect() -> dict[str, dict[str, str]]:
    """Run every golden run; fingerprint per run name."""
    from stressbots.control import assemble
    from stressbots.sim import SimulatedPlant

    out = {}
    for name, scn, s, plan in runs():
        t0 = time.perf_counter()
        r = assemble(scn, SimulatedPlant(scn, seed=s), seed=s, plan=plan)
        out[name] = fingerprint(r)
        print(f"{name:<28} success={r.success!s:<5} {time.perf_counter() - t0:6.1f} s wall", file=sys.stderr)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    group = ap.add_mutually_exclusive_group(required=True)
    group.add_argument("--record", metavar="FILE", help="run the golden runs and write their fingerprints to FILE")
    group.add_argument("--check", metavar="FILE", help="run the golden runs and compare them with FILE")
    args = ap.parse_args(argv)
    got = collect()
    if args.record:
        path = Path(args.record)
        tmp = path.with_name(path.name + ".tmp")
        tmp.write_text(json.dumps(got, indent=1, sort_keys=True))
        tmp.replace(path)
        print(f"recorded {len(got)} runs to {path}")
        return 0
    want = json.loads(Path(args.check).read_text())
    bad = 0
    for name in sorted(set(want) | set(got)):
        if name not in got or name not in want:
            print(f"{name}: only in {'the file' if name in want else 'this run'}")
            bad += 1
            continue
        diff = [k for k in want[name] if want[name][k] != got[name].get(k)]
        if diff:
            bad += 1
            print(f"{name}: differs in {', '.join(diff)}")
    print(f"{len(got) - bad}/{len(got)} runs identical" if not bad else f"MISMATCH: {bad} run(s) differ")
    return 1 if bad else 0


if __name__ == "__main__":
    raise SystemExit(main())
