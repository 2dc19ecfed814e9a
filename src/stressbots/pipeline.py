"""The main job (``stressbots run`` and ``stressbots demo``): from a scenario to a report.

1. **validate**: the scenario is loaded and checked by :func:`stressbots.scenario.load` (the caller);
2. **analyse** the voltage design (:func:`stressbots.electrostatics.analyse_scenario`);
3. **plan** the assembly the controller will follow (:func:`stressbots.control.nominal_plan`) and turn
   it into the voltage waveform of the whole plan (:func:`stressbots.sim.plan_waveform`);
4. **closed loop**: :func:`stressbots.control.assemble` drives a :class:`stressbots.sim.SimulatedPlant`
   (``record=True`` for the pictures) through the Plant protocol only;
5. **write** ``report.html`` (:mod:`stressbots.report`) and beside it ``result.json``, ``plan.json``,
   ``states.json``, ``waveform.json`` / ``waveform.npy`` and the pictures.

A run that does not assemble is still a finished job: it gets the same files, with the controller's
failure reason and the event log. Only bad input (a :class:`~stressbots.errors.StressbotsError`) stops
the job. An unexpected exception inside the controller is reported as the run's failure (with its
traceback in ``result.json``), as the Monte Carlo runner does, so the report still shows how far the
robots got.
"""

from __future__ import annotations

import math
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .errors import StressbotsError

__all__ = ["OUTPUT_FILES", "ClosedLoop", "JobResult", "closed_loop", "result_document", "merged_events", "run_job"]

#: Sample rate of the sampled waveform excerpt (Hz) and its length (s).
RATE_HZ = 100_000.0
EXCERPT_S = 1.0

#: Files the job writes into its folder, with what they hold.
OUTPUT_FILES: tuple[tuple[str, str], ...] = (
    ("report.html", "this report: one self-contained page"),
    ("result.json", "the closed-loop run: success, seed, per-robot final/goal poses, errors, docked flags, shape error, events"),
    ("plan.json", "the nominal plan the controller followed (stressbots.plan/1)"),
    ("states.json", "the voltage analysis, as `stressbots states --json`"),
    ("waveform.json", "the whole plan's voltage waveform as Hold/Drive segments"),
    ("waveform.npy", f"the first {EXCERPT_S:g} s of that waveform sampled at {RATE_HZ / 1000:g} kS/s, columns time (s), level (V)"),
    ("waveform.png", "picture of the plan's waveform"),
    ("plan.png", "picture of the nominal plan"),
    ("run.png", "picture of the closed-loop trajectories and contact events"),
    ("structure.png", "picture of the final structure against the target"),
)


# ----------------------------------------------------------------------------------------------------
# The closed-loop run


class _WatchedPlant:
    """The simulator behind the Plant protocol, telling a callback the simulated time after each apply.

    Only ``observe`` and ``apply`` are the protocol; ``true_poses`` is forwarded because
    :func:`stressbots.control.assemble` reports the true final pose of a plant that offers it.
    """

    def __init__(self, plant, on_time: Callable[[float], None] | None):
        self._plant = plant
        self._on_time = on_time

    def observe(self) -> np.ndarray:
        return self._plant.observe()

    def apply(self, waveform) -> None:
        self._plant.apply(waveform)
        if self._on_time is not None:
            self._on_time(self._plant.time_s)

    def true_poses(self) -> np.ndarray:
        return self._plant.true_poses()


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """A closed-loop run on the simulator: the controller's result, the plant (truth, trace, events)."""

    result: Any  # stressbots.control.AssemblyResult
    plant: Any  # stressbots.sim.SimulatedPlant
    wall_s: float
    time_budget_s: float | None
    error: str | None = None  # traceback of an exception the controller raised
    camera: str = "poses"  # "images": the controller saw rendered frames through the tracker
    frames: tuple = ()  # with camera "images": a few stressbots.lab.plants.TrackedFrame for the report
    camera_info: dict = field(default_factory=dict)  # with camera "images": calibration, image model, frames observed


