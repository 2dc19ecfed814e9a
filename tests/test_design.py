"""STRING voltage design: optimality (against a linear program), feasibility limits, ties, yield, CLI."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st
from scipy.optimize import linprog

from stressbots.design import design_string, estimate_yield, max_robots
from stressbots.electrostatics import Electrodes, analyse_thresholds
from stressbots.errors import DesignError
from stressbots.scenario import load, loads
from stressbots.waveform import decode, synthesize

from .conftest import assert_user_error


def lp_clearance(e: Electrodes, k_u: int, k_d: int) -> float:
    """Largest clearance rho by linear programming (independent of the closed form).

    Variables: release values x_1..x_ku, snap-down values y_1..y_kd, rho. Levels sit at 0 V, mid-gap,
    the drive band and max_V; every threshold keeps rho from the levels around it, consecutive values
    are 2 rho apart, and the drive-band rule keeps 2 margin from the band.
    """
    nv = k_u + k_d + 1
    R = nv - 1
    A, b = [], []

    def row(coefs, rhs):
        r = np.zeros(nv)
        for i, c in coefs:
            r[i] += c
        A.append(r)
        b.append(rhs)

    x = list(range(k_u))
    y = list(range(k_u, k_u + k_d))
    row([(R, 1.0), (x[0], -1.0)], 0.0)  # x_1 - 0 >= rho
    for a, c in zip(x, x[1:], strict=False):
        row([(R, 2.0), (c, -1.0), (a, 1.0)], 0.0)  # x_{j+1} - x_j >= 2 rho
    row([(x[-1], 1.0), (R, 1.0)], e.drive_low_V)  # drive_low - x_K >= rho
    row([(x[-1], 1.0)], e.drive_low_V - 2 * e.margin_V)  # drive-band rule
    row([(R, 1.0), (y[0], -1.0)], -e.drive_high_V)  # y_1 - drive_high >= rho
    row([(y[0], -1.0)], -(e.drive_high_V + 2 * e.margin_V))  # drive-band rule
    for a, c in zip(y, y[1:], strict=False):
        row([(R, 2.0), (c, -1.0), (a, 1.0)], 0.0)
    row([(y[-1], 1.0), (R, 1.0)], e.max_V)  # max_V - y_K >= rho
    cost = np.zeros(nv)
    cost[R] = -1.0
    res = linprog(cost, A_ub=np.array(A), b_ub=np.array(b), bounds=[(None, None)] * nv, method="highs")
    return -res.fun if res.status == 0 else -math.inf


def measured_clearance(d) -> float:
    """Smallest distance from a threshold to the levels actually used (hold levels, 0, band, max_V)."""
    e = d.electrodes
    levels = [v for v in d.raise_levels_V + d.release_levels_V if math.isfinite(v)]
    levels += [0.0, e.drive_low_V, e.drive_high_V, e.max_V]
    th = np.array(d.snap_down_V + d.release_V)
    return float(np.min(np.abs(th[:, None] - np.array(levels)[None, :])))


limits = st.builds(
    lambda mx, m, lo_frac, width: Electrodes(
        max_V=mx, margin_V=m, drive_low_V=lo_frac * mx, drive_high_V=min(mx, lo_frac * mx + width)
    ),
    st.floats(50.0, 400.0),
    st.floats(0.5, 8.0),
    st.floats(0.2, 0.6),
    st.floats(1.0, 40.0),
)


@settings(max_examples=60)
@given(limits, st.data())
def test_clearance_is_the_lp_optimum(e, data):
    for ties in (False, True):
        best = max_robots(e, ties=ties)
        assume(best >= 1)
        n = data.draw(st.integers(1, min(best, 30)))
        d = design_string(n, e, ties=ties)
        if ties:
            lp = max(lp_clearance(e, k, n + 1 - k) for k in range(1, n + 1))
        else:
            lp = lp_clearance(e, n, n)
        assert d.clearance_V == pytest.approx(lp, rel=1e-7, abs=1e-7)
        assert measured_clearance(d) == pytest.approx(d.clearance_V, rel=1e-7, abs=1e-7)
        assert d.clearance_V >= e.margin_V - 1e-9
        a = analyse_thresholds(d.snap_down_V, d.release_V, e, names=d.names)
        assert a.is_string and a.count == n + 1 and a.order == d.names


tight_limits = st.builds(
    lambda mx, m, lo_frac, width: Electrodes(
        max_V=mx, margin_V=m, drive_low_V=lo_frac * mx, drive_high_V=min(mx, lo_frac * mx + width)
    ),
    st.floats(30.0, 250.0),
    st.floats(2.0, 10.0),
    st.floats(0.2, 0.6),
    st.floats(1.0, 40.0),
)


@settings(max_examples=40)
@given(tight_limits)
def test_largest_n_is_exactly_the_feasibility_limit(e):
    for ties in (False, True):
        best = max_robots(e, ties=ties)
        if ties:
            feasible = lambda n: max(lp_clearance(e, k, n + 1 - k) for k in range(1, n + 1)) >= e.margin_V - 1e-9  # noqa: E731
        else:
            feasible = lambda n: lp_clearance(e, n, n) >= e.margin_V - 1e-9  # noqa: E731
        assert not feasible(best + 1)
        if best >= 1:
            assert feasible(best)
            design_string(best, e, ties=ties)
        with pytest.raises(DesignError, match=f"has {best} robot"):
            design_string(best + 1, e, ties=ties)


def test_default_limits_and_the_error_message():
    e = Electrodes()
    assert max_robots(e) == 7 and max_robots(e, ties=True) == 15
    with pytest.raises(DesignError) as info:
        design_string(12, e)
    msg = info.value.message
    assert msg.startswith("--robots: 12 robots do not fit") and "has 7 robots (15 with --ties)" in msg
    d = design_string(12, e, ties=True)
    assert d.ties and d.n == 12


def test_four_robot_design_values():
    d = design_string(4, Electrodes())
    # Release side: 4 values in [0, 75 - 10] with clearance min(75/8, 65/7) = 65/7 V.
    assert d.release_V == pytest.approx([65 / 7, 3 * 65 / 7, 5 * 65 / 7, 65.0])
    # Snap-down side: 4 values below 200 V with clearance min(95/8, 85/7) = 11.875 V.
    assert d.snap_down_V == pytest.approx([200 - 7 * 11.875, 200 - 5 * 11.875, 200 - 3 * 11.875, 200 - 11.875])
    assert d.clearance_V == pytest.approx(65 / 7)
    assert d.min_gap_V == pytest.approx(2 * 65 / 7)
    assert d.release_levels_V[0] == 0.0 and d.raise_levels_V[4] == 200.0


def test_ties_share_one_value_and_waveforms_cross_them():
    e = Electrodes()
    d = design_string(10, e, ties=True)
    vd, vu = np.array(d.snap_down_V), np.array(d.release_V)
    shared_d = vd[1:] == vd[:-1]
    shared_u = vu[1:] == vu[:-1]
    assert np.all(shared_d ^ shared_u)  # each neighbour pair shares exactly one threshold, never both
    assert np.all(np.diff(vd) >= 0) and np.all(np.diff(vu) >= 0)
    a = d.analysis()
    assert a.is_string and a.count == 11
    steps = [(f"P{k}", 0.01) for k in (3, 10, 1, 7, 0, 5, 2, 9, 4)]
    drives = decode(synthesize(a, steps), vd, vu)
    assert [d_.states.tolist() for d_ in drives] == [list(a.primitive(p).state) for p, _ in steps]
    assert all(d_.ok for d_ in drives)


def test_design_fragment_loads_as_a_scenario():
    d = design_string(5, Electrodes(max_V=180.0, margin_V=3.0, drive_low_V=60.0, drive_high_V=90.0))
    text = d.to_toml()
    s = loads(text, source="design.toml")
    assert s.names == ("D1", "D2", "D3", "D4", "D5") and s.electrodes == d.electrodes
    with_starts = text.replace('release_V', 'start = [100.0, 100.0, 0.0]\nrelease_V')
    assert loads(with_starts).has_starts
    j = d.to_json_dict()
    assert j["string"] and [r["name"] for r in j["robots"]] == list(d.names)
    assert j["levels"]["raise_to_P_k_V"]["P5"] == 180.0


# ----------------------------------------------------------------------------------------------------
# Yield


def test_yield_limits_and_reproducibility():
    d = design_string(4, Electrodes())
    y0 = estimate_yield(d, 0.0, trials=500, seed=1)
    assert y0.fraction == 1.0 and y0.successes == 500 and y0.ci_high == 1.0 and 0.99 < y0.ci_low < 1.0
    a = estimate_yield(d, 4.0, trials=3000, seed=7)
    b = estimate_yield(d, 4.0, trials=3000, seed=7)
    c = estimate_yield(d, 4.0, trials=3000, seed=8)
    assert a == b and a != c
    assert 0.05 < a.fraction < 0.95 and a.ci_low < a.fraction < a.ci_high
    assert estimate_yield(d, 60.0, trials=500, seed=1).fraction == 0.0


def test_yield_agrees_with_decoding_real_waveforms():
    """Independent estimate: decode the nominal waveform of every transition P_j -> P_k on scattered sets."""
    e = Electrodes()
    d = design_string(3, e)
    sd = 6.0
    a = d.analysis()
    steps = []
    for j in range(4):
        for k in range(4):
            if j != k:
                steps += [(f"P{j}", 0.001), (f"P{k}", 0.001)]
    wf = synthesize(a, steps)
    want = [list(a.primitive(p).state) for p, _ in steps]
    rng = np.random.default_rng(12345)
    trials = 600
    ok = 0
    for _ in range(trials):
        vd = np.array(d.snap_down_V) + sd * rng.standard_normal(3)
        vu = np.array(d.release_V) + sd * rng.standard_normal(3)
        drives = decode(wf, vd, vu)
        ok += all(dr.ok and dr.states.tolist() == w for dr, w in zip(drives, want, strict=False))
    independent = ok / trials
    y = estimate_yield(d, sd, trials=20_000, seed=3)
    sigma = math.sqrt(max(independent * (1 - independent), 0.01) / trials)
    assert abs(independent - y.fraction) < 4 * sigma + 0.01, (independent, y)


@pytest.mark.parametrize(
    "kwargs, option",
    [
        (dict(max_V=0.0), "--max-V"),
        (dict(margin_V=-1.0), "--margin-V"),
        (dict(drive_low_V=110.0), "--drive-high-V"),
        (dict(drive_high_V=250.0), "--drive-high-V"),
        (dict(max_V=float("nan")), "--max-V"),
        (dict(hold_s=0.0), "--hold-s"),
    ],
)
def test_bad_limits_name_the_option(kwargs, option):
    with pytest.raises(DesignError) as info:
        design_string(3, Electrodes(**kwargs))
    assert info.value.source == option


def test_bad_yield_arguments():
    d = design_string(2, Electrodes())
    cases: list[tuple[float, dict[str, int], str]] = [(-1.0, {}, "--sd-V"), (1.0, {"trials": 0}, "--trials"), (1.0, {"seed": -3}, "--seed")]
    for sd, kwargs, option in cases:
        with pytest.raises(DesignError) as info:
            estimate_yield(d, sd, **kwargs)
        assert info.value.source == option


# ----------------------------------------------------------------------------------------------------
# CLI


def test_cli_design_toml_json_and_out(run_cli, tmp_path):
    r = run_cli("design", "--robots", "4")
    assert r.code == 0, r.err
    s = loads(r.out)
    assert s.n == 4 and s.electrodes.max_V == 200.0
    r = run_cli("design", "--robots", "3", "--json", "--sd-V", "2", "--trials", "500", "--seed", "5")
    j = json.loads(r.out)
    assert j["yield"]["trials"] == 500 and j["yield"]["seed"] == 5 and 0 <= j["yield"]["fraction"] <= 1
    out = tmp_path / "d.toml"
    r = run_cli("design", "--robots", "6", "--margin-V", "4", "--max-V", "190", "--out", out)
    assert r.code == 0 and r.out == "" and "wrote" in r.err
    st_ = run_cli("states", out, "--json")
    assert json.loads(st_.out)["string"] is True and json.loads(st_.out)["count"] == 7
    assert load(out).electrodes.margin_V == 4.0
    r = run_cli("design", "--robots", "2", "--out", tmp_path / "d.json")
    assert json.loads((tmp_path / "d.json").read_text())["format"] == "stressbots.design/1"


def test_cli_design_errors(run_cli, tmp_path):
    assert_user_error(run_cli("design", "--robots", "30"), "--robots", "largest", "has 7 robots")
    assert_user_error(run_cli("design", "--robots", "0"), "--robots", ">= 1")
    assert_user_error(run_cli("design", "--robots", "abc"), "--robots")
    assert_user_error(run_cli("design"), "--robots")
    assert_user_error(run_cli("design", "--robots", "3", "--sd-V", "-1"), "--sd-V")
    assert_user_error(run_cli("design", "--robots", "3", "--drive-low-V", "120"), "--drive-high-V")
    assert_user_error(run_cli("design", "--robots", "3", "--out", tmp_path), "--out", "folder")


def test_cli_help_teaches():
    from typer.testing import CliRunner

    from stressbots.cli import app

    for cmd, words in [("design", ["--sd-V", "(V)", "Examples"]), ("states", ["--json", "margin_V", "Example"]),
                       ("waveform", ["--steps", "P1:2.5", "--rate-hz"])]:
        r = CliRunner().invoke(app, [cmd, "--help"], env={"COLUMNS": "200", "TERM": "dumb"})
        assert r.exit_code == 0
        for w in words:
            assert w in r.output, (cmd, w)
