"""Benchmark: the closed loop on an independent plant (benchmarks/independent_plant.py) beside our simulator.

Runs the generality benchmark's layouts (:func:`bench_generality.layout_spec`, its plan cache and summary)
with :class:`independent_plant.IndependentPlant` behind a protocol-only wrapper, so the controller sees
``observe``/``apply`` and nothing else, as an outside checker's plant would. A trial counts as a success
only when the controller reports success AND the plant's true poses confirm it: RMS shape error after the
best rigid alignment (own Kabsch) within the controller's tolerance, every body touching the structure
(the contact graph connected within ``--touch-um``) and every robot *docked in the plant's own judgement*
(a member of its structure: G_1 or joined by docking compliance). SPEC 6 counts success as "every robot
docked" and an outside checker asks its own plant: a robot stopped off flush against a structure corner
(the plant's "front edge on a structure corner", "docking rotation blocked") is stuck, not docked, even
when it sits within the shape tolerance; later robots then meet a free robot, not the structure. Both
verdicts are recorded.

With ``--baseline FILE[,FILE]`` (bench_generality JSONL records of our simulator on the same layouts and
plant seeds) it prints, for every trial, where the two plants disagree, with the controller's last events
and the independent plant's contact events.

Run (long: ``nice``, background)::

    cp -r /tmp/h6/tplans_base /tmp/h6/lint_plans
    nice python benchmarks/bench_independent_plant.py --layouts 60 --seeds 0 --workers 2 --cap-s 240 \\
        --plan-cache /tmp/h6/lint_plans --jsonl /tmp/h6/lint/indep.jsonl \\
        --baseline /tmp/h6/base_tune0_59.jsonl,/tmp/h6/base_tune60_119.jsonl
    python benchmarks/bench_independent_plant.py --summarise /tmp/h6/lint/indep.jsonl --baseline ...
"""

from __future__ import annotations

import argparse
import json
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import bench_generality as bg  # noqa: E402
import independent_plant as ip  # noqa: E402

TOUCH_UM = 5.0
"""Two bodies closer than this (um, separating-axis gap) touch: the structure must be one connected piece."""


def connected(poses: np.ndarray, L: np.ndarray, W: np.ndarray, touch_um: float = TOUCH_UM) -> bool:
    """Whether the bodies at ``poses`` form one piece (each pair's gap below ``touch_um`` links them)."""
    n = len(poses)
    c = ip.corners(poses, L, W)
    link = np.array([[i != j and ip.penetration(c[i], c[j:j + 1])[0] > -touch_um for j in range(n)] for i in range(n)])
    seen, todo = {0}, [0]
    while todo:
        i = todo.pop()
        for j in np.flatnonzero(link[i]):
            if int(j) not in seen:
                seen.add(int(j))
                todo.append(int(j))
    return len(seen) == n


def judge(result, plant: ip.IndependentPlant, L, W) -> dict:
    """The outside checker's verdict from the plant's true poses (beside the controller's own)."""
    from stressbots.control.tuning import ControllerOptions

    tol = ControllerOptions().shape_tol_um
    true = plant.true_poses()
    rms, rot = ip.rigid_rms(true, result.nominal_goals, L, W)
    joined = connected(true, L, W)
    free = [plant.names[i] for i in np.flatnonzero(~plant.member)]
    ok = bool(result.success) and rms <= tol and joined and not free
    why = None
    if result.success and not ok:
        why = (f"claimed success but true shape error {rms:.1f} um" if rms > tol else
               "claimed success but the structure is not one piece" if not joined else
               f"claimed success but the plant never docked {', '.join(free)} (stuck, not members of its structure)")
    return {"success": ok, "claimed": bool(result.success), "true_shape_um": rms, "true_rotation_deg": rot,
            "connected": joined, "not_docked": free, "truth_failure": why}


