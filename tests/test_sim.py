"""The simulated plant: protocol, motion against the closed form, noise model, camera, determinism,
zero-noise agreement with the planner on random scenarios, assessment, and ``stressbots simulate``.

Contact and compliance rules have their own file (test_contact.py).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from stressbots import kinematics as km
from stressbots.assessment import assess, kabsch_2d, placement_errors, shape_error
from stressbots.control import Plant
from stressbots.electrostatics import Electrodes
from stressbots.errors import PlanningError
from stressbots.generate import LITERATURE_NOISE, random_scenario
from stressbots.planning import plan_assembly
from stressbots.plans import save as save_plan
from stressbots.robots import Pose, Robot
from stressbots.scenario import Noise, Scenario, load
from stressbots.sim import SimulatedPlant, check_determinism, plan_waveform, run_plan
from stressbots.waveform import Drive, Hold, Segment, replay

from .conftest import EXAMPLES, assert_user_error

THRESHOLDS = [(120.0, 15.0), (140.0, 30.0), (160.0, 45.0), (185.0, 60.0)]


def far_scenario(poses_deg, noise=Noise(), speeds=None, radii=None) -> Scenario:
    """Robots far apart in an unbounded plane: no contact can happen."""
    n = len(poses_deg)
    speeds = speeds or [100.0, 130.0, 80.0, 150.0][:n]
    radii = radii or [200.0, 170.0, 240.0, 150.0][:n]
    robots = tuple(
        Robot(f"R{k}", *THRESHOLDS[k], speed_um_s=speeds[k], turn_radius_um=radii[k], start=Pose.from_degrees(*p))
        for k, p in enumerate(poses_deg)
    )
    return Scenario(name="far", robots=robots, electrodes=Electrodes(), arena_um=None, noise=noise)


FAR = [(0.0, 0.0, 10.0), (5000.0, 0.0, 100.0), (0.0, 5000.0, 200.0), (5000.0, 5000.0, 300.0)]


@pytest.fixture(scope="module")
def example_plan():
    """The example scenario without noise and its nominal plan."""
    sc = load(EXAMPLES / "four-robots.toml").with_noise(Noise())
    return sc, plan_assembly(sc)


# ----------------------------------------------------------------------------------------------------
# Protocol


def test_simulated_plant_and_a_plant_written_here_conform_to_the_protocol():
    class Bench:
        """A stand-in plant: remembers what it was sent, sees nothing."""

        def __init__(self):
            self.sent = []

        def observe(self):
            return np.full((2, 3), np.nan)

        def apply(self, waveform):
            self.sent.append(tuple(waveform))

    class Blind:
        def apply(self, waveform):
            pass

    assert isinstance(SimulatedPlant(far_scenario(FAR[:2]), seed=0), Plant)
    assert isinstance(Bench(), Plant)
    assert not isinstance(Blind(), Plant)
    plant = SimulatedPlant(far_scenario(FAR[:2]), seed=0)
    assert plant.observe().shape == (2, 3)
    assert plant.seed == 0


# ----------------------------------------------------------------------------------------------------
# Motion


@pytest.mark.parametrize("level", [None, 130.0, 150.0, 170.0, 190.0])
def test_free_motion_is_the_closed_form_of_the_decoded_arm_states(level):
    sc = far_scenario(FAR)
    wf = ([Hold(level, 0.001)] if level is not None else []) + [Drive(75.0, 105.0, 3.7)]
    turning = replay(wf, sc.snap_down_V, sc.release_V).drives[0].turning
    plant = SimulatedPlant(sc, seed=5)
    plant.apply(wf)
    expected = km.advance(sc.starts, turning, sc.speeds_um_s, sc.turn_radii_um, 3.7)
    np.testing.assert_allclose(plant.true_poses(), expected, atol=1e-9, rtol=0)
    assert plant.time_s == pytest.approx(3.7 + (0.001 if level else 0.0))
    assert plant.events == ()


def test_holds_move_nobody_and_arms_persist_between_applies():
    sc = far_scenario(FAR)
    plant = SimulatedPlant(sc, seed=0)
    plant.apply([Hold(150.0, 0.5), Hold(100.0, 0.5)])  # lowers R0, R1; 100 V keeps them
    np.testing.assert_array_equal(plant.true_poses(), km.wrap_pose(sc.starts))
    assert plant.arm_states.tolist() == [1, 1, 0, 0]
    plant.apply([Drive(75.0, 105.0, 2.0)])  # the arms set by the previous apply still hold
    expected = km.advance(sc.starts, [True, True, False, False], sc.speeds_um_s, sc.turn_radii_um, 2.0)
    np.testing.assert_allclose(plant.true_poses(), expected, atol=1e-9, rtol=0)


def test_flipped_and_chattering_arms_are_honoured():
    sc = far_scenario(FAR)
    # High level 150 V >= V_d of R0, R1: their raised arms snap down for the Drive (flip).
    plant = SimulatedPlant(sc, seed=0)
    plant.apply([Drive(75.0, 150.0, 2.0)])
    expected = km.advance(sc.starts, [True, True, False, False], sc.speeds_um_s, sc.turn_radii_um, 2.0)
    np.testing.assert_allclose(plant.true_poses(), expected, atol=1e-9, rtol=0)
    assert {e.robot for e in plant.events if e.kind == "arm_flip"} == {"R0", "R1"}
    # Band [10, 130] V: R0 snaps down on the high level and releases on the low one every cycle.
    plant = SimulatedPlant(sc, seed=0)
    plant.apply([Drive(10.0, 130.0, 2.0)])
    s = sc.speeds_um_s * 2.0
    np.testing.assert_allclose(plant.true_poses()[0], km.move(sc.starts[0], s[0], 0.5 / sc.turn_radii_um[0]), atol=1e-9)
    assert [e.robot for e in plant.events if e.kind == "arm_chatter"] == ["R0"]


# ----------------------------------------------------------------------------------------------------
# Noise model and camera


def test_per_run_factors_follow_the_scenario_sds():
    sc = far_scenario(FAR, noise=Noise(speed_rel_sd=0.05, turn_radius_rel_sd=0.03))
    f = np.array([SimulatedPlant(sc, seed=s).speed_factors for s in range(300)]).ravel()
    g = np.array([SimulatedPlant(sc, seed=s).radius_factors for s in range(300)]).ravel()
    assert abs(f.mean() - 1.0) < 0.01 and 0.045 < f.std() < 0.055
    assert abs(g.mean() - 1.0) < 0.006 and 0.027 < g.std() < 0.033


def test_speed_error_scales_the_distance_driven():
    sc = far_scenario(FAR, noise=Noise(speed_rel_sd=0.05))
    ratios = []
    for seed in range(200):
        plant = SimulatedPlant(sc, seed=seed)
        plant.apply([Drive(75.0, 105.0, 1.0)])  # all straight
        travel = np.hypot(*(plant.true_poses()[:, :2] - sc.starts[:, :2]).T)
        ratios.append(travel / (sc.speeds_um_s * plant.speed_factors))
    r = np.array(ratios).ravel()
    # per-segment jitter: sd = SEGMENT_JITTER * 5 % = 1 % around the per-run factor
    assert abs(r.mean() - 1.0) < 0.002 and 0.008 < r.std() < 0.012
    np.testing.assert_allclose(plant.true_poses()[:, 2], km.wrap(sc.starts[:, 2]), atol=1e-12)  # no drift, no turn


# Heading drift (a per-robot process of the distance driven) has its own file, test_drift.py.


def test_camera_noise_and_dropouts():
    noise = Noise(camera_position_sd_um=2.0, camera_heading_sd_rad=math.radians(1.0), camera_dropout=0.1)
    sc = far_scenario(FAR, noise=noise)
    plant = SimulatedPlant(sc, seed=3)
    truth = plant.true_poses()
    obs = np.array([plant.observe() for _ in range(2000)])
    missing = np.isnan(obs).any(axis=2)
    assert np.array_equal(missing, np.isnan(obs).all(axis=2))  # whole rows
    assert 0.085 < missing.mean() < 0.115
    seen = obs[~missing]
    err = seen - np.repeat(truth[None], 2000, axis=0)[~missing]
    err[:, 2] = (err[:, 2] + math.pi) % (2 * math.pi) - math.pi
    assert 1.9 < err[:, 0].std() < 2.1 and 1.9 < err[:, 1].std() < 2.1
    assert math.radians(0.95) < err[:, 2].std() < math.radians(1.05)
    assert (seen[:, 2] >= 0).all() and (seen[:, 2] < 2 * math.pi).all()
    np.testing.assert_array_equal(plant.true_poses(), truth)  # looking moves nothing


def test_observing_never_changes_the_motion():
    sc = far_scenario(FAR, noise=LITERATURE_NOISE)
    a, b = SimulatedPlant(sc, seed=9), SimulatedPlant(sc, seed=9)
    for k in range(4):
        for _ in range(k):
            a.observe()
        a.apply([Hold(150.0, 0.001), Drive(75.0, 105.0, 1.0)])
        b.apply([Hold(150.0, 0.001), Drive(75.0, 105.0, 1.0)])
    np.testing.assert_array_equal(a.true_poses(), b.true_poses())


def test_zero_noise_camera_sees_the_truth():
    plant = SimulatedPlant(far_scenario(FAR), seed=1)
    plant.apply([Drive(75.0, 105.0, 1.0)])
    np.testing.assert_array_equal(plant.observe(), plant.true_poses())


# ----------------------------------------------------------------------------------------------------
# Determinism


def _chunks(waveform, k):
    """A waveform cut into k consecutive pieces at segment boundaries."""
    cuts = np.linspace(0, len(waveform), k + 1).astype(int)
    return [waveform[a:b] for a, b in zip(cuts[:-1], cuts[1:], strict=True) if b > a]


def test_same_seed_is_bit_identical_and_copies_continue_identically(example_plan):
    sc, result = example_plan
    noisy = sc.with_noise(LITERATURE_NOISE)
    check_determinism(noisy, _chunks(plan_waveform(noisy, result.plan), 8), seed=11)


def test_different_seeds_differ(example_plan):
    sc, result = example_plan
    noisy = sc.with_noise(LITERATURE_NOISE)
    wf = plan_waveform(noisy, result.plan)[:12]
    a, b = SimulatedPlant(noisy, seed=1), SimulatedPlant(noisy, seed=2)
    a.apply(wf)
    b.apply(wf)
    assert not np.array_equal(a.true_poses(), b.true_poses())
    assert not np.array_equal(a.speed_factors, b.speed_factors)


def test_copy_is_independent_and_continues_bit_identically(example_plan):
    sc, result = example_plan
    noisy = sc.with_noise(LITERATURE_NOISE)
    wf = plan_waveform(noisy, result.plan)
    plant = SimulatedPlant(noisy, seed=4)
    plant.apply(wf[:10])
    twin = plant.copy()
    plant.apply(wf[10:])
    obs = plant.observe()
    assert twin.time_s < plant.time_s  # the copy did not move with the original
    twin.apply(wf[10:])
    assert twin.true_poses().tobytes() == plant.true_poses().tobytes()
    assert twin.observe().tobytes() == obs.tobytes()
    assert twin.events == plant.events


def test_check_determinism_reports_a_plant_that_is_not_reproducible():
    class Leaky(SimulatedPlant):
        """Draws camera noise from a source the seed does not control."""

        _global = np.random.default_rng()

        def observe(self):
            return super().observe() + self._global.normal(size=(self.n, 3))

    sc = far_scenario(FAR)
    with pytest.raises(AssertionError, match=r"waveform 0: two runs differ: observation of robot R0"):
        check_determinism(sc, [[Drive(75.0, 105.0, 1.0)]] * 2, seed=0, plant_factory=Leaky)


def _crowded(seed):
    """2-4 random robots crowded in a 1.2 mm arena, amplified literature noise, random waveforms
    (some with drive bands that flip or chatter arms)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 5))
    poses: list[np.ndarray] = []
    while len(poses) < n:
        p = np.array([rng.uniform(200, 1000), rng.uniform(200, 1000), rng.uniform(0, 2 * math.pi)])
        if all(np.hypot(*(p[:2] - q[:2])) > 300 for q in poses):
            poses.append(p)
    robots = tuple(
        Robot(f"R{k}", *THRESHOLDS[k], length_um=float(rng.uniform(200, 300)), width_um=float(rng.uniform(50, 80)),
              speed_um_s=float(rng.uniform(80, 150)), turn_radius_um=float(rng.uniform(150, 250)), start=Pose(*poses[k]))
        for k in range(n)
    )
    sc = Scenario("crowded", robots, Electrodes(), (1200.0, 1200.0), noise=LITERATURE_NOISE.scaled(3.0))
    wfs = []
    for _ in range(25):
        wf: list[Segment] = []
        for _ in range(int(rng.integers(1, 4))):
            if rng.random() < 0.6:
                wf.append(Hold(float(rng.choice([0, 25, 52, 130, 150, 170, 190])), 0.001))
            band = (75.0, 105.0) if rng.random() < 0.9 else (float(rng.choice([10, 75])), float(rng.choice([105, 130, 150])))
            wf.append(Drive(*band, float(rng.uniform(0.05, 1.5))))
        wfs.append(wf)
    return sc, wfs


