"""The closed-loop EDR controller (work in progress: issue 6).

What already holds, and is pinned here: without control error the controller assembles the example in
closed loop through the Plant protocol alone, and the result it reports agrees with the plant's truth.
"""

from __future__ import annotations

import numpy as np

from stressbots.assessment import shape_error
from stressbots.edr import assemble, nominal_plan
from stressbots.scenario import Noise, load
from stressbots.sim import SimulatedPlant

from .conftest import EXAMPLES


class ProtocolOnly:
    """A plant that offers nothing but ``observe`` and ``apply`` (no truth for the controller to peek at)."""

    def __init__(self, inner):
        self._inner = inner

    def observe(self):
        return self._inner.observe()

    def apply(self, waveform):
        self._inner.apply(waveform)


def test_closed_loop_without_noise_assembles_through_the_protocol():
    scn = load(EXAMPLES / "four-robots.toml").with_noise(Noise())
    plan = nominal_plan(scn)
    sim = SimulatedPlant(scn, seed=0)
    result = assemble(scn, ProtocolOnly(sim), seed=0, plan=plan)
    assert result.success, (result.failure, result.events)
    assert result.final_true is None  # the controller saw only the protocol
    truth = sim.true_poses()
    assert np.allclose(result.final_observed, truth, atol=1e-6)  # noiseless camera: estimate = truth
    independent = shape_error(truth, plan.plan.goal_array(), scn.lengths_um, scn.widths_um).rms_um
    assert independent < 5.0 and abs(independent - result.shape_error_rms_um) < 1e-9
    assert sim.docked.all()
    # the report carries the SPEC 7 result.json keys
    d = result.to_dict()
    assert {"success", "seed", "robots"} <= set(d) and all({"name", "final", "goal", "docked"} <= set(r) for r in d["robots"])
