"""Error bounds (seed App. 3.4): delta(t) against closed forms, cylinders, the forward projection, A_i*,
fine-motion cones, the empirical check against the simulator, and the ``bounds`` command.

Truth here is independent of the implementation where it can be: turn-rate and drift formulas written
out by hand, the kinematics module's own integrator, :func:`stressbots.paths.arc_through`, random error
values inside the box, and the simulator.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from stressbots import bounds as B
from stressbots.kinematics import trajectory
from stressbots.outputs import to_json
from stressbots.paths import arc_through, interpolated_arc, interpolated_radius
from stressbots.planning import plan_assembly
from stressbots.scenario import Noise, load, loads

from .conftest import EXAMPLES, assert_user_error

LIT = Noise(speed_rel_sd=0.05, turn_radius_rel_sd=0.03, heading_drift_rad_per_um=math.radians(3.7) / 1000.0,
            camera_position_sd_um=2.0, camera_heading_sd_rad=math.radians(1.0), camera_dropout=0.02)
V, R = 100.0, 200.0


@pytest.fixture(scope="module")
def four():
    return load(EXAMPLES / "four-robots.toml")


@pytest.fixture(scope="module")
def structure(four):
    return plan_assembly(four).structure


def coarse(scn, structure, **kw):
    return B.analyse_bounds(scn, structure=structure, spacing_um=40.0, heading_step_deg=10.0, levels=3, **kw)


# ----------------------------------------------------------------------------------------------------
# the error model and delta(t)


def test_error_model_is_the_k_sigma_box_of_the_noise():
    m = B.ErrorModel.from_noise(LIT, 3.0)
    assert m.speed_rel == pytest.approx(3 * 0.05 * 1.2) and m.radius_rel == pytest.approx(3 * 0.03 * 1.2)
    assert m.drift_rad_per_um == pytest.approx(3 * math.radians(3.7) / 1000)
    assert m.camera_position_um == 6.0 and m.camera_heading_rad == pytest.approx(math.radians(3.0))
    assert B.ErrorModel.from_noise(Noise(), 3.0).is_zero
    g = m.samples(5)
    assert g.shape == (125, 3) and np.isclose(g[:, 0].max(), 0.18) and np.isclose(g[:, 2].min(), -m.drift_rad_per_um)
    assert B.ErrorModel.from_noise(Noise(), 3.0).samples(5).shape == (1, 3)
    with pytest.raises(ValueError):
        B.ErrorModel.from_noise(LIT, -1.0)


def test_bounds_share_the_simulators_constants():
    from stressbots import sim

    assert B.SEGMENT_JITTER == sim.SEGMENT_JITTER
    assert B.STICKING_CONE_RAD == sim.STICKING_CONE_RAD
    assert B.SELF_ALIGN_MAX_INCIDENCE_RAD == sim.SELF_ALIGN_MAX_INCIDENCE_RAD
    assert B.SELF_ALIGN_MAX_OFFSET_UM == sim.SELF_ALIGN_MAX_OFFSET_UM


def test_nominal_sequence_poses_match_the_kinematics_integrator():
    rng = np.random.default_rng(3)
    turning = rng.random(12) < 0.5
    durs = rng.uniform(0.1, 2.0, 12)
    start = np.array([100.0, -50.0, 1.0])
    times, ref = trajectory(start, turning[:, None], durs, V, R)
    ours = B.sequence_poses(start, turning, durs, V, R, np.zeros((1, 3)), times)[0]
    assert np.allclose(ours, ref[:, 0], atol=1e-9)


def test_zero_noise_gives_zero_bounds():
    m = B.ErrorModel.from_noise(Noise(), 3.0)
    for seq in (B.turning_sequence(20.0), B.straight_sequence(20.0), B.s2f_sequence(0.4, 20.0, 1.0)):
        c = B.deviation_envelope(seq, V, R, m)
        assert np.all(c.xy_um == 0) and np.all(c.theta_rad == 0)
    cyl = B.cylinder(V, R, m)
    assert cyl.radius_um == 0 and cyl.height_rad == 0
    assert B.turn_time(2 * math.pi, V, R, m) == pytest.approx(2 * math.pi * R / V)


def test_delta_grows_monotonically():
    m = B.ErrorModel.from_noise(LIT, 3.0)
    rng = np.random.default_rng(0)
    for _ in range(5):
        k = 8
        seq = B.PrimitiveSequence("random", rng.random(k) < 0.5, rng.uniform(0.2, 3.0, k))
        c = B.deviation_envelope(seq, V, R, m)
        for arr in (c.xy_um, c.theta_rad, c.across_um, c.along_um):
            assert np.all(np.diff(arr) >= 0)
        assert np.all(c.xy_um <= np.hypot(c.across_um, c.along_um) + 1e-9)
    # and grows with the noise level
    small = B.deviation_envelope(B.turning_sequence(10.0), V, R, B.ErrorModel.from_noise(LIT.scaled(0.5), 3.0))
    big = B.deviation_envelope(B.turning_sequence(10.0), V, R, m)
    assert np.all(small.xy_um <= big.xy_um + 1e-9) and big.end[0] > small.end[0]


def test_straight_bound_matches_the_analytic_heading_error():
    """Driving straight, only the drift turns the robot: delta_theta(t) = d s + c sqrt(s) (bias and random
    walk) over the longest distance s = (1 + a) v t, and the lateral error is the bias arc's offset
    (1 - cos(d s)) / d plus the walk's (2/3) c s^1.5."""
    m = B.ErrorModel.from_noise(LIT, 3.0)
    a, d, cw = m.speed_rel, m.drift_rad_per_um, m.drift_walk_rad_per_sqrt_um
    assert cw == pytest.approx(3 * math.radians(3.7) / 1000 * math.sqrt(0.5 * 1000))  # k sd sqrt((1 - f) S)
    t = np.linspace(0.0, 30.0, 31)
    c = B.deviation_envelope(B.straight_sequence(30.0), V, R, m, times_s=t)
    s = (1 + a) * V * t
    assert np.allclose(c.theta_rad, d * s + cw * np.sqrt(s), rtol=1e-12, atol=1e-15)
    assert np.allclose(c.across_um, (1 - np.cos(d * s)) / d + (2 / 3) * cw * s**1.5, rtol=1e-9)
    assert np.all(c.along_um >= a * V * t - 1e-9)


