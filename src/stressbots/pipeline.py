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
failure reason and the event log. Bad input (a :class:`~stressbots.errors.StressbotsError`) stops the
job before anything is computed where it can be found out in advance. An unexpected exception inside
the computation is a bug, not an outcome: it propagates (the CLI reports it as an internal error, exit
status 1). Progress goes to a :class:`JobObserver` (the console's is in :mod:`stressbots.console`), so
this module prints nothing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .errors import StressbotsError

__all__ = ["OUTPUT_FILES", "ClosedLoop", "JobObserver", "JobResult", "JobSummary", "closed_loop", "plan_for", "result_document",
           "merged_events", "run_job"]

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

    Only ``observe`` and ``apply`` are the protocol; ``true_poses`` and ``docked`` are forwarded because
    :func:`stressbots.control.assemble` reports the true final pose of a plant that offers it, and asks it which
    robots it docked (SPEC 6: success is every robot docked).
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

    @property
    def docked(self) -> np.ndarray:
        return self._plant.docked


@dataclass(frozen=True, eq=False)
class ClosedLoop:
    """A closed-loop run on the simulator: the controller's result, the plant (truth, trace, events)."""

    result: Any  # stressbots.control.AssemblyResult
    plant: Any  # stressbots.sim.SimulatedPlant
    wall_s: float
    time_budget_s: float | None
    strategy: str = "rendezvous"  # stressbots.strategies.STRATEGIES key
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


#: The default simulated time budget of a closed-loop run scales with its layout (s): a base plus a
#: number of crossings (:func:`stressbots.scenario.crossing_s`), and at most a number of measurements
#: (re-plans, about 0.01 s of CPU each); never above the controller's own default. The example: 300 + 10 x 42 s = 724 s, where
#: runs take 110-180 s. It bounds the wall time of a run that never assembles.
BUDGET_BASE_S = 300.0
BUDGET_CROSSINGS = 10.0
BUDGET_MEASUREMENTS = 2500


def layout_time_budget_s(scenario) -> float | None:
    """The default simulated time budget of a closed-loop run of ``scenario`` (s); see :data:`BUDGET_BASE_S`."""
    from .scenario import crossing_s

    own = default_time_budget_s()
    layout = min(BUDGET_BASE_S + BUDGET_CROSSINGS * crossing_s(scenario),
                 BUDGET_MEASUREMENTS * scenario.control.replan_interval_s)
    return layout if own is None else min(own, layout)


def plan_for(scenario, source: str | None = None, *, seed: int = 0, options=None):
    """The nominal plan the controller follows (:func:`stressbots.control.nominal_plan`).

    This one function plans for ``stressbots plan``, ``run``, ``simulate`` and ``demo``, so they all
    follow the same plan (the planner settings are the controller's). ``seed`` is the route search's
    seed; ``options`` (a :class:`~stressbots.planning.PlannerOptions`) replaces the controller's
    settings when given. A planning error that names no file is attributed to ``source``.
    """
    try:
        if options is not None:
            from .planning import plan_assembly

            return plan_assembly(scenario, options)
        from .control import nominal_plan

        return nominal_plan(scenario, seed=seed)
    except StressbotsError as exc:
        if exc.source is None and source:
            exc.source = source
        raise


def closed_loop(scenario, plan_result, *, seed: int, time_budget_s: float | None = None,
                on_time: Callable[[float], None] | None = None, strategy: str = "rendezvous",
                camera: str = "poses") -> ClosedLoop:
    """Run the ``strategy``'s assembly (:mod:`stressbots.strategies`; default :func:`stressbots.control.assemble`)
    on a recording :class:`~stressbots.sim.SimulatedPlant`.

    ``camera="images"`` puts the image in the loop: the controller observes the plant through rendered
    frames and the tracker (:class:`stressbots.lab.SyntheticLab`, needs the ``[lab]`` extra)."""
    from .sim import SimulatedPlant
    from .strategies import strategy_function

    assemble = strategy_function(strategy)

    plant = SimulatedPlant(scenario, seed=seed, record=True)
    observed: Any = plant  # the simulator, or an image lab around it (frames, describe)
    if camera == "images":
        observed = _image_lab(scenario, plant, seed)
    kwargs: dict[str, Any] = {"seed": seed, "plan": plan_result}
    if time_budget_s is not None:
        kwargs["time_budget_s"] = float(time_budget_s)
    t0 = time.perf_counter()
    res = assemble(scenario, _WatchedPlant(observed, on_time), **kwargs)
    frames = tuple(observed.frames) if observed is not plant else ()
    info = observed.describe() if observed is not plant else {}
    return ClosedLoop(res, plant, time.perf_counter() - t0, time_budget_s, strategy, camera, frames, info)


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
        "strategy": run.strategy,
        "scenario": source,
        "noise": scenario.noise.to_file_units(),
        "time_budget_s": run.time_budget_s,
        "shape_tol_um": _shape_tol(),
        "plant": {
            "speed_factors": dict(zip(scenario.names, plant.speed_factors.tolist(), strict=True)),
            "radius_factors": dict(zip(scenario.names, plant.radius_factors.tolist(), strict=True)),
            "docked": dict(zip(scenario.names, plant.docked.tolist(), strict=True)),
            "stuck": dict(zip(scenario.names, plant.stuck.tolist(), strict=True)),
            "time_s": plant.time_s,
        },
        "plant_events": [e.as_dict() for e in plant.events],
        "camera": run.camera,
        **({"image_camera": run.camera_info} if run.camera_info else {}),
        "wall_time_s": run.wall_s,
        **(extra or {}),
        "provenance": provenance(run.result.seed),
    }
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
    t_g1 = retarget_time_s(res)
    figs = {
        "run": figure_bytes(plot_run(scenario, times, poses, res.nominal_goals, plant.events, title=title,
                                     retargeted=res.goals if t_g1 is not None else None)),
        "structure": figure_bytes(plot_final_structure(
            scenario, final, res.nominal_goals, res.docked,
            title=f"{verdict}: shape error {res.shape_error_rms_um:.3g} um RMS, alignment rotation {res.shape_rotation_deg:.1f} deg")),
    }
    if run.frames:
        from .lab.pictures import plot_tracked_frames

        figs["frames"] = figure_bytes(plot_tracked_frames(
            scenario, run.frames, title="camera frames the controller saw (image in the loop), tracked poses outlined"))
    anim = animation_data(scenario, times, poses, res.nominal_goals, merged_events(res, plant), title=title,
                          retargeted=res.goals, retarget_time_s=t_g1)
    return figs, anim


