"""The waveform generator (SPEC 9.1): compile, export, upload, and the safety refusals."""

from __future__ import annotations

import struct
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from stressbots.electrostatics import Electrodes
from stressbots.lab.awg import (
    DAC_MAX,
    AwgError,
    AwgProgram,
    arb_text,
    codes_to_volts,
    compile_awg,
    upload,
    volts_to_codes,
)
from stressbots.waveform import Drive, Hold, sample

DATA = Path(__file__).parent / "data"
E = Electrodes()  # max_V 200, drive 10 kHz
WF = (Hold(140.0, 0.0002), Drive(75.0, 105.0, 0.0003), Hold(20.0, 0.0001))


class RecordingInstrument:
    """A fake PyVISA resource in the style of pymeasure's ``expected_protocol``: it records every message
    and answers queries from a script. Binary blocks are encoded by pyvisa's own ``write_binary_values``."""

    _write_termination = "\n"
    _encoding = "ascii"

    def __init__(self, replies: dict[str, list[str]] | None = None):
        self.log: list[tuple[str, Any]] = []  # (kind, message): str for write/query, bytes for write_raw
        self.replies = {k: list(v) for k, v in (replies or {}).items()}

    def write(self, msg: str) -> None:
        self.log.append(("write", msg))

    def query(self, msg: str) -> str:
        self.log.append(("query", msg))
        default = {"*IDN?": "Agilent Technologies,33522B,0,1", "*OPC?": "1", "SYST:ERR?": '+0,"No error"'}[msg]
        queue = self.replies.get(msg)
        return queue.pop(0) if queue else default

    def write_raw(self, data: bytes) -> int:
        self.log.append(("write_raw", data))
        return len(data)

    def write_binary_values(self, *args, **kwargs):
        pytest.importorskip("pyvisa")
        from pyvisa.resources import MessageBasedResource

        # duck-typed on purpose: pyvisa's block encoder only needs write_raw and the two attributes above
        return MessageBasedResource.write_binary_values(self, *args, **kwargs)  # type: ignore[arg-type]


def _program() -> AwgProgram:
    return compile_awg(WF, E, gain=20.0, offset_V=0.0, sample_rate_hz=100_000.0)


def test_compile_maps_levels_to_codes_by_the_spec():
    prog = _program()
    t, v = sample(WF, 100_000.0, E.drive_frequency_hz)
    assert prog.points == t.size == 60
    u = v / 20.0
    assert (prog.u_low, prog.u_high) == (u.min(), u.max()) == (1.0, 7.0)
    # -32767 -> VOLT:LOW, +32767 -> VOLT:HIGH, linear, round to nearest (independent formula)
    expected = np.rint(-DAC_MAX + (u - 1.0) / 6.0 * 2 * DAC_MAX).astype(int)
    assert prog.codes.dtype == np.int16
    assert prog.codes.tolist() == expected.tolist()
    assert prog.codes[0] == DAC_MAX and prog.codes[-1] == -DAC_MAX
    np.testing.assert_allclose(prog.electrode_volts(), v, atol=6.0 * 20 / 65534)


def test_upload_binary_sends_the_exact_spec_sequence():
    prog = _program()
    inst = RecordingInstrument()
    upload(prog, inst, name="wf1")
    payload = struct.pack(f"<{prog.points}h", *prog.codes.tolist())
    nbytes = str(len(payload)).encode()
    block = b"#" + str(len(nbytes)).encode() + nbytes + payload
    assert inst.log == [
        ("query", "*IDN?"),
        ("write", "*CLS"),
        ("write", "SOUR1:DATA:VOL:CLE"),
        ("write", "FORM:BORD SWAP"),
        ("write_raw", b"SOUR1:DATA:ARB:DAC wf1," + block + b"\n"),
        ("query", "*OPC?"),
        ("query", "SYST:ERR?"),
        ("write", "SOUR1:FUNC:ARB wf1"),
        ("write", "SOUR1:FUNC ARB"),
        ("write", "SOUR1:FUNC:ARB:SRAT 100000.0"),
        ("write", "SOUR1:FUNC:ARB:FILT STEP"),
        ("write", "SOUR1:VOLT:HIGH 7.0"),
        ("write", "SOUR1:VOLT:LOW 1.0"),
        ("write", "OUTP1:LOAD INF"),
        ("query", "SYST:ERR?"),
    ]
    assert block.startswith(b"#3120") and payload[:2] == b"\xff\x7f"  # 120 bytes; +32767 little-endian


