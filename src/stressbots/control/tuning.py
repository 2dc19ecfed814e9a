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

import math
from dataclasses import dataclass, field

from ..assessment import SHAPE_TOL_UM

__all__ = ["ControllerOptions", "DockingTuning", "GrossTuning", "PairTuning", "ParkingTuning", "Tuning"]


@dataclass(frozen=True)
class PairTuning:
    """G_1: D_(n-1)'s station transfer, D_n's timed rendezvous, the meeting, holding orbits, searched escapes and pair
    rounds (seed App. 3.3; :mod:`~stressbots.control.pair` and its parts)."""

    tend_during_rendezvous: bool = True
    """Whether D_n's timed approach to D_{n-1}'s orbit (:meth:`~stressbots.control.rendezvous.Rendezvous.arrive_timed`)
    first moves waiting orbits that drifted near trouble, every t_x (otherwise nothing tends them for the whole
    rendezvous; :class:`~stressbots.control.rendezvous.Tending`). On since session 21, with ``tend_during_transfer``:
    waiting orbits drifted into the arena edge during G_1 and trapped their robots, which then found no route when their
    turn came (held-out 2x 10:0, 10:3, 34:1, 34:3; 1x 33:3, 34:4); both on: held-out 1x 295 -> 297/300 (no trial
    lost), 2x 215 -> 216/240 (+4 -3). Session 12 had measured this one alone, with ``park_retry_drift_um`` = 20: only the
    tuning set gained then."""
    tend_during_transfer: bool = True
    """Whether D_n's timed run to a clear track (a station-transfer leg) first moves waiting orbits that drifted near
    trouble, every t_x; the leg is planned again after such a move (:class:`~stressbots.control.rendezvous.Tending`).
    On since session 21, with ``tend_during_rendezvous`` (see there)."""
    fresh_pair_disc: bool = True
    """Whether D_n's manoeuvres that run many t_x (a timing loop, a drive to a holding orbit) check each t_x against
    D_{n-1}'s orbit disc as measured at that frame (:meth:`~stressbots.control.pair.PairPhase.orbit_disc`), not as
    it was when the manoeuvre began. The identified radius of a robot that has barely turned yet keeps changing while
    it orbits (held-out 40:4 at 2x: D_{n-1}'s r_hat 205 -> 223 um in 9 s, its measured centre 55 um away): a 15 s
    timing loop checked against the disc of its first frame ran D_n into D_{n-1}'s body, and they stayed wedged. Alone
    (session 25): held-out 1x and 2x seeds 0-3 trial for trial the same, a few durations changed; with
    ``loop_body_clearance_um`` see there."""
    g1_clearance_um: float = 25.0
    """Clearance of D_n's timed paths from D_{n-1}'s orbit while G_1 forms (its approach runs close to it)."""
    wall_clearance_um: float = 40.0
    """Clearance of D_n's timed paths from the arena edge and the other orbits (a robot against the edge is stuck: it
    cannot pivot off it)."""
    final_leg_s: float = 3.0
    """D_n drives the last seconds of a timed path open loop when re-planning them would cost a loop."""
    station_tol_um: float = 150.0
    """After a first leg, D_{n-1} moves its orbit again only if farther than this from its station: the rendezvous
    adapts to the orbit it is on."""
    turn_stall_fraction: float = 0.25
    """While D_{n-1} turns toward a transfer leg (closed loop on its measured heading), a t_x in which it turned less than
    this fraction of what it was commanded counts as stalled (it turns into something and cannot pivot off)."""
    turn_stall_frames: int = 3
    """... and this many such t_x in a row end the leg (G_1 is planned again): D_{n-1} held against the arena edge turned
    nothing for 3900 s of simulated time, until the time budget ran out (held-out 25:1 at 2x)."""
    early_s: float = 1.2
    """D_n arrives on its approach line this long before D_{n-1} passes the tangent point."""
    pair_frames: int = 6
    """How many pair frames (the nominal one, then re-planned ones) G_1 may be tried in."""
    frame_turns_deg: tuple[float, ...] = (0.0, 20.0, -20.0, 45.0, -45.0, 90.0, -90.0, 135.0, -135.0, 180.0)
    """Turns of the structure about the G_1 junction tried when G_1 is re-planned (clockwise)."""
    frame_shifts_um: tuple[float, ...] = (0.0, 200.0, 400.0)
    """Shifts of the structure tried when G_1 is re-planned (each in 8 directions)."""
    frame_for_approach_room: bool = True
    """Whether G_1 first aims at a pair frame in which every later robot has room to come round onto its approach
    (:meth:`~stressbots.control.pair.PairPhase.room_frame`) when the nominal frame leaves one without. Session 14
    measured it a wash (tuning 1x +6 -3, held-out 2x +1 -3, independent plant +2 -4) and left it off; the controller
    around it has changed since, and in session 30 the 33 tuning trials at 2x (seeds 0-1) where it fires went from
    14 to 27 successes (234/240 at 1x, as without it): on by default (design.md 3.9)."""
    approach_room_um: float = 0.0
    """um. Room a later robot's approach needs (:func:`~stressbots.control.pair_geometry.approach_room`): its orbit disc
    one turning radius behind the start of its fine motion fits inside the arena (0: just)."""
    approach_room_behind_radii: float = 1.0
    """Turning radii behind the start of fine motion where ``approach_room_um`` is measured: a robot comes round onto
    its approach there (0: at the start of fine motion itself)."""
    approach_room_gain_um: float = 100.0
    """um. When no frame gives every approach ``approach_room_um``, the roomiest is taken only if it gains this much
    over the nominal (a frame costs the pair a longer way to its station)."""
    frame_slot_clearance_um: float = 30.0
    """Clearance of a re-planned frame's slots and station orbit from the measured orbits."""
    track_overshoot: float = 0.15
    """D_n's straight runs during a transfer may end this fraction (plus 40 um) further than planned (3 sigma of the
    literature's 5 % speed error, and the bearing fixes): it must have room to orbit there."""
    leg_overrun_s: float = 0.3
    """s. How far past a station-transfer leg's end D_{n-1}'s straight track must be clear (at its identified speed):
    the leg is driven closed loop and its last frame (at most 1.6 t_x) runs long by the speed error, 3 sigma of 10 %
    at 2x the literature's noise. It was a whole second: past a via orbit of the station route (whose own check is the
    orbit disc at the leg's end) that reached into a waiting orbit, and every pair frame failed in zero time (held-out
    19:0 at 2x)."""
    rendezvous_attempts: int = 4
    """Rendezvous tries at one station before G_1 is re-planned."""
    departure_cost_max: float = 0.6
    """Largest accepted max(|w_y| / 80 um, |alpha| / 60 deg) of D_{n-1}'s departure (self-alignment limits)."""
    last_meet_cost_max: float = 1.0
    """Largest accepted cost (as ``departure_cost_max``) of the pair meeting where it stands once every pair frame has
    failed (:meth:`~stressbots.control.departure.Departure.meet_as_they_are`): the self-alignment limits themselves,
    no margin, since the alternative is giving G_1 up."""
    meet_gap_um: float = 25.0
    """Front edges of the stopped pair at most this far apart count as G_1 formed."""
    via_tol_um: float = 60.0
    """D_{n-1}'s orbit counts as at an intermediate orbit of its route (and, on the first try, at its station) within
    this."""
    station_grid_um: float = 150.0
    """Spacing of the grid of free orbit centres D_{n-1}'s route to its station may pass through."""
    station_leg_cost_um: float = 300.0
    """Cost of one more leg on that route (the orbiting before it, one more chance for error), um of length."""
    station_via_wall_um: float = 60.0
    """um. The route's intermediate orbits keep this much more than the transfer clearance from the arena edge: a via
    orbit placed 35 um from the left edge landed 40 um into it at 2x noise, and D_{n-1}, held there, never turned
    again (held-out 25:1)."""
    orbit_room_um: float = 15.0
    """um. Room to orbit (gap of its orbit disc to the arena edge and the lower orbits) D_n keeps at the
    predicted end of every straight frame of a station transfer: a one-way robot that loses it while the
    edge lies ahead is trapped for good. Beyond the predicted end (which already runs ``track_overshoot``
    long), a few camera sigmas at 2x noise."""
    hold_candidates: int = 24
    """Free orbits near its target (cheapest first) D_n considers when it has no timed path and goes to
    wait: the first with a clear shortest path there (and, preferably, on to the target) is taken."""
    separate_frames: int = 8
    """t_x. After a failed meeting the G_1 pair drives straight apart for at most this long (until D_n's
    orbit clears D_{n-1}'s): at the literature's speeds about 1.5 mm between them, beyond any orbit disc."""
    timing_loops_max: int = 3
    """Interpolated timing loops one timed arrival of D_n may drive before it counts as having no timed way
    (the caller falls back). A loop that comes back off time is followed by another, just as far off: at
    2x noise D_n looped 45 times (700 s simulated, 100 s wall) without arriving."""
    hold_keeps_loop: bool = False
    """Whether D_n's drive to a holding orbit stops before a t_x that would leave it without its clockwise loop
    (:meth:`~stressbots.control.holding.HoldingOrbit.loses_loop`): stopped there, D_n and D_(n-1) were wedged for good
    (held-out 38:3 at 2x, which it fixes). Off: measured in session 22, held-out 1x 299/300 and the tuning set 236/240
    and the independent plant 115/120 identical, held-out 2x 215/240 against 216 (+3:0 +38:3, -20:3 -34:1 -55:1, each
    loss a different path, none a hold that stopped short) and on seeds 4-7 218/240 both: inside the noise."""
    hold_frames: int = 120
    """t_x. Longest drive of D_n to a holding orbit (re-planned every t_x): the gross-motion cap it had before."""
    escape_search_frames: int = 12
    """t_x. Longest searched escape of D_n (:meth:`~stressbots.control.pair_recovery.PairRecovery.searched_escape`),
    re-searched every t_x: a turn of up to a loop (~20 s at the literature's speeds) and a straight."""
    escape_search_step_deg: float = 15.0
    """deg. Grid of the turns a searched escape tries before its straight: fine enough that one of them slips
    between two orbiting bodies (a body passes a point of its orbit in a few degrees of D_n's turn)."""
    escape_search_straight_um: float = 900.0
    """um. Longest straight of a searched escape: beyond an orbit disc's diameter (D_n's orbit can overlap one by
    its whole radius), short of crossing the arena."""
    escape_body_clearance_um: float = 10.0
    """um. Gap a searched escape keeps between D_n's body and every other body at the same instants (their
    poses are predicted over seconds from identified turn rates, a few um off at 2x noise). Smaller than
    ``g1_clearance_um``: the escape is the last move before G_1 gives up, and at 25 um every candidate
    was refused with the other body still 108 um away."""
    hold_centre_tol_um: float = 100.0
    """um. D_n has reached its holding orbit once it orbits a free centre this close to the chosen one (the
    hold is a place to wait, not a pose): a quarter of a typical turning radius, well inside the 100 um grid
    the free orbits are chosen on."""
    hold_headings: int = 24
    """Poses on a holding orbit (evenly spaced headings) D_n's way there may end at, re-chosen every t_x: the
    nearest one needs no loop of a one-way robot (15 deg apart: a few um of path between neighbours)."""
    meet_diverge_um: float = math.inf
    """um. The pair's front edges this much farther apart than at their closest during the meeting's straight
    run count as having passed each other and the run stops. Off (inf) by default: at 80 um it misfired on
    the estimate jumps after camera dropouts (tests/test_edr.py, 20 % dropouts: 1 of 3 seeds). The meeting
    still stops wherever either robot would lose room to orbit (instead of driving on for 60 t_x into the
    arena edges)."""
    meet_free_fraction: float = 0.8
    """The meeting's stop checks (``meet_diverge_um``, room to orbit) apply only after a t_x in which both robots
    covered at least this fraction of their nominal travel: driving freely, not in contact (where the front
    edges slide apart while compliance aligns the pair, a meeting that succeeds)."""
    loop_clearance_um: float = 15.0
    """um. Clearance the rest of D_n's timing loop keeps from the arena edge and the orbits, checked from its
    measured pose every t_x; below it the loop stops and the timing is planned again. The loop was planned at
    ``wall_clearance_um`` (40 um): this leaves 25 um for drift before the check fires."""
    loop_body_clearance_um: float = 20.0
    """um (0: off). Each t_x of D_n's timing loop must also keep this far from D_{n-1}'s body as predicted at the same
    instants (:meth:`~stressbots.control.pair.PairPhase.body_gap`), else the loop stops and the timing is planned again.
    The rest of the loop is checked against D_{n-1}'s orbit disc at no margin (``loop_clearance_um`` less the G_1
    shortfall): a loop predicted to pass 4 um outside that disc ran into D_{n-1}'s body one t_x later, where its body
    was just then (held-out 40:4 at 2x; predicted 17 um apart, they touched), and the pair stayed wedged. With
    ``fresh_pair_disc`` (session 25): held-out 2x seeds 4-7 221/240 against 219 (+33:7 +40:4), tuning 236/240 against
    235 (+93:0), held-out 1x and 2x seeds 0-3 trial for trial the same. The same check on D_n's drives to a holding
    orbit (stop before a t_x that ends within 20 um of D_{n-1}'s body) lost 32:0, 55:1 and 33:5 at 2x and gained
    none: a hold stopped there left D_n unable to move at all."""
    recovery_keeps_off_discs: bool = False
    """When True, D_n's direct way out of the orbits around it (:meth:`~stressbots.control.pair_recovery.PairRecovery.escape`)
    stops turning before its body would enter a lower robot's orbit disc it is not in (then the searched escape, body
    to body in time, takes over): turning in place, D_n was carried onto a waiting orbit whose body then blocked every
    way out (held-out 20:4 at 1x). Off: it gained that trial and lost 20:1, held-out 2x 90/120 against 89, the
    independent plant 57/60 both (design.md 3.9, session 13)."""
    give_up_boxed_in: bool = True
    """Whether G_1 gives up at once, rather than re-planning pair frames, when D_n is boxed in against the arena edge
    (:meth:`~stressbots.control.pair.PairPhase.boxed_note`: no clockwise turn and straight of it keeps
    ``viable_clearance_um`` from it): nothing a re-plan does frees a one-way robot there, and held-out 14:0 at 2x spent
    200 s of simulated time (7.3 s of wall time, 22x the median pair) re-planning transfers and holds after its D_n was
    boxed in at 3 s."""
    pair_rounds: int = 2
    """Rounds of pair frames G_1 may try (each up to ``pair_frames``); between rounds D_n goes to wait on a free
    orbit (or gets clear of the orbits), so a round plans from new poses. Every frame of a round failed at one
    instant with nothing moved, and the run was given up with time budget left."""
    round_moved_um: float = 20.0
    """um. D_n must have moved at least this far between two rounds of pair frames (else the same poses would
    fail the same way and G_1 gives up): several camera sigmas."""
    round_frames: int = 3
    """Pair frames a later round (after the first's ``pair_frames``) may try: the nearest frames from the new
    poses. A frame costs seconds of wall time in the timed-track searches; a whole second round of six cost
    66 s on one trial (issue 12, goal 5: no failing trial 10x a normal one)."""
    group_escape_waits: int = 24
    """Waits (evenly spaced fractions of D_n's orbit period, everyone orbiting) a group escape tries before its
    group straight (:func:`~stressbots.control.group_escape.group_escape`): 15 deg of D_n's turn apart, like
    ``escape_search_step_deg``."""
    group_escape_straight_um: float = 600.0
    """um. Longest straight of D_n in a group escape: the other movers (D_{n-1}, waiting robots) drive as far at
    their own speeds, so shorter than ``escape_search_straight_um``; an orbit disc's diameter is ~500-600 um."""
    group_disc_clearance_um: float = 25.0
    """um. Gap the orbit disc of every robot but D_n that drives straight in a group escape keeps from the arena edge,
    the docked bodies and the other discs along its track (or its present gap, if smaller): ``park_clearance_um``,
    since the move is a park move of the group."""
    group_escape_sequences: bool = True
    """Whether D_n's group way out may be two manoeuvres in turn (any primitive first, then a group manoeuvre:
    :func:`~stressbots.control.group_escape.group_escape_sequence`) when no single one exists. 24 of the 28 G_1
    failures of sessions 12-13's baselines gave up with "no way out of the orbits around it" (held-out 14:3 at 2x:
    two robots alone in the arena, orbits overlapping by 254 um; every single manoeuvre met the other body)."""
    group_sequence_cut_um: float = 60.0
    """um of D_n's travel between the points where a sequence's first manoeuvre may end: a quarter of a body length,
    so the window in which a body passing beside D_n's track leaves the way open is not stepped over, and about 24
    cuts per primitive over an orbit of ~1400 um, few enough to search again every t_x (only when no single
    manoeuvre exists)."""
    transfer_stops_before_wedge: bool = True
    """Whether a straight leg of the station transfer stops before a t_x after which every primitive of the pair
    would bring D_n's and D_{n-1}'s bodies together within ``wedge_horizon_s``
    (:meth:`~stressbots.control.transfer.StationTransfer.would_wedge`). Tracks planned apart converge under heading
    drift (3.7 deg/mm, twice that at 2x); stopped only when they "would touch" in the next t_x, the pair was
    already wedged and G_1 gave up (held-out 47:2, 9:2 at 2x)."""
    wedge_horizon_s: float = 3.0
    """s. How long one primitive must keep the pair's bodies apart for the pair to count as having a way apart: about
    a quarter of an orbit, time for the next leg's wait or turn to begin."""
    group_tight_body_um: float = 0.0
    """um. When no group way out keeps ``escape_body_clearance_um`` between D_n's body and the others, one that keeps
    this at the search's samples is taken (no margin: bodies may graze by a few um between samples), the last way
    out before every pair frame fails at the same instant with nothing moved (2x tuning layouts 19 seed 1 and 34
    seed 0: D_n hemmed in beside a waiting robot at t = 9 and 27 s)."""
    transfer_tracks_apart: bool = False
    """Whether a turn-together leg of the station transfer must keep D_n's straight track off D_{n-1}'s whatever the
    timing (:func:`~stressbots.control.transfer_legs.tracks_apart`, half the two body lengths plus the leg
    clearance). Tracks timed to pass in front of each other met under noise and locked the pair (2x tuning 31:0,
    10:0). Measured in session 11 at 2x: tuning 84 -> 89/120 (+5 -0), held-out 96 -> 97/120 (+4 -3); on the
    independent plant 57/60 (main: 56/60); held-out 1x 288/300 (main: 290/300), so off (docs/design.md 3.9, session 11)."""
    leg_stall_frames: int = 4
    """t_x. A straight leg of D_{n-1}'s station transfer stops after this many frames in a row without progress
    (:class:`~stressbots.control.leg_watch.LegProgress`): the pair pushing each other, one leg ran 242 s."""
    leg_stall_fraction: float = 0.3
    """Progress of a leg frame below this fraction of the commanded travel counts as none: a robot pushed by another
    still creeps, camera noise is a few um of a ~100 um frame."""


