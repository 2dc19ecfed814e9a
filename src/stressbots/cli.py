"""The ``stressbots`` command line: a thin layer over the library.

Each command validates its inputs through the library (which raises
:class:`~stressbots.errors.StressbotsError` for anything the user got wrong), calls the pure computation,
and writes results through :mod:`stressbots.outputs`. :func:`main` turns every user error, including bad
options, into one ``error:`` line on stderr and exit status 2, with no traceback.
"""

from __future__ import annotations

import contextlib
import sys
from enum import StrEnum
from pathlib import Path
from typing import Any

import numpy as np
import typer
from rich.console import Console

from .errors import StressbotsError

app = typer.Typer(
    name="stressbots",
    help=(
        "Plan and control groups of stress-engineered MEMS microrobots (MicroStressBots) that all share "
        "one global voltage signal.\n\n"
        "Start with `stressbots demo`. Scenario files are TOML (see README, 'Scenario files'); lengths in "
        "um, times in s, voltages in V, file angles in degrees."
    ),
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode="markdown",
)

#: Most threshold pairs `design --sd-V` draws (trials x robots): a few seconds of work on one core.
MAX_YIELD_DRAWS = 20_000_000

#: Largest --seed accepted: seeds are recorded in JSON outputs and fed to numpy's SeedSequence; 2^63 - 1
#: keeps them ordinary 64-bit integers everywhere.
MAX_SEED = 2**63 - 1

# Results go to stdout; progress and notes to stderr so that `--json` output stays clean.
out = Console()
err = Console(stderr=True)


class StrategyChoice(StrEnum):
    """The --strategy choices of simulate and run (stressbots.strategies.STRATEGIES)."""

    rendezvous = "rendezvous"
    seed = "seed"


def _strategy_option():
    from .strategies import STRATEGY_HELP

    return typer.Option(StrategyChoice.rendezvous, "--strategy", help=STRATEGY_HELP)


# Options of the campaign commands (montecarlo, study: SPEC 10), declared once so both read the same.


def _workers_option():
    return typer.Option(None, "--workers", min=1, max=256, help="Worker processes (default: every core; 1 = in this process).",
                        show_default=False)


def _resume_option():
    return typer.Option(False, "--resume", help="Continue the campaign in DIR/trials.sqlite: run only its missing trials "
                                                "(refused if it was made with other settings).")


def _overwrite_option():
    return typer.Option(False, "--overwrite", help="Start again even though DIR/trials.sqlite holds a campaign (it is deleted).")


def _dask_option():
    return typer.Option(None, "--dask", metavar="ADDRESS", show_default=False,
                        help="Run the trials on a Dask cluster: 'local' (a LocalCluster of --workers processes), a scheduler "
                             "address tcp://host:8786 or a scheduler file *.json. Needs the [dask] extra.")

class CameraChoice(StrEnum):
    """The --camera choices of simulate and run: what the controller sees."""

    poses = "poses"
    images = "images"


CAMERA_HELP = ("What the controller sees: 'poses' (the simulator's noisy pose camera) or 'images' (rendered microscope "
               "frames tracked by stressbots.tracking: image in the loop; needs the [lab] extra).")


class NoiseChoice(StrEnum):
    """The --noise choices of simulate and run."""

    scenario = "scenario"
    none = "none"
    literature = "literature"


def scenario_arg(path: Path, *, moving: bool = False, planning: bool = False):
    """Load a scenario given on the command line (errors name the file and field).

    ``moving``: the command simulates the robots, so the scenario must also be small enough for that
    (:func:`stressbots.scenario.check_movable`), checked before any computation; ``planning``: the
    command only plans (the planner's larger limits).
    """
    from .scenario import check_movable, load

    scn = load(path)
    if moving or planning:
        return check_movable(scn, source=str(path), planning_only=not moving)
    return scn


def _show_version(value: bool) -> None:
    if value:
        from .outputs import versions

        print(" ".join(f"{k} {v}" for k, v in versions().items()))
        raise typer.Exit()


@app.callback()
def _root(
    version: bool = typer.Option(
        False, "--version", callback=_show_version, is_eager=True, help="Print the versions and exit."
    ),
) -> None:
    """Plan and control groups of MEMS microrobots that share one global voltage signal."""


@app.command()
def demo(
    out_dir: Path = typer.Option(Path("stressbots-demo"), "--out", help="Folder for the demo's outputs."),
    seed: int = typer.Option(0, "--seed", min=0, max=MAX_SEED, help="Seed of the simulated plant (same seed, same run)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors (the files are still written)."),
) -> None:
    """Run the main job end to end on the built-in 4-robot scenario and write its report.

    Analyses the built-in voltage design (accessible control states, control matrix, primitives) and
    tours the waveform of every primitive, plans the assembly of a tee, runs it in closed loop on the
    simulated plant with the literature's error levels, and writes DIR/report.html (one self-contained
    page that opens offline) with result.json, plan.json, the waveform and pictures beside it; for
    comparison also the plan open loop with and without noise and closed loop without noise
    (DIR/comparisons/). A run that does not assemble still gets its full report, with the reason.

    Example: `stressbots demo --out demo-out`, then open demo-out/report.html.
    """
    from . import demo as demo_mod

    demo_mod.run_demo(out_dir, console=out, quiet=quiet, seed=seed, err_console=err)


