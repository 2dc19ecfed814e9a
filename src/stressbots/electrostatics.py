"""Electrostatic control: arm hysteresis, accessible control states, STRING designs, primitives.

SPEC section 4. Every robot sees the same voltage. A robot's steering arm snaps down when the applied
level reaches its snap-down voltage ``V_d`` and releases when the level falls to its release voltage
``V_u`` (``V_u < V_d``); in between it keeps its state. At 0 V every arm is up.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Electrodes:
    """The electrode array's electrical limits (volts, hertz, seconds).

    Attributes
    ----------
    max_V:
        Largest level the hardware may apply. No waveform ever leaves ``[0, max_V]``.
    margin_V:
        delta_v: every applied level keeps at least this distance from every threshold, so that
        fabrication scatter does not flip an arm by accident.
    drive_low_V, drive_high_V:
        The power-delivery band. The scratch drives move while the signal oscillates between the two.
    drive_frequency_hz:
        Oscillation frequency of the power-delivery waveform.
    hold_s:
        How long a setting level is held to let arms snap or release (robots do not move meanwhile).
    """

    max_V: float = 200.0
    margin_V: float = 5.0
    drive_low_V: float = 75.0
    drive_high_V: float = 105.0
    drive_frequency_hz: float = 10000.0
    hold_s: float = 0.001
