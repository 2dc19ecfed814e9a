"""Heading drift is a per-robot process of the distance driven (SPEC 6, issue 11).

The truth here is statistical: with ``N`` independent robots the sample variance of a Gaussian drift
satisfies ``(N - 1) s^2 / sigma^2 ~ chi^2(N - 1)``, and the ratio of two independent sample variances
``F(N1 - 1, N2 - 1)``. Tolerances are those distributions' 1e-4 tails (the seeds are fixed, so the
tests are deterministic; the tails say how surprising a failure would be). The old model (a new drift
rate per Drive) fails the one-vs-forty test by a factor sqrt(40) in variance.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from stressbots.drift import DEFAULT_DRIFT, DriftModel, HeadingDrift, drift_variance
from stressbots.electrostatics import Electrodes
from stressbots.robots import Pose, Robot
from stressbots.scenario import Noise, Scenario
from stressbots.sim import SimulatedPlant
from stressbots.waveform import Drive, Hold

SIGMA = math.radians(3.7) / 1000.0  # the literature's 3.7 deg/mm, in rad/um
TAIL = 1e-4


def many_robots(n: int, *, speed=100.0, sigma=SIGMA, heading_deg=0.0) -> Scenario:
    """``n`` identical robots 3 mm apart on a line (no contact within a few mm of driving)."""
    robots = tuple(
        Robot(f"R{k}", 120.0, 15.0, speed_um_s=speed, turn_radius_um=200.0,
              start=Pose.from_degrees(3000.0 * k, 0.0, heading_deg))
        for k in range(n)
    )
    return Scenario(name="many", robots=robots, electrodes=Electrodes(), arena_um=None, noise=Noise(heading_drift_rad_per_um=sigma))


def heading_change(plant: SimulatedPlant, start_deg=0.0) -> np.ndarray:
    return (plant.true_poses()[:, 2] - math.radians(start_deg) + math.pi) % (2 * math.pi) - math.pi


def sd_interval(sd_true: float, n: int, tail: float = TAIL) -> tuple[float, float]:
    """Two-sided ``1 - tail`` interval of the sample sd of ``n`` normal draws with sd ``sd_true``."""
    lo, hi = stats.chi2.ppf([tail / 2, 1 - tail / 2], n - 1)
    return sd_true * math.sqrt(lo / (n - 1)), sd_true * math.sqrt(hi / (n - 1))


def test_one_mm_spread_is_the_scenarios_figure_whether_driven_as_one_drive_or_forty():
    n = 300
    sc = many_robots(n)
    one = SimulatedPlant(sc, seed=1)
    one.apply([Drive(75.0, 105.0, 10.0)])  # 1 mm at 100 um/s
    forty = SimulatedPlant(sc, seed=2)  # independent robots
    forty.apply([Drive(75.0, 105.0, 0.25)] * 40)
    d1, d40 = heading_change(one), heading_change(forty)
    lo, hi = sd_interval(SIGMA * 1000.0, n)
    assert lo < d1.std(ddof=1) < hi, math.degrees(d1.std(ddof=1))
    assert lo < d40.std(ddof=1) < hi, math.degrees(d40.std(ddof=1))
    f_lo, f_hi = stats.f.ppf([TAIL / 2, 1 - TAIL / 2], n - 1, n - 1)
    assert f_lo < d1.var(ddof=1) / d40.var(ddof=1) < f_hi
    np.testing.assert_allclose(one.odometer, 1000.0, rtol=1e-12)


@pytest.mark.parametrize("cuts", [[10.0], [0.25] * 40, [3.0, 0.013, 4.5, 0.987, 1.5], [0.07] * 142 + [0.06]])
def test_the_same_seed_gives_the_same_drift_however_the_motion_is_cut(cuts):
    """Same plant seed, any cut of 1 mm into Drives (and Holds in between): the same final poses."""
    sc = many_robots(12)
    ref = SimulatedPlant(sc, seed=7)
    ref.apply([Drive(75.0, 105.0, 10.0)])
    plant = SimulatedPlant(sc, seed=7)
    for k, t in enumerate(cuts):
        plant.apply([Drive(75.0, 105.0, t)] + ([Hold(50.0, 0.1)] if k % 2 else []))
    np.testing.assert_allclose(plant.odometer, 1000.0, rtol=1e-12)
    np.testing.assert_allclose(plant.true_poses()[:, :2], ref.true_poses()[:, :2], atol=1e-9, rtol=0)
    np.testing.assert_allclose(heading_change(plant), heading_change(ref), atol=1e-12, rtol=0)


def test_drift_is_the_integral_of_the_knot_curvatures_and_bends_the_path_accordingly():
    """The simulator's heading change equals the process's own integral; the path is the composed arcs."""
    sc = many_robots(5)
    plant = SimulatedPlant(sc, seed=3)
    plant.apply([Drive(75.0, 105.0, 7.3)])
    drift = HeadingDrift(5, SIGMA, np.random.SeedSequence(3).spawn(4)[3])  # the plant's named stream
    expected = np.array([drift.heading_change(i, 0.0, 730.0) for i in range(5)])
    np.testing.assert_allclose(heading_change(plant), expected, atol=1e-12, rtol=0)
    lengths, kappas = drift.segments(0, 0.0, 730.0)
    assert lengths.size == math.ceil(730.0 / DEFAULT_DRIFT.knot_um) and np.all(lengths <= DEFAULT_DRIFT.knot_um + 1e-9)
    x, y, th = 0.0, 0.0, 0.0  # composed arcs, written out
    for s, k in zip(lengths, kappas, strict=False):
        t = k * s
        x += (math.cos(th) - math.cos(th + t)) / k if k else 0.0
        y += (math.sin(th + t) - math.sin(th)) / k if k else s
        th += t
    np.testing.assert_allclose(plant.true_poses()[0, :2], [x, y], atol=1e-9)


def test_variance_grows_as_bias_plus_walk_and_the_split_is_the_documented_one():
    """Var over s is sigma^2 (f s^2 + (1 - f) s S); the first and second millimetres share the bias only."""
    n = 4000
    drift = HeadingDrift(n, SIGMA, np.random.SeedSequence(11))
    f = DEFAULT_DRIFT.bias_share
    for s in (25.0, 100.0, 1000.0):
        d = np.array([drift.heading_change(i, 0.0, s) for i in range(n)])
        lo, hi = sd_interval(math.sqrt(float(drift_variance(s, SIGMA))), n)
        assert lo < d.std(ddof=1) < hi, (s, d.std(ddof=1))
    first = np.array([drift.heading_change(i, 0.0, 1000.0) for i in range(n)])
    second = np.array([drift.heading_change(i, 1000.0, 1000.0) for i in range(n)])
    rho = np.corrcoef(first, second)[0, 1]  # Cov = f (sigma S)^2, Var = (sigma S)^2 each
    z = np.arctanh(rho) - np.arctanh(f)  # Fisher: sd 1 / sqrt(n - 3)
    assert abs(z) * math.sqrt(n - 3) < stats.norm.ppf(1 - TAIL / 2), rho
    np.testing.assert_allclose(drift.bias.std(ddof=1), math.sqrt(f) * SIGMA, rtol=0.1)


def test_other_knot_spacings_and_splits_keep_the_one_mm_figure():
    n = 3000
    for model in (DriftModel(knot_um=10.0, bias_share=0.0), DriftModel(knot_um=100.0, bias_share=1.0), DriftModel(knot_um=50.0,
                                                                                                                  bias_share=0.3)):
        drift = HeadingDrift(n, SIGMA, np.random.SeedSequence(5), model)
        d = np.array([drift.heading_change(i, 0.0, 1000.0) for i in range(n)])
        lo, hi = sd_interval(SIGMA * 1000.0, n)
        assert lo < d.std(ddof=1) < hi, (model, d.std(ddof=1))
    with pytest.raises(ValueError, match="bias_share"):
        DriftModel(bias_share=1.5)


def test_no_drift_means_no_draws_and_straight_lines():
    sc = many_robots(3, sigma=0.0)
    plant = SimulatedPlant(sc, seed=0)
    plant.apply([Drive(75.0, 105.0, 4.0)])
    np.testing.assert_array_equal(plant.true_poses()[:, 2], 0.0)
    np.testing.assert_allclose(plant.true_poses()[:, 1], 400.0, atol=1e-12)
    np.testing.assert_array_equal(plant.drift_bias, 0.0)


def test_a_robot_that_does_not_move_does_not_drift():
    """The odometer advances only with driving: a robot stopped against the arena edge keeps its heading."""
    robots = (Robot("A", 120.0, 15.0, start=Pose.from_degrees(500.0, 2700.0, 0.0)),)
    sc = Scenario(name="wall", robots=robots, electrodes=Electrodes(), arena_um=(1000.0, 3000.0),
                  noise=Noise(heading_drift_rad_per_um=SIGMA))
    plant = SimulatedPlant(sc, seed=4)
    plant.apply([Drive(75.0, 105.0, 3.0)])
    stopped = plant.true_poses()
    odo = plant.odometer.copy()
    assert plant.arena_hits[0] and odo[0] < 200.0
    plant.apply([Drive(75.0, 105.0, 3.0)])
    np.testing.assert_array_equal(plant.true_poses(), stopped)
    np.testing.assert_array_equal(plant.odometer, odo)


@pytest.mark.parametrize(("o0", "length"), [(0.0, 0.0), (0.0, 730.0), (12.5, 12.5), (24.999, 0.002), (50.0, 25.0),
                                            (1234.567, 333.3), (99.0, -5.0)])
def test_pieces_in_plain_floats_are_the_segments_bit_for_bit(o0, length):
    """``pieces`` (lists of floats, for the simulator's one-time fast path) equals ``segments``."""
    drift = HeadingDrift(3, SIGMA, np.random.SeedSequence(5))
    for i in range(3):
        lengths, kappas = drift.segments(i, o0, length)
        fl, fk = drift.pieces(i, o0, length)
        assert np.array_equal(np.array(fl), lengths) and np.array_equal(np.array(fk), kappas)
