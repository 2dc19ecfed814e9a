"""Waveforms: segments, synthesis, the decoder, sampling, export, JSON, step lists and the CLI command."""

from __future__ import annotations

import dataclasses
import doctest
import json

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import stressbots.waveform as wfm
from stressbots import plans
from stressbots.electrostatics import Electrodes, analyse_scenario, analyse_thresholds
from stressbots.errors import WaveformError
from stressbots.scenario import load
from stressbots.waveform import (
    Drive,
    Hold,
    Segment,
    check_drive_band,
    decode,
    export,
    from_json,
    parse_steps,
    replay,
    sample,
    steps_from_plan,
    synthesize,
    synthesize_primitive,
    to_json,
)

from .conftest import EXAMPLES, assert_user_error
from .electro_reference import brute_shortest, hysteresis, integer_designs, string_float_designs

EXAMPLE = EXAMPLES / "four-robots.toml"


@pytest.fixture(scope="module")
def four():
    return analyse_scenario(load(EXAMPLE))


def replay_samples(v: np.ndarray, vd, vu) -> np.ndarray:
    """Arm states after every sample, by applying each run of equal samples as a level (plain Python)."""
    states = np.zeros((v.size, len(vd)), dtype=np.uint8)
    s = tuple(0 for _ in vd)
    starts = np.flatnonzero(np.r_[True, v[1:] != v[:-1]])
    ends = np.r_[starts[1:], v.size]
    for a, b in zip(starts, ends, strict=False):
        s = hysteresis(s, float(v[a]), vd, vu)
        states[a:b] = s
    return states


# ----------------------------------------------------------------------------------------------------
# Segments


@pytest.mark.parametrize(
    "make, words",
    [
        (lambda: Hold(float("nan"), 1.0), "finite"),
        (lambda: Hold(10.0, -1.0), ">= 0"),
        (lambda: Hold("10", 1.0), "number"),  # type: ignore[arg-type]  # deliberately a str: the check under test
        (lambda: Hold(True, 1.0), "number"),
        (lambda: Drive(105.0, 75.0, 1.0), "below"),
        (lambda: Drive(75.0, 75.0, 1.0), "below"),
        (lambda: Drive(75.0, 105.0, 0.0), "> 0"),
        (lambda: Drive(75.0, float("inf"), 1.0), "finite"),
    ],
)
def test_segments_validate(make, words):
    with pytest.raises(WaveformError, match=words):
        make()


def test_segments_are_frozen_values():
    h = Hold(10, 1)
    assert h == Hold(10.0, 1.0) and isinstance(h.volts, float)
    with pytest.raises(dataclasses.FrozenInstanceError):
        h.volts = 3.0  # type: ignore[misc]


# ----------------------------------------------------------------------------------------------------
# Synthesis and decoding


@settings(max_examples=40, deadline=None)
@given(st.lists(st.lists(st.tuples(st.integers(0, 4), st.floats(0.01, 5.0)), min_size=1, max_size=4), min_size=1, max_size=8))
def test_a_synthesizer_gives_the_waveforms_of_synthesize_frame_after_frame(four, frames):
    """Independent of its memory: every frame's waveform from a Synthesizer (transitions remembered from the frames
    before) equals a fresh :func:`synthesize` from the same arm state, and both equal the segments of
    :func:`synthesize_primitive`, step after step, each from the state the step before left (the definition)."""
    synth = wfm.Synthesizer(four)
    state = None
    for frame in frames:
        steps = [(f"P{k}", d) for k, d in frame]
        assert synth(steps, initial=state) == synthesize(four, steps, initial=state)
        by_step: list = []
        s = np.zeros(four.n, np.uint8) if state is None else state
        for prim, d in steps:
            by_step.extend(synthesize_primitive(four, prim, d, current=s))
            s = np.array(four.primitive(prim).state, dtype=np.uint8)
        assert synth(steps, initial=state) == tuple(by_step)
        state = np.array(four.primitive(steps[-1][0]).state, dtype=np.uint8)


def test_a_synthesizer_names_the_step_it_refuses(four):
    with pytest.raises(WaveformError, match="step 1: unknown primitive"):
        wfm.Synthesizer(four)([("P1", 1.0), ("P9", 1.0)])


