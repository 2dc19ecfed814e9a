"""Campaigns of closed-loop trials: cells x trials, streamed into a trial store, on processes or Dask.

A *campaign* is a set of *cells* (conditions: a scenario with its noise, the nominal plan, controller
options and strategy) and ``trials`` trials per cell. Trial ``k`` of every cell uses the same seed,
``trial_seeds(seed, trials)[k]`` (:func:`stressbots.trial.trial_seeds`): paired seeds, so the
differences between cells are not blurred by different draws. The campaign-wide trial number is
``cell * trials + k``.

Trials are pure functions of (cell, seed), so they may run anywhere, in any order: in this process, in a
local process pool, or on a Dask cluster (:func:`run_campaign`, ``dask=``). Each finished trial is
committed to the :class:`stressbots.store.TrialStore` as it arrives; ``--resume`` runs only those not
there. Interrupting (Ctrl-C, SIGTERM from a batch scheduler) stops the workers and raises
:class:`CampaignInterrupted` with the count kept.
"""

from __future__ import annotations

import hashlib
import math
import os
import signal
import socket
import threading
import time
from collections.abc import Callable, Iterator, Mapping, Sequence
from contextlib import closing, contextmanager
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

from .errors import StressbotsError

__all__ = [
    "Cell",
    "Campaign",
    "CampaignInterrupted",
    "RunInfo",
    "run_campaign",
    "run_task",
    "outcome_row",
    "row_outcome",
    "code_fingerprint",
    "base_settings",
    "controller_kwargs",
]

Task = tuple[int, int, int, int]  # (trial, cell, cell_trial, seed)

DASK_RESUBMITS = 3
"""A trial whose Dask task failed for the cluster's reasons (a worker killed under it more often than the
scheduler's ``allowed-failures``) is submitted again this many times before the campaign gives up."""


class CampaignInterrupted(KeyboardInterrupt):
    """Ctrl-C (or SIGTERM) stopped a campaign; ``kept`` of ``total`` trials are in the store."""

    def __init__(self, kept: int, total: int, path: Path | None):
        super().__init__(f"interrupted: {kept} of {total} trials kept")
        self.kept, self.total, self.path = kept, total, path


@dataclass(frozen=True)
class Cell:
    """One set of conditions of a campaign.

    ``scenario`` already carries the cell's noise and ``[control]``; ``plan`` is the nominal plan its
    trials follow (``None`` with ``plan_error`` when no plan could be made: the cell's trials are then
    failures that name it); ``controller`` holds extra keyword arguments for the controller
    (``options=ControllerOptions(...)``, ``strategy=...``), as ``(name, value)`` pairs.
    """

    label: str
    params: Mapping[str, Any]
    scenario: Any
    plan: Any
    plan_error: str | None = None
    noise_scale: float = 1.0
    controller: tuple[tuple[str, Any], ...] = ()


@dataclass(frozen=True)
class Campaign:
    """Cells x ``trials`` paired trials of one ``seed`` (everything a worker needs to run any trial)."""

    cells: tuple[Cell, ...]
    trials: int
    seed: int
    assemble: Callable
    time_budget_s: float | None = None
    seeds: tuple[int, ...] = field(default=(), compare=False)

    def __post_init__(self):
        from .trial import trial_seeds

        if self.trials < 1:
            raise StressbotsError(f"must be at least 1, got {self.trials}", source="--trials")
        if not self.cells:
            raise ValueError("a campaign needs at least one cell")
        object.__setattr__(self, "seeds", tuple(trial_seeds(self.seed, self.trials)))

    @property
    def total(self) -> int:
        return len(self.cells) * self.trials

    def tasks(self, skip: set[int] | frozenset[int] = frozenset()) -> list[Task]:
        """Every trial not in ``skip``, cell by cell."""
        out = []
        for c in range(len(self.cells)):
            for k, s in enumerate(self.seeds):
                t = c * self.trials + k
                if t not in skip:
                    out.append((t, c, k, s))
        return out


