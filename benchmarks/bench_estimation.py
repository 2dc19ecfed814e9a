"""Benchmark: how well does the estimator predict and track the robots, with and without the straight drift?

Runs closed-loop trials of the tuning set's layouts (:mod:`bench_generality`'s layouts, protocol-only plant),
records every input the estimator got (steps, held robots, camera frame) and the simulator's true poses
at each frame, then replays the same inputs through three estimators:

- ``none``: predictions drive straight runs straight (the estimator before the straight-drift identification);
- ``identified``: :class:`stressbots.control.straight_drift.StraightDrift` identifies each robot's curvature
  from the raw frames and the predictions follow it (what the closed loop does);
- ``oracle``: the plant's true drift bias (hidden from the controller): the best a bias model can do;

Reported per variant, over the frames in which a robot drove straight the whole frame (where the drift
acts) and over all frames in which it moved: the median / 90th percentile of the prediction error (the
dead-reckoned pose before the frame is taken, against the truth) and of the filtered estimate's error,
position (um) and heading (deg); and the curvature error |kappa_hat - bias| (deg/mm) at the end of each
trial for robots that drove straight at least 300 um. Then the *model-only* error: each frame predicted from
the true previous pose, by kind of frame (turning, straight, mixed), which separates what the motion model
misses from the filter's own error. The replay is exact: the controller's decisions were
made once (with the installed code) and every variant sees the same frames.

Run::

    nice python benchmarks/bench_estimation.py --layouts 12 --seeds 0,1 --noise-scale 2
"""

from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_generality import ProtocolOnly, layout_spec  # noqa: E402

VARIANTS = ("none", "identified", "oracle")
"""Replayed estimators: the drift model of straight drives (none / identified / the plant's true bias)."""


def record_trial(j: int, seed: int, noise_scale: float) -> dict | None:
    """Run layout ``j`` of the tuning set with plant ``seed``; the estimator's inputs and the truth."""
    import stressbots.control.loop as loop_mod
    from stressbots.control import assemble
    from stressbots.errors import PlanningError
    from stressbots.estimation import Estimator
    from stressbots.generate import LITERATURE_NOISE, random_scenario
    from stressbots.sim import SimulatedPlant

    _, n, shape = layout_spec("tuning", j)
    try:
        scn = random_scenario(n, 1000 + j, shape=shape, noise=LITERATURE_NOISE.scaled(noise_scale))
    except (PlanningError, RuntimeError):
        return None
    plant = SimulatedPlant(scn, seed=seed)
    log: dict = {"first": None, "updates": [], "truth": [], "scn": scn}

    class Recording(Estimator):
        def __init__(self, first, *a, **k):
            log["first"] = np.array(first, dtype=np.float64)
            log["truth"].append(plant.true_poses())
            super().__init__(first, *a, **k)

        def update(self, steps, frozen, frame):
            log["updates"].append(([(np.array(t), float(d)) for t, d in steps], np.array(frozen), np.array(frame, float)))
            log["truth"].append(plant.true_poses())
            super().update(steps, frozen, frame)

    saved = loop_mod.Estimator
    loop_mod.Estimator = Recording  # type: ignore[misc]
    try:
        r = assemble(scn, ProtocolOnly(plant, 240.0), seed=seed)
        log["success"] = bool(r.success)
    except Exception as exc:  # a failed trial still has its frames
        log["success"] = f"error: {type(exc).__name__}"
    finally:
        loop_mod.Estimator = saved
    log["bias"] = plant.drift_bias
    return log


def replay(log: dict, variant: str) -> dict:
    """Feed a recorded trial's inputs to a fresh estimator; per-frame errors against the truth."""
    from stressbots.control.straight_drift import StraightDrift
    from stressbots.estimation import Estimator
    from stressbots.robots import angle_difference

    scn = log["scn"]
    nz = scn.noise
    est = Estimator(log["first"], scn.starts, scn.speeds_um_s, scn.turn_radii_um)
    ident = StraightDrift(scn.n, drift_rad_per_um=nz.heading_drift_rad_per_um,
                          camera_heading_rad=nz.camera_heading_sd_rad, camera_position_um=nz.camera_position_sd_um)
    ident.frame(log["first"], np.zeros(scn.n, bool), np.zeros(scn.n))
    if variant.startswith("oracle"):
        est.straight_curvature = np.asarray(log["bias"], float)
    rows = []
    straight_len = np.zeros(scn.n)
    for (steps, frozen, frame), truth in zip(log["updates"], log["truth"][1:], strict=True):
        pred = est.predict(steps, frozen)
        turning_any = np.zeros(scn.n, bool)
        for t, _ in steps:
            turning_any |= t
        total = math.fsum(d for _, d in steps)
        straight = ~turning_any & ~frozen
        est.update(steps, frozen, frame)
        if variant.startswith("identified"):
            ident.frame(frame, straight, est.speed * total)
            est.straight_curvature = ident.kappa
        straight_len += np.where(straight, est.speed * total, 0.0)
        for name, p in (("pred", pred), ("filt", est.pose)):
            e_pos = np.hypot(*(p[:, :2] - truth[:, :2]).T)
            e_h = np.degrees(np.abs(angle_difference(p[:, 2], truth[:, 2])))
            for i in np.flatnonzero(~frozen):
                rows.append((name, bool(straight[i]), float(e_pos[i]), float(e_h[i])))
    kap = ident.kappa if variant.startswith("identified") else est.straight_curvature
    k_err = [abs(float(kap[i] - log["bias"][i])) * 180e3 / math.pi for i in range(scn.n) if straight_len[i] >= 300.0]
    return {"rows": rows, "kappa_err": k_err}