def test_turning_bound_matches_the_analytic_turn_rate_error():
    m = B.ErrorModel.from_noise(LIT, 2.0)
    a, b, d = m.speed_rel, m.radius_rel, m.drift_rad_per_um
    w = V / R
    w_hi = V * (1 + a) * (1 / (R * (1 - b)) + d)
    w_lo = V * (1 - a) * (1 / (R * (1 + b)) - d)
    assert B.turn_rate_range(V, R, m) == pytest.approx((w_lo, w_hi))
    t = np.linspace(0.0, 40.0, 41)
    c = B.deviation_envelope(B.turning_sequence(40.0), V, R, m, times_s=t)
    walk = m.drift_walk_rad_per_sqrt_um * np.sqrt((1 + a) * V * t)
    assert np.allclose(c.theta_rad, max(w_hi - w, w - w_lo) * t + walk, rtol=1e-12)  # unwrapped: beyond pi too
    assert B.turn_time(2 * math.pi, V, R, m) == pytest.approx(2 * math.pi / w_lo)


def test_random_errors_inside_the_box_stay_inside_delta():
    m = B.ErrorModel.from_noise(LIT, 3.0)
    rng = np.random.default_rng(7)
    k = 10
    seq = B.PrimitiveSequence("mix", rng.random(k) < 0.5, rng.uniform(0.3, 2.0, k))
    c = B.deviation_envelope(seq, V, R, m)
    lo = np.array([m.speed_factors[0] - 1, m.radius_factors[0] - 1, -m.drift_rad_per_um])
    hi = np.array([m.speed_factors[1] - 1, m.radius_factors[1] - 1, m.drift_rad_per_um])
    errs = lo + (hi - lo) * rng.random((400, 3))
    nom = B.sequence_poses((0, 0, 0), seq.turning, seq.durations_s, V, R, np.zeros((1, 3)), c.times_s, unwrapped=True)[0]
    p = B.sequence_poses((0, 0, 0), seq.turning, seq.durations_s, V, R, errs, c.times_s, unwrapped=True)
    dxy = np.hypot(p[..., 0] - nom[:, 0], p[..., 1] - nom[:, 1])
    dth = np.abs(p[..., 2] - nom[:, 2])
    assert np.all(dxy <= c.xy_um * (1 + 1e-9) + 1e-9)
    assert np.all(dth <= c.theta_rad * (1 + 1e-9) + 1e-12)


