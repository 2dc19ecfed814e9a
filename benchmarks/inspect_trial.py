"""Look inside one closed-loop trial of ``bench_generality``: its events, a picture of the plant, the shape residuals.

A failing benchmark trial is named by its set, layout index and plant seed (``tuning 25:0`` at ``--noise-scale
2``). This tool replays exactly that trial (the controller and the simulator are deterministic, so the replay
is the benchmark's run, event for event) and shows one of:

- ``events``: the controller's event log, optionally of one robot (``--robot R2``) in a time window
  (``--from 300 --to 400``);
- ``snap``: the true poses at simulated time ``--at T`` as a picture (``--out snap.png``): bodies (docked ones
  filled), headings, the orbit disc every undocked robot sweeps if it orbits from there (dotted); ``--robot``
  is outlined in red;
- ``shape``: each robot's share of the final shape error (RMS of its body-corner residuals after the best rigid
  alignment, um), the RMS without each robot, and the docking and G_1 events: which robot spoiled the shape.
- ``routes``: every roadmap search of the gross motion that found no route, with the reason the planner gives when
  asked again (``it starts within 10 um of the arena edge``, ``the start of its straight approach is blocked by ...``):
  whether the robot was boxed in or aimed somewhere no route ends;
- ``pins``: every applied step list that took ``--robot`` (default: the robot the failure names) from a pose where it
  can move on to one where it is *boxed in* (:meth:`stressbots.control.escapes.Escapes.boxed_in`: no turn of
  ``Tuning.escape_turns`` then one body length straight keeps ``Tuning.viable_clearance_um`` clear), with the
  controller calls that applied it: which manoeuvre pinned a robot that then gave up its target.

``--plant independent`` replays the trial on ``bench_independent_plant``'s plant (SPEC 3, 4 and 6 alone) instead
of the simulator, as that benchmark ran it; ``--tune k=v,...`` changes the controller's tuning as
``bench_generality --tune`` does, so a tuning experiment's failure can be looked at too.

Examples::

    python benchmarks/inspect_trial.py events tuning 25:0 --noise-scale 2 --robot R2 --from 300
    python benchmarks/inspect_trial.py snap tuning 31:0 --noise-scale 2 --at 10.4 --robot R4 --out snap.png
    python benchmarks/inspect_trial.py shape tuning 33:1 --noise-scale 2
    python benchmarks/inspect_trial.py pins tuning 118:0
    python benchmarks/inspect_trial.py routes heldout 34:0 --noise-scale 2 --from 900
    python benchmarks/inspect_trial.py events tuning 30:0 --plant independent --robot R1
    python benchmarks/inspect_trial.py events heldout 20:4 --tune pair_rounds=4

``--plan-cache DIR`` reuses ``bench_generality``'s pickled nominal plans (the same key, so a benchmark run's
cache serves here). Poses are ``(x_um, y_um, heading)``, heading clockwise from +y, as everywhere in stressbots.
"""

from __future__ import annotations

import argparse
import math
import os
import re
import sys
from typing import Any, NamedTuple

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from bench_generality import SETS, ProtocolOnly, _cached_plan, _plan_or_error, layout_spec, tuning_options  # noqa: E402

PLANTS = ("sim", "independent")
"""The plants a trial replays on: the project's simulator (``bench_generality``) or ``bench_independent_plant``'s."""


class _StopAt(Exception):
    """Raised by :class:`_UntilTime` to end a replay at the requested simulated time."""


class _UntilTime:
    """A protocol-only plant that stops the run (raises :class:`_StopAt`) once the simulated time reaches ``t_s``."""

    def __init__(self, inner, t_s: float):
        self._inner, self._t_s = inner, t_s

    def observe(self):
        return self._inner.observe()

    def apply(self, waveform):
        if _plant_time(self._inner) >= self._t_s:
            raise _StopAt
        self._inner.apply(waveform)


def _plant_time(plant) -> float:
    """Simulated time (s) of either plant (the simulator's ``time_s``, the independent plant's ``t``)."""
    return float(plant.time_s if hasattr(plant, "time_s") else plant.t)


def _plant_docked(plant) -> np.ndarray:
    """Which robots are part of the structure, per the plant (the independent plant calls them members)."""
    return np.asarray(plant.docked if hasattr(plant, "docked") else plant.member, dtype=bool)


