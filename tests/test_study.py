"""Studies: the grid of cells, paired seeds, parameter application, refusals, resume and the report.
The controller is the stand-in of :mod:`tests.campaign_fake` (it reads the noise, the replanning
interval and ``options.clearance_um``, so the grid's effect is visible)."""

from __future__ import annotations

import itertools
import json
import math
import sqlite3

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots import montecarlo as mc
from stressbots.errors import StressbotsError
from stressbots.scenario import load
from stressbots.store import read_rows
from stressbots.study import build_cells, parse_study, run_study

from . import campaign_fake
from .conftest import EXAMPLES, assert_user_error

FOUR = EXAMPLES / "four-robots.toml"


def _study(**over) -> dict:
    data = {
        "name": "t", "trials": 5, "seed": 3,
        "layouts": [{"file": str(FOUR)}, {"file": str(FOUR), "label": "four-b"}],
        "grid": {"control": {"replan_interval_s": [0.5, 2.0]}, "noise.scale": [0.0, 1.0, 2.0]},
        "fixed": {"controller.clearance_um": 15.0},
    }
    data.update(over)
    return data


@pytest.fixture(autouse=True)
def fake(monkeypatch):
    monkeypatch.setenv("STRESSBOTS_FAKE_TRIAL_S", "0")
    campaign_fake.install(monkeypatch)


def test_grid_cells_conditions_and_paired_seeds(tmp_path):
    spec = parse_study(_study())
    assert spec.cells == 2 * 2 * 3 and [k for k, _ in spec.axes] == ["control.replan_interval_s", "noise.scale"]
    cells = build_cells(spec, campaign_fake.fake_assemble, campaign_fake.fake_plan)
    base = load(FOUR)
    expected = list(itertools.product(["four-robots", "four-b"], [0.5, 2.0], [0.0, 1.0, 2.0]))  # last axis fastest
    assert [(c.params["layout"], c.params["control.replan_interval_s"], c.params["noise.scale"]) for c in cells] == expected
    for cell, (_, dt, scale) in zip(cells, expected, strict=False):
        assert cell.scenario.control.replan_interval_s == dt
        assert cell.scenario.noise == base.noise.scaled(scale)
        assert dict(cell.controller)["options"].clearance_um == 15.0
        assert cell.scenario.robots == base.robots
    summary, _, outcomes = run_study(spec, store=tmp_path / "s.sqlite", workers=2)
    rows = read_rows(tmp_path / "s.sqlite")
    assert [r["trial"] for r in rows] == list(range(12 * 5))
    seeds = mc.trial_seeds(3, 5)
    for r in rows:  # paired: trial k of every cell has the same seed
        assert r["trial"] == r["cell"] * 5 + r["cell_trial"] and r["seed"] == seeds[r["cell_trial"]]
    for c, row in enumerate(summary["cells"]):  # per-cell counts straight from the store
        mine = [r for r in rows if r["cell"] == c]
        assert row["successes"] == sum(r["success"] for r in mine) and row["trials"] == 5
        assert row["success_rate_ci95"] == pytest.approx(list(mc.wilson_interval(row["successes"], 5)))
    # paired cells share the draws: at zero noise and short interval every layout copy agrees trial by trial
    by_cell = {c: [r["success"] for r in rows if r["cell"] == c] for c in range(12)}
    assert by_cell[0] == by_cell[6]  # the same conditions on the same scenario (two labels) -> identical trials
    for c, row in enumerate(summary["cells"]):  # paired comparison with the layout's first cell, from the store
        base_cell = c - c % 6
        pv = row["paired_vs_baseline"]
        if c == base_cell:
            assert pv is None
            continue
        pairs = list(zip(by_cell[c], by_cell[base_cell], strict=False))
        gained, lost = sum(a and not b for a, b in pairs), sum(b and not a for a, b in pairs)
        assert (pv["baseline_cell"], pv["gained"], pv["lost"]) == (base_cell, gained, lost)
    assert summary["trials"] == 60 and summary["axes"] == {"control.replan_interval_s": [0.5, 2.0], "noise.scale": [0.0, 1.0, 2.0]}


