"""Benchmark: how general is the closed loop? Generated layouts of 2-8 robots, tuning and held-out sets.

Each layout is :func:`stressbots.generate.random_scenario` with a layout seed: ``n`` from 2 to 8, every
named shape (``pair`` for n = 2; ``tee``, ``cross``, ``comb``, ``ladder`` otherwise, which cover docking
on a robot's rear edge and into the gaps between docked teeth), heterogeneous robots (L, W, v, r drawn
per robot), the structure anywhere in the middle of the arena at any rotation, start orbits anywhere
around it. Every layout runs ``--plant-seeds`` plant seeds (default 5) at the literature's noise
(:data:`stressbots.generate.LITERATURE_NOISE`, times ``--noise-scale``) through a protocol-only wrapper
around the built-in simulator: the controller sees ``observe``/``apply`` and nothing else.

Two disjoint ranges of layout seeds:

- ``tuning`` (layout seeds 1000 + j): what the controller is developed and measured on;
- ``heldout`` (layout seeds 900000 + j): run only to report, never looked at while tuning.

The layout of index j has ``n = 2 + j % 7`` robots and shape ``(tee, cross, comb, ladder)[(j // 7) % 4]``
(every combination within 28 layouts). Layouts the planner cannot plan (no nominal plan: issue 15) and
layouts the generator cannot place are counted separately, not as controller failures.

A trial counts as a success only when the controller reports one *and* the simulator agrees (:func:`judge_truth`:
it docked every robot, and the true shape is within tolerance), as an outside checker asks its own plant.

Reported: successes over all trials with the 95 % Wilson interval; per-layout successes; failure reasons
grouped (numbers and robot names replaced by ``#`` / ``R``); median and 95th percentile wall time per
assembly for 4 and 8 robots (controller + simulator; the nominal plan, shared by a layout's trials,
excluded). Output is incremental (one line per layout as it finishes) and, with ``--jsonl``, one JSON
record per layout.

``--plan-cache DIR`` pickles each layout's nominal plan (the controller does not change it), so repeated
runs while developing the controller skip the planning; ``--seeds 0,1,2`` picks plant seeds; failing
trials keep their last twelve controller events in the JSONL record (``events_tail``).

Run (long: use ``nice`` and the background)::

    nice python benchmarks/bench_generality.py --set tuning --layouts 60 --jsonl tuning.jsonl > tuning.txt
    nice python benchmarks/bench_generality.py --set heldout --layouts 60 --noise-scale 2
"""

from __future__ import annotations

import argparse
import json
import re
import sys
import time
import traceback
from collections import Counter
from concurrent.futures import ProcessPoolExecutor, as_completed

import numpy as np

SETS = {"tuning": 1000, "heldout": 900000}
"""First layout seed of each set: the two ranges never overlap for up to 899000 layouts."""

SHAPES = ("tee", "cross", "comb", "ladder")


class WallTimeCap(Exception):
    """A trial ran longer (wall time) than the benchmark's cap: counted as a failure of its own kind."""


class ProtocolOnly:
    """A plant offering nothing but ``observe`` and ``apply`` (the controller cannot peek at the truth).

    With ``cap_s`` it also stops a trial that has run longer than that (wall time) by raising
    :class:`WallTimeCap` from ``apply``: a limit wrapped around the plant, not threaded through the
    controller (goal 5 of issue 12: no failing trial may cost 10x a normal one).
    """

    def __init__(self, inner, cap_s: float | None = None):
        self._inner = inner
        self._deadline = None if cap_s is None else time.perf_counter() + cap_s

    def observe(self):
        return self._inner.observe()

    def apply(self, waveform):
        if self._deadline is not None and time.perf_counter() > self._deadline:
            raise WallTimeCap("stopped by the benchmark's wall-time cap")
        self._inner.apply(waveform)


def judge_truth(result, sim, scn, shape_tol_um: float) -> str | None:
    """Why the simulator's truth denies a success the controller claims, or None.

    The controller judges from its estimates; SPEC 6 counts success as every robot docked and the true
    shape within tolerance, and an outside checker asks its own plant both. So a claimed success counts
    only if the simulator docked every robot (:attr:`~stressbots.sim.SimulatedPlant.docked`: flush against
    the structure) and its true poses match the shape.
    """
    from stressbots.assessment import shape_error

    free = [scn.names[i] for i in np.flatnonzero(~sim.docked)]
    rms = shape_error(sim.true_poses(), result.nominal_goals, scn.lengths_um, scn.widths_um).rms_um
    if free:
        return f"claimed success but the plant never docked {', '.join(free)} (stuck, not flush against the structure)"
    if rms > shape_tol_um:
        return f"claimed success but true shape error {rms:.1f} um"
    return None


