"""Voltage waveforms: Hold/Drive segments, synthesis of primitives, the decoder, sampling and export.

A waveform is a sequence of segments (SPEC 4):

- :class:`Hold` ``(volts, duration_s)``: one level, held long enough for arms to snap down or release.
  Robots do not move.
- :class:`Drive` ``(low_V, high_V, duration_s)``: power delivery, a square wave between two levels at the
  drive frequency; every robot moves for ``duration_s`` with its arm state (arm down = turning).

Synthesis (:func:`synthesize_primitive`, :func:`synthesize`) turns primitives into segments with the
fewest level changes (:func:`stressbots.electrostatics.level_sequence`), never leaves ``[0, max_V]``, and
refuses an inaccessible state or a drive band that would flip an arm of the intended state.

The decoder (:func:`decode`, :func:`replay`) is the one source of truth for what a waveform does: it
replays *any* waveform through the hysteresis model with the exact thresholds and reports, for every
Drive, the interval and the arm states the robots hold during it, flagging arms that the drive band
itself flips or makes chatter. The simulator calls it to know which robots turn when.

Examples
--------
>>> from stressbots.electrostatics import Electrodes, analyse_thresholds
>>> from stressbots.waveform import synthesize, decode
>>> a = analyse_thresholds([160.0, 120.0], [45.0, 15.0], Electrodes(), names=["A", "B"])
>>> wf = synthesize(a, [("P1", 2.0), ("P0", 1.0)])
>>> wf[0]
Hold(volts=140.0, duration_s=0.001)
>>> [d.states.tolist() for d in decode(wf, a.snap_down_V, a.release_V)]
[[0, 1], [0, 0]]
"""

from __future__ import annotations

import io
import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from .electrostatics import TOLERANCE_V, ControlAnalysis, Primitive, apply_level, level_sequence
from .errors import WaveformError

__all__ = [
    "Hold",
    "Drive",
    "Segment",
    "DriveInterval",
    "Decoded",
    "WaveformSummary",
    "synthesize_primitive",
    "synthesize",
    "Synthesizer",
    "check_limits",
    "check_drive_band",
    "replay",
    "decode",
    "duration",
    "excerpt",
    "sample",
    "export",
    "summarize",
    "to_json",
    "from_json",
    "parse_steps",
    "steps_from_plan",
]


def _finite(name: str, x: Any) -> float:
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise WaveformError(f"{name} must be a number, got {type(x).__name__} {x!r}")
    f = float(x)
    if not math.isfinite(f):
        raise WaveformError(f"{name} must be finite, got {f!r}")
    return f


@dataclass(frozen=True)
class Hold:
    """Apply ``volts`` (V) for ``duration_s`` (s, >= 0) so that arms snap down or release.

    A zero-length Hold applies no level (the hardware never outputs it) and the decoder ignores it.
    """

    volts: float
    duration_s: float

    def __post_init__(self) -> None:
        object.__setattr__(self, "volts", _finite("Hold.volts", self.volts))
        d = _finite("Hold.duration_s", self.duration_s)
        if d < 0:
            raise WaveformError(f"Hold.duration_s must be >= 0, got {d:g}")
        object.__setattr__(self, "duration_s", d)


@dataclass(frozen=True)
class Drive:
    """Power delivery: a square wave between ``low_V`` and ``high_V`` (V) for ``duration_s`` (s, > 0).

    The scratch drives move while it runs; each robot turns or goes straight according to its arm.
    """

    low_V: float
    high_V: float
    duration_s: float

    def __post_init__(self) -> None:
        lo = _finite("Drive.low_V", self.low_V)
        hi = _finite("Drive.high_V", self.high_V)
        d = _finite("Drive.duration_s", self.duration_s)
        if not lo < hi:
            raise WaveformError(f"Drive.low_V ({lo:g} V) must be below Drive.high_V ({hi:g} V)")
        if d <= 0:
            raise WaveformError(f"Drive.duration_s must be > 0, got {d:g}")
        object.__setattr__(self, "low_V", lo)
        object.__setattr__(self, "high_V", hi)
        object.__setattr__(self, "duration_s", d)


Segment = Hold | Drive


def duration(waveform: Sequence[Segment]) -> float:
    """Total duration (s)."""
    return float(sum(seg.duration_s for seg in waveform))