@dataclass(frozen=True)
class GrossTuning:
    """Gross motion of a single robot to its approach funnel: regions, routes, stalls and escapes (seed App. 3.1,
    sigma_1; :mod:`~stressbots.control.gross`, :mod:`~stressbots.control.single`)."""

    gross_docked_clearance_um: float = 40.0
    """Clearance of gross motion from the docked structure away from its target: a robot grazing the structure is
    turned flush against the wrong edge by docking compliance and is trapped there."""
    gross_start_relief: bool = True
    """Whether that clearance is also waived within the first loop's reach of where a gross motion starts
    (:meth:`~stressbots.control.gross.GrossMotion.obstacles_hit`): after a missed approach line the loop back runs
    close to the structure, and with 40 um everywhere no path, detour or route left the robot there ("no route ... 0 um
    of its path clear"). On with ``DockingTuning.loop_back_clearance_um`` 15, ``late_miss_um`` inf and
    ``dead_end_guard`` (session 18, all four together against all off: independent plant 114/120 against 111,
    held-out 1x 296/300 against 295, held-out 2x 180/240 the same, tuning 1x 239/240 against 240; design.md 3.9)."""
    dead_end_guard: bool = True
    """Whether a gross-motion path whose next t_x would leave the robot without a clear loop counts as blocked
    (:meth:`~stressbots.control.escapes.Escapes.dead_end_ahead`): a 2x drift bent a long straight past the structure
    until neither its loop nor its straight was free (held-out 53:0 at 2x). Alone: held-out 2x seeds 0, 1 90/120
    against 94; with the loop-back switches see ``gross_start_relief``."""
    arrive_um: float = 25.0
    arrive_deg: float = 6.0
    """(arrive_um, arrive_deg) A gross-motion target region (the seed's regions instead of points)."""
    region_targets: bool = True
    """Whether gross motion aims at a region around a waypoint (nominal route or roadmap) rather than the point
    (:func:`~stressbots.control.queries.shortest_into`): its arrival region (``waypoint_region_um``,
    ``waypoint_region_deg``). Held-out 33:1 at 2x circled a nominal waypoint for 57 s and a roadmap one for another
    57 s, ending each loop 20-35 um on the side that needs one more. Measured (session 22): held-out 1x 299/300 against
    298, 2x 216/240 against 217 (11 trials gained, 12 lost: noise)."""
    region_aims: bool = False
    """Whether it does so for its aim too: poses inside the approach funnel, or a_i's arrival region
    (:meth:`~stressbots.control.slot_approach.SlotApproach.aim_region`). Off: measured with the waypoint regions
    (session 22), held-out 1x 299/300 both ways, 2x 213/240 against 216: a robot that no longer loops back enters its
    funnel where it first touches it, and more of them docked off their line (11 shape errors at 2x against 9)."""
    circling_widen: float = 0.0
    """A route waypoint's arrival region (``arrive_um``, ``arrive_deg``) grows by this much of itself for every whole loop
    spent steering to it (:func:`~stressbots.control.gross.circling_scale`; 0: never): a waypoint nearly on the robot's
    turning circle is missed by a few degrees a loop, every loop (tuning 90:0 with the drift identified: four loops round
    one waypoint, then boxed in against the arena edge; at 1 it assembles). Measured at 1 (session 23, drift
    identification off): held-out 1x 299/300 (identical), 2x 213/240 against 216 (13 shape errors against 9): off."""
    region_min_saving_loops: float = 0.5
    """Loops (2 pi r) a goal of the region must save on the path to the target itself to be taken instead: the region
    is for a target that needs a loop more than its neighbours, not for shaving um off ordinary paths."""
    waypoint_region_um: float = 12.0
    waypoint_region_deg: float = 3.0
    """(waypoint_region_um, waypoint_region_deg) A waypoint's goals lie this far (um) ahead, behind, left and right of
    it and turned this far (deg) either way: about half of ``arrive_um`` / ``arrive_deg``, so the errors of the last leg
    still end inside its arrival region."""
    left_bias_deg: float = 3.0
    """A turn into a long straight is cut short by up to this much (one-way robots correct clockwise)."""
    left_bias_hold: bool = True
    """Whether a turn into a long straight no longer than ``left_bias_deg`` is not driven at all, so the robot keeps
    a standing margin left of the straight's heading. Cut by half every t_x instead, the margin shrank to nothing
    within a few t_x, and a frame's heading error (1 deg at 2x) past the straight's heading re-planned a full loop:
    held-out 41:0 at 2x looped four times round its first roadmap waypoint (60 s) that way. Measured alone (session 24,
    against off): held-out 1x 297/300 (298), 2x seeds 0-3 223/240 (216), seeds 4-7 219/240 (222), tuning 235/240 (236),
    independent plant 116/120 (114); simulated assembly time 12-14 % shorter. Holding the whole bias for turns up to twice
    it as well measured 217/240 at 2x, with more docks off the line (10 shape errors over 10 um against 4)."""
    left_bias_shrink: bool = True
    """Whether a left bias whose biased straight would pass too near an obstacle is tried at half and a quarter of itself
    before none is kept: refused whole, a robot driving a long straight along the structure kept no margin at all and
    looped for the first frame that put it past its heading (held-out 6:4: next to the stem it was to dock at the end of).
    Measured with ``loop_defer_deg`` 2 on top of the hold (session 24): held-out 1x 298/300 (6:4 assembles; the hold
    alone 297), 2x 220/240 and 219/240 on seeds 0-3 and 4-7, tuning 235/240, independent plant 115/120: within the
    noise of the hold alone on success, 5-6 % shorter assemblies again."""
    loop_defer_deg: float = 2.0
    """A robot measured up to this far (deg) clockwise of the heading of a long straight drives straight one t_x instead
    of the full loop its shortest path starts with (:func:`~stressbots.control.gross.loop_deferred`; 0:
    never): about twice the heading estimate's error at 2x the literature's camera noise. With the hold, 2x seeds 0-3:
    225/240 (223 without); measured with ``left_bias_shrink`` above."""
    loop_defer_min_straight_tx: float = 4.0
    """A loop is deferred only while that straight is at least this many t_x long: a robot truly past its heading loops
    later, and the loop should not move near its target (the structure)."""
    whole_leg_factor: float = 1.6
    """A path shorter than this many t_x runs whole (stopping short and overshooting would cost a loop)."""
    stall_fraction: float = 0.15
    """A robot that moved less than this fraction of its commanded distance stalled (failure region H)."""
    stall_count: int = 3
    """Consecutive stalls after which gross motion gives up (stuck) and recovery begins."""
    dock_attempts: int = 6
    """Docking attempts of a single robot before the run fails."""
    skip_blocked_waypoints: bool = True
    """A waypoint of the nominal route whose path is blocked is dropped and the gross motion heads for the next target
    (:meth:`~stressbots.control.single.SingleDocking._steer_through`): the waypoint was planned for the nominal poses."""
    approach_lengths_um: tuple[float, ...] = (450.0, 350.0, 250.0, 150.0)
    """Candidate clear corridor lengths behind a slot, longest first."""
    funnel_min_behind_um: float = 120.0
    funnel_extra_um: float = 250.0
    funnel_right_um: float = 60.0
    """(funnel_min_behind_um, funnel_extra_um, funnel_right_um) The approach funnel: at least this far behind the slot,
    at most the corridor plus the extra, at most this far right of the line."""
    aim_behind_extra_um: float = 150.0
    """um. How far behind the corridor's end the gross motion to a slot with an approach line may aim (half of it, then
    all), where a clockwise loop through the corridor's end would meet something
    (:meth:`~stressbots.control.slot_approach.SlotApproach._aim_behind`); within the funnel (``funnel_extra_um``)."""
    funnel_psi_deg: float = 12.0
    """deg. The approach funnel takes a robot pointing at most this far left of its approach line: the line approach
    merges by clockwise bursts, and from 32 deg (tried where the way to the funnel was blocked) they docked a robot 74 um
    off its slot."""
    funnel_aim_left_deg: float = 6.0
    """deg. The funnel aim points this far left of the approach line (more by the lead an identified clockwise drift
    needs: :func:`~stressbots.control.slot_approach.funnel_aim_left_rad`), so that the last leg's heading error keeps
    the robot pointing into the funnel (``funnel_psi_deg``) rather than past the line's heading, where only a loop
    brings it back."""
    funnel_aim_right_um: float = 20.0
    """um. The funnel aim lies this far right of the approach line: the line approach merges by clockwise bursts from
    the right, and a last leg that ends a few um left of its aim is then still on the right side of the line."""
    tight_aim_deg: tuple[float, ...] = (90.0, 60.0, 45.0)
    """deg, tried in order. Where a slot's a_i lies within ``escape_clearance_um`` of the arena edge or beyond it (a
    structure that formed 150-230 um nearer the edge than planned moved a stem's end there: the nominal a_i was 50 um
    outside the arena, held-out 34:0 at 2x, and every attempt asked for a route to it), the robot aims instead at the
    start of an arc of this turn into the slot, which starts beside the slot rather than behind it (the planner's
    ``PlannerOptions.tight_approach_deg``)."""
    tight_aim_radius: float = 1.1
    """Radius of those arcs, times the robot's identified turning radius (the planner's ``tight_approach_radius``)."""
    fine_arc_arrival_deg: float = 40.0
    """deg. The S_2f fine motion steers one interpolated arc into the slot only while that arc arrives within this of the
    slot's heading (docking compliance turns the robot flush from there); beyond it, gross motion again."""
    arc_in_reach: float = 2.0
    """Lengths of the S_2f arc (:func:`~stressbots.control.queries.fine_motion_length`). Where a loop is blocked, a robot
    within this of its slot that one interpolated arc takes in starts its fine motion from there
    (:meth:`~stressbots.control.slot_approach.SlotApproach.can_arc_in`): a_i lies one such length out, and a robot short of it
    by 100 um and 30 deg had only the loop back."""
    arc_in_aim_um: float = 40.0
    """um. That arc aims where docking compliance ends the robot in the slot (:func:`~stressbots.control.docking.compliant_aim`),
    29 um along the face for a robot arriving 13 deg off; an aim further from the slot than this is not taken (one 170 um
    off ended the arc against a neighbour's end)."""
    merge_heading_margin_deg: float = 1.5
    """The merge onto the approach line must survive this much less left heading than measured."""
    no_route_quiet_cycles: int = 5
    """After the roadmap found no way around the obstacles, gross motion drives on this many t_x before it asks again
    (each failed query costs a full roadmap build: failing runs spent minutes there)."""
    approach_lead_in_radii: float = 1.0
    """An approach corridor counts only if its line goes on this many of the robot's turn radii beyond the funnel,
    clear of the structure and the arena edge: a one-way robot enters the funnel from behind, so a funnel backed
    against the edge is a target no path reaches (those robots drove on along blocked paths into the edge, where
    turning and driving both push into it: trapped)."""
    arc_when_line_unreachable: bool = True
    """When no clear approach corridor behind a slot is reachable (``approach_lead_in_radii``), the robot arcs into the
    slot from its intermediate pose a_i (the nominal route's first, where the planner's own final arc begins) instead
    of aiming at the clear but unreachable line: by the arena edge a slot whose rear lies 250 um from it has a
    150 um corridor that only a path from outside the arena joins, and the robot toured the arena for hundreds of
    seconds until it was trapped at the edge (the tee-by-wall layouts: tuning 4:0, 89:0, 89:1, held-out 6:3 at 1x)."""
    escape_clearance_um: float = 10.0
    """Clearance of the last roadmap search, after the full one found nothing: a robot in a tight spot (its loop 12 um
    from the edge, say) has no route at 15-20 um from where it is, and the clear part of a route at a few um is
    safer than the blocked shortest path (5 sigma of the 2 um camera error)."""
    route_searches_max: int = 3
    """Failed roadmap searches (each at up to three clearances) a robot may spend on one target (same structure and
    orbits) in a run; each costs up to six roadmap builds (0.1-0.5 s each), and failing 8-robot runs spent 40-80 s
    asking again and again."""
    min_clear_run_s: float = 1.0
    """With no route, a robot drives the clear beginning of its blocked path only if it is at least this many seconds
    of travel; otherwise it gives up the target (the caller re-plans) instead of driving into what blocks it."""
    escapes_per_steer: int = 2
    """Escapes (:meth:`~stressbots.control.escapes.Escapes.escape`) one gross motion may make from a contact or a
    stall before it reports the robot stuck (each is a turn and a straight: a few seconds)."""
    escape_turns: tuple[float, ...] = (0.0, 0.03125, 0.0625, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875)
    """Fractions of a loop an escape may turn before its straight (a one-way robot cannot reverse). Fine steps first
    (1/32 = 11 deg): a robot beside a wall swings its rear corner out by tens of um when it turns further, so the
    way off is often a slight turn, then straight."""
    escape_straights: tuple[float, ...] = (0.5, 1.0, 1.5)
    """Lengths of an escape's straight, in body lengths (one clears a body it touched end to end)."""
    viable_clearance_um: float = 5.0
    """um. A robot is *boxed in* at a pose when none of its escapes (``escape_turns`` of a loop, then one body
    length straight) keeps this far from the orbits, the docked bodies and the arena edge: it can neither turn
    nor drive on. The clear part of a blocked path is driven only up to its last pose that does not box the
    robot in, an escape of a free robot must end free, and a failed attempt's back-off leaves a free robot where
    it is: on the tuning set most "no route ... gives up this target" failures had driven the clear part of
    their path to a stop 10-50 um short of the structure, the arena edge or a waiting robot, heading into it,
    and were pinned there by the next blind move. Above the camera's and one t_x of drift's error (a few um),
    well below the controller's 15 um clearance."""
    prefixed_checks_max: int = 0
    """Off (0) by default. When > 0, a blocked shortest path is first replaced by the shortest clear "turn, straight, then
    shortest path" (:mod:`~stressbots.control.prefixed`), at most this many candidates checked, before the roadmap is
    asked. Each check is one swept-body test of a path of a few mm (~0.5 ms); the rest of the last t_x's choice is checked
    first, so a robot on its way costs one; near-equal candidates crowd the front of the list (beside a tee's stem the
    first clear one was the 125th), hence 200 when on. Measured with 200 (session 12): held-out 1x, first 31 layouts,
    145/155 against 149/155 without: it took robots along the structure near their target, where they stopped against
    it off their slot (the long roadmap detours it replaces were safer). Only a candidate's last body length may now
    come within ``gross_docked_clearance_um`` of the structure; on 9 traced held-out 1x trials that won 2 of main's
    failures (6:3, 27:0) and still lost 5 of its successes, so it stays off."""
    prefixed_extra_um: float = 3000.0
    """um. Such a path may be at most this much longer than the blocked shortest path; a longer way round is the
    roadmap's."""
    viable_step_um: float = 25.0
    """um. Spacing of the ends tried back along the clear part for one that does not box the robot in (a fifth
    of a body length)."""
    viable_checks_max: int = 40
    """Most ends tried (each up to ``len(escape_turns)`` swept-body checks): 1 mm of path back from the clear
    part's end."""
    corridor_miss_um: float = 30.0
    """um. A robot whose gross motion stopped outside the approach funnel but already *in* the approach corridor
    (:func:`~stressbots.control.queries.in_corridor`), heading for a lateral miss at the slot within this, goes
    on with the line approach instead of steering back to the funnel's aim behind it: the approach fixes such a
    miss (a left one by clockwise bursts, a right one up to ``late_miss_um`` by driving in where a loop would
    meet the structure), while the gross motion's loop back met the structure and gave up six times."""
    corridor_psi_deg: float = 12.0
    """deg. Largest heading error from the line of such a robot (the funnel's own bound on pointing left)."""


