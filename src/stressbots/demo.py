"""``stressbots demo``: the main job, end to end, on the built-in 4-robot scenario.

The demo is :func:`stressbots.pipeline.run_job` (analyse, plan, closed loop on the simulated plant with
the literature's error levels, report) on the built-in scenario (``data/demo.toml``, a copy of
``examples/four-robots.toml``), plus two things that only make sense on a fixed example:

1. a tour of the electrostatic control layer: the waveform of every primitive ``P_0, P_1, ..., P_n, ...,
   P_0`` (each reached with the fewest Holds, then driven), checked with the decoder;
2. comparisons: the same nominal plan open loop without noise (every robot ends in its slot: planner,
   waveform and simulator agree) and with noise (it drifts far, which is why the closed loop exists),
   and the closed loop without noise.

Outputs in the chosen folder: everything :data:`stressbots.pipeline.OUTPUT_FILES` lists
(``report.html``, ``result.json``, ``plan.json``, ``states.json``, ``waveform.json``/``.npy``/``.png``,
``plan.png``, ``run.png``, ``structure.png``), ``tour/`` (``waveform.json``, ``waveform.npy`` at 100 kS/s,
``waveform.png``) and ``comparisons/`` (``open-loop-nominal.json``/``.png``, ``open-loop-noisy.json``/``.png``,
``closed-loop-nominal.json``).
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
    for d, (name, _) in zip(decoded.drives, steps, strict=True):
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


#: Simulated time budget of the demo's closed-loop run (s): the nominal plan takes about 124 s and a
#: run without control error about 180 s; the budget keeps ``stressbots demo`` under a minute of wall time.
DEMO_TIME_BUDGET_S = 600.0


def _print_analysis(scenario, analysis, console) -> None:
    """The voltage analysis and the waveform that reaches each primitive from all arms up (Holds of
    ``hold_s``, then a Drive of :data:`STEP_S`)."""
    from .console import render_analysis, render_waveform
    from .waveform import synthesize_primitive

    render_analysis(analysis, console, title=f"built-in scenario {scenario.name!r}")
    console.print()
    console.print("[bold]Waveform of each primitive from all arms up[/bold] (Holds of hold_s, then a Drive)")
    for p in analysis.primitives:
        segs = synthesize_primitive(analysis, p, STEP_S)
        render_waveform(segs, console, title=f"{p.name}: turning {', '.join(p.turning) or 'none'}")


def _checked_tour(analysis):
    """The tour's steps, waveform and decoding, checked: every Drive must decode to the arm state of its
    primitive (else the synthesis and the decoder disagree: an internal error)."""
    from .waveform import replay, synthesize

    steps = tour(analysis)
    waveform = synthesize(analysis, steps)
    decoded = replay(waveform, analysis.snap_down_V, analysis.release_V)
    intended = np.array([analysis.primitive(name).state for name, _ in steps], dtype=np.uint8)
    got = np.array([d.states for d in decoded.drives], dtype=np.uint8)
    if got.shape != intended.shape or not np.array_equal(got, intended) or not all(d.ok for d in decoded.drives):
        raise RuntimeError("internal error: the demo waveform does not decode to its primitives")
    return steps, waveform, decoded


def _write_tour(out: Path, scenario, analysis, steps, waveform, decoded):
    """``tour/``: the waveform as segments (``waveform.json``), sampled at :data:`RATE_HZ`
    (``waveform.npy``) and drawn (``waveform.png``); returns the sampled file's summary."""
    from .outputs import prepare_dir, save_figure, write_json
    from .waveform import export, to_json

    tdir = prepare_dir(out / "tour")
    write_json(tdir / "waveform.json", to_json(waveform))
    summary = export(waveform, tdir / "waveform.npy", rate_hz=RATE_HZ, drive_frequency_hz=scenario.electrodes.drive_frequency_hz)
    save_figure(_figure(waveform, decoded, analysis, steps), tdir / "waveform.png")
    return summary


def _print_tour(console, scenario, analysis, steps, decoded, summary) -> None:
    """The tour as decoded (the robots each Drive turns, which are the intended ones) and what it wrote."""
    console.print()
    console.print("[bold]Tour[/bold] " + " -> ".join(name for name, _ in steps), highlight=False)
    for d, (name, _) in zip(decoded.drives, steps, strict=True):
        turning = [analysis.names[i] for i in np.flatnonzero(d.states)]
        console.print(
            f"  t = {d.t_start_s:7.3f} s  {name}: decoded turning {', '.join(turning) or 'none'} (as intended)",
            highlight=False,
        )
    verdict = f"STRING, order {', '.join(analysis.order or ())}" if analysis.is_string else "not STRING"
    console.print(
        f"tour: {analysis.n} robots, {verdict}, {analysis.count} accessible control states; {len(steps)} primitives, "
        f"{summary.duration_s:.3f} s, levels {min(summary.levels_V):g}-{max(summary.levels_V):g} V within "
        f"[0, {scenario.electrodes.max_V:g}] V; wrote tour/waveform.json, tour/waveform.npy, tour/waveform.png",
        soft_wrap=True, highlight=False,
    )
    console.print()


