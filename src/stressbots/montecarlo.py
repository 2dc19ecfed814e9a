"""Monte Carlo studies of closed-loop assembly (``stressbots montecarlo``).

A study runs N independent closed-loop trials of one scenario: trial ``i`` builds a fresh
:class:`stressbots.sim.SimulatedPlant` and lets the controller (:func:`stressbots.control.assemble`)
assemble the structure through it, following one nominal plan computed once for the whole study.

Determinism
-----------
Trial ``i``'s seed is ``np.random.SeedSequence(seed).spawn(N)[i]``, turned into an integer (the top 53 bits
of its first 64-bit word, so JSON readers keep it exact; :func:`trial_seeds`); the plant and the
controller both receive that integer. A trial depends on nothing else, so the results are the same
whatever the number of worker processes and in whatever order they finish: outcomes are collected by
trial index. Only the ``"run"`` block of the summary (workers, wall time) differs between runs.

``--sweep`` repeats the study with the scenario's ``[noise]`` multiplied by each factor
(:meth:`stressbots.scenario.Noise.scaled`), with the *same* trial seeds (common random numbers: the
differences between noise levels are not blurred by different draws).

Trial store
-----------
:func:`run_study` runs the trials as a :mod:`stressbots.campaign` (one cell per noise scale) and commits
each finished trial to a :class:`stressbots.store.TrialStore` (``DIR/trials.sqlite`` from the command
line); the summary is computed from the store, so an interrupted and resumed study summarises exactly
like an uninterrupted one.

Statistics
----------
The success rate comes with a 95 % Wilson score interval (:func:`wilson_interval`), which stays inside
[0, 1] and keeps its coverage for rates near 0 or 1 and small N (unlike the normal approximation).
Error figures are percentiles (50/90/95/max, linear interpolation) over the trials where they are
defined: the RMS shape error after the best rigid alignment, the largest placement error over the robots,
the largest heading error, the simulated duration and the replans. Failure reasons are counted with their
numbers replaced by ``#`` so that like failures group together; the failed trials' seeds are listed for
reproduction with ``stressbots simulate --seed``.
"""

from __future__ import annotations

import math
import re
from collections import Counter
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .errors import StressbotsError
from .trial import TrialOutcome, run_trial, trial_seeds  # re-exported: the one-trial unit

__all__ = [
    "TrialOutcome",
    "Study",
    "trial_seeds",
    "wilson_interval",
    "percentiles",
    "failure_kind",
    "run_trial",
    "run_trials",
    "summarise",
    "run_study",
    "montecarlo_campaign",
    "montecarlo_settings",
    "montecarlo_summary",
    "default_assemble",
    "default_planner",
    "parse_sweep",
    "MAX_LISTED_FAILURES",
]

MAX_LISTED_FAILURES = 100
"""At most this many failed trials are listed (with their seeds) in a summary."""

_Z95 = 1.959963984540054  # standard normal quantile 0.975


# ----------------------------------------------------------------------------------------------------
# Pure pieces


def wilson_interval(successes: int, trials: int, confidence: float = 0.95) -> tuple[float, float]:
    """Wilson score interval of a binomial proportion.

    ``p = s / n``, ``z`` the normal quantile of ``(1 + confidence) / 2``::

        centre = (p + z^2 / (2 n)) / (1 + z^2 / n)
        half   = z / (1 + z^2 / n) * sqrt(p (1 - p) / n + z^2 / (4 n^2))

    ``(0, 1)`` for ``n = 0``. E.g. 8 of 10 gives (0.490, 0.943); 0 of 10 gives (0, 0.278).
    """
    n = int(trials)
    s = int(successes)
    if n < 0 or s < 0 or s > n:
        raise ValueError(f"need 0 <= successes <= trials, got {s} of {n}")
    if n == 0:
        return 0.0, 1.0
    if confidence == 0.95:
        z = _Z95
    else:
        from scipy.stats import norm

        z = float(norm.ppf(0.5 * (1.0 + confidence)))
    p = s / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z / denom * math.sqrt(p * (1.0 - p) / n + z * z / (4 * n * n))
    lo, hi = max(0.0, centre - half), min(1.0, centre + half)
    if s == 0:
        lo = 0.0
    if s == n:
        hi = 1.0
    return lo, hi