def controller_kwargs(assemble: Callable, *, options=None, strategy: str | None = None,
                      source: str = "--strategy") -> tuple[tuple[str, Any], ...]:
    """The extra controller arguments of a cell, checked against what ``assemble`` accepts.

    A strategy other than ``"default"`` is passed as ``ControllerOptions.strategy`` when the options have
    that field, else as ``assemble(..., strategy=...)`` when the controller takes it; otherwise it is
    refused (this controller has one strategy).
    """
    import dataclasses
    import inspect

    out: dict[str, Any] = {}
    params: Mapping[str, inspect.Parameter]
    try:
        params = inspect.signature(assemble).parameters
    except (TypeError, ValueError):  # pragma: no cover - builtins
        params = {}
    takes_kwargs = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    from .strategies import DEFAULT_STRATEGY, STRATEGIES

    if strategy not in (None, "default", DEFAULT_STRATEGY):  # the default strategy needs no argument

        if "strategy" in params and strategy not in STRATEGIES:
            raise StressbotsError(f"unknown strategy {strategy!r}; choose one of {', '.join(STRATEGIES)}", source=source)
        names = {f.name for f in dataclasses.fields(options)} if options is not None else set()
        if options is None and ("options" in params or takes_kwargs):
            try:
                from .control import ControllerOptions

                names = {f.name for f in dataclasses.fields(ControllerOptions)}
                if "strategy" in names:
                    options = ControllerOptions()
            except ImportError:  # pragma: no cover
                pass
        if options is not None and "strategy" in names:
            options = dataclasses.replace(options, strategy=strategy)
        elif "strategy" in params or takes_kwargs:
            out["strategy"] = strategy
        else:
            raise StressbotsError(f"the controller offers no strategy {strategy!r} (only 'default')", source=source)
    if options is not None:
        if "options" not in params and not takes_kwargs:
            raise StressbotsError("this controller takes no options (controller.* settings)", source=source)
        out["options"] = options
    return tuple(sorted(out.items()))


# ----------------------------------------------------------------------------------------------------
# Fingerprints


PRESENTATION_MODULES = frozenset({"__init__.py", "__main__.py", "cli.py", "demo.py", "outputs.py", "report.py", "store.py",
                                  "studyreport.py", "viz.py"})
"""Modules that cannot change a trial's outcome (command line, pictures, files): left out of
:func:`code_fingerprint`, so editing them does not invalidate stores."""


@lru_cache(maxsize=1)
def code_fingerprint() -> str:
    """SHA-256 of the stressbots sources that decide a trial's outcome (every ``*.py`` of the installed
    package but :data:`PRESENTATION_MODULES`): a store made by other code may hold other outcomes, so
    ``--resume`` compares this too; Dask workers are checked against it."""
    root = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for p in sorted(q for q in root.rglob("*.py") if q.name not in PRESENTATION_MODULES):
        h.update(str(p.relative_to(root)).encode())
        h.update(b"\0")
        h.update(p.read_bytes())
    return h.hexdigest()


def base_settings(trials: int, seed: int, time_budget_s: float | None) -> dict[str, Any]:
    """The fingerprint fields every campaign shares (versions and code included: they decide outcomes)."""
    from .outputs import versions

    return {
        "trials": int(trials),
        "seed": int(seed),
        "time_budget_s": None if time_budget_s is None else float(time_budget_s),
        "versions": versions(),
        "code_sha256": code_fingerprint(),
    }


# ----------------------------------------------------------------------------------------------------
# One trial, and the store's rows