def test_primitive_from_each_state_uses_one_hold(four):
    # Raising to P3 from P1: one Hold between V_d,3 (160, A) and V_d,4 (185, C); releasing to P1 from P4:
    # one Hold between V_u,1 (15, B) and V_u,2 (30, D).
    p1, p3, p4 = (np.array(four.primitive(k).state) for k in ("P1", "P3", "P4"))
    assert synthesize_primitive(four, "P3", 2.0, current=p1) == (Hold(172.5, 0.001), Drive(75.0, 105.0, 2.0))
    assert synthesize_primitive(four, "P1", 1.0, current=p4) == (Hold(22.5, 0.001), Drive(75.0, 105.0, 1.0))
    assert synthesize_primitive(four, "P3", 1.0, current=p3) == (Drive(75.0, 105.0, 1.0),)
    assert synthesize_primitive(four, "P0", 1.0, current=p4)[0] == Hold(0.0, 0.001)


def test_round_trip_four_robots(four):
    steps = [("P1", 2.5), ("P4", 1.0), ("P2", 0.5), ("P2", 0.5), ("P0", 1.0), ("P3", 0.25)]
    wf = synthesize(four, steps)
    drives = decode(wf, four.snap_down_V, four.release_V)
    assert [d.states.tolist() for d in drives] == [list(four.primitive(n).state) for n, _ in steps]
    assert all(d.ok for d in drives)
    assert [d.duration_s for d in drives] == [2.5, 1.0, 0.5, 0.5, 1.0, 0.25]
    # Drive k starts after the previous drives and the holds before it.
    t = 0.0
    k = 0
    for seg in wf:
        if isinstance(seg, Drive):
            assert drives[k].t_start_s == pytest.approx(t)
            k += 1
        t += seg.duration_s
    assert replay(wf, four.snap_down_V, four.release_V).final.tolist() == list(four.primitive("P3").state)


@settings(max_examples=60)
@given(string_float_designs(max_n=6), st.data())
def test_synthesise_then_decode_gives_the_intended_states(design, data):
    vd, vu, e, order = design
    e = Electrodes(e.max_V, e.margin_V, e.drive_low_V, e.drive_high_V, drive_frequency_hz=1000.0, hold_s=0.002)
    a = analyse_thresholds(vd, vu, e)
    idx = data.draw(st.lists(st.integers(0, a.n), min_size=1, max_size=8))
    steps = [(a.primitives[k], data.draw(st.floats(0.003, 0.01))) for k in idx]
    wf = synthesize(a, steps)
    drives = decode(wf, vd, vu)
    assert [tuple(d.states.tolist()) for d in drives] == [a.primitives[k].state for k in idx]
    assert all(d.ok for d in drives)
    thresholds = np.concatenate([vd, vu])
    for seg in wf:
        if isinstance(seg, Hold):
            assert 0.0 <= seg.volts <= e.max_V
            assert np.all(np.abs(seg.volts - thresholds) >= e.margin_V - 1e-9)
    # Sampling never leaves [0, max_V] and the samples replay to the same arm states.
    t, v = sample(wf, rate_hz=20_000.0, drive_frequency_hz=e.drive_frequency_hz)
    assert v.min() >= 0.0 and v.max() <= e.max_V
    arms = replay_samples(v, vd, vu)
    for d in drives:
        mid = np.searchsorted(t, d.t_start_s + 0.5 * d.duration_s)
        assert arms[mid].tolist() == d.states.tolist()


@settings(max_examples=60)
@given(integer_designs(max_n=4), st.data())
def test_general_designs_synthesise_or_refuse_for_a_reason(design, data):
    vd, vu, e = design
    a = analyse_thresholds(vd, vu, e)
    target = a.accessible_states[data.draw(st.integers(0, a.count - 1))]
    m = e.margin_V
    flips = any(
        (s == 0 and e.drive_high_V > d - m) or (s == 1 and e.drive_low_V < u + m)
        or (s == 0 and e.drive_high_V >= d) or (s == 1 and e.drive_low_V <= u)
        for s, d, u in zip(target, vd, vu, strict=False)
    )
    reachable = brute_shortest(vd, vu, e.max_V, e.margin_V, [0] * len(vd), target) is not None
    assert reachable  # every accessible state is reachable from all-up, by definition
    if flips:
        with pytest.raises(WaveformError, match="would flip"):
            synthesize_primitive(a, target, 1.0)
        return
    wf = synthesize_primitive(a, target, 1.0)
    holds = [seg for seg in wf if isinstance(seg, Hold)]
    assert len(holds) == brute_shortest(vd, vu, e.max_V, e.margin_V, [0] * len(vd), target)
    (d,) = decode(wf, vd, vu)
    assert d.ok and d.states.tolist() == target.tolist()