def _new_plant(scn, ps: int, kind: str):
    """A fresh plant of ``kind`` (:data:`PLANTS`) for scenario ``scn`` and plant seed ``ps``."""
    if kind == "independent":
        import independent_plant

        return independent_plant.IndependentPlant(scn, seed=ps)
    from stressbots.sim import SimulatedPlant

    return SimulatedPlant(scn, seed=ps)


def _trial(set_name: str, spec: str, noise_scale: float, plan_cache: str):
    """``(scenario, plan, plant_seed)`` of trial ``spec`` (``"j:seed"``) of a benchmark set."""
    from stressbots.control import nominal_plan
    from stressbots.generate import LITERATURE_NOISE, random_scenario

    j, ps = (int(x) for x in spec.split(":"))
    seed, n, shape = layout_spec(set_name, j)
    scn = random_scenario(n, seed, shape=shape, noise=LITERATURE_NOISE.scaled(noise_scale))
    plan = _cached_plan(plan_cache, f"{set_name}-{j}-x{noise_scale:g}", lambda: _plan_or_error(nominal_plan, scn))
    return scn, plan, ps


class Replay(NamedTuple):
    """How a trial is replayed: on which plant (:data:`PLANTS`), with which controller options (``--tune``; None:
    the defaults)."""

    plant: str = "sim"
    options: Any = None


def _run(scn, plan, ps: int, stop_at: float | None = None, replay: Replay = Replay()):
    """Replay the trial; ``(result or None if stopped, plant)``."""
    from stressbots.control import assemble
    from stressbots.errors import PlanningError

    sim = _new_plant(scn, ps, replay.plant)
    plant = ProtocolOnly(sim) if stop_at is None else _UntilTime(sim, stop_at)
    if isinstance(plan, PlanningError):
        plan = None
    try:
        return assemble(scn, plant, seed=ps, plan=plan, options=replay.options), sim
    except _StopAt:
        return None, sim


def docking_order(scn) -> list[str]:
    """The robots' names in STRING order D_1 .. D_n (D_n and D_{n-1} form G_1, D_1 docks last), not scenario order."""
    from stressbots.electrostatics import analyse_scenario

    order = analyse_scenario(scn).order_index
    return [scn.names[i] for i in order] if order is not None else list(scn.names)


def show_events(scn, plan, ps: int, robot: str | None, t0: float, t1: float, replay: Replay = Replay()) -> None:
    result, _ = _run(scn, plan, ps, replay=replay)
    assert result is not None
    print("robots in docking order D_1 .. D_n:", " ".join(docking_order(scn)))
    for e in result.events:
        if (robot is None or e["robot"] == robot) and t0 <= e["t_s"] <= t1:
            print(f"{e['t_s']:8.1f} {e['kind']:<12} {e['robot']}: {e['detail']}")
    verdict = "assembled" if result.success else f"not assembled: {result.failure}"
    print(f"{verdict} (shape error {result.shape_error_rms_um:.1f} um RMS, {result.duration_s:.0f} s simulated)")


