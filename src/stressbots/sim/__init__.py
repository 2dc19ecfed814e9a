"""The simulated plant: robots with control error, contact and compliance, seen through a noisy camera.

:class:`SimulatedPlant` implements :class:`stressbots.control.Plant`. It stands in for the lab: a
waveform is decoded by the hysteresis model (:func:`stressbots.waveform.replay`, the one source of
truth for arm states), the robots move by the closed-form kinematics (:func:`stressbots.kinematics.move`)
with the scenario's ``[noise]``, bodies never interpenetrate, and the seed's compliance (App. 3.5)
turns near misses into docked robots while larger errors leave robots stuck (failure region H).

Motion (per Drive of the waveform)
----------------------------------
Holds move nobody. During a Drive every robot drives forward at its speed on an arc of constant
curvature: ``kappa = 1/r`` with its arm down, 0 with its arm up, ``1/(2 r)`` for an arm the drive band
makes chatter (it turns every other cycle: an interpolated turn of mean radius 2r), plus its heading
drift, a curvature that is piecewise constant between the knots of the robot's odometer (below). Between
contacts and knots the motion is the closed form, so with all noise zero the simulator reproduces
:func:`stressbots.kinematics.advance` exactly (to rounding, no integration error).

Noise model (``scenario.noise``; all draws from the seed, see *Determinism*)
---------------------------------------------------------------------------
- per robot and run: speed factor ``1 + speed_rel_sd * z`` and radius factor ``1 + turn_radius_rel_sd * z``
  (z standard normal; floored at 0.1);
- per robot and Drive: the same factors jittered by :data:`SEGMENT_JITTER` times those sds
  ("small per-segment variation");
- per robot, as a function of its odometer (distance driven, :attr:`SimulatedPlant.odometer`): heading
  drift (:mod:`stressbots.drift`), a bias drawn once per run plus a random walk whose variance grows with
  the distance driven, realised as a curvature constant between odometer knots every
  :attr:`~stressbots.drift.DriftModel.knot_um` (25 um). The spread after 1 mm has sd
  ``heading_drift_deg_per_mm`` however the millimetre is cut into Drives (the same seed even gives the
  same drift, to rounding); the odometer advances only while a robot drives (not while it is held,
  slides past a corner or is turned by compliance);
- camera (:meth:`SimulatedPlant.observe`): position N(0, sd) per axis, heading N(0, sd), and each robot
  missing (NaN row) with probability ``camera_dropout``.

Contact (bodies never interpenetrate)
-------------------------------------
A broad phase first checks whether any two bodies (or a body and the arena edge) could come within
:data:`~.bodies.NEAR_UM` during the Drive (bounding circles grown by each body's largest travel); if not, the
Drive is one closed-form step. Otherwise the first contact is found by sampling the motion every
:data:`~.bodies.SAMPLE_UM` of relative travel, a Lipschitz bound on the separating-axis gap between samples (so
no contact between samples is missed), finer sampling of doubtful intervals and a 16-way bisection
down to ~1e-10 um of travel. At that instant everyone stops, the rules below are applied, and the rest
of the Drive continues. A contact is interpenetration beyond :data:`~.bodies.CONTACT_TOL_UM` (1e-9 um); a pair
already touching whose motion does not push may graze by up to :data:`~.bodies.GRAZE_TOL_UM` (1e-4 um). A
robot's motion *pushes* into a touching body (or the arena edge) when moving it alone by
:data:`~.bodies.PROBE_UM` deepens the contact by more than :data:`~.bodies.PUSH_EPS_UM`. Rules, for every robot whose
motion pushes (also applied at the end of every Drive, so a contact made on its last instant counts):

1. **Self-aligning compliance (G_1).** Two robots with arms up, neither docked, meeting head-on:
   headings opposed, closing on each other (at least one pushes), every contact point in the front half
   of both bodies (front edges against each other, corner to corner, or a front corner on the other's
   long side near its front). With incidence ``alpha = theta_i - theta_j - pi`` (wrapped) and lateral
   misalignment ``w_y`` (offset of the two front-edge centres across the meeting axis, the bisector of
   the two headings), if ``|alpha| < 60 deg`` and ``|w_y| < 80 um`` they form G_1 (seed App. 3.5: also
   when ``w_y`` exceeds the width, so that only a corner meets the other's side): both turn to the mean
   axis (each by alpha/2, so the pair rotates as a whole) and slide until their front-edge midpoints
   coincide at the midpoint of the two, collinear and flush. Both are docked. A front corner that reaches
   the rear half of the other's side is a sideswipe, not a meeting: rule 5, they slide past.
   Outside those limits, or if the aligned pair would overlap a third body or leave the arena, both stop
   where they met: stuck (H).
2. **Turning robot** (arm down or chattering) whose motion pushes into anything: blocked; it stops for
   the rest of the Drive (it pivots on its stylus and cannot pivot off an obstacle). If its front edge is
   flush against a docked body (it arrived in its slot on an arc), it is **docked** there: arriving flush
   against the structure is docking, with or without a straight push afterwards (SPEC 6).
3. **Arena edge**: a robot pushing out of the arena stops at the edge ("arena"; ``arena_hits``).
4. **Straight robot (arm up) against a static body** (one that does not move now: docked, stopped or
   stuck), contact on its front (its front corner on a face, the body's corner on its front edge, or
   the front edge flush). The face met is the body's face the contact lies on; at a corner of the body
   (two faces) the one the contact is not behind, and of equals the one most opposed to the robot's
   heading. ``alpha`` is the signed angle between the robot's heading and that face's inward normal.

   - **Docking compliance** needs all that SPEC 6 names: the body is part of the structure (docked: a
     G_1 member or a docked robot), ``|alpha| <= 45 deg`` (the sticking cone) and a *front corner* of the
     robot on the face (or its front edge already flush). It rotates about the contact point (the
     touching corner(s)) until its front edge is flush with the face, then stays there pushing: docked.
     If the rotation would sweep into another body it stops at first touch: stuck (H).
   - Otherwise it is **stuck** (H) where it met the body: a front corner outside the cone (it neither
     turns nor slides), the body's corner on its front edge, or any front contact with a robot that is
     not docked (a stopped or stuck robot is no structure to dock on).
   - a body's corner touching its long side: it slides past it, straight, without turning ("graze").
   - pushing into several static bodies at once: it stops; docked if flush with a docked one.
5. Any other pushing contact (e.g. into a robot that is itself moving): the pushing robot stops
   ("contact"); it is re-checked every :data:`~.bodies.RECHECK_S` while its partner moves.

A stopped robot is re-examined after every contact and at every later Drive: it moves again as soon as
its motion no longer pushes. ``docked`` and ``stuck`` clear when it moves. Compliance moves are
instantaneous. An event is logged when a contact's outcome changes; outcomes are remembered while the
pair stays within :data:`~.bodies.NEAR_UM`, so robots jostling against each other do not flood the log.

Determinism
-----------
Everything random comes from ``np.random.SeedSequence(seed)``, spawned into independent streams for
the per-run factors, the per-Drive jitter, the camera (so observing more or less often never changes
the motion) and the drift (one child stream per robot, knot values drawn in knot order). The same seed
and the same calls give bit-identical results; :meth:`SimulatedPlant.copy` continues bit-identically;
:func:`check_determinism` proves it.

Modules
-------
- :mod:`.bodies`: the bodies' shared state (poses, odometers, flags, event log), geometry kernels, tolerances;
- :mod:`.search`: motion between contacts (closed form, drift) and the first-contact search;
- :mod:`.contact`: the contact rules applied at each contact instant (touch graph, outcomes, memory);
- :mod:`.compliance`: docking compliance, grazes and self-aligning compliance (G_1), seed App. 3.5;
- :mod:`.plant`: :class:`SimulatedPlant`, the noise streams and one Drive at a time;
- :mod:`.runs`: a plan's waveform, open-loop runs, :func:`check_determinism`.
"""

from __future__ import annotations

from .bodies import (
    SELF_ALIGN_MAX_INCIDENCE_RAD,
    SELF_ALIGN_MAX_OFFSET_UM,
    STICKING_CONE_RAD,
    SimEvent,
)
from .plant import SEGMENT_JITTER, SimulatedPlant
from .runs import check_determinism, plan_waveform, run_plan

__all__ = [
    "SimEvent",
    "SimulatedPlant",
    "check_determinism",
    "plan_waveform",
    "run_plan",
    "STICKING_CONE_RAD",
    "SELF_ALIGN_MAX_INCIDENCE_RAD",
    "SELF_ALIGN_MAX_OFFSET_UM",
    "SEGMENT_JITTER",
]