def run_task(campaign: Campaign, task: Task):
    """Run one trial of ``campaign`` (pure: the same task gives the same outcome anywhere)."""
    from .trial import TrialOutcome, run_trial

    trial, c, k, seed = task
    cell = campaign.cells[c]
    if cell.plan is None:
        n = cell.scenario.n
        return TrialOutcome(k, seed, cell.noise_scale, False, f"no nominal plan: {cell.plan_error}", math.nan, math.nan, math.nan,
                            math.nan, 0, 0, n, None, 0.0, c)
    return run_trial(cell.scenario, cell.plan, k, seed, campaign.assemble, noise_scale=cell.noise_scale,
                     time_budget_s=campaign.time_budget_s, controller=dict(cell.controller), cell=c)


def outcome_row(outcome, trials: int, worker: str = "") -> dict[str, Any]:
    """A :class:`~stressbots.montecarlo.TrialOutcome` as a row of the store's ``trials`` table."""
    return {
        "trial": outcome.cell * trials + outcome.index,
        "cell": outcome.cell,
        "cell_trial": outcome.index,
        "seed": outcome.seed,
        "noise_scale": outcome.noise_scale,
        "success": outcome.success,
        "failure": outcome.failure,
        "shape_error_um": outcome.shape_error_rms_um,
        "placement_error_um": outcome.placement_error_um,
        "heading_error_deg": outcome.heading_error_deg,
        "duration_s": outcome.duration_s,
        "replans": outcome.replans,
        "docked": outcome.docked,
        "robots": outcome.robots,
        "error": outcome.error,
        "wall_s": outcome.wall_s,
        "worker": worker,
    }


def _f(x) -> float:
    return math.nan if x is None else float(x)


def row_outcome(row: Mapping[str, Any]):
    """The inverse of :func:`outcome_row` (NULL floats come back as NaN)."""
    from .trial import TrialOutcome

    return TrialOutcome(
        index=int(row["cell_trial"]), seed=int(row["seed"]), noise_scale=_f(row["noise_scale"]), success=bool(row["success"]),
        failure=row["failure"], shape_error_rms_um=_f(row["shape_error_um"]), placement_error_um=_f(row["placement_error_um"]),
        heading_error_deg=_f(row["heading_error_deg"]), duration_s=_f(row["duration_s"]), replans=int(row["replans"] or 0),
        docked=int(row["docked"] or 0), robots=int(row["robots"] or 0), error=row["error"], wall_s=_f(row["wall_s"]),
        cell=int(row["cell"]),
    )


# ----------------------------------------------------------------------------------------------------
# Where trials run: this process, a local process pool, a Dask cluster. Each yields (outcome, worker).

_WORKER: dict[str, Any] = {}


def _init_worker(campaign: Campaign) -> None:
    """Pool worker start: the campaign once per process; Ctrl-C is the parent's to handle (it stops us);
    on Linux the worker dies with its parent (a ``kill -9``'d campaign leaves no orphans)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # not the parent's SIGTERM-as-Ctrl-C
    try:
        import ctypes

        ctypes.CDLL("libc.so.6", use_errno=True).prctl(1, signal.SIGKILL)  # PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux
        pass
    _WORKER["campaign"] = campaign
    _WORKER["name"] = f"{socket.gethostname()}:{os.getpid()}"


def _worker_task(task: Task):
    return run_task(_WORKER["campaign"], task), _WORKER["name"]


def _inline(campaign: Campaign, tasks: Sequence[Task]) -> Iterator[tuple[Any, str]]:
    name = f"{socket.gethostname()}:{os.getpid()}"
    for t in tasks:
        yield run_task(campaign, t), name


def _pool(campaign: Campaign, tasks: Sequence[Task], k: int) -> Iterator[tuple[Any, str]]:
    import multiprocessing
    from concurrent.futures import ProcessPoolExecutor, as_completed

    # fork where the platform has it: workers inherit the loaded modules and the campaign (nothing is
    # pickled but the tasks); elsewhere the platform's default. Outcomes do not depend on the method.
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("fork" if "fork" in methods else None)
    pool = ProcessPoolExecutor(max_workers=k, mp_context=ctx, initializer=_init_worker, initargs=(campaign,))
    try:
        futures = [pool.submit(_worker_task, t) for t in tasks]
        for fut in as_completed(futures):
            yield fut.result()
    except BaseException:  # Ctrl-C, SIGTERM, the consumer stopping early (GeneratorExit), a broken pool
        procs = list(getattr(pool, "_processes", {}).values())
        pool.shutdown(wait=False, cancel_futures=True)
        for p in procs:  # a stopped campaign does not wait for the trials under way
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join(timeout=5)
        raise
    pool.shutdown(wait=True)


def _dask_task(campaign: Campaign, task: Task):
    """A trial on a Dask worker; also returns the worker's code fingerprint (checked by the client)."""
    return run_task(campaign, task), f"{socket.gethostname()}:{os.getpid()}", code_fingerprint()