def layout_spec(set_name: str, j: int) -> tuple[int, int, str]:
    """``(layout_seed, n, shape)`` of layout ``j`` of a set."""
    n = 2 + j % 7
    shape = "pair" if n == 2 else SHAPES[(j // 7) % 4]
    return SETS[set_name] + j, n, shape


def failure_kind(failure: str, names) -> str:
    """A failure reason with robot names replaced by ``R`` and numbers by ``#`` (to group like failures), as
    ``stressbots montecarlo`` groups them (:func:`stressbots.montecarlo.failure_kind`: G_1, D_(n-1) and
    "stage-2" keep their names)."""
    from stressbots.montecarlo import failure_kind as kind

    text = str(failure)
    for nm in sorted(names, key=len, reverse=True):
        text = re.sub(rf"\b{re.escape(nm)}\b", "R", text)
    return kind(text) or ""


def _cached_plan(cache_dir: str, key: str, make):
    """``make()`` once per ``key``: nominal plans do not depend on the controller, so iterating on the
    controller need not re-plan every layout (pickled under ``cache_dir``; delete it after planner changes)."""
    import os
    import pickle

    if not cache_dir:
        return make()
    path = os.path.join(cache_dir, f"{key}.pkl")
    if os.path.exists(path):
        with open(path, "rb") as fh:
            return pickle.load(fh)
    value = make()
    os.makedirs(cache_dir, exist_ok=True)
    tmp = f"{path}.{os.getpid()}.tmp"
    with open(tmp, "wb") as fh:
        pickle.dump(value, fh)
    os.replace(tmp, path)
    return value


def tuning_options(spec: str):
    """``ControllerOptions`` whose ``Tuning`` has the fields of ``spec`` (``"name=value,..."``) changed; None for ``""``.

    >>> tuning_options("transfer_tracks_apart=true,arrive_um=30").tuning.arrive_um
    30.0
    >>> tuning_options("park_short_shifts_um=100;60").tuning.park_short_shifts_um
    (100.0, 60.0)
    >>> tuning_options("park_short_shifts_um=").tuning.park_short_shifts_um
    ()
    """
    from dataclasses import fields, replace

    from stressbots.control.tuning import ControllerOptions, Tuning

    if not spec:
        return None
    kinds = {f.name: f.type for f in fields(Tuning)}
    changes = {}
    for item in spec.split(","):
        name, _, value = item.partition("=")
        name = name.strip()
        if name not in kinds:
            print(f"error: --tune: {name!r} is not a field of stressbots.control.tuning.Tuning", file=sys.stderr)
            raise SystemExit(2)
        kind = str(kinds[name])
        try:
            if kind == "bool":
                changes[name] = value.strip().lower() in ("1", "true", "yes", "on")
            elif kind in ("int", "float"):
                changes[name] = int(value) if kind == "int" else float(value)
            elif kind == "tuple[float, ...]":  # values separated by ';', none for an empty tuple
                changes[name] = tuple(float(x) for x in value.split(";") if x.strip())
            else:
                raise ValueError(f"a field of type {kind} cannot be set here")
        except ValueError as exc:
            print(f"error: --tune: {name}={value!r}: {exc}", file=sys.stderr)
            raise SystemExit(2) from None
    return ControllerOptions(tuning=replace(Tuning(), **changes))


def run_layout(set_name: str, j: int, plant_seeds, noise_scale: float, cap_s: float | None = None,
               plan_cache: str = "", tune: str = "") -> dict:
    """Plan layout ``j`` (or load its plan from ``plan_cache``) and run its plant seeds; a JSON-able record."""
    from stressbots.control import assemble, nominal_plan, structure_targets
    from stressbots.control.tuning import ControllerOptions
    from stressbots.errors import PlanningError
    from stressbots.generate import LITERATURE_NOISE, random_scenario
    from stressbots.sim import SimulatedPlant

    seed, n, shape = layout_spec(set_name, j)
    rec: dict = {"set": set_name, "index": j, "layout_seed": seed, "n": n, "shape": shape}
    try:
        scn = random_scenario(n, seed, shape=shape, noise=LITERATURE_NOISE.scaled(noise_scale))
    except (PlanningError, RuntimeError) as exc:
        rec["status"] = "no-layout"
        rec["reason"] = str(exc)
        return rec
    t0 = time.perf_counter()
    try:
        plan = _cached_plan(plan_cache, f"{set_name}-{j}-x{noise_scale:g}", lambda: _plan_or_error(nominal_plan, scn))
        if isinstance(plan, PlanningError):
            raise plan
        rec["status"] = "ran"
    except PlanningError as exc:
        # counted apart (issue 15): the controller still runs, on the structure's slots alone
        rec["status"] = "no-plan"
        rec["reason"] = str(exc)
        try:
            plan = structure_targets(scn)
        except PlanningError as exc2:
            rec["reason"] += f"; no target structure either: {exc2}"
            rec["plan_s"] = time.perf_counter() - t0
            return rec
    rec["plan_s"] = time.perf_counter() - t0
    trials = []
    options = tuning_options(tune)
    for ps in (range(plant_seeds) if isinstance(plant_seeds, int) else plant_seeds):
        t0 = time.perf_counter()
        try:
            sim = SimulatedPlant(scn, seed=ps)
            r = assemble(scn, ProtocolOnly(sim, cap_s), seed=ps, plan=plan, options=options)
            ok, failure, sim_s, shape_err = bool(r.success), r.failure, float(r.duration_s), float(r.shape_error_rms_um)
            truth = judge_truth(r, sim, scn, (options or ControllerOptions()).shape_tol_um)
            if ok and truth:
                ok, failure = False, truth
            tail = [] if ok else [f"{e['t_s']:.1f} {e['kind']} {e['robot']}: {e['detail']}" for e in r.events[-12:]]
            counts = dict(Counter(e["kind"] for e in r.events))
        except WallTimeCap as exc:
            tail, counts = [], {}
            ok, failure, sim_s, shape_err = False, f"wall-time cap: {exc} ({cap_s:g} s)", float("nan"), float("nan")
        except Exception as exc:  # a controller exception is a failure of the trial, with its type
            tail, counts = [], {}
            ok, failure, sim_s, shape_err = False, f"controller error: {type(exc).__name__}: {exc}", float("nan"), float("nan")
            rec.setdefault("tracebacks", []).append(traceback.format_exc(limit=4))
        trials.append(
            {
                "plant_seed": ps,
                "success": ok,
                "failure": failure,
                "kind": None if ok else failure_kind(failure or "", scn.names),
                "wall_s": time.perf_counter() - t0,
                "sim_s": sim_s,
                "shape_error_um": shape_err,
                "events_tail": tail,
                "event_counts": counts,
            }
        )
    rec["trials"] = trials
    rec["successes"] = sum(t["success"] for t in trials)
    return rec


def _plan_or_error(nominal_plan, scn):
    """The nominal plan, or the PlanningError (cached like a plan: an unplannable layout stays so)."""
    from stressbots.errors import PlanningError

    try:
        return nominal_plan(scn)
    except PlanningError as exc:
        return exc


def _wilson(s: int, n: int) -> tuple[float, float]:
    from stressbots.montecarlo import wilson_interval

    return wilson_interval(s, n)


def _print_detours(trials: list[dict], out) -> None:
    """Roadmap routes (``detour`` events) per trial, successes and failures apart: a robot that drifts clockwise
    off its route cannot rejoin it without a loop and draws a new one (route thrash; records from before
    ``event_counts`` existed are skipped)."""
    for label, want in (("successes", True), ("failures", False)):
        d = np.array([t["event_counts"].get("detour", 0) for t in trials if "event_counts" in t and t["success"] is want])
        if d.size:
            print(f"roadmap routes per trial, {label}: median {np.median(d):g}, 90th {np.percentile(d, 90):g}, max {d.max():g} "
                  f"({d.size} trials)", file=out)


def summarise(records: list[dict], out=sys.stdout) -> dict:
    """Print (and return) the totals: success with its Wilson interval, failures grouped, wall times."""
    ran = [r for r in records if r["status"] == "ran"]
    trials = [t for r in ran for t in r["trials"]]
    ok = sum(t["success"] for t in trials)
    lo, hi = _wilson(ok, len(trials))
    worst = sorted(ran, key=lambda r: r["successes"])[:8]
    kinds = Counter(t["kind"] for t in trials if not t["success"])
    print(f"\nlayouts: {len(records)} ({len(ran)} ran, {sum(r['status'] == 'no-plan' for r in records)} not planned, "
          f"{sum(r['status'] == 'no-layout' for r in records)} not generated)", file=out)
    print(f"success: {ok}/{len(trials)} = {ok / max(len(trials), 1):.3f}  Wilson 95 % [{lo:.3f}, {hi:.3f}]", file=out)
    if ran:
        k = len(ran[0]["trials"])
        below = [r for r in ran if r["successes"] < k]
        named = (f"{r['layout_seed']} ({r['n']} {r['shape']}) {r['successes']}/{k}" for r in worst if r["successes"] < k)
        print(f"layouts below {k}/{k}: {len(below)}; worst: " + ", ".join(named), file=out)
        by_n = {}
        for r in ran:
            by_n.setdefault(r["n"], [0, 0])
            by_n[r["n"]][0] += r["successes"]
            by_n[r["n"]][1] += len(r["trials"])
        print("by n: " + ", ".join(f"{n}: {s}/{t}" for n, (s, t) in sorted(by_n.items())), file=out)
    for kind, c in kinds.most_common():
        print(f"  {c:>3} x {kind[:150]}", file=out)
    _print_detours(trials, out)
    walls = {}
    for n in (4, 8):
        w = np.array([t["wall_s"] for r in ran if r["n"] == n for t in r["trials"]])
        if w.size:
            walls[n] = (float(np.median(w)), float(np.percentile(w, 95)), float(w.max()))
            print(f"wall per assembly, {n} robots: median {walls[n][0]:.2f} s, 95th {walls[n][1]:.2f} s, max {walls[n][2]:.2f} s "
                  f"({w.size} trials)", file=out)
    for r in records:
        if r["status"] == "no-plan":
            got = f"controller alone {r['successes']}/{len(r['trials'])}" if r.get("trials") else "not run"
            print(f"  not planned: {r['layout_seed']} ({r['n']} {r['shape']}), {got}: {r['reason'][:120]}", file=out)
    return {"successes": ok, "trials": len(trials), "wilson": (lo, hi), "walls": walls}


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", choices=sorted(SETS), default="tuning")
    ap.add_argument("--layouts", type=int, default=60, help="number of layouts (indices --first .. --first + N - 1)")
    ap.add_argument("--first", type=int, default=0, help="first layout index")
    ap.add_argument("--only", default="", help="comma-separated layout indices (overrides --layouts/--first)")
    ap.add_argument("--plant-seeds", type=int, default=5)
    ap.add_argument("--noise-scale", type=float, default=1.0, help="multiple of the literature's noise")
    ap.add_argument("--workers", type=int, default=2, help="processes (at most 2 on the shared machine)")
    ap.add_argument("--jsonl", default="", help="append one JSON record per layout to this file")
    ap.add_argument("--cap-s", type=float, default=60.0, help="wall-time cap per trial (s); a capped trial fails")
    ap.add_argument("--plan-cache", default="", help="directory of pickled nominal plans (reused across controller runs)")
    ap.add_argument("--seeds", default="", help="comma-separated plant seeds (overrides --plant-seeds)")
    ap.add_argument("--summarise", default="", help="only print the summary of the records in this JSONL file")
    ap.add_argument("--tune", default="", help="controller tuning changes, e.g. transfer_tracks_apart=true,arrive_um=30")
    a = ap.parse_args(argv)
    if a.summarise:
        with open(a.summarise) as fh:
            recs = {}
            for line in fh:
                r = json.loads(line)
                recs[(r["set"], r["index"])] = r  # a re-run layout replaces the earlier record
        summarise(sorted(recs.values(), key=lambda r: (r["set"], r["index"])))
        return
    idx = [int(x) for x in a.only.split(",")] if a.only else list(range(a.first, a.first + a.layouts))
    workers = max(1, min(a.workers, 2))
    seeds = [int(x) for x in a.seeds.split(",")] if a.seeds else list(range(a.plant_seeds))
    tuning_options(a.tune)  # a bad --tune fails here, before any work
    print(f"set {a.set}, {len(idx)} layouts x plant seeds {seeds}, noise x{a.noise_scale:g}, {workers} processes, "
          f"wall-time cap {a.cap_s:g} s per trial" + (f", tuning {a.tune}" if a.tune else ""), flush=True)
    records = []
    with ProcessPoolExecutor(max_workers=workers) as pool:
        futs = {pool.submit(run_layout, a.set, j, seeds, a.noise_scale, a.cap_s or None, a.plan_cache, a.tune): j for j in idx}
        for fut in as_completed(futs):
            rec = fut.result()
            records.append(rec)
            if rec.get("trials"):
                fails = [f"{t['plant_seed']}: {t['failure']}" for t in rec["trials"] if not t["success"]]
                walls = [t["wall_s"] for t in rec["trials"]]
                tag = "" if rec["status"] == "ran" else " (no nominal plan: slots only)"
                head = f"{rec['index']:>3} seed {rec['layout_seed']} n={rec['n']} {rec['shape']:<6}"
                print(f"{head} {rec['successes']}/{len(rec['trials'])}{tag}"
                      f"  wall med {np.median(walls):.2f} s  plan {rec['plan_s']:.1f} s", flush=True)
                for f in fails:
                    print(f"      {f[:160]}", flush=True)
            else:
                head = f"{rec['index']:>3} seed {rec['layout_seed']} n={rec['n']} {rec['shape']:<6}"
                print(f"{head} {rec['status']}: {rec['reason'][:140]}", flush=True)
            if a.jsonl:
                with open(a.jsonl, "a") as fh:
                    fh.write(json.dumps(rec) + "\n")
    records.sort(key=lambda r: r["index"])
    summarise(records)


if __name__ == "__main__":
    main()
