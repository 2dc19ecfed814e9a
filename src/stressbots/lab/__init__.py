"""Lab hardware (SPEC 9): the waveform generator, the camera, and plants with an image in the loop.

- :mod:`stressbots.lab.awg` - compile a waveform to the generator's DAC codes, export and upload it;
- :mod:`stressbots.lab.camera` - the synthetic camera: renders poses by the SPEC 9.2 image model;
- :mod:`stressbots.lab.plants` - :class:`SyntheticLab` (simulator seen through rendered frames) and
  :class:`HardwarePlant` (generator + camera).

The optional packages of the ``[lab]`` extra (pyvisa, pyvisa-sim, opencv-python-headless) are imported
only inside the functions that need them; this package imports without them.
"""

from __future__ import annotations

from typing import Any

__all__ = ["SyntheticLab", "HardwarePlant"]


def __getattr__(name: str) -> Any:
    if name in ("SyntheticLab", "HardwarePlant"):
        from . import plants

        return getattr(plants, name)
    raise AttributeError(f"module 'stressbots.lab' has no attribute {name!r}")