def test_s2f_sequence_durations_and_mean_radius():
    seq = B.s2f_sequence(0.25, 10.0, 0.8)
    assert seq.duration_s == pytest.approx(10.0) and seq.turn_fraction == pytest.approx(0.25)
    with pytest.raises(ValueError):
        B.s2f_sequence(1.5, 10.0, 1.0)


# ----------------------------------------------------------------------------------------------------
# C_alpha,i and the timed forward projection


def test_cylinder_of_camera_noise_only_is_the_camera_bound():
    m = B.ErrorModel.from_noise(Noise(camera_position_sd_um=2.0, camera_heading_sd_rad=0.01), 3.0)
    cyl = B.cylinder(V, R, m)
    assert cyl.radius_um == pytest.approx(math.sqrt(2) * 6.0) and cyl.height_rad == pytest.approx(0.03)
    assert cyl.motion_radius_um == 0 and cyl.t_2pi_s == pytest.approx(2 * math.pi * R / V)


def test_cylinder_is_delta_at_t_2pi_over_the_sequence_family():
    m = B.ErrorModel.from_noise(LIT.scaled(0.3), 3.0)
    cyl = B.cylinder(V, R, m)
    t2 = B.turn_time(2 * math.pi, V, R, m)
    turn = B.deviation_envelope(B.turning_sequence(t2), V, R, m)
    assert cyl.t_2pi_s == pytest.approx(t2)
    assert cyl.motion_height_rad >= turn.end[1] - 1e-12 and cyl.motion_radius_um >= turn.end[0] - 1e-9
    assert cyl.radius_um == pytest.approx(cyl.motion_radius_um + math.sqrt(2) * m.camera_position_um)


def test_forward_projection_of_a_heading_uncertainty_is_the_lateral_offset():
    """No motion error, a start cylinder of radius 5 um and +-h: D_n's straight run of s = v t_4pi ends
    up to s sin(h) + 5 across and its heading error stays the start's h (the drift is zero)."""
    h = math.radians(4.0)
    start = B.Cylinder("n", 5.0, h, 1.0, 0.0, 0.0, 5.0, h, "-", "-")
    m = B.ErrorModel()
    fp = B.timed_forward_projection(V, R, 80.0, 150.0, m, start)
    t4 = 4 * math.pi * 150.0 / 80.0
    assert fp.t_4pi_s == pytest.approx(t4) and fp.straight_um == pytest.approx(V * t4)
    assert fp.across_um == pytest.approx(V * t4 * math.sin(h) + 5.0)
    assert fp.heading_rad == pytest.approx(h) and fp.radius_um >= fp.across_um - 1e-9


# ----------------------------------------------------------------------------------------------------
# fine motion, A_i*


