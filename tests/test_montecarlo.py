"""Monte Carlo studies: seeds, Wilson intervals, worker-count invariance, sweeps and the ``montecarlo``
command. The controller is replaced by :func:`fake_assemble` (a module-level function, so worker
processes can run it) except in one test that runs the real controller for a few simulated seconds.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from stressbots import montecarlo as mc
from stressbots.errors import StressbotsError
from stressbots.scenario import load

from .conftest import EXAMPLES, assert_user_error


@dataclass(frozen=True)
class FakeResult:
    """The fields of the controller's AssemblyResult that a study reads."""

    success: bool
    seed: int | None
    names: tuple
    final_true: np.ndarray | None
    final_observed: np.ndarray
    goals: np.ndarray
    docked: np.ndarray
    shape_error_rms_um: float
    placement_error_um: np.ndarray
    heading_error_deg: np.ndarray
    duration_s: float
    replans: int
    events: tuple
    failure: str | None


PLAN = object()  # stands for the nominal plan in unit tests


def fake_assemble(scenario, plant, *, seed=None, plan=None, time_budget_s=None):
    """A deterministic stand-in: outcome drawn from the seed, failure more likely with more noise."""
    assert plant.seed == seed, "the plant must be built with the trial's seed"
    rng = np.random.default_rng([seed, 99])
    level = scenario.noise.speed_rel_sd / 0.05  # 1 at the example's noise
    ok = bool(rng.random() >= min(1.0, 0.1 + 0.35 * level))
    n = scenario.n
    err = rng.gamma(2.0, 2.0 + 3.0 * level, n)
    failure = None if ok else ("stuck in H" if rng.random() < 0.5 else f"shape error {20 + 10 * rng.random():.1f} um RMS exceeds 20 um")
    if seed % 11 == 3:
        raise RuntimeError("a crashing trial")
    return FakeResult(ok, seed, scenario.names, None, np.zeros((n, 3)), np.zeros((n, 3)), np.full(n, ok), float(err.mean()), err,
                      err / 10, float(100 + 50 * rng.random()), int(rng.integers(5, 30)), (), failure)


@pytest.fixture(scope="module")
def four():
    return load(EXAMPLES / "four-robots.toml")


def _strip(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k != "run"}


# ----------------------------------------------------------------------------------------------------
# pure pieces


def test_trial_seeds_come_from_spawned_seed_sequences():
    s = mc.trial_seeds(42, 6)
    kids = np.random.SeedSequence(42).spawn(6)
    assert s == [int(k.generate_state(1, np.uint64)[0]) >> 11 for k in kids]
    assert len(set(s)) == 6 and all(0 <= x < 2**53 for x in s)
    assert mc.trial_seeds(42, 3) == s[:3]  # a longer study extends a shorter one
    assert mc.trial_seeds(43, 3) != s[:3]
    with pytest.raises(ValueError):
        mc.trial_seeds(-1, 3)


def _wilson_by_roots(s: int, n: int, z: float = 1.959963984540054) -> tuple[float, float]:
    """Wilson's interval as the two p solving (p_hat - p)^2 = z^2 p (1 - p) / n (independent algebra)."""
    ph = s / n
    a = 1 + z * z / n
    b = -(2 * ph + z * z / n)
    c = ph * ph
    r = np.sort(np.roots([a, b, c]).real)
    return float(r[0]), float(r[1])


@pytest.mark.parametrize("s, n", [(8, 10), (0, 10), (10, 10), (95, 100), (1, 3), (500, 1000), (0, 1)])
def test_wilson_interval_matches_the_quadratic_roots(s, n):
    lo, hi = mc.wilson_interval(s, n)
    rlo, rhi = _wilson_by_roots(s, n)
    assert lo == pytest.approx(max(rlo, 0.0), abs=1e-9) and hi == pytest.approx(min(rhi, 1.0), abs=1e-9)
    assert 0.0 <= lo <= s / n <= hi <= 1.0


def test_wilson_interval_known_values():
    assert mc.wilson_interval(8, 10) == pytest.approx((0.4902, 0.9433), abs=1e-4)
    assert mc.wilson_interval(0, 10) == pytest.approx((0.0, 0.2775), abs=1e-4)
    assert mc.wilson_interval(10, 10) == pytest.approx((0.7225, 1.0), abs=1e-4)
    assert mc.wilson_interval(0, 0) == (0.0, 1.0)
    lo90, hi90 = mc.wilson_interval(8, 10, 0.90)
    assert 0.4902 < lo90 and hi90 < 0.9433  # narrower at lower confidence
    with pytest.raises(ValueError):
        mc.wilson_interval(11, 10)


def test_percentiles_and_failure_kinds():
    p = mc.percentiles([1.0, 2.0, 3.0, 4.0, math.nan, None])
    assert p == {"p50": 2.5, "p90": pytest.approx(3.7), "p95": pytest.approx(3.85), "max": 4.0, "mean": 2.5, "n": 4}
    assert mc.percentiles([])["p50"] is None
    assert mc.failure_kind("shape error 23.4 um RMS exceeds 20 um") == "shape error # um RMS exceeds # um"
    assert mc.failure_kind("budget of 4e3 s") == "budget of # s"
    assert mc.failure_kind(None) is None