@dataclass(frozen=True)
class DockingTuning:
    """Fine motion along a slot's approach line and the push into it (seed App. 3.2, sigma_2;
    :mod:`~stressbots.control.docking`)."""

    small_miss_um: float = 12.0
    """A straight-in whose lateral miss and offset are below this is driven rather than looped (~6 um RMS)."""
    loop_back_clearance_um: float = 15.0
    """um. On the approach line, a loop back counts as blocked (the robot drives on, ``late_miss_um``) when the loop
    from where it is comes this close to the structure, a lower orbit or the arena edge: the gross motion that drives
    a loop back keeps the route clearance (15 um) near its start (``GrossTuning.gross_start_relief``). At contact
    clearance (0) loops were approved that no gross motion then drove: "no route ... 0 um clear" (held-out 12:0,
    46:1, 26:1 at 2x)."""
    late_miss_um: float = math.inf
    """A straight-in with a larger miss, up to this, is driven when a loop from where the robot is would meet the
    structure (a turning robot cannot pivot off it, and a loop back that meets the structure traps the robot: no
    route, held-out 20:2 at 1x). Driven in, it docks within the slot's 30 um tolerance or off it; 25 until session 18."""
    approach_frames: int = 80
    """Frames the fine motion along an approach line may take before it gives up."""
    aligned_um: float = 3.0
    aligned_deg: float = 1.0
    """(aligned_um, aligned_deg) On the approach line: predicted docking offset
    (:func:`~stressbots.control.docking.contact_offset`) and heading error below these need no merge."""
    aim_left_um: float = 0.0
    """A robot on its approach line aims at least this far left of its slot (see ``lead_drift_deg_per_mm``)."""
    final_run_um: float = 220.0
    """The last stretch before the slot is driven in short frames with clockwise re-aim bursts: heading drift over it
    (3.7 deg/mm at the literature's noise) moves the docking point by several um."""
    final_frame_s: float = 0.3
    """Frame length (s) of the final run: shorter than t_x, so a drift is seen while it can be corrected."""
    incidence_keep_share: float = 0.5
    """Share of a chosen incidence (``landing_incidence_*deg``) a robot keeps over its final run, so that the corner
    chosen to lead does (:func:`~stressbots.control.docking.incidence_bounds`). One to arrive turned clockwise (left
    corner first) gets a burst up to it, counting the clockwise bursts that will give back its lead; one to arrive
    turned anticlockwise takes no burst beyond it, and loops back, where a loop is clear, once past it or when that
    burst would leave it more than ``small_miss_um`` left of its aim (a one-way robot cannot turn back). Half: the
    camera's heading error at twice the literature's noise (1-2 deg filtered) then still leaves the chosen corner
    first. 0: not kept. Session 28, against 0: tuning layouts at 2x (seeds 0-1) 195/240 against 190, trials with a
    robot stuck 12 -> 7; held-out 1x 296/300 against 295 (no layout below 4/5)."""
    at_face_um: float = 5.0
    """um. A robot on its approach line within the docking tolerance of its slot is taken to be at the structure (it
    pushes, and is judged) only if it is also at most this far behind its face: short of that it still gets its look,
    its last re-aim burst and its run-in. With the 30 um tolerance alone, robots 25 um short pushed straight in on the
    heading of their last frame (session 28), and the run-in decision was made a frame earlier, 30-75 um out."""
    look_at_um: float = 30.0
    """um behind its face at which a docking robot stops and looks (``look_frames``), once per approach: its last
    re-aim burst and its run-in are decided on the sharpened estimate. Close, so that little of the heading drift's
    walk comes after it (1 deg over 30 um at twice the literature's noise, 2 um of docking offset on a 250 um robot),
    but far enough for a burst of several degrees to turn the robot before its front meets the face."""
    look_frames: int = 12
    """Camera frames read while nobody moves at ``look_at_um`` (0: no look). A moving robot's filtered heading is off by
    about 1.1 deg at twice the literature's noise, 2.5 um of docking offset; the mean of 12 still frames halves that
    (0.54 deg, position 2.2 -> 1.3 um; held-out layouts 0-59 at 2x, seed 0, against the simulator's truth). 12
    frames are 0.6 s per docking."""
    look_prior_frames: float = 3.0
    """How many frames' worth the filtered estimate counts against the look's mean (its steady state keeps about a third
    of a frame's position variance and a quarter of its heading variance)."""
    flush_look_frames: int = 48
    """Camera frames read while nobody moves once a robot has stopped at its slot, before it counts as docked (0: no
    such look): its mean heading against the body it touches (:func:`~stressbots.control.landing.contact_misalignment`)
    tells a robot turned flush by docking compliance from one stopped on a corner of the structure (failure region H),
    which stops within the docking tolerances of its slot just the same and was counted docked. On the tuning layouts
    at twice the literature's noise (seeds 0-1, 641 dockings, 24 frames) docked robots read at most 1.41 deg (99 %
    under 1.05) from their face and stuck ones 0.9-15 deg; 48 frames (2.4 s a docking) bring the look to 0.3 deg. Claimed
    successes the simulator did not dock: 6 -> 0 (with ``frame_for_approach_room``), success 211 -> 212 of 240: a robot
    on a corner is pinned (a one-way robot pushing against it can neither turn nor drive off), so the check makes the
    verdict true rather than the run successful."""
    flush_tol_deg: float = 0.25
    """deg. A stopped robot turned further than this (plus ``flush_tol_sigmas`` of its look's heading error) from the
    body it touches is not flush: it is stuck (H) and backs off. The floor covers what the camera's noise does not:
    the docked body's own heading error."""
    flush_tol_sigmas: float = 3.0
    """The look's heading error (the camera's declared heading error over the square root of the frames) allowed on top
    of ``flush_tol_deg``: at 3 a flush robot is taken for a stuck one less than once in 370 dockings (then it backs off,
    cannot leave the face, and its next push is judged again). 1.09 deg at twice the literature's noise."""
    run_in_lead_share: float = 0.0
    """Share of the aim's lead left of the slot (``aim_left_um`` .. ``blocked_walk_sigmas``) kept at the run-in, the
    approach's last decision, by all but right-first landings (:func:`~stressbots.control.docking.aim_lead`). The lead
    is room for later clockwise bursts to take back; after the run-in there are none, so a lead kept there is a bias:
    at 1 robots that took a burst docked 4.7 um left of their slots on average (held-out 2x, seeds 0-1)."""
    reaim_tol_um: float = 1.0
    """In the final run, a predicted offset further left than this is corrected by a clockwise burst."""
    lead_drift_deg_per_mm: float = 2.0
    """On its approach line a robot aims left of its slot by what a clockwise heading drift of this much would add
    before it docks (:func:`~stressbots.control.docking.lead_um`): a drift to the right then carries it onto the
    slot, one to the left is corrected by a clockwise burst (about half the literature's 3.7 deg/mm: the random part
    of the drift goes either way)."""
    drift_turn_max_deg: float = 0.0
    """deg. Frames in which a robot turned at most this much before or after driving straight identify its heading
    drift's bias too, less the turn (:class:`~stressbots.control.straight_drift.StraightDrift`'s turn-corrected runs;
    0: all-straight frames only). Gross motion starts nearly every t_x with a short turn, so robots that waited on
    their orbits reached their slots with the bias unidentified (robots of 9-11 deg/mm identified under 1 docked 20-45
    um right of their slots at 2x). At 6 the bias is identified (18:1's 9.0 deg/mm as 9.2) and the shape error's median
    falls 5 % at 2x, but the success rates did not follow: held-out 2x 433/480 against 434 (seeds 0-7), 1x 298/300
    against 299, the tuning set 234/240 against 236, the independent plant 112/120 against 115 (session 23): off."""
    aim_heading_sigma_deg: float = 0.6
    """The aim also leads left by the docking offset a heading estimate error of this much would cause, ``(behind +
    L/2) sigma``: far out, a re-aim burst overshoots by about that much (camera: 1 deg per frame, filtered), and
    only what ends up left is fixed later."""
    reaim_max_deg: float = 4.0
    """Largest single clockwise re-aim burst (a larger one means the robot is not on its line)."""
    blocked_reaim_max_deg: float = 20.0
    """Largest re-aim burst of a robot too far left for ``reaim_max_deg`` that can neither merge nor loop back (a
    loop would meet the structure): the whole turn its predicted offset needs, up to this (well inside the 45 deg
    sticking cone). Capped at ``reaim_max_deg``, a robot 13 deg left of its line whose heading drifted 2 deg left
    per frame gained 2 deg a frame and docked 99 um left of its slot, pinned (held-out 19:0 at 2x)."""
    final_right_um: float = 6.0
    """In the final run, a predicted offset further right than this loops back when a loop is clear (a one-way robot
    cannot turn left; a robot that docks off its slot cannot leave it)."""
    miss_relax_um: float = 5.0
    """After each miss of the same robot, the offsets its approach accepts without looping back grow by this much (and
    its largest re-aim burst by ``reaim_max_deg``): precision first, then docking at all."""
    settle_frames: int = 6
    """Push frames after the run in, waiting for the robot to stop."""
    settle_fraction: float = 0.2
    """A pushing robot that moved less than this fraction of a frame's nominal travel has stopped."""
    flush_um: float = 15.0
    """A robot stopped within this of its slot's face line, heading within the docking tolerance, is flush against the
    face it was to dock on."""
    off_slot_um: float = 90.0
    """... and counts as docked off its slot up to this far along the face: its front touches the structure, so it can
    neither turn (every front point moves forward) nor reverse; recovery is impossible."""
    landing_left_margin_um: float = 7.0
    """A docking robot's left front corner should land at least this far (um) inside the face its slot rests on
    (:func:`~stressbots.control.landing.landing_pose`): docking compliance turns a robot flush only about a front
    corner on a structure edge, which corner leads depends on how the robot arrives turned (either way, measured),
    and a docked robot sits a few um off its own slot, so the face under a later slot is not where the plan put it.
    The line approach aims left of the slot (:func:`~stressbots.control.docking.aim_lead`), so its landings spread
    further left: measured on an independent plant at the literature's noise, 5 % landed more than 7.1 um left of
    their aim, 5 % more than 2.3 um right."""
    landing_right_margin_um: float = 4.5
    """The same for the right front corner (um). On the SPEC-strict simulator (tuning layouts 0-119, seed 0, literature
    noise) landings aimed with both corners on the face arrived 2.5 um left of their aim on average, 5 % more than
    4.3 um right: with 3 um, two right corners landed past the end of their face (tuning 68:1, 97:1)."""
    landing_lead_left_margin_um: float = 10.5
    """The left front corner's margin (um) when it is to lead alone (a chosen incidence, clockwise): it is then the only
    contact, placed by the least shift right at its margin, and every landing error further left sticks the robot on
    the face's corner for good. The landings spread left of their aim (``aim_lead``): measured on the SPEC-strict
    simulator at the literature's noise (tuning layouts 0-119, seed 0), left-first landings arrived 3.0 um left of their
    aim on average, 1 % more than 8.7 um left, and with the 7 um of ``landing_left_margin_um`` 11 of 82 stuck on the
    face's corner."""
    landing_lead_right_margin_um: float = 7.5
    """The same for the right front corner leading alone (a chosen incidence, anticlockwise), um: its landings spread
    less far right (1 % more than 6.4 um right of their aim, same measurement), but with the 3 um of
    ``landing_right_margin_um`` the right-first landings the wider left margin brings stuck in 6 of the 120 trials."""
    landing_min_margin_um: float = 1.0
    """The least margin (um) a landing corner keeps whatever the declared noise (the margins above scale with it): a
    robot within ``reaim_tol_um`` of its aim takes no burst, so even without noise it docks up to that far off. With
    none, a robot as wide as the face it docks on aimed its corners at the face's very ends, and once the run-in
    dropped its lead (``run_in_lead_share``) the noiseless example's B met D's corner with its own and stuck."""
    landing_incidence_deg: float = 4.0
    """The chosen incidence (deg) of a robot whose face has room for one leading corner only: it arrives turned this
    much, so that the corner that leads is known. Twice the spread of the incidence at contact measured on an
    independent plant (quartiles +-1.1 deg): the other corner then leads in about 2 % of dockings."""
    landing_incidence_anticlockwise_deg: float = 6.0
    """The chosen incidence (deg) of a robot whose right corner is to lead: it arrives turned this much anticlockwise.
    More than ``landing_incidence_deg`` because the approach's only corrections are clockwise bursts, which eat an
    anticlockwise turn: measured on the SPEC-strict simulator (tuning layouts 0-119, seed 0, literature noise), 4 deg
    chosen either way arrived at +4.5 (1 % below +0.8) clockwise but -3.6 (5 % above -0.2, the wrong corner then
    leads) anticlockwise."""
    landing_incidence_cost_um: float = 3.0
    """What a chosen incidence counts as (um of shift) when choosing between it and moving the slot: the turned
    approach lands its leading corner as precisely, but it is a second manoeuvre the gross motion's funnel was not
    aimed for, and its compliance turn sweeps 4 deg of body."""
    landing_level_tol_um: float = 2.0
    """Parts of the structure within this (um) of the face's level under the slot are the face; anything standing
    further out in the robot's span blocks it. It covers the measured docked bodies' tilt (a 1 deg heading error is
    1.2 um across a 70 um rear edge)."""
    landing_step_um: float = 0.02
    """A jump of the face by more than this (um) between neighbouring samples (0.25 um apart) is a step, not a
    measured tilt (a body measured 4 deg off tilts its face by under 0.02 um per sample). A corner that lands on a
    step's inner side and turns flush meets it; an independent plant stops such a rotation at the first overlap,
    however slight (the sides of a G_1 pair 0.2 um apart in width blocked it 4 deg short of flush, tuning 6:0). The G_1
    pair's members are placed collinear and flush as self-alignment leaves them
    (:func:`~stressbots.control.landing.aligned_pair`), so the step between the sides of two widths is exact."""
    landing_max_shift_um: float = 10.0
    """The largest move (um) of a slot along its face for its corners' landing: about the shape tolerance (10 um
    RMS), beyond which a shifted slot costs more than a corner on the face's end risks."""
    aim_walk_sigmas: float = 1.0
    """Standard deviations of the heading drift's random walk (:func:`~stressbots.control.docking.walk_lead_um`)
    a robot on its approach line aims left of its slot by, on top of ``lead_drift_deg_per_mm`` and
    ``aim_heading_sigma_deg``. The walk is the part of the drift nobody predicts, and its docking offset
    grows with the declared noise (sd 4.6 um from 200 um out at the literature's figure, 9 um at 2x): at 2x,
    robots docked 10-25 um right of their slots, an offset a one-way robot cannot take back."""
    blocked_walk_sigmas: float = 1.5
    """Standard deviations added to ``aim_walk_sigmas`` while a loop back from where the robot is would meet the
    structure, a lower orbit or the arena edge: a miss to the right is then driven in (``late_miss_um``) or traps the
    robot, while a miss to the left still costs only a clockwise burst, and with the look before the run-in
    (``look_frames``) and bursts solved on their arc a precise one. Session 29, tuning layouts 0-119 at 2x (seed 0):
    robots that docked more than 15 um right of their slots 9 -> 3 and more than 10 um off either way 24 -> 16, against
    0 with the look. Before the look (session 18) 1 scored within the noise of 0."""


