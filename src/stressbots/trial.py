"""One closed-loop trial of a campaign and its seed: the unit that Monte Carlo runs, studies and the
trial store share (:mod:`stressbots.montecarlo`, :mod:`stressbots.campaign`, :mod:`stressbots.store`).

A trial builds a fresh :class:`stressbots.sim.SimulatedPlant` from its own seed and lets a controller
assemble the structure through it; :class:`TrialOutcome` is what is kept of it. Trial ``k`` of a
campaign seeded ``seed`` always gets ``trial_seeds(seed, N)[k]``, so outcomes do not depend on which
worker ran it or when.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

import numpy as np

__all__ = ["TrialOutcome", "run_trial", "trial_seeds"]

def trial_seeds(seed: int, trials: int) -> list[int]:
    """Integer seeds of trials ``0..trials-1``: ``SeedSequence(seed).spawn(trials)[i]``, 53 bits each.

    Spawned children are independent streams; trial ``i``'s seed does not depend on ``trials`` beyond
    ``i < trials`` (spawning is sequential), so a longer study extends a shorter one.
    """
    if int(seed) < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    children = np.random.SeedSequence(int(seed)).spawn(int(trials))
    return [int(c.generate_state(1, np.uint64)[0] >> np.uint64(11)) for c in children]


# One trial


@dataclass(frozen=True)
class TrialOutcome:
    """What one closed-loop trial produced (reduced from the controller's ``AssemblyResult``).

    ``placement_error_um`` and ``heading_error_deg`` are the largest over the robots; ``error`` holds
    the exception when the trial raised instead of returning (then ``success`` is False). ``wall_s``
    is the only field that varies between identical runs. ``index`` is the trial's number within its
    ``cell`` (a noise scale of a sweep, a grid point of a study; :mod:`stressbots.campaign`).
    """

    index: int
    seed: int
    noise_scale: float
    success: bool
    failure: str | None
    shape_error_rms_um: float
    placement_error_um: float
    heading_error_deg: float
    duration_s: float
    replans: int
    docked: int
    robots: int
    error: str | None = None
    wall_s: float = field(default=0.0, compare=False)
    cell: int = 0

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def _maxf(x) -> float:
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    a = a[np.isfinite(a)]
    return float(a.max()) if a.size else math.nan


def run_trial(scenario, plan, index: int, seed: int, assemble: Callable, *, noise_scale: float = 1.0, time_budget_s: float | None = None,
              controller: dict[str, Any] | None = None, cell: int = 0) -> TrialOutcome:
    """Run one closed-loop trial: ``assemble(scenario, SimulatedPlant(scenario, seed=seed), seed=seed, plan=plan)``.

    ``controller`` adds keyword arguments (``options=``, ``strategy=``: :func:`stressbots.campaign.controller_kwargs`).
    An exception inside the trial becomes a failed outcome naming it (one bad trial does not end the
    study); the study reports how many trials raised.
    """
    from .sim import SimulatedPlant

    t0 = time.perf_counter()
    n = scenario.n
    try:
        plant = SimulatedPlant(scenario, seed=seed)
        kwargs: dict[str, Any] = {"seed": seed, "plan": plan, **(controller or {})}
        if time_budget_s is not None:
            kwargs["time_budget_s"] = time_budget_s
        res = assemble(scenario, plant, **kwargs)
    except Exception as exc:  # noqa: BLE001 - a trial's crash is data, reported in the summary
        msg = f"{type(exc).__name__}: {exc}"
        return TrialOutcome(index, seed, noise_scale, False, f"exception: {msg}", math.nan, math.nan, math.nan, math.nan, 0, 0, n, msg,
                            time.perf_counter() - t0, cell)
    docked = np.asarray(res.docked, dtype=bool)
    return TrialOutcome(
        index=int(index),
        seed=int(seed),
        noise_scale=float(noise_scale),
        success=bool(res.success),
        failure=None if res.failure is None else str(res.failure),
        shape_error_rms_um=float(res.shape_error_rms_um),
        placement_error_um=_maxf(res.placement_error_um),
        heading_error_deg=_maxf(res.heading_error_deg),
        duration_s=float(res.duration_s),
        replans=int(res.replans),
        docked=int(docked.sum()),
        robots=n,
        error=None,
        wall_s=time.perf_counter() - t0,
        cell=int(cell),
    )