@pytest.mark.parametrize("seed", range(6))
def test_crowded_random_runs_never_interpenetrate_and_repeat_bit_for_bit(seed):
    from stressbots.collision import outside_arena, pairwise_overlaps

    sc, wfs = _crowded(seed)
    a, b = SimulatedPlant(sc, seed=seed, record=True), SimulatedPlant(sc, seed=seed)
    for wf in wfs:
        a.apply(wf)
        b.apply(wf)
    assert a.true_poses().tobytes() == b.true_poses().tobytes() and a.events == b.events
    _, poses = a.trace()
    for p in poses:  # touching is allowed; a grazing pair may overlap by the 1e-4 um graze allowance
        assert not pairwise_overlaps(p, sc.lengths_um, sc.widths_um, tol_um=1.01e-4)
        assert not outside_arena(p, sc.lengths_um, sc.widths_um, sc.arena_um, tol_um=1.01e-4).any()
    assert a.events  # crowded enough that contacts happen


# ----------------------------------------------------------------------------------------------------
# Zero noise: planner, waveform and simulator agree


AGREEMENT_CASES = [
    (2, 1, "tee"),
    (2, 4, "tee"),
    (3, 0, "tee"),
    (3, 0, "cross"),
    (3, 3, "comb"),
    (3, 4, "ladder"),
    (4, 0, "tee"),
    (4, 1, "comb"),
    (4, 1, "cross"),
    (4, 0, "ladder"),
    (5, 2, "tee"),
    (5, 0, "comb"),
    (5, 3, "cross"),
    (5, 2, "ladder"),
]


