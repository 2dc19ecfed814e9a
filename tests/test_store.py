"""The trial store and campaigns that survive interruption (SPEC 10): idempotent commits, resume,
refusal of a store of other settings, kill -9 and Ctrl-C of a running ``stressbots montecarlo``, and
Dask's LocalCluster against the local process pool.

The interruption tests run the real CLI in a subprocess with the stand-in controller of
:mod:`tests.campaign_fake` (a fixed wall time per trial, outcomes from the seed), so they are fast and
independent of the controller's speed; the Dask test runs the real controller on a 2-robot scenario.
"""

from __future__ import annotations

import json
import math
import os
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots import montecarlo as mc
from stressbots.errors import StressbotsError
from stressbots.store import STORE_NAME, TRIAL_COLUMNS, TrialStore, csv_text, read_rows, settings_differences

from . import campaign_fake
from .conftest import EXAMPLES, ROOT, assert_user_error

SCENARIO = EXAMPLES / "four-robots.toml"
OUTCOME_COLUMNS = ("trial", "cell", "cell_trial", "seed", "noise_scale", "success", "failure", "shape_error_um",
                   "placement_error_um", "heading_error_deg", "duration_s", "replans", "docked", "robots", "error")


def _row(trial: int, **kw) -> dict:
    base = {"trial": trial, "cell": 0, "cell_trial": trial, "seed": 1000 + trial, "noise_scale": 1.0, "success": trial % 2 == 0,
            "failure": None if trial % 2 == 0 else "stuck", "shape_error_um": float(trial), "duration_s": 2.5 * trial}
    base.update(kw)
    return base


def _outcomes(db: Path) -> list[tuple]:
    return [tuple(r[c] for c in OUTCOME_COLUMNS) for r in read_rows(db)]


# ----------------------------------------------------------------------------------------------------
# the store itself


def test_store_schema_has_the_spec_columns(tmp_path):
    with TrialStore.open(tmp_path / STORE_NAME, {"seed": 1}) as s:
        s.record(_row(0))
    con = sqlite3.connect(tmp_path / STORE_NAME)
    cols = {r[1]: (r[2], r[5]) for r in con.execute("PRAGMA table_info(trials)")}
    for name, decl in {"trial": "INTEGER", "seed": "INTEGER", "success": "INTEGER", "failure": "TEXT", "shape_error_um": "REAL",
                       "duration_s": "REAL"}.items():
        assert cols[name][0] == decl
    assert cols["trial"][1] == 1  # the primary key
    assert con.execute("PRAGMA journal_mode").fetchone()[0] == "wal"
    assert json.loads(con.execute("SELECT value FROM campaign WHERE key='settings'").fetchone()[0]) == {"seed": 1}


@settings(max_examples=30)
@given(st.lists(st.integers(0, 19), min_size=1, max_size=60))
def test_any_order_of_arrivals_keeps_each_trial_once(arrivals):
    """Duplicated and reordered arrivals (Dask re-runs, two resumes at once) leave every trial once."""
    with TrialStore.open(":memory:", {}) as s:
        fresh = [s.record(_row(t)) for t in arrivals]
        rows = s.rows()
    assert [r["trial"] for r in rows] == sorted(set(arrivals))
    assert sum(fresh) == len(set(arrivals))  # record() says whether the trial was new
    assert all(r["seed"] == 1000 + r["trial"] and r["success"] == (r["trial"] % 2 == 0) for r in rows)


_json_values = st.recursive(st.none() | st.booleans() | st.integers() | st.floats(allow_nan=False) | st.text(max_size=5),
                            lambda kids: st.lists(kids, max_size=3) | st.dictionaries(st.text(max_size=3), kids, max_size=3),
                            max_leaves=6)


@settings(max_examples=60)
@given(st.dictionaries(st.sampled_from(["seed", "trials", "noise", "versions", "code_sha256"]), _json_values),
       st.dictionaries(st.sampled_from(["seed", "trials", "noise", "versions", "code_sha256"]), _json_values))
def test_settings_differences_name_exactly_the_keys_that_differ(a, b):
    diff = settings_differences(a, b)
    differing = [k for k in list(a) + [k for k in b if k not in a] if a.get(k, "\0missing") != b.get(k, "\0missing")]
    assert [d.split(" ")[0] for d in diff] == differing
    assert (diff == []) == (a == b)


def test_nan_and_none_round_trip(tmp_path):
    with TrialStore.open(tmp_path / STORE_NAME, {}) as s:
        s.record(_row(0, shape_error_um=math.nan, failure="exception: boom", error="boom"))
        s.record(_row(1, duration_s=1e-300))
    rows = read_rows(tmp_path / STORE_NAME)
    assert rows[0]["shape_error_um"] is None and rows[0]["error"] == "boom" and rows[1]["duration_s"] == 1e-300
    assert rows[0]["finished_utc"].endswith("Z")
    text = csv_text(rows)
    assert text.splitlines()[0].split(",")[: len(TRIAL_COLUMNS)] == [c for c, _ in TRIAL_COLUMNS]
    assert len(text.splitlines()) == 3


