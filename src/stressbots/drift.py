"""Heading drift as a per-robot physical process of the distance driven (SPEC 6).

A MicroStressBot driving "straight" does not keep its heading: the literature bounds the drift at
3.7 deg per mm. The simulator models it as a property of each robot and of the distance it has driven,
never of how a waveform happens to be cut into Drives:

- a **bias** ``b_i`` (rad per um, i.e. a constant curvature) drawn once per run: a device's systematic
  asymmetry, the part a controller could learn;
- a **random walk** of the heading in the robot's *odometer* ``o`` (cumulative distance driven, um):
  Brownian motion with variance ``sigma_w^2 o``, the part nobody can predict.

The heading drift accumulated between odometer readings ``o0`` and ``o1`` is ``b (o1 - o0) + W(o1) -
W(o0)``. With ``sigma = heading_drift_rad_per_um`` and reference distance ``S`` (1 mm) the split of the
1-mm variance is

``Var[drift over S] = f sigma^2 S^2 (bias) + (1 - f) sigma^2 S^2 (walk) = (sigma S)^2``,

so the spread after 1 mm is ``sigma S`` (3.7 deg for the literature's figure) whether the millimetre is
driven as one Drive or as forty. Over ``s`` um (knot-aligned) ``Var = sigma^2 (f s^2 + (1 - f) s S)``
(:func:`drift_variance`): the bias dominates long runs, the walk short ones.

Realisation
-----------
The walk is realised at fixed *knots* of the odometer, every :attr:`DriftModel.knot_um`: between knots
``k Delta`` and ``(k + 1) Delta`` the drift is a constant curvature ``b + w_k``, with ``w_k = sigma
sqrt((1 - f) S / Delta) z_k`` (so each knot interval adds heading variance ``(1 - f) sigma^2 S Delta``,
exactly the Brownian increment). Motion between knots therefore stays the closed-form arc of
:func:`stressbots.kinematics.move`. The ``z_k`` of robot ``i`` come from its own named stream (a child
of the plant's ``drift`` SeedSequence), drawn in fixed blocks of :data:`BLOCK` in knot order, so the
value of knot ``k`` depends only on the seed and ``k``: the same plant seed gives the same drift
realisation however the waveform is cut, and however far ahead the simulator happened to look.

Why half and half (``bias_share = 0.5``): the literature gives one figure in deg/mm, a rate, and no
split. A pure bias (``f = 1``) is a constant curvature a controller identifies after one observation and
then cancels; a pure walk (``f = 0``) grows only as ``sqrt(s)`` and would make the figure meaningless as
a rate beyond 1 mm. Equal shares keep both behaviours, and are stated here rather than hidden.

Examples
--------
>>> import math
>>> sigma = math.radians(3.7) / 1000.0
>>> round(math.degrees(math.sqrt(drift_variance(1000.0, sigma))), 6)   # 1 mm: the scenario's figure
3.7
>>> round(math.degrees(math.sqrt(drift_variance(100.0, sigma))), 3)    # 0.1 mm: walk-dominated
0.868
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = ["DriftModel", "DEFAULT_DRIFT", "HeadingDrift", "drift_variance", "BLOCK"]

BLOCK = 64
"""Knot values are drawn in blocks of this many per robot (a fixed size keeps streams cut-independent)."""


@dataclass(frozen=True)
class DriftModel:
    """Settings of the heading-drift process (see the module docstring).

    Attributes
    ----------
    knot_um:
        Odometer distance between the walk's knots (um). 25 um: a tenth of a body length, so the walk is
        resolved well below the scale of a contact or of the controller's shortest Drives (tens of um),
        while a 1-s Drive at 100 um/s crosses only four knots (cheap). It divides the reference
        distance, so the 1-mm variance is exact.
    bias_share:
        Fraction ``f`` of the variance over ``reference_um`` carried by the per-run bias; the rest is the
        random walk. See the module docstring for why 0.5.
    reference_um:
        The distance the scenario's ``heading_drift_deg_per_mm`` refers to (1 mm).
    """

    knot_um: float = 25.0
    bias_share: float = 0.5
    reference_um: float = 1000.0

    def __post_init__(self) -> None:
        if not (math.isfinite(self.knot_um) and self.knot_um > 0):
            raise ValueError(f"knot_um must be a positive length (um), got {self.knot_um!r}")
        if not (0.0 <= self.bias_share <= 1.0):
            raise ValueError(f"bias_share must be in [0, 1], got {self.bias_share!r}")
        if not (math.isfinite(self.reference_um) and self.reference_um > 0):
            raise ValueError(f"reference_um must be a positive length (um), got {self.reference_um!r}")


DEFAULT_DRIFT = DriftModel()
"""The simulator's drift settings."""


def drift_variance(s_um, sigma_rad_per_um: float, model: DriftModel = DEFAULT_DRIFT):
    """Variance (rad^2) of the heading drift over ``s_um`` of driving from a knot (closed form).

    ``sigma^2 (f s^2 + (1 - f) s S)``; exact at knot-aligned distances, and equal to ``(sigma S)^2``
    over the reference distance ``S``.
    """
    s = np.asarray(s_um, dtype=np.float64)
    f, big_s = model.bias_share, model.reference_um
    return sigma_rad_per_um**2 * (f * s**2 + (1.0 - f) * s * big_s)