@pytest.mark.parametrize("n, seed, shape", AGREEMENT_CASES)
def test_zero_noise_open_loop_docks_every_robot_at_its_goal(n, seed, shape):
    sc = random_scenario(n, seed, shape=shape)
    try:
        result = plan_assembly(sc)
    except PlanningError as exc:  # the planner may refuse a layout; that is its business
        pytest.skip(f"no plan: {exc}")
    plant = run_plan(sc, result.plan, seed=seed)
    goals = np.array([result.plan.goals[name] for name in sc.names])
    final = plant.true_poses()
    pos, head = placement_errors(final, goals)
    assert plant.docked.all(), plant.events
    assert pos.max() < 1e-6 and head.max() < 1e-6, (pos, head)
    np.testing.assert_allclose(final[:, :2], result.replay.final[:, :2], atol=1e-6)  # the planner's own replay
    kinds = {e.kind for e in plant.events}
    assert kinds <= {"self_align", "dock"}, plant.events  # nothing stuck, slid, blocked or outside
    holds_s = sum(s.duration_s for s in plan_waveform(sc, result.plan) if isinstance(s, Hold))
    assert plant.time_s == pytest.approx(result.plan.duration_s + holds_s)


LAYOUTS = sorted((EXAMPLES.parent / "tests" / "data" / "layouts").glob("*.toml"))