@dataclass(frozen=True)
class ParkingTuning:
    """Robots waiting on their orbits: watching, parking and moving them off a docking robot's way
    (:mod:`~stressbots.control.parking`)."""

    orbit_watch_um: float = 10.0
    """An orbit closer than this to another orbit, a docked body or the arena edge is logged."""
    park_margin_um: float = 40.0
    """Before each docking phase, a waiting orbit closer than this to the arena edge, the structure or another orbit is
    moved away (:mod:`~stressbots.control.parking`): orbits drift with the heading noise, and one that reaches an
    obstacle traps its robot."""
    park_shift_um: float = 150.0
    """How far such an orbit is moved."""
    park_keeps_others: bool = True
    """Whether a park move must leave every other mover's orbit at least the margin that called for it from trouble (or
    no closer, if closer already: :func:`~stressbots.control.parking.park_move`'s ``keep_um``); off: only the transit
    clearance ``park_clearance_um``."""
    park_short_shifts_um: tuple[float, ...] = (100.0, 60.0)
    """um. Shorter park moves tried, in turn, when no clear move shifts an orbit ``park_shift_um``: the other movers'
    straights are as short, and a shorter move that gains half its length still buys the orbit time to drift."""
    park_moves_per_phase: int = 3
    """Park moves of one waiting orbit per docking phase. Orbits keep drifting after a move: at twice the literature's
    noise, orbits moved once 150 um away drifted back into the arena edge within the same (200-300 s) phase and
    trapped their robots, which then failed every docking attempt."""
    park_progress_um: float = 20.0
    """um. A park move that widened its orbit's gap by less than this did not help (the robot is held): it is the
    last of its phase."""
    park_replans_after_wait: int = 1
    """Times a park move whose straight, checked again after its wait from the measured poses, is not clear is planned
    again from there (another wait, another heading) before it is refused. At 2x the literature's noise the start-up
    parks were refused this way (the other movers' headings predicted from little motion) and those orbits drifted
    into the arena edge during G_1 (held-out 10:0, 10:3, 32:0 at 2x)."""
    park_retry_drift_um: float = math.inf
    """um. A park move refused after its wait (the straight, checked again from the measured poses, was not clear) is
    tried again in the same phase once its orbit's gap shrank this much more: the poses then differ (inf: never again in
    the phase). Refusing it for the whole phase let orbits refused 70-90 um from trouble at t = 0 drift into the arena
    edge during G_1 and trap their robots at their start; with 20 um (and ``tend_during_rendezvous``) see there; alone,
    tuning 2x 83/120 against 84."""
    park_clearance_um: float = 25.0
    """Clearance every robot driving straight during that move keeps (or, if closer already, does not lose)."""
    unblock_margin_um: float = 30.0
    """um. A waiting orbit whose disc comes within (half body diagonal + ``ControllerOptions.clearance_um``) of a
    docking robot's aim, approach corridor or (after a blocked attempt) its path is moved until it is this
    much further: a disc over the aim left no route at all, and every retry hit the same disc."""
    unblock_max_shift_um: float = 600.0
    """um. Longest straight move of such an orbit (one wait and one straight drive of the waiting group)."""
    unblock_moves_per_phase: int = 2
    """Moves of one waiting orbit per docking phase: a move that did not free the way is not repeated forever."""
    unblock_extra_loops: int = 2
    """Extra loops of the waiting robot an orbit move may wait before its straight: the robots driving straight with it
    (D_j .. D_k, turning at their own rates) then head elsewhere, and a move that ran one of them into the arena
    edge or another orbit may find a clear set of tracks."""
    unblock_heading_tol_deg: float = 15.0
    """deg. After its wait, a waiting robot more than this off its planned departure heading does not drive the
    straight: it was held (touched by the docking robot, it cannot turn) and would leave in a direction nobody
    checked (one ran its orbit 137 um into the arena edge so)."""
    start_park_margin_um: float = 100.0
    """um. Before G_1 (t = 0), waiting orbits closer than this to the arena edge, the structure or another orbit
    are moved away (:mod:`~stressbots.control.parking`): until session 21 nothing tended them during the G_1 phase, and an orbit
    64 um from the edge at t = 0 was 6 um from it at 52 s and trapped by 96 s. Wider than ``park_margin_um`` by
    the drift of one G_1 phase."""


