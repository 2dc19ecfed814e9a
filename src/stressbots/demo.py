"""``stressbots demo``: the main job, end to end, on the built-in 4-robot scenario.

The main job so far, in three parts:

1. the electrostatic control layer: analyse the built-in design (accessible control states, STRING
   order, control matrix, primitives), synthesise the waveform of every primitive in a tour
   ``P_0, P_1, ..., P_n, ..., P_0`` (each reached with the fewest Holds, then driven) and check it with
   the decoder;
2. the nominal assembly plan of the built-in tee (seed Appendix 2, verified by an independent replay);
3. that plan played open loop on the simulated plant: without noise every robot ends in its slot
   (planner, waveform and simulator agree); with the literature's error levels open loop drifts far,
   which is why the closed-loop controller exists (a later issue adds it here).

Outputs in the chosen folder:

- ``states.json``: the analysis, exactly as ``stressbots states --json`` (SPEC 7);
- ``waveform.json``: the tour's segments (:func:`stressbots.waveform.to_json`);
- ``waveform.npy``: the tour sampled at 100 kS/s, columns time (s) and level (V);
- ``waveform.png``: a picture of the tour with the robots' thresholds;
- ``plan/``: ``plan.json``, ``plan.png``, ``summary.json`` (as ``stressbots plan``);
- ``open-loop/``: ``result-nominal.json``, ``result-noisy.json`` and their ``trajectory-*.png``.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

import numpy as np

#: Drive time of each primitive in the demo tour (s).
STEP_S = 0.2

#: Sample rate of the exported waveform (Hz).
RATE_HZ = 100_000.0


def load_builtin():
    """The built-in demo scenario (package data ``stressbots/data/demo.toml``)."""
    from .scenario import loads

    text = resources.files("stressbots").joinpath("data", "demo.toml").read_text(encoding="utf-8")
    return loads(text, source="stressbots/data/demo.toml")


def tour(analysis) -> list[tuple[str, float]]:
    """Every primitive up and back down: ``P_0, P_1, ..., P_last, ..., P_0``, each for :data:`STEP_S`."""
    names = [p.name for p in analysis.primitives]
    order = names + names[-2::-1]
    return [(nm, STEP_S) for nm in order]


def _figure(waveform, decoded, analysis, steps):
    """The tour's levels over time: Holds as lines, Drives as bands, thresholds dotted."""
    from matplotlib.figure import Figure

    from .waveform import Hold

    fig = Figure(figsize=(9.0, 4.2))
    ax = fig.add_subplot(1, 1, 1)
    e = analysis.electrodes
    t = 0.0
    for seg in waveform:
        t1 = t + seg.duration_s
        if isinstance(seg, Hold):
            # A Hold is short (hold_s): draw it as a spike from the drive band to its level.
            ax.plot([t, t], [0.5 * (e.drive_low_V + e.drive_high_V), seg.volts], color="tab:blue", linewidth=1.2)
            ax.plot([t], [seg.volts], "o", color="tab:blue", markersize=4)
            ax.annotate(f"{seg.volts:g} V", (t, seg.volts), textcoords="offset points", xytext=(4, 3), fontsize=7)
        else:
            ax.fill_between([t, t1], seg.low_V, seg.high_V, color="tab:orange", alpha=0.35, linewidth=0)
        t = t1
    for d, (name, _) in zip(decoded.drives, steps):
        ax.text(d.t_start_s + 0.5 * d.duration_s, analysis.electrodes.drive_high_V + 3, name, ha="center", fontsize=8)
    for i, nm in enumerate(analysis.names):
        ax.axhline(analysis.snap_down_V[i], color="tab:red", linestyle=":", linewidth=0.8)
        ax.axhline(analysis.release_V[i], color="tab:green", linestyle=":", linewidth=0.8)
        ax.text(t, analysis.snap_down_V[i], f" V_d {nm}", va="center", fontsize=7, color="tab:red")
        ax.text(t, analysis.release_V[i], f" V_u {nm}", va="center", fontsize=7, color="tab:green")
    ax.set_xlim(0, t * 1.08)
    ax.set_ylim(0, analysis.electrodes.max_V * 1.03)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("level (V)")
    ax.set_title(f"Tour {steps[0][0]} -> {max(steps, key=lambda s: int(s[0][1:]))[0]} -> {steps[-1][0]}: "
                 "Holds (blue) set the arms, Drives (band) move the robots", fontsize=10)
    return fig


