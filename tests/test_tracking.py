"""Tracking (SPEC 9.2): poses from frames, against an independent supersampling renderer and the camera."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.generate import random_scenario
from stressbots.tracking import Calibration, locate

cv2 = pytest.importorskip("cv2")

from stressbots.lab.camera import Camera, ImageModel  # noqa: E402


def reference_render(poses, lengths, widths, cal: Calibration, shape, rng, *, sub=4, noise=5.0, blur_px=0.8,
                     arm_w=8.0, gap=6.0, frac=0.6):
    """An independent renderer of the SPEC 9.2 image model: hard-edged shapes on a grid ``sub`` times finer,
    averaged down to pixels (exact area coverage up to the grid), then blur and noise."""
    rows, cols = shape
    fine = np.full((rows * sub, cols * sub), 30.0)
    cc = (np.arange(cols * sub) + 0.5) / sub - 0.5
    rr = (np.arange(rows * sub) + 0.5) / sub - 0.5
    X = (cc[None, :] - cal.origin_px[0]) * cal.um_per_px
    Y = (cal.origin_px[1] - rr[:, None]) * cal.um_per_px
    for (x, y, th), L, W in zip(poses, lengths, widths, strict=False):
        h = np.array([math.sin(th), math.cos(th)])  # heading
        right = np.array([math.cos(th), -math.sin(th)])
        u = (X - x) * h[0] + (Y - y) * h[1]
        w = (X - x) * right[0] + (Y - y) * right[1]
        fine[(np.abs(u) <= L / 2) & (np.abs(w) <= W / 2)] = 200.0
        arm = (u >= -L / 2) & (u <= -L / 2 + frac * L) & (w >= W / 2 + gap) & (w <= W / 2 + gap + arm_w)
        fine[arm] = 200.0
    img = fine.reshape(rows, sub, cols, sub).mean(axis=(1, 3)).astype(np.float32)
    img = cv2.GaussianBlur(img, (0, 0), blur_px)
    img += noise * rng.standard_normal(img.shape).astype(np.float32)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def errors(true, est):
    d = np.hypot(*(true[:, :2] - est[:, :2]).T)
    a = np.degrees(np.abs((true[:, 2] - est[:, 2] + np.pi) % (2 * np.pi) - np.pi))
    return d, a


@pytest.fixture(scope="module")
def tee():
    """A 4-robot tee (equal bodies) with its assembled goal poses: robots touching."""
    return random_scenario(4, seed=3, shape="tee", explicit_goals=True, heterogeneous=False)


def _view(centre, upx, size_um=900.0):
    n = int(size_um / upx)
    return Calibration(upx, ((size_um / 2 - centre[0]) / upx, (centre[1] + size_um / 2) / upx)), (n, n)


@given(c0=st.floats(-1e3, 1e3), r0=st.floats(-1e3, 1e3), upx=st.floats(0.1, 20.0),
       x=st.floats(-1e4, 1e4), y=st.floats(-1e4, 1e4))
@settings(max_examples=50)
def test_calibration_round_trip(c0, r0, upx, x, y):
    cal = Calibration(upx, (c0, r0))
    col, row = cal.to_px(x, y)
    xx, yy = cal.to_um(col, row)
    assert math.isclose(float(xx), x, abs_tol=1e-6) and math.isclose(float(yy), y, abs_tol=1e-6)
    # rows grow downward: a point further up the arena is on a smaller row
    assert cal.to_px(x, y + 10.0)[1] < row


def test_isolated_robots_independent_renderer():
    sc = random_scenario(4, seed=1, shape="tee", heterogeneous=False)
    rng = np.random.default_rng(5)
    cal, shape = _view((450.0, 450.0), 2.0)
    D, A = [], []
    for _ in range(3):
        true = np.array([[200.0, 200.0, 0], [650.0, 230.0, 0], [220.0, 680.0, 0], [660.0, 640.0, 0]])
        true[:, :2] += rng.uniform(-30, 30, (4, 2))
        true[:, 2] = rng.uniform(0, 2 * np.pi, 4)
        frame = reference_render(true, sc.lengths_um, sc.widths_um, cal, shape, rng)
        est = locate(frame, sc, cal, previous=true + rng.normal(0, [15, 15, 0.2], (4, 3)))
        d, a = errors(true, est)
        D.extend(d)
        A.extend(a)
    assert np.median(D) <= 2.0 and np.median(A) <= 1.0
    assert np.max(A) < 5.0  # front and back never confused


def test_docked_structure_is_separated(tee):
    rng = np.random.default_rng(2)
    goals = tee.goals
    c = goals[:, :2].mean(axis=0)
    cal, shape = _view(c, 2.0)
    for ang in (0.3, 2.0):
        R = np.array([[math.cos(ang), math.sin(ang)], [-math.sin(ang), math.cos(ang)]])
        true = goals.copy()
        true[:, :2] = (goals[:, :2] - c) @ R.T + c
        true[:, 2] = (goals[:, 2] + ang) % (2 * np.pi)
        frame = reference_render(true, tee.lengths_um, tee.widths_um, cal, shape, rng)
        for prev in (true + rng.normal(0, [30, 30, 0.3], (4, 3)), None):
            est = locate(frame, tee, cal, previous=prev)
            d, a = errors(true, est)
            if prev is None:  # identities from start poses are arbitrary for a frame far from them: compare as sets
                from scipy.optimize import linear_sum_assignment

                r, k = linear_sum_assignment(np.hypot(true[:, None, 0] - est[None, :, 0], true[:, None, 1] - est[None, :, 1]))
                d, a = errors(true[r], est[k])
            assert np.median(d) <= 2.0 and np.median(a) <= 1.0, (d, a)
            assert d.max() < 5.0 and a.max() < 3.0


def test_front_back_from_the_arm():
    sc = random_scenario(2, seed=1, shape="pair", heterogeneous=False)
    cal, shape = _view((300.0, 300.0), 2.5, 600.0)
    cam = Camera(cal, shape, ImageModel())
    rng = np.random.default_rng(0)
    for th in (0.2, 1.9, 3.5, 5.5):
        true = np.array([[200.0, 300.0, th], [420.0, 330.0, th + math.pi]])
        # previous headings pointing the wrong way: the arm decides, not the previous pose
        prev = true.copy()
        prev[:, 2] += math.pi
        est = locate(cam.render(true, sc.lengths_um, sc.widths_um, rng), sc, cal, previous=prev)
        _, a = errors(true, est)
        assert a.max() < 2.0, (th, a)


def test_identities_follow_previous_through_a_close_pass():
    """Two robots drive past each other and touch; each frame's identities come from the previous ones."""
    sc = random_scenario(2, seed=4, shape="pair", heterogeneous=False)
    cal, shape = _view((400.0, 300.0), 3.0, 800.0)
    cam = Camera(cal, shape, ImageModel())
    rng = np.random.default_rng(3)
    W = sc.widths_um[0]
    prev = None
    for t in np.linspace(0.0, 1.0, 6):
        true = np.array([[150.0 + 500 * t, 300.0 - W / 2, math.pi / 2], [650.0 - 500 * t, 300.0 + W / 2, 3 * math.pi / 2]])
        est = locate(cam.render(true, sc.lengths_um, sc.widths_um, rng), sc, cal, previous=true if prev is None else prev)
        d, _ = errors(true, est)
        assert d.max() < 3.0, (t, d)
        prev = est