def test_upload_output_on_and_ascii():
    prog = _program()
    inst = RecordingInstrument()
    upload(prog, inst, ascii=True, output_on=True)
    msgs = [m for _, m in inst.log]
    assert "FORM:BORD SWAP" not in msgs
    assert msgs[3] == "SOUR1:DATA:ARB:DAC stressbots," + ",".join(str(c) for c in prog.codes.tolist())
    assert msgs[-1] == "OUTP1 ON" and msgs.count("OUTP1 ON") == 1


@pytest.mark.parametrize("when", [0, 1])
def test_instrument_error_aborts_with_output_off(when):
    errs = ['+0,"No error"'] * when + ['-222,"Data out of range"']
    inst = RecordingInstrument({"SYST:ERR?": errs})
    with pytest.raises(AwgError, match="Data out of range"):
        upload(_program(), inst, output_on=True)
    msgs = [m for _, m in inst.log]
    assert msgs[-1] == "OUTP1 OFF" and "OUTP1 ON" not in msgs
    assert ("SOUR1:FUNC ARB" in msgs) == (when == 1)


@pytest.mark.parametrize(
    "wf, kwargs, match",
    [
        ((Hold(210.0, 0.001),), {}, "max_V"),  # electrode level above max_V
        ((Hold(140.0, 0.001),), {"gain": 10.0}, r"outside \[-10, 10\]"),  # u = 14 V
        ((Hold(140.0, 0.001),), {"gain": 1.0, "offset_V": 120.0}, r"outside \[-10, 10\]"),  # u = 20 V
        ((Hold(-1.0, 0.001),), {}, "max_V"),  # electrode level below 0
        ((Drive(75.0, 105.0, 20.5),), {}, "split the plan into at least 3 pieces of at most 10 s"),
        ((Hold(140.0, 0.00005),), {}, "fewer than the 8"),
    ],
)
def test_refusals_before_touching_the_instrument(wf, kwargs, match):
    args = {"gain": 20.0, "sample_rate_hz": 100_000.0, **kwargs}
    with pytest.raises(AwgError, match=match):
        compile_awg(wf, E, **args)


def test_quantised_levels_stay_inside_max_V():
    # a level at max_V exactly: codes stand for at most max_V (no rounding above it)
    prog = compile_awg((Hold(200.0, 0.0001), Hold(0.0, 0.0001)), E, gain=20.0, sample_rate_hz=100_000.0)
    ev = prog.electrode_volts()
    assert ev.max() <= 200.0 + 1e-9 and ev.min() >= -1e-9


def test_constant_waveform_gets_a_valid_span():
    prog = compile_awg((Hold(100.0, 0.0001),), E, gain=10.0, sample_rate_hz=100_000.0)
    assert prog.u_high > prog.u_low
    np.testing.assert_allclose(prog.electrode_volts(), 100.0)


def test_arb_file_format():
    prog = _program()
    lines = arb_text(prog).split("\r\n")
    assert lines[0] == "File Format:1.10"
    head = dict(line.split(":", 1) for line in lines[: lines.index("Data:")])
    assert head["Data Points"] == "60" and float(head["High Level"]) == 7.0 and float(head["Low Level"]) == 1.0
    assert head["Sample Rate"] == "100000.0"
    codes = [int(x) for x in lines[lines.index("Data:") + 1:] if x]
    assert codes == prog.codes.tolist()


@settings(max_examples=60, deadline=None)
@given(
    levels=st.lists(st.floats(0.0, 200.0), min_size=1, max_size=20),
    gain=st.floats(20.01, 100.0),
    frac=st.floats(-1.0, 1.0),
)
def test_levels_codes_levels_within_one_lsb(levels, gain, frac):
    offset = frac * (10.0 * gain - 200.0)  # any offset that keeps 0..200 V inside the generator's +-10 V
    wf = tuple(Hold(v, 0.0001) for v in levels) + (Hold(levels[0], 0.0001),) * 8
    prog = compile_awg(wf, E, gain=gain, offset_V=offset, sample_rate_hz=100_000.0, awg_max_V=10.0)
    t, v = sample(wf, 100_000.0)
    lsb_V = gain * (prog.u_high - prog.u_low) / (2 * DAC_MAX)  # one code, electrode side
    assert np.all(np.abs(prog.electrode_volts() - v) <= lsb_V + 1e-9)
    # the codes map back to themselves
    assert np.array_equal(volts_to_codes(codes_to_volts(prog.codes, prog.u_low, prog.u_high), prog.u_low, prog.u_high), prog.codes)