def excerpt(waveform: Sequence[Segment], duration_s: float) -> tuple[Segment, ...]:
    """The first ``duration_s`` seconds of a waveform (the segment running at that time is cut short).

    >>> excerpt([Hold(140.0, 0.001), Drive(75.0, 105.0, 2.0)], 0.5)
    (Hold(volts=140.0, duration_s=0.001), Drive(low_V=75.0, high_V=105.0, duration_s=0.499))
    """
    end = _finite("duration_s", duration_s)
    out: list[Segment] = []
    t = 0.0
    for seg in waveform:
        if t >= end:
            break
        d = min(seg.duration_s, end - t)
        out.append(Hold(seg.volts, d) if isinstance(seg, Hold) else Drive(seg.low_V, seg.high_V, d))
        t += seg.duration_s
    return tuple(out)


# ----------------------------------------------------------------------------------------------------
# Synthesis


def _levels(seg: Segment) -> tuple[float, ...]:
    return (seg.volts,) if isinstance(seg, Hold) else (seg.low_V, seg.high_V)


def check_limits(waveform: Sequence[Segment], max_V: float) -> None:
    """Raise :class:`WaveformError` if any level of the waveform leaves ``[0, max_V]``."""
    for k, seg in enumerate(waveform):
        for v in _levels(seg):
            if not 0.0 <= v <= max_V:
                raise WaveformError(f"segment {k} ({type(seg).__name__}) uses {v:g} V, outside [0, {max_V:g}] V")


def _resolve(analysis: ControlAnalysis, primitive) -> np.ndarray:
    """A primitive given as :class:`Primitive`, name, or arm-state vector -> arm states ``(n,)``."""
    if isinstance(primitive, Primitive):
        return np.array(primitive.state, dtype=np.uint8)
    if isinstance(primitive, str):
        try:
            return np.array(analysis.primitive(primitive).state, dtype=np.uint8)
        except KeyError:
            raise WaveformError(
                f"unknown primitive {primitive!r} (this design has P0..P{analysis.primitive_states.shape[0] - 1})"
            ) from None
    s = np.asarray(primitive).reshape(-1)
    if s.size != analysis.n or not np.all((s == 0) | (s == 1)):
        raise WaveformError(f"an arm state needs {analysis.n} entries of 0 or 1")
    return s.astype(np.uint8)


def _describe(analysis: ControlAnalysis, state: np.ndarray) -> str:
    down = [analysis.names[i] for i in np.flatnonzero(state)]
    return f"arm state with {', '.join(down)} down" if down else "all-up arm state"


def check_drive_band(analysis: ControlAnalysis, state, low_V: float | None = None, high_V: float | None = None) -> None:
    """Refuse a drive band that could flip an arm of ``state``.

    The band keeps every arm only if ``high_V`` stays ``margin_V`` below ``V_d`` of every raised arm and
    ``low_V`` stays ``margin_V`` above ``V_u`` of every lowered arm (SPEC 4; strictly, when the margin is
    0). Defaults to the electrodes' band. Raises :class:`WaveformError` naming the arm.
    """
    e = analysis.electrodes
    lo = e.drive_low_V if low_V is None else float(low_V)
    hi = e.drive_high_V if high_V is None else float(high_V)
    if not (0.0 <= lo < hi <= e.max_V):
        raise WaveformError(f"drive band [{lo:g}, {hi:g}] V is not inside [0, {e.max_V:g}] V")
    s = np.asarray(state, dtype=np.uint8).reshape(-1)
    m = e.margin_V - TOLERANCE_V
    vd, vu = analysis.snap_down_V, analysis.release_V
    up_bad = (s == 0) & ((hi >= vd) | (hi > vd - m))
    down_bad = (s == 1) & ((lo <= vu) | (lo < vu + m))
    for i in np.flatnonzero(up_bad | down_bad):
        if s[i] == 0:
            why = f"its high level {hi:g} V is within margin_V of {analysis.names[i]}'s snap-down voltage {vd[i]:g} V"
        else:
            why = f"its low level {lo:g} V is within margin_V of {analysis.names[i]}'s release voltage {vu[i]:g} V"
        raise WaveformError(
            f"drive band [{lo:g}, {hi:g}] V would flip {analysis.names[i]}'s arm in the {_describe(analysis, s)}: {why}"
        )


