"""Layouts that truly cannot be planned are refused in one line naming the robot, the obstacle and the
change that makes them plannable (issue 15 goal 1); applying that change makes them plannable.

Each layout is the example with one deliberate defect (truth: the geometry of the defect, placed by
hand); the change the refusal advises restores the example, which plans and replays.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import pytest

from stressbots.errors import PlanningError
from stressbots.planning import plan_assembly
from stressbots.replay import replay
from stressbots.robots import Pose
from stressbots.scenario import StructureSpec, load

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "four-robots.toml"


def _moved(scn, name: str, start: tuple[float, float, float]):
    """The scenario with robot ``name`` starting at ``start`` (um, um, deg)."""
    x, y, deg = start
    robots = tuple(replace(r, start=Pose(x, y, math.radians(deg))) if r.name == name else r for r in scn.robots)
    return replace(scn, robots=robots)


# (defect, what the refusal must say: robots and obstacle, advice)
CASES = {
    # B (D1) starts 400 um below A (D3): their orbit discs (r* = 264 um) overlap by 128 um
    "start orbits overlap": (lambda s: _moved(s, "B", (600.0, 2000.0, 0.0)),
                             ("orbits of D3 ('A') and D1 ('B') overlap", "move the start of D3 ('A') or D1 ('B')")),
    # the tee's junction 50 um from the right edge: D3's slot sticks out
    "slot outside the arena": (lambda s: replace(s, structure=StructureSpec("tee", Pose(2950.0, 1500.0, 0.0))),
                               ("the slot of D3 ('A') is", "outside the arena", "move the structure", "enlarge the arena")),
    # B (D1) starts beside the tee's junction: its orbit covers the slot D3 docks into while it orbits
    "orbit over a slot": (lambda s: _moved(s, "B", (1300.0, 1500.0, 0.0)),
                          ("the orbit of D1 ('B') crosses the slot of D3 ('A')", "move the start of D1 ('B')")),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_an_impossible_layout_is_refused_naming_robot_obstacle_and_remedy(case):
    defect, needles = CASES[case]
    with pytest.raises(PlanningError) as info:
        plan_assembly(defect(load(EXAMPLE)))
    msg = info.value.message
    assert "\n" not in msg and "; to make it plannable: " in msg, msg
    for needle in needles:
        assert needle in msg, msg


def test_the_advised_change_makes_the_layout_plannable():
    """Every defect above is undone by the change its refusal names (the start moved back, the structure
    moved into the arena): the example, which plans, and its plan replays."""
    scn = load(EXAMPLE)
    res = plan_assembly(scn)
    assert replay(res.plan, scn, max_step_um=2.0).ok


def test_the_plan_command_refuses_in_one_error_line(run_cli, tmp_path):
    text = EXAMPLE.read_text().replace("start = [600.0, 600.0, 0.0]", "start = [600.0, 2000.0, 0.0]")
    bad = tmp_path / "overlap.toml"
    bad.write_text(text)
    res = run_cli("plan", str(bad), "--out", str(tmp_path / "out"))
    assert res.code == 2
    lines = [ln for ln in res.err.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error: "), res.err
    assert "orbits of D3 ('A') and D1 ('B') overlap" in lines[0] and "to make it plannable: move the start of" in lines[0]
    assert not (tmp_path / "out" / "plan.json").exists()