@pytest.mark.parametrize("path", LAYOUTS, ids=[p.stem for p in LAYOUTS])
def test_zero_noise_open_loop_docks_every_robot_of_larger_generated_layouts(path):
    """6-8 robots, every shape (and a tee or cross stem docking on a rear edge): generated layouts and the
    planner's own plans, written by ``benchmarks/bench_physics.py --write-layouts`` (planning them takes
    seconds to minutes, replaying them a fraction of a second). The wider sweep is that benchmark's."""
    from stressbots.plans import load as load_plan

    sc = load(path)
    plan = load_plan(path.with_suffix("").with_suffix(".plan.json"))
    plant = run_plan(sc, plan, seed=0)
    goals = np.array([plan.goals[name] for name in sc.names])
    pos, head = placement_errors(plant.true_poses(), goals)
    assert plant.docked.all(), [e for e in plant.events if e.kind not in ("dock", "self_align")]
    assert pos.max() < 1e-6 and head.max() < 1e-6, (pos, head)
    assert {e.kind for e in plant.events} <= {"self_align", "dock"}, plant.events


def test_layout_fixtures_cover_six_to_eight_robots_of_every_shape():
    have = {(p.stem.split("-")[0], int(p.stem.split("-")[1])) for p in LAYOUTS}
    assert have == {(shape, n) for shape in ("tee", "cross", "comb", "ladder") for n in (6, 7, 8)}