def percentiles(values, qs: Sequence[float] = (50, 90, 95)) -> dict[str, float | int | None]:
    """``{"p50": .., "p90": .., "p95": .., "max": .., "mean": .., "n": ..}`` over the finite values
    (``None`` when there are none)."""
    v = np.asarray([x for x in values if x is not None], dtype=np.float64)
    v = v[np.isfinite(v)]
    out: dict[str, float | int | None] = {}
    for q in qs:
        out[f"p{q:g}"] = float(np.percentile(v, q)) if v.size else None
    out["max"] = float(v.max()) if v.size else None
    out["mean"] = float(v.mean()) if v.size else None
    out["n"] = int(v.size)
    return out


# a sign only where it cannot be a hyphen inside a word ("stage-2" keeps its hyphen: "stage-#")
_NUMBER = r"(?:(?<![A-Za-z0-9_])[-+])?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?"
# a named object of the seed's vocabulary: a letter, "_", then a subscript (G_1, D_n, D_(n-1), D_{n-1}, A_2*, t_4pi)
_NAMED = r"(?<![A-Za-z0-9])[A-Za-z]+_(?:\([^()]*\)|\{[^{}]*\}|[A-Za-z0-9]+)"
_KIND = re.compile(f"(?P<named>{_NAMED})|(?P<number>{_NUMBER})")


def failure_kind(failure: str | None) -> str | None:
    """A failure message with its numbers replaced by ``#`` (so that like failures count together).

    Numbers and robot indices (``D3`` -> ``D#``) are replaced; named objects of the seed's vocabulary
    keep their subscripts, since they say which stage failed.

    >>> failure_kind("D_(n-1)'s straight move to its station orbit is blocked after 12.5 s")
    "D_(n-1)'s straight move to its station orbit is blocked after # s"
    >>> failure_kind("G_1 did not form: D3 stopped 40 um from D_n")
    'G_1 did not form: D# stopped # um from D_n'
    >>> failure_kind("no clear straight stage-2 run; R2 is -34 um from an obstacle")
    'no clear straight stage-# run; R# is # um from an obstacle'
    """
    if failure is None:
        return None
    return _KIND.sub(lambda m: m.group("named") or "#", str(failure)).strip()


def parse_sweep(text: str, *, option: str = "--sweep") -> tuple[float, ...]:
    """Parse ``"0,0.5,1,1.5,2"`` into noise scale factors (finite, >= 0, distinct, in the given order)."""
    items = [t.strip() for t in str(text).split(",")]
    if not str(text).strip() or any(not t for t in items):
        raise StressbotsError("expected comma-separated noise scale factors, e.g. '0,0.5,1,1.5,2'", source=option)
    out: list[float] = []
    for t in items:
        try:
            f = float(t)
        except ValueError:
            raise StressbotsError(f"{t!r} is not a number", source=option) from None
        if not math.isfinite(f) or f < 0:
            raise StressbotsError(f"noise scale factors must be finite and >= 0, got {t}", source=option)
        if f not in out:
            out.append(f)
    return tuple(out)


# ----------------------------------------------------------------------------------------------------
# The controller and its planner


def default_assemble() -> Callable:
    """The controller: :func:`stressbots.strategies.assemble_strategy` (:func:`stressbots.control.assemble`
    by default, the strategy chosen by name with ``strategy=``)."""
    from .strategies import assemble_strategy

    return assemble_strategy


def default_planner() -> Callable:
    """The nominal planner a study shares between its trials: the controller's own
    (:func:`stressbots.control.nominal_plan`), so a trial follows exactly the plan ``assemble(..., plan=None)``
    would have made."""
    from .control import nominal_plan

    return nominal_plan


