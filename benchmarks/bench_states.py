"""Benchmark: accessible-control-state analysis (issue 2 targets).

- STRING designs with n = 10, 100, 1000 robots (target: 1000 analysed in < 1 s). Lemma 1's closed form
  after the O(n log n) STRING check; for n <= 100 also the general search, as a cross-check.
- General (non-STRING) designs: nested hysteresis windows, where every one of the 2^n arm patterns is
  accessible, n = 8, 12, 16 (target: < 10 s each).

Run: ``python benchmarks/bench_states.py`` (add ``--repeat K`` for the best of K runs).
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from stressbots.electrostatics import Electrodes, analyse_thresholds


def string_design(n: int, seed: int = 0):
    """n robots, thresholds evenly spread, file order shuffled; margin small enough to fit them."""
    margin = 0.01
    vu = np.linspace(0.05, 60.0, n)
    vd = np.linspace(120.0, 190.0, n)
    perm = np.random.default_rng(np.random.SeedSequence(seed)).permutation(n)
    return vd[perm], vu[perm], Electrodes(margin_V=margin)


def nested_design(n: int):
    """Nested windows [V_u,i, V_d,i]: inner robots release higher and snap lower; 2^n states."""
    vu = 5.0 + 4.0 * np.arange(n)
    vd = 195.0 - 4.0 * np.arange(n)
    return vd, vu, Electrodes(max_V=200.0, margin_V=1.0, drive_low_V=90.0, drive_high_V=100.0)


def timed(fn, repeat: int):
    best = float("inf")
    out = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    print(f"{'design':<10} {'n':>5} {'method':<8} {'states':>8} {'time (s)':>10}  target")
    for n in (10, 100, 1000):
        vd, vu, e = string_design(n)
        dt, a = timed(lambda vd=vd, vu=vu, e=e: analyse_thresholds(vd, vu, e), args.repeat)
        assert a.is_string and a.count == n + 1
        ok = "ok" if n != 1000 or dt < 1.0 else "MISSED (< 1 s)"
        print(f"{'STRING':<10} {n:>5} {a.method:<8} {a.count:>8} {dt:>10.4f}  {ok if n == 1000 else ''}")
        if n <= 100:
            dt, b = timed(lambda vd=vd, vu=vu, e=e: analyse_thresholds(vd, vu, e, method="search"), args.repeat)
            assert np.array_equal(a.accessible_states, b.accessible_states)
            print(f"{'STRING':<10} {n:>5} {'search':<8} {b.count:>8} {dt:>10.4f}  (cross-check)")
    for n in (8, 12, 16):
        vd, vu, e = nested_design(n)
        dt, a = timed(lambda vd=vd, vu=vu, e=e: analyse_thresholds(vd, vu, e), args.repeat)
        assert not a.is_string and a.count == 2**n
        print(f"{'general':<10} {n:>5} {a.method:<8} {a.count:>8} {dt:>10.4f}  {'ok' if dt < 10 else 'MISSED (< 10 s)'}")


if __name__ == "__main__":
    main()