def test_dropout_gives_a_nan_row():
    sc = random_scenario(3, seed=1, shape="tee", heterogeneous=False)
    cal, shape = _view((400.0, 400.0), 3.0, 800.0)
    true = np.array([[150.0, 150.0, 0.4], [600.0, 200.0, 1.0], [300.0, 600.0, 2.0]])
    cam = Camera(cal, shape, ImageModel())
    frame = cam.render(np.where(np.arange(3)[:, None] == 1, np.nan, true), sc.lengths_um, sc.widths_um, np.random.default_rng(0))
    est = locate(frame, sc, cal, previous=true)
    assert np.isnan(est[1]).all() and np.isfinite(est[[0, 2]]).all()
    assert np.isnan(locate(np.full(shape, 30, np.uint8), sc, cal)).all()


def test_camera_renders_the_image_model():
    """Heading +y (theta 0): body x 170..230, y -30..230; the arm on the right (+x) 6 um off the body,
    x 236..244, from the rear edge y = -30 over 60 % of L to y = 126. Pixel (col, row) = (x, 200 - y)."""
    cal = Calibration(1.0, (0.0, 200.0))
    cam = Camera(cal, (200, 400), ImageModel(noise_sd=0.0, blur_um=0.0))
    f = cam.render(np.array([[200.0, 100.0, 0.0]]), [260.0], [60.0], np.random.default_rng(0)).astype(int)
    assert f[100, 200] == 200  # body
    assert f[150, 240] == 200 and f[150, 233] == 30  # arm (y = 50) and the dark gap between it and the body
    assert f[50, 240] == 30  # y = 150: in front of the arm's end
    assert f[150, 163] == 30  # left side: no arm
    assert f[150, 230] in (115, 116)  # a pixel centred on the body's edge is half lit (anti-aliased)
    noisy = Camera(cal, (200, 400), ImageModel()).render(np.zeros((0, 3)), [], [], np.random.default_rng(1))
    assert abs(noisy.mean() - 30.0) < 0.5 and 4.0 < noisy.std() < 8.0


