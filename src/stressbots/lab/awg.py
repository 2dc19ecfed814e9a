"""The arbitrary waveform generator (Keysight 33500B class): compile a waveform to DAC codes and upload it.

The electrode array is driven by a high-voltage amplifier of voltage gain ``gain`` behind the generator,
so an electrode level ``V`` needs the generator output ``u = (V - offset_V) / gain`` (SPEC 9.1). A
waveform (Hold/Drive segments, :mod:`stressbots.waveform`) is sampled by
:func:`stressbots.waveform.sample` (piecewise-constant levels, a Drive a square wave that starts on
``high_V``), mapped to ``u`` and quantised to int16 DAC codes: ``-32767`` stands for ``u_low`` (the
instrument's ``VOLT:LOW``), ``+32767`` for ``u_high`` (``VOLT:HIGH``), linear in between, rounded to
nearest.

Safety first: :func:`compile_awg` refuses, before any instrument is touched, an electrode level outside
``[0, max_V]`` (also after quantisation), a generator level outside ``[-awg_max_V, awg_max_V]``, fewer
than :data:`MIN_POINTS` or more than ``max_points`` samples. :func:`upload` sends the SCPI sequence of
SPEC 9.1 over an open PyVISA resource and checks ``SYST:ERR?`` after the data and after the settings; on
any instrument error it switches the output off and raises :class:`~stressbots.errors.StressbotsError`
with the instrument's message. The output is switched on only when asked (``output_on=True``).

Examples
--------
>>> from stressbots.electrostatics import Electrodes
>>> from stressbots.waveform import Drive, Hold
>>> prog = compile_awg([Hold(140.0, 0.001), Drive(75.0, 105.0, 0.001)], Electrodes(), gain=20.0,
...                    sample_rate_hz=100_000.0)
>>> prog.points, prog.u_low, prog.u_high
(200, 3.75, 7.0)
>>> prog.codes[:2].tolist(), prog.electrode_volts()[:1].tolist()
([32767, 32767], [140.0])
"""

from __future__ import annotations

import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from ..errors import StressbotsError, WaveformError

__all__ = [
    "DAC_MAX",
    "MIN_POINTS",
    "AwgProgram",
    "AwgError",
    "compile_awg",
    "upload",
    "export_program",
    "arb_text",
    "scpi_number",
    "play_once",
]

#: Largest DAC code; ``-DAC_MAX`` stands for ``VOLT:LOW`` and ``+DAC_MAX`` for ``VOLT:HIGH`` (SPEC 9.1).
DAC_MAX = 32767
#: Fewest points the 33500 series accepts in an arbitrary waveform.
MIN_POINTS = 8
#: Span (V) given to ``VOLT:HIGH - VOLT:LOW`` when the waveform holds one level only (the instrument
#: needs HIGH > LOW); every code is then -32767, which stands for the level itself.
MIN_SPAN_V = 0.001
#: Slack (V, electrode side) for rounding when checking quantised levels against ``[0, max_V]``.
LEVEL_TOL_V = 1e-9


class AwgError(StressbotsError):
    """A waveform the generator must not play, or an instrument that reported an error."""


@dataclass(frozen=True, eq=False)
class AwgProgram:
    """A waveform compiled for the generator.

    Attributes
    ----------
    codes:
        ``(N,)`` int16 DAC codes, one per sample.
    u_low, u_high:
        Generator output (V) that codes ``-32767`` and ``+32767`` stand for (``VOLT:LOW`` / ``VOLT:HIGH``).
    sample_rate_hz:
        Sample rate (Hz) the instrument plays the codes at (``FUNC:ARB:SRAT``).
    gain, offset_V:
        Amplifier: electrode level ``V = gain * u + offset_V``.
    """

    codes: np.ndarray
    u_low: float
    u_high: float
    sample_rate_hz: float
    gain: float
    offset_V: float = 0.0

    @property
    def points(self) -> int:
        return int(self.codes.size)

    @property
    def duration_s(self) -> float:
        """Play time (s) of one pass through the codes."""
        return self.points / self.sample_rate_hz

    def times_s(self) -> np.ndarray:
        """Sample times (s), ``k / sample_rate_hz``."""
        return np.arange(self.points, dtype=np.float64) / self.sample_rate_hz

    def awg_volts(self) -> np.ndarray:
        """Generator output (V) each code stands for."""
        return codes_to_volts(self.codes, self.u_low, self.u_high)

    def electrode_volts(self) -> np.ndarray:
        """Electrode level (V) each code produces behind the amplifier: ``gain * u + offset_V``."""
        return self.gain * self.awg_volts() + self.offset_V


