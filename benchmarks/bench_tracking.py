"""Benchmark: tracking accuracy and speed on rendered frames (issue 13, SPEC 9.2).

- **speed**: ``locate`` on a 2000 x 2000 frame (1.5 um/px) of 8 separate robots, ms per frame and
  frames/s (target >= 20 frames/s);
- **accuracy**: docked structures (tee, cross, comb, ladder; equal and different bodies) rendered by the
  synthetic camera at random rotations, located with ``previous`` = the truth disturbed by 20 um / 6 deg
  and without ``previous`` (then compared as sets): median and worst position (um) and heading (deg)
  error (targets: median <= 2 um and <= 1 deg, no identity swaps with ``previous``);
- a moving sequence: 8 robots driving straight or on arcs for 20 frames of 15 um, each frame's ``previous`` the last result:
  identity swaps counted.

Run: ``python benchmarks/bench_tracking.py [--um-per-px 1.5] [--frames 20]``
"""

from __future__ import annotations

import argparse
import time

import numpy as np
from scipy.optimize import linear_sum_assignment

from stressbots.generate import random_scenario
from stressbots.lab.camera import Camera, ImageModel
from stressbots.tracking import Calibration, locate


def errors(true, est):
    d = np.hypot(*(true[:, :2] - est[:, :2]).T)
    a = np.degrees(np.abs((true[:, 2] - est[:, 2] + np.pi) % (2 * np.pi) - np.pi))
    return d, a


def speed(frames: int) -> None:
    sc = random_scenario(8, seed=1, shape="comb", heterogeneous=False)
    rng = np.random.default_rng(0)
    cal = Calibration(1.5, (0.0, 2000.0))
    cam = Camera(cal, (2000, 2000), ImageModel())
    gx, gy = np.meshgrid([400.0, 1100.0, 1800.0, 2500.0], [900.0, 2100.0])
    poses = np.column_stack([gx.ravel(), gy.ravel(), rng.uniform(0, 2 * np.pi, 8)])
    f = cam.render(poses, sc.lengths_um, sc.widths_um, rng)
    locate(f, sc, cal, previous=poses)
    ts, cpu = [], []
    for _ in range(frames):
        t, c = time.perf_counter(), time.process_time()
        est = locate(f, sc, cal, previous=poses)
        ts.append(time.perf_counter() - t)
        cpu.append(time.process_time() - c)
    d, a = errors(poses, est)
    print(f"speed: 2000x2000 frame, 8 robots: median {1000 * np.median(ts):.1f} ms/frame = {1 / np.median(ts):.1f} frames/s "
          f"(best {1000 * min(ts):.1f} ms; CPU {1000 * np.median(cpu):.1f} ms/frame, all threads); "
          f"errors median {np.median(d):.2f} um, {np.median(a):.3f} deg")


def structures(upx: float) -> None:
    for shape, n, het in [("tee", 4, False), ("cross", 5, False), ("tee", 5, True), ("comb", 6, True), ("ladder", 8, True)]:
        sc = random_scenario(n, seed=3, shape=shape, explicit_goals=True, heterogeneous=het)
        g = sc.goals
        rng = np.random.default_rng(1)
        c = g[:, :2].mean(axis=0)
        cal = Calibration(upx, ((600 - c[0]) / upx, (c[1] + 600) / upx))
        cam = Camera(cal, (int(1200 / upx), int(1200 / upx)), ImageModel())
        for mode in ("previous", "none"):
            D, A, swaps = [], [], 0
            for _ in range(8):
                ang = rng.uniform(0, 2 * np.pi)
                R = np.array([[np.cos(ang), np.sin(ang)], [-np.sin(ang), np.cos(ang)]])
                true = g.copy()
                true[:, :2] = (g[:, :2] - c) @ R.T + c + rng.uniform(-5, 5, 2)
                true[:, 2] = (g[:, 2] + ang) % (2 * np.pi)
                f = cam.render(true, sc.lengths_um, sc.widths_um, rng)
                prev = true + rng.normal(0, [20, 20, 0.1], true.shape) if mode == "previous" else None
                est = locate(f, sc, cal, previous=prev)
                ok = np.all(np.isfinite(est), axis=1)
                r, k = linear_sum_assignment(np.hypot(true[:, None, 0] - est[None, ok, 0], true[:, None, 1] - est[None, ok, 1]))
                if mode == "previous":
                    swaps += int(np.sum(np.flatnonzero(ok)[k] != r))
                    d, a = errors(true, est)
                else:
                    d, a = errors(true[r], est[ok][k])
                D.extend(d)
                A.extend(a)
            D, A = np.array(D), np.array(A)
            print(f"{shape:6s} n={n} {'different' if het else 'equal    '} bodies, {mode:8s}: median {np.nanmedian(D):.2f} um "
                  f"{np.nanmedian(A):.3f} deg; worst {np.nanmax(D):.1f} um {np.nanmax(A):.1f} deg"
                  + (f"; identity swaps {swaps}" if mode == "previous" else ""))


def moving(upx: float, frames: int = 20) -> None:
    sc = random_scenario(8, seed=2, shape="comb", heterogeneous=True)
    rng = np.random.default_rng(4)
    cal = Calibration(upx, (0.0, 3000.0 / upx))
    cam = Camera(cal, (int(3000 / upx), int(3000 / upx)), ImageModel())
    gx, gy = np.meshgrid([450.0, 1150.0, 1850.0, 2550.0], [900.0, 2100.0])
    pose = np.column_stack([gx.ravel(), gy.ravel(), rng.uniform(0, 2 * np.pi, 8)])
    turning = rng.random(8) < 0.5
    prev, swaps, D, A = pose.copy(), 0, [], []
    for _ in range(frames):
        step = 15.0  # um per frame (robots stay apart: 300 um of travel, 700 um spacing)
        dphi = np.where(turning, step / sc.turn_radii_um, 0.0)
        r = sc.turn_radii_um
        th = pose[:, 2]
        pose[:, 0] += np.where(turning, r * (np.cos(th) - np.cos(th + dphi)), step * np.sin(th))
        pose[:, 1] += np.where(turning, r * (np.sin(th + dphi) - np.sin(th)), step * np.cos(th))
        pose[:, 2] = (th + dphi) % (2 * np.pi)
        est = locate(cam.render(pose, sc.lengths_um, sc.widths_um, rng), sc, cal, previous=prev)
        d, a = errors(pose, est)
        swaps += int(np.sum(d > 30))
        D.extend(d)
        A.extend(a)
        prev = np.where(np.isfinite(est), est, prev)
    print(f"moving: 8 robots (different bodies), {frames} frames at {upx:g} um/px: median {np.median(D):.2f} um "
          f"{np.median(A):.3f} deg, worst {np.max(D):.1f} um {np.max(A):.1f} deg; identity swaps {swaps}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--um-per-px", type=float, default=1.5)
    ap.add_argument("--frames", type=int, default=20)
    args = ap.parse_args()
    speed(args.frames)
    structures(args.um_per_px)
    moving(2.0)


if __name__ == "__main__":
    main()