def test_open_loop_with_literature_noise_drifts_away(example_plan):
    sc, result = example_plan
    noisy = sc.with_noise(LITERATURE_NOISE)
    goals = np.array([result.plan.goals[name] for name in sc.names])
    errors = [placement_errors(run_plan(noisy, result.plan, seed=s).true_poses(), goals)[0].max() for s in range(4)]
    assert min(errors) > 50.0  # open loop cannot absorb a 5 % speed error over minutes of driving


# ----------------------------------------------------------------------------------------------------
# Assessment


def test_kabsch_recovers_a_rigid_motion_and_shape_error_ignores_it():
    rng = np.random.default_rng(0)
    pts = rng.uniform(0, 1000, (12, 2))
    phi = 0.7
    rot = np.array([[math.cos(phi), -math.sin(phi)], [math.sin(phi), math.cos(phi)]])
    moved = pts @ rot.T + [30.0, -50.0]
    r, t = kabsch_2d(pts, moved)
    np.testing.assert_allclose(r, rot, atol=1e-12)
    np.testing.assert_allclose(t, [30.0, -50.0], atol=1e-9)
    # a structure moved rigidly has no shape error but a placement error
    goals = np.array([[0.0, 0.0, 0.0], [0.0, 260.0, math.pi], [100.0, 130.0, 1.0]])
    c, s = math.cos(-0.3), math.sin(-0.3)
    xy = goals[:, :2] @ np.array([[c, -s], [s, c]]).T + [500.0, 20.0]
    final = np.column_stack([xy, goals[:, 2] + 0.3])  # ccw -0.3 rad = clockwise +0.3 in headings
    err = shape_error(final, goals, 260.0, 60.0)
    assert err.rms_um < 1e-9 and err.rotation_deg == pytest.approx(-math.degrees(0.3))
    pos, head = placement_errors(final, goals)
    assert pos.min() > 400 and head == pytest.approx(np.full(3, math.degrees(0.3)))