def test_refusals(four):
    with pytest.raises(WaveformError, match="not an accessible control state"):
        synthesize_primitive(four, four.state_of(["C"]), 1.0)
    with pytest.raises(WaveformError, match="unknown primitive 'P9'"):
        synthesize(four, [("P9", 1.0)])
    with pytest.raises(WaveformError, match="step 1"):
        synthesize(four, [("P1", 1.0), (four.state_of(["A"]), 1.0)])
    with pytest.raises(WaveformError, match="> 0"):
        synthesize(four, [("P1", 0.0)])
    # A drive band whose high level reaches an up arm's snap-down voltage would flip it.
    with pytest.raises(WaveformError, match="would flip C's arm"):
        check_drive_band(four, four.primitive("P3").state, 75.0, 182.0)
    with pytest.raises(WaveformError, match="would flip B's arm"):
        check_drive_band(four, four.primitive("P1").state, 18.0, 105.0)
    check_drive_band(four, four.primitive("P3").state, 75.0, 180.0)  # exactly margin_V below 185: fine


def test_non_string_design_refuses_a_band_that_flips():
    # B's snap-down voltage (100 V) lies inside the drive band [75, 105]: any state with B up is refused.
    e = Electrodes()
    a = analyse_thresholds([140.0, 100.0], [30.0, 20.0], e, names=["A", "B"])
    assert not a.is_string
    with pytest.raises(WaveformError, match="would flip B's arm"):
        synthesize_primitive(a, a.state_of([]), 1.0)
    wf = synthesize_primitive(a, a.state_of(["B"]), 1.0)
    assert decode(wf, a.snap_down_V, a.release_V)[0].states.tolist() == [0, 1]


def test_decoder_flags_flips_and_chatter():
    vd = np.array([100.0, 150.0, 90.0])
    vu = np.array([20.0, 40.0, 80.0])
    # All up; the band [70, 120] snaps robot 0 (V_d 100) down, and robot 2 (V_u 80, V_d 90) chatters.
    wf: list[Segment] = [Hold(0.0, 0.001), Drive(70.0, 120.0, 1.0)]
    (d,) = decode(wf, vd, vu)
    assert d.entry.tolist() == [0, 0, 0]
    assert d.flipped.tolist() == [True, False, False]
    assert d.chatter.tolist() == [False, False, True]
    assert d.states.tolist() == [1, 0, 0] and not d.ok
    # A zero-length Hold applies nothing; the initial state is honoured.
    (d2,) = decode([Hold(200.0, 0.0), Drive(50.0, 60.0, 1.0)], vd, vu, initial=[1, 0, 1])
    assert d2.entry.tolist() == [1, 0, 1] and d2.t_start_s == 0.0
    # The band's low level 50 V is below robot 2's release voltage 80 V: its arm is released for the drive.
    assert d2.flipped.tolist() == [False, False, True] and d2.states.tolist() == [1, 0, 0]


def test_synthesised_levels_never_leave_the_limits():
    e = Electrodes(max_V=120.0, margin_V=2.0, drive_low_V=40.0, drive_high_V=50.0)
    a = analyse_thresholds([60.0, 80.0, 117.0], [5.0, 20.0, 30.0], e)
    assert a.is_string
    wf = synthesize(a, [(f"P{k}", 0.01) for k in (3, 0, 2, 1, 3)])
    levels = [v for seg in wf for v in ((seg.volts,) if isinstance(seg, Hold) else (seg.low_V, seg.high_V))]
    assert min(levels) >= 0.0 and max(levels) <= 120.0
    with pytest.raises(WaveformError, match="outside"):
        wfm.check_limits([Hold(121.0, 0.001)], 120.0)


# ----------------------------------------------------------------------------------------------------
# Sampling and export


def test_square_wave_at_the_drive_frequency():
    wf: list[Segment] = [Hold(130.0, 0.001), Drive(75.0, 105.0, 0.01)]
    t, v = sample(wf, rate_hz=100_000.0, drive_frequency_hz=1000.0)
    assert t.size == 1100 and np.allclose(np.diff(t), 1e-5)
    assert np.all(v[:100] == 130.0)
    drive = v[100:]
    assert set(drive.tolist()) == {75.0, 105.0}
    assert drive[0] == 105.0  # starts on the high level
    rises = np.count_nonzero((drive[1:] == 105.0) & (drive[:-1] == 75.0))
    assert rises == 9  # 10 cycles in 10 ms, the first starts high
    assert np.count_nonzero(drive == 105.0) == 500