def default_time_budget_s() -> float | None:
    """The controller's default simulated time budget (s), if it declares one."""
    try:
        from .control import ControllerOptions

        return float(ControllerOptions().time_budget_s)
    except (ImportError, AttributeError, TypeError):  # pragma: no cover - depends on the controller
        return None


def plan_for(scenario, source: str | None = None):
    """The nominal plan the controller follows (:func:`stressbots.control.nominal_plan`); a planning
    error that names no file is attributed to ``source``."""
    from .control import nominal_plan

    try:
        return nominal_plan(scenario)
    except StressbotsError as exc:
        if exc.source is None and source:
            exc.source = source
        raise


def closed_loop(scenario, plan_result, *, seed: int, time_budget_s: float | None = None,
                on_time: Callable[[float], None] | None = None, camera: str = "poses") -> ClosedLoop:
    """Run :func:`stressbots.control.assemble` on a recording :class:`~stressbots.sim.SimulatedPlant`.

    ``camera="images"`` puts the image in the loop: the controller observes the plant through rendered
    frames and the tracker (:class:`stressbots.lab.SyntheticLab`, needs the ``[lab]`` extra)."""
    from .control import assemble
    from .sim import SimulatedPlant

    plant = SimulatedPlant(scenario, seed=seed, record=True)
    observed = plant
    if camera == "images":
        observed = _image_lab(scenario, plant, seed)
    kwargs: dict[str, Any] = {"seed": seed, "plan": plan_result}
    if time_budget_s is not None:
        kwargs["time_budget_s"] = float(time_budget_s)
    t0 = time.perf_counter()
    try:
        res = assemble(scenario, _WatchedPlant(observed, on_time), **kwargs)
        error = None
    except StressbotsError:
        raise
    except Exception as exc:  # noqa: BLE001 - a controller crash is the run's outcome; the report shows it
        error = traceback.format_exc()
        res = _crashed_result(scenario, plant, plan_result, seed, f"controller error: {type(exc).__name__}: {exc}")
    frames = tuple(observed.frames) if observed is not plant else ()
    info = observed.describe() if observed is not plant else {}
    return ClosedLoop(res, plant, time.perf_counter() - t0, time_budget_s, error, camera, frames, info)


#: Frames of an image-in-the-loop run kept for the report.
REPORT_FRAMES = 4


def _image_lab(scenario, plant, seed: int):
    """The simulated plant seen through rendered frames (:class:`stressbots.lab.SyntheticLab`)."""
    try:
        import cv2  # noqa: F401
    except ImportError:
        raise StressbotsError("needs OpenCV for tracking: pip install 'stressbots[lab]'", source="--camera images") from None
    from .lab import SyntheticLab

    return SyntheticLab(scenario, seed=seed, plant=plant, keep_frames=REPORT_FRAMES)


def _crashed_result(scenario, plant, plan_result, seed, reason: str):
    """An AssemblyResult for a run whose controller raised: the plant's truth, nothing docked by the controller."""
    from .assessment import placement_errors, shape_error
    from .control import AssemblyResult

    final = plant.true_poses()
    goals = plan_result.plan.goal_array()
    shape = shape_error(final, goals, scenario.lengths_um, scenario.widths_um)
    pos, head = placement_errors(final, goals)
    return AssemblyResult(
        success=False, seed=seed, names=scenario.names, final_true=final, final_observed=final.copy(), goals=goals,
        nominal_goals=goals.copy(), docked=plant.docked, shape_error_rms_um=shape.rms_um, shape_rotation_deg=shape.rotation_deg,
        placement_error_um=pos, heading_error_deg=head, duration_s=plant.time_s, replans=0,
        events=({"t_s": round(plant.time_s, 3), "kind": "error", "robot": None, "detail": reason},), failure=reason,
    )