class HeadingDrift:
    """The drift processes of ``n`` robots: a bias each and a walk tabulated lazily at odometer knots.

    Parameters
    ----------
    n:
        Number of robots.
    sigma_rad_per_um:
        ``heading_drift_rad_per_um`` of the scenario (sd of the drift over the reference distance,
        divided by it). Zero gives no drift at all (no draws are made).
    seed_sequence:
        The plant's ``drift`` stream; one child per robot is spawned from it.
    model:
        Knot spacing and variance split.
    """

    def __init__(
        self, n: int, sigma_rad_per_um: float, seed_sequence: np.random.SeedSequence, model: DriftModel = DEFAULT_DRIFT
    ):
        self.n = int(n)
        self.model = model
        self.sigma = float(sigma_rad_per_um)
        f, big_s, delta = model.bias_share, model.reference_um, model.knot_um
        self._walk_scale = self.sigma * math.sqrt((1.0 - f) * big_s / delta)  # curvature sd per knot (1/um)
        self._rngs = [np.random.default_rng(c) for c in seed_sequence.spawn(self.n)]
        # The bias is each stream's first draw; knot values follow in blocks.
        z = np.array([g.standard_normal() for g in self._rngs]) if self.n else np.zeros(0)
        self.bias = self.sigma * math.sqrt(f) * z if self.sigma > 0 else np.zeros(self.n)
        self._table: list[np.ndarray] = [np.zeros(0) for _ in range(self.n)]

    @property
    def active(self) -> bool:
        return self.sigma > 0.0

    def _walk(self, i: int, k_hi: int) -> np.ndarray:
        """Walk curvatures of robot i for knot intervals ``0 .. k_hi`` (inclusive), extending the table."""
        tab = self._table[i]
        while tab.size <= k_hi:
            tab = np.concatenate([tab, self._walk_scale * self._rngs[i].standard_normal(BLOCK)])
        self._table[i] = tab
        return tab

    def segments(self, i: int, o0: float, length_um: float) -> tuple[np.ndarray, np.ndarray]:
        """Drift over odometer ``[o0, o0 + length_um]`` of robot i: ``(lengths (K,), curvatures (K,))``.

        Consecutive pieces cut at the knots, each of constant drift curvature (1/um).
        """
        k0, k1, end = self._knots(o0, length_um)
        tab = self._walk(i, k1)
        # the edges o0, the knots inside, o0 + length, clipped to that range; pieces are their differences
        edges = np.empty(k1 - k0 + 2)
        edges[0] = o0
        edges[1:-1] = self.model.knot_um * np.arange(k0 + 1, k1 + 1, dtype=np.float64)
        edges[-1] = end
        np.minimum(np.maximum(edges, o0, out=edges), end, out=edges)
        return edges[1:] - edges[:-1], self.bias[i] + tab[k0 : k1 + 1]

    def pieces(self, i: int, o0: float, length_um: float) -> tuple[list[float], list[float]]:
        """:meth:`segments` as lists of plain floats, bit-identical (the same clipping and differences):
        the simulator asks for a few pieces of several robots at every sub-interval of a Drive, where
        building small arrays costs more than the arithmetic."""
        k0, k1, end = self._knots(o0, length_um)
        walk = self._walk(i, k1)[k0 : k1 + 1].tolist()
        delta = self.model.knot_um
        edges = [o0] + [min(max(delta * float(k), o0), end) for k in range(k0 + 1, k1 + 1)] + [end]
        bias = float(self.bias[i])
        return [b - a for a, b in zip(edges[:-1], edges[1:], strict=True)], [bias + w for w in walk]

    def _knots(self, o0: float, length_um: float) -> tuple[int, int, float]:
        """``(k0, k1, o0 + length)``: the knot intervals ``k0..k1`` an odometer range ``[o0, o0 + length]`` meets."""
        delta = self.model.knot_um
        end = o0 + max(float(length_um), 0.0)
        k0 = int(math.floor(o0 / delta))
        return k0, max(k0, int(math.ceil(end / delta)) - 1), end

    def curvature_at(self, odometer) -> np.ndarray:
        """Drift curvature ``(n,)`` (1/um) each robot has at its odometer reading (um): the knot interval
        the robot is in, or about to enter."""
        return np.array([self.curvature_one(i, float(odometer[i])) for i in range(self.n)], dtype=np.float64)

    def curvature_one(self, i: int, odometer: float) -> float:
        """The drift curvature of robot i alone (1/um) at its odometer reading (um), a plain float: 0.0 without drift
        (:meth:`curvature_at` of every robot)."""
        if not self.active:
            return 0.0
        k = int(math.floor(odometer / self.model.knot_um))
        return float(self.bias[i]) + float(self._walk(i, k)[k])

    def max_abs(self, i: int, o0: float, length_um: float) -> float:
        """Largest drift curvature magnitude (1/um) robot i meets over odometer ``[o0, o0 + length_um]``."""
        if not self.active:
            return 0.0
        k0, k1, _ = self._knots(o0, length_um)  # the curvatures of :meth:`segments`, without the lengths
        bias = float(self.bias[i])
        return max(abs(bias + k) for k in self._walk(i, k1)[k0 : k1 + 1].tolist())  # plain floats: ~10x faster for a few knots

    def max_abs_all(self, odometer, lengths_um) -> np.ndarray:
        """:meth:`max_abs` of every robot ``(n,)`` (1/um): odometer readings and lengths (um) ``(n,)``."""
        if not self.active:
            return np.zeros(self.n)
        return np.array([self.max_abs(i, o, s) for i, (o, s) in enumerate(zip(np.asarray(odometer, float).tolist(),
                                                                            np.asarray(lengths_um, float).tolist(), strict=True))])

    def heading_change(self, i: int, o0: float, length_um: float) -> float:
        """Heading drift (rad, clockwise positive) accumulated over odometer ``[o0, o0 + length_um]``."""
        if not self.active:
            return 0.0
        lengths, kappas = self.segments(i, o0, length_um)
        return float(lengths @ kappas)
