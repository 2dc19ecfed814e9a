"""stressbots: planning and control for groups of MEMS microrobots that share one global voltage signal.

Modules, by concept (see ``docs/design.md``):

- :mod:`stressbots.robots` - poses, robot parameters, body geometry
- :mod:`stressbots.scenario` - scenario files (TOML) and their validation
- :mod:`stressbots.electrostatics` - arm hysteresis, accessible control states, STRING, primitives
- :mod:`stressbots.waveform` - Hold/Drive segments, synthesis, decoding, sampling
- :mod:`stressbots.design` - STRING voltage design and its fabrication yield
- :mod:`stressbots.kinematics` - closed-form motion along straight segments and clockwise arcs
- :mod:`stressbots.paths` - exact shortest paths for a robot that turns one way only
- :mod:`stressbots.structures` - target structures: slots, contact geometry, named shapes
- :mod:`stressbots.planning` - the nominal n-robot assembly planner (seed Appendix 2)
- :mod:`stressbots.sim` - the simulated plant: control error, contact, compliance, camera
- :mod:`stressbots.control` - the Plant protocol and closed-loop EDR assembly (seed Appendix 3)
- :mod:`stressbots.bounds` - error bounds and forward projections
- :mod:`stressbots.viz` - pictures and animations
- :mod:`stressbots.cli` - the command line
"""

__version__ = "0.1.0"