def test_resume_checks_the_settings(tmp_path):
    db = tmp_path / STORE_NAME
    with TrialStore.open(db, {"seed": 1, "trials": 10, "noise": {"a": 1.0}}) as s:
        s.record(_row(3))
    with pytest.raises(StressbotsError, match="already holds a campaign \\(1 trials\\).*--resume.*--overwrite"):
        TrialStore.open(db, {"seed": 1, "trials": 10, "noise": {"a": 1.0}})
    with pytest.raises(StressbotsError) as e:
        TrialStore.open(db, {"seed": 2, "trials": 10, "noise": {"a": 1.5}}, resume=True)
    assert e.value.source == "--resume" and "seed 1 in the store, 2 now" in e.value.message and '"a": 1.5' in e.value.message
    with TrialStore.open(db, {"seed": 1, "trials": 10, "noise": {"a": 1.0}}, resume=True) as s:
        assert s.done() == {3}
    with TrialStore.open(db, {"seed": 5}, overwrite=True) as s:
        assert len(s) == 0
    assert settings_differences({"x": [1, 2]}, {"x": [1, 2]}) == []


def test_an_empty_file_or_database_is_no_campaign(tmp_path):
    """A reader that connected before the campaign created its store, or a campaign killed while creating
    it, leaves an empty file or schema: it holds no trial and is replaced, with or without --resume."""
    db = tmp_path / STORE_NAME
    db.touch()
    with TrialStore.open(db, {"seed": 1}) as s:
        assert len(s) == 0
    db.unlink()
    sqlite3.connect(db).execute("PRAGMA journal_mode = WAL").fetchone()
    with TrialStore.open(db, {"seed": 1}, resume=True) as s:
        assert s.settings == {"seed": 1}


def test_a_file_that_is_not_a_store_is_refused(tmp_path):
    db = tmp_path / STORE_NAME
    db.write_text("not sqlite at all" * 100)
    with pytest.raises(StressbotsError, match="not a stressbots trial store"):
        TrialStore.open(db, {}, resume=True)


# ----------------------------------------------------------------------------------------------------
# campaigns through the CLI


def _cli_args(out: Path, trials: int = 24, seed: int = 2, *extra) -> list[str]:
    return ["montecarlo", str(SCENARIO), "--trials", str(trials), "--seed", str(seed), "--out", str(out), *extra]


