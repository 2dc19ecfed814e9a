"""Plants written for the tests (shared by the closed-loop test modules)."""

from __future__ import annotations


class ProtocolOnly:
    """A plant that offers nothing but ``observe`` and ``apply`` (no truth for the controller to peek at)."""

    def __init__(self, inner):
        self._inner = inner

    def observe(self):
        return self._inner.observe()

    def apply(self, waveform):
        self._inner.apply(waveform)
