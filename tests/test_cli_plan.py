"""`stressbots plan` writes the very plan the main job follows, and reports its real wall time."""

from __future__ import annotations

import json

import pytest

from .conftest import EXAMPLES

EXAMPLE = EXAMPLES / "four-robots.toml"


def _without_provenance(doc: dict) -> dict:
    return {k: v for k, v in doc.items() if k != "provenance"}


@pytest.mark.xdist_group("main_job")
def test_plan_command_writes_the_plan_the_main_job_runs(run_cli, tmp_path, main_job):
    job, job_dir = main_job
    assert job.code == 0, job.err
    r = run_cli("plan", EXAMPLE, "--out", tmp_path / "plan")
    assert r.code == 0, r.err
    planned = json.loads((tmp_path / "plan" / "plan.json").read_text())
    followed = json.loads((job_dir / "plan.json").read_text())
    assert planned["steps"] and _without_provenance(planned) == _without_provenance(followed)
    summary = json.loads((tmp_path / "plan" / "summary.json").read_text())
    assert summary["controller_settings"] is True
    # the printed time is the command's wall time, not one candidate's planning time
    assert "wall time of the command" in r.out
    assert summary["wall_time_s"] >= summary["planning_time_s"]


def test_plan_with_other_settings_says_it_differs(run_cli, tmp_path):
    r = run_cli("plan", EXAMPLE, "--out", tmp_path / "p", "--clearance-um", "10")
    assert r.code == 0, r.err
    assert "different plan" in r.out
    assert json.loads((tmp_path / "p" / "summary.json").read_text())["controller_settings"] is False