def _default_sigint() -> None:
    """In the child before exec: Ctrl-C handled as in a terminal. A test suite started as a background job of
    a non-interactive shell (``pytest ... &``) inherits SIGINT ignored, and so would the campaign: it ran
    to the end through the test's Ctrl-C."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _spawn(args: list[str], trial_s: float) -> subprocess.Popen:
    env = dict(os.environ, STRESSBOTS_FAKE_TRIAL_S=str(trial_s), PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))
    return subprocess.Popen([sys.executable, "-m", "tests.campaign_fake", *args], env=env, cwd=ROOT,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, preexec_fn=_default_sigint)


def _wait_for_trials(db: Path, at_least: int, proc: subprocess.Popen, timeout_s: float = 30.0) -> int:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout_s:
        assert proc.poll() is None, proc.communicate()
        if db.exists() and db.stat().st_size > 0:
            try:
                con = sqlite3.connect(f"file:{db}?mode=ro", uri=True)
                n = con.execute("SELECT count(*) FROM trials").fetchone()[0]
                con.close()
                if n >= at_least:
                    return n
            except sqlite3.Error:
                pass
        time.sleep(0.05)
    raise AssertionError("the campaign stored too few trials in time")


@pytest.fixture
def reference(tmp_path_factory, monkeypatch):
    """An uninterrupted campaign (in-process, one worker): the outcomes every interrupted one must reach."""
    monkeypatch.setenv("STRESSBOTS_FAKE_TRIAL_S", "0")
    campaign_fake.install(monkeypatch)
    from stressbots.cli import main

    out = tmp_path_factory.mktemp("reference")
    main(_cli_args(out, 40, 2, "--workers", "1", "--quiet"))
    return out


def _strip(summary: dict) -> dict:
    return {k: v for k, v in summary.items() if k not in ("run", "store")}


def test_kill_9_then_resume_gives_every_trial_once_with_the_same_outcomes(tmp_path, reference, run_cli):
    out = tmp_path / "mc"
    proc = _spawn(_cli_args(out, 40, 2, "--workers", "2"), trial_s=1.0)
    _wait_for_trials(out / STORE_NAME, 4, proc)
    proc.kill()  # SIGKILL: no handler runs
    proc.communicate(timeout=10)  # returns at once: the workers died with their parent
    assert proc.returncode == -signal.SIGKILL
    kept = _outcomes(out / STORE_NAME)
    assert 4 <= len(kept) < 40
    # every committed trial is a finished one with its reference outcome
    ref = {r[0]: r for r in _outcomes(reference / STORE_NAME)}
    assert all(ref[r[0]] == r for r in kept)
    r = run_cli(*_cli_args(out, 40, 2, "--workers", "2", "--resume", "--quiet"))
    assert r.code == 0, r.err
    assert _outcomes(out / STORE_NAME) == _outcomes(reference / STORE_NAME)  # each trial exactly once, same outcomes
    s, s_ref = (json.loads((d / "summary.json").read_text()) for d in (out, reference))
    assert _strip(s) == _strip(s_ref)
    assert s["run"]["resumed_with"] == len(kept) and s["run"]["trials_run"] == 40 - len(kept)
    assert len((out / "trials.csv").read_text().splitlines()) == 41


def test_ctrl_c_keeps_the_finished_trials(tmp_path, reference, run_cli):
    out = tmp_path / "mc"
    proc = _spawn(_cli_args(out, 40, 2, "--workers", "2"), trial_s=1.0)
    _wait_for_trials(out / STORE_NAME, 3, proc)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=20)
    assert proc.returncode == 130, err
    lines = [ln for ln in err.splitlines() if ln.startswith("error:") or "kept" in ln]
    assert lines[0] == "error: interrupted"
    kept = _outcomes(out / STORE_NAME)
    assert f"{len(kept)} of 40 trials are kept in {out / STORE_NAME}" in lines[1] and "--resume" in lines[1]
    assert "Traceback" not in err and 3 <= len(kept) < 40
    r = run_cli(*_cli_args(out, 40, 2, "--workers", "1", "--resume", "--quiet"))
    assert r.code == 0, r.err
    assert _outcomes(out / STORE_NAME) == _outcomes(reference / STORE_NAME)


def test_resume_refuses_a_store_of_other_settings(tmp_path, reference, run_cli, monkeypatch):
    campaign_fake.install(monkeypatch)
    monkeypatch.setenv("STRESSBOTS_FAKE_TRIAL_S", "0")
    assert_user_error(run_cli(*_cli_args(reference, 40, 3, "--resume")), "--resume", "other settings", "seed 2 in the store, 3 now")
    assert_user_error(run_cli(*_cli_args(reference, 30, 2, "--resume")), "trials 40 in the store, 30 now")
    assert_user_error(run_cli(*_cli_args(reference, 40, 2, "--resume", "--sweep", "0,1")), "noise_scales")
    assert_user_error(run_cli(*_cli_args(reference, 40, 2)), "--out", "already holds a campaign (40 trials)", "--resume")
    r = run_cli(*_cli_args(reference, 40, 2, "--resume", "--json"))  # complete: nothing to run, same summary
    assert r.code == 0 and json.loads(r.out)["run"]["trials_run"] == 0


def test_export_parquet_or_a_clear_error(tmp_path, reference, run_cli):
    r = run_cli("export", reference, "--out", tmp_path / "t.csv")
    assert r.code == 0 and (tmp_path / "t.csv").read_text() == (reference / "trials.csv").read_text()
    assert_user_error(run_cli("export", reference, "--format", "xls"), "--format")
    try:
        import pyarrow.parquet as pq
    except ImportError:
        assert_user_error(run_cli("export", reference, "--format", "parquet"), "pyarrow")
        return
    r = run_cli("export", reference, "--format", "parquet", "--out", tmp_path / "t.parquet")
    assert r.code == 0, r.err
    table = pq.read_table(tmp_path / "t.parquet").to_pylist()
    assert [(t["trial"], t["seed"], bool(t["success"])) for t in table] == [(r["trial"], r["seed"], bool(r["success"]))
                                                                             for r in read_rows(reference / STORE_NAME)]


# ----------------------------------------------------------------------------------------------------
# Dask


def test_dask_local_cluster_equals_the_local_pool_even_when_a_worker_dies(tmp_path, monkeypatch):
    """The real controller on a 2-robot layout, on the local pool and on a LocalCluster where the first
    trial kills its worker process: Dask re-runs it elsewhere; every trial once, identical outcomes."""
    pytest.importorskip("distributed")
    from stressbots.generate import LITERATURE_NOISE, random_scenario

    scn = random_scenario(2, 3, shape="pair", noise=LITERATURE_NOISE)
    plan = mc.default_planner()(scn)
    kw = dict(plan=plan, time_budget_s=60.0, assemble=campaign_fake.dying_assemble)  # short trials: most fail by the budget
    pool = mc.run_study(scn, 4, 7, workers=2, store=tmp_path / "pool.sqlite", **kw)
    marker = tmp_path / "died"
    monkeypatch.setenv("STRESSBOTS_DIE_ONCE", str(marker))  # inherited by the cluster's worker processes
    dask = mc.run_study(scn, 4, 7, workers=2, store=tmp_path / "dask.sqlite", dask="local", **kw)
    assert marker.exists()  # a worker did die under a trial
    assert dask.summary["run"]["backend"] == "dask local" and dask.summary["run"]["trials_run"] == 4
    assert _outcomes(tmp_path / "dask.sqlite") == _outcomes(tmp_path / "pool.sqlite")
    assert _strip(dask.summary) == _strip(pool.summary)
    assert len({r[OUTCOME_COLUMNS.index("placement_error_um")] for r in _outcomes(tmp_path / "pool.sqlite")}) == 4  # trials differ