def test_pyvisa_sim_ascii_flow_reads_back_the_state():
    pyvisa = pytest.importorskip("pyvisa")
    pytest.importorskip("pyvisa_sim")
    rm = pyvisa.ResourceManager(f"{DATA / 'awg-sim.yaml'}@sim")
    inst = rm.open_resource("TCPIP::awg.local::INSTR", read_termination="\n", write_termination="\n")
    try:
        prog = _program()
        upload(prog, inst, name="tee1", ascii=True)
        assert inst.query("OUTP1?") == "OFF"
        assert inst.query("SOUR1:FUNC?") == "ARB" and inst.query("SOUR1:FUNC:ARB?") == "tee1"
        assert float(inst.query("SOUR1:FUNC:ARB:SRAT?")) == 100_000.0
        assert inst.query("SOUR1:FUNC:ARB:FILT?") == "STEP" and inst.query("OUTP1:LOAD?") == "INF"
        assert (float(inst.query("SOUR1:VOLT:HIGH?")), float(inst.query("SOUR1:VOLT:LOW?"))) == (prog.u_high, prog.u_low)
        name, *codes = inst.query("SOUR1:DATA:ARB:DAC?").split(",")
        assert name == "tee1" and [int(c) for c in codes] == prog.codes.tolist()
        upload(prog, inst, ascii=True, output_on=True)
        assert inst.query("OUTP1?") == "ON"
    finally:
        inst.close()
        rm.close()


def test_pyvisa_sim_error_leaves_output_off():
    pyvisa = pytest.importorskip("pyvisa")
    pytest.importorskip("pyvisa_sim")
    rm = pyvisa.ResourceManager(f"{DATA / 'awg-sim.yaml'}@sim")
    inst = rm.open_resource("TCPIP::awg.local::INSTR", read_termination="\n", write_termination="\n")
    try:
        # 300 MHz is beyond the simulated instrument's sample rate: it queues an error at the settings
        prog = AwgProgram(np.zeros(8, np.int16), 0.0, 1.0, 3e8, 20.0)
        with pytest.raises(AwgError, match="error after the settings"):
            upload(prog, inst, ascii=True, output_on=True)
        assert inst.query("OUTP1?") == "OFF"
    finally:
        inst.close()
        rm.close()


def test_cli_awg_exports_and_uploads_to_the_simulated_instrument(run_cli, tmp_path):
    from tests.conftest import EXAMPLES

    pytest.importorskip("pyvisa_sim")
    out = tmp_path / "wf.arb"
    r = run_cli("awg", EXAMPLES / "four-robots.toml", "--steps", "P1:0.002,P0:0.001", "--out", out, "--gain", "25",
                "--upload", "TCPIP::awg.local::INSTR", "--visa-library", f"{DATA / 'awg-sim.yaml'}@sim", "--ascii")
    assert r.code == 0, r.err
    assert "uploaded" in r.out and "left off" in r.out
    lines = out.read_bytes().decode().split("\r\n")
    points = int(next(ln for ln in lines if ln.startswith("Data Points:")).split(":")[1])
    assert lines[0] == "File Format:1.10" and points == len(lines) - lines.index("Data:") - 2


def test_upload_refuses_a_resource_where_nothing_answers():
    inst = RecordingInstrument({"*IDN?": [""]})
    with pytest.raises(AwgError, match="no instrument answers"):
        upload(_program(), inst)
    assert inst.log == [("query", "*IDN?")]  # nothing written after the silent *IDN?


def test_cli_awg_names_an_unknown_simulated_resource(run_cli, tmp_path):
    from tests.conftest import EXAMPLES, assert_user_error

    pytest.importorskip("pyvisa_sim")
    r = run_cli("awg", EXAMPLES / "four-robots.toml", "--steps", "P1:0.002", "--out", tmp_path / "wf.arb", "--gain", "25",
                "--upload", "TCPIP::nothere::INSTR", "--visa-library", f"{DATA / 'awg-sim.yaml'}@sim", "--ascii")
    assert_user_error(r, "--upload TCPIP::nothere::INSTR", "no instrument answers")


def test_cli_awg_refuses_before_writing(run_cli, tmp_path):
    from tests.conftest import EXAMPLES, assert_user_error

    out = tmp_path / "wf.csv"
    r = run_cli("awg", EXAMPLES / "four-robots.toml", "--steps", "P1:0.01", "--out", out, "--gain", "5")
    assert_user_error(r, "outside [-10, 10] V")
    assert not out.exists()
    assert_user_error(run_cli("awg", EXAMPLES / "four-robots.toml", "--steps", "P1:0.01", "--out", tmp_path / "x.wav"), "--out", ".arb")


def test_docstring_examples():
    import doctest

    from stressbots.lab import awg

    assert doctest.testmod(awg).failed == 0