def synthesize_primitive(
    analysis: ControlAnalysis, primitive, duration_s: float, *, current=None
) -> tuple[Segment, ...]:
    """Segments that apply one primitive from the current arm state: the fewest Holds, then a Drive.

    Parameters
    ----------
    analysis:
        The design (:func:`stressbots.electrostatics.analyse`).
    primitive:
        A :class:`~stressbots.electrostatics.Primitive`, its name (``"P2"``), or an arm-state vector.
    duration_s:
        Drive duration (s, > 0).
    current:
        Arm states before the segments (default all up).

    Raises
    ------
    WaveformError
        The state is not accessible, no level sequence reaches it, or the drive band would flip an arm.
    """
    e = analysis.electrodes
    target = _resolve(analysis, primitive)
    if not analysis.is_accessible(target):
        raise WaveformError(f"the {_describe(analysis, target)} is not an accessible control state of this design")
    check_drive_band(analysis, target)
    s0 = np.zeros(analysis.n, np.uint8) if current is None else np.asarray(current, dtype=np.uint8).reshape(-1)
    holds = tuple(Hold(v, e.hold_s) for v in level_sequence(analysis, s0, target))
    segs = holds + (Drive(e.drive_low_V, e.drive_high_V, duration_s),)
    check_limits(segs, e.max_V)
    return segs


def synthesize(analysis: ControlAnalysis, steps: Iterable[tuple[Any, float]], *, initial=None) -> tuple[Segment, ...]:
    """The waveform of a step list ``[(primitive, duration_s), ...]``, starting from all-up (or ``initial``).

    Each step is :func:`synthesize_primitive` from the state the previous step left; a step that repeats
    the current primitive adds only a Drive.
    """
    return Synthesizer(analysis)(steps, initial=initial)


class Synthesizer:
    """:func:`synthesize` for one design, remembering the Holds of each (arm state, primitive) transition.

    A closed loop synthesizes a waveform every frame from the few transitions of its design; resolving the
    primitive, checking its accessibility and drive band and searching the level sequence each time cost a few
    percent of a simulated assembly's wall time (the example on an idle machine: median 0.91-0.96 s before, 0.89 s
    with one). Each step is :func:`synthesize_primitive` from the state the previous step left, its Holds then
    remembered; a Drive is made for each step, so only its duration differs between calls.

    >>> from stressbots.electrostatics import Electrodes, analyse_thresholds
    >>> a = analyse_thresholds([160.0, 120.0], [45.0, 15.0], Electrodes(), names=["A", "B"])
    >>> synth = Synthesizer(a)
    >>> steps = [("P1", 2.0), ("P0", 1.0)]
    >>> synth(steps) == synthesize(a, steps) and synth(steps) == synthesize(a, steps)   # the second from memory
    True
    """

    def __init__(self, analysis: ControlAnalysis):
        self.analysis = analysis
        self._holds: dict[tuple[bytes, Any], tuple[tuple[Segment, ...], np.ndarray]] = {}

    def __call__(self, steps: Iterable[tuple[Any, float]], *, initial=None) -> tuple[Segment, ...]:
        """The waveform of ``steps`` from the arm state ``initial`` (default all up), as :func:`synthesize`."""
        a = self.analysis
        e = a.electrodes
        s = np.zeros(a.n, np.uint8) if initial is None else np.asarray(initial, dtype=np.uint8).reshape(-1)
        out: list[Segment] = []
        for k, (prim, dur) in enumerate(steps):
            key = (s.tobytes(), prim if isinstance(prim, str | int) else np.asarray(prim).tobytes())
            known = self._holds.get(key)
            if known is None:
                try:
                    holds = synthesize_primitive(a, prim, dur, current=s)[:-1]
                except WaveformError as exc:
                    raise WaveformError(f"step {k}: {exc.problem}", source=exc.source, field=exc.field) from None
                known = self._holds[key] = (holds, _resolve(a, prim))
            out.extend(known[0])
            out.append(Drive(e.drive_low_V, e.drive_high_V, dur))
            s = known[1]
        return tuple(out)


# ----------------------------------------------------------------------------------------------------
# Decoder