@settings(max_examples=25, deadline=None)
@given(st.lists(st.integers(1, 3), min_size=0, max_size=3))
def test_points_are_the_full_product_once(sizes):
    grid = {f"controller.opt{i}": list(range(n)) for i, n in enumerate(sizes)}
    spec = parse_study(_study(grid={}, fixed={}))  # the options are not checked by points()
    spec = type(spec)(spec.name, spec.trials, spec.seed, spec.layouts, tuple((k, tuple(v)) for k, v in grid.items()), ())
    pts = spec.points()
    assert len(pts) == math.prod(sizes)
    assert len({json.dumps(p, sort_keys=True) for p in pts}) == len(pts)


@pytest.mark.parametrize(
    "over, needles",
    [
        ({"grid": {"noise.speedy": [1]}}, ["noise.speedy", "unknown parameter"]),
        ({"grid": {"control.replan_interval_s": [-1.0]}}, ["replan_interval_s", "four-robots"]),
        ({"grid": {"controller.nope": [1]}}, ["controller.nope", "ControllerOptions has no field"]),
        ({"grid": {"robots[9].speed_um_s": [1.0]}}, ["robots[9].speed_um_s", "4 robots"]),
        ({"grid": {"noise.scale": []}}, ["grid.noise.scale", "non-empty"]),
        ({"trials": 0}, ["trials", ">= 1"]),
        ({"layouts": []}, ["layouts", "at least one"]),
        ({"colour": "red"}, ["colour", "unknown key"]),
        ({"grid": {"noise.scale": [1.0]}, "fixed": {"noise.scale": 2.0}}, ["noise.scale", "both"]),
    ],
)
def test_bad_study_files_are_user_errors(tmp_path, run_cli, over, needles):
    p = tmp_path / "bad.study.toml"
    data = _study(**over)
    lines = [f"{k} = {json.dumps(v)}" for k, v in data.items() if k not in ("layouts", "grid", "fixed")]
    for lay in data["layouts"]:
        lines += ["[[layouts]]"] + [f"{k} = {json.dumps(v)}" for k, v in lay.items()]
    for table in ("grid", "fixed"):
        lines.append(f"[{table}]")
        for k, v in mc_flatten(data.get(table, {})).items():
            lines.append(f"{json.dumps(k)} = {json.dumps(v)}")
    p.write_text("\n".join(lines) + "\n")
    assert_user_error(run_cli("study", p, "--out", tmp_path / "o"), str(p), *needles)


def mc_flatten(table: dict, prefix: str = "") -> dict:
    out = {}
    for k, v in table.items():
        if isinstance(v, dict):
            out.update(mc_flatten(v, f"{prefix}{k}."))
        else:
            out[f"{prefix}{k}"] = v
    return out


def test_a_strategy_the_controller_lacks_is_refused_and_default_passes():
    def plain(scenario, plant, *, seed=None, plan=None, time_budget_s=None):  # a controller of one strategy
        raise AssertionError("not run")

    with pytest.raises(StressbotsError, match="no strategy 'seed'"):
        build_cells(parse_study(_study(grid={"strategy": ["default", "seed"]}, fixed={})), plain, campaign_fake.fake_plan)
    ok = build_cells(parse_study(_study(grid={"strategy": ["default"]})), campaign_fake.fake_assemble, campaign_fake.fake_plan)
    assert all("strategy" not in dict(c.controller) for c in ok)

    def with_strategy(scenario, plant, *, seed=None, plan=None, time_budget_s=None, strategy="default"):
        raise AssertionError("not run")

    cells = build_cells(parse_study(_study(grid={"strategy": ["default", "seed"]}, fixed={})), with_strategy, campaign_fake.fake_plan)
    assert [dict(c.controller).get("strategy") for c in cells[:2]] == [None, "seed"]  # passed through when offered


