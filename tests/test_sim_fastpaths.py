"""The simulator's plain-float fast paths and caches give the array forms' results to the last bit."""

from __future__ import annotations

import numpy as np
import pytest

from stressbots.generate import LITERATURE_NOISE, random_scenario
from stressbots.sim import SimulatedPlant
from stressbots.sim.search import drift_poses, drift_poses_one


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_drift_poses_at_one_time_are_the_array_forms_bit_for_bit(seed):
    """``drift_poses_one`` (plain floats) against ``drift_poses`` asked for the same time twice (arrays)."""
    scn = random_scenario(4, 900 + seed, shape="tee", noise=LITERATURE_NOISE.scaled(3.0))
    plant = SimulatedPlant(scn, seed=seed)
    b, drift = plant._bodies, plant._drift
    rng = np.random.default_rng(seed)
    idx = np.arange(4)
    for _ in range(50):
        b.odo = rng.uniform(0.0, 3000.0, 4) * (rng.random(4) < 0.8)
        speed = rng.uniform(20.0, 150.0, 4)
        kappa = np.where(rng.random(4) < 0.5, 1.0 / rng.uniform(100.0, 400.0, 4), 0.0)
        tau = float(rng.choice([0.0, 1e-9, rng.uniform(0.0, 2.0)]))
        fast = drift_poses_one(b, drift, b.pose, idx, speed, kappa, tau)
        slow = drift_poses(b, drift, b.pose, idx, speed, kappa, np.array([tau, tau]))[0]
        assert np.array_equal(fast, slow)