@contextmanager
def _sigint_ignored_by_children():
    """Ctrl-C in a terminal reaches the whole process group: the LocalCluster's processes, started while
    SIGINT is ignored, keep ignoring it (the disposition survives exec) and are stopped by us instead."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    old = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, old)


@contextmanager
def dask_client(address: str, workers: int | None):
    """A ``distributed.Client`` for ``address``: ``local`` (a LocalCluster of ``workers`` single-threaded
    processes), a scheduler file (``*.json``, as written by ``dask scheduler --scheduler-file``) or a
    scheduler address (``tcp://host:8786``)."""
    try:
        import logging

        from distributed import Client, LocalCluster
    except ImportError:
        raise StressbotsError("needs Dask: pip install 'stressbots[dask]'", source="--dask") from None
    cluster = None
    try:
        if address == "local":
            n = int(workers or os.cpu_count() or 1)
            # single-threaded worker processes (a trial holds the GIL); dashboards on free ports; quiet
            # logs (a worker's connection closing at shutdown is not news)
            import dask

            # the workers' statistical profiler samples every thread's stack every 10 ms, holding the GIL:
            # measurable on CPU-bound pure-Python trials (remote clusters: set it in the workers' config)
            with _sigint_ignored_by_children(), dask.config.set({"distributed.worker.profile.enabled": False}):
                cluster = LocalCluster(n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
                                       worker_dashboard_address=":0", silence_logs=logging.CRITICAL)
            client = Client(cluster)
        elif address.endswith(".json"):
            client = Client(scheduler_file=address, timeout="30s")
        else:
            client = Client(address, timeout="30s")
    except (OSError, TimeoutError, ValueError) as exc:
        if cluster is not None:
            cluster.close()
        raise StressbotsError(f"cannot reach the Dask scheduler {address!r}: {exc}", source="--dask") from None
    try:
        yield client
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


def _dask(campaign: Campaign, tasks: Sequence[Task], client, token: str) -> Iterator[tuple[Any, str]]:
    from distributed import as_completed
    from distributed.scheduler import KilledWorker

    mine = code_fingerprint()
    ctx = client.scatter(campaign, broadcast=True, hash=False)

    def submit(t: Task, attempt: int):
        key = f"stressbots-{token}-trial-{t[0]}-{attempt}"
        fut = client.submit(_dask_task, ctx, t, key=key, pure=False, retries=1)
        tries[fut.key] = (t, attempt)
        return fut

    tries: dict[str, tuple[Task, int]] = {}
    futures = [submit(t, 0) for t in tasks]
    ac = as_completed(futures)
    try:
        for fut in ac:
            t, attempt = tries.pop(fut.key)
            if fut.status == "error":
                exc = fut.exception()
                if isinstance(exc, KilledWorker) and attempt < DASK_RESUBMITS:
                    ac.add(submit(t, attempt + 1))  # its workers died under it: run it again, elsewhere
                    fut.release()
                    continue
                raise StressbotsError(f"trial {t[0]} failed on the cluster: {type(exc).__name__}: {exc}", source="--dask")
            outcome, worker, theirs = fut.result()
            fut.release()
            if theirs != mine:
                raise StressbotsError(f"worker {worker} runs other stressbots code than this machine (sources differ); "
                                      "install the same version on every worker", source="--dask")
            yield outcome, worker
    finally:  # stopped early (Ctrl-C, an error): the cluster should not go on with our trials
        try:
            client.cancel([f for f in futures if not f.done()] + list(getattr(ac, "futures", ())), force=True)
        except Exception:  # noqa: BLE001 - the client may already be gone; nothing is lost either way
            pass


# ----------------------------------------------------------------------------------------------------
# The campaign loop


@dataclass(frozen=True)
class RunInfo:
    """What one invocation did (the machine-dependent ``"run"`` block of a summary)."""

    backend: str
    workers: int
    kept_before: int
    ran: int
    wall_s: float

    def to_dict(self) -> dict[str, Any]:
        return {"backend": self.backend, "workers": self.workers, "resumed_with": self.kept_before, "trials_run": self.ran,
                "wall_s": self.wall_s}


@contextmanager
def _sigterm_as_interrupt():
    """SIGTERM (a batch scheduler's preemption) stops a campaign like Ctrl-C, keeping what finished."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(_signum, _frame):
        raise KeyboardInterrupt

    old = signal.signal(signal.SIGTERM, handler)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def run_campaign(
    campaign: Campaign,
    store,
    *,
    workers: int | None = None,
    dask: str | None = None,
    progress: Callable[[int, int], None] | None = None,
) -> RunInfo:
    """Run the trials of ``campaign`` that are not in ``store`` yet, committing each as it finishes.

    Parameters
    ----------
    store:
        An open :class:`stressbots.store.TrialStore` (its settings already checked against this campaign).
    workers:
        Local processes (default every core, at most the trials to run; ``1`` runs in this process), or
        the LocalCluster's size with ``dask="local"``.
    dask:
        ``None`` (local), ``"local"``, a scheduler address or a scheduler file (:func:`dask_client`).
    progress:
        ``progress(done, total)`` after every committed trial (``done`` counts the kept ones too).

    Raises
    ------
    CampaignInterrupted
        On Ctrl-C / SIGTERM, after stopping the workers; every finished trial is in the store.
    """
    if workers is not None and workers < 1:
        raise StressbotsError(f"must be at least 1, got {workers}", source="--workers")
    t0 = time.perf_counter()
    done = store.done()
    tasks = campaign.tasks(done)
    total = campaign.total
    kept = total - len(tasks)
    if progress is not None:
        progress(kept, total)
    ran = 0
    try:
        with _sigterm_as_interrupt():
            if dask is not None:
                k = int(workers or os.cpu_count() or 1) if dask == "local" else 0
                backend = f"dask {dask}"
                with dask_client(dask, workers) as client:
                    if dask != "local":
                        k = len(client.scheduler_info().get("workers", {}))
                    token = hashlib.sha256(repr(sorted(store.settings.items())).encode()).hexdigest()[:12]
                    ran = _consume(_dask(campaign, tasks, client, token), store, campaign, kept, total, progress) if tasks else 0
            else:
                k = max(1, min(int(workers or os.cpu_count() or 1), len(tasks)))
                backend = "processes" if k > 1 else "in-process"
                stream = _pool(campaign, tasks, k) if k > 1 else _inline(campaign, tasks)
                ran = _consume(stream, store, campaign, kept, total, progress)
    except KeyboardInterrupt:
        raise CampaignInterrupted(len(store), total, None if str(store.path) == ":memory:" else store.path) from None
    return RunInfo(backend, k, kept, ran, time.perf_counter() - t0)


def _consume(stream, store, campaign: Campaign, kept: int, total: int, progress) -> int:
    ran = 0
    with closing(stream):
        for outcome, worker in stream:
            if store.record(outcome_row(outcome, campaign.trials, worker)):
                ran += 1
                if progress is not None:
                    progress(kept + ran, total)
    return ran
