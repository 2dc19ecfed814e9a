"""Scenario files: loading, defaults, overrides, and one clear error for each kind of bad input."""

from __future__ import annotations

import math
import re

import pytest
from hypothesis import given
from hypothesis import strategies as st

from stressbots.errors import ScenarioError
from stressbots.scenario import load, loads, to_toml

from .conftest import EXAMPLES

GOOD = """
name = "t"
arena_um = [3000.0, 2000.0]
[robot_defaults]
turn_radius_um = 150.0
[electrodes]
margin_V = 2.0
[[robots]]
name = "a"
snap_down_V = 120.0
release_V = 30.0
start = [100.0, 200.0, 90.0]
[[robots]]
name = "b"
snap_down_V = 140
release_V = 40
turn_radius_um = 300.0
"""


def test_defaults_and_overrides():
    s = loads(GOOD)
    a, b = s.robots
    assert a.turn_radius_um == 150.0 and b.turn_radius_um == 300.0  # default vs per-robot override
    assert a.length_um == 260.0 and a.width_um == 60.0 and a.speed_um_s == 100.0  # SPEC defaults
    assert s.electrodes.margin_V == 2.0 and s.electrodes.max_V == 200.0
    assert a.start is not None and a.start.theta == pytest.approx(math.pi / 2)  # file degrees -> radians
    assert b.start is None and s.arena_um == (3000.0, 2000.0)
    assert b.snap_down_V == 140.0 and isinstance(b.snap_down_V, float)


def test_example_loads():
    s = load(EXAMPLES / "four-robots.toml")
    assert s.n == 4 and s.has_starts and s.structure is not None and s.structure.shape == "tee"
    assert s.noise.heading_drift_rad_per_um == pytest.approx(math.radians(3.7) / 1000)


def test_round_trip_through_toml():
    s = loads(GOOD)
    again = loads(to_toml(s))
    assert again.robots == s.robots and again.electrodes == s.electrodes and again.arena_um == s.arena_um


ROBOT = '[[robots]]\nname = "a"\nsnap_down_V = 120.0\nrelease_V = 30.0\n'


@pytest.mark.parametrize(
    "text, field, words",
    [
        ("[[robots]\nname='a'", None, "not valid TOML"),
        ('[[robots]]\nname = "a"\nsnap_down_V = "high"\nrelease_V = 30.0', "robots[0] (a).snap_down_V", "number"),
        ('[[robots]]\nname = "a"\nsnap_down_V = nan\nrelease_V = 30.0', "robots[0] (a).snap_down_V", "finite"),
        ('[[robots]]\nname = "a"\nsnap_down_V = inf\nrelease_V = 30.0', "robots[0] (a).snap_down_V", "finite"),
        ('[[robots]]\nsnap_down_V = 120.0\nrelease_V = 30.0', "robots[0].name", "missing"),
        (ROBOT + ROBOT, "robots[1] (a).name", "duplicate"),
        ('[[robots]]\nname = "a"\nsnap_down_V = 30.0\nrelease_V = 30.0', "robots[0] (a).release_V", "below snap_down_V"),
        ('[[robots]]\nname = "a"\nsnap_down_V = 100.0\nrelease_V = 130.0', "robots[0] (a).release_V", "below"),
        (ROBOT + "speed_um_s = -3.0", "robots[0] (a).speed_um_s", "in [10, 5000] um/s"),
        (ROBOT + "turn_radius_um = 0.0", "robots[0] (a).turn_radius_um", "in [10, 10000] um"),
        ("[electrodes]\nmax_V = 0.0\n" + ROBOT, "electrodes.max_V", "in [1, 1000] V"),
        ("[electrodes]\nmargin_V = -1.0\n" + ROBOT, "electrodes.margin_V", "in [0, 100] V"),
        ("[electrodes]\ndrive_low_V = 110.0\n" + ROBOT, "electrodes.drive_low_V", "below drive_high_V"),
        (ROBOT + "start = [1.0, 2.0]", "robots[0] (a).start", "3 numbers"),
        (ROBOT + "goal = [1.0, 2.0, 3.0, 4.0]", "robots[0] (a).goal", "3 numbers"),
        (ROBOT + 'start = [1.0, "x", 3.0]', "robots[0] (a).start", "number"),
        (ROBOT + "colour = 3", "robots[0] (a).colour", "unknown field"),
        ("", "robots", "missing"),
        ("arena_um = [100.0]\n" + ROBOT, "arena_um", "width_um"),
        ("arena_um = [300.0, 300.0]\n" + ROBOT + "start = [500.0, 50.0, 0.0]", "robots[0] (a).start", "outside the arena"),
        ("[noise]\ncamera_dropout = 1.5\n" + ROBOT, "noise.camera_dropout", "in [0, 0.5]"),
        ("[control]\nreplan_interval_s = 0\n" + ROBOT, "control.replan_interval_s", "in [0.25, 60] s"),
        ('[structure]\nshape = "tee"\n' + ROBOT + "goal = [1.0, 2.0, 3.0]", "robots[0] (a).goal", "structure"),
        ('[[robots]]\nname = "a"\nrelease_V = 30.0', "robots[0] (a).snap_down_V", "missing"),
    ],
)
def test_bad_input_names_the_field(text, field, words):
    with pytest.raises(ScenarioError) as info:
        loads(text, source="bad.toml")
    msg = info.value.message
    assert msg.startswith("bad.toml")
    if field:
        assert f": {field}:" in msg, msg
    assert words.lower() in msg.lower(), msg
    assert "\n" not in msg