def volts_to_codes(u: np.ndarray, u_low: float, u_high: float) -> np.ndarray:
    """Generator volts -> int16 DAC codes (``u_low -> -32767``, ``u_high -> +32767``, round to nearest)."""
    x = -DAC_MAX + (np.asarray(u, dtype=np.float64) - u_low) * (2 * DAC_MAX) / (u_high - u_low)
    return np.clip(np.rint(x), -DAC_MAX, DAC_MAX).astype(np.int16)


def codes_to_volts(codes: np.ndarray, u_low: float, u_high: float) -> np.ndarray:
    """int16 DAC codes -> the generator volts they stand for (inverse of :func:`volts_to_codes`)."""
    c = np.asarray(codes, dtype=np.float64)
    return u_low + (c + DAC_MAX) * (u_high - u_low) / (2 * DAC_MAX)


def _positive(name: str, x: Any) -> float:
    try:
        f = float(x)
    except (TypeError, ValueError):
        raise AwgError(f"must be a number, got {x!r}", field=name) from None
    if not (math.isfinite(f) and f > 0):
        raise AwgError(f"must be a finite number > 0, got {f:g}", field=name)
    return f


class _Settings(NamedTuple):
    """The checked settings of a compilation: the amplifier (electrode level ``gain * u + offset_V``), the
    sample rate (Hz) and the generator's output limit (V)."""

    gain: float
    offset_V: float
    sample_rate_hz: float
    awg_max_V: float


def _checked_settings(gain: Any, offset_V: Any, sample_rate_hz: Any, awg_max_V: Any, max_points: int) -> _Settings:
    """The settings as numbers, or an :class:`AwgError` naming the first bad one (gain, sample rate,
    generator limit, offset, then the memory size)."""
    g = _positive("gain", gain)
    rate = _positive("sample_rate_hz", sample_rate_hz)
    umax = _positive("awg_max_V", awg_max_V)
    off = float(offset_V)
    if not math.isfinite(off):
        raise AwgError(f"must be finite, got {off!r}", field="offset_V")
    if int(max_points) < MIN_POINTS:
        raise AwgError(f"must be at least {MIN_POINTS}, got {max_points}", field="max_points")
    return _Settings(g, off, rate, umax)


def _check_point_count(total_s: float, rate: float, max_points: int, drive_frequency_hz: float) -> None:
    """Refuse a waveform of ``total_s`` seconds whose samples at ``rate`` (Hz) overflow the generator's
    memory (saying how to split the plan) or are fewer than :data:`MIN_POINTS`."""
    count = int(math.ceil(total_s * rate - 1e-9))
    if count > max_points:
        fit_s = max_points / rate
        pieces = math.ceil(count / max_points)
        raise AwgError(
            f"{count} points ({total_s:g} s at {rate:g} Hz) exceed the generator's {int(max_points)}: split the plan into "
            f"at least {pieces} pieces of at most {fit_s:g} s each (fewer steps per upload), or lower --sample-rate-hz "
            f"(not below {2 * drive_frequency_hz:g} Hz, twice the drive frequency)"
        )
    if count < MIN_POINTS:
        raise AwgError(
            f"{count} points ({total_s:g} s at {rate:g} Hz) are fewer than the {MIN_POINTS} the generator needs: "
            f"raise --sample-rate-hz or lengthen the waveform"
        )


def _output_range(u: np.ndarray, s: _Settings) -> tuple[float, float]:
    """``(VOLT:LOW, VOLT:HIGH)`` (V) for the generator levels ``u``: their range, refused beyond
    ``+-awg_max_V``, widened to :data:`MIN_SPAN_V` (inside the limit) when the waveform holds one level."""
    lo, hi = float(u.min()), float(u.max())
    umax = s.awg_max_V
    if lo < -umax or hi > umax:
        bad = lo if lo < -umax else hi
        raise AwgError(
            f"generator level {bad:g} V (electrode {s.gain * bad + s.offset_V:g} V at gain {s.gain:g}, offset {s.offset_V:g} V) "
            f"is outside [-{umax:g}, {umax:g}] V: raise the amplifier gain or change the offset"
        )
    if hi - lo < MIN_SPAN_V:
        if lo + MIN_SPAN_V <= umax:
            hi = lo + MIN_SPAN_V
        else:
            lo = hi - MIN_SPAN_V
    return lo, hi


def _check_quantised(prog: AwgProgram, max_V: float) -> None:
    """Refuse a program whose quantised codes put an electrode outside ``[0, max_V]`` (V, within
    :data:`LEVEL_TOL_V`): rounding to the DAC's grid may push a level at the limit beyond it."""
    ev = prog.electrode_volts()
    if ev.min() < -LEVEL_TOL_V or ev.max() > max_V + LEVEL_TOL_V:
        raise AwgError(
            f"after quantisation an electrode level reaches {ev.min() if ev.min() < 0 else ev.max():g} V, outside "
            f"[0, {max_V:g}] V (max_V): keep the waveform's levels further inside the range"
        )