@dataclass(frozen=True, eq=False)
class DriveInterval:
    """What the robots do during one Drive of a waveform.

    Attributes
    ----------
    segment:
        Index of the Drive in the waveform.
    t_start_s, duration_s:
        When it starts (s from the waveform's start) and how long it lasts (s).
    low_V, high_V:
        The band.
    entry:
        ``(n,)`` uint8 arm states when the Drive starts (set by the Holds before it).
    states:
        ``(n,)`` uint8 arm states during the Drive: 1 = arm down = the robot turns. Equal to ``entry``
        unless the band flips an arm, which then holds its new state from the first cycle on (one
        drive period, negligible). A chattering arm is reported up (its state after the low level).
    flipped:
        ``(n,)`` bool arms whose state the band changes for the rest of the Drive (``V_d <= high_V`` for
        an up arm, or ``V_u >= low_V`` for a down arm).
    chatter:
        ``(n,)`` bool arms that toggle every cycle (``V_u >= low_V`` and ``V_d <= high_V``): the robot
        alternates turning and going straight; its motion is not a primitive's.
    """

    segment: int
    t_start_s: float
    duration_s: float
    low_V: float
    high_V: float
    entry: np.ndarray
    states: np.ndarray
    flipped: np.ndarray
    chatter: np.ndarray

    @property
    def t_end_s(self) -> float:
        return self.t_start_s + self.duration_s

    @property
    def turning(self) -> np.ndarray:
        """``(n,)`` bool: robots that turn during the Drive."""
        return self.states.astype(bool)

    @property
    def ok(self) -> bool:
        """The band keeps every arm as the Holds set it."""
        return not (self.flipped.any() or self.chatter.any())


@dataclass(frozen=True, eq=False)
class Decoded:
    """A replayed waveform: the Drive intervals, the arm states at the end, the total duration (s)."""

    drives: tuple[DriveInterval, ...]
    final: np.ndarray
    duration_s: float


def replay(waveform: Sequence[Segment], snap_down_V, release_V, initial=None) -> Decoded:
    """Replay any waveform through the hysteresis model (exact thresholds, SPEC 4).

    Holds of positive length apply their level. A Drive applies ``high_V`` then ``low_V`` once per cycle;
    after one cycle every arm is settled except chattering ones (:class:`DriveInterval`), so one cycle
    decides the states for the whole Drive. The Drive is taken to end on its low level.

    Parameters
    ----------
    waveform:
        Segments (:class:`Hold`, :class:`Drive`).
    snap_down_V, release_V:
        ``(n,)`` thresholds (V) of the robots the waveform drives, e.g. a fabricated set.
    initial:
        Arm states at the start (default all up: the state at 0 V).
    """
    vd = np.asarray(snap_down_V, dtype=np.float64).reshape(-1)
    vu = np.asarray(release_V, dtype=np.float64).reshape(-1)
    s = np.zeros(vd.size, np.uint8) if initial is None else np.asarray(initial, dtype=np.uint8).reshape(-1).copy()
    t = 0.0
    drives: list[DriveInterval] = []
    for k, seg in enumerate(waveform):
        if isinstance(seg, Hold):
            if seg.duration_s > 0:
                s = apply_level(s, seg.volts, vd, vu)
        elif isinstance(seg, Drive):
            entry = s
            settled = apply_level(apply_level(entry, seg.high_V, vd, vu), seg.low_V, vd, vu)
            chatter = (seg.high_V >= vd) & (seg.low_V <= vu)
            flipped = (settled != entry) & ~chatter
            drives.append(DriveInterval(k, t, seg.duration_s, seg.low_V, seg.high_V, entry, settled, flipped, chatter))
            s = settled
        else:
            raise TypeError(f"segment {k} is not a Hold or a Drive: {seg!r}")
        t += seg.duration_s
    return Decoded(tuple(drives), s, t)


def decode(waveform: Sequence[Segment], snap_down_V, release_V, initial=None) -> tuple[DriveInterval, ...]:
    """The Drive intervals of a waveform with the arm states during each (see :func:`replay`)."""
    return replay(waveform, snap_down_V, release_V, initial).drives


# ----------------------------------------------------------------------------------------------------
# Sampling and export