def test_cli_track_folder_of_pngs(run_cli, tmp_path, tee):
    import csv

    from stressbots.scenario import to_toml
    from tests.conftest import assert_user_error

    scn = tmp_path / "tee.toml"
    scn.write_text(to_toml(tee))
    cal, shape = _view(tee.goals[:, :2].mean(axis=0), 3.0, 1200.0)
    folder = tmp_path / "frames"
    folder.mkdir()
    rng = np.random.default_rng(0)
    truth = []
    for k in range(2):
        true = tee.goals.copy()
        true[:, 0] += 20.0 * k
        truth.append(true)
        cv2.imwrite(str(folder / f"f{k}.png"), reference_render(true, tee.lengths_um, tee.widths_um, cal, shape, rng, sub=3))
    out = tmp_path / "poses.csv"
    r = run_cli("track", folder, "--scenario", scn, "--um-per-px", "3", "--origin-px", *map(str, cal.origin_px), "--out", out)
    assert r.code == 0, r.err
    rows = list(csv.DictReader(out.open()))
    assert [r_["robot"] for r_ in rows[:4]] == list(tee.names) and len(rows) == 8
    # the first frame's identities come from the start poses, far away: compare frame 1 against frame 0's labels
    got = {(int(r_["frame"]), r_["robot"]): (float(r_["x_um"]), float(r_["y_um"]), float(r_["heading_deg"])) for r_ in rows}
    for nm in tee.names:
        (x0, y0, h0), (x1, y1, h1) = got[(0, nm)], got[(1, nm)]
        assert abs(x1 - x0 - 20.0) < 2.0 and abs(y1 - y0) < 2.0 and abs((h1 - h0 + 180) % 360 - 180) < 1.0
    empty = tmp_path / "empty"
    empty.mkdir()
    assert_user_error(run_cli("track", empty, "--scenario", scn, "--um-per-px", "3", "--origin-px", "0", "0", "--out", out), "no .png")
    assert_user_error(run_cli("track", folder, "--scenario", scn, "--um-per-px", "-1", "--origin-px", "0", "0", "--out", out),
                      "--um-per-px")


def test_docstring_examples():
    import doctest

    from stressbots import tracking
    from stressbots.lab import camera

    assert doctest.testmod(tracking).failed == 0 and doctest.testmod(camera).failed == 0