def test_missing_directory_and_binary_files(tmp_path):
    with pytest.raises(ScenarioError, match="no such file"):
        load(tmp_path / "nope.toml")
    with pytest.raises(ScenarioError, match="directory"):
        load(tmp_path)
    garbage = tmp_path / "g.toml"
    garbage.write_bytes(bytes(range(256)) * 4)
    with pytest.raises(ScenarioError, match="binary"):
        load(garbage)
    latin = tmp_path / "l.toml"
    latin.write_bytes(b'name = "caf\xe9"\n')
    with pytest.raises(ScenarioError, match="UTF-8"):
        load(latin)


@given(st.binary(max_size=300))
def test_arbitrary_bytes_never_crash(data):
    """Any byte string is either a valid scenario or a ScenarioError, never another exception."""
    import tempfile
    from pathlib import Path

    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / "x.toml"
        p.write_bytes(data)
        try:
            load(p)
        except ScenarioError as exc:
            assert "\n" not in exc.message


def test_builtin_demo_scenario_is_the_example():
    """The packaged demo scenario is a copy of examples/four-robots.toml (examples/ is not installed)."""
    from dataclasses import replace

    from stressbots.demo import load_builtin

    builtin, example = load_builtin(), load(EXAMPLES / "four-robots.toml")
    assert replace(builtin, source=None) == replace(example, source=None)


def test_readme_lists_every_accepted_range():
    """The README's table of accepted values is stressbots.scenario.LIMITS, row for row."""
    import re

    from stressbots.scenario import LIMITS

    readme = (EXAMPLES.parent / "README.md").read_text(encoding="utf-8")
    rows = dict(re.findall(r"^\| `([^`]+)` \| ([\[(][^|]+?) \|", readme, re.M))
    for key, rng in LIMITS.items():
        assert rows.get(key) == rng.text(), (key, rows.get(key), rng.text())


@pytest.mark.parametrize("key", ["speed_um_s", "snap_down_V", "camera_dropout", "replan_interval_s"])
def test_every_range_is_enforced_at_both_ends(key):
    """Values at the ends of a range load; values just outside are refused, naming the range."""
    from stressbots.scenario import LIMITS

    rng = LIMITS[key]
    where = {"speed_um_s": "[[robots]]", "snap_down_V": "[[robots]]", "camera_dropout": "[noise]", "replan_interval_s": "[control]"}[key]
    base = '[[robots]]\nname = "a"\nsnap_down_V = 120.0\nrelease_V = 0.0\n'

    def doc(value: float) -> str:
        if where == "[[robots]]":
            if key == "snap_down_V":
                return base.replace("snap_down_V = 120.0", f"snap_down_V = {value!r}")
            return base + f"{key} = {value!r}\n"
        return f"{where}\n{key} = {value!r}\n" + base

    for ok in (rng.high, rng.low if not rng.open_low else rng.low + 1e-9):
        if key == "snap_down_V" and ok == 0.0:
            continue  # release_V (0) must stay below it
        loads(doc(float(ok)))
    for bad in (rng.high * (1 + 1e-9) + 1e-12, rng.low - 1e-6):
        with pytest.raises(ScenarioError, match=re.escape(rng.text())):
            loads(doc(bad))