def retarget_time_s(result) -> float | None:
    """When the controller re-targeted the remaining slots (s, simulated): the time G_1 formed, from its
    event log; None when G_1 never formed (then the re-targeted slots are the planned ones)."""
    for ev in result.events:
        if ev.get("kind") in ("G_1", "retarget") and ev.get("t_s") is not None:
            return float(ev["t_s"])
    return None


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
    coverage: dict[str, Any] | None = None
    """The controller's regions and their coverage (:func:`coverage_extra`), a report section of its own."""
    figures: dict[str, bytes] = field(default_factory=dict)
    """Pictures the extra step adds (PNG bytes by figure name, e.g. ``coverage``)."""


class JobObserver:
    """Watches :func:`run_job`: the job tells it what it computed and how far it got; this base does nothing.

    A console (:class:`stressbots.console.RichJobObserver`) shows tables and progress bars; tests and
    library callers use the silent default. Used as a context manager around the job's stages.
    """

    def analysed(self, scenario, analysis, source: str | None) -> None:
        """The voltage analysis is done."""

    def stage(self, name: str, *, total: float | None = None, completed: float | None = None, info: str | None = None,
              advance: float | None = None) -> None:
        """Stage ``name`` started (first call) or progressed."""

    def finished(self, summary: JobSummary) -> None:
        """The job is done and its files are written."""

    def __enter__(self) -> JobObserver:
        return self

    def __exit__(self, *exc) -> None:
        return None


@dataclass(frozen=True, eq=False)
class JobSummary:
    """What a finished job hands its observer: enough to print a summary."""

    scenario: Any
    plan_summary: dict[str, Any]
    result: Any  # AssemblyResult
    document: dict[str, Any]
    out_dir: Path
    report_bytes: int
    wall_s: float
    lines: tuple[str, ...] = ()


def _prepared_out(scenario, out_dir: Path | str, inputs: list[Path | str], source: str | None) -> Path:
    """The output folder, checked before anything is computed: creatable, no output file on an input, and
    a scenario the job can run (every robot has a start pose, small enough to plan and simulate in
    reasonable time, start bodies apart)."""
    from .outputs import prepare_dir
    from .scenario import check_movable, check_starts

    out = prepare_dir(out_dir, inputs=inputs, files=[name for name, _ in OUTPUT_FILES])
    if not scenario.has_starts:
        raise StressbotsError("every robot needs a start pose for the job (robots[].start)", source=source, field="robots")
    check_movable(scenario, source=source)
    check_starts(scenario, source=source)
    return out


def _closed_loop_stage(scenario, plan_result, obs: JobObserver, *, seed: int, budget: float | None, strategy: str,
                       camera: str) -> ClosedLoop:
    """The closed-loop run as the ``closed loop`` stage: progress in simulated seconds (s) against the
    time budget, then the simulated duration and the outcome."""
    obs.stage("closed loop", total=budget or None)

    def on_time(t: float) -> None:
        obs.stage("closed loop", completed=min(t, budget) if budget else t, info=f"{t:.0f} s simulated")

    run = closed_loop(scenario, plan_result, seed=seed, time_budget_s=budget, on_time=on_time, strategy=strategy,
                      camera=camera)
    res = run.result
    obs.stage("closed loop", total=max(res.duration_s, 1e-9), completed=max(res.duration_s, 1e-9),
              info=f"{res.duration_s:.0f} s simulated, {'assembled' if res.success else 'not assembled'}")
    return run