def run_demo(out_dir: Path, console, quiet: bool = False, *, seed: int = 0, err_console=None) -> dict:
    """Run the demo, print what it does (unless ``quiet``) and write its outputs into ``out_dir``.

    The main job (:func:`stressbots.pipeline.run_job`) on the built-in scenario, with the literature's
    error levels, plus the waveform tour (``tour/``) and, for comparison, the same plan open loop with and
    without noise and closed loop without noise (``comparisons/``). Returns a small summary dict.
    """
    from .console import RichJobObserver
    from .electrostatics import analyse_scenario
    from .outputs import prepare_dir
    from .pipeline import run_job

    out = prepare_dir(out_dir)
    scenario = load_builtin()
    analysis = analyse_scenario(scenario)
    if not quiet:
        _print_analysis(scenario, analysis, console)
    steps, waveform, decoded = _checked_tour(analysis)
    summary = _write_tour(out, scenario, analysis, steps, waveform, decoded)
    if not quiet:
        _print_tour(console, scenario, analysis, steps, decoded, summary)
    job = run_job(
        scenario, out, seed=seed, source="built-in demo scenario (stressbots/data/demo.toml)", time_budget_s=DEMO_TIME_BUDGET_S,
        observer=RichJobObserver(console, err_console, quiet=quiet, show_analysis=False), extra=_comparisons,
        title=f"stressbots demo: {scenario.name}",
    )
    return {
        "out_dir": str(out), "count": analysis.count, "steps": len(steps), "samples": summary.samples,
        "report": str(job.report_path), "report_bytes": job.report_bytes, "success": job.success,
        "failure": job.result.get("failure"), "wall_s": job.wall_s, **job.extra,
    }


def _comparisons(ctx):
    """The demo's comparison runs: the same plan open loop (no noise, literature noise) and closed loop
    without noise. Writes ``comparisons/`` and returns the rows for the report."""
    from .control import assemble
    from .openloop import run_open_loop
    from .outputs import prepare_dir, provenance, save_figure, write_json
    from .pipeline import Extra, run_summary
    from .scenario import Noise
    from .sim import SimulatedPlant
    from .viz import plot_run

    scenario, plan = ctx.scenario, ctx.plan_result.plan
    seed = ctx.run.result.seed
    cdir = prepare_dir(ctx.out_dir / "comparisons")
    extra = Extra()
    nominal = scenario.with_noise(Noise())
    for label, scn, s in (("open-loop-nominal", nominal, 0), ("open-loop-noisy", scenario, seed)):
        run = run_open_loop(scn, plan, seed=s)
        plant, a, goals = run.plant, run.assessment, run.goals
        write_json(cdir / f"{label}.json", {
            "success": a.success, "seed": s, "robots": a.robot_rows(run.observed), "mode": "open-loop",
            "noise": scn.noise.to_file_units(), **{k: v for k, v in a.summary().items() if k != "success"},
            "events": [e.as_dict() for e in plant.events], "provenance": provenance(s),
        })
        times, poses = plant.trace()
        what = "no control error" if scn is nominal else "literature noise"
        save_figure(plot_run(scn, times, poses, goals, plant.events,
                             title=f"{scn.name}: the nominal plan open loop, {what}, seed {s}"), cdir / f"{label}.png")
        extra.comparisons.append({
            "label": f"open loop, {what}" + (f", seed {s}" if scn is not nominal else ""), "success": a.success,
            "docked": f"{int(a.docked.sum())}/{scn.n}", "shape_error_rms_um": a.shape.rms_um,
            "max_position_error_um": float(a.position_error_um.max()),
            "note": "the plan played without feedback" + ("; every robot ends in its slot" if a.success and scn is nominal else ""),
        })
        extra.files += [(f"comparisons/{label}.json", f"result of the plan open loop, {what}"),
                        (f"comparisons/{label}.png", "picture of that run")]
    plant = SimulatedPlant(nominal, seed=seed)
    res = assemble(nominal, plant, seed=seed, plan=ctx.plan_result)
    write_json(cdir / "closed-loop-nominal.json", {**res.to_dict(), "noise": nominal.noise.to_file_units(), "provenance": provenance(seed)})
    rs = run_summary(res)
    extra.comparisons.append({
        "label": "closed loop, no control error", "success": rs["success"], "docked": rs["docked"],
        "shape_error_rms_um": rs["shape_error_rms_um"], "max_position_error_um": rs["max_position_error_um"],
        "note": ("assembled" if rs["success"] else f"not assembled: {rs['failure']}") + f" in {rs['duration_s']:.1f} s simulated",
    })
    extra.files.append(("comparisons/closed-loop-nominal.json", "result of the closed loop without control error"))
    noisy = extra.comparisons[1]
    extra.lines.append(
        f"for comparison: open loop without noise {'docks every robot' if extra.comparisons[0]['success'] else 'FAILS'}; "
        f"open loop with literature noise ends {noisy['max_position_error_um']:.0f} um off; closed loop without noise "
        f"{'assembles' if rs['success'] else 'does not assemble: ' + str(rs['failure'])} (comparisons/)"
    )
    extra.summary.update({"open_loop_nominal_success": bool(extra.comparisons[0]["success"]),
                          "closed_loop_nominal_success": rs["success"]})
    return extra