def merged_events(result, plant) -> list[dict[str, Any]]:
    """The controller's and the plant's events in one list by time: ``t_s``, ``source``, ``robot``, ``kind``,
    ``detail`` (and ``other`` for contacts)."""
    rows = []
    for k, ev in enumerate(result.events):
        rows.append((float(ev.get("t_s", 0.0) or 0.0), 1, k, {"t_s": ev.get("t_s"), "source": "controller", "robot": ev.get("robot"),
                                                             "kind": ev.get("kind"), "detail": ev.get("detail", "")}))
    for k, ev in enumerate(plant.events):
        rows.append((float(ev.time_s), 0, k, {"t_s": round(float(ev.time_s), 3), "source": "plant", "robot": ev.robot, "kind": ev.kind,
                                              "other": ev.other, "detail": ev.detail}))
    rows.sort(key=lambda r: r[:3])
    out = [r[3] for r in rows]
    t_end = round(float(result.duration_s), 3)
    if result.success:
        out.append({"t_s": t_end, "source": "controller", "robot": None, "kind": "outcome", "detail": "assembled"})
    else:
        out.append({"t_s": t_end, "source": "controller", "robot": None, "kind": "outcome",
                    "detail": f"stopped: {result.failure or 'not assembled'}"})
    return out


def result_document(scenario, run: ClosedLoop, *, source: str | None = None, extra: dict[str, Any] | None = None) -> dict[str, Any]:
    """``result.json`` of a closed-loop run: the controller's :meth:`AssemblyResult.to_dict` (SPEC 7 keys
    first), then the plant's side (noise, hidden factors, contact events), timing and provenance."""
    from .outputs import provenance

    doc = dict(run.result.to_dict())
    plant = run.plant
    more: dict[str, Any] = {
        "mode": "closed-loop",
        "scenario": source,
        "noise": scenario.noise.to_file_units(),
        "time_budget_s": run.time_budget_s,
        "shape_tol_um": _shape_tol(),
        "plant": {
            "speed_factors": dict(zip(scenario.names, plant.speed_factors.tolist())),
            "radius_factors": dict(zip(scenario.names, plant.radius_factors.tolist())),
            "docked": dict(zip(scenario.names, plant.docked.tolist())),
            "stuck": dict(zip(scenario.names, plant.stuck.tolist())),
            "time_s": plant.time_s,
        },
        "plant_events": [e.as_dict() for e in plant.events],
        "camera": run.camera,
        **({"image_camera": run.camera_info} if run.camera_info else {}),
        "wall_time_s": run.wall_s,
        **(extra or {}),
        "provenance": provenance(run.result.seed),
    }
    if run.error:
        more["controller_traceback"] = run.error
    for k, v in more.items():
        doc.setdefault(k, v)
    return doc


def _shape_tol() -> float | None:
    try:
        from .control import ControllerOptions

        return float(ControllerOptions().shape_tol_um)
    except (ImportError, AttributeError, TypeError):  # pragma: no cover
        return None


def run_summary(result) -> dict[str, Any]:
    """A short dict for comparisons and console lines."""
    return {
        "success": bool(result.success),
        "docked": f"{int(np.sum(result.docked))}/{len(result.names)}",
        "shape_error_rms_um": float(result.shape_error_rms_um),
        "max_position_error_um": float(np.nanmax(result.placement_error_um)) if len(result.names) else 0.0,
        "failure": result.failure,
        "duration_s": float(result.duration_s),
    }


# ----------------------------------------------------------------------------------------------------
# Pictures and animation