def test_parse_sweep():
    assert mc.parse_sweep("0, 0.5,1,1.5,2") == (0.0, 0.5, 1.0, 1.5, 2.0)
    assert mc.parse_sweep("1,1,2") == (1.0, 2.0)
    for bad in ("", "a", "1,,2", "-1", "inf", "nan"):
        with pytest.raises(StressbotsError):
            mc.parse_sweep(bad)


# ----------------------------------------------------------------------------------------------------
# studies


def test_same_numbers_whatever_the_worker_count(four):
    one = mc.run_study(four, 12, 5, workers=1, assemble=fake_assemble, plan=PLAN)
    two = mc.run_study(four, 12, 5, workers=2, assemble=fake_assemble, plan=PLAN)
    assert one.main == two.main  # outcomes compare without their wall times
    assert _strip(one.summary) == _strip(two.summary)
    assert one.summary["run"]["workers"] == 1 and two.summary["run"]["workers"] == 2
    assert [o.seed for o in one.main] == mc.trial_seeds(5, 12)


def test_summary_holds_the_contract_keys_and_statistics(four):
    st = mc.run_study(four, 40, 1, workers=1, assemble=fake_assemble, plan=PLAN, source="x.toml")
    s = st.summary
    assert s["trials"] == 40 and isinstance(s["successes"], int)
    assert s["success_rate"] == pytest.approx(s["successes"] / 40)
    assert s["success_rate_ci95"] == pytest.approx(list(mc.wilson_interval(s["successes"], 40)))
    fails = [o for o in st.main if not o.success]
    assert sum(s["failures"].values()) == len(fails) == len(s["failed_trials"])
    crashed = [o for o in st.main if o.error is not None]
    assert s["exceptions"] == len(crashed) > 0 and s["failures"]["exception: RuntimeError: a crashing trial"] == len(crashed)
    shapes = [o.shape_error_rms_um for o in st.main if math.isfinite(o.shape_error_rms_um)]
    assert s["shape_error_rms_um"]["p50"] == pytest.approx(float(np.percentile(shapes, 50)))
    assert s["shape_error_rms_um"]["max"] == pytest.approx(max(shapes))
    assert s["seed"] == 1 and s["provenance"]["seed"] == 1 and "versions" in s["provenance"]
    assert s["noise"]["speed_rel_sd"] == 0.05 and "sweep" not in s
    json.dumps(s)  # plain JSON (through outputs it also loses NaN)


def test_sweep_scales_the_noise_with_common_seeds(four):
    st = mc.run_study(four, 30, 2, workers=1, sweep=(0.0, 1.0, 2.0), assemble=fake_assemble, plan=PLAN)
    rows = st.sweep
    assert rows is not None  # a sweep was asked for
    assert [r["noise_scale"] for r in rows] == [0.0, 1.0, 2.0]
    assert rows[1]["successes"] == st.summary["successes"]  # scale 1 is the main study
    rates = [r["success_rate"] for r in rows]
    assert rates[0] > rates[1] > rates[2]  # the fake fails more with more noise
    assert [o.seed for o in st.outcomes[2.0]] == [o.seed for o in st.main]
    assert all(o.noise_scale == 2.0 for o in st.outcomes[2.0])


def test_bad_counts_are_user_errors(four):
    with pytest.raises(StressbotsError, match="at least 1"):
        mc.run_study(four, 0, 1, assemble=fake_assemble, plan=PLAN)
    with pytest.raises(StressbotsError, match="--workers"):
        mc.run_study(four, 2, 1, workers=0, assemble=fake_assemble, plan=PLAN)


def test_real_controller_is_deterministic_across_workers(four):
    control = pytest.importorskip("stressbots.control")
    if not hasattr(control, "assemble"):
        pytest.skip("stressbots.control.assemble is not there yet")
    plan = mc.default_planner()(four)
    a = mc.run_study(four, 2, 3, workers=1, plan=plan, time_budget_s=15.0)
    b = mc.run_study(four, 2, 3, workers=2, plan=plan, time_budget_s=15.0)
    assert _strip(a.summary) == _strip(b.summary)


# ----------------------------------------------------------------------------------------------------
# the command


@pytest.fixture
def fake_controller(monkeypatch):
    monkeypatch.setattr(mc, "default_assemble", lambda: fake_assemble)
    monkeypatch.setattr(mc, "default_planner", lambda: (lambda _scenario: PLAN))