@dataclass(frozen=True)
class Tuning(PairTuning, GrossTuning, DockingTuning, ParkingTuning):
    """Thresholds of the closed loop (seed App. 3), each a named field with its units and reason.

    One frozen dataclass with every field of its phases' groups (:class:`PairTuning`, :class:`GrossTuning`,
    :class:`DockingTuning`, :class:`ParkingTuning`): ``Tuning().pair_frames``, ``replace(t, dock_attempts=3)``.
    Angles in deg and lengths in um unless the name says; ``t_x`` is the control period.
    """


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
    frame_interval_s, frames_per_step:
        Each step list (a t_x of gross motion, a 0.3 s frame of a final run) ends with ``frames_per_step`` camera
        frames ``frame_interval_s`` s of driving apart, all taken in by the pose filter (it is played in pieces,
        :func:`~stressbots.control.loop.frame_pieces`); decisions stay once per step list. The estimate a decision
        reads rests on the last few frames (the filter's heading gain 0.35 forgets a frame's weight in ~4 frames), so
        a few frames 0.05 s apart at its end give what ten through it would: on held-out 2x seeds 0-3 three scored
        197/240 and five 196/240, at 1.7 s and 3.5 s per example assembly (one frame: 1.2 s). At twice the
        literature's noise one frame per t_x left headings 3-5 deg off on final runs (one camera frame reads 2 deg off,
        the drift's walk turns a robot several deg in 200 um) and robots docked 28 um off their slots. Heading error at
        decision time (orbit-and-straight robots against the simulator's truth): 2x 1.75 deg with one frame, 1.28 with
        three, 1.10 with five; 1x 1.10, 0.52, 0.44. Held-out 2x: 197/240 against 180. None or 1: one frame per step
        list. A real camera streams frames; this sets how many the controller uses (and how often a lab plant's
        waveform is cut).
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
    frame_interval_s: float | None = 0.05
    frames_per_step: int = 3
    tuning: Tuning = field(default_factory=Tuning)
