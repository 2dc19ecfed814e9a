"""Shared test helpers: run the CLI in-process and capture what a user would see."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import pytest
from hypothesis import settings

settings.register_profile("ci", deadline=None, print_blob=True)
settings.register_profile("dev", deadline=None)
settings.load_profile("ci" if os.environ.get("CI") else "dev")

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


#: The slowest tests (over ~10 s each on 2 loaded cores, measured with --durations): marked ``slow`` so
#: that `pytest -m "not slow"` gives a quick loop; they stay in the suite.
SLOW_TESTS = {
    "test_bounds_command_writes_json_and_picture",
    "test_demo_writes_its_outputs",
    "test_interpolated_arc_matches_bound",
    "test_closed_loop_without_noise_assembles_through_the_protocol",
    "test_brute_force_lp_never_beats_closed_form",
    "test_brute_force_slsqp_never_beats_closed_form",
    "test_real_controller_is_deterministic_across_workers",
    "test_same_seed_same_run",
    "test_simulate_without_a_plan_runs_the_closed_loop",
    "test_cli_plan_writes_files_and_reports_errors",
    "test_planner_solves_random_layouts_it_is_known_to_solve",
    "test_plan_command_writes_the_plan_the_main_job_runs",
    "test_run_assembles_without_noise_and_writes_the_report",
    "test_report_loads_in_headless_chromium_without_errors",
}


def pytest_configure(config):
    """With pytest-xdist's default distribution, keep each xdist_group on one worker (``--dist loadgroup``),
    so the tests that share the session's main-job run (:func:`main_job`) run it once."""
    if hasattr(config, "workerinput"):  # an xdist worker: report grouped node ids (it re-parses the plain args)
        config.option.loadgroup = True
    elif getattr(config.option, "dist", None) == "load":  # the xdist controller: schedule by group
        config.option.dist = "loadgroup"


def pytest_collection_modifyitems(items):
    for item in items:
        if getattr(item, "originalname", item.name) in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)


@dataclass
class CliResult:
    code: int
    out: str
    err: str


@pytest.fixture
def run_cli(capsys):
    """Run ``stressbots ARGS...`` in-process; returns exit code, stdout and stderr."""
    from stressbots.cli import main

    def _run(*args: str) -> CliResult:
        capsys.readouterr()
        try:
            main([str(a) for a in args])
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        captured = capsys.readouterr()
        return CliResult(code, captured.out, captured.err)

    return _run


@pytest.fixture(scope="session")
def main_job(tmp_path_factory):
    """One run of the main job, shared by the report, CLI and browser tests: ``stressbots run`` on the
    example without noise, seed 3, in-process. Returns ``(CliResult, out_dir)``.

    Tests that use it carry ``@pytest.mark.xdist_group("main_job")`` so that one worker runs them all
    (``--dist loadgroup``, set by :func:`pytest_configure`) and the job runs once per test session.
    """
    import contextlib
    import io

    from stressbots.cli import main

    out_dir = tmp_path_factory.mktemp("main-job") / "run"
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
        try:
            main(["run", str(EXAMPLES / "four-robots.toml"), "--out", str(out_dir), "--noise", "none", "--seed", "3"])
            code = 0
        except SystemExit as exc:
            code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
    return CliResult(code, stdout.getvalue(), stderr.getvalue()), out_dir


def assert_user_error(result: CliResult, *needles: str) -> None:
    """A user error: exit 2, exactly one stderr line starting 'error:', naming what is wrong."""
    assert result.code == 2, (result.code, result.out, result.err)
    lines = [ln for ln in result.err.splitlines() if ln.strip()]
    assert len(lines) == 1, result.err
    assert lines[0].startswith("error:"), lines[0]
    assert "Traceback" not in result.err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