def test_montecarlo_command_writes_summary_and_pictures(run_cli, tmp_path, fake_controller):
    out = tmp_path / "mc"
    r = run_cli("montecarlo", EXAMPLES / "four-robots.toml", "--trials", "16", "--seed", "4", "--out", out,
                "--workers", "2", "--sweep", "0,1,2")
    assert r.code == 0, r.err
    s = json.loads((out / "summary.json").read_text())
    assert {"trials", "successes", "success_rate", "success_rate_ci95", "shape_error_rms_um", "placement_error_um",
            "duration_s", "failures", "seed", "provenance", "sweep"} <= set(s)
    assert s["trials"] == 16 and [row["noise_scale"] for row in s["sweep"]] == [0.0, 1.0, 2.0]
    for name in ("montecarlo.png", "sweep.png"):
        assert (out / name).stat().st_size > 5_000
    assert "successes" in r.out and "noise sweep" in r.out
    j = run_cli("montecarlo", EXAMPLES / "four-robots.toml", "--trials", "16", "--seed", "4", "--out", tmp_path / "mc1",
                "--workers", "1", "--sweep", "0,1,2", "--json")
    assert j.code == 0
    s1 = json.loads(j.out)
    assert _strip(s1) == _strip(s)  # same numbers with one worker


@pytest.mark.parametrize(
    "args, needles",
    [
        (["--trials", "0"], ["--trials"]),
        (["--workers", "0"], ["--workers"]),
        (["--seed", "-2"], ["--seed"]),
        (["--sweep", "0,x"], ["--sweep", "'x'"]),
        (["--sweep", "-1"], ["--sweep", ">= 0"]),
        (["--time-budget-s", "0"], ["--time-budget-s"]),
    ],
)
def test_montecarlo_rejects_bad_options(run_cli, tmp_path, fake_controller, args, needles):
    r = run_cli("montecarlo", EXAMPLES / "four-robots.toml", "--out", tmp_path / "o", *args)
    assert_user_error(r, *needles)


def test_montecarlo_rejects_bad_scenarios(run_cli, tmp_path, monkeypatch):
    monkeypatch.setattr(mc, "default_assemble", lambda: fake_assemble)
    assert_user_error(run_cli("montecarlo", tmp_path / "none.toml", "--out", tmp_path / "o"), "none.toml", "no such file")
    p = tmp_path / "nostart.toml"
    p.write_text('[[robots]]\nname = "a"\nsnap_down_V = 120.0\nrelease_V = 30.0\n[[robots]]\nname = "b"\n'
                 'snap_down_V = 140.0\nrelease_V = 40.0\n[structure]\nshape = "pair"\n')
    assert_user_error(run_cli("montecarlo", p, "--out", tmp_path / "o", "--trials", "2", "--quiet"), "start")
    f = tmp_path / "file"
    f.write_text("x")
    assert_user_error(run_cli("montecarlo", EXAMPLES / "four-robots.toml", "--out", f), "--out", "not a folder")


def test_a_stored_study_summarises_like_an_in_memory_one(four, tmp_path):
    """The summary is computed from the store: the same numbers as in memory; a sweep is one cell per
    noise scale (scale 1 first) with the same trial seeds in every cell."""
    from stressbots.store import read_rows, read_settings

    mem = mc.run_study(four, 6, 9, workers=1, sweep=(0.0, 1.0, 2.0), assemble=fake_assemble, plan=PLAN)
    db = tmp_path / "trials.sqlite"
    stored = mc.run_study(four, 6, 9, workers=2, sweep=(0.0, 1.0, 2.0), assemble=fake_assemble, plan=PLAN, store=db)
    assert {k: v for k, v in stored.summary.items() if k not in ("run", "store")} == _strip(mem.summary)
    rows = read_rows(db)
    cells = read_settings(db)["cells"]
    assert [c["params"]["noise_scale"] for c in cells] == [1.0, 0.0, 2.0]
    seeds = mc.trial_seeds(9, 6)
    assert [(r["trial"], r["cell"], r["seed"], r["noise_scale"]) for r in rows] == [
        (c * 6 + k, c, seeds[k], cells[c]["params"]["noise_scale"]) for c in range(3) for k in range(6)]
    assert sum(r["success"] for r in rows if r["cell"] == 0) == stored.summary["successes"]


def test_failure_kind_keeps_named_objects():
    # the seed's named objects keep their subscripts; numbers and robot indices are replaced
    assert mc.failure_kind("D_(n-1)'s straight move to its station orbit is blocked") == (
        "D_(n-1)'s straight move to its station orbit is blocked")
    assert mc.failure_kind("G_1 did not form: D_n stopped 12.5 um from D_{n-1}") == "G_1 did not form: D_n stopped # um from D_{n-1}"
    assert mc.failure_kind("D3 did not dock in 6 attempts") == "D# did not dock in # attempts"
    assert mc.failure_kind("A_2* is empty after 1e3 s") == "A_2* is empty after # s"
    # a hyphen inside a word is not a minus sign; a minus sign after a space is part of the number
    assert mc.failure_kind("no clear straight stage-2 run for C") == "no clear straight stage-# run for C"
    assert mc.failure_kind("R2: -34 um from an obstacle") == "R#: # um from an obstacle"


@given(st.text(alphabet=st.characters().filter(lambda c: not c.isdigit()), max_size=40))
def test_failure_kind_without_digits_is_unchanged(text):
    assert mc.failure_kind(text) == text.strip()
