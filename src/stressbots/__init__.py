"""stressbots: planning and control for groups of MEMS microrobots that share one global voltage signal.

Modules, by concept (see ``docs/design.md``):

- :mod:`stressbots.robots` - poses, robot parameters, body geometry
- :mod:`stressbots.scenario` - scenario files (TOML) and their validation
- :mod:`stressbots.errors` - the user-facing errors (one ``error:`` line, exit 2)
- :mod:`stressbots.outputs` - atomic output files and provenance (seed, versions)
- :mod:`stressbots.electrostatics` - arm hysteresis, accessible control states, STRING, primitives
- :mod:`stressbots.waveform` - Hold/Drive segments, synthesis, decoding, sampling
- :mod:`stressbots.design` - STRING voltage design and its fabrication yield
- :mod:`stressbots.kinematics` - closed-form motion along straight segments and clockwise arcs
- :mod:`stressbots.paths` - exact shortest paths for a robot that turns one way only
- :mod:`stressbots.structures` - target structures: slots, contact geometry, named shapes
- :mod:`stressbots.collision` - body/body, body/disc and arena tests shared by planner, replay and controller
- :mod:`stressbots.plans` - plans and the plan.json format
- :mod:`stressbots.planning` - the nominal n-robot assembly planner (seed Appendix 2)
- :mod:`stressbots.replay` - independent replay verification of plans
- :mod:`stressbots.generate` - random feasible scenarios for tests and benchmarks
- :mod:`stressbots.sim` - the simulated plant: control error, contact, compliance, camera
- :mod:`stressbots.drift` - heading drift as a per-robot process of the distance driven
- :mod:`stressbots.assessment` - placement and shape errors after a best rigid alignment
- :mod:`stressbots.control` - the Plant protocol and the closed-loop EDR controller (seed Appendix 3; :mod:`stressbots.edr` re-exports it)
- :mod:`stressbots.strategies` - the selectable closed-loop strategies (``rendezvous``, ``seed``)
- :mod:`stressbots.seed_strategy` - the paper's two-step EDR strategy as written (with ``seed_loop``, ``seed_pair``, ``seed_fine_motion``)
- :mod:`stressbots.se2` - rigid transforms of the plane
- :mod:`stressbots.bounds` - error bounds, forward projections, regions A_i*
- :mod:`stressbots.montecarlo` - Monte Carlo studies of closed-loop assembly
- :mod:`stressbots.trial` - one closed-loop trial of a campaign and its seed
- :mod:`stressbots.store` - the trial store of a campaign (DIR/trials.sqlite)
- :mod:`stressbots.campaign` - cells x paired trials, run in-process, on a process pool or on Dask
- :mod:`stressbots.study` - study files: a grid of conditions over layouts
- :mod:`stressbots.studyreport` - the HTML report of a study
- :mod:`stressbots.tracking` - robot poses from camera frames (SPEC 9.2)
- :mod:`stressbots.lab` - lab hardware: waveform generator, synthetic camera, image-in-the-loop plants
- :mod:`stressbots.viz` - pictures
- :mod:`stressbots.console` - terminal rendering (rich) of the command line
- :mod:`stressbots.demo` - the main job on the built-in scenario
- :mod:`stressbots.cli` - the command line
"""

__version__ = "0.1.0"