def run_trial(scn, plan, ps: int, cap_s: float | None) -> dict:
    """One controller run on the independent plant with plant seed ``ps``; a JSON-able trial record."""
    from stressbots.control import assemble

    t0 = time.perf_counter()
    plant = ip.IndependentPlant(scn, seed=ps)
    rec: dict = {"plant_seed": ps}
    try:
        r = assemble(scn, bg.ProtocolOnly(plant, cap_s), seed=ps, plan=plan)
        rec.update(judge(r, plant, scn.lengths_um, scn.widths_um))
        failure = r.failure if not r.success else rec["truth_failure"]
        rec.update(sim_s=float(r.duration_s), shape_error_um=float(r.shape_error_rms_um),
                   events_tail=[] if rec["success"] else
                   [f"{e['t_s']:.1f} {e['kind']} {e['robot']}: {e['detail']}" for e in r.events[-12:]])
    except bg.WallTimeCap as exc:
        failure = f"wall-time cap: {exc} ({cap_s:g} s)"
        rec.update(success=False, claimed=False, sim_s=float("nan"), shape_error_um=float("nan"), events_tail=[])
    except Exception as exc:  # a controller exception fails the trial, with its type
        failure = f"controller error: {type(exc).__name__}: {exc}"
        rec.update(success=False, claimed=False, sim_s=float("nan"), shape_error_um=float("nan"), events_tail=[],
                   traceback=traceback.format_exc(limit=6))
    rec.update(failure=None if rec["success"] else failure, kind=None if rec["success"] else bg.failure_kind(failure or "", scn.names),
               wall_s=time.perf_counter() - t0, plant_t_s=plant.t,
               plant_events=[f"{e['t_s']:.1f} {e['kind']} {e['robot']}/{e['other']}: {e['detail']}" for e in plant.events[-15:]])
    return rec


def run_layout(set_name: str, j: int, plant_seeds, noise_scale: float, cap_s: float | None, plan_cache: str) -> dict:
    """bench_generality's layout ``j`` (its generator, noise and cached nominal plan) on the independent plant."""
    from stressbots.control import nominal_plan, structure_targets
    from stressbots.errors import PlanningError
    from stressbots.generate import LITERATURE_NOISE, random_scenario

    seed, n, shape = bg.layout_spec(set_name, j)
    rec: dict = {"set": set_name, "index": j, "layout_seed": seed, "n": n, "shape": shape, "plant": "independent"}
    try:
        scn = random_scenario(n, seed, shape=shape, noise=LITERATURE_NOISE.scaled(noise_scale))
    except (PlanningError, RuntimeError) as exc:
        rec.update(status="no-layout", reason=str(exc))
        return rec
    t0 = time.perf_counter()
    plan = bg._cached_plan(plan_cache, f"{set_name}-{j}-x{noise_scale:g}", lambda: bg._plan_or_error(nominal_plan, scn))
    rec["status"] = "ran"
    if isinstance(plan, PlanningError):
        rec.update(status="no-plan", reason=str(plan))
        try:
            plan = structure_targets(scn)
        except PlanningError as exc:
            rec["reason"] += f"; no target structure either: {exc}"
            return rec
    rec["plan_s"] = time.perf_counter() - t0
    rec["trials"] = [run_trial(scn, plan, ps, cap_s) for ps in plant_seeds]
    rec["successes"] = sum(t["success"] for t in rec["trials"])
    return rec


def load_records(paths: str) -> dict[int, dict]:
    """JSONL records by layout index (comma-separated files; a later record of a layout replaces an earlier one)."""
    recs: dict[int, dict] = {}
    for path in filter(None, paths.split(",")):
        with open(path) as fh:
            for line in fh:
                r = json.loads(line)
                recs[r["index"]] = r
    return recs