def test_study_command_resume_and_report(tmp_path, run_cli):
    study = tmp_path / "s.study.toml"
    study.write_text(
        f'name = "noise"\ntrials = 6\nseed = 2\n[[layouts]]\nfile = "{FOUR}"\n[[layouts]]\ngenerate = {{ n = 2, shape = "pair", seed = 3 '
        '}\n'
        '[grid]\n"noise.scale" = [0.0, 1.0, 3.0]\n'
    )
    out = tmp_path / "out"
    r = run_cli("study", study, "--out", out, "--workers", "2", "--quiet")
    assert r.code == 0, r.err
    ref = [tuple(v for k, v in row.items() if k not in ("wall_s", "worker", "finished_utc")) for row in read_rows(out / "trials.sqlite")]
    assert len(ref) == 2 * 3 * 6
    con = sqlite3.connect(out / "trials.sqlite")
    with con:
        con.execute("DELETE FROM trials WHERE trial % 5 = 1")  # as if the run had been killed with these unfinished
    con.close()
    r = run_cli("study", study, "--out", out, "--workers", "1", "--resume", "--json")
    assert r.code == 0, r.err
    s = json.loads(r.out)
    assert s["run"]["trials_run"] == len([t for t in range(36) if t % 5 == 1])
    again = [tuple(v for k, v in row.items() if k not in ("wall_s", "worker", "finished_utc")) for row in read_rows(out / "trials.sqlite")]
    assert again == ref
    rates = [c["success_rate"] for c in s["cells"][:3]]
    assert rates[0] >= rates[2]  # the stand-in fails more with more noise
    html = (out / "report.html").read_text()
    assert html.count("data:image/png;base64,") >= 3 and "http://" not in html and "https://" not in html
    assert "noise.scale" in html and "Wilson" in html
    study.write_text(study.read_text().replace("3.0]", "4.0]"))
    assert_user_error(run_cli("study", study, "--out", out, "--resume"), "--resume", "other settings", "axes")


def test_a_strategy_goes_into_the_options_when_they_have_that_field():
    from dataclasses import dataclass

    from stressbots.campaign import controller_kwargs

    @dataclass(frozen=True)
    class Opts:
        clearance_um: float = 15.0
        strategy: str = "default"

    def asm(scenario, plant, *, seed=None, plan=None, options=None):
        raise AssertionError("not run")

    assert controller_kwargs(asm, options=Opts(), strategy="seed") == (("options", Opts(strategy="seed")),)
    assert controller_kwargs(asm, options=Opts(), strategy="default") == (("options", Opts()),)
    assert controller_kwargs(asm) == ()
    import dataclasses

    from stressbots.edr import ControllerOptions

    if "strategy" in {f.name for f in dataclasses.fields(ControllerOptions)}:  # a controller that offers strategies
        assert dict(controller_kwargs(asm, strategy="seed"))["options"].strategy == "seed"
    else:
        with pytest.raises(StressbotsError, match="no strategy 'seed'"):
            controller_kwargs(asm, strategy="seed")


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.booleans(), st.booleans()), max_size=30))
def test_paired_comparison_counts_and_mcnemar(pairs):
    from scipy.stats import binomtest

    from stressbots.study import paired_comparison

    this, base = [a for a, _ in pairs], [b for _, b in pairs]
    r = paired_comparison(this, base)
    assert r["gained"] == sum(a and not b for a, b in pairs) and r["lost"] == sum(b and not a for a, b in pairs)
    assert r["both"] == sum(a and b for a, b in pairs)
    n = r["gained"] + r["lost"]
    expected = 1.0 if n == 0 else binomtest(r["gained"], n, 0.5).pvalue  # scipy's exact two-sided binomial test
    assert r["mcnemar_p"] == pytest.approx(min(1.0, expected), rel=1e-9)


def test_the_real_controller_chooses_the_strategy_by_name():
    from stressbots.campaign import controller_kwargs
    from stressbots.strategies import assemble_strategy

    asm = assemble_strategy  # what montecarlo.default_assemble returns (this module's fixture replaces it)
    assert controller_kwargs(asm, strategy="seed") == (("strategy", "seed"),)
    assert controller_kwargs(asm, strategy="default") == ()
    with pytest.raises(StressbotsError, match="unknown strategy 'nope'"):
        controller_kwargs(asm, strategy="nope")