def show_snap(scn, plan, ps: int, t_s: float, robot: str | None, out: str, replay: Replay = Replay()) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.patches import Circle, Polygon

    from stressbots.robots import body_corners, turning_centres

    _, sim = _run(scn, plan, ps, stop_at=t_s, replay=replay)
    poses, names, docked = sim.true_poses(), sim.names, _plant_docked(sim)
    fig, ax = plt.subplots(figsize=(8, 8))
    if scn.arena_um is not None:
        w, h = scn.arena_um
        ax.plot([0, w, w, 0, 0], [0, 0, h, h, 0], "k-", lw=1)
    lengths = np.asarray(scn.lengths_um, float)
    widths = np.asarray(scn.widths_um, float)
    corners = body_corners(poses, lengths, widths)
    radii = np.array([rb.turn_radius_um for rb in scn.robots])
    centres = turning_centres(poses, radii)  # clockwise turning centres, on each robot's right
    for k, name in enumerate(names):
        colour = f"C{k % 10}"
        ax.add_patch(Polygon(corners[k], closed=True, fill=bool(docked[k]), alpha=0.6, color=colour))
        x, y, th = poses[k]
        ax.arrow(x, y, 0.6 * lengths[k] * math.sin(th), 0.6 * lengths[k] * math.cos(th), width=3, color="k")
        ax.annotate(f"{name} {math.degrees(th) % 360:.0f}", (x, y), fontsize=8)
        if not docked[k]:
            ax.add_patch(Circle(tuple(centres[k]), radii[k] + 0.5 * math.hypot(lengths[k], widths[k]), fill=False, ls=":",
                                color=colour))
        if name == robot:
            ax.add_patch(Polygon(corners[k], closed=True, fill=False, lw=2, color="red"))
        goal = getattr(getattr(plan, "plan", plan), "goals", {}).get(name)
        if goal is not None:  # the nominal plan's slot (before any retarget), dashed
            slot = body_corners(np.asarray([tuple(goal)], float), lengths[k:k + 1], widths[k:k + 1])[0]
            ax.add_patch(Polygon(slot, closed=True, fill=False, ls="--", lw=0.8, color=colour))
    ax.set_aspect("equal")
    ax.set_title(f"t = {_plant_time(sim):.1f} s (true poses; dotted: orbit discs from here; dashed: nominal slots)")
    fig.savefig(out, dpi=90)
    print(f"wrote {out} at t = {_plant_time(sim):.1f} s; docked: {', '.join(n for n, d in zip(names, docked, strict=True) if d) or 'none'}")


