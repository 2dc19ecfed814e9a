"""Generated scenarios (stressbots.generate): every slot inside the arena, starts clear of each other."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as hs

from stressbots.collision import arena_gap, disc_overlaps
from stressbots.electrostatics import analyse_scenario
from stressbots.generate import random_scenario
from stressbots.robots import orbit_radii, turning_centres
from stressbots.structures import target_structures


def _slots(scn) -> np.ndarray:
    order = analyse_scenario(scn).order_index
    assert order is not None  # generated designs are STRING
    st = target_structures([scn.robots[i] for i in order], scn.structure)[0] if scn.structure else None
    if st is None:
        return np.array([tuple(r.goal) for r in scn.robots])
    return st.goal_poses(scn.names)


@pytest.mark.parametrize(("n", "seed"), [(12, 1204), (13, 1221), (14, 1238), (16, 1272)])
def test_long_tees_fit_in_the_arena(n, seed):
    # these draws put a slot outside the default arena before the arena grew to fit the structure
    scn = random_scenario(n, seed, shape="tee", explicit_goals=seed % 2 == 1)
    gap = arena_gap(_slots(scn), scn.lengths_um, scn.widths_um, scn.arena_um)
    assert gap.min() >= 60.0 - 1e-6


@settings(max_examples=12, deadline=None)
@given(n=hs.integers(2, 9), seed=hs.integers(0, 10_000), shape=hs.sampled_from(["tee", "cross", "comb", "ladder"]))
def test_generated_slots_inside_and_orbits_disjoint(n, seed, shape):
    scn = random_scenario(n, seed, shape=shape)
    assert arena_gap(_slots(scn), scn.lengths_um, scn.widths_um, scn.arena_um).min() >= 60.0 - 1e-6
    rstar = orbit_radii(scn.lengths_um, scn.widths_um, scn.turn_radii_um)
    centres = turning_centres(scn.starts, scn.turn_radii_um)
    assert disc_overlaps(centres, rstar + 30.0) == []  # generated with a 60 um gap between discs


def test_a_given_arena_is_kept_or_refused_never_grown():
    """A caller's arena is never enlarged behind its back: roomy, the scenario keeps exactly that size; too crowded for
    the orbits, a RuntimeError says to make it larger (only the default arena grows by 10 % steps)."""
    roomy = random_scenario(3, 0, arena_um=(5000.0, 4000.0))
    assert roomy.arena_um == (5000.0, 4000.0)
    with pytest.raises(RuntimeError, match="make it larger"):
        random_scenario(6, 0, arena_um=(2600.0, 2600.0), max_tries=200)