def sample(
    waveform: Sequence[Segment],
    rate_hz: float = 100_000.0,
    drive_frequency_hz: float = 10_000.0,
    *,
    max_samples: int = 50_000_000,
) -> tuple[np.ndarray, np.ndarray]:
    """Sample a waveform: times ``t`` (s) and levels ``v`` (V), ``t_k = k / rate_hz``.

    A Drive is a square wave at ``drive_frequency_hz`` that starts on ``high_V`` (first half period) and
    alternates with ``low_V``. The sample rate must be at least twice the drive frequency and give every
    Hold at least one sample, so that the samples replay to the same arm states.
    """
    rate = _finite("rate_hz", rate_hz)
    f = _finite("drive_frequency_hz", drive_frequency_hz)
    if rate <= 0 or f <= 0:
        raise WaveformError("the sample rate and the drive frequency must be > 0")
    if rate < 2.0 * f:
        raise WaveformError(f"sample rate {rate:g} Hz is below twice the drive frequency {f:g} Hz; raise --rate-hz")
    for k, seg in enumerate(waveform):
        if isinstance(seg, Hold) and 0 < seg.duration_s * rate < 1.0:
            raise WaveformError(f"sample rate {rate:g} Hz gives Hold segment {k} ({seg.duration_s:g} s) no sample; raise --rate-hz")
    total = duration(waveform)
    count = int(math.ceil(total * rate - 1e-9))
    if count > max_samples:
        raise WaveformError(f"{count} samples ({total:g} s at {rate:g} Hz) is more than {max_samples}; lower --rate-hz")
    t = np.arange(count, dtype=np.float64) / rate
    if count == 0:
        return t, np.zeros(0)
    durs = np.array([seg.duration_s for seg in waveform])
    ends = np.cumsum(durs)
    starts = ends - durs
    idx = np.minimum(np.searchsorted(ends, t, side="right"), len(waveform) - 1)
    is_drive = np.array([isinstance(seg, Drive) for seg in waveform])
    hold_v = np.array([seg.volts if isinstance(seg, Hold) else 0.0 for seg in waveform])
    low = np.array([seg.low_V if isinstance(seg, Drive) else 0.0 for seg in waveform])
    high = np.array([seg.high_V if isinstance(seg, Drive) else 0.0 for seg in waveform])
    phase = np.mod((t - starts[idx]) * f, 1.0)
    v = np.where(is_drive[idx], np.where(phase < 0.5, high[idx], low[idx]), hold_v[idx])
    return t, v


@dataclass(frozen=True)
class WaveformSummary:
    """What an exported waveform contains (for the CLI and the lab notebook)."""

    duration_s: float
    segments: int
    holds: int
    drives: int
    levels_V: tuple[float, ...]
    min_V: float
    max_V: float
    samples: int = 0
    rate_hz: float | None = None
    path: str | None = None

    def as_dict(self) -> dict[str, Any]:
        return {k: (list(v) if isinstance(v, tuple) else v) for k, v in self.__dict__.items()}


def summarize(waveform: Sequence[Segment]) -> WaveformSummary:
    """Duration, segment counts and the levels used (Hold levels and drive band levels, V)."""
    levels = sorted({v for seg in waveform for v in _levels(seg)})
    return WaveformSummary(
        duration_s=duration(waveform),
        segments=len(waveform),
        holds=sum(isinstance(s, Hold) for s in waveform),
        drives=sum(isinstance(s, Drive) for s in waveform),
        levels_V=tuple(levels),
        min_V=float(levels[0]) if levels else 0.0,
        max_V=float(levels[-1]) if levels else 0.0,
    )


def export(
    waveform: Sequence[Segment],
    path,
    *,
    rate_hz: float = 100_000.0,
    drive_frequency_hz: float = 10_000.0,
) -> WaveformSummary:
    """Write a waveform atomically, format by suffix.

    - ``.npy``: sampled, float64 array ``(N, 2)``: columns time (s), level (V);
    - ``.csv``: sampled, header ``t_s,volts``;
    - ``.json``: the segments (:func:`to_json`), not sampled.
    """
    from .outputs import write_bytes, write_json, write_text

    target = Path(path)
    suffix = target.suffix.lower()
    summary = summarize(waveform)
    if suffix == ".json":
        write_json(target, to_json(waveform))
        return WaveformSummary(**{**summary.__dict__, "path": str(target)})
    if suffix not in (".npy", ".csv"):
        raise WaveformError(f"unsupported output {target.name!r}: use a .npy, .csv or .json file", source="--out")
    t, v = sample(waveform, rate_hz, drive_frequency_hz)
    if suffix == ".npy":
        buf = io.BytesIO()
        np.save(buf, np.stack([t, v], axis=1))
        write_bytes(target, buf.getvalue())
    else:
        buf_s = io.StringIO()
        buf_s.write("t_s,volts\n")
        np.savetxt(buf_s, np.stack([t, v], axis=1), fmt="%.9g", delimiter=",")
        write_text(target, buf_s.getvalue())
    lo = float(v.min()) if v.size else 0.0
    hi = float(v.max()) if v.size else 0.0
    return WaveformSummary(
        **{**summary.__dict__, "min_V": lo, "max_V": hi, "samples": int(t.size), "rate_hz": float(rate_hz), "path": str(target)}
    )


# ----------------------------------------------------------------------------------------------------
# JSON and step lists