def run_pictures(scenario, run: ClosedLoop, *, label: str = "closed loop") -> tuple[dict[str, bytes], dict[str, Any]]:
    """PNG bytes of ``run.png`` and ``structure.png`` and the animation data of a closed-loop run."""
    from .outputs import figure_bytes
    from .report import animation_data
    from .viz import plot_final_structure, plot_run

    res, plant = run.result, run.plant
    times, poses = plant.trace()
    final = poses[-1]
    verdict = "assembled" if res.success else "not assembled"
    title = (f"{scenario.name}: {label}, seed {res.seed} - {verdict}, {int(np.sum(res.docked))}/{scenario.n} docked, "
             f"shape error {res.shape_error_rms_um:.3g} um RMS")
    figs = {
        "run": figure_bytes(plot_run(scenario, times, poses, res.goals, plant.events, title=title)),
        "structure": figure_bytes(plot_final_structure(
            scenario, final, res.nominal_goals, res.docked,
            title=f"{verdict}: shape error {res.shape_error_rms_um:.3g} um RMS, alignment rotation {res.shape_rotation_deg:.1f} deg")),
    }
    if run.frames:
        from .lab.pictures import plot_tracked_frames

        figs["frames"] = figure_bytes(plot_tracked_frames(
            scenario, run.frames, title="camera frames the controller saw (image in the loop), tracked poses outlined"))
    anim = animation_data(scenario, times, poses, res.goals, merged_events(res, plant), title=title)
    return figs, anim


# ----------------------------------------------------------------------------------------------------
# The whole job


@dataclass(frozen=True, eq=False)
class JobResult:
    """What :func:`run_job` did: the folder, the result document and a few numbers."""

    out_dir: Path
    result: dict[str, Any]
    report_path: Path
    report_bytes: int
    wall_s: float
    files: tuple[str, ...]
    extra: dict[str, Any] = field(default_factory=dict)

    @property
    def success(self) -> bool:
        return bool(self.result.get("success"))


@dataclass(frozen=True, eq=False)
class JobContext:
    """Handed to an ``extra`` step (the demo's comparisons): everything computed before the report."""

    scenario: Any
    analysis: Any
    plan_result: Any
    out_dir: Path
    run: ClosedLoop


@dataclass
class Extra:
    """What an ``extra`` step adds to the report: comparison rows and files (name, description)."""

    comparisons: list[dict[str, Any]] = field(default_factory=list)
    files: list[tuple[str, str]] = field(default_factory=list)
    lines: list[str] = field(default_factory=list)
    summary: dict[str, Any] = field(default_factory=dict)


def _progress(err_console, quiet: bool):
    from rich.progress import BarColumn, Progress, SpinnerColumn, TextColumn, TimeElapsedColumn

    return Progress(
        SpinnerColumn(), TextColumn("{task.description:<22}"), BarColumn(), TextColumn("{task.fields[info]}"), TimeElapsedColumn(),
        console=err_console, disable=quiet or not err_console.is_terminal, transient=False,
    )