def compile_awg(
    waveform: Sequence[Any],
    electrodes,
    *,
    gain: float,
    offset_V: float = 0.0,
    sample_rate_hz: float,
    awg_max_V: float = 10.0,
    max_points: int = 1_000_000,
) -> AwgProgram:
    """Sample a waveform and quantise it to the generator's DAC codes, refusing anything unsafe.

    Parameters
    ----------
    waveform:
        Hold/Drive segments (:mod:`stressbots.waveform`).
    electrodes:
        :class:`stressbots.electrostatics.Electrodes`: ``max_V`` (electrode limit) and the drive frequency.
    gain:
        Voltage gain of the amplifier between generator and electrodes (> 0).
    offset_V:
        Electrode level (V) at generator output 0 V.
    sample_rate_hz:
        Sample rate (Hz); at least twice the drive frequency (a Drive is a square wave).
    awg_max_V:
        The generator's output limit (V): every ``u`` must lie in ``[-awg_max_V, awg_max_V]``.
    max_points:
        Most samples the generator's memory holds.

    Raises
    ------
    AwgError
        A level outside the electrode or generator range, fewer than 8 or more than ``max_points``
        points (the message says how to shorten or split the plan), or bad parameters.
    """
    from ..waveform import check_limits, duration, sample

    s = _checked_settings(gain, offset_V, sample_rate_hz, awg_max_V, max_points)
    segs = tuple(waveform)
    try:
        check_limits(segs, electrodes.max_V)
    except WaveformError as exc:
        raise AwgError(f"electrode level outside [0, max_V]: {exc.problem}") from None
    _check_point_count(duration(segs), s.sample_rate_hz, max_points, electrodes.drive_frequency_hz)
    try:
        _, v = sample(segs, s.sample_rate_hz, electrodes.drive_frequency_hz, max_samples=int(max_points))
    except WaveformError as exc:
        raise AwgError(exc.problem.replace("--rate-hz", "--sample-rate-hz"), field="sample_rate_hz") from None
    u = (v - s.offset_V) / s.gain
    lo, hi = _output_range(u, s)
    prog = AwgProgram(volts_to_codes(u, lo, hi), lo, hi, s.sample_rate_hz, s.gain, s.offset_V)
    _check_quantised(prog, electrodes.max_V)
    return prog


# ----------------------------------------------------------------------------------------------------
# Export


def scpi_number(x: float) -> str:
    """A number as SCPI text without an exponent and with a decimal point (``100000.0``, ``-2.5``).

    >>> scpi_number(1e5), scpi_number(5), scpi_number(-0.125)
    ('100000.0', '5.0', '-0.125')
    """
    return np.format_float_positional(float(x), trim="0")


def arb_text(program: AwgProgram) -> str:
    """The 33500 series' text ARB file: header lines, ``Data:``, then one DAC code per line (CRLF)."""
    header = [
        "File Format:1.10",
        "Checksum:0",
        "Channel Count:1",
        f"Sample Rate:{scpi_number(program.sample_rate_hz)}",
        f"High Level:{scpi_number(program.u_high)}",
        f"Low Level:{scpi_number(program.u_low)}",
        'Data Type:"short"',
        'Filter:"STEP"',
        f"Data Points:{program.points}",
        "Data:",
    ]
    return "\r\n".join(header + [str(int(c)) for c in program.codes]) + "\r\n"


def export_program(program: AwgProgram, path) -> Path:
    """Write a program atomically, format by suffix: ``.arb``, ``.csv`` (``t_s,awg_V,electrode_V``) or ``.npy``.

    ``.npy`` holds the int16 codes (what the generator stores); the levels follow from ``u_low`` /
    ``u_high`` (printed by the CLI and in the ``.arb`` header).
    """
    from ..outputs import write_bytes, write_text

    target = Path(path)
    suffix = target.suffix.lower()
    if suffix == ".arb":
        write_text(target, arb_text(program))
    elif suffix == ".csv":
        buf = io.StringIO()
        buf.write("t_s,awg_V,electrode_V\n")
        np.savetxt(buf, np.stack([program.times_s(), program.awg_volts(), program.electrode_volts()], axis=1),
                   fmt="%.10g", delimiter=",")
        write_text(target, buf.getvalue())
    elif suffix == ".npy":
        buf_b = io.BytesIO()
        np.save(buf_b, program.codes)
        write_bytes(target, buf_b.getvalue())
    else:
        raise AwgError(f"unsupported output {target.name!r}: use a .arb, .csv or .npy file", source="--out")
    return target


# ----------------------------------------------------------------------------------------------------
# Upload (SCPI over PyVISA)