def _extra_stage(extra: Callable[[JobContext], Extra] | None, ctx: JobContext, obs: JobObserver) -> Extra:
    """The ``extra`` step (the demo's comparisons, the controller's regions) as the ``comparisons`` stage;
    nothing without one."""
    if extra is None:
        return Extra()
    obs.stage("comparisons")
    more = extra(ctx)
    obs.stage("comparisons", total=1, completed=1,
              info=f"{len(more.comparisons)} runs" if more.comparisons or not more.lines else more.lines[0])
    return more


def run_job(
    scenario,
    out_dir: Path | str,
    *,
    seed: int = 0,
    source: str | None = None,
    inputs: Iterable[Path | str | None] = (),
    time_budget_s: float | None = None,
    observer: JobObserver | None = None,
    title: str | None = None,
    extra: Callable[[JobContext], Extra] | None = None,
    strategy: str = "rendezvous",
    camera: str = "poses",
) -> JobResult:
    """Analyse, plan, run closed loop on the simulator and write the report and its files into ``out_dir``.

    ``inputs`` are the user's input files (never overwritten). ``observer`` is told of every stage (for
    progress bars and a printed summary; default: silent). ``extra`` runs after the closed loop and
    adds comparison rows and files to the report (the demo uses it). The output folder is checked
    before anything is computed.
    """
    from .electrostatics import analyse_scenario
    from .sim import plan_waveform

    t_job = time.perf_counter()
    obs = observer or JobObserver()
    out = _prepared_out(scenario, out_dir, [p for p in inputs if p is not None], source)
    budget = time_budget_s if time_budget_s is not None else layout_time_budget_s(scenario)
    analysis = analyse_scenario(scenario)
    obs.analysed(scenario, analysis, source)
    with obs:
        obs.stage("planning")
        plan_result = plan_for(scenario, source)
        s = plan_result.summary
        obs.stage("planning", total=1, completed=1, info=f"{s['duration_s']:.1f} s plan, {s['steps']} steps")
        wf = plan_waveform(scenario, plan_result.plan)
        run = _closed_loop_stage(scenario, plan_result, obs, seed=seed, budget=budget, strategy=strategy, camera=camera)
        more = _extra_stage(extra, JobContext(scenario, analysis, plan_result, out, run), obs)
        doc, files, report_bytes = _write_outputs(scenario, analysis, plan_result, wf, run, more, out, obs,
                                                  source=source, title=title)
    wall = time.perf_counter() - t_job
    obs.finished(JobSummary(scenario, s, run.result, doc, out, report_bytes, wall, tuple(more.lines)))
    return JobResult(out, doc, out / "report.html", report_bytes, wall, files, more.summary)


def _write_outputs(scenario, analysis, plan_result, wf, run: ClosedLoop, more: Extra, out: Path, obs: JobObserver, *,
                   source: str | None, title: str | None) -> tuple[dict[str, Any], tuple[str, ...], int]:
    """Pictures, the files beside the report, and report.html; returns the result document, the file
    names and the report's size (bytes)."""
    from . import plans
    from .outputs import figure_bytes, write_bytes, write_json, write_text
    from .viz import plot_plan, plot_plan_waveform
    from .waveform import excerpt, export, to_json

    s = plan_result.summary
    obs.stage("pictures and report", total=5)
    figs: dict[str, bytes] = {"plan": figure_bytes(plot_plan(scenario, plan_result))}
    obs.stage("pictures and report", advance=1)
    figs["waveform"] = figure_bytes(plot_plan_waveform(wf, analysis, title=f"{scenario.name}: waveform of the nominal plan"))
    obs.stage("pictures and report", advance=1)
    run_figs, anim = run_pictures(scenario, run)
    figs.update(run_figs)
    figs.update(more.figures)
    obs.stage("pictures and report", advance=1)
    plans.save(plan_result.plan, out / "plan.json")
    write_json(out / "states.json", analysis.to_json_dict())
    write_json(out / "waveform.json", to_json(wf))
    wsum = export(excerpt(wf, EXCERPT_S), out / "waveform.npy", rate_hz=RATE_HZ,
                  drive_frequency_hz=scenario.electrodes.drive_frequency_hz)
    for key in ("waveform", "plan", "run", "structure") + tuple(k for k in ("frames", "coverage") if k in figs):
        write_bytes(out / f"{key}.png", figs[key])
    doc = result_document(scenario, run, source=source, extra={
        "plan": {"file": "plan.json",
                 **{k: s.get(k) for k in ("structure", "variant", "duration_s", "steps", "lower_bound_s", "efficiency")}},
        **({"comparisons": more.comparisons} if more.comparisons else {}),
    })
    write_json(out / "result.json", doc)
    obs.stage("pictures and report", advance=1)
    files = [*OUTPUT_FILES, *more.files]
    if "frames" in figs:
        files.append(("frames.png", "camera frames of the image-in-the-loop run with the tracked poses"))
    if "coverage" in figs:
        files.append(("coverage.png", "the regions the controller aims at, with the true poses of the Monte Carlo trials"))
    write_text(out / "report.html", _report_html(scenario, analysis, plan_result, wf, wsum, run, doc, figs, anim, more, files,
                                                 source=source, title=title))
    report_bytes = (out / "report.html").stat().st_size
    obs.stage("pictures and report", advance=1, info=f"report.html {report_bytes / 1e6:.2f} MB")
    return doc, tuple(n for n, _ in files), report_bytes


