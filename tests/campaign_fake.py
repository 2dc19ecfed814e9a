"""A cheap, deterministic stand-in controller for campaign tests, importable by worker processes and by
the ``stressbots`` subprocesses the interruption tests kill.

``python -m tests.campaign_fake ARGS...`` runs the ``stressbots`` CLI with this controller (and a trivial
nominal plan); each trial takes ``STRESSBOTS_FAKE_TRIAL_S`` seconds of wall time (default 0.05) so that
a test can interrupt a campaign mid-way.
"""

from __future__ import annotations

import os
import sys
import time
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class FakeResult:
    """The fields of the controller's AssemblyResult that a campaign reads."""

    success: bool
    failure: str | None
    docked: np.ndarray
    shape_error_rms_um: float
    placement_error_um: np.ndarray
    heading_error_deg: np.ndarray
    duration_s: float
    replans: int


class FakePlan:
    """Stands for the nominal plan (picklable, compares equal to itself only by type)."""

    duration_s = 10.0
    steps = ()

    def __eq__(self, other):
        return isinstance(other, FakePlan)

    def __hash__(self):
        return 1


def fake_plan(scenario, **_):
    return FakePlan()


def fake_assemble(scenario, plant, *, seed=None, plan=None, time_budget_s=None, options=None):
    """Outcome drawn from the seed; failure more likely with more noise and a longer replan interval."""
    assert plant.seed == seed, "the plant must be built with the trial's seed"
    time.sleep(float(os.environ.get("STRESSBOTS_FAKE_TRIAL_S", "0.05")))
    rng = np.random.default_rng([seed, 99])
    level = scenario.noise.speed_rel_sd / 0.05 + scenario.control.replan_interval_s / 4.0
    ok = bool(rng.random() >= min(1.0, 0.1 + 0.3 * level))
    n = scenario.n
    err = rng.gamma(2.0, 2.0 + 3.0 * level, n)
    failure = None if ok else ("stuck in H" if rng.random() < 0.5 else f"shape error {20 + 10 * rng.random():.1f} um RMS exceeds 20 um")
    clearance = getattr(options, "clearance_um", None)
    if clearance is not None and clearance > 30 and ok:
        ok, failure = False, "no clear track"
    return FakeResult(ok, failure, np.full(n, ok), float(err.mean()), err, err / 10, float(100 + 50 * rng.random()),
                      int(rng.integers(5, 30)))


def dying_assemble(scenario, plant, **kwargs):
    """The real controller, except that the first trial to start kills its worker process (hard, as a
    node failure would) when ``STRESSBOTS_DIE_ONCE`` names a marker file that does not exist yet."""
    marker = os.environ.get("STRESSBOTS_DIE_ONCE")
    if marker:
        try:
            with open(marker, "x"):
                pass
        except FileExistsError:
            pass
        else:
            os._exit(1)
    from stressbots.control import assemble

    return assemble(scenario, plant, **kwargs)


def install(monkeypatch=None) -> None:
    """Make the montecarlo and study commands use the fake controller and plan."""
    from stressbots import montecarlo as mc

    if monkeypatch is None:
        mc.default_assemble = lambda: fake_assemble
        mc.default_planner = lambda: fake_plan
    else:
        monkeypatch.setattr(mc, "default_assemble", lambda: fake_assemble)
        monkeypatch.setattr(mc, "default_planner", lambda: fake_plan)


if __name__ == "__main__":
    install()
    from stressbots.cli import main

    main(sys.argv[1:])