def test_sampling_refuses_rates_that_lose_the_waveform():
    wf: list[Segment] = [Hold(130.0, 0.001), Drive(75.0, 105.0, 0.01)]
    with pytest.raises(WaveformError, match="twice the drive frequency"):
        sample(wf, rate_hz=15_000.0, drive_frequency_hz=10_000.0)
    with pytest.raises(WaveformError, match="no sample"):
        sample([Hold(130.0, 1e-6), Drive(75.0, 105.0, 0.01)], rate_hz=100_000.0, drive_frequency_hz=1000.0)
    with pytest.raises(WaveformError, match="more than"):
        sample([Drive(75.0, 105.0, 1000.0)], rate_hz=100_000.0, drive_frequency_hz=1000.0)


def test_export_npy_csv_json(tmp_path, four):
    wf = synthesize(four, [("P2", 0.01), ("P0", 0.005)])
    t, v = sample(wf, 100_000.0, 10_000.0)
    s = export(wf, tmp_path / "w.npy", rate_hz=100_000.0, drive_frequency_hz=10_000.0)
    arr = np.load(tmp_path / "w.npy")
    assert arr.shape == (t.size, 2) and np.array_equal(arr[:, 1], v) and np.array_equal(arr[:, 0], t)
    assert s.samples == t.size and s.segments == len(wf) and s.holds == 2 and s.drives == 2
    assert s.levels_V == (0.0, 75.0, 105.0, 150.0) and s.min_V == 0.0 and s.max_V == 150.0
    assert s.duration_s == pytest.approx(0.017)
    export(wf, tmp_path / "w.csv", rate_hz=100_000.0, drive_frequency_hz=10_000.0)
    lines = (tmp_path / "w.csv").read_text().splitlines()
    assert lines[0] == "t_s,volts" and len(lines) == t.size + 1
    assert np.allclose(np.loadtxt(tmp_path / "w.csv", delimiter=",", skiprows=1), arr)
    export(wf, tmp_path / "w.json")
    assert from_json(json.loads((tmp_path / "w.json").read_text())) == wf
    with pytest.raises(WaveformError, match="unsupported"):
        export(wf, tmp_path / "w.txt")


def test_json_round_trip_and_errors(four):
    wf = synthesize(four, [("P3", 1.0), ("P1", 2.0)])
    assert from_json(json.loads(json.dumps(to_json(wf)))) == wf
    cases = [
        ({"kind": "hold"}, "[0]"),
        ([{"kind": "ramp", "volts": 1.0}], "[0]"),
        ([{"kind": "hold", "volts": 1.0}], "[0].duration_s"),
        ([{"kind": "hold", "volts": 1.0, "duration_s": 1.0, "colour": 1}], "[0].colour"),
        ([{"kind": "drive", "low_V": 90.0, "high_V": 80.0, "duration_s": 1.0}], "[0]"),
        ([{"kind": "hold", "volts": "x", "duration_s": 1.0}], "[0]"),
    ]
    for data, where in cases:
        with pytest.raises(WaveformError) as info:
            from_json(data, source="w.json")
        msg = info.value.message
        assert msg.startswith("w.json") and "\n" not in msg
        if isinstance(data, list):
            assert f": {where}:" in msg, msg


def test_parse_steps(four):
    steps = parse_steps("P1:2.5, P0:1", four)
    assert [(p.name, d) for p, d in steps] == [("P1", 2.5), ("P0", 1.0)]
    for text, words in [
        ("", "comma-separated"),
        ("P1", "needs a duration"),
        ("P1:x", "not a number"),
        ("P1:-1", "> 0"),
        ("P1:nan", "> 0"),
        ("P8:1", "P0..P4"),
        ("P1:1,,P2:1", "comma-separated"),
    ]:
        with pytest.raises(WaveformError, match=words) as info:
            parse_steps(text, four)
        assert info.value.source == "--steps"


def plan_dict(**over):
    d = {
        "format": "stressbots.plan/1",
        "robots": ["A", "B", "C", "D"],
        "primitives": [{"name": "P0", "turning": []}, {"name": "Q", "turning": ["B", "D"]}],
        "steps": [{"primitive": "Q", "duration_s": 2.5}, {"primitive": "P0", "duration_s": 0.0}, {"primitive": "P0", "duration_s": 1.0}],
    }
    d.update(over)
    return d


