"""The controller's tuned numbers, each a named, documented field (um, s, deg unless the name says).

Every threshold the closed loop uses lives here, with why it has its value, so that tuning is a change
of :class:`Tuning` (passed as ``ControllerOptions(tuning=...)``), never of the algorithm. The defaults are
what the generality benchmark (``benchmarks/bench_generality.py``, tuning set) was measured with.

Examples
--------
>>> from stressbots.control.tuning import Tuning
>>> t = Tuning()
>>> t.pair_frames, t.gross_docked_clearance_um
(6, 40.0)
>>> from dataclasses import replace
>>> replace(t, pair_frames=3).pair_frames   # a variant; the default is untouched (frozen)
3
"""

from __future__ import annotations

from dataclasses import dataclass, field

from ..assessment import SHAPE_TOL_UM

__all__ = ["ControllerOptions", "Tuning"]


@dataclass(frozen=True)
class Tuning:
    """Thresholds of the closed loop (seed App. 3), with their reasons.

    Attributes
    ----------
    g1_clearance_um:
        Clearance of D_n's timed paths from D_{n-1}'s orbit while G_1 forms (its approach runs close to it).
    wall_clearance_um:
        Clearance of D_n's timed paths from the arena edge and the other orbits (a robot against the edge
        is stuck: it cannot pivot off it).
    final_leg_s:
        D_n drives the last seconds of a timed path open loop when re-planning them would cost a loop.
    station_tol_um:
        After a first leg, D_{n-1} moves its orbit again only if farther than this from its station: the
        rendezvous adapts to the orbit it is on.
    early_s:
        D_n arrives on its approach line this long before D_{n-1} passes the tangent point.
    pair_frames:
        How many pair frames (the nominal one, then re-planned ones) G_1 may be tried in.
    frame_turns_deg:
        Turns of the structure about the G_1 junction tried when G_1 is re-planned (clockwise).
    frame_shifts_um:
        Shifts of the structure tried when G_1 is re-planned (each in 8 directions).
    frame_slot_clearance_um:
        Clearance of a re-planned frame's slots and station orbit from the measured orbits.
    track_overshoot:
        D_n's straight runs during a transfer may end this fraction (plus 40 um) further than planned
        (3 sigma of the literature's 5 % speed error, and the bearing fixes): it must have room to orbit there.
    rendezvous_attempts:
        Rendezvous tries at one station before G_1 is re-planned.
    departure_cost_max:
        Largest accepted max(|w_y| / 80 um, |alpha| / 60 deg) of D_{n-1}'s departure (self-alignment limits).
    meet_gap_um:
        Front edges of the stopped pair at most this far apart count as G_1 formed.
    gross_docked_clearance_um:
        Clearance of gross motion from the docked structure away from its target: a robot grazing the
        structure is turned flush against the wrong edge by docking compliance and is trapped there.
    arrive_um, arrive_deg:
        A gross-motion target region (the seed's regions instead of points).
    left_bias_deg:
        A turn into a long straight is cut short by up to this much (one-way robots correct clockwise).
    whole_leg_factor:
        A path shorter than this many t_x runs whole (stopping short and overshooting would cost a loop).
    stall_fraction:
        A robot that moved less than this fraction of its commanded distance stalled (failure region H).
    stall_count:
        Consecutive stalls after which gross motion gives up (stuck) and recovery begins.
    dock_attempts:
        Docking attempts of a single robot before the run fails.
    approach_lengths_um:
        Candidate clear corridor lengths behind a slot, longest first.
    funnel_min_behind_um, funnel_extra_um, funnel_right_um:
        The approach funnel: at least this far behind the slot, at most the corridor plus the extra, at
        most this far right of the line.
    merge_heading_margin_deg:
        The merge onto the approach line must survive this much less left heading than measured.
    small_miss_um:
        A straight-in whose lateral miss and offset are below this is driven rather than looped (~6 um RMS).
    late_miss_um:
        A straight-in with a larger miss, up to this, is driven when a loop from where the robot is would
        meet the structure (a turning robot cannot pivot off it; the slot's docking tolerance is 30 um).
    orbit_watch_um:
        An orbit closer than this to another orbit, a docked body or the arena edge is logged.
    """

    g1_clearance_um: float = 25.0
    wall_clearance_um: float = 40.0
    final_leg_s: float = 3.0
    station_tol_um: float = 150.0
    early_s: float = 1.2
    pair_frames: int = 6
    frame_turns_deg: tuple[float, ...] = (0.0, 20.0, -20.0, 45.0, -45.0, 90.0, -90.0, 135.0, -135.0, 180.0)
    frame_shifts_um: tuple[float, ...] = (0.0, 200.0, 400.0)
    frame_slot_clearance_um: float = 30.0
    track_overshoot: float = 0.15
    rendezvous_attempts: int = 4
    departure_cost_max: float = 0.6
    meet_gap_um: float = 25.0
    gross_docked_clearance_um: float = 40.0
    arrive_um: float = 25.0
    arrive_deg: float = 6.0
    left_bias_deg: float = 3.0
    whole_leg_factor: float = 1.6
    stall_fraction: float = 0.15
    stall_count: int = 3
    dock_attempts: int = 6
    approach_lengths_um: tuple[float, ...] = (450.0, 350.0, 250.0, 150.0)
    funnel_min_behind_um: float = 120.0
    funnel_extra_um: float = 250.0
    funnel_right_um: float = 60.0
    merge_heading_margin_deg: float = 1.5
    small_miss_um: float = 12.0
    late_miss_um: float = 25.0
    orbit_watch_um: float = 10.0


@dataclass(frozen=True)
class ControllerOptions:
    """Closed-loop settings (um, s, deg).

    Attributes
    ----------
    replan_interval_s:
        t_x, the time between measurements; default the scenario's ``[control]`` value.
    time_budget_s:
        Simulated time after which the run is declared failed.
    fine_distance_um:
        Distance of the intermediate pose a_i behind a slot for the S_2f arc (tight gaps only; elsewhere
        the approach funnel's depth follows the clear corridor behind the slot, 150-450 um).
    switch_period_s:
        Period of the primitive alternation in interpolated turning (shorter = closer to the arc).
    push_s:
        How long a docking robot keeps pushing after its fine motion, for compliance to act.
    dock_tol_um, dock_tol_deg:
        A stationary robot this close to its slot counts as docked (camera error included).
    clearance_um:
        Clearance kept by single robots' replanned paths from orbits, the structure and the arena edge
        (G_1's own: ``Tuning.g1_clearance_um``, ``Tuning.wall_clearance_um``).
    shape_tol_um:
        Success threshold on the RMS shape error after best rigid alignment.
    tuning:
        The closed loop's thresholds (:class:`Tuning`).
    """

    replan_interval_s: float | None = None
    time_budget_s: float = 4000.0
    fine_distance_um: float = 200.0
    switch_period_s: float = 0.2
    push_s: float = 1.5
    dock_tol_um: float = 30.0
    dock_tol_deg: float = 15.0
    clearance_um: float = 15.0
    shape_tol_um: float = SHAPE_TOL_UM
    tuning: Tuning = field(default_factory=Tuning)