def run_job(
    scenario,
    out_dir: Path | str,
    *,
    seed: int = 0,
    source: str | None = None,
    inputs: Iterable[Path | str | None] = (),
    time_budget_s: float | None = None,
    console=None,
    err_console=None,
    quiet: bool = False,
    title: str | None = None,
    extra: Callable[[JobContext], Extra] | None = None,
    show_analysis: bool = True,
    camera: str = "poses",
) -> JobResult:
    """Analyse, plan, run closed loop on the simulator and write the report and its files into ``out_dir``.

    ``inputs`` are the user's input files (never overwritten). ``console`` gets the readable summary
    (stdout), ``err_console`` the progress bars; ``quiet`` leaves one summary line. ``extra`` runs after the
    closed loop and adds comparison rows and files to the report (the demo uses it).
    """
    from rich.console import Console

    from . import plans
    from .electrostatics import analyse_scenario
    from .outputs import check_not_input, figure_bytes, prepare_dir, write_bytes, write_json, write_text
    from .report import build_report
    from .sim import plan_waveform
    from .viz import plot_plan, plot_plan_waveform
    from .waveform import export, excerpt, summarize, to_json

    t_job = time.perf_counter()
    console = console or Console()
    err_console = err_console or Console(stderr=True)
    inputs = [p for p in inputs if p is not None]
    out = prepare_dir(out_dir, inputs=inputs)
    for name, _ in OUTPUT_FILES:
        check_not_input(out / name, inputs)
    if not scenario.has_starts:
        raise StressbotsError("every robot needs a start pose for the job (robots[].start)", source=source, field="robots")
    budget = time_budget_s if time_budget_s is not None else default_time_budget_s()

    def line(text: str) -> None:
        if not quiet:
            console.print(text, highlight=False, soft_wrap=True)

    analysis = analyse_scenario(scenario)
    if show_analysis and not quiet:
        from .cli import render_analysis

        render_analysis(analysis, console, title=f"{scenario.name}" + (f" ({source})" if source else ""))
        console.print()
    with _progress(err_console, quiet) as bar:
        t_plan = bar.add_task("planning", total=None, info="")
        plan_result = plan_for(scenario, source)
        s = plan_result.summary
        bar.update(t_plan, total=1, completed=1, info=f"{s['duration_s']:.1f} s plan, {s['steps']} steps")
        wf = plan_waveform(scenario, plan_result.plan)
        t_run = bar.add_task("closed loop", total=budget or None, info="")

        def on_time(t: float) -> None:
            bar.update(t_run, completed=min(t, budget) if budget else t, info=f"{t:.0f} s simulated")

        run = closed_loop(scenario, plan_result, seed=seed, time_budget_s=time_budget_s, on_time=on_time, camera=camera)
        res = run.result
        bar.update(t_run, total=max(res.duration_s, 1e-9), completed=max(res.duration_s, 1e-9),
                   info=f"{res.duration_s:.0f} s simulated, {'assembled' if res.success else 'not assembled'}")
        ctx = JobContext(scenario, analysis, plan_result, out, run)
        more = Extra()
        if extra is not None:
            t_extra = bar.add_task("comparisons", total=None, info="")
            more = extra(ctx)
            bar.update(t_extra, total=1, completed=1, info=f"{len(more.comparisons)} runs")
        t_rep = bar.add_task("pictures and report", total=5, info="")
        figs: dict[str, bytes] = {}
        figs["plan"] = figure_bytes(plot_plan(scenario, plan_result))
        bar.advance(t_rep)
        figs["waveform"] = figure_bytes(plot_plan_waveform(wf, analysis, title=f"{scenario.name}: waveform of the nominal plan"))
        bar.advance(t_rep)
        run_figs, anim = run_pictures(scenario, run)
        figs.update(run_figs)
        bar.advance(t_rep)
        # files beside the report
        plans.save(plan_result.plan, out / "plan.json")
        write_json(out / "states.json", analysis.to_json_dict())
        write_json(out / "waveform.json", to_json(wf))
        wsum = export(excerpt(wf, EXCERPT_S), out / "waveform.npy", rate_hz=RATE_HZ,
                      drive_frequency_hz=scenario.electrodes.drive_frequency_hz)
        for key in ("waveform", "plan", "run", "structure") + (("frames",) if "frames" in figs else ()):
            write_bytes(out / f"{key}.png", figs[key])
        doc = result_document(scenario, run, source=source, extra={
            "plan": {"file": "plan.json", **{k: s.get(k) for k in ("structure", "variant", "duration_s", "steps", "lower_bound_s", "efficiency")}},
            **({"comparisons": more.comparisons} if more.comparisons else {}),
        })
        write_json(out / "result.json", doc)
        bar.advance(t_rep)
        full = summarize(wf).as_dict()
        full["excerpt"] = (f"waveform.json: all {full['segments']} segments; waveform.npy: the first {wsum.duration_s:g} s sampled at "
                           f"{RATE_HZ / 1000:g} kS/s ({wsum.samples} samples); `stressbots waveform SCENARIO --plan plan.json --out FILE` "
                           f"samples all of it")
        by_name = {p.name: p for p in plan_result.plan.primitives}
        steps = [(st.primitive, by_name[st.primitive].turning, st.duration_s) for st in plan_result.plan.steps]
        files = [f for f in OUTPUT_FILES] + list(more.files)
        if "frames" in figs:
            files.append(("frames.png", "camera frames of the image-in-the-loop run with the tracked poses"))
        html_text = build_report(
            title=title or f"stressbots: {scenario.name}",
            scenario=scenario, analysis=analysis, plan_summary=s, plan_steps=steps, plan_notes=plan_result.notes,
            goals=plan_result.plan.goal_array(), waveform_summary=full, result=doc, figures=figs, animation=anim,
            events=merged_events(res, run.plant), files=files, comparisons=more.comparisons,
            provenance=doc.get("provenance"), source=source,
        )
        write_text(out / "report.html", html_text)
        bar.advance(t_rep)
        report_bytes = (out / "report.html").stat().st_size
        bar.update(t_rep, info=f"report.html {report_bytes / 1e6:.2f} MB")
    wall = time.perf_counter() - t_job
    _print_summary(console, scenario, s, res, doc, out, report_bytes, wall, quiet, more.lines)
    return JobResult(out, doc, out / "report.html", report_bytes, wall, tuple(n for n, _ in files), more.summary)