def run_demo(out_dir: Path, console, quiet: bool = False) -> dict:
    """Run the demo, print what it does (unless ``quiet``) and write its outputs into ``out_dir``.

    Returns a small summary dict (paths and counts) for callers and tests.
    """
    from .cli import render_analysis, render_waveform
    from .electrostatics import analyse_scenario
    from .outputs import prepare_dir, save_figure, write_json
    from .waveform import export, replay, synthesize, synthesize_primitive, to_json

    out = prepare_dir(out_dir)
    scenario = load_builtin()
    analysis = analyse_scenario(scenario)
    if not quiet:
        render_analysis(analysis, console, title=f"built-in scenario {scenario.name!r}")
        console.print()
        console.print("[bold]Waveform of each primitive from all arms up[/bold] (Holds of hold_s, then a Drive)")
        for p in analysis.primitives:
            segs = synthesize_primitive(analysis, p, STEP_S)
            render_waveform(segs, console, title=f"{p.name}: turning {', '.join(p.turning) or 'none'}")

    steps = tour(analysis)
    waveform = synthesize(analysis, steps)
    decoded = replay(waveform, analysis.snap_down_V, analysis.release_V)
    intended = np.array([analysis.primitive(name).state for name, _ in steps], dtype=np.uint8)
    got = np.array([d.states for d in decoded.drives], dtype=np.uint8)
    if got.shape != intended.shape or not np.array_equal(got, intended) or not all(d.ok for d in decoded.drives):
        raise RuntimeError("internal error: the demo waveform does not decode to its primitives")

    write_json(out / "states.json", analysis.to_json_dict())
    write_json(out / "waveform.json", to_json(waveform))
    summary = export(waveform, out / "waveform.npy", rate_hz=RATE_HZ, drive_frequency_hz=scenario.electrodes.drive_frequency_hz)
    save_figure(_figure(waveform, decoded, analysis, steps), out / "waveform.png")

    if not quiet:
        console.print()
        console.print("[bold]Tour[/bold] " + " -> ".join(name for name, _ in steps), highlight=False)
        for d, (name, _) in zip(decoded.drives, steps):
            turning = [analysis.names[i] for i in np.flatnonzero(d.states)]
            console.print(
                f"  t = {d.t_start_s:7.3f} s  {name}: decoded turning {', '.join(turning) or 'none'} (as intended)",
                highlight=False,
            )
    planned = _plan_and_simulate(scenario, out, console, quiet)
    verdict = f"STRING, order {', '.join(analysis.order)}" if analysis.is_string else "not STRING"
    first = (
        f"demo: {analysis.n} robots, {verdict}, {analysis.count} accessible control states; "
        f"tour of {len(steps)} primitives, {summary.duration_s:.3f} s, levels {min(summary.levels_V):g}-{max(summary.levels_V):g} V "
        f"within [0, {scenario.electrodes.max_V:g}] V; wrote states.json, waveform.json, waveform.npy, waveform.png to {out}"
    )
    if quiet:  # one summary line
        console.print(f"{first}; {planned['line']}", soft_wrap=True, highlight=False)
    else:
        console.print(first, soft_wrap=True, highlight=False)
        console.print(planned["line"], soft_wrap=True, highlight=False)
    return {"out_dir": str(out), "count": analysis.count, "steps": len(steps), "samples": summary.samples, **planned["summary"]}


def _plan_and_simulate(scenario, out: Path, console, quiet: bool) -> dict:
    """Plan the built-in tee, then play the plan open loop without and with noise."""
    from . import plans
    from .assessment import assess
    from .outputs import prepare_dir, provenance, save_figure, write_json
    from .planning import plan_assembly
    from .scenario import Noise
    from .sim import run_plan
    from .viz import plot_plan, plot_run

    result = plan_assembly(scenario)
    pdir = prepare_dir(out / "plan")
    plans.save(result.plan, pdir / "plan.json")
    write_json(pdir / "summary.json", {**result.summary, "provenance": dict(result.plan.provenance)})
    save_figure(plot_plan(scenario, result), pdir / "plan.png")
    s = result.summary
    if not quiet:
        console.print()
        console.print(
            f"[bold]Plan[/bold]: {s['structure']} in {s['duration_s']:.1f} s, {s['steps']} steps "
            f"(lower bound {s['lower_bound_s']:.1f} s, efficiency {s['efficiency']:.2f}); replayed independently: ok",
            highlight=False,
        )
        for note in result.notes:
            console.print(f"  note: {note}", highlight=False)
    odir = prepare_dir(out / "open-loop")
    goals = result.plan.goal_array()
    rows = {}
    for label, scn, seed in (("nominal", scenario.with_noise(Noise()), 0), ("noisy", scenario, 1)):
        plant = run_plan(scn, result.plan, seed=seed, record=True)
        a = assess(scn.names, plant.true_poses(), goals, plant.docked, scn.lengths_um, scn.widths_um)
        write_json(odir / f"result-{label}.json", {
            "success": a.success, "seed": seed, "robots": a.robot_rows(plant.observe()), "mode": "open-loop",
            **a.summary(), "events": [e.as_dict() for e in plant.events], "provenance": provenance(seed),
        })
        times, poses = plant.trace()
        save_figure(plot_run(scn, times, poses, goals, plant.events), odir / f"trajectory-{label}.png")
        rows[label] = a
        if not quiet:
            console.print(
                f"[bold]Open loop, {label}[/bold]: {int(a.docked.sum())}/{scn.n} docked, worst position error "
                f"{a.position_error_um.max():.3g} um, shape error {a.shape.rms_um:.3g} um RMS",
                highlight=False,
            )
    line = (
        f"plan: {s['duration_s']:.1f} s, efficiency {s['efficiency']:.2f}; open loop: nominal "
        f"{'docks every robot' if rows['nominal'].success else 'FAILED'}, with literature noise the worst robot ends "
        f"{rows['noisy'].position_error_um.max():.0f} um off; wrote plan/ and open-loop/ to {out}"
    )
    return {"line": line, "summary": {"plan_duration_s": s["duration_s"], "open_loop_nominal_success": rows["nominal"].success}}