def compare(records: list[dict], baseline: dict[int, dict], out=sys.stdout) -> dict[str, int]:
    """Trial by trial (same layout, same plant seed): where the independent plant and our simulator disagree."""
    counts = dict.fromkeys(["both succeed", "both fail", "only our simulator succeeds", "only the independent plant succeeds",
                            "no baseline"], 0)
    lines = []
    for r in sorted(records, key=lambda r: r["index"]):
        base = {t["plant_seed"]: t for t in baseline.get(r["index"], {}).get("trials", [])}
        for t in r.get("trials", []):
            b = base.get(t["plant_seed"])
            if b is None:
                counts["no baseline"] += 1
                continue
            key = {(True, True): "both succeed", (False, False): "both fail", (True, False): "only our simulator succeeds",
                   (False, True): "only the independent plant succeeds"}[(bool(b["success"]), bool(t["success"]))]
            counts[key] += 1
            if b["success"] != t["success"] or not t["success"]:
                ours, new = "ok" if b["success"] else b["kind"], "ok" if t["success"] else t["kind"]
                lines.append(f"  {r['index']:>3} ({r['n']} {r['shape']}) seed {t['plant_seed']}: ours {ours} | independent {new}")
    print("\nindependent plant vs our simulator, same layouts and plant seeds:", file=out)
    for k, c in counts.items():
        print(f"  {c:>4} {k}", file=out)
    for line in lines:
        print(line[:240], file=out)
    return counts


def _print_layout(rec: dict) -> None:
    head = f"{rec['index']:>3} seed {rec['layout_seed']} n={rec['n']} {rec['shape']:<6}"
    if not rec.get("trials"):
        print(f"{head} {rec['status']}: {rec.get('reason', '')[:140]}", flush=True)
        return
    walls = [t["wall_s"] for t in rec["trials"]]
    print(f"{head} {rec['successes']}/{len(rec['trials'])}  wall med {np.median(walls):.2f} s", flush=True)
    for t in rec["trials"]:
        if not t["success"]:
            print(f"      {t['plant_seed']}: {str(t['failure'])[:160]}", flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--set", choices=["tuning"], default="tuning", help="layout set (only tuning: held-out layouts are the lead's)")
    ap.add_argument("--layouts", type=int, default=60, help="number of layouts (indices --first .. --first + N - 1)")
    ap.add_argument("--first", type=int, default=0, help="first layout index")
    ap.add_argument("--only", default="", help="comma-separated layout indices (overrides --layouts/--first)")
    ap.add_argument("--seeds", default="0", help="comma-separated plant seeds")
    ap.add_argument("--noise-scale", type=float, default=1.0, help="multiple of the literature's noise")
    ap.add_argument("--workers", type=int, default=1, help="processes (at most 2 on the shared machine)")
    ap.add_argument("--cap-s", type=float, default=240.0, help="wall-time cap per trial (s); a capped trial fails")
    ap.add_argument("--plan-cache", default="", help="directory of pickled nominal plans (bench_generality's)")
    ap.add_argument("--jsonl", default="", help="append one JSON record per layout to this file")
    ap.add_argument("--baseline", default="", help="comma-separated bench_generality JSONL files of our simulator to compare with")
    ap.add_argument("--summarise", default="", help="only print the summary (and comparison) of the records in this JSONL file")
    a = ap.parse_args(argv)
    baseline = load_records(a.baseline) if a.baseline else {}
    if a.summarise:
        records = list(load_records(a.summarise).values())
    else:
        idx = [int(x) for x in a.only.split(",")] if a.only else list(range(a.first, a.first + a.layouts))
        seeds = [int(x) for x in a.seeds.split(",")]
        print(f"independent plant: set {a.set}, {len(idx)} layouts x plant seeds {seeds}, noise x{a.noise_scale:g}, "
              f"cap {a.cap_s:g} s", flush=True)
        records = []
        with ProcessPoolExecutor(max_workers=max(1, min(a.workers, 2))) as pool:
            futs = [pool.submit(run_layout, a.set, j, seeds, a.noise_scale, a.cap_s or None, a.plan_cache) for j in idx]
            for fut in as_completed(futs):
                rec = fut.result()
                records.append(rec)
                _print_layout(rec)
                if a.jsonl:
                    with open(a.jsonl, "a") as fh:
                        fh.write(json.dumps(rec) + "\n")
    records.sort(key=lambda r: r["index"])
    bg.summarise(records)
    claimed = [t for r in records for t in r.get("trials", []) if t.get("claimed") and not t["success"]]
    print(f"controller claimed success but the plant's truth disagrees: {len(claimed)}")
    if baseline:
        compare(records, baseline)


if __name__ == "__main__":
    main()
