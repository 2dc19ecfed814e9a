"""Adversarial input through the whole command line, in-process.

Every case is input a user (or an attacker, or a typo) can give: absurd numbers, wrong types, names
with control characters, files nested 100,000 deep, output paths that cannot be written. Each must end
with exit status 2 and exactly one stderr line starting ``error:`` that names the file, field or option,
with no traceback, quickly (the input is refused before any computation). Plus Hypothesis fuzzing of
scenario and plan loading: any value in any field gives either a valid value or the library's one-line
error, never another exception.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
import time

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.errors import ScenarioError, StressbotsError
from stressbots.scenario import LIMITS, MAX_MOVING_ROBOTS, MAX_PLANNED_ROBOTS, from_dict, loads

from .conftest import EXAMPLES, assert_user_error

EXAMPLE = EXAMPLES / "four-robots.toml"
TEXT = EXAMPLE.read_text()
BIG = "1" + "0" * 400  # 10**400: no float holds it


def mutate(pattern: str, replacement: str, count: int = 1) -> str:
    out, n = re.subn(pattern, lambda _m: replacement, TEXT, count=count, flags=re.M)
    assert n, pattern
    return out


def write(tmp_path, text: str, name: str = "adv.toml"):
    p = tmp_path / name
    p.write_text(text, encoding="utf-8")
    return p


# (scenario text, words the error line must contain)
SCENARIOS = [
    (mutate(r"^speed_um_s = 100.0", "speed_um_s = true"), ["speed_um_s", "bool", "[10, 5000] um/s"]),
    (mutate(r"^speed_um_s = 100.0", 'speed_um_s = "100"'), ["speed_um_s", "str", "[10, 5000] um/s"]),
    (mutate(r"^snap_down_V = 160.0", 'snap_down_V = "160"'), ["robots[0] (A).snap_down_V", "str"]),
    (mutate(r"^speed_um_s = 100.0", "speed_um_s = 1e308"), ["speed_um_s", "[10, 5000]"]),
    (mutate(r"^speed_um_s = 100.0", "speed_um_s = 1.0"), ["speed_um_s", "[10, 5000]"]),
    (mutate(r"^speed_um_s = 100.0", f"speed_um_s = {BIG}"), ["speed_um_s", "[10, 5000]"]),
    (mutate(r"^turn_radius_um = 200.0", "turn_radius_um = 1e-300"), ["turn_radius_um", "[10, 10000] um"]),
    (mutate(r"^turn_radius_um = 200.0", "turn_radius_um = 1e308"), ["turn_radius_um", "[10, 10000] um"]),
    (mutate(r"^start = \[600.0, 2400.0, 90.0\]", f"start = [{BIG}, 2400.0, 90.0]"), ["robots[0] (A).start", "x_um"]),
    (mutate(r"^start = \[600.0, 2400.0, 90.0\]", f"start = [600.0, 2400.0, {BIG}]"), ["robots[0] (A).start", "heading_deg"]),
    (mutate(r"^at = .*$", f"at = [1500.0, 1500.0, {BIG}]"), ["structure.at", "heading_deg"]),
    (mutate(r"^camera_position_sd_um = 2.0", "camera_position_sd_um = 1e6"), ["noise.camera_position_sd_um", "[0, 50] um"]),
    (mutate(r"^speed_rel_sd = 0.05", "speed_rel_sd = 1e6"), ["noise.speed_rel_sd", "[0, 0.3]"]),
    (mutate(r"^heading_drift_deg_per_mm = 3.7", "heading_drift_deg_per_mm = 1e9"), ["noise.heading_drift_deg_per_mm"]),
    (mutate(r"^camera_dropout = 0.02", "camera_dropout = 1.0"), ["noise.camera_dropout", "[0, 0.5]"]),
    (mutate(r"^replan_interval_s = 1.0", "replan_interval_s = 1e-9"), ["control.replan_interval_s", "[0.25, 60] s"]),
    (mutate(r"^replan_interval_s = 1.0", "replan_interval_s = true"), ["control.replan_interval_s", "bool"]),
    (mutate(r"^arena_um = .*$", "arena_um = [1e9, 1e9]"), ["arena_um", "[200, 20000] um"]),
    (mutate(r"^arena_um = .*$", "arena_um = [1e308, 3000.0]"), ["arena_um"]),
    (mutate(r"^arena_um = .*$", 'arena_um = "big"'), ["arena_um"]),
    (mutate(r'^name = "A"', 'name = "' + "x" * 100_000 + '"'), ["robots[0]", "name", "at most 64 characters"]),
    (mutate(r'^name = "A"', 'name = "A\\nB"'), ["robots[0]", "name", "printable"]),
    (mutate(r'^name = "four-robots"', 'name = "four\\u0007robots"'), ["name", "printable"]),
    (mutate(r'^name = "A"', "name = 5"), ["robots[0]", "name", "string"]),
    (mutate(r"^max_V = 200.0", "max_V = 1e308"), ["electrodes.max_V", "[1, 1000] V"]),
    (mutate(r"^drive_frequency_hz = 10000.0", "drive_frequency_hz = 1e12"), ["electrodes.drive_frequency_hz", "Hz"]),
    (mutate(r"^margin_V = 5.0", "margin_V = -1"), ["electrodes.margin_V", "[0, 100] V"]),
    (mutate(r"^length_um = 260.0", "length_um = 0"), ["robot_defaults.length_um", "[10, 2000] um"]),
    (mutate(r"^width_um = 60.0", "width_um = nan"), ["robot_defaults.width_um", "finite"]),
    ("x = " + "[" * 100_000 + "]" * 100_000, ["adv.toml"]),
    ("\x00\x01binary", ["adv.toml", "binary"]),
]


@pytest.mark.parametrize("command", ["plan", "simulate", "run", "waveform", "states"])
@pytest.mark.parametrize("text, words", SCENARIOS, ids=[f"s{k}" for k in range(len(SCENARIOS))])
def test_absurd_scenarios_get_one_error_line(run_cli, tmp_path, command, text, words):
    p = write(tmp_path, text)
    if command == "waveform":
        args = ["waveform", p, "--steps", "P1:1", "--out", tmp_path / "wf.json"]
    elif command == "states":
        args = ["states", p]
    else:
        args = [command, p, "--out", tmp_path / "o"]
    t0 = time.perf_counter()
    r = run_cli(*args)
    assert time.perf_counter() - t0 < 10.0
    assert_user_error(r, "adv.toml", *words)


SLOW_LAYOUTS = [
    (mutate(r"^speed_um_s = 100.0", "speed_um_s = 10.0"), ["speed_um_s", "too slow", "at most 100 s"]),
    (mutate(r"^speed_um_s = 100.0", "speed_um_s = 10.0").replace("arena_um = [3000.0, 3000.0]", "arena_um = [20000.0, 20000.0]"),
     ["speed_um_s", "too slow"]),
    (mutate(r"^speed_um_s = 100.0", "speed_um_s = 50.0").replace("replan_interval_s = 1.0", "replan_interval_s = 0.25"),
     ["control.replan_interval_s", "measurements per crossing"]),
]


def _slow_cases():
    """(command, layout, words) of the refusals; ``plan`` simulates nothing in closed loop: it has its own,
    longer crossing limit (400 s) and no camera rate to check."""
    for command in ("plan", "simulate", "run", "bounds", "montecarlo"):
        for k, (text, words) in enumerate(SLOW_LAYOUTS):
            if command == "plan" and "measurements per crossing" in words:
                continue
            if command == "plan":
                words = [w.replace("at most 100 s", "at most 400 s") for w in words]
            yield pytest.param(command, text, words, id=f"slow{k}-{command}")


@pytest.mark.parametrize("command, text, words", list(_slow_cases()))
def test_layouts_too_slow_to_run_are_refused_before_computing(run_cli, tmp_path, command, text, words):
    """Boundary values that load but would make a run take minutes: refused by the commands that move or plan."""
    p = write(tmp_path, text)
    t0 = time.perf_counter()
    r = run_cli(command, p, "--out", tmp_path / "o")
    assert time.perf_counter() - t0 < 10.0
    assert_user_error(r, "adv.toml", *words)
    assert run_cli("states", p, "--json").code == 0  # the voltage analysis does not move robots


def _movable_limit_scenario(n: int) -> str:
    """A STRING design of ``n`` robots with spread-out starts (nothing else matters: it is refused first)."""
    rows = []
    for i in range(n):
        rows.append(f'[[robots]]\nname = "R{i}"\nsnap_down_V = {120 + 2 * i}.0\nrelease_V = {5 + 2 * i}.0\n'
                    f"start = [{300 + 400 * (i % 7)}.0, {300 + 400 * (i // 7)}.0, 0.0]\n")
    head = 'arena_um = [4000.0, 4000.0]\n[electrodes]\nmargin_V = 0.5\n[structure]\nshape = "line"\nat = [2000.0, 2000.0, 0.0]\n'
    return head + "".join(rows)


@pytest.mark.parametrize("extra", [1, 40])
@pytest.mark.parametrize("command", ["plan", "simulate", "run", "bounds", "montecarlo"])
def test_too_many_robots_to_move_are_refused_before_computing(run_cli, tmp_path, command, extra):
    most = MAX_PLANNED_ROBOTS if command == "plan" else MAX_MOVING_ROBOTS
    p = write(tmp_path, _movable_limit_scenario(most + extra))
    t0 = time.perf_counter()
    r = run_cli(command, p, "--out", tmp_path / "o")
    assert time.perf_counter() - t0 < 10.0
    assert_user_error(r, "adv.toml", "robots", f"at most {most} robots")


def test_plan_takes_more_robots_and_a_longer_crossing_than_the_simulating_commands():
    from stressbots.errors import StressbotsError
    from stressbots.scenario import MAX_CROSSING_S, MAX_PLANNED_CROSSING_S, check_movable, crossing_s

    scn = loads(_movable_limit_scenario(MAX_PLANNED_ROBOTS))
    assert check_movable(scn, planning_only=True) is scn
    with pytest.raises(StressbotsError, match=f"at most {MAX_MOVING_ROBOTS} robots"):
        check_movable(scn)
    few = dataclasses.replace(scn, robots=tuple(dataclasses.replace(r, speed_um_s=25.0) for r in scn.robots[:4]))
    assert MAX_CROSSING_S < crossing_s(few) <= MAX_PLANNED_CROSSING_S  # slow robots: too long to simulate, not to plan
    assert check_movable(few, planning_only=True) is few
    with pytest.raises(StressbotsError, match="too slow"):
        check_movable(few)


def test_too_many_robots_for_a_file(run_cli, tmp_path):
    text = "".join(f'[[robots]]\nname = "R{i}"\nsnap_down_V = 150.0\nrelease_V = 20.0\n' for i in range(101))
    assert_user_error(run_cli("states", write(tmp_path, text)), "adv.toml", "robots", "at most 100 robots")


# ----------------------------------------------------------------------------------------------------
# plan.json


@pytest.fixture(scope="module")
def plan_doc():
    """A valid plan.json document for the example (a fixed, hand-checkable plan: P1 then P0)."""
    return {
        "format": "stressbots.plan/1",
        "robots": ["A", "B", "C", "D"],
        "primitives": [{"name": "P0", "turning": []}, {"name": "P1", "turning": ["B"]}],
        "steps": [{"primitive": "P1", "duration_s": 1.0}, {"primitive": "P0", "duration_s": 1.0}],
        "goals": {n: [600.0 + 10 * k, 600.0, 0.0] for k, n in enumerate("ABCD")},
    }


PLANS = [
    (lambda d: {**d, "goals": [1, 2]}, ["goals", "dictionary", "list"]),
    (lambda d: {**d, "goals": "everywhere"}, ["goals", "str"]),
    (lambda d: {**d, "goals": {"A": None}}, ["goals.A", "null"]),
    (lambda d: {**d, "goals": {"A": [1e308, 0, 0]}}, ["goals.A", "x_um"]),
    (lambda d: {**d, "goals": {"Z": [0, 0, 0]}}, ["goals", "unknown robot"]),
    (lambda d: {**d, "steps": {"primitive": "P1"}}, ["steps", "list"]),
    (lambda d: {**d, "steps": [{"primitive": "P1", "duration_s": 1e308}]}, ["steps[0].duration_s", "[0, 3600]"]),
    (lambda d: {**d, "steps": [{"primitive": "P1", "duration_s": True}]}, ["steps[0].duration_s", "bool"]),
    (lambda d: {**d, "steps": [{"primitive": "P1", "duration_s": "1"}]}, ["steps[0].duration_s", "str"]),
    (lambda d: {**d, "steps": [{"primitive": "P1", "duration_s": 3000}, {"primitive": "P0", "duration_s": 3000}]},
     ["steps[1].duration_s", "3600"]),
    (lambda d: {**d, "steps": [{"primitive": "P9", "duration_s": 1}]}, ["steps[0].primitive", "unknown primitive"]),
    (lambda d: {**d, "robots": ["A\nB", "B", "C", "D"]}, ["robots[0]", "printable"]),
    (lambda d: {**d, "robots": "ABCD"}, ["robots", "list"]),
    (lambda d: {**d, "primitives": [{"name": "P1", "turning": ["nobody"]}]}, ["primitives[0].turning", "unknown robot"]),
    (lambda d: {**d, "format": "other/1"}, ["format", "stressbots.plan/1"]),
    (lambda d: [d], ["JSON object"]),
]


@pytest.mark.parametrize("command", ["simulate", "waveform"])
@pytest.mark.parametrize("change, words", PLANS, ids=[f"p{k}" for k in range(len(PLANS))])
def test_malformed_plans_get_one_error_line(run_cli, tmp_path, plan_doc, command, change, words):
    p = tmp_path / "bad-plan.json"
    p.write_text(json.dumps(change(plan_doc)))
    out = tmp_path / ("o" if command == "simulate" else "wf.json")
    assert_user_error(run_cli(command, EXAMPLE, "--plan", p, "--out", out), "bad-plan.json", *words)


@pytest.mark.parametrize("text, words", [
    ("[" * 100_000 + "]" * 100_000, ["nested too deeply"]),
    ('{"format": "stressbots.plan/1", "steps": [{"duration_s": ' + BIG * 20 + "}]}", []),
    ("{not json", ["not valid JSON"]),
    ("", ["not valid JSON"]),
])
def test_unreadable_plan_files(run_cli, tmp_path, text, words):
    p = tmp_path / "bad-plan.json"
    p.write_text(text)
    for command in ("simulate", "waveform"):
        out = tmp_path / ("o" if command == "simulate" else "wf.json")
        assert_user_error(run_cli(command, EXAMPLE, "--plan", p, "--out", out), "bad-plan.json", *words)


def test_valid_hand_written_plan_still_runs(run_cli, tmp_path, plan_doc):
    """The schema rejects nonsense, not valid plans: the fixed plan of this module synthesises."""
    p = tmp_path / "plan.json"
    p.write_text(json.dumps(plan_doc))
    r = run_cli("waveform", EXAMPLE, "--plan", p, "--out", tmp_path / "wf.json")
    assert r.code == 0, r.err
    segs = json.loads((tmp_path / "wf.json").read_text())
    assert sum(s["duration_s"] for s in segs if s["kind"] == "drive") == pytest.approx(2.0)


# ----------------------------------------------------------------------------------------------------
# Command-line options and output paths


def test_absurd_options(run_cli, tmp_path):
    o = tmp_path / "o"
    cases = [
        (["plan", EXAMPLE, "--out", o, "--seed", "-1"], ["--seed"]),
        (["montecarlo", EXAMPLE, "--out", o, "--trials", str(10**12)], ["--trials"]),
        (["montecarlo", EXAMPLE, "--out", o, "--workers", str(10**6)], ["--workers"]),
        (["montecarlo", EXAMPLE, "--out", o, "--time-budget-s", "1e308"], ["--time-budget-s"]),
        (["run", EXAMPLE, "--out", o, "--time-budget-s", "1e308"], ["--time-budget-s", "20000"]),
        (["simulate", EXAMPLE, "--out", o, "--time-budget-s", BIG], ["--time-budget-s"]),
        (["bounds", EXAMPLE, "--k", "1e308"], ["--k"]),
        (["bounds", EXAMPLE, "--coverage-trials", str(10**12)], ["--coverage-trials"]),
        (["design", "--robots", "4", "--trials", str(10**12), "--sd-V", "1"], ["--trials"]),
        (["design", "--robots", "4", "--sd-V", "1e308"], ["--sd-V"]),
        (["waveform", EXAMPLE, "--steps", "P1:1e308", "--out", tmp_path / "w.json"], ["--steps", "3600"]),
        (["waveform", EXAMPLE, "--steps", f"P1:{BIG}", "--out", tmp_path / "w.json"], ["--steps"]),
        (["waveform", EXAMPLE, "--steps", "P1:nan", "--out", tmp_path / "w.json"], ["--steps"]),
        (["waveform", EXAMPLE, "--steps", "P1:1", "--rate-hz", "0", "--out", tmp_path / "w.npy"], ["--rate-hz"]),
        (["waveform", EXAMPLE, "--steps", "P1:600", "--out", tmp_path / "w.csv"], ["--out", "--large"]),
        (["plan", EXAMPLE, "--out", o, "--clearance-um", "1e308"], ["--clearance-um"]),
    ]
    for args, words in cases:
        t0 = time.perf_counter()
        r = run_cli(*args)
        assert time.perf_counter() - t0 < 10.0, args
        assert_user_error(r, *words)
    assert not (tmp_path / "w.csv").exists()


def test_unwritable_outputs_are_refused_before_computing(run_cli, tmp_path):
    a_file = tmp_path / "a-file"
    a_file.write_text("x")
    folder = tmp_path / "wf.npy"
    folder.mkdir()
    cases = [
        (["plan", EXAMPLE, "--out", a_file / "sub"], ["--out", "a-file", "is a file"]),
        (["simulate", EXAMPLE, "--out", a_file / "sub" / "deeper"], ["--out", "a-file"]),
        (["run", EXAMPLE, "--out", a_file], ["--out", "a-file", "not a folder"]),
        (["montecarlo", EXAMPLE, "--out", a_file / "x", "--trials", "1"], ["--out", "a-file"]),
        (["bounds", EXAMPLE, "--out", a_file / "x"], ["--out", "a-file"]),
        (["waveform", EXAMPLE, "--steps", "P1:1", "--out", folder], ["--out", "wf.npy", "folder"]),
        (["waveform", EXAMPLE, "--steps", "P1:1", "--out", a_file / "wf.npy"], ["--out", "a-file"]),
        (["design", "--robots", "3", "--out", a_file / "d.toml"], ["--out", "a-file"]),
        (["demo", "--out", a_file], ["--out", "a-file"]),
    ]
    for args, words in cases:
        t0 = time.perf_counter()
        r = run_cli(*args)
        assert time.perf_counter() - t0 < 10.0, args
        assert_user_error(r, *words)
    assert a_file.read_text() == "x"


@pytest.mark.skipif(not hasattr(os, "geteuid") or os.geteuid() == 0, reason="root can write into a read-only folder")
def test_read_only_output_folder(run_cli, tmp_path):
    ro = tmp_path / "ro"
    ro.mkdir()
    ro.chmod(0o555)
    try:
        assert_user_error(run_cli("plan", EXAMPLE, "--out", ro), "--out", "ro", "cannot write")
    finally:
        ro.chmod(0o755)


def test_outputs_refuse_a_read_only_folder_via_the_probe(tmp_path, monkeypatch):
    """The writability probe is what refuses an unwritable folder (simulated: root ignores permissions)."""
    import tempfile

    from stressbots import outputs

    def denied(*a, **k):
        raise PermissionError(13, "Permission denied")

    monkeypatch.setattr(tempfile, "mkstemp", denied)
    with pytest.raises(StressbotsError) as info:
        outputs.prepare_dir(tmp_path / "x")
    assert "cannot write into folder" in info.value.message and "Permission denied" in info.value.message
    with pytest.raises(StressbotsError, match="cannot write"):
        outputs.write_bytes(tmp_path / "y.json", b"{}")


def test_stale_temporaries_of_a_killed_run_are_cleaned(run_cli, tmp_path):
    out = tmp_path / "w"
    out.mkdir()
    dead = out / ".wf.json.stressbots-999999999.abcd1234.tmp"  # written by a killed run: no such process
    dead.write_text("half")
    mine = out / f".wf.json.stressbots-{os.getpid()}.abcd1234.tmp"  # a live writer (this process): kept
    mine.write_text("in progress")
    users = [out / ".hidden-user-file", out / ".notes.999999999.abcd1234.tmp", out / ".x.stressbots-1x.y.tmp"]
    for f in users:  # the user's own hidden files, even look-alikes, are never touched
        f.write_text("user")
    r = run_cli("waveform", EXAMPLE, "--steps", "P1:1", "--out", out / "wf.json")
    assert r.code == 0, r.err
    assert not dead.exists() and mine.exists() and all(f.read_text() == "user" for f in users)
    assert not [f for f in out.iterdir() if f.name.startswith(".wf.json") and f != mine]  # no leftovers of this run


def test_ctrl_c_says_interrupted_and_exits_130(run_cli, monkeypatch):
    import stressbots.electrostatics as es

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(es, "analyse_scenario", interrupted)
    r = run_cli("states", EXAMPLE)
    assert r.code == 130 and r.err.strip() == "error: interrupted"


def test_numpy_warnings_do_not_reach_stderr(run_cli, monkeypatch):
    import warnings

    import stressbots.electrostatics as es

    original = es.analyse_scenario

    def noisy(*a, **k):
        np.log(np.zeros(3))  # RuntimeWarning: divide by zero
        warnings.warn("a library warning", UserWarning, stacklevel=1)
        return original(*a, **k)

    monkeypatch.setattr(es, "analyse_scenario", noisy)
    r = run_cli("states", EXAMPLE, "--json")
    assert r.code == 0 and r.err == "" and json.loads(r.out)["count"] == 5


def test_internal_errors_exit_1_with_one_line(run_cli, monkeypatch):
    import stressbots.electrostatics as es

    def broken(*a, **k):
        raise ZeroDivisionError("a bug\non two lines")

    monkeypatch.setattr(es, "analyse_scenario", broken)
    monkeypatch.delenv("STRESSBOTS_DEBUG", raising=False)
    r = run_cli("states", EXAMPLE)
    assert r.code == 1
    lines = r.err.splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: internal error: ZeroDivisionError: a bug on two lines")


def test_bounds_with_the_structure_outside_the_arena(run_cli, tmp_path):
    p = write(tmp_path, mutate(r"^at = .*$", "at = [9000.0, 1500.0, 0.0]"))
    assert_user_error(run_cli("bounds", p, "--json"), "adv.toml", "structure.at", "does not fit in the arena")


def test_simulate_plan_rejects_overlapping_starts(run_cli, tmp_path, plan_doc):
    p = write(tmp_path, mutate(r"^start = \[600.0, 600.0, 0.0\]", "start = [600.0, 2400.0, 90.0]"))  # B on top of A
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps(plan_doc))
    assert_user_error(run_cli("simulate", p, "--plan", plan, "--out", tmp_path / "o"), "adv.toml", "overlap", "robots[1] (B).start")
    assert_user_error(run_cli("simulate", p, "--out", tmp_path / "o2"), "adv.toml", "overlap")


def test_quiet_prints_nothing(run_cli, tmp_path):
    r = run_cli("waveform", EXAMPLE, "--steps", "P1:1", "--out", tmp_path / "wf.json", "-q")
    assert r.code == 0 and r.out == "" and r.err == ""


def test_help_names_no_document_users_do_not_have(run_cli, monkeypatch):
    """--help speaks the user's terms: no SPEC sections, no "seed" for the paper, flags without a
    `<bool>` value, and the README section the top-level help points to exists."""
    import typer
    import typer.core

    from stressbots.cli import app

    monkeypatch.setenv("COLUMNS", "400")
    monkeypatch.setenv("TERM", "dumb")
    group = typer.main.get_command(app)
    assert isinstance(group, typer.core.TyperGroup)  # the app has subcommands
    names = list(group.commands)
    for name in [None, *names]:
        r = run_cli("--help") if name is None else run_cli(name, "--help")
        assert r.code == 0, (name, r.err)
        for bad in ("SPEC", "seed App", "seed Appendix", "<bool>"):
            assert bad not in r.out, (name, bad)
    top = run_cli("--help").out
    see = re.search(r"see README, '([^']+)'", top)
    assert see is not None, top
    section = see.group(1)
    readme = (EXAMPLES.parent / "README.md").read_text()
    assert re.search(rf"^#+ {re.escape(section)}\s*$", readme, re.M), section


# ----------------------------------------------------------------------------------------------------
# Fuzzing: any value in any field -> a Scenario or a ScenarioError (one line), nothing else.

BASE = {
    "name": "fuzz",
    "arena_um": [3000.0, 3000.0],
    "electrodes": {"max_V": 200.0, "margin_V": 5.0},
    "robots": [
        {"name": "A", "snap_down_V": 160.0, "release_V": 45.0, "start": [600.0, 2400.0, 90.0]},
        {"name": "B", "snap_down_V": 120.0, "release_V": 15.0, "start": [600.0, 600.0, 0.0]},
    ],
    "structure": {"shape": "line", "at": [1500.0, 1500.0, 0.0]},
    "noise": {"speed_rel_sd": 0.05},
    "control": {"replan_interval_s": 1.0},
}
PATHS = [
    ("name",), ("arena_um",), ("arena_um", 0), ("electrodes", "max_V"), ("electrodes", "margin_V"),
    ("electrodes", "drive_low_V"), ("electrodes", "hold_s"), ("electrodes", "drive_frequency_hz"),
    ("robots",), ("robots", 0), ("robots", 0, "name"), ("robots", 0, "snap_down_V"), ("robots", 1, "release_V"),
    ("robots", 0, "speed_um_s"), ("robots", 1, "turn_radius_um"), ("robots", 0, "length_um"), ("robots", 0, "width_um"),
    ("robots", 0, "start"), ("robots", 1, "start", 2), ("robots", 0, "goal"), ("structure",), ("structure", "shape"),
    ("structure", "at"), ("noise", "speed_rel_sd"), ("noise", "camera_dropout"), ("noise", "camera_position_sd_um"),
    ("control", "replan_interval_s"), ("control",), ("robot_defaults",), ("extra_field",),
]

scalars = st.one_of(
    st.none(), st.booleans(), st.integers(), st.integers(min_value=10**300, max_value=10**400),
    st.floats(allow_nan=True, allow_infinity=True), st.text(max_size=80),
    st.sampled_from([0, -1, 1e-300, 1e308, -1e308, 10**400, "", "\n", "A\x00", "160", "true"]),
)


def _containers(inner: st.SearchStrategy) -> st.SearchStrategy:
    return st.one_of(st.lists(inner, max_size=4), st.dictionaries(st.text(max_size=8), inner, max_size=3))


values = st.recursive(scalars, _containers, max_leaves=8)


def _set(doc, path, value):
    node = doc
    for key in path[:-1]:
        node = node[key]
    if isinstance(node, list) and path[-1] >= len(node):
        return
    node[path[-1]] = value


@settings(max_examples=400, deadline=None)
@given(st.lists(st.tuples(st.sampled_from(PATHS), values), min_size=1, max_size=3))
def test_fuzzed_scenarios_load_or_fail_with_one_line(changes):
    doc = json.loads(json.dumps(BASE))
    for path, value in changes:
        try:
            _set(doc, path, value)
        except (KeyError, TypeError, IndexError):
            continue  # an earlier change replaced the parent
    try:
        scn = from_dict(doc, source="fuzz.toml")
    except ScenarioError as exc:
        msg = exc.message
        assert msg.startswith("fuzz.toml") and "\n" not in msg and msg.isprintable() and len(msg) < 600, msg
        return
    # a valid scenario respects every documented range
    for r in scn.robots:
        for key in ("speed_um_s", "turn_radius_um", "length_um", "width_um", "snap_down_V", "release_V"):
            assert LIMITS[key].contains(getattr(r, key)), (key, getattr(r, key))
        assert r.release_V < r.snap_down_V and r.name.isprintable()
    assert LIMITS["replan_interval_s"].contains(scn.control.replan_interval_s)
    if scn.has_starts:
        assert all(math.isfinite(v) for v in scn.starts.ravel())


toml_values = st.one_of(
    st.sampled_from(["true", "false", '"160"', "nan", "inf", "-inf", "1e308", "1e-300", BIG, "-" + BIG, "[]", "[1, 2]",
                     '"x\\ny"', "{a = 1}", "0", "-1", "1979-05-27"]),
    st.floats(allow_nan=False, allow_infinity=False).map(repr),
    st.integers().map(str),
)
TOML_FIELDS = ["speed_um_s", "turn_radius_um", "snap_down_V", "release_V", "length_um", "width_um", "max_V", "margin_V",
               "camera_dropout", "replan_interval_s", "speed_rel_sd", "camera_heading_sd_deg", "drive_frequency_hz", "name"]


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(TOML_FIELDS), toml_values)
def test_fuzzed_toml_values_load_or_fail_with_one_line(field, value):
    text, n = re.subn(rf"^{field} = .*$", lambda _m: f"{field} = {value}", TEXT, count=1, flags=re.M)
    assert n
    try:
        loads(text, source="f.toml")
    except ScenarioError as exc:
        assert exc.message.startswith("f.toml") and "\n" not in exc.message and exc.message.isprintable()


@settings(max_examples=200, deadline=None)
@given(st.sampled_from(["robots", "primitives", "steps", "goals", "format", "provenance"]), values)
def test_fuzzed_plans_load_or_fail_with_one_line(key, value):
    from stressbots.plans import from_dict as plan_from_dict

    doc = {"format": "stressbots.plan/1", "robots": ["A", "B"], "primitives": [{"name": "P0", "turning": []}],
           "steps": [{"primitive": "P0", "duration_s": 1.0}]}
    doc[key] = value
    try:
        plan = plan_from_dict(doc, source="p.json")
    except StressbotsError as exc:
        assert exc.message.startswith("p.json") and "\n" not in exc.message and exc.message.isprintable()
        return
    assert 0 <= plan.duration_s <= 3600 and all(math.isfinite(d) for d in plan.durations())