def test_assess_needs_every_robot_docked_and_the_shape_within_tolerance():
    goals = np.array([[0.0, 0.0, 0.0], [0.0, 260.0, math.pi]])
    near = goals + [[3.0, 0.0, 0.0], [0.0, 0.0, 0.0]]
    ok = assess(["a", "b"], near, goals, [True, True], 260.0, 60.0)
    assert ok.success and 1.0 < ok.shape.rms_um < 3.0
    assert not assess(["a", "b"], near, goals, [True, False], 260.0, 60.0).success
    assert not assess(["a", "b"], near, goals, [True, True], 260.0, 60.0, shape_tol_um=0.5).success
    rows = ok.robot_rows(observed=np.array([[1.0, 2.0, 0.0], [np.nan] * 3]))
    assert set(rows[0]) == {"name", "final", "goal", "docked", "position_error_um", "heading_error_deg", "observed"}
    assert rows[1]["observed"] is None and rows[0]["position_error_um"] == pytest.approx(3.0)


# ----------------------------------------------------------------------------------------------------
# CLI


@pytest.fixture(scope="module")
def plan_file(example_plan, tmp_path_factory):
    path = tmp_path_factory.mktemp("plan") / "plan.json"
    save_plan(example_plan[1].plan, path)
    return path


def test_cli_simulate_plan_without_noise_ends_exactly_in_the_slots(run_cli, plan_file, tmp_path):
    res = run_cli("simulate", EXAMPLES / "four-robots.toml", "--plan", plan_file, "--seed", "5", "--noise", "none", "--out",
                  tmp_path / "sim")
    assert res.code == 0, res.err
    data = json.loads((tmp_path / "sim" / "result.json").read_text())
    assert data["success"] is True and data["seed"] == 5
    assert [r["name"] for r in data["robots"]] == ["A", "B", "C", "D"]
    for r in data["robots"]:
        assert r["docked"] and r["position_error_um"] < 1e-6 and r["heading_error_deg"] < 1e-6
        assert len(r["final"]) == 3 and len(r["goal"]) == 3 and r["observed"] == pytest.approx(r["final"])
    assert data["shape_error"]["rms_um"] < 1e-6
    assert {e["kind"] for e in data["events"]} == {"self_align", "dock"}
    assert data["provenance"]["seed"] == 5 and "numpy" in data["provenance"]["versions"]
    assert (tmp_path / "sim" / "trajectory.png").stat().st_size > 10_000
    assert "success" in res.out


def test_cli_simulate_with_noise_reports_the_drift(run_cli, plan_file, tmp_path):
    res = run_cli("simulate", EXAMPLES / "four-robots.toml", "--plan", plan_file, "--noise", "literature", "--out", tmp_path / "sim", "-q")
    assert res.code == 0, res.err
    data = json.loads((tmp_path / "sim" / "result.json").read_text())
    assert data["success"] is False
    assert data["noise"]["heading_drift_deg_per_mm"] == pytest.approx(3.7)
    assert max(r["position_error_um"] for r in data["robots"]) > 50.0
    assert res.out == ""


# `stressbots simulate` without --plan (closed loop) is tested in test_report.py.


def test_cli_simulate_errors(run_cli, plan_file, tmp_path):
    scn = EXAMPLES / "four-robots.toml"
    assert_user_error(run_cli("simulate", scn, "--plan", tmp_path / "none.json", "--out", tmp_path / "o"), "none.json", "no such file")
    other = tmp_path / "other.json"
    data = json.loads(plan_file.read_text())
    data["robots"][0] = "Z"
    other.write_text(json.dumps(data))
    assert_user_error(run_cli("simulate", scn, "--plan", other, "--out", tmp_path / "o"), "other.json")
    assert_user_error(run_cli("simulate", tmp_path / "missing.toml", "--plan", plan_file, "--out", tmp_path / "o"), "missing.toml")
    assert_user_error(run_cli("simulate", scn, "--plan", plan_file, "--noise", "loud", "--out", tmp_path / "o"), "loud")
    assert_user_error(run_cli("simulate", scn, "--plan", plan_file, "--out", plan_file), "plan.json")