def model_errors(log: dict) -> dict[str, list[float]]:
    """Heading error (deg, signed) of one frame's prediction made from the *true* previous pose with the
    identified model, by kind of frame (``turn``, ``straight``, ``mixed``): what the model itself misses
    (per-Drive speed/radius jitter, the drift's walk, contacts), with the filter's own error taken out."""
    from stressbots.estimation import Estimator
    from stressbots.robots import angle_difference

    scn = log["scn"]
    est = Estimator(log["first"], scn.starts, scn.speeds_um_s, scn.turn_radii_um)
    out: dict[str, list[float]] = {"turn": [], "straight": [], "mixed": []}
    prev = log["truth"][0]
    for (steps, frozen, frame), truth in zip(log["updates"], log["truth"][1:], strict=True):
        filtered = est.pose
        est.pose = prev.copy()
        pm = est.predict(steps, frozen)
        est.pose = filtered
        turn_s = sum(np.where(t, d, 0.0) for t, d in steps)
        total = math.fsum(d for _, d in steps)
        err = np.degrees(angle_difference(pm[:, 2], truth[:, 2]))
        for i in np.flatnonzero(~frozen):
            kind = "turn" if turn_s[i] >= total - 1e-9 else ("straight" if turn_s[i] <= 1e-9 else "mixed")
            out[kind].append(float(err[i]))
        est.update(steps, frozen, frame)
        prev = truth
    return out


def _stats(vals) -> str:
    a = np.asarray(vals, dtype=np.float64)
    if a.size == 0:
        return "   -  /   -  "
    return f"{np.median(a):5.2f} / {np.percentile(a, 90):5.2f}"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--first", type=int, default=0, help="first tuning layout index")
    ap.add_argument("--layouts", type=int, default=12, help="number of tuning layouts")
    ap.add_argument("--seeds", default="0", help="comma-separated plant seeds")
    ap.add_argument("--noise-scale", type=float, default=1.0, help="multiple of the literature's noise")
    a = ap.parse_args(argv)
    seeds = [int(s) for s in a.seeds.split(",") if s.strip()]
    logs = []
    for j in range(a.first, a.first + a.layouts):
        for s in seeds:
            lg = record_trial(j, s, a.noise_scale)
            if lg is not None:
                logs.append(lg)
                print(f"  layout {j} seed {s}: {len(lg['updates'])} frames, success {lg['success']}", flush=True)
    print(f"noise x{a.noise_scale:g}, {len(logs)} trials; median / 90th percentile over robot-frames")
    print(f"{'variant':17s} {'frames':9s} {'pred pos um':>13s} {'pred head deg':>13s} {'filt pos um':>13s} "
          f"{'filt head deg':>13s}  kappa err deg/mm")
    for variant in VARIANTS:
        out = [replay(lg, variant) for lg in logs]
        rows = [r for o in out for r in o["rows"]]
        kerr = [k for o in out for k in o["kappa_err"]]
        for label, sel in (("straight", lambda r: r[1]), ("all moving", lambda _r: True)):
            cols = []
            for name in ("pred", "filt"):
                pos = [r[2] for r in rows if r[0] == name and sel(r)]
                hd = [r[3] for r in rows if r[0] == name and sel(r)]
                cols += [_stats(pos), _stats(hd)]
            k = _stats(kerr) if label == "straight" else ""
            print(f"{variant:17s} {label:10s} {cols[0]:>13s} {cols[1]:>13s} {cols[2]:>13s} {cols[3]:>13s}  {k}")
    print("model-only heading error per frame (deg; prediction from the true previous pose), by kind of frame:")
    per = [model_errors(lg) for lg in logs]
    for kind in ("turn", "mixed", "straight"):
        e = np.array([x for m in per for x in m[kind]])
        if e.size:
            print(f"  {kind:9s} {e.size:6d} frames  |err| median / 90th {_stats(np.abs(e))}  signed median {np.median(e):+.2f}"
                  f"  share over 10 deg {np.mean(np.abs(e) > 10):.3f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