@app.command()
def run(
    scenario: Path = typer.Argument(..., help="Scenario file (TOML): robots with start poses, a target ([structure] or goals), [noise].",
                                    show_default=False),
    out_dir: Path = typer.Option(..., "--out", help="Folder for report.html, result.json, plan.json, the waveform and pictures.",
                                 show_default=False),
    seed: int = typer.Option(0, "--seed", min=0, max=MAX_SEED, help="Seed of the simulated plant (same seed, same run)."),
    noise: NoiseChoice = typer.Option(
        NoiseChoice.scenario, "--noise", help="Control and camera error: the scenario's [noise], none, or the literature's levels."
    ),
    time_budget_s: float | None = typer.Option(
        None, "--time-budget-s", help="Simulated time budget of the closed-loop run (s); default from the layout (a few crossings).",
        show_default=False
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors (the files are still written)."),
    strategy: StrategyChoice = _strategy_option(),
    camera: CameraChoice = typer.Option(CameraChoice.poses, "--camera", help=CAMERA_HELP),
    region_trials: int = typer.Option(
        0, "--region-trials", min=0, max=10_000,
        help="Also run N closed-loop trials at 1x and 2x the scenario's noise and add the regions the controller aims at, "
             "with their coverage by the true poses, to the report (section 'Controller regions', coverage.png). 0: skip."),
) -> None:
    """The main job: validate, analyse the design, plan, run closed loop on the simulator, write the report.

    Validates the scenario, analyses its voltage design (accessible states, control matrix), plans the
    assembly the controller follows, runs the closed-loop controller on the simulated plant (control
    error, contact, compliance, noisy camera; re-planning every [control] replan_interval_s) and writes
    DIR/report.html: one self-contained page (no network) with the design, a waveform excerpt, the
    plan, the run as an animation, the final structure against the target, the metrics and the event
    log. Beside it: result.json, plan.json, states.json, waveform.json, waveform.npy and the pictures.
    A run that does not assemble is reported as "not assembled: <reason>" (exit status 0: the job ran).

    With --region-trials N the report also shows the regions the controller aims at (approach funnel,
    straight-in aim, docking capture G_i*, G_1 rendezvous) and how often the true pose was inside them
    over N more runs at 1x and 2x the noise, beside the seed's A_i* verdict (as `stressbots bounds --trials`).

    Example: `stressbots run examples/four-robots.toml --out out/run --seed 1`
    """
    from .pipeline import coverage_extra, finite_budget, run_job

    budget = finite_budget(time_budget_s)
    scn = _with_noise_choice(scenario_arg(scenario, moving=True), noise)
    from .console import RichJobObserver

    observer = RichJobObserver(out, err, quiet=quiet)
    extra = None
    if region_trials:
        def progress(done: int, total: int) -> None:
            observer.stage("comparisons", total=total, completed=done, info="controller regions")

        extra = coverage_extra(region_trials, seed=seed, progress=progress)
    run_job(scn, out_dir, seed=seed, source=str(scenario), inputs=[scenario], time_budget_s=budget,
            observer=observer, strategy=strategy.value, camera=camera.value, extra=extra)


def _with_noise_choice(scn, choice):
    from .generate import LITERATURE_NOISE
    from .scenario import Noise

    value = getattr(choice, "value", choice)
    if value == "none":
        return scn.with_noise(Noise())
    if value == "literature":
        return scn.with_noise(LITERATURE_NOISE)
    return scn


# ----------------------------------------------------------------------------------------------------
# JSON on stdout


def _print_json(obj) -> None:
    """Exactly one JSON document on stdout (no rich markup, no wrapping)."""
    import json

    from .outputs import _jsonable

    sys.stdout.write(json.dumps(_jsonable(obj), allow_nan=False) + "\n")
    sys.stdout.flush()


# ----------------------------------------------------------------------------------------------------
# states, design, waveform


@app.command()
def states(
    scenario: Path = typer.Argument(..., help="Scenario file (TOML), e.g. examples/four-robots.toml.", show_default=False),
    as_json: bool = typer.Option(False, "--json", help="Print only the JSON object (as shown below) on stdout."),
) -> None:
    """Which arm-state patterns (control states) the one global voltage can reach.

    Searches exactly: levels in [0, max_V], each at least margin_V from every snap-down and release
    voltage, starting from all arms up (0 V). Says whether the design is STRING (and its order
    D_1..D_n, D_1 = lowest snap-down voltage) or why not, and lists the accessible states, the control
    matrix M and the primitives P_k with the Hold level that reaches each.

    Example: `stressbots states examples/four-robots.toml --json` prints
    `{"robots": [...], "string": true, "order": [...], "accessible_states": [[0, 0, 0, 0], ...], "count": 5}`
    (states in scenario order, sorted).
    """
    from .console import render_analysis
    from .electrostatics import analyse_scenario

    sc = scenario_arg(scenario)
    analysis = analyse_scenario(sc)
    if as_json:
        _print_json(analysis.to_json_dict())
        return
    render_analysis(analysis, out, title=f"{scenario} ({sc.name})")


@app.command()
def design(
    robots: int = typer.Option(..., "--robots", "-n", help="Number of robots N (>= 1).", show_default=False),
    max_v: float = typer.Option(200.0, "--max-V", help="Largest level the hardware may apply (V)."),
    margin_v: float = typer.Option(5.0, "--margin-V", help="delta_v: distance every level keeps from every threshold (V)."),
    drive_low_v: float = typer.Option(75.0, "--drive-low-V", help="Low level of the power-delivery band (V)."),
    drive_high_v: float = typer.Option(105.0, "--drive-high-V", help="High level of the power-delivery band (V)."),
    drive_frequency_hz: float = typer.Option(10000.0, "--drive-frequency-hz", help="Drive frequency (Hz), written to the fragment."),
    hold_s: float = typer.Option(0.001, "--hold-s", help="How long each setting level is held (s), written to the fragment."),
    ties: bool = typer.Option(
        False, "--ties/--no-ties", help="Let consecutive robots share V_d or V_u (not both): fits about twice as many robots."
    ),
    sd_v: float | None = typer.Option(
        None, "--sd-V", help="Also estimate the yield when every threshold scatters with this standard deviation (V).", show_default=False
    ),
    resolution_v: float = typer.Option(
        0.1, "--resolution-V", min=0.0, max=10.0,
        help="Round every voltage to this step (V): the resolution of the instrument that sets the levels; 0 = exact.",
    ),
    trials: int = typer.Option(10000, "--trials", min=1, max=10_000_000, help="Monte Carlo trials for the yield."),
    seed: int = typer.Option(0, "--seed", min=0, max=MAX_SEED, help="Random seed for the yield (same seed, same estimate)."),
    as_json: bool = typer.Option(False, "--json", help="Write JSON instead of a TOML scenario fragment."),
    out_file: Path | None = typer.Option(
        None, "--out", help="Write to this file (atomically) instead of stdout; .json implies --json.", show_default=False
    ),
) -> None:
    """Design STRING snap-down/release voltages for N robots, or say why N does not fit.

    Places the release voltages between 0 V and the drive band and the snap-down voltages between the
    band and max_V, evenly, so the smallest gap between thresholds (and so the room for fabrication
    scatter) is as large as the margins and the drive-band rule (V_u <= drive_low - 2 delta_v,
    V_d >= drive_high + 2 delta_v) allow. Output: a scenario fragment ([electrodes] and [[robots]]
    D1..DN) that `stressbots states` loads; add start poses to plan with it.

    Examples: `stressbots design --robots 4`;
    `stressbots design --robots 12 --ties --sd-V 2 --out design.toml`.
    """
    from .design import design_string, estimate_yield, round_design
    from .electrostatics import Electrodes
    from .outputs import prepare_file, to_json, write_text

    e = Electrodes(max_V=max_v, margin_V=margin_v, drive_low_V=drive_low_v, drive_high_V=drive_high_v,
                   drive_frequency_hz=drive_frequency_hz, hold_s=hold_s)
    if out_file is not None:
        prepare_file(out_file)
    d = design_string(robots, e, ties=ties)
    if resolution_v > 0:
        d = round_design(d, resolution_v)
    if sd_v is not None:
        _check_yield_request(sd_v, trials, d.n)
    y = estimate_yield(d, sd_v, trials=trials, seed=seed) if sd_v is not None else None
    use_json = as_json or (out_file is not None and out_file.suffix.lower() == ".json")
    text = to_json(d.to_json_dict(y)) if use_json else d.to_toml(y)
    if out_file is None:
        sys.stdout.write(text)
        return
    write_text(out_file, text)
    err.print(f"wrote {out_file}: STRING design for {d.n} robots, smallest gap {d.min_gap_V:g} V", highlight=False, soft_wrap=True)
    if y is not None:
        err.print(f"yield (sd {y.sd_V:g} V): {y.fraction:.4f}, 95% CI {y.ci_low:.4f}-{y.ci_high:.4f}", highlight=False, soft_wrap=True)


def _check_yield_request(sd_v: float, trials: int, n: int) -> None:
    """``design --sd-V``: a scatter in [0, 100] V and at most :data:`MAX_YIELD_DRAWS` threshold pairs drawn."""
    if not (0 <= sd_v <= 100):
        raise StressbotsError(f"must be a number in [0, 100] V, got {sd_v:g}", source="--sd-V")
    if trials * n > MAX_YIELD_DRAWS:
        raise StressbotsError(
            f"{trials} trials of {n} robots draw {trials * n:,} threshold pairs; at most {MAX_YIELD_DRAWS:,} "
            f"(at most {MAX_YIELD_DRAWS // n:,} trials for {n} robots)",
            source="--trials",
        )


#: Sampled waveform outputs (.npy/.csv) above this many samples need --large: about 32 MB as .npy and
#: 40 MB as CSV. The segments (.json) describe any waveform exactly in a few kB.
LARGE_SAMPLES = 2_000_000


@app.command()
def waveform(
    scenario: Path = typer.Argument(..., help="Scenario file (TOML) giving the robots' voltages and the limits.", show_default=False),
    out_file: Path = typer.Option(
        ..., "--out", help="Output file: .json (segments, small), .npy (samples, columns t_s and volts) or .csv (same).",
        show_default=False,
    ),
    steps: str | None = typer.Option(
        None, "--steps", help="Primitives and drive durations (s), e.g. 'P1:2.5,P0:1.0'.", show_default=False
    ),
    plan: Path | None = typer.Option(None, "--plan", help="A plan.json (as `stressbots plan` writes) instead of --steps.",
                                        show_default=False),
    rate_hz: float = typer.Option(100_000.0, "--rate-hz", min=1.0, max=10_000_000.0,
                                  help="Sample rate (Hz) for .npy/.csv; at least twice the drive frequency."),
    large: bool = typer.Option(False, "--large",
                               help=f"Allow a sampled output of more than {LARGE_SAMPLES:,} samples (tens of MB or more)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Synthesise the voltage waveform of a list of primitives and write it.

    Each step reaches its primitive's arm state from the previous one with the fewest Holds (levels
    keep margin_V from every threshold and stay in [0, max_V]), then drives for the given time: a
    square wave between drive_low_V and drive_high_V at drive_frequency_hz. Refuses inaccessible states
    and a drive band that would flip an arm. Primitive names are those `stressbots states` prints.
    A .json output lists the segments (exact, small); .npy/.csv sample them, which for a whole plan is
    large (a 2-minute plan at 100 kS/s is 200 MB of CSV), so more than 2,000,000 samples need --large.

    Examples: `stressbots waveform examples/four-robots.toml --steps P1:2.5,P0:1.0 --out wf.npy`;
    `stressbots waveform SCENARIO --plan out/plan/plan.json --out wf.json`.
    """
    from .electrostatics import analyse_scenario
    from .outputs import prepare_file
    from .waveform import export, replay, synthesize

    if (steps is None) == (plan is None):
        raise StressbotsError("give exactly one of --steps or --plan", source="stressbots waveform")
    prepare_file(out_file, inputs=[scenario, plan])
    if out_file.suffix.lower() not in (".npy", ".csv", ".json"):
        raise StressbotsError(f"unsupported output {out_file.name!r}: use a .json, .npy or .csv file", source="--out")
    sc = scenario_arg(scenario)
    analysis = analyse_scenario(sc)
    step_list = _waveform_steps(analysis, steps, plan)
    _check_sampled_size(out_file, step_list, sc, rate_hz, large)
    wf = synthesize(analysis, step_list)
    decoded = replay(wf, analysis.snap_down_V, analysis.release_V)
    summary = export(wf, out_file, rate_hz=rate_hz, drive_frequency_hz=sc.electrodes.drive_frequency_hz)
    if quiet:
        return
    levels = ", ".join(f"{v:g}" for v in summary.levels_V)
    size = out_file.stat().st_size
    out.print(
        f"wrote {out_file} ({size / 1e6:.3g} MB): {summary.segments} segments ({summary.holds} holds, {summary.drives} drives), "
        f"{summary.duration_s:g} s" + (f", {summary.samples} samples at {summary.rate_hz:g} Hz" if summary.samples else ""),
        highlight=False,
        soft_wrap=True,
    )
    out.print(f"levels used (V): {levels}; min {summary.min_V:g} V, max {summary.max_V:g} V", highlight=False, soft_wrap=True)
    bad = [d for d in decoded.drives if not d.ok]
    out.print(
        f"decoded: {len(decoded.drives)} drives, " + ("every arm as intended" if not bad else f"{len(bad)} with flipped arms"),
        highlight=False,
        soft_wrap=True,
    )


def _waveform_steps(analysis, steps: str | None, plan: Path | None) -> list:
    """The (state, duration) steps of ``waveform``, from --plan or --steps, bounded in total duration."""
    from .plans import MAX_PLAN_S
    from .waveform import parse_steps, steps_from_plan

    if plan is not None:
        from .plans import load as load_plan

        return steps_from_plan(load_plan(plan), analysis, source=str(plan))
    assert steps is not None
    if len(steps) > 100_000:
        raise StressbotsError(f"too long ({len(steps)} characters); give a plan file (--plan) for long sequences", source="--steps")
    step_list = parse_steps(steps, analysis)
    total = sum(d for _, d in step_list)
    if total > MAX_PLAN_S:
        raise StressbotsError(f"the drives add up to {total:g} s; at most {MAX_PLAN_S:g} s are accepted", source="--steps")
    return step_list


def _check_sampled_size(out_file: Path, step_list, sc, rate_hz: float, large: bool) -> None:
    """Refuse, before synthesising, a sampled output larger than :data:`LARGE_SAMPLES` without --large."""
    if out_file.suffix.lower() == ".json":
        return
    e = sc.electrodes
    total = sum(d for _, d in step_list) + 2 * sc.n * e.hold_s * len(step_list)
    samples = int(total * rate_hz)
    if samples > LARGE_SAMPLES and not large:
        per = 16 if out_file.suffix.lower() == ".npy" else 22
        raise StressbotsError(
            f"{out_file} would hold about {samples:,} samples ({total:.3g} s at {rate_hz:g} Hz, about {samples * per / 1e6:.0f} MB): "
            f"write the segments instead (a .json file), lower --rate-hz, or pass --large",
            source="--out",
        )


def _waveform_of(scenario: Path, steps: str | None, plan: Path | None, out_file: Path, suffixes: tuple[str, ...], command: str):
    """The scenario, its voltage analysis and the waveform of ``--steps`` or ``--plan`` (shared by ``waveform``
    and ``awg``), after checking ``--out`` (not an input, not a folder, a known suffix)."""
    from .electrostatics import analyse_scenario
    from .outputs import prepare_file
    from .waveform import synthesize

    if (steps is None) == (plan is None):
        raise StressbotsError("give exactly one of --steps or --plan", source=f"stressbots {command}")
    prepare_file(out_file, inputs=[scenario, plan])
    if out_file.suffix.lower() not in suffixes:
        kinds = ", ".join(suffixes[:-1]) + f" or {suffixes[-1]}"
        raise StressbotsError(f"unsupported output {out_file.name!r}: use a {kinds} file", source="--out")
    sc = scenario_arg(scenario)
    analysis = analyse_scenario(sc)
    step_list = _waveform_steps(analysis, steps, plan)
    return sc, analysis, synthesize(analysis, step_list)


@app.command()
def plan(
    scenario: Path = typer.Argument(..., help="Scenario file (TOML) with start poses and goals or a [structure].", show_default=False),
    out_dir: Path = typer.Option(..., "--out", help="Folder for plan.json, plan.png and summary.json.", show_default=False),
    seed: int = typer.Option(
        0, "--seed", min=0, max=MAX_SEED,
        help="Seed of the route search's random waypoints (recorded in plan.json); `run`, `simulate` and `demo` plan with 0.",
    ),
    clearance_um: float | None = typer.Option(
        None, "--clearance-um", min=0.0, max=1000.0,
        help="Distance kept from orbits, the structure and the arena edge (um); default the controller's setting.", show_default=False,
    ),
    approach_um: float | None = typer.Option(
        None, "--approach-um", min=1.0, max=5000.0,
        help="Final approach into every slot (um): a gentle clockwise arc, then a short straight push; default the controller's.",
        show_default=False,
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors."),
) -> None:
    """Plan the assembly: one sequence of primitives that docks every robot in its slot.

    D_n and D_{n-1} form G_1 while the others orbit; then D_{n-2} .. D_1 dock one at a time
    (the paper's Appendix 2, generalised). The plan is replayed by an independent verifier before it
    is written. With the default settings it is exactly the plan `run`, `simulate` and `demo` follow;
    --clearance-um or --approach-um plan differently (for exploring), and say so.

    Example: `stressbots plan examples/four-robots.toml --out out/plan`
    """
    import time

    from . import plans as plans_mod
    from .outputs import prepare_dir, save_figure, write_json
    from .pipeline import plan_for
    from .viz import plot_plan

    t0 = time.perf_counter()
    scn = scenario_arg(scenario, planning=True)
    folder = prepare_dir(out_dir, inputs=[scenario], files=("plan.json", "plan.png", "summary.json"))
    options = _planner_options(seed, clearance_um, approach_um)
    with err.status("planning...", spinner="dots") if not quiet and err.is_terminal else _nullcontext():
        result = plan_for(scn, str(scenario), seed=seed, options=options)
    plans_mod.save(result.plan, folder / "plan.json")
    wall = time.perf_counter() - t0
    write_json(folder / "summary.json", {**result.summary, "wall_time_s": wall, "controller_settings": options is None,
                                         "provenance": dict(result.plan.provenance)})
    save_figure(plot_plan(scn, result), folder / "plan.png")
    if not quiet:
        _print_plan_summary(scn, result, time.perf_counter() - t0)
        if options is not None:
            out.print("note: planned with non-default settings: `run`, `simulate` and `demo` follow a different plan",
                      highlight=False, soft_wrap=True)
        out.print(f"wrote {folder / 'plan.json'}, {folder / 'plan.png'}, {folder / 'summary.json'}", highlight=False, soft_wrap=True)


def _planner_options(seed: int, clearance_um: float | None, approach_um: float | None):
    """None (the controller's planner settings) unless the user changed a planner option."""
    if clearance_um is None and approach_um is None:
        return None
    from dataclasses import replace

    from .control.targets import PLAN_CLEARANCE_UM
    from .planning import PlannerOptions

    base = PlannerOptions(seed=seed, clearance_um=PLAN_CLEARANCE_UM)
    if clearance_um is not None:
        base = replace(base, clearance_um=clearance_um)
    if approach_um is not None:
        base = replace(base, approach_um=approach_um)
    return base


@contextlib.contextmanager
def _attributed(source: str):
    """Name ``source`` in a user error raised inside that names no file (e.g. a planning error)."""
    try:
        yield
    except StressbotsError as exc:
        if exc.source is None:
            exc.source = source
            exc.args = (exc.message,)
        raise


def _nullcontext():
    import contextlib

    return contextlib.nullcontext()


def _print_plan_summary(scn, result, wall_s: float) -> None:
    from rich.table import Table

    s = result.summary
    rank = {name: k + 1 for k, name in enumerate(result.analysis.order)}
    t = Table(title=f"{scn.name}: {s['structure']} ({s['variant']})", show_lines=False)
    t.add_column("robot")
    t.add_column("D_k", justify="right")
    t.add_column("route (um)", justify="right")
    t.add_column("docks at (s)", justify="right")
    for i, name in enumerate(scn.names):
        t.add_row(name, f"D{rank[name]}", f"{s['route_length_um'][name]:.0f}", f"{result.replay.dock_times_s[i]:.1f}")
    out.print(t)
    out.print(
        f"duration {s['duration_s']:.1f} s in {s['steps']} steps; lower bound {s['lower_bound_s']:.1f} s; "
        f"efficiency {s['efficiency']:.2f}; planned in {wall_s:.1f} s (wall time of the command)",
        highlight=False, soft_wrap=True,
    )
    for note in result.notes:
        out.print(f"note: {note}", highlight=False, soft_wrap=True)


# ----------------------------------------------------------------------------------------------------
# simulate


def _noise_dict(noise) -> dict[str, float]:
    """The noise levels in the file's units (deg, deg/mm)."""
    return noise.to_file_units()


@app.command()
def simulate(
    scenario: Path = typer.Argument(..., help="Scenario file (TOML): robots, start poses, arena and [noise].", show_default=False),
    out_dir: Path = typer.Option(..., "--out", help="Folder for result.json and the pictures.", show_default=False),
    seed: int = typer.Option(0, "--seed", min=0, max=MAX_SEED,
                             help="Seed of every random draw of the simulated plant (same seed, same run)."),
    plan: Path | None = typer.Option(
        None, "--plan", help="Execute this plan.json open loop instead of the closed-loop controller.", show_default=False
    ),
    noise: NoiseChoice = typer.Option(
        NoiseChoice.scenario, "--noise", help="Control and camera error: the scenario's [noise], none, or the literature's levels."
    ),
    time_budget_s: float | None = typer.Option(
        None, "--time-budget-s", help="Closed loop: simulated time budget (s); default from the layout (a few crossings).",
        show_default=False
    ),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors."),
    strategy: StrategyChoice = _strategy_option(),
    camera: CameraChoice = typer.Option(CameraChoice.poses, "--camera", help=CAMERA_HELP),
) -> None:
    """Run the simulated plant: robots with control error, contact, compliance and a noisy camera.

    Without `--plan` the closed-loop controller assembles the target structure: it follows the nominal
    plan, measures the poses every [control] replan_interval_s and re-plans from where the robots
    really are. Writes DIR/result.json (success, seed, per-robot true and observed final poses, goals,
    errors and docked flags, the shape error after a best rigid alignment, the failure reason if any,
    the controller's and the plant's events), DIR/trajectory.png, DIR/structure.png (final structure
    against the target) and DIR/animation.html (the run as an animation; opens offline).

    With `--plan` the plan's waveform is played open loop (no feedback) from the start poses. With no
    noise the robots end exactly in their slots (planner, waveform and simulator agree); with noise you
    see how far open loop drifts. Writes DIR/result.json and DIR/trajectory.png.

    Examples: `stressbots simulate examples/four-robots.toml --seed 1 --out out/sim`;
    `stressbots simulate examples/four-robots.toml --plan out/plan/plan.json --noise none --out out/open`
    """
    if plan is None:
        _simulate_closed_loop(scenario, out_dir, seed, noise, time_budget_s, quiet, strategy.value, camera.value)
        return
    if camera is CameraChoice.images:
        raise StressbotsError("a plan played open loop observes nothing; use --camera images without --plan", source="--camera")
    _simulate_open_loop(scenario, plan, out_dir, seed, noise, quiet)


def _simulate_open_loop(scenario: Path, plan: Path, out_dir: Path, seed: int, noise: NoiseChoice, quiet: bool) -> None:
    """``simulate --plan``: the plan's waveform open loop (:mod:`stressbots.openloop`), result.json and a picture."""
    import time

    from .openloop import result_document, run_open_loop
    from .outputs import prepare_dir, save_figure, write_json
    from .plans import check_against
    from .plans import load as load_plan
    from .scenario import check_starts
    from .viz import plot_run

    t_command = time.perf_counter()
    scn = scenario_arg(scenario, moving=True)
    folder = prepare_dir(out_dir, inputs=[scenario, plan], files=("result.json", "trajectory.png"))
    check_starts(scn, source=str(scenario))
    the_plan = load_plan(plan)
    check_against(the_plan, scn, source=str(plan))
    scn = _with_noise_choice(scn, noise)
    run = run_open_loop(scn, the_plan, seed=seed, source=str(plan))
    write_json(folder / "result.json", result_document(run, scenario_source=str(scenario), plan_source=str(plan)))
    plant, a = run.plant, run.assessment
    times, poses = plant.trace()
    title = (
        f"{scn.name}: open loop, noise {noise.value}, seed {plant.seed} - "
        f"{'success' if a.success else 'failure'}, shape error {a.shape.rms_um:.3g} um RMS"
    )
    save_figure(plot_run(scn, times, poses, run.goals, plant.events, title=title), folder / "trajectory.png")
    if not quiet:
        _print_open_loop(run, plan, folder, time.perf_counter() - t_command)


def _print_open_loop(run, plan: Path, folder: Path, command_s: float) -> None:
    """The open-loop run's table (docked, position and heading error per robot) and verdict."""
    from rich.table import Table

    scn, plant, a = run.scenario, run.plant, run.assessment
    t = Table(title=f"{scn.name}: plan {plan} open loop, {plant.time_s:.1f} s simulated; the command took {command_s:.1f} s")
    for col, just in (("robot", "left"), ("docked", "left"), ("position error (um)", "right"), ("heading error (deg)", "right")):
        t.add_column(col, justify=just)  # type: ignore[arg-type]
    for k, name in enumerate(scn.names):
        t.add_row(name, "yes" if a.docked[k] else "no", f"{a.position_error_um[k]:.3g}", f"{a.heading_error_deg[k]:.3g}")
    out.print(t)
    out.print(
        f"{'success' if a.success else 'failure'}: {int(a.docked.sum())}/{scn.n} docked, shape error {a.shape.rms_um:.3g} um RMS "
        f"(tolerance {a.shape_tol_um:g} um), {len(plant.events)} events",
        highlight=False,
        soft_wrap=True,
    )
    out.print(f"wrote {folder / 'result.json'}, {folder / 'trajectory.png'}", highlight=False, soft_wrap=True)

def _simulate_closed_loop(scenario: Path, out_dir: Path, seed: int, noise: NoiseChoice, time_budget_s, quiet: bool,
                          strategy: str = "rendezvous", camera: str = "poses") -> None:
    """``simulate`` without ``--plan``: the closed-loop controller on the simulated plant."""
    import time

    from .console import verdict_text
    from .outputs import prepare_dir, write_bytes, write_json, write_text
    from .pipeline import (
        closed_loop,
        finite_budget,
        layout_time_budget_s,
        plan_for,
        result_document,
        run_pictures,
    )
    from .report import animation_page
    from .scenario import check_starts

    t_command = time.perf_counter()
    budget = finite_budget(time_budget_s)
    scn = _with_noise_choice(scenario_arg(scenario, moving=True), noise)
    names: tuple[str, ...] = ("result.json", "trajectory.png", "structure.png", "animation.html")
    folder = prepare_dir(out_dir, inputs=[scenario], files=names)
    if not scn.has_starts:
        raise StressbotsError("every robot needs a start pose to be simulated (robots[].start)", source=str(scenario), field="robots")
    check_starts(scn, source=str(scenario))
    show = not quiet and err.is_terminal  # spinners only on a terminal (no stray lines in logs)
    with err.status("planning the nominal assembly...", spinner="dots") if show else _nullcontext() as status:
        plan_result = plan_for(scn, str(scenario))
        on_time = (lambda t: status.update(f"closed loop: {t:.0f} s simulated...")) if show else None
        if show:
            status.update("closed loop...")
        if budget is None:
            budget = layout_time_budget_s(scn)
        run = closed_loop(scn, plan_result, seed=seed, time_budget_s=budget, on_time=on_time, strategy=strategy,
                          camera=camera)
        if show:
            status.update("pictures...")
        doc = result_document(scn, run, source=str(scenario))
        write_json(folder / "result.json", doc)
        figs, anim = run_pictures(scn, run)
        write_bytes(folder / "trajectory.png", figs["run"])
        write_bytes(folder / "structure.png", figs["structure"])
        if "frames" in figs:
            write_bytes(folder / "frames.png", figs["frames"])
            names = names + ("frames.png",)
        write_text(folder / "animation.html", animation_page(anim, title=anim["title"], subtitle=f"{verdict_text(doc)}"))
    if not quiet:
        _print_closed_loop(scn, run, doc, f"noise {noise.value}, camera {camera}", folder, names, time.perf_counter() - t_command)


def _print_closed_loop(scn, run, doc: dict, conditions: str, folder: Path, names: tuple[str, ...], command_s: float) -> None:
    """``simulate`` (closed loop) on the terminal: the run's headline, the per-robot table, the verdict and
    the files written."""
    from .console import robot_table, verdict_text
    from .pipeline import merged_events

    res = run.result
    out.print(f"[bold]{scn.name}[/bold]: closed loop ({run.strategy}), {conditions}, seed {res.seed}: "
              f"{res.duration_s:.1f} s simulated, "
              f"{res.replans} re-plans; the command took {command_s:.1f} s (wall time)",
              highlight=False, soft_wrap=True)
    out.print(robot_table(scn.names, res))
    style = "bold green" if res.success else "bold red"
    out.print(f"[{style}]{verdict_text(doc)}[/{style}]", highlight=False, soft_wrap=True)
    out.print(
        f"{int(np.sum(res.docked))}/{scn.n} docked, shape error {res.shape_error_rms_um:.3g} um RMS after the best rigid alignment; "
        f"{len(merged_events(res, run.plant))} events",
        highlight=False, soft_wrap=True,
    )
    out.print("wrote " + ", ".join(str(folder / n) for n in names), highlight=False, soft_wrap=True)


# ----------------------------------------------------------------------------------------------------
# bounds, montecarlo


#: Largest --k of `bounds` (standard deviations): beyond 10 sigma every error box is meaningless.
MAX_K = 10.0


def _check_structure_in_arena(scn, source: str) -> None:
    """Refuse, before computing, a target whose every slot layout leaves the arena (as the planner does)."""
    if scn.arena_um is None:
        return
    from .collision import outside_arena
    from .electrostatics import analyse_scenario
    from .structures import target_structures

    analysis = analyse_scenario(scn)
    if not analysis.is_string or scn.n < 2:
        return  # the command itself explains why it cannot go on
    robots = [scn.robots[i] for i in analysis.order_index or ()]
    worst: tuple[str, float] | None = None
    for st in target_structures(robots, scn.structure):
        goals = st.goal_poses(scn.names)
        over = outside_arena(goals, scn.lengths_um, scn.widths_um, scn.arena_um)
        if not np.any(over > 0):
            return
        i = int(np.argmax(over))
        worst = (scn.names[i], float(over[i])) if worst is None or over[i] > worst[1] else worst
    if worst is not None:
        w, h = scn.arena_um
        field = "structure.at" if scn.structure is not None else "robots.goal"
        raise StressbotsError(
            f"the target does not fit in the arena [0, {w:g}] x [0, {h:g}] um: the slot of {worst[0]} is {worst[1]:.1f} um outside",
            source=source, field=field,
        )


def _finite_nonneg(value: float, option: str) -> float:
    import math

    if not (math.isfinite(value) and value >= 0):
        raise StressbotsError(f"must be a finite number >= 0, got {value:g}", source=option)
    return float(value)


@app.command()
def bounds(
    scenario: Path = typer.Argument(..., help="Scenario file (TOML) with goals or a [structure], and a [noise] section.",
                                    show_default=False),
    out_dir: Path | None = typer.Option(None, "--out", help="Folder for bounds.json and bounds.png.", show_default=False),
    as_json: bool = typer.Option(False, "--json", help="Print only the bounds.json object on stdout."),
    k: float = typer.Option(3.0, "--k", help="Standard deviations of each noise factor the bounds cover (k-sigma box)."),
    critical: bool = typer.Option(
        False, "--critical", help="Also find, per robot, the largest multiple of [noise] at which it is still guaranteed (a few s)."
    ),
    coverage_trials: int = typer.Option(
        0, "--coverage-trials", min=0, max=10_000,
        help="Also simulate N open-loop runs per robot and report how often they stay inside delta(t)."
    ),
    seed: int = typer.Option(0, "--seed", min=0, max=MAX_SEED, help="Seed of the coverage runs (open-loop and closed-loop)."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="Print nothing but errors (files are still written)."),
    trials: int = typer.Option(
        0, "--trials", min=0, max=10_000,
        help="Also run N closed-loop assemblies per noise scale and report how often the true poses lie in the regions the "
             "controller aims at (about 1-3 s each)."
    ),
    scales_text: str = typer.Option("1,2", "--scales", help="Noise scales of the --trials runs (multiples of [noise]), e.g. '1,2'."),
) -> None:
    """Error bounds of the EDR strategy (the paper's App. 3.4): delta(t), C_alpha,i, A_i* and a verdict per robot.

    delta(t) integrates the kinematic error model in closed form (straight runs and clockwise arcs with
    speed v + v_e and turn rate omega + omega_e) over a k-sigma box of the scenario's [noise]: speed and radius
    factors (plus the simulator's per-Drive jitter) and heading drift; the worst case over the box and
    over time. C_alpha,i has radius delta_xy(t_2pi) and half-height delta_theta(t_2pi) (t_theta =
    theta / omega_hat, slowest turn), plus the camera's error. D_n's timed forward projection covers its
    uncorrected straight run for the t_4pi D_{n-1} may need. A_i* is the set of poses from which fine
    motion plus compliance (+-45 deg sticking cone; |alpha| < 60 deg, |w_y| < 80 um for G_1) reaches the
    slot with the whole cylinder, outside C_O; a robot is "guaranteed" when A_i* is not empty. Writes
    DIR/bounds.json and DIR/bounds.png (delta curves, A_i*, the reachable cones of S_2f and S_3f).

    With --trials N it also describes the closed-loop controller as it runs: the regions it aims at (the
    approach funnel where gross motion ends; the straight-in aim and the docking capture region G_i* at the
    start of each final straight approach; the G_1 rendezvous region when the pair departs) and, over N
    simulated assemblies per noise scale, how often the true pose lies in each (Wilson 95 % interval),
    next to the seed's A_i* verdict. Adds "controller_coverage" to bounds.json and writes DIR/coverage.png
    and DIR/coverage.html (the regions over the structure with the Monte Carlo moments).

    Examples: `stressbots bounds examples/four-robots.toml --out out/bounds`;
    `stressbots bounds SCENARIO --k 2 --critical --coverage-trials 200 --json`;
    `stressbots bounds SCENARIO --trials 50 --scales 1,2 --out out/bounds`.
    """
    from .montecarlo import parse_sweep
    from .outputs import prepare_dir, save_figure, to_json, write_json
    from .viz import plot_bounds

    k = _finite_nonneg(k, "--k")
    if k > MAX_K:
        raise StressbotsError(f"must be in [0, {MAX_K:g}] standard deviations, got {k:g}", source="--k")
    noise_scales = parse_sweep(scales_text, option="--scales")
    scn = scenario_arg(scenario, moving=True)
    _check_structure_in_arena(scn, str(scenario))
    folder = None
    if out_dir is not None:
        folder = prepare_dir(out_dir, inputs=[scenario], files=("bounds.json", "bounds.png", "coverage.png", "coverage.html"))
    show = not (quiet or as_json)
    report, scales, plan = _analyse_bounds(scn, k, critical, trials, show)
    if coverage_trials:
        report = report.with_coverage(_open_loop_coverage(scn, coverage_trials, seed, k, show))
    ctl = _controller_coverage(scn, report, plan, trials, seed, noise_scales, show) if trials else None
    doc = report.to_dict()
    if scales is not None:
        doc["critical_noise_scale"] = scales
    if ctl is not None:
        doc["controller_coverage"] = ctl.to_dict()
    if folder is not None:
        write_json(folder / "bounds.json", doc)
        save_figure(plot_bounds(scn, report), folder / "bounds.png")
        _write_coverage_files(scn, ctl, folder)
    if as_json:
        sys.stdout.write(to_json(doc))
    elif not quiet:
        _print_bounds(scn, report, scales, ctl, folder)


def _analyse_bounds(scn, k: float, critical: bool, trials: int, show: bool):
    """``(report, critical scales or None, nominal plan or None)`` of ``bounds``, with a spinner on the terminal.

    With closed-loop ``trials`` the nominal plan they will follow is made first, and the bounds are computed
    on its structure, so that both describe the same assembly.
    """
    from .bounds import analyse_bounds, critical_noise_scales

    with err.status("computing bounds...", spinner="dots") if show else _nullcontext() as status:
        say = (lambda m: status.update(f"{m}...")) if show else None
        plan = _shared_plan(scn) if trials else None
        report = analyse_bounds(scn, k=k, progress=say, structure=None if plan is None else plan.structure)
        scales = critical_noise_scales(scn, k=k, structure=report.structure, progress=say) if critical else None
    return report, scales, plan


def _open_loop_coverage(scn, trials: int, seed: int, k: float, show: bool):
    """``bounds --coverage-trials``: open-loop runs per robot checked against delta(t), with a progress bar."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from .bounds import empirical_coverage

    with Progress(TextColumn("coverage"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), console=err,
                  disable=not show, transient=True) as bar:
        task = bar.add_task("coverage", total=trials * scn.n)
        return empirical_coverage(scn, trials=trials, seed=seed, k=k, progress=lambda d, _total: bar.update(task, completed=d))


def _print_bounds(scn, report, scales, ctl, folder: Path | None) -> None:
    """``bounds`` on the terminal: the error box, the per-robot table and verdicts, D_n's projection, the
    growth between measurements, the coverages and the files written."""
    import math

    m = report.model
    out.print(
        f"[bold]{scn.name}[/bold]: {m.k:g}-sigma error box: speed +-{100 * m.speed_rel:.1f} %, radius +-{100 * m.radius_rel:.1f} %, "
        f"drift bias +-{math.degrees(m.drift_rad_per_um) * 1000:.3g} deg/mm plus random walk "
        f"+-{math.degrees(m.drift_walk_rad_per_sqrt_um) * math.sqrt(1000.0):.3g} deg/sqrt(mm); camera {m.camera_position_um:.3g} um / "
        f"{math.degrees(m.camera_heading_rad):.3g} deg",
        highlight=False,
        soft_wrap=True,
    )
    out.print(_bounds_table(report, scales))
    for rb in report.robots:
        out.print(f"{rb.label}: {rb.reason}", highlight=False, soft_wrap=True)
    p = report.projection
    out.print(
        f"timed forward projection of D_n ({p.robot}) over t_4pi = {p.t_4pi_s:.1f} s of {p.partner} ({p.straight_um:.0f} um straight): "
        f"radius {p.radius_um:.0f} um (across {p.across_um:.0f} um), heading +-{math.degrees(p.heading_rad):.1f} deg "
        f"(self-alignment needs |w_y| < 80 um, |alpha| < 60 deg)",
        highlight=False,
        soft_wrap=True,
    )
    worst = max(report.robots, key=lambda rb: rb.delta_replan[0])
    out.print(
        f"between two measurements (t_x = {worst.replan_interval_s:g} s) the error grows by at most {worst.delta_replan[0]:.3g} um "
        f"and {math.degrees(worst.delta_replan[1]):.3g} deg ({worst.label}): what the closed loop corrects at each measurement",
        highlight=False,
        soft_wrap=True,
    )
    if report.coverage is not None:
        c = report.coverage
        out.print(
            f"empirical coverage: {100 * c.fraction:.2f} % of {c.checkpoints} simulated checkpoints inside delta(t) "
            f"({100 * c.end_fraction:.2f} % of sequence ends; error/bound median {c.ratio_p50:.2f}, max {c.ratio_max:.2f})",
            highlight=False,
            soft_wrap=True,
        )
    if ctl is not None:
        out.print(_coverage_table(ctl))
        out.print("moments: funnel when gross motion ends; straight-in and capture (G_i*) at the start of the final straight "
                  "approach; rendezvous when the G_1 pair departs", highlight=False, soft_wrap=True)
    for note in report.notes:
        out.print(f"note: {note}", highlight=False, soft_wrap=True)
    if folder is not None:
        more = f", {folder / 'coverage.png'}, {folder / 'coverage.html'}" if ctl is not None else ""
        out.print(f"wrote {folder / 'bounds.json'}, {folder / 'bounds.png'}{more}", highlight=False, soft_wrap=True)

def _shared_plan(scn):
    """The nominal plan the closed-loop trials follow, when the bounds would resolve their structure from it
    (a named shape and start poses); else None."""
    from .control import nominal_plan
    from .errors import PlanningError

    if scn.structure is None or not scn.has_starts:
        return None
    try:
        return nominal_plan(scn)
    except PlanningError:
        return None


def _controller_coverage(scn, report, plan, trials: int, seed: int, noise_scales, show: bool):
    """`bounds --trials`: the controller's regions and their Monte Carlo coverage, with a progress bar."""
    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TextColumn, TimeRemainingColumn

    from .coverage import controller_coverage

    verdicts = {rb.name: "yes" if rb.guaranteed else "no" for rb in report.robots}
    with Progress(TextColumn("closed-loop trials"), BarColumn(), MofNCompleteColumn(), TimeRemainingColumn(), console=err,
                  disable=not show, transient=True) as bar:
        task = bar.add_task("trials", total=trials * len(noise_scales))
        return controller_coverage(scn, trials=trials, seed=seed, scales=noise_scales, verdicts=verdicts, plan=plan,
                                   progress=lambda d, _total: bar.update(task, completed=d))


def _write_coverage_files(scn, ctl, folder: Path) -> None:
    """DIR/coverage.png and DIR/coverage.html of `bounds --trials` (nothing without trials)."""
    from .outputs import figure_bytes, write_bytes, write_text
    from .report import coverage_page
    from .viz import plot_controller_coverage

    if ctl is None:
        return
    png = figure_bytes(plot_controller_coverage(scn, ctl))
    write_bytes(folder / "coverage.png", png)
    write_text(folder / "coverage.html", coverage_page(ctl.to_dict(), png, title=f"stressbots bounds: {scn.name}"))


def _coverage_table(ctl):
    """The table of `bounds --trials`: region, its size, coverage with its Wilson interval, the seed's verdict."""
    from rich import box
    from rich.table import Table

    succ = ", ".join(f"{s}/{ctl.trials} at {x:g}x" for x, s in zip(ctl.scales, ctl.successes, strict=True))
    t = Table(title=f"the controller's regions: true pose inside at the moment it commits ({ctl.trials} trials per noise scale; "
                    f"assembled {succ})",
              caption="seed A*: the seed's verdict (guaranteed?)", box=box.SIMPLE_HEAD, pad_edge=False)
    for col in ("region", "robot", "size", "noise", "inside", "95% CI", "seed A*"):
        t.add_column(col, justify="left" if col in ("region", "robot", "size", "seed A*") else "right", no_wrap=col != "size",
                     min_width=14 if col == "size" else None)
    for r in ctl.regions:
        t.add_row(r.region, r.robot, r.size, f"{r.scale:g}x", f"{r.inside}/{r.samples} {100 * r.fraction:.0f}%",
                  f"{100 * r.low:.0f}-{100 * r.high:.0f}%", r.seed_verdict)
    return t


def _bounds_table(report, scales: dict[str, float] | None):
    """The per-robot table of `stressbots bounds` (with a critical-noise column when ``scales`` is given)."""
    import math

    from rich.table import Table

    t = Table(caption="r_a, h_a: C_alpha,i; pair: G_1; critical: largest multiple of \\[noise] still guaranteed" if scales else
              "r_a, h_a: the cylinder C_alpha,i; pair: the G_1 robots")
    for col in ("robot", "role", "t_2pi s", "r_a um", "h_a deg", "A* mm2", "guaranteed"):
        t.add_column(col, justify="left" if col in ("robot", "role", "guaranteed") else "right", no_wrap=True)
    if scales is not None:
        t.add_column("critical", justify="right", no_wrap=True)
    for rb in report.robots:
        area = "-" if rb.region is None else f"{rb.region.area_um2 / 1e6:.3g}"
        row = [rb.label, rb.role, f"{rb.t_2pi_s:.1f}", f"{rb.cylinder.radius_um:.0f}",
               f"{math.degrees(rb.cylinder.height_rad):.1f}", area, "yes" if rb.guaranteed else "no"]
        if scales is not None:
            row.append(f"{scales[rb.name]:.3g}")
        t.add_row(*row)
    return t


@app.command()
def montecarlo(
    scenario: Path = typer.Argument(..., help="Scenario file (TOML): robots, start poses, target and [noise].", show_default=False),
    trials: int = typer.Option(100, "--trials", min=1, max=10_000, help="Closed-loop trials (at each noise scale)."),
    seed: int = typer.Option(0, "--seed", min=0, max=MAX_SEED, help="Study seed: trial i uses SeedSequence(seed).spawn(trials)[i]."),
    out_dir: Path = typer.Option(..., "--out", help="Folder for summary.json, montecarlo.png (and sweep.png).", show_default=False),
    workers: int | None = _workers_option(),
    sweep: str | None = typer.Option(None, "--sweep", show_default=False,
                                     help="Also run at these multiples of the scenario's [noise], e.g. '0,0.5,1,1.5,2'."),
    time_budget_s: float | None = typer.Option(None, "--time-budget-s", show_default=False,
                                               help="Simulated time budget per trial (s); default the controller's."),
    as_json: bool = typer.Option(False, "--json", help="Print only summary.json on stdout."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar, print nothing but errors."),
    resume: bool = _resume_option(),
    overwrite: bool = _overwrite_option(),
    dask: str | None = _dask_option(),
    strategy: StrategyChoice = _strategy_option(),
) -> None:
    """Run N independent closed-loop assemblies on the simulated plant and summarise them.

    Every trial builds a SimulatedPlant with its own seed and lets the controller assemble the
    structure, following one nominal plan computed once. The same seed gives the same numbers whatever
    the number of workers. Writes DIR/summary.json (trials, successes, success_rate, its 95 % Wilson
    interval, percentiles of the shape error, placement error and duration, failure reasons with the
    failed trials' seeds, seeds and provenance) and DIR/montecarlo.png; with --sweep also the success
    rate against the noise scale (summary "sweep" and DIR/sweep.png).

    Every finished trial is committed to DIR/trials.sqlite as it finishes and the summary is
    computed from it; DIR/trials.csv is written at the end. Ctrl-C (or kill) keeps the finished trials:
    run the same command with --resume to run only the missing ones (exit status 130 after an
    interrupt). --dask runs the trials on a Dask cluster with the same per-trial outcomes.

    Examples: `stressbots montecarlo examples/four-robots.toml --trials 100 --seed 1 --out out/mc`;
    `stressbots montecarlo SCENARIO --trials 50 --seed 0 --out out/sweep --sweep 0,0.5,1,1.5,2`;
    `stressbots montecarlo SCENARIO --trials 5000 --out out/big --dask tcp://scheduler:8786 --resume`.
    """
    from . import montecarlo as mc
    from .outputs import prepare_dir, save_figure, to_json, write_json
    from .pipeline import finite_budget
    from .viz import plot_montecarlo, plot_sweep

    factors = mc.parse_sweep(sweep) if sweep is not None else None
    finite_budget(time_budget_s)
    scn = scenario_arg(scenario, moving=True)
    folder = prepare_dir(out_dir, inputs=[scenario], files=("summary.json", "montecarlo.png", "sweep.png", "trials.sqlite", "trials.csv"))
    if resume and overwrite:
        raise StressbotsError("choose one of --resume and --overwrite", source="--resume")
    assemble = mc.default_assemble()
    show = not (quiet or as_json)
    with err.status("planning the nominal assembly...", spinner="dots") if show else _nullcontext():
        with _attributed(str(scenario)):
            plan = mc.default_planner()(scn)

    def run_with_progress():
        with _campaign_progress(show) as progress:
            return mc.run_study(
                scn, trials, seed, workers=workers, sweep=factors, assemble=assemble, plan=plan, time_budget_s=time_budget_s,
                progress=progress, source=str(scenario),
                store=folder / "trials.sqlite", resume=resume, overwrite=overwrite, dask=dask, strategy=strategy.value,
            )

    study = _campaign_interrupt_guard(run_with_progress)
    s = study.summary
    _write_trials_csv(folder)
    write_json(folder / "summary.json", s)
    save_figure(plot_montecarlo(s, study.main), folder / "montecarlo.png")
    if factors:
        save_figure(plot_sweep(s["sweep"], title=f"{scn.name}: success rate vs noise ({trials} trials per point, seed {seed})"),
                    folder / "sweep.png")
    if as_json:
        sys.stdout.write(to_json(s))
    elif not quiet:
        _print_montecarlo(scn.name, s, seed, bool(factors), folder)


def _montecarlo_percentiles(block: dict, unit: str) -> str:
    """``p50 .., p90 .., p95 .., max .. unit`` of a summary's percentile block, ``-`` when it is empty."""
    if block["n"] == 0:
        return "-"
    return f"p50 {block['p50']:.3g}, p90 {block['p90']:.3g}, p95 {block['p95']:.3g}, max {block['max']:.3g} {unit}"


def _print_montecarlo(name: str, s: dict, seed: int, swept: bool, folder: Path) -> None:
    """``montecarlo`` on the terminal: the success rate with its interval, error and duration percentiles,
    failure reasons with seeds to rerun, the noise sweep and the files written."""
    lo, hi = s["success_rate_ci95"]
    pct = _montecarlo_percentiles
    line = lambda text: out.print(text, highlight=False, soft_wrap=True)  # noqa: E731
    line(f"[bold]{name}[/bold]: {s['successes']}/{s['trials']} successes, rate {s['success_rate']:.3f} (95 % CI {lo:.3f}-{hi:.3f}), "
         f"seed {seed}, {s['run']['workers']} workers, {s['run']['wall_s']:.1f} s")
    if s["run"]["resumed_with"]:
        line(f"resumed: {s['run']['resumed_with']} trials were in the store, {s['run']['trials_run']} run now")
    line(f"shape error RMS: {pct(s['shape_error_rms_um'], 'um')}")
    line(f"placement error (largest per trial): {pct(s['placement_error_um'], 'um')}")
    line(f"duration (simulated): {pct(s['duration_s'], 's')}")
    for kind, count in s["failures"].items():
        line(f"failure x{count}: {kind}")
    if s["failed_trials"]:
        seeds = ", ".join(str(f["seed"]) for f in s["failed_trials"][:5])
        line(f"failed trials' seeds (rerun with `stressbots simulate --seed`): {seeds}{', ...' if len(s['failed_trials']) > 5 else ''}")
    if swept:
        out.print(_sweep_table(s["sweep"]))
    files = ["summary.json", "montecarlo.png"] + (["sweep.png"] if swept else []) + ["trials.sqlite", "trials.csv"]
    line("wrote " + ", ".join(str(folder / f) for f in files))


def _sweep_table(rows: list[dict]):
    """The noise sweep of ``montecarlo --sweep``: successes, rate, interval and median shape error per scale."""
    from rich.table import Table

    t = Table(title="noise sweep")
    for col in ("noise scale", "successes", "rate", "95 % CI", "shape error p50 (um)"):
        t.add_column(col, justify="right")
    for row in rows:
        p50 = row["shape_error_rms_um"]["p50"]
        t.add_row(f"{row['noise_scale']:g}", f"{row['successes']}/{row['trials']}", f"{row['success_rate']:.3f}",
                  f"{row['success_rate_ci95'][0]:.3f}-{row['success_rate_ci95'][1]:.3f}", "-" if p50 is None else f"{p50:.3g}")
    return t


# ----------------------------------------------------------------------------------------------------
# campaigns: interruption, export (SPEC 10)


from contextlib import contextmanager as _contextmanager  # noqa: E402 - kept with the campaign block


@_contextmanager
def _campaign_progress(show: bool, label: str = "trials"):
    """A progress bar with ETA for a campaign; it appears at the first report (after the store is
    checked, so a refusal prints only its error line). No refresh thread: workers may be forked."""
    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    bar = Progress(TextColumn(label), BarColumn(), MofNCompleteColumn(), TimeElapsedColumn(), TimeRemainingColumn(),
                   console=err, disable=not show, auto_refresh=False, transient=False)
    state: dict = {}

    def report(done: int, total: int) -> None:
        if "task" not in state:
            bar.start()
            state["task"] = bar.add_task(label, total=total, completed=done)
        bar.update(state["task"], completed=done, total=total, refresh=True)
        if done >= total:
            bar.stop()  # done: make room for the next bar (planning, then trials)

    try:
        yield report
    finally:
        if "task" in state:
            bar.stop()


def _campaign_interrupt_guard(run):
    """Run a campaign; on Ctrl-C / SIGTERM say what was kept and how to go on, exit status 130."""
    from .campaign import CampaignInterrupted

    try:
        return run()
    except CampaignInterrupted as exc:
        print("error: interrupted", file=sys.stderr)
        where = f" in {exc.path}" if exc.path is not None else ""
        print(f"{exc.kept} of {exc.total} trials are kept{where}; run the same command with --resume to finish", file=sys.stderr)
        raise typer.Exit(130) from None


def _write_trials_csv(folder: Path) -> Path:
    from .outputs import write_text
    from .store import csv_text, read_rows, read_settings

    path = folder / "trials.sqlite"
    return write_text(folder / "trials.csv", csv_text(read_rows(path), read_settings(path)["cells"]))


@app.command()
def export(
    store_dir: Path = typer.Argument(..., metavar="DIR", help="A campaign's folder (or its trials.sqlite).", show_default=False),
    fmt: str = typer.Option("csv", "--format", help="csv, or parquet (needs pyarrow)."),
    out_file: Path | None = typer.Option(None, "--out", help="File to write (default DIR/trials.csv or DIR/trials.parquet).",
                                         show_default=False),
) -> None:
    """Export a campaign's trial store (finished, interrupted or still running) for pandas & co.

    One row per stored trial: trial, cell, cell_trial, seed, noise_scale, success, failure,
    shape_error_um, placement_error_um, heading_error_deg, duration_s (simulated), replans, docked,
    robots, error, wall_s, worker, finished_utc, cell_label.

    Example: `stressbots export out/mc --format parquet`, then `pandas.read_parquet("out/mc/trials.parquet")`.
    """
    from .outputs import check_not_input, write_text
    from .store import STORE_NAME, csv_text, read_rows, read_settings, write_parquet

    if fmt not in ("csv", "parquet"):
        raise StressbotsError(f"must be csv or parquet, got {fmt!r}", source="--format")
    db = store_dir / STORE_NAME if store_dir.is_dir() else store_dir
    rows, cells = read_rows(db), read_settings(db)["cells"]
    target = out_file or db.with_name(f"trials.{fmt}")
    check_not_input(target, [db], option="--out")
    if fmt == "csv":
        write_text(target, csv_text(rows, cells))
    else:
        write_parquet(rows, cells, target)
    err.print(f"wrote {target} ({len(rows)} trials)", highlight=False, soft_wrap=True)


@app.command()
def study(
    study_file: Path = typer.Argument(..., metavar="STUDY.toml",
                                      help="Study file: layouts, [grid], [fixed], trials, seed (see examples/).", show_default=False),
    out_dir: Path = typer.Option(..., "--out", help="Folder for trials.sqlite, trials.csv, summary.json and report.html.",
                                 show_default=False),
    workers: int | None = _workers_option(),
    resume: bool = _resume_option(),
    overwrite: bool = _overwrite_option(),
    dask: str | None = _dask_option(),
    as_json: bool = typer.Option(False, "--json", help="Print only summary.json on stdout."),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar, print nothing but errors."),
) -> None:
    """Run a study: a grid of conditions x a set of layouts, N paired closed-loop trials per cell.

    The grid may vary any scenario, noise or control parameter (noise.speed_rel_sd, noise.scale,
    control.replan_interval_s, robots.speed_um_s, ...), any controller option (controller.clearance_um,
    ... : fields of stressbots.edr.ControllerOptions) and the controller strategy. Trial k of every cell
    uses the same plant seed, so cells are compared on the same draws. Every trial is committed to
    DIR/trials.sqlite as it finishes (table trials, column cell; table cells) and --resume runs only the
    missing ones. Writes DIR/summary.json (per-cell success rates with Wilson 95 % intervals, failure
    reasons) and DIR/report.html (success-rate curves with confidence bands, failure reasons per cell).

    Example: `stressbots study examples/replanning.study.toml --out out/study`.
    """
    from .outputs import prepare_dir, to_json, write_json, write_text
    from .study import load_study, run_study
    from .studyreport import build_study_report

    if resume and overwrite:
        raise StressbotsError("choose one of --resume and --overwrite", source="--resume")
    spec = load_study(study_file)
    folder = prepare_dir(out_dir, inputs=[study_file, *(lay.source for lay in spec.layouts)],
                         files=("summary.json", "report.html", "trials.sqlite", "trials.csv"))
    show = not (quiet or as_json)

    def run_with_progress():
        with _campaign_progress(show, "plans ") as planning, _campaign_progress(show) as progress:
            return run_study(spec, store=folder / "trials.sqlite", resume=resume, overwrite=overwrite, dask=dask, workers=workers,
                             progress=progress, planning=planning)

    summary, _, _ = _campaign_interrupt_guard(run_with_progress)
    _write_trials_csv(folder)
    write_json(folder / "summary.json", summary)
    write_text(folder / "report.html", build_study_report(summary))
    if as_json:
        sys.stdout.write(to_json(summary))
    elif not quiet:
        _print_study(summary, folder)


def _print_study(summary: dict, folder: Path) -> None:
    """``study`` on the terminal: the overall rate, one row per cell (conditions, successes, interval, most
    common failure) and the files written."""
    from rich.table import Table

    lo, hi = summary["success_rate_ci95"]
    out.print(f"[bold]{summary['name']}[/bold]: {len(summary['cells'])} cells x {summary['trials_per_cell']} paired trials, "
              f"{summary['successes']}/{summary['trials']} successes ({lo:.3f}-{hi:.3f}), {summary['run']['wall_s']:.1f} s",
              highlight=False, soft_wrap=True)
    axes = list(summary["axes"])
    t = Table(title="cells (conditions, successes, Wilson 95 % CI, most common failure)")
    for col in ["cell", "layout", *axes, "ok", "rate", "95 % CI", "top failure"]:
        t.add_column(col, justify="left" if col in ("layout", "top failure") else "right",
                     overflow="ellipsis" if col in ("layout", "top failure") else "fold", no_wrap=col in ("layout", "top failure"))
    for r in summary["cells"]:
        top = next(iter(r["failures"]), "-")
        t.add_row(str(r["cell"]), r["layout"], *(str(r["params"].get(k, "")) for k in axes), f"{r['successes']}/{r['trials']}",
                  f"{r['success_rate']:.2f}", f"{r['success_rate_ci95'][0]:.2f}-{r['success_rate_ci95'][1]:.2f}",
                  top if len(top) <= 40 else top[:39] + "...")
    out.print(t)
    out.print("wrote " + ", ".join(str(folder / f) for f in ("summary.json", "report.html", "trials.sqlite", "trials.csv")),
              highlight=False, soft_wrap=True)


# ----------------------------------------------------------------------------------------------------
# Lab hardware (SPEC 9): awg, track


@app.command()
def awg(
    scenario: Path = typer.Argument(..., help="Scenario file (TOML) giving the robots' voltages, max_V and the drive frequency.",
                                    show_default=False),
    out_file: Path = typer.Option(
        ..., "--out", help="Output file: .arb (33500-series text ARB: header, then one DAC code per line), .csv (t_s,awg_V,electrode_V) "
                           "or .npy (int16 codes).",
        show_default=False,
    ),
    steps: str | None = typer.Option(None, "--steps", help="Primitives and drive durations (s), e.g. 'P1:2.5,P0:1.0'.", show_default=False),
    plan: Path | None = typer.Option(None, "--plan", help="A plan.json (from stressbots plan) instead of --steps.", show_default=False),
    gain: float = typer.Option(20.0, "--gain", help="Voltage gain of the amplifier between generator and electrodes (V/V)."),
    offset_V: float = typer.Option(0.0, "--offset-V", help="Electrode level (V) at generator output 0 V (amplifier offset)."),
    sample_rate_hz: float = typer.Option(100_000.0, "--sample-rate-hz",
                                         help="Generator sample rate (Hz); at least twice the drive frequency."),
    awg_max_V: float = typer.Option(10.0, "--awg-max-V", help="The generator's output limit (V): every level must stay within +-this."),
    name: str = typer.Option("stressbots", "--name", help="Name of the arbitrary waveform in the generator's memory (<= 12 characters)."),
    upload_to: str | None = typer.Option(
        None, "--upload", help="VISA resource of the generator, e.g. TCPIP::192.168.1.5::INSTR: upload over PyVISA ([lab] extra).",
        show_default=False
    ),
    visa_library: str | None = typer.Option(
        None, "--visa-library", help="PyVISA backend, e.g. '@py' (pyvisa-py) or 'awg.yaml@sim' (pyvisa-sim); default PyVISA's.",
        show_default=False
    ),
    ascii_data: bool = typer.Option(False, "--ascii", help="Send the DAC codes as text instead of a binary block (pyvisa-sim needs this)."),
    output_on: bool = typer.Option(False, "--output-on", help="Switch the generator's output on after a clean upload (off by default)."),
) -> None:
    """Compile a waveform for an arbitrary waveform generator (Keysight 33500B class) and export or upload it.

    The electrode level is `V = gain * u + offset_V` for generator output `u` (an amplifier follows the
    generator). The waveform of --steps or --plan is sampled at --sample-rate-hz (a Drive is a square
    wave at the scenario's drive frequency), mapped to `u` and quantised to int16 DAC codes
    (-32767 = VOLT:LOW, +32767 = VOLT:HIGH). Before anything is written or sent it refuses electrode
    levels outside [0, max_V], generator levels outside +-awg_max_V and more points than the generator
    holds (saying how to split the plan). --upload sends the SCPI sequence documented in the README
    ("Running on your hardware") to channel 1 and checks SYST:ERR? after the data and after the settings;
    the output stays off unless --output-on.

    Examples: `stressbots awg examples/four-robots.toml --steps P1:0.5,P0:0.5 --out wf.arb`;
    dry run against the simulated instrument: `stressbots awg examples/four-robots.toml --steps P1:0.5
    --out wf.csv --upload TCPIP::awg.local::INSTR --visa-library examples/awg-sim.yaml@sim --ascii`.
    """
    from .lab.awg import compile_awg, export_program

    sc, _, wf = _waveform_of(scenario, steps, plan, out_file, (".arb", ".csv", ".npy"), "awg")
    prog = compile_awg(wf, sc.electrodes, gain=gain, offset_V=offset_V, sample_rate_hz=sample_rate_hz, awg_max_V=awg_max_V)
    if upload_to is not None:
        _upload_program(prog, upload_to, visa_library, name=name, ascii_data=ascii_data, output_on=output_on)
    export_program(prog, out_file)
    ev = prog.electrode_volts()
    out.print(
        f"wrote {out_file}: {prog.points} points at {prog.sample_rate_hz:g} Hz ({prog.duration_s:g} s); generator "
        f"{prog.u_low:g}..{prog.u_high:g} V (VOLT:LOW/HIGH), electrodes {ev.min():g}..{ev.max():g} V at gain {gain:g}, offset "
        f"{offset_V:g} V",
        highlight=False, soft_wrap=True,
    )
    if upload_to is not None:
        out.print(f"uploaded to {upload_to} as {name!r}; output {'ON' if output_on else 'left off (use --output-on)'}",
                  highlight=False, soft_wrap=True)


@app.command()
def track(
    frames: Path = typer.Argument(..., help="A folder of PNG frames (tracked in name order) or a video file.", show_default=False),
    scenario: Path = typer.Option(..., "--scenario", help="Scenario file (TOML): the robots' names, body sizes and start poses.",
                                  show_default=False),
    um_per_px: float = typer.Option(..., "--um-per-px", help="Camera calibration: micrometres per pixel.", show_default=False),
    origin_px: tuple[float, float] = typer.Option(
        ..., "--origin-px", help="Camera calibration: the pixel (column, row) of the arena origin (x = y = 0).", show_default=False
    ),
    out_file: Path = typer.Option(..., "--out", help="CSV of the poses: frame,name,robot,x_um,y_um,heading_deg (nan: not found).",
                                  show_default=False),
    quiet: bool = typer.Option(False, "--quiet", "-q", help="No progress bar."),
) -> None:
    """Track the robots in camera frames: one pose per robot and frame, identities kept from frame to frame.

    Frames are grey images, rows downward; `x = (col - C) * U`, `y = (R - row) * U` for `--origin-px C R`
    and `--um-per-px U` (see the README, "Running on your hardware"). Each frame is segmented, touching
    robots are split into their known body rectangles, centres and headings are fitted to a fraction of a pixel (the steering arm on the
    robot's right tells front from back) and identities follow the previous frame (the first frame's
    come from the scenario's start poses). Needs the [lab] extra (OpenCV).

    Example: `stressbots track frames/ --scenario examples/four-robots.toml --um-per-px 2 --origin-px 50 1550 --out poses.csv`
    """
    import io

    from .lab.frames import frame_source
    from .outputs import check_not_input, write_text
    from .tracking import Calibration, locate

    sc = scenario_arg(scenario)
    check_not_input(out_file, [scenario, frames])
    if out_file.suffix.lower() != ".csv":
        raise StressbotsError(f"unsupported output {out_file.name!r}: use a .csv file", source="--out")
    try:
        cal = Calibration(um_per_px, origin_px)
    except StressbotsError as exc:
        raise StressbotsError(exc.problem, source="--um-per-px" if exc.field == "um_per_px" else "--origin-px") from None
    count, source = frame_source(frames)
    buf = io.StringIO()
    buf.write("frame,name,robot,x_um,y_um,heading_deg\n")
    previous = sc.starts if sc.has_starts else None
    seen_total, k = 0, 0
    from rich.progress import Progress

    with Progress(console=err, disable=quiet or not err.is_terminal, transient=True) as bar:
        task = bar.add_task("tracking", total=count if count > 0 else None)
        for k, (name, img) in enumerate(source):
            poses = locate(img, sc, cal, previous=previous)
            found = np.all(np.isfinite(poses), axis=1)
            seen_total += int(found.sum())
            for i, robot in enumerate(sc.names):
                x, y, th = poses[i]
                buf.write(f"{k},{name},{robot},{x:.4f},{y:.4f},{np.degrees(th):.4f}\n" if found[i] else f"{k},{name},{robot},nan,nan,nan\n")
            previous = poses if previous is None else np.where(found[:, None], poses, previous)
            bar.advance(task)
    frames_done = k + 1
    write_text(out_file, buf.getvalue())
    if not quiet:
        out.print(f"wrote {out_file}: {frames_done} frames, {seen_total} of {frames_done * sc.n} robot poses found", highlight=False,
                  soft_wrap=True)


def _upload_program(prog, resource: str, visa_library: str | None, *, name: str, ascii_data: bool, output_on: bool) -> None:
    """Open the VISA resource and upload (errors from PyVISA become one ``error:`` line)."""
    from .lab.awg import upload

    try:
        import pyvisa
    except ImportError:
        raise StressbotsError("needs PyVISA: pip install 'stressbots[lab]'", source="--upload") from None
    try:
        rm = pyvisa.ResourceManager(visa_library) if visa_library else pyvisa.ResourceManager()
        inst = rm.open_resource(resource, read_termination="\n", write_termination="\n")
    except Exception as exc:  # noqa: BLE001 - any failure to open is the user's resource or library
        raise StressbotsError(f"cannot open {resource!r}{f' with {visa_library!r}' if visa_library else ''}: "
                              f"{_one_line(exc)}", source="--upload") from None
    try:
        inst.timeout = 60_000  # ms: large waveforms take a while
        upload(prog, inst, name=name, ascii=ascii_data, output_on=output_on)
    except StressbotsError as exc:
        if exc.source is None and exc.field is None:
            exc.source = f"--upload {resource}"
        raise
    except Exception as exc:  # noqa: BLE001 - an I/O failure on the bus, reported in one line
        raise StressbotsError(f"upload failed: {_one_line(exc)}", source="--upload") from None
    finally:
        inst.close()
        rm.close()


def _one_line(exc: BaseException) -> str:
    """An exception's message on one line; of an embedded traceback only the text before it and its last line."""
    text = str(exc).replace("\\n", "\n")
    if "Traceback" in text:
        before, _, tb = text.partition("Traceback")
        last = [ln for ln in tb.splitlines() if ln.strip(" '\"")][-1:]
        text = before.rstrip(" '\"") + " " + " ".join(last)
    return " ".join(text.split()).strip(" '\"") or type(exc).__name__


def _click_base(name: str) -> Any:
    """The click exception class ``name`` as used by this Typer (newer Typers vendor their own click)."""
    for cls in typer.BadParameter.__mro__:
        if cls.__name__ == name:
            return cls
    raise RuntimeError(f"typer has no {name}")  # pragma: no cover


_UsageError = _click_base("UsageError")
_ClickException = _click_base("ClickException")


def main(argv: list[str] | None = None) -> None:
    """Console-script entry point: run the CLI, mapping every failure to one ``error:`` line.

    Exit status: 0 done, 1 internal error (a bug: ``error: internal error: ...``; set
    ``STRESSBOTS_DEBUG=1`` for the traceback), 2 bad input, 130 interrupted (files already written stay,
    none is left half-written). Warnings of the numerical libraries are not shown (one line per error).
    """
    import os
    import warnings

    command = _plain_flags(typer.main.get_command(app))
    args = sys.argv[1:] if argv is None else list(argv)
    try:
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore")
            code = command.main(args=args, prog_name="stressbots", standalone_mode=False)
    except StressbotsError as exc:
        _fail(exc.message, 2)
    except _UsageError as exc:
        if type(exc).__name__ == "NoArgsIsHelpError":  # bare `stressbots`: Typer has shown the help
            sys.exit(0)
        msg = " ".join(exc.format_message().split())
        where = f"stressbots {exc.ctx.info_name}" if exc.ctx is not None and exc.ctx.parent is not None else "stressbots"
        _fail(f"{msg} (see '{where} --help')", 2)
    except _ClickException as exc:
        _fail(" ".join(exc.format_message().split()), 2)
    except (typer.Abort, KeyboardInterrupt):
        _fail("interrupted", 130)
    except BrokenPipeError:  # e.g. `stressbots states x.toml | head`
        sys.exit(0)
    except typer.Exit as exc:  # pragma: no cover - Typer raises it only in standalone mode
        sys.exit(exc.exit_code)
    except MemoryError:
        _fail("out of memory: the problem is too large for this machine (fewer robots or a smaller arena)", 2)
    except Exception as exc:  # noqa: BLE001 - a bug: one line, exit 1, the traceback on request
        if os.environ.get("STRESSBOTS_DEBUG"):
            raise
        _fail(f"internal error: {type(exc).__name__}: {exc} (please report it; STRESSBOTS_DEBUG=1 shows the traceback)", 1)
    if code == 130:  # Typer turns Ctrl-C into exit status 130
        _fail("interrupted", 130)
    if isinstance(code, int) and code != 0:
        sys.exit(code)


def _plain_flags(command):
    """Show on/off options (``--json``, ``-q``, ``--help``) as plain flags in ``--help``: Typer would print a
    ``<bool>`` type beside them, suggesting a value (``--json true``) that the flag does not take."""

    def fix(cmd) -> None:
        for p in getattr(cmd, "params", ()):
            if getattr(p, "is_flag", False) and not getattr(p, "count", False):
                p.metavar = ""
        for sub in getattr(cmd, "commands", {}).values():
            fix(sub)

    fix(command)
    # --help is made on demand by each command class: make it plain too (once per class).
    for cls in {type(command), *(type(c) for c in getattr(command, "commands", {}).values())}:
        if cls.__dict__.get("_stressbots_plain_help"):
            continue
        original = cls.get_help_option

        def get_help_option(self, ctx, _original=original):
            opt = _original(self, ctx)
            if opt is not None:
                opt.metavar = ""
            return opt

        cls.get_help_option = get_help_option
        cls._stressbots_plain_help = True
    return command


def _fail(message: str, status: int) -> None:
    """Print ``error: MESSAGE`` as exactly one line on stderr and exit with ``status``."""
    text = " ".join(str(message).split())
    if not text.isprintable():
        text = text.encode("unicode_escape").decode("ascii")
    try:
        print(f"error: {text}", file=sys.stderr)
    finally:
        sys.exit(status)