def test_preimage_agrees_with_arc_through():
    rng = np.random.default_rng(11)
    m = B.ErrorModel()
    pos = rng.uniform(-800, 800, (300, 2))
    hd = rng.uniform(0, 2 * math.pi, 24)
    q = np.array([[0.0, 0.0]])
    got = B.fine_motion_preimage(pos, hd, q, 0.3, 0.5, R, m, clearance_samples=2)
    poses = np.concatenate([np.repeat(pos[:, None, :], hd.size, 1), np.broadcast_to(hd[None, :, None], (300, 24, 1))], axis=-1)
    arc = arc_through(poses, q[0])
    with np.errstate(invalid="ignore"):
        arrival = np.angle(np.exp(1j * (poses[..., 2] + arc.turn_rad - 0.3)))
        want = (arc.radius_um >= R) & (np.abs(arrival) < 0.5)
    want = np.where(np.isnan(arc.radius_um), False, want)
    assert np.array_equal(got, want) and 0 < want.sum() < want.size


def test_erosion_by_a_cylinder_on_a_synthetic_preimage():
    dx, step = 10.0, math.radians(5.0)
    xs = np.arange(-500, 501, dx)
    X, Y = np.meshgrid(xs, xs, indexing="ij")
    nh = 72
    disc = (np.hypot(X, Y) <= 300)[..., None] & (np.arange(nh) < 18)[None, None, :]  # headings [0, 90) deg
    out = B.erode(disc, dx, step, 100.0, math.radians(20.0))
    heads = np.flatnonzero(out.any(axis=(0, 1)))
    assert heads.min() == 4 and heads.max() == 13  # [20, 65] deg: 20 deg from both ends (85 is the last sample)
    kept = out[..., 8]
    d = np.hypot(X, Y)
    assert np.all(d[kept] <= 300 - 100 + 1e-9)  # never closer than r to the boundary
    assert np.all(kept[d <= 300 - 100 - 2 * dx])  # and nothing more than the discretisation removed
    assert not B.erode(disc, dx, step, 0.0, math.pi).any()  # every heading needed: none qualifies