def to_json(waveform: Sequence[Segment]) -> list[dict[str, Any]]:
    """Segments as a list of dicts: ``{"kind": "hold", "volts", "duration_s"}`` / ``{"kind": "drive", ...}``."""
    out: list[dict[str, Any]] = []
    for seg in waveform:
        if isinstance(seg, Hold):
            out.append({"kind": "hold", "volts": seg.volts, "duration_s": seg.duration_s})
        else:
            out.append({"kind": "drive", "low_V": seg.low_V, "high_V": seg.high_V, "duration_s": seg.duration_s})
    return out


def from_json(data: Any, *, source: str | None = None) -> tuple[Segment, ...]:
    """Parse :func:`to_json`'s list; one-line errors name the segment and field."""
    if not isinstance(data, list):
        raise WaveformError("a waveform must be a JSON list of segments", source=source)
    fields = {"hold": ("volts", "duration_s"), "drive": ("low_V", "high_V", "duration_s")}
    out: list[Segment] = []
    for k, item in enumerate(data):
        where = f"[{k}]"
        if not isinstance(item, dict) or item.get("kind") not in fields:
            raise WaveformError('must be an object with "kind": "hold" or "drive"', source=source, field=where)
        names = fields[item["kind"]]
        extra = sorted(set(item) - set(names) - {"kind"})
        if extra:
            raise WaveformError("unknown field", source=source, field=f"{where}.{extra[0]}")
        for nm in names:
            if nm not in item:
                raise WaveformError("missing: this field is required", source=source, field=f"{where}.{nm}")
        try:
            out.append(Hold(*(item[nm] for nm in names)) if item["kind"] == "hold" else Drive(*(item[nm] for nm in names)))
        except WaveformError as exc:
            raise WaveformError(exc.problem, source=source, field=where) from None
    return tuple(out)


def parse_steps(text: str, analysis: ControlAnalysis, *, option: str = "--steps") -> list[tuple[Primitive, float]]:
    """Parse ``"P1:2.5,P0:1.0"`` (primitive name : drive duration in s) against a design."""
    steps: list[tuple[Primitive, float]] = []
    items = [s.strip() for s in text.split(",")]
    if not text.strip() or any(not s for s in items):
        raise WaveformError("expected a comma-separated list like 'P1:2.5,P0:1.0'", source=option)
    for item in items:
        name, sep, dur = item.partition(":")
        if not sep:
            raise WaveformError(f"step {item!r} needs a duration: NAME:SECONDS, e.g. 'P1:2.5'", source=option)
        try:
            prim = analysis.primitive(name.strip())
        except KeyError:
            raise WaveformError(
                f"unknown primitive {name.strip()!r}; this design has P0..P{analysis.primitive_states.shape[0] - 1}", source=option
            ) from None
        try:
            d = float(dur)
        except ValueError:
            raise WaveformError(f"duration {dur.strip()!r} of {name.strip()} is not a number", source=option) from None
        if not math.isfinite(d) or d <= 0:
            raise WaveformError(f"duration of {name.strip()} must be a finite number > 0 s, got {dur.strip()}", source=option)
        steps.append((prim, d))
    return steps


def steps_from_plan(plan, analysis: ControlAnalysis, *, source: str | None = None) -> list[tuple[np.ndarray, float]]:
    """Map a :class:`~stressbots.plans.Plan`'s steps to ``(arm state, duration_s)`` for :func:`synthesize`.

    A plan names primitives by their ``turning`` lists, so it needs no voltage analysis to be read; here
    each list becomes an arm state, which must be an accessible control state of the design. Steps of
    zero duration are skipped.
    """
    missing = [nm for nm in analysis.names if nm not in plan.robots]
    extra = [nm for nm in plan.robots if nm not in analysis.names]
    if missing or extra:
        what = f"robot {missing[0]!r} of the scenario is not in the plan" if missing else f"robot {extra[0]!r} is not in the scenario"
        raise WaveformError(what, source=source, field="robots")
    states: dict[str, np.ndarray] = {}
    for k, p in enumerate(plan.primitives):
        s = analysis.state_of(p.turning)
        if not analysis.is_accessible(s):
            raise WaveformError(
                f"turning {list(p.turning)} is not an accessible control state of the scenario's design",
                source=source,
                field=f"primitives[{k}] ({p.name}).turning",
            )
        states[p.name] = s
    return [(states[st.primitive], st.duration_s) for st in plan.steps if st.duration_s > 0]