def shape_shares(final: np.ndarray, goals: np.ndarray, lengths: np.ndarray, widths: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Each robot's share of the shape error and the shape error without it: ``(per_robot, without)`` (um, ``(n,)``).

    ``per_robot[k]`` is the RMS distance of robot k's four body corners after the best rigid alignment of the whole
    structure (so the mean of their squares is the square of the shape error, SPEC 6); ``without[k]`` re-aligns the
    other robots alone (NaN for fewer than two left). Poses ``(n, 3)`` in um and rad."""
    from stressbots.assessment import kabsch_2d
    from stressbots.robots import body_corners

    def residuals(keep: np.ndarray) -> np.ndarray:
        f = body_corners(final[keep], lengths[keep], widths[keep]).reshape(-1, 2)
        g = body_corners(goals[keep], lengths[keep], widths[keep]).reshape(-1, 2)
        rot, t = kabsch_2d(f, g)
        return np.hypot(*(f @ rot.T + t - g).T).reshape(int(keep.sum()), 4)

    n = len(final)
    per_robot = np.sqrt((residuals(np.ones(n, dtype=bool)) ** 2).mean(axis=1))
    without = np.full(n, np.nan)
    for k in range(n):
        keep = np.ones(n, dtype=bool)
        keep[k] = False
        if keep.sum() >= 2:
            without[k] = float(np.sqrt(np.mean(residuals(keep) ** 2)))
    return per_robot, without


def show_shape(scn, plan, ps: int, replay: Replay = Replay()) -> None:
    result, sim = _run(scn, plan, ps, replay=replay)
    assert result is not None
    per_robot, without = shape_shares(sim.true_poses(), result.nominal_goals, np.asarray(scn.lengths_um, float),
                                      np.asarray(scn.widths_um, float))
    print(f"shape error {result.shape_error_rms_um:.1f} um RMS ({'assembled' if result.success else result.failure})")
    print("per robot (RMS of its corners, um):", "  ".join(f"{nm} {e:.1f}" for nm, e in zip(scn.names, per_robot, strict=True)))
    print("RMS without each robot (um):       ", "  ".join(f"{nm} {e:.1f}" for nm, e in zip(scn.names, without, strict=True)))
    for e in result.events:
        if e["kind"] in ("docked", "G_1", "retarget", "late"):
            print(f"{e['t_s']:8.1f} {e['kind']:<9} {e['robot']}: {e['detail']}")


def failing_robot(failure: str | None, names) -> str | None:
    """The first robot name (``R3``) a failure message mentions, if any.

    >>> failing_robot("R3 did not dock in 6 attempts (last: no route ...)", ("R0", "R3"))
    'R3'
    """
    for word in re.findall(r"\bR\w+", failure or ""):
        if word in names:
            return word
    return None


class _PinWatch:
    """Wraps the closed loop's ``drive`` (the one place steps reach the plant) and records, for robot ``i``, every step
    list after which it is boxed in though it was not before: ``(t_s, pose_before, pose_after, steps, callers)``.
    While it is docked nothing is checked (docked robots are meant to be pressed against the structure)."""

    def __init__(self, i: int):
        self.i = i
        self.pins: list[tuple[float, np.ndarray, np.ndarray, list, list[str]]] = []
        self.freed = 0

    def _boxed(self, loop) -> bool | None:
        if loop.docked[self.i] or not hasattr(loop, "gross"):
            return None
        return bool(loop.gross.escapes.boxed_in(self.i, loop.est[self.i], loop.orbiting_below(int(loop.rank[self.i]))))

    def __enter__(self):
        import traceback

        from stressbots.control.loop import PlantLoop

        self._orig = orig = PlantLoop.drive
        watch = self

        def drive(loop, steps):
            before, pose = watch._boxed(loop), loop.est[watch.i].copy()
            orig(loop, steps)
            after = watch._boxed(loop)
            if before is False and after is True:
                callers = [f"{f.name} ({os.path.basename(f.filename)}:{f.lineno})" for f in traceback.extract_stack()[:-1]
                           if f"stressbots{os.sep}control" in f.filename]
                watch.pins.append((loop.t, pose, loop.est[watch.i].copy(), list(steps), callers[::-1]))
            elif before is True and after is False:
                watch.freed += 1

        PlantLoop.drive = drive  # type: ignore[method-assign]
        return self

    def __exit__(self, *exc):
        from stressbots.control.loop import PlantLoop

        PlantLoop.drive = self._orig  # type: ignore[method-assign]
        return False


def show_pins(scn, plan, ps: int, robot: str | None, replay: Replay = Replay()) -> None:
    if robot is None:
        result, _ = _run(scn, plan, ps, replay=replay)
        assert result is not None
        robot = failing_robot(result.failure, scn.names)
        if robot is None:
            print("the run names no robot in a failure: pass --robot")
            return
    with _PinWatch(scn.names.index(robot)) as watch:
        result, _ = _run(scn, plan, ps, replay=replay)
    assert result is not None
    rank = docking_order(scn).index(robot) + 1  # the watched robot is D_rank: P_k turns D_1 .. D_k, drives the rest straight
    for t, p0, p1, steps, callers in watch.pins:
        moves = ", ".join(f"P_{k} {d:.2f} s ({'turns' if rank <= k else 'straight'})" for k, d in steps)
        print(f"{t:8.1f} {robot} boxed in: ({p0[0]:.0f}, {p0[1]:.0f}) um {math.degrees(p0[2]) % 360:.0f} deg -> "
              f"({p1[0]:.0f}, {p1[1]:.0f}) um {math.degrees(p1[2]) % 360:.0f} deg by {moves}")
        print(f"         {robot} is D_{rank}; applied by", " < ".join(callers))
    verdict = "assembled" if result.success else f"not assembled: {result.failure}"
    print(f"{robot}: boxed in {len(watch.pins)} time(s), freed {watch.freed} time(s); {verdict}")


class _RouteWatch:
    """While active, records why each roadmap search of the gross motion found no route: ``(t_s, robot, clearance_um,
    measured pose, target, reason)``, the reason from :func:`stressbots.planning.route` asked again with the same
    obstacles (the structure at the plain clearance) and its own random stream, so the replay itself is unchanged."""

    def __init__(self):
        self.failed: list[tuple[float, int, float, np.ndarray, np.ndarray, str]] = []

    def __enter__(self):
        from stressbots.control import gross

        self._orig = original = gross.GrossMotion.roadmap_route
        watch = self

        def roadmap_route(gm, i, target, orbiting, extra_discs, clearance):
            found = original(gm, i, target, orbiting, extra_discs, clearance)
            if found[1] is None:
                watch.failed.append((gm.loop.t, i, clearance, gm.loop.est[i].copy(), np.asarray(target, float).copy(),
                                     watch.reason(gm, i, target, orbiting, extra_discs, clearance)))
            return found

        gross.GrossMotion.roadmap_route = roadmap_route  # type: ignore[method-assign]
        return self

    @staticmethod
    def reason(gm, i, target, orbiting, extra_discs, clearance) -> str:
        from stressbots.control import gross
        from stressbots.planning import NoRoute, PlannerOptions, route

        lp = gm.loop
        obst = gross._roadmap_obstacles(lp, i, orbiting, extra_discs, 0.0)
        try:
            route(lp.est[i][None, :], np.zeros(1), np.asarray(target, float), lp.r_hat[i], lp.L[i], lp.W[i], obst,
                  PlannerOptions(clearance_um=clearance, roadmap_nodes=(60, 200)), np.random.default_rng(0), "")
        except NoRoute as exc:
            return str(exc).lstrip(": ")
        return "found when asked again (another random roadmap)"

    def __exit__(self, *exc):
        from stressbots.control import gross

        gross.GrossMotion.roadmap_route = self._orig  # type: ignore[method-assign]
        return False


def show_routes(scn, plan, ps: int, robot: str | None, t0: float, t1: float, replay: Replay = Replay()) -> None:
    with _RouteWatch() as watch:
        result, _ = _run(scn, plan, ps, replay=replay)
    assert result is not None
    print("robots in docking order D_1 .. D_n:", " ".join(docking_order(scn)))
    shown = 0
    for t, i, c, pose, target, why in watch.failed:
        if (robot is None or scn.names[i] == robot) and t0 <= t <= t1:
            shown += 1
            print(f"{t:8.1f} {scn.names[i]} at ({pose[0]:.0f}, {pose[1]:.0f}) um {math.degrees(pose[2]) % 360:.0f} deg -> "
                  f"({target[0]:.0f}, {target[1]:.0f}) um {math.degrees(target[2]) % 360:.0f} deg, {c:g} um clearance: {why}")
    verdict = "assembled" if result.success else f"not assembled: {result.failure}"
    print(f"{shown} failed roadmap search(es) shown of {len(watch.failed)}; {verdict}")


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("what", choices=("events", "snap", "shape", "pins", "routes"))
    ap.add_argument("set", choices=sorted(SETS))
    ap.add_argument("trial", help="layout index and plant seed, e.g. 25:0")
    ap.add_argument("--noise-scale", type=float, default=1.0, help="multiple of the literature's noise (as the benchmark ran)")
    ap.add_argument("--robot", default=None,
                    help="one robot's events or failed searches (events, routes), outlined in red (snap), watched (pins; default: the "
                         "failing one)")
    ap.add_argument("--from", dest="t0", type=float, default=0.0, help="events from this simulated time (s)")
    ap.add_argument("--to", dest="t1", type=float, default=math.inf, help="events up to this simulated time (s)")
    ap.add_argument("--at", type=float, default=0.0, help="snap: simulated time (s) of the picture")
    ap.add_argument("--out", default="snap.png", help="snap: the picture's file")
    ap.add_argument("--plan-cache", default="", help="bench_generality's directory of pickled nominal plans")
    ap.add_argument("--plant", choices=PLANTS, default="sim",
                    help="replay on the simulator (bench_generality) or the independent plant (bench_independent_plant)")
    ap.add_argument("--tune", default="", help="controller tuning changes as bench_generality --tune, e.g. pair_rounds=4")
    a = ap.parse_args(argv)
    replay = Replay(a.plant, tuning_options(a.tune))  # a bad --tune fails here (error: ..., exit 2), before any work
    try:
        scn, plan, ps = _trial(a.set, a.trial, a.noise_scale, a.plan_cache)
    except ValueError:
        ap.error(f"trial: expected LAYOUT:SEED such as 25:0, got {a.trial!r}")
    if a.robot is not None and a.robot not in scn.names:
        ap.error(f"--robot: {a.robot!r} is not one of {', '.join(scn.names)}")
    if a.what == "events":
        show_events(scn, plan, ps, a.robot, a.t0, a.t1, replay)
    elif a.what == "snap":
        show_snap(scn, plan, ps, a.at, a.robot, a.out, replay)
    elif a.what == "pins":
        show_pins(scn, plan, ps, a.robot, replay)
    elif a.what == "routes":
        show_routes(scn, plan, ps, a.robot, a.t0, a.t1, replay)
    else:
        show_shape(scn, plan, ps, replay)


if __name__ == "__main__":
    main()