def verdict_text(result_doc: dict[str, Any]) -> str:
    """``assembled`` or ``not assembled: <reason>``."""
    from .report import outcome_text

    return outcome_text(result_doc)


def _print_summary(console, scenario, plan_summary, res, doc, out: Path, report_bytes: int, wall: float, quiet: bool,
                   extra_lines: Sequence[str]) -> None:
    docked = int(np.sum(res.docked))
    verdict = verdict_text(doc)
    if quiet:
        console.print(
            f"{scenario.name}: {verdict}; {docked}/{scenario.n} docked, shape error {res.shape_error_rms_um:.3g} um RMS, "
            f"{res.duration_s:.1f} s simulated; report {out / 'report.html'} ({report_bytes / 1e6:.2f} MB), {wall:.1f} s",
            highlight=False, soft_wrap=True,
        )
        return
    s = plan_summary
    console.print(
        f"[bold]Plan[/bold]: {s['structure']} in {s['duration_s']:.1f} s, {s['steps']} steps (lower bound {s['lower_bound_s']:.1f} s, "
        f"efficiency {s['efficiency']:.2f}); replayed independently: ok",
        highlight=False, soft_wrap=True,
    )
    console.print(f"[bold]Closed loop[/bold] on the simulated plant, seed {res.seed}: {res.duration_s:.1f} s simulated, "
                  f"{res.replans} re-plans", highlight=False, soft_wrap=True)
    console.print(robot_table(scenario.names, res))
    style = "bold green" if res.success else "bold red"
    console.print(f"[{style}]{verdict}[/{style}]", highlight=False, soft_wrap=True)
    console.print(
        f"{docked}/{scenario.n} docked, shape error {res.shape_error_rms_um:.3g} um RMS after the best rigid alignment "
        f"(rotation {res.shape_rotation_deg:.1f} deg); {len(doc.get('events', []))} controller events, "
        f"{len(doc.get('plant_events', []))} plant events",
        highlight=False, soft_wrap=True,
    )
    for text in extra_lines:
        console.print(text, highlight=False, soft_wrap=True)
    console.print(
        f"wrote {out / 'report.html'} ({report_bytes / 1e6:.2f} MB, opens offline), result.json, plan.json, states.json, "
        f"waveform.json, waveform.npy and the pictures to {out} in {wall:.1f} s",
        highlight=False, soft_wrap=True,
    )


def finite_budget(value: float | None, option: str = "--time-budget-s") -> float | None:
    """Validate a time budget given on the command line."""
    if value is None:
        return None
    if not (math.isfinite(value) and value > 0):
        raise StressbotsError(f"must be a finite number > 0 s, got {value:g}", source=option)
    return float(value)


def robot_table(names, res):
    """A rich table of a closed-loop result, one row per robot: docked, placement and heading error."""
    from rich.table import Table

    t = Table()
    for col, just in (("robot", "left"), ("docked", "left"), ("placement error (um)", "right"), ("heading error (deg)", "right")):
        t.add_column(col, justify=just)  # type: ignore[arg-type]
    for i, name in enumerate(names):
        t.add_row(name, "yes" if res.docked[i] else "no", f"{res.placement_error_um[i]:.3g}", f"{res.heading_error_deg[i]:.3g}")
    return t
