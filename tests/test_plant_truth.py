"""Success as SPEC 6 counts it: every robot docked by the plant, not only by the controller's verdict.

A robot stopped against a structure corner a few degrees off flush sits within the controller's docking tolerances of
its slot, so the controller counts it docked; the plant knows better. The run's judge (``judge_run``) and the
generality benchmark's (``bench_generality.judge_truth``) both ask a plant that can tell.
"""

from __future__ import annotations

import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from stressbots.control.result import judge_run
from stressbots.generate import random_scenario

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import bench_generality  # noqa: E402

SCN = random_scenario(3, 5, shape="tee")


def _goals() -> np.ndarray:
    """Some target poses (3, 3): where the robots start will do, the judge only compares final with target."""
    starts = [r.start for r in SCN.robots]
    assert all(p is not None for p in starts)
    return np.array([(p.x, p.y, p.theta) for p in starts if p is not None], dtype=np.float64)


def _judge(plant):
    g = _goals()
    return judge_run(SCN, plant, seed=0, failure=None, estimates=g, goals=g, nominal_goals=g, docked=np.ones(3, bool),
                     shape_tol_um=10.0, duration_s=1.0, replans=0, events=(), trace_t=np.zeros(0),
                     trace_poses=np.zeros((0, 3, 3)))


@pytest.mark.parametrize("plant_docked", [[True, True, True], [True, False, True]])
def test_a_robot_the_plant_did_not_dock_fails_the_run(plant_docked):
    plant = SimpleNamespace(true_poses=_goals, docked=np.array(plant_docked))
    r = _judge(plant)
    assert r.success is all(plant_docked)
    assert r.docked.tolist() == plant_docked
    if not all(plant_docked):
        assert r.failure.startswith(f"the plant did not dock {SCN.names[1]}:")


def test_a_plant_that_cannot_tell_leaves_the_controllers_verdict():
    assert _judge(SimpleNamespace(true_poses=_goals)).success  # no `docked`: the controller's word stands
    assert _judge(SimpleNamespace()).success  # no truth at all (lab hardware): estimates and verdicts


@pytest.mark.parametrize(("docked", "shift_um", "why"), [
    ([True, True, True], 0.0, None),
    ([True, True, False], 0.0, "never docked"),
    ([True, True, True], 30.0, "true shape error"),
])
def test_the_benchmark_judges_a_claimed_success_from_the_simulators_truth(docked, shift_um, why):
    g = _goals()
    true = g.copy()
    true[0, 0] += shift_um
    sim = SimpleNamespace(docked=np.array(docked), true_poses=lambda: true)
    got = bench_generality.judge_truth(SimpleNamespace(nominal_goals=g), sim, SCN, 10.0)
    assert (got is None) if why is None else (why in got)
    if why == "never docked":
        assert SCN.names[2] in got


def test_the_wrapped_simulators_of_simulate_and_the_image_camera_say_which_robots_they_docked():
    """``simulate``, the demo and ``--camera images`` wrap the simulator; the judge can ask them which robots it docked
    only if they pass ``docked`` on (else a robot stuck off flush passes as docked there and fails in montecarlo)."""
    from stressbots.lab.plants import SyntheticLab
    from stressbots.pipeline import _WatchedPlant
    from stressbots.sim import SimulatedPlant
    from stressbots.waveform import Drive

    sim = SimulatedPlant(SCN, seed=0)
    sim.apply([Drive(0.0, 1.0, 0.5)])
    for wrapped in (_WatchedPlant(sim, None), SyntheticLab(SCN, plant=sim)):
        assert np.array_equal(wrapped.docked, sim.docked)
        assert np.array_equal(wrapped.true_poses(), sim.true_poses())
