"""Golden runs of the closed loop: record a fingerprint of several runs, check a refactor left them bit-identical.

A behaviour-preserving change of the controller (moving code between modules, renaming) must give the
same runs to the last bit: same success, shape error, simulated duration, final poses (true and
observed) and event list. This script runs a fixed set of closed-loop assemblies and stores the
``repr`` of those values per run (``--record FILE``), or compares a fresh set of runs against a stored
file (``--check FILE``: exit status 1 and the first differing field per run on a mismatch).

The runs: the example ``examples/four-robots.toml`` with the literature's noise
(:data:`stressbots.generate.LITERATURE_NOISE`), plant seeds 0-3; generated layouts of
``benchmarks/bench_generality.py``'s tuning set (:data:`TUNING_LAYOUTS`: 4 to 6 robots, all four shapes
but ladder, chosen so that between them the runs hold, loop, retry, detour, park, transfer in several
legs, stall and fail), built the same way as there (:func:`stressbots.generate.random_scenario` with the
layout seed, shape and noise); and two runs whose first rendezvous is made to fail (as in
``tests/test_control_recovery.py``), so that G_1 is re-planned in another pair frame.

Run (a few minutes; use ``nice``)::

    nice python benchmarks/golden_control.py --record golden.json
    nice python benchmarks/golden_control.py --check golden.json
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from contextlib import contextmanager, nullcontext
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

TUNING_LAYOUTS = ((3, 5, "tee", (0, 1)), (4, 6, "tee", (0, 1)), (2, 4, "tee", (0, 2)), (9, 4, "cross", (0,)),
                  (17, 5, "comb", (0,)))
"""``(index j, robots, shape, plant seeds)`` of the tuning-set layouts used (layout seed 1000 + j, as in
bench_generality)."""

INJECTED = (("four-robots", 1), ("tuning3-n5-tee", 0))
"""``(scenario name, plant seed)`` of the runs whose first rendezvous fails (injected)."""


def runs():
    """``(name, scenario, plant seed, plan, injected)`` of every golden run."""
    from stressbots.control import nominal_plan
    from stressbots.generate import LITERATURE_NOISE, random_scenario
    from stressbots.scenario import load

    ex = load(ROOT / "examples" / "four-robots.toml").with_noise(LITERATURE_NOISE)
    scenarios = {"four-robots": (ex, nominal_plan(ex), range(4))}
    for j, n, shape, seeds in TUNING_LAYOUTS:
        scn = random_scenario(n, 1000 + j, shape=shape, noise=LITERATURE_NOISE)
        scenarios[f"tuning{j}-n{n}-{shape}"] = (scn, nominal_plan(scn), seeds)
    for name, (scn, plan, seeds) in scenarios.items():
        for s in seeds:
            yield f"{name}/seed{s}", scn, s, plan, False
    for name, s in INJECTED:
        scn, plan, _ = scenarios[name]
        yield f"{name}/seed{s}/first-rendezvous-fails", scn, s, plan, True


@contextmanager
def first_rendezvous_fails():
    """The controller's first rendezvous raises its re-plan error (the seam tests/test_control_recovery.py uses)."""
    from stressbots.control import pair

    original = pair.Rendezvous.rendezvous
    calls = {"n": 0}

    def first_fails(self, N, M, D, lower):
        calls["n"] += 1
        if calls["n"] == 1:
            raise pair.Replan(f"{self.loop.scn.names[N]} found no timed path to its approach line (injected)")
        return original(self, N, M, D, lower)

    pair.Rendezvous.rendezvous = first_fails  # type: ignore[method-assign]
    try:
        yield
    finally:
        pair.Rendezvous.rendezvous = original  # type: ignore[method-assign]


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
    for name, scn, s, plan, injected in runs():
        t0 = time.perf_counter()
        with first_rendezvous_fails() if injected else nullcontext():
            r = assemble(scn, SimulatedPlant(scn, seed=s), seed=s, plan=plan)
        out[name] = fingerprint(r)
        print(f"{name:<44} success={r.success!s:<5} {time.perf_counter() - t0:6.1f} s wall", file=sys.stderr)
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