def _report_html(scenario, analysis, plan_result, wf, wsum, run: ClosedLoop, doc, figs, anim, more: Extra, files, *,
                 source: str | None, title: str | None) -> str:
    from .report import build_report
    from .waveform import summarize

    full = summarize(wf).as_dict()
    full["excerpt"] = (f"waveform.json: all {full['segments']} segments; waveform.npy: the first {wsum.duration_s:g} s sampled at "
                       f"{RATE_HZ / 1000:g} kS/s ({wsum.samples} samples); `stressbots waveform SCENARIO --plan plan.json --out FILE` "
                       f"samples all of it")
    by_name = {p.name: p for p in plan_result.plan.primitives}
    steps = [(st.primitive, by_name[st.primitive].turning, st.duration_s) for st in plan_result.plan.steps]
    return build_report(
        title=title or f"stressbots: {scenario.name}",
        scenario=scenario, analysis=analysis, plan_summary=plan_result.summary, plan_steps=steps, plan_notes=plan_result.notes,
        goals=plan_result.plan.goal_array(), waveform_summary=full, result=doc, figures=figs, animation=anim,
        events=merged_events(run.result, run.plant), files=files, comparisons=more.comparisons,
        provenance=doc.get("provenance"), source=source, coverage=more.coverage,
    )


#: Largest simulated time budget a command accepts (s): five times the controller's default, far beyond
#: any assembly that will still finish; it bounds the wall time of a run that never assembles.
MAX_TIME_BUDGET_S = 20_000.0


def finite_budget(value: float | None, option: str = "--time-budget-s") -> float | None:
    """Validate a time budget given on the command line: a number of seconds in (0, MAX_TIME_BUDGET_S]."""
    if value is None:
        return None
    if not (math.isfinite(value) and 0 < value <= MAX_TIME_BUDGET_S):
        raise StressbotsError(f"must be a number of seconds in (0, {MAX_TIME_BUDGET_S:g}], got {value:g}", source=option)
    return float(value)


def coverage_extra(trials: int, *, seed: int = 0, scales: tuple[float, ...] = (1.0, 2.0),
                   progress: Callable[[int, int], None] | None = None) -> Callable[[JobContext], Extra]:
    """An ``extra`` step for :func:`run_job`: the regions the controller aims at and their coverage.

    Runs ``trials`` closed-loop assemblies at each noise scale (the scenario's ``[noise]`` times the
    scale) on the job's nominal plan (:func:`stressbots.coverage.controller_coverage`), with the seed's
    ``A_i*`` verdict of each robot beside its regions, and adds them to the report as the section
    "Controller regions" with ``coverage.png``. Costs ``trials * len(scales)`` assemblies.
    """
    from .bounds import analyse_bounds
    from .coverage import controller_coverage
    from .outputs import figure_bytes
    from .viz import plot_controller_coverage

    def step(ctx: JobContext) -> Extra:
        report = analyse_bounds(ctx.scenario, structure=ctx.plan_result.structure)
        verdicts = {rb.name: "yes" if rb.guaranteed else "no" for rb in report.robots}
        ctl = controller_coverage(ctx.scenario, trials=trials, seed=seed, scales=scales, verdicts=verdicts,
                                  plan=ctx.plan_result, progress=progress)
        doc = ctl.to_dict()
        lines = [f"controller regions: {trials} trials at {', '.join(f'{x:g}x' for x in scales)} noise, assembled "
                 + ", ".join(f"{k}/{trials}" for k in ctl.successes)]
        return Extra(lines=lines, coverage=doc, figures={"coverage": figure_bytes(plot_controller_coverage(ctx.scenario, ctl))},
                     summary={"controller_coverage": {"trials": trials, "noise_scales": list(scales),
                                                      "successes": list(ctl.successes)}})

    return step