def _check_errors(instrument, stage: str) -> None:
    """Query ``SYST:ERR?``; anything but error 0 switches the output off and raises the instrument's message."""
    reply = str(instrument.query("SYST:ERR?")).strip()
    head = reply.split(",", 1)[0].strip()
    try:
        ok = int(head) == 0
    except ValueError:
        ok = False
    if not ok:
        try:
            instrument.write("OUTP1 OFF")
        finally:
            what = f"reported an error after {stage}: {reply}" if reply else f"gave no error status after {stage} (no reply to SYST:ERR?)"
            raise AwgError(f"the generator {what} (output left off)")


def upload(program: AwgProgram, instrument, *, name: str = "stressbots", ascii: bool = False, output_on: bool = False) -> None:
    """Send a compiled program to channel 1 of an open PyVISA resource (SPEC 9.1 sequence).

    ``*IDN?``, ``*CLS``, ``SOUR1:DATA:VOL:CLE``; the data as an IEEE 488.2 binary block of little-endian
    int16 (after ``FORM:BORD SWAP``) or, with ``ascii``, as comma-separated codes; ``*OPC?``;
    ``SYST:ERR?``; the settings (arb name, function, sample rate, step filter, HIGH/LOW levels, high-Z
    load); ``SYST:ERR?``; ``OUTP1 ON`` only with ``output_on``. An instrument error aborts with the output
    switched off. A resource whose ``*IDN?`` reply is empty is refused before anything is written: nothing
    answers there (pyvisa-sim opens any name and answers silence).
    """
    if not isinstance(program, AwgProgram):
        raise TypeError("program must be an AwgProgram from compile_awg")
    if not (name and name.replace("_", "").isalnum() and name[0].isalpha() and len(name) <= 12):
        raise AwgError(f"arb name {name!r} must start with a letter, hold letters, digits or _, at most 12 characters",
                       field="name")
    if not str(instrument.query("*IDN?")).strip():
        raise AwgError("no instrument answers at this resource (*IDN? returned nothing): check the resource name")
    instrument.write("*CLS")
    instrument.write("SOUR1:DATA:VOL:CLE")
    if ascii:
        instrument.write(f"SOUR1:DATA:ARB:DAC {name}," + ",".join(str(int(c)) for c in program.codes))
    else:
        instrument.write("FORM:BORD SWAP")
        instrument.write_binary_values(f"SOUR1:DATA:ARB:DAC {name},", program.codes.astype(np.int16).tolist(),
                                       datatype="h", is_big_endian=False)
    instrument.query("*OPC?")
    _check_errors(instrument, "the data")
    for cmd in (
        f"SOUR1:FUNC:ARB {name}",
        "SOUR1:FUNC ARB",
        f"SOUR1:FUNC:ARB:SRAT {scpi_number(program.sample_rate_hz)}",
        "SOUR1:FUNC:ARB:FILT STEP",
        f"SOUR1:VOLT:HIGH {scpi_number(program.u_high)}",
        f"SOUR1:VOLT:LOW {scpi_number(program.u_low)}",
        "OUTP1:LOAD INF",
    ):
        instrument.write(cmd)
    _check_errors(instrument, "the settings")
    if output_on:
        instrument.write("OUTP1 ON")


def play_once(program: AwgProgram, instrument, *, name: str = "stressbots", sleep=None, burst: bool = True) -> None:
    """Upload a program and play it once, then switch the output off.

    With ``burst`` (real instruments): after :func:`upload` a bus-triggered burst of one cycle
    (``SOUR1:BURS:MODE TRIG``, ``SOUR1:BURS:NCYC 1``, ``TRIG1:SOUR BUS``, ``SOUR1:BURS:STAT ON``), checked
    with ``SYST:ERR?``, then ``OUTP1 ON``, ``*TRG``, a wait of the program's duration (``sleep``, default
    :func:`time.sleep`), ``*OPC?`` and ``OUTP1 OFF``. Without it (instruments or simulators that know only
    the SPEC 9.1 commands): :func:`upload` with ``output_on=True``, the wait, ``OUTP1 OFF``; the
    waveform then repeats until the output goes off, so the timing of the wait matters.
    """
    import time

    wait = time.sleep if sleep is None else sleep
    upload(program, instrument, name=name, output_on=not burst)
    try:
        if burst:
            for cmd in ("SOUR1:BURS:MODE TRIG", "SOUR1:BURS:NCYC 1", "TRIG1:SOUR BUS", "SOUR1:BURS:STAT ON"):
                instrument.write(cmd)
            _check_errors(instrument, "the burst settings")
            instrument.write("OUTP1 ON")
            instrument.write("*TRG")
        wait(program.duration_s)
        if burst:
            instrument.query("*OPC?")
    finally:
        instrument.write("OUTP1 OFF")