def test_zero_noise_region_is_guaranteed_and_sound(four, structure):
    scn = four.with_noise(Noise())
    rep = coarse(scn, structure)
    assert all(r.guaranteed for r in rep.robots) and rep.guaranteed
    rb = rep.robot("B")  # docks against the stem: sticking cone 45 deg
    reg = rb.region
    import shapely

    co = structure.proximity_region("B")
    i, j, k = np.nonzero(reg.mask)
    assert not shapely.contains_xy(co, reg.xs_um[i], reg.ys_um[j]).any()  # outside C_O
    pos = np.stack([reg.xs_um[i], reg.ys_um[j]], -1)
    m = B.ErrorModel()
    ok = [B.fine_motion_preimage(pos[n:n + 1], reg.headings_rad[k[n]:k[n] + 1], rb.goal[None, :2], rb.goal[2],
                                 B.STICKING_CONE_RAD, R, m)[0, 0] for n in range(0, i.size, max(1, i.size // 200))]
    assert all(ok)
    ex = reg.example()
    assert ex is not None and np.hypot(*(ex[:2] - rb.goal[:2])) < 1500


def test_sampled_cylinders_around_region_poses_stay_in_the_preimage(four, structure):
    import shapely

    scn = four.with_noise(LIT.scaled(0.1))
    rep = coarse(scn, structure)
    rb = rep.robot("D")
    assert rb.guaranteed
    reg = rb.region
    m = rep.model
    co = structure.proximity_region("D")
    rng = np.random.default_rng(5)
    i, j, k = np.nonzero(reg.mask)
    pick = rng.choice(i.size, 20, replace=False)
    for n in pick:
        a = np.array([reg.xs_um[i[n]], reg.ys_um[j[n]], reg.headings_rad[k[n]]])
        rr = 0.5 * reg.erosion_radius_um * np.sqrt(rng.random(30))
        ph = rng.uniform(0, 2 * math.pi, 30)
        pts = a[:2] + np.stack([rr * np.cos(ph), rr * np.sin(ph)], -1)
        hs = a[2] + rng.uniform(-0.5, 0.5, 30) * reg.erosion_height_rad
        assert not shapely.contains_xy(co, pts[:, 0], pts[:, 1]).any()
        ok = np.array([B.fine_motion_preimage(pts[q:q + 1], hs[q:q + 1], rb.goal[None, :2], rb.goal[2], B.STICKING_CONE_RAD,
                                              reg.min_radius_um, m)[0, 0] for q in range(30)])
        assert ok.all()


def test_verdicts_follow_the_noise_level(four, structure):
    hi = coarse(four, structure)  # the literature's levels at 3 sigma: no guarantee
    assert not any(r.guaranteed for r in hi.robots)
    assert all("empty" in r.reason for r in hi.robots)
    assert "h_alpha" in hi.robot("B").reason
    low = coarse(four.with_noise(four.noise.scaled(0.1)), structure)
    assert low.robot("B").guaranteed and low.robot("D").guaranteed and low.robot("A").guaranteed
    n = low.robots[-1]
    assert n.role == "pair" and "forward projection" in n.reason
    doc = json.loads(to_json(low.to_dict()))
    assert doc["format"] == "stressbots.bounds/1" and len(doc["robots"]) == 4
    assert doc["robots"][0]["verdict"] == "guaranteed" and doc["robots"][0]["region"]["area_um2"] > 0


def test_critical_scale_is_the_upper_limit_without_noise(four, structure):
    scn = four.with_noise(Noise())
    scales = B.critical_noise_scales(scn, structure=structure, spacing_um=60.0, heading_step_deg=15.0, iterations=2)
    assert scales == {nm: 1.0 for nm in ("B", "D", "A", "C")}


# ----------------------------------------------------------------------------------------------------
# cones (seed Fig. 4)


def test_s2f_cone_contains_every_interpolated_arc():
    cone = B.s2f_cone(R)
    rng = np.random.default_rng(1)
    for rho in rng.uniform(0.02, 1.0, 20):
        r_prime = interpolated_radius(rho, R)
        turn = cone.length_um / r_prime
        pts = B.arc_points(r_prime, cone.length_um)
        assert cone.contains(pts).all()
        path = interpolated_arc((0, 0, 0), turn, r_prime, R, 20.0)
        assert cone.contains(path.nodes[::2, :2]).all()  # every cycle ends on the ideal arc
    tight = B.arc_points(0.8 * R, cone.length_um)  # tighter than the robot can turn: outside
    assert not cone.contains(tight[10:]).any()
    with pytest.raises(ValueError):
        B.fine_motion_cone(R, math.inf, 4 * R)


def test_s3f_cones_hold_their_duty_ranges():
    cone_n, cone_m = B.s3f_cones(R, 180.0)
    rng = np.random.default_rng(2)
    for rho_b in rng.uniform(1 / 3, 2 / 3, 10):  # D_{n-1}: rho_a = 1/3 fixed (D_n stays at 3 r)
        rp = interpolated_radius(1 / 3 + rho_b, 180.0)
        assert cone_m.contains(B.arc_points(rp, cone_m.length_um)).all()
    for rho_a in rng.uniform(1e-3, 1 / 3, 10):  # D_n: rho_a + rho_b = 2/3 fixed (D_{n-1} stays at 1.5 r)
        rp = interpolated_radius(rho_a, R)
        assert cone_n.contains(B.arc_points(rp, cone_n.length_um)).all()
    assert cone_m.radius_min_um == 180.0 and cone_m.radius_max_um == pytest.approx(270.0)
    assert cone_n.radius_min_um == pytest.approx(3 * R) and math.isinf(cone_n.radius_max_um)
    assert not cone_n.contains(B.arc_points(2 * R, cone_n.length_um)[20:]).any()


# ----------------------------------------------------------------------------------------------------
# empirical coverage


def test_simulated_open_loop_motion_stays_inside_the_bounds(four):
    cov = B.empirical_coverage(four, trials=3, seed=0, k=3.0)
    assert cov.fraction == 1.0 and cov.end_fraction == 1.0 and cov.ratio_max < 1.0
    t2 = B.turn_time(2 * math.pi, V, R, B.ErrorModel.from_noise(four.noise, 3.0))
    steps = math.ceil(t2 / four.control.replan_interval_s)  # Drives of <= t_x: turning, straight, random, 2 per S_2f cycle
    assert cov.checkpoints == 3 * 4 * 5 * steps
    assert set(cov.by_sequence) == {"turning", "straight", "S_2f(sym)", "random"}
    assert cov.plant.endswith("SimulatedPlant")


def test_coverage_check_can_fail():
    """At k = 0 the bound is the nominal motion: a noisy plant almost never stays inside it."""
    scn = loads('[[robots]]\nname = "a"\nsnap_down_V = 120.0\nrelease_V = 30.0\n[[robots]]\nname = "b"\n'
                'snap_down_V = 140.0\nrelease_V = 40.0\n[noise]\nspeed_rel_sd = 0.05\nturn_radius_rel_sd = 0.03\n')
    cov = B.empirical_coverage(scn, trials=2, seed=1, k=0.0)
    assert cov.fraction < 0.2


# ----------------------------------------------------------------------------------------------------
# the command


def test_bounds_command_writes_json_and_picture(run_cli, tmp_path):
    out = tmp_path / "b"
    r = run_cli("bounds", EXAMPLES / "four-robots.toml", "--out", out, "--coverage-trials", "1")
    assert r.code == 0, r.err
    assert "guaranteed" in r.out and "timed forward projection" in r.out and "empirical coverage" in r.out
    assert "between two measurements" in r.out
    # both drift terms of the error box: the bias (deg/mm) and the random walk (deg/sqrt(mm))
    line = " ".join(r.out.split())
    assert "drift bias +-" in line and "deg/mm plus random walk +-" in line and "deg/sqrt(mm)" in line
    doc = json.loads((out / "bounds.json").read_text())
    assert doc["format"] == "stressbots.bounds/1" and doc["error_model"]["k_sigma"] == 3.0
    assert [rb["verdict"] for rb in doc["robots"]] == ["not guaranteed"] * 4
    assert doc["coverage"]["fraction"] == 1.0
    tx = doc["robots"][0]["delta_replan_interval"]
    assert tx["t_x_s"] == 1.0 and 0 < tx["xy_um"] < doc["robots"][0]["cylinder"]["radius_um"]
    assert (out / "bounds.png").stat().st_size > 10_000
    j = run_cli("bounds", EXAMPLES / "four-robots.toml", "--json", "--k", "1")
    assert j.code == 0
    assert json.loads(j.out)["error_model"]["k_sigma"] == 1.0


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--k", "-1"], ["--k", ">= 0"]),
        (["--k", "nan"], ["--k"]),
        (["--coverage-trials", "-3"], ["--coverage-trials"]),
    ],
)
def test_bounds_rejects_bad_options(run_cli, args, needles):
    assert_user_error(run_cli("bounds", EXAMPLES / "four-robots.toml", *args), *needles)


def test_bounds_rejects_bad_scenarios(run_cli, tmp_path):
    assert_user_error(run_cli("bounds", tmp_path / "missing.toml"), "missing.toml", "no such file")
    two = '[[robots]]\nname = "a"\nsnap_down_V = 120.0\nrelease_V = 30.0\n[[robots]]\nname = "b"\nsnap_down_V = 140.0\nrelease_V = 40.0\n'
    p = tmp_path / "nogoal.toml"
    p.write_text(two)
    assert_user_error(run_cli("bounds", p), "goal")
    p1 = tmp_path / "one.toml"
    p1.write_text('[[robots]]\nname = "a"\nsnap_down_V = 120.0\nrelease_V = 30.0\ngoal = [0.0, 0.0, 0.0]\n')
    assert_user_error(run_cli("bounds", p1), "2 robots")