def test_steps_from_plan(four):
    steps = steps_from_plan(plans.from_dict(plan_dict()), four)
    assert [(s.tolist(), d) for s, d in steps] == [([0, 1, 0, 1], 2.5), ([0, 0, 0, 0], 1.0)]  # 0 s step skipped
    bad = plans.from_dict(plan_dict(primitives=[{"name": "P0", "turning": []}, {"name": "Q", "turning": ["C"]}]))
    with pytest.raises(WaveformError, match=r"primitives\[1\] \(Q\)\.turning: turning \['C'\] is not an accessible"):
        steps_from_plan(bad, four, source="p.json")
    other = plans.from_dict(plan_dict(robots=["A", "B", "C", "E"], primitives=[{"name": "P0", "turning": []}, {"name": "Q",
                                                                                                               "turning": []}]))
    with pytest.raises(WaveformError, match="robots: robot 'D' of the scenario is not in the plan"):
        steps_from_plan(other, four, source="p.json")


def test_docstring_examples():
    assert doctest.testmod(wfm).failed == 0


# ----------------------------------------------------------------------------------------------------
# CLI


def test_cli_waveform_steps(run_cli, tmp_path, four):
    out = tmp_path / "w.npy"
    r = run_cli("waveform", EXAMPLE, "--steps", "P1:0.02,P3:0.01,P0:0.01", "--out", out)
    assert r.code == 0, r.err
    assert "wrote" in r.out and "every arm as intended" in r.out
    arr = np.load(out)
    assert arr[:, 1].min() >= 0.0 and arr[:, 1].max() <= 200.0
    wf = synthesize(four, [("P1", 0.02), ("P3", 0.01), ("P0", 0.01)])
    assert np.array_equal(arr[:, 1], sample(wf, 100_000.0, 10_000.0)[1])
    r = run_cli("waveform", EXAMPLE, "--steps", "P1:0.01", "--out", tmp_path / "w.csv", "--rate-hz", "50000")
    assert r.code == 0 and (tmp_path / "w.csv").read_text().startswith("t_s,volts\n")


def test_cli_waveform_plan(run_cli, tmp_path):
    plan = tmp_path / "plan.json"
    plan.write_text(json.dumps(plan_dict()))
    out = tmp_path / "w.json"
    r = run_cli("waveform", EXAMPLE, "--plan", plan, "--out", out)
    assert r.code == 0, r.err
    wf = from_json(json.loads(out.read_text()))
    drives = decode(wf, load(EXAMPLE).snap_down_V, load(EXAMPLE).release_V)
    assert [d.states.tolist() for d in drives] == [[0, 1, 0, 1], [0, 0, 0, 0]]


def test_cli_waveform_errors(run_cli, tmp_path):
    plan = tmp_path / "plan.json"
    out = str(tmp_path / "w.npy")
    assert_user_error(run_cli("waveform", EXAMPLE, "--out", out), "exactly one of --steps or --plan")
    plan.write_text(json.dumps(plan_dict()))
    assert_user_error(run_cli("waveform", EXAMPLE, "--steps", "P1:1", "--plan", plan, "--out", out), "exactly one")
    assert_user_error(run_cli("waveform", EXAMPLE, "--steps", "P1:1", "--out", tmp_path / "w.wav"), "--out", ".npy")
    assert_user_error(run_cli("waveform", EXAMPLE, "--steps", "P1:1", "--out", EXAMPLE), "--out", "overwrite the input")
    assert_user_error(run_cli("waveform", EXAMPLE, "--steps", "P7:1", "--out", out), "--steps", "P7")
    assert_user_error(run_cli("waveform", EXAMPLE, "--plan", plan, "--out", plan), "overwrite the input")
    assert_user_error(run_cli("waveform", EXAMPLE, "--steps", "P1:0.01", "--rate-hz", "1000", "--out", out), "--rate-hz")
    plan.write_text(json.dumps(plan_dict(primitives=[{"name": "P0", "turning": []}, {"name": "Q", "turning": ["A"]}])))
    assert_user_error(run_cli("waveform", EXAMPLE, "--plan", plan, "--out", out), str(plan), "primitives[1] (Q).turning", "accessible")
    plan.write_text("{not json")
    assert_user_error(run_cli("waveform", EXAMPLE, "--plan", plan, "--out", out), str(plan), "not valid JSON")
    plan.write_text(json.dumps(plan_dict(steps=[{"primitive": "Q", "duration_s": -1}])))
    assert_user_error(run_cli("waveform", EXAMPLE, "--plan", plan, "--out", out), "steps[0].duration_s")
    assert_user_error(run_cli("waveform", tmp_path / "nope.toml", "--steps", "P1:1", "--out", out), "nope.toml", "no such file")
    assert not (tmp_path / "w.npy").exists()
