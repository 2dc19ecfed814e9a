"""STRING voltage design (``stressbots design``) and its fabrication yield.

A STRING design (SPEC 4) puts the release voltages ``V_u`` below the drive band and the snap-down
voltages ``V_d`` above it, both rising along ``D_1..D_N``. Every threshold sits between two *levels*
the synthesiser may apply, and the distance from a threshold to those levels (its *clearance*) is what
fabrication scatter can eat before an arm does the wrong thing:

- release side, bottom to top: the level 0 V, ``V_u`` values with one release level mid-gap between
  consecutive ones, then ``drive_low_V``;
- snap-down side: ``drive_high_V``, ``V_d`` values with one raise level mid-gap, then ``max_V``.

For ``K`` distinct values on a side ``W`` volts wide (``drive_low_V`` resp. ``max_V - drive_high_V``),
the largest clearance is ``rho(K) = min(W / 2K, (W - 2 delta_v) / (2K - 1))``: evenly spaced values
``2 rho`` apart, ``rho`` from the outer level and at least ``2 delta_v`` from the drive band (the
drive-band rule). So the design maximises the smallest gap between consecutive thresholds (``2 rho``)
within ``[0, max_V]``, the margins and the drive band. It is feasible when ``rho >= delta_v`` on both
sides, i.e. every level keeps its margin.

Ties (seed Lemma 1, cases (V1, V4) and (V2, V3)): consecutive robots may share ``V_d`` or ``V_u``, not
both. ``N`` robots then need only ``K_d + K_u = N + 1`` distinct values (a monotone staircase), which fits
about twice as many robots; reaching a tied primitive costs one extra Hold.

Yield: thresholds of a fabricated set scatter around the design (normal, standard deviation ``sd_V``).
A set works when every hold level of the design and the drive band still act on it as intended,
judged with the decoder's hysteresis rule (:func:`stressbots.electrostatics.apply_level`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from .electrostatics import TOLERANCE_V, ControlAnalysis, Electrodes, analyse_thresholds, apply_level
from .errors import DesignError

__all__ = [
    "StringDesign", "YieldEstimate", "side_clearance", "max_robots", "design_string", "estimate_yield", "works", "check_limits",
    "round_design", "DEFAULT_RESOLUTION_V",
]

#: Largest design produced (the check analyses it, with O(N^2) memory); a margin of 0 fits any N.
MAX_DESIGN_ROBOTS = 2000

#: Stands for "no limit" in :func:`max_robots` (margin 0).
_UNLIMITED = 10**9


def check_limits(electrodes: Electrodes) -> None:
    """Refuse impossible limits, naming the CLI option."""
    e = electrodes
    for opt, v in (
        ("--max-V", e.max_V),
        ("--margin-V", e.margin_V),
        ("--drive-low-V", e.drive_low_V),
        ("--drive-high-V", e.drive_high_V),
        ("--drive-frequency-hz", e.drive_frequency_hz),
        ("--hold-s", e.hold_s),
    ):
        if not math.isfinite(v):
            raise DesignError(f"must be finite, got {v}", source=opt)
    if e.max_V <= 0:
        raise DesignError(f"must be > 0 V, got {e.max_V:g}", source="--max-V")
    if e.margin_V < 0:
        raise DesignError(f"must be >= 0 V, got {e.margin_V:g}", source="--margin-V")
    if e.drive_low_V < 0:
        raise DesignError(f"must be >= 0 V, got {e.drive_low_V:g}", source="--drive-low-V")
    if not e.drive_low_V < e.drive_high_V:
        raise DesignError(f"must be above --drive-low-V ({e.drive_low_V:g} V), got {e.drive_high_V:g} V", source="--drive-high-V")
    if e.drive_high_V > e.max_V:
        raise DesignError(f"must not exceed --max-V ({e.max_V:g} V), got {e.drive_high_V:g} V", source="--drive-high-V")
    if e.drive_frequency_hz <= 0:
        raise DesignError(f"must be > 0 Hz, got {e.drive_frequency_hz:g}", source="--drive-frequency-hz")
    if e.hold_s <= 0:
        raise DesignError(f"must be > 0 s, got {e.hold_s:g}", source="--hold-s")


def side_clearance(width_V: float, k: int, margin_V: float) -> float:
    """Largest clearance (V) for ``k`` distinct thresholds on a side ``width_V`` wide (see module doc)."""
    if k < 1:
        return math.inf
    return min(width_V / (2 * k), (width_V - 2.0 * margin_V) / (2 * k - 1))


def _side_widths(e: Electrodes) -> tuple[float, float]:
    return float(e.drive_low_V), float(e.max_V - e.drive_high_V)


def _k_max(width_V: float, margin_V: float) -> int:
    """Most distinct thresholds that fit on a side with clearance >= margin (capped)."""
    if side_clearance(width_V, 1, margin_V) < margin_V - TOLERANCE_V:
        return 0
    if margin_V <= TOLERANCE_V:
        return _UNLIMITED
    k = min(_UNLIMITED, max(1, int((width_V - margin_V) / (2.0 * margin_V))))
    while k > 1 and side_clearance(width_V, k, margin_V) < margin_V - TOLERANCE_V:
        k -= 1
    while k < _UNLIMITED and side_clearance(width_V, k + 1, margin_V) >= margin_V - TOLERANCE_V:
        k += 1
    return k


def max_robots(electrodes: Electrodes, *, ties: bool = False) -> int:
    """The largest N for which a STRING design fits the limits (0 if none does; 10^9 means no limit)."""
    wu, wd = _side_widths(electrodes)
    ku, kd = _k_max(wu, electrodes.margin_V), _k_max(wd, electrodes.margin_V)
    if ku == 0 or kd == 0:
        return 0
    return min(ku + kd - 1, _UNLIMITED) if ties else min(ku, kd)


@dataclass(frozen=True)
class YieldEstimate:
    """Monte Carlo yield: the fraction of fabricated sets that still work, with a 95 % Wilson interval."""

    sd_V: float
    trials: int
    seed: int
    successes: int
    fraction: float
    ci_low: float
    ci_high: float

    def as_dict(self) -> dict[str, Any]:
        return dict(self.__dict__)


@dataclass(frozen=True)
class StringDesign:
    """A STRING voltage design for robots ``D1..DN`` (already in ``D_1..D_N`` order).

    Attributes
    ----------
    electrodes:
        The limits it was designed for.
    names, snap_down_V, release_V:
        Robots and thresholds (V), ``D_1..D_N``.
    raise_levels_V, release_levels_V:
        The hold levels the synthesiser uses (V): the raise level to ``P_k`` (``k = 1..N``) and the
        release level to ``P_k`` (``k = 0..N-1``); NaN where a tie makes ``P_k`` need two levels.
    min_gap_V:
        Smallest gap between consecutive distinct thresholds of the same kind (inf for one robot).
    clearance_V:
        Smallest distance from a threshold to the levels around it (0 V, hold levels, drive band, max_V).
    ties:
        Whether thresholds may be shared by consecutive robots.
    """

    electrodes: Electrodes
    names: tuple[str, ...]
    snap_down_V: tuple[float, ...]
    release_V: tuple[float, ...]
    raise_levels_V: tuple[float, ...]
    release_levels_V: tuple[float, ...]
    min_gap_V: float
    clearance_V: float
    ties: bool

    @property
    def n(self) -> int:
        return len(self.names)

    def analysis(self) -> ControlAnalysis:
        return analyse_thresholds(self.snap_down_V, self.release_V, self.electrodes, names=self.names)

    def to_json_dict(self, yield_estimate: YieldEstimate | None = None) -> dict[str, Any]:
        e = self.electrodes
        return {
            "format": "stressbots.design/1",
            "string": True,
            "order": list(self.names),
            "ties": self.ties,
            "electrodes": dict(e.__dict__),
            "robots": [
                {"name": nm, "snap_down_V": vd, "release_V": vu}
                for nm, vd, vu in zip(self.names, self.snap_down_V, self.release_V, strict=True)
            ],
            "levels": {
                "raise_to_P_k_V": {f"P{k}": v for k, v in enumerate(self.raise_levels_V) if math.isfinite(v)},
                "release_to_P_k_V": {f"P{k}": v for k, v in enumerate(self.release_levels_V) if math.isfinite(v)},
            },
            "min_gap_V": self.min_gap_V if math.isfinite(self.min_gap_V) else None,
            "clearance_V": self.clearance_V,
            "yield": yield_estimate.as_dict() if yield_estimate is not None else None,
        }

    def to_toml(self, yield_estimate: YieldEstimate | None = None) -> str:
        """A scenario fragment: ``[electrodes]`` and ``[[robots]]`` (add ``start``/``goal`` to move them)."""
        e = self.electrodes

        def num(x: float) -> str:
            return repr(float(x))

        def short(items: list[str]) -> str:
            return ", ".join(items if len(items) <= 10 else items[:4] + ["..."] + items[-2:])

        def lv(vals) -> str:
            return short([f"P{k} {v:.6g}" for k, v in enumerate(vals) if math.isfinite(v)])

        gap = f"{self.min_gap_V:.6g} V" if math.isfinite(self.min_gap_V) else "none (one robot)"
        lines = [
            f"# STRING design for {self.n} robots (stressbots design); D_1..D_{self.n} = {short(list(self.names))}.",
            f"# smallest gap between thresholds {gap}; clearance to the nearest level {self.clearance_V:.6g} V"
            + ("; ties allowed" if self.ties else ""),
            f"# hold levels, raise to:   {lv(self.raise_levels_V)}",
            f"# hold levels, release to: {lv(self.release_levels_V)}",
        ]
        if yield_estimate is not None:
            y = yield_estimate
            lines.append(
                f"# yield with thresholds scattered by sd {y.sd_V:g} V: {y.fraction:.4f} "
                f"(95% CI {y.ci_low:.4f}-{y.ci_high:.4f}; {y.successes}/{y.trials} sets, seed {y.seed})"
            )
        lines += ["# Add start = [x_um, y_um, heading_deg] (and goals) to each robot to plan with it.", "", "[electrodes]"]
        for key in ("max_V", "margin_V", "drive_low_V", "drive_high_V", "drive_frequency_hz", "hold_s"):
            lines.append(f"{key} = {num(getattr(e, key))}")
        for nm, vd, vu in zip(self.names, self.snap_down_V, self.release_V, strict=True):
            lines += ["", "[[robots]]", f'name = "{nm}"', f"snap_down_V = {num(vd)}", f"release_V = {num(vu)}"]
        return "\n".join(lines) + "\n"


def _staircase(n: int, k_d: int, _k_u: int) -> tuple[np.ndarray, np.ndarray]:
    """Indices of the distinct ``V_d`` / ``V_u`` value of each of ``n = k_d + k_u - 1`` robots.

    Each step to the next robot raises exactly one of the two (a monotone lattice path), so consecutive
    robots share one value, never both.
    """
    if n == 1:
        return np.zeros(1, dtype=int), np.zeros(1, dtype=int)
    s = np.arange(n)
    d = (s * (k_d - 1)) // (n - 1)
    return d, s - d


def _checked_count(n: Any, e: Electrodes, ties: bool) -> int:
    """``n`` as a robot count, or a :class:`DesignError` on ``--robots``: not a whole number >= 1, beyond
    :data:`MAX_DESIGN_ROBOTS`, or more than fit the limits (saying how many do, and how many with the
    other tie setting when that differs)."""
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 1:
        raise DesignError(f"must be a whole number >= 1, got {n!r}", source="--robots")
    n = int(n)
    if n > MAX_DESIGN_ROBOTS:
        raise DesignError(f"at most {MAX_DESIGN_ROBOTS} robots per design, got {n}", source="--robots")
    best = max_robots(e, ties=ties)
    if n > best:
        other = max_robots(e, ties=not ties)
        hint = f" ({other} with {'--no-ties' if ties else '--ties'})" if other != best else ""
        raise DesignError(
            f"{n} robots do not fit: the largest STRING design within max_V {e.max_V:g} V, margin_V {float(e.margin_V):g} V and "
            f"the drive band [{e.drive_low_V:g}, {e.drive_high_V:g}] V has {best} robot{'s' if best != 1 else ''}{hint}",
            source="--robots",
        )
    return n


def _value_counts(n: int, wu: float, wd: float, m: float, ties: bool) -> tuple[int, int, np.ndarray, np.ndarray]:
    """``(k_u, k_d, d_idx, u_idx)``: how many distinct release / snap-down values the design uses and
    which of them each robot D_1..D_n gets.

    Without ties every robot has its own two values. With ties the fewest values serve
    (``k_u + k_d = n + 1``, a staircase), split between the release side (width ``wu``, V) and the
    snap-down side (``wd``) so that the worse side's clearance is the largest, then their sum.
    """
    if not ties:
        return n, n, np.arange(n), np.arange(n)
    splits = [(k_u, n + 1 - k_u) for k_u in range(1, n + 1)]
    k_u, k_d = max(
        splits,
        key=lambda s: (
            min(side_clearance(wu, s[0], m), side_clearance(wd, s[1], m)),
            side_clearance(wu, s[0], m) + side_clearance(wd, s[1], m),
        ),
    )
    d_idx, u_idx = _staircase(n, k_d, k_u)
    return k_u, k_d, d_idx, u_idx


def _with_hold_levels(draft: StringDesign) -> StringDesign:
    """``draft`` with the Hold levels that set each primitive, from its analysis (it must be STRING)."""
    a = draft.analysis()
    if not a.is_string:  # pragma: no cover - guarded by max_robots; a bug if it happens
        raise DesignError("internal error: the design is not STRING: " + "; ".join(a.reasons))
    assert a.raise_levels_V is not None and a.release_levels_V is not None  # a STRING analysis has both
    return replace(
        draft,
        raise_levels_V=tuple(float(x) for x in a.raise_levels_V),
        release_levels_V=tuple(float(x) for x in a.release_levels_V),
    )


def design_string(n: int, electrodes: Electrodes, *, ties: bool = False) -> StringDesign:
    """The STRING design for ``n`` robots with the largest clearance (see the module docstring).

    Raises
    ------
    DesignError
        The limits are impossible, or ``n`` robots do not fit; the message gives the largest N that does.
    """
    check_limits(electrodes)
    e = electrodes
    n = _checked_count(n, e, ties)
    m = float(e.margin_V)
    wu, wd = _side_widths(e)
    k_u, k_d, d_idx, u_idx = _value_counts(n, wu, wd, m, ties)
    rho_u, rho_d = side_clearance(wu, k_u, m), side_clearance(wd, k_d, m)
    u_vals = rho_u * (2 * np.arange(k_u) + 1)  # rho above 0 V, 2 rho apart
    d_vals = e.max_V - rho_d * (2 * np.arange(k_d)[::-1] + 1)  # rho below max_V, 2 rho apart
    gaps = [2 * rho_u] * (k_u > 1) + [2 * rho_d] * (k_d > 1)
    draft = StringDesign(
        electrodes=e,
        names=tuple(f"D{i + 1}" for i in range(n)),
        snap_down_V=tuple(float(x) for x in d_vals[d_idx]),
        release_V=tuple(float(x) for x in u_vals[u_idx]),
        raise_levels_V=(),
        release_levels_V=(),
        min_gap_V=float(min(gaps)) if gaps else math.inf,
        clearance_V=float(min(rho_u, rho_d)),
        ties=ties,
    )
    return _with_hold_levels(draft)


#: Resolution of the levels an instrument sets (V): a waveform generator behind a high-voltage amplifier
#: sets levels in steps of about 0.1 V, so designed thresholds finer than that are spurious precision.
DEFAULT_RESOLUTION_V = 0.1


def _on_grid(values, resolution_V: float) -> tuple[float, ...]:
    """Values rounded to multiples of ``resolution_V``, printed without float noise (133.9, not 133.90000000000001)."""
    digits = max(0, -math.floor(math.log10(resolution_V)) + 3)
    return tuple(round(round(float(v) / resolution_V) * resolution_V, digits) for v in values)


def round_design(design: StringDesign, resolution_V: float = DEFAULT_RESOLUTION_V) -> StringDesign:
    """The design with every threshold and hold level rounded to the instrument's resolution.

    Rounding moves each value by at most ``resolution_V / 2``; the gaps and the clearance are measured
    again on the rounded values (the clearance as the smallest distance from a threshold to a level
    used: 0 V, the hold levels, the drive band, max_V).

    Raises
    ------
    DesignError
        ``resolution_V`` is not a finite number > 0, or the rounded design is no longer STRING or keeps
        less than margin_V from a level (then use a finer resolution).

    Examples
    --------
    >>> from stressbots.electrostatics import Electrodes
    >>> d = round_design(design_string(4, Electrodes()))
    >>> d.snap_down_V
    (116.9, 140.6, 164.4, 188.1)
    """
    if isinstance(resolution_V, bool) or not (isinstance(resolution_V, (int, float)) and 0 < resolution_V <= 10):
        raise DesignError(f"must be a number in (0, 10] V, got {resolution_V!r}", source="--resolution-V")
    vd = _on_grid(design.snap_down_V, resolution_V)
    vu = _on_grid(design.release_V, resolution_V)
    a = analyse_thresholds(vd, vu, design.electrodes, names=design.names)
    e = design.electrodes
    if not a.is_string or a.raise_levels_V is None or a.release_levels_V is None:
        raise DesignError(
            f"rounding the design to {resolution_V:g} V makes it not STRING (thresholds closer than the resolution); "
            f"use a finer --resolution-V, or 0 for exact values",
            source="--resolution-V",
        )
    levels = _on_grid([v for v in np.r_[a.raise_levels_V, a.release_levels_V] if math.isfinite(v)], resolution_V)
    used = np.array([*levels, 0.0, e.drive_low_V, e.drive_high_V, e.max_V])
    th = np.array(vd + vu)
    clearance = float(np.min(np.abs(th[:, None] - used[None, :])))
    if clearance < e.margin_V - 1e-9:
        raise DesignError(
            f"rounding the design to {resolution_V:g} V leaves {clearance:.3g} V between a threshold and a level, less "
            f"than margin_V {e.margin_V:g} V; use a finer resolution",
            source="--resolution-V",
        )
    gaps = [b - c for side in (sorted(set(vd)), sorted(set(vu))) for c, b in zip(side[:-1], side[1:], strict=True)]

    def rounded_levels(vals) -> tuple[float, ...]:
        return tuple(_on_grid([v], resolution_V)[0] if math.isfinite(v) else math.nan for v in vals)

    return replace(
        design,
        snap_down_V=vd,
        release_V=vu,
        raise_levels_V=rounded_levels(a.raise_levels_V),
        release_levels_V=rounded_levels(a.release_levels_V),
        min_gap_V=_on_grid([min(gaps)], resolution_V / 1000)[0] if gaps else math.inf,
        clearance_V=_on_grid([clearance], resolution_V / 1000)[0],
    )


def _wilson(successes: int, trials: int, z: float = 1.959963984540054) -> tuple[float, float]:
    if trials == 0:
        return 0.0, 1.0
    p = successes / trials
    den = 1.0 + z * z / trials
    centre = (p + z * z / (2 * trials)) / den
    half = z * math.sqrt(p * (1 - p) / trials + z * z / (4 * trials * trials)) / den
    lo = 0.0 if successes == 0 else max(0.0, centre - half)
    hi = 1.0 if successes == trials else min(1.0, centre + half)
    return lo, hi


def works(design: StringDesign, snap_down_V: np.ndarray, release_V: np.ndarray) -> np.ndarray:
    """Which fabricated sets ``(T, N)`` still work with the design's levels and drive band, ``(T,)`` bool.

    Each hysteresis level maps every arm to "down", "up" or "unchanged", so a level acts on a set as
    designed iff it maps the all-up and the all-down states as it does for the nominal thresholds; then
    every transition ``P_j -> P_k`` the synthesiser makes lands on ``P_k``. The drive band (high then low,
    as the decoder replays it) must keep both the all-up and the all-down state, i.e. flip no arm in any
    primitive. All through :func:`~stressbots.electrostatics.apply_level`.
    """
    vd = np.atleast_2d(np.asarray(snap_down_V, dtype=np.float64))
    vu = np.atleast_2d(np.asarray(release_V, dtype=np.float64))
    nom_d = np.asarray(design.snap_down_V)
    nom_u = np.asarray(design.release_V)
    levels = [v for v in design.raise_levels_V + design.release_levels_V if math.isfinite(v)]
    up = np.zeros(vd.shape, np.uint8)
    down = np.ones(vd.shape, np.uint8)
    ok = np.ones(vd.shape[0], dtype=bool)
    for lv in levels:
        want_up = apply_level(up[:1], lv, nom_d, nom_u)
        want_down = apply_level(down[:1], lv, nom_d, nom_u)
        ok &= np.all(apply_level(up, lv, vd, vu) == want_up, axis=1)
        ok &= np.all(apply_level(down, lv, vd, vu) == want_down, axis=1)
    e = design.electrodes
    for s in (up, down):
        after = apply_level(apply_level(s, e.drive_high_V, vd, vu), e.drive_low_V, vd, vu)
        ok &= np.all(after == s, axis=1)
    return ok


def estimate_yield(design: StringDesign, sd_V: float, *, trials: int = 10_000, seed: int = 0, chunk: int = 4096) -> YieldEstimate:
    """Monte Carlo yield of a design when every threshold scatters with standard deviation ``sd_V`` (V).

    Draws come from ``np.random.default_rng(np.random.SeedSequence(seed))``, so the same seed gives the
    same estimate. See :func:`works` for what "still works" means.
    """
    if not math.isfinite(sd_V) or sd_V < 0:
        raise DesignError(f"must be a finite number >= 0 V, got {sd_V:g}", source="--sd-V")
    if isinstance(trials, bool) or int(trials) != trials or trials < 1:
        raise DesignError(f"must be a whole number >= 1, got {trials!r}", source="--trials")
    if isinstance(seed, bool) or int(seed) != seed or seed < 0:
        raise DesignError(f"must be a whole number >= 0, got {seed!r}", source="--seed")
    rng = np.random.default_rng(np.random.SeedSequence(int(seed)))
    nom_d = np.asarray(design.snap_down_V)
    nom_u = np.asarray(design.release_V)
    successes = 0
    done = 0
    while done < trials:
        t = min(chunk, trials - done)
        vd = nom_d + sd_V * rng.standard_normal((t, design.n))
        vu = nom_u + sd_V * rng.standard_normal((t, design.n))
        successes += int(works(design, vd, vu).sum())
        done += t
    lo, hi = _wilson(successes, trials)
    return YieldEstimate(float(sd_V), int(trials), int(seed), successes, successes / trials, lo, hi)