def run_trials(
    scenario,
    trials: int,
    seed: int,
    *,
    workers: int | None = None,
    assemble: Callable | None = None,
    plan=None,
    noise_scales: Sequence[float] = (1.0,),
    time_budget_s: float | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> dict[float, list[TrialOutcome]]:
    """Run ``trials`` closed-loop trials at each noise scale; outcomes by scale, in trial order.

    Parameters
    ----------
    scenario:
        The scenario; its ``[noise]`` is scale 1.
    trials, seed:
        Number of trials per scale and the study's seed (:func:`trial_seeds`, the same at every scale).
    workers:
        Processes (default ``os.cpu_count()``, at most the number of tasks). ``1`` runs in this process.
    assemble:
        The controller, ``assemble(scenario, plant, *, seed, plan[, time_budget_s]) -> AssemblyResult``
        (default :func:`default_assemble`). With several workers it must be picklable (a module-level
        function).
    plan:
        The nominal plan passed to every trial (default :func:`default_planner` on the scenario, once).
    noise_scales:
        Factors on the scenario's noise.
    progress:
        Called as ``progress(done, total)`` after every finished trial (in this process).
    """
    from .campaign import run_campaign
    from .store import TrialStore

    if workers is not None and workers < 1:
        raise StressbotsError(f"must be at least 1, got {workers}", source="--workers")
    assemble = assemble or default_assemble()
    if plan is None:
        plan = default_planner()(scenario)
    scales = tuple(dict.fromkeys(float(f) for f in noise_scales))
    camp = montecarlo_campaign(scenario, trials, seed, scales, assemble=assemble, plan=plan, time_budget_s=time_budget_s)
    with TrialStore.open(":memory:", {}) as store:
        run_campaign(camp, store, workers=workers, progress=progress)
        return _by_scale(camp, store.rows())


def montecarlo_campaign(scenario, trials: int, seed: int, scales: Sequence[float], *, assemble: Callable, plan,
                        time_budget_s: float | None = None, strategy: str | None = None, options=None):
    """The :class:`stressbots.campaign.Campaign` of a Monte Carlo study: one cell per noise scale (in the
    given order), every cell with the same trial seeds."""
    from .campaign import Campaign, Cell, controller_kwargs

    kw = controller_kwargs(assemble, options=options, strategy=strategy)
    cells = tuple(
        Cell(label=f"noise x{f:g}", params={"noise_scale": float(f)},
             scenario=scenario if f == 1.0 else scenario.with_noise(scenario.noise.scaled(f)), plan=plan, noise_scale=float(f),
             controller=kw)
        for f in scales
    )
    return Campaign(cells, int(trials), int(seed), assemble, time_budget_s)


def montecarlo_settings(scenario, trials: int, seed: int, scales: Sequence[float], *, time_budget_s: float | None,
                        strategy: str | None = None, options=None) -> dict[str, Any]:
    """The fingerprint of a Monte Carlo campaign (compared on ``--resume``): what decides its outcomes."""
    import hashlib

    from .campaign import base_settings
    from .scenario import to_toml

    out: dict[str, Any] = {
        "command": "montecarlo",
        "scenario": scenario.name,
        "scenario_sha256": hashlib.sha256(to_toml(scenario).encode()).hexdigest(),
        "noise": _noise_dict(scenario.noise),
        "noise_scales": [float(f) for f in scales],
        "strategy": "rendezvous" if strategy in (None, "default") else strategy,
        "controller_options": None if options is None else asdict(options),
    }
    base = base_settings(trials, seed, time_budget_s)
    return {**{k: base.pop(k) for k in ("trials", "seed")}, **out, **base}


def _by_scale(camp, rows) -> dict[float, list[TrialOutcome]]:
    from .campaign import row_outcome

    outs = [row_outcome(r) for r in rows]
    return {cell.noise_scale: [o for o in outs if o.cell == c] for c, cell in enumerate(camp.cells)}


# ----------------------------------------------------------------------------------------------------
# Summaries


def _noise_dict(noise) -> dict[str, float]:
    """The noise levels in the file's units (deg, deg/mm)."""
    return noise.to_file_units()


def summarise(outcomes: Sequence[TrialOutcome]) -> dict[str, Any]:
    """Statistics of one set of trials (deterministic: no wall times)."""
    n = len(outcomes)
    s = sum(1 for o in outcomes if o.success)
    lo, hi = wilson_interval(s, n)
    failed = [o for o in outcomes if not o.success]
    kinds = Counter(failure_kind(o.failure) or "unknown" for o in failed)
    return {
        "trials": n,
        "successes": s,
        "success_rate": s / n if n else 0.0,
        "success_rate_ci95": [lo, hi],
        "shape_error_rms_um": percentiles(o.shape_error_rms_um for o in outcomes),
        "shape_error_rms_um_successes": percentiles(o.shape_error_rms_um for o in outcomes if o.success),
        "placement_error_um": percentiles(o.placement_error_um for o in outcomes),
        "heading_error_deg": percentiles(o.heading_error_deg for o in outcomes),
        "duration_s": percentiles(o.duration_s for o in outcomes),
        "replans": percentiles(o.replans for o in outcomes),
        "failures": dict(sorted(kinds.items(), key=lambda kv: (-kv[1], kv[0]))),
        "exceptions": sum(1 for o in outcomes if o.error is not None),
        "failed_trials": [
            {"trial": o.index, "seed": o.seed, "failure": o.failure} for o in failed[:MAX_LISTED_FAILURES]
        ],
    }


@dataclass(frozen=True, eq=False)
class Study:
    """A finished Monte Carlo study: the summary (``summary.json``) and every outcome by noise scale."""

    summary: dict
    outcomes: dict  # noise scale -> list[TrialOutcome]

    @property
    def main(self) -> list[TrialOutcome]:
        return self.outcomes[1.0]

    @property
    def sweep(self) -> list[dict] | None:
        return self.summary.get("sweep")


def _noise_scales(sweep: Sequence[float] | None) -> tuple[float, ...]:
    """The noise scales a study runs, in order and each once: the scenario's own noise (1.0) first, then
    the ``sweep`` factors."""
    scales = (1.0,) + tuple(float(f) for f in (sweep or ()) if f != 1.0)
    return tuple(dict.fromkeys(scales))


def _study_summary(scenario, outcomes: dict[float, list[TrialOutcome]], seed: int, plan, run, *, sweep: Sequence[float] | None,
                   source: str | None, strategy: str | None, store: Path | str | None) -> dict[str, Any]:
    """``summary.json``: the deterministic part from the stored outcomes (:func:`montecarlo_summary`), the
    strategy, the ``"run"`` block (backend, workers, wall times: what depends on the machine and on
    interruptions), where the trial store is, and the provenance."""
    from .outputs import provenance

    summary = montecarlo_summary(scenario, outcomes, seed, plan, sweep=sweep, source=source)
    summary["strategy"] = "rendezvous" if strategy in (None, "default") else strategy
    summary["run"] = {**run.to_dict(), "trial_wall_s": percentiles(o.wall_s for v in outcomes.values() for o in v)}
    if store is not None:
        summary["store"] = {"path": Path(store).name, "trials": sum(len(v) for v in outcomes.values()),
                            "table": "trials", "campaign_settings": "table campaign, key 'settings'"}
    summary["provenance"] = provenance(seed, scenario=source or scenario.name)
    return summary


def run_study(
    scenario,
    trials: int,
    seed: int,
    *,
    workers: int | None = None,
    sweep: Sequence[float] | None = None,
    assemble: Callable | None = None,
    plan=None,
    time_budget_s: float | None = None,
    progress: Callable[[int, int], None] | None = None,
    source: str | None = None,
    store: Path | str | None = None,
    resume: bool = False,
    overwrite: bool = False,
    dask: str | None = None,
    strategy: str | None = None,
    options=None,
) -> Study:
    """The whole study: trials at the scenario's noise (and at every ``sweep`` factor), summarised.

    Every finished trial is committed to the trial store ``store`` (``DIR/trials.sqlite``; ``None`` keeps
    it in memory) and the summary is computed from the store, so a resumed study (``resume=True``: only
    the missing trials run; a store of other settings is refused) summarises exactly like an
    uninterrupted one. ``dask`` runs the trials on a Dask cluster (:func:`stressbots.campaign.run_campaign`).

    The summary holds the SPEC 7 keys (``trials``, ``successes``, ``success_rate``), the Wilson 95 %
    interval, percentiles, failure counts, seeds and provenance, a ``"sweep"`` list when asked, and a
    ``"run"`` block (backend, workers, wall time, trials run now: the only part that depends on the
    machine and on interruptions).

    Raises
    ------
    stressbots.campaign.CampaignInterrupted
        On Ctrl-C / SIGTERM; the finished trials are in the store.
    """
    from .campaign import run_campaign
    from .outputs import provenance
    from .store import TrialStore

    if trials < 1:
        raise StressbotsError(f"must be at least 1, got {trials}", source="--trials")
    if workers is not None and workers < 1:
        raise StressbotsError(f"must be at least 1, got {workers}", source="--workers")
    assemble = assemble or default_assemble()
    if plan is None:
        plan = default_planner()(scenario)
    scales = _noise_scales(sweep)
    camp = montecarlo_campaign(scenario, trials, seed, scales, assemble=assemble, plan=plan, time_budget_s=time_budget_s,
                               strategy=strategy, options=options)
    settings = montecarlo_settings(scenario, trials, seed, scales, time_budget_s=time_budget_s, strategy=strategy, options=options)
    info = provenance(seed, scenario=source or scenario.name)
    with TrialStore.open(":memory:" if store is None else store, settings, resume=resume, overwrite=overwrite, info=info,
                         cells=[(c.label, c.params) for c in camp.cells]) as st:
        run = run_campaign(camp, st, workers=workers, dask=dask, progress=progress)
        outcomes = _by_scale(camp, st.rows())
    summary = _study_summary(scenario, outcomes, seed, plan, run, sweep=sweep, source=source, strategy=strategy, store=store)
    return Study(summary, outcomes)


def montecarlo_summary(scenario, outcomes: dict[float, list[TrialOutcome]], seed: int, plan, *, sweep: Sequence[float] | None = None,
                       source: str | None = None) -> dict[str, Any]:
    """The deterministic part of ``summary.json`` from the stored outcomes (by noise scale)."""
    summary: dict[str, Any] = {"format": "stressbots.montecarlo/1", "scenario": scenario.name, "source": source}
    summary.update(summarise(outcomes[1.0]))
    summary["ci_method"] = "Wilson score interval, 95 %"
    summary["seed"] = int(seed)
    summary["trial_seeds"] = ("trial i: int(SeedSequence(seed).spawn(trials)[i].generate_state(1, uint64)[0] >> 11), "
                              "for plant and controller")
    summary["noise"] = _noise_dict(scenario.noise)
    pl = getattr(plan, "plan", plan)
    summary["nominal_plan"] = {
        "duration_s": float(getattr(pl, "duration_s", math.nan)),
        "steps": len(getattr(pl, "steps", ())),
    }
    if sweep:
        rows = []
        for f in sweep:
            st = summarise(outcomes[1.0 if f == 1.0 else float(f)])
            rows.append(
                {
                    "noise_scale": float(f),
                    "trials": st["trials"],
                    "successes": st["successes"],
                    "success_rate": st["success_rate"],
                    "success_rate_ci95": st["success_rate_ci95"],
                    "shape_error_rms_um": st["shape_error_rms_um"],
                    "duration_s": st["duration_s"],
                    "failures": st["failures"],
                }
            )
        summary["sweep"] = rows
    return summary
