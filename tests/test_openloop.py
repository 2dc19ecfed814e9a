"""Open-loop runs (stressbots.openloop) and the output folder's input check."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from stressbots import outputs
from stressbots.errors import StressbotsError
from stressbots.openloop import plan_goals, result_document, run_open_loop
from stressbots.scenario import Noise, load

from .conftest import EXAMPLES


@pytest.fixture(scope="module")
def example_and_plan():
    from stressbots.control import nominal_plan

    scn = load(EXAMPLES / "four-robots.toml")
    return scn, nominal_plan(scn).plan


def test_without_control_error_the_plan_ends_every_robot_in_its_slot(example_and_plan):
    """Planner, waveform and simulator agree: open loop with no noise assembles, to rounding."""
    scn, plan = example_and_plan
    run = run_open_loop(scn.with_noise(Noise()), plan, seed=0)
    assert run.assessment.success
    assert np.allclose(run.plant.true_poses()[:, :2], plan.goal_array()[:, :2], atol=1e-6)
    doc = result_document(run, scenario_source="s.toml", plan_source="p.json")
    assert doc["success"] is True and doc["mode"] == "open-loop" and doc["seed"] == 0
    assert [r["name"] for r in doc["robots"]] == list(scn.names)
    assert doc["duration_s"] == run.plant.time_s > 0


def test_the_same_seed_gives_the_same_run_and_another_seed_another(example_and_plan):
    scn, plan = example_and_plan
    a, b, c = (run_open_loop(scn, plan, seed=s) for s in (3, 3, 4))
    assert a.plant.true_poses().tobytes() == b.plant.true_poses().tobytes()
    assert a.observed.tobytes() == b.observed.tobytes()
    assert a.plant.true_poses().tobytes() != c.plant.true_poses().tobytes()


def test_goals_come_from_the_plan_else_the_scenario_else_an_error_naming_the_robot(example_and_plan):
    scn, plan = example_and_plan
    assert np.array_equal(plan_goals(scn, plan), plan.goal_array())
    no_goals = dataclasses.replace(plan, goals={})
    robots = tuple(dataclasses.replace(r, goal=None) for r in scn.robots)
    with pytest.raises(StressbotsError, match=f"no goal for robot '{scn.names[0]}'") as info:
        plan_goals(dataclasses.replace(scn, robots=robots), no_goals, source="plan.json")
    assert info.value.field == "goals"


def test_an_output_folder_refuses_to_hold_a_file_that_is_an_input(tmp_path):
    src = tmp_path / "result.json"
    src.write_text("{}")
    with pytest.raises(StressbotsError, match="would overwrite the input file"):
        outputs.prepare_dir(tmp_path, inputs=[src], files=("summary.json", "result.json"))
    assert src.read_text() == "{}"
    assert outputs.prepare_dir(tmp_path / "new", inputs=[src], files=("result.json",)).is_dir()
