"""Plants for the lab (SPEC 9.2): the simulator seen through a camera, and real hardware.

Both implement :class:`stressbots.control.Plant` (``observe() -> (n, 3)``, ``apply(waveform)``), so the
closed-loop controller (:func:`stressbots.control.assemble`) runs on them unchanged.

- :class:`SyntheticLab`: a :class:`~stressbots.sim.SimulatedPlant` whose ``observe`` renders a frame of the
  true poses by the image model (:class:`~stressbots.lab.camera.Camera`) and tracks it
  (:func:`stressbots.tracking.locate`): the image is in the loop, and so is every tracking error.
- :class:`HardwarePlant`: ``apply`` compiles each waveform for the generator and plays it once
  (:func:`stressbots.lab.awg.play_once`); ``observe`` grabs a frame from the camera and tracks it.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..tracking import Calibration, TrackerSettings, locate
from .camera import Camera, ImageModel, frame_for_scenario, shape_for

__all__ = ["SyntheticLab", "HardwarePlant", "TrackedFrame", "FRAME_STREAM"]

#: Spawn key of the image stream (noise, dropouts), independent of the simulator's streams of the same seed.
FRAME_STREAM = 0x1AB


@dataclass(frozen=True, eq=False)
class TrackedFrame:
    """A frame kept for the report: when (s), the frame, the tracked and the true poses (um, rad)."""

    time_s: float
    index: int
    frame: np.ndarray
    tracked: np.ndarray
    true: np.ndarray | None
    calibration: Calibration


class _Tracker:
    """``locate`` with memory: the last pose seen of every robot is the next frame's ``previous``."""

    def __init__(self, scenario, calibration: Calibration, settings: TrackerSettings | None):
        self.scenario = scenario
        self.calibration = calibration
        self.settings = settings
        self.last = scenario.starts.copy() if scenario.has_starts else None

    def __call__(self, frame: np.ndarray) -> np.ndarray:
        poses = locate(frame, self.scenario, self.calibration, previous=self.last, settings=self.settings)
        if self.last is None:
            self.last = poses.copy()
        else:
            seen = np.all(np.isfinite(poses), axis=1)
            self.last[seen] = poses[seen]
        return poses


def _keep(index: int) -> bool:
    """Frames kept for the report: 0, 1, 2, 4, 8, ... (spread over a run of any length)."""
    return index == 0 or (index & (index - 1)) == 0


class SyntheticLab:
    """The simulated plant observed through rendered camera frames (image in the loop).

    Parameters
    ----------
    scenario:
        The scenario (robots, arena, ``[noise]``: control error and ``camera_dropout``).
    seed:
        Seed of the simulated plant and of the image noise (a separate named stream).
    calibration:
        The camera's calibration; default: ``um_per_px`` over the whole arena (:func:`frame_for_scenario`).
    um_per_px:
        Pixel size when ``calibration`` is not given.
    model:
        The image model (grey levels, noise, blur); its dropout defaults to the scenario's ``camera_dropout``.
    plant:
        An existing :class:`~stressbots.sim.SimulatedPlant` to observe (e.g. one that records its trace).
    keep_frames:
        How many frames to keep for the report (frames 0, 1, 2, 4, 8, ... and the latest).
    shape:
        Frame shape ``(rows, cols)``; default: the arena in ``calibration`` plus its margin.

    Notes
    -----
    ``true_poses`` is forwarded so that :func:`stressbots.control.assemble` reports the true final poses
    (as for the simulator); a controller must not use it.
    """

    def __init__(self, scenario, seed: int | None = None, calibration: Calibration | None = None, *, um_per_px: float = 2.0,
                 model: ImageModel | None = None, plant=None, keep_frames: int = 0, shape: tuple[int, int] | None = None,
                 tracker: TrackerSettings | None = None):
        from ..sim import SimulatedPlant

        self.scenario = scenario
        self.plant = plant if plant is not None else SimulatedPlant(scenario, seed=seed)
        self.seed = self.plant.seed
        if calibration is None:
            calibration, auto_shape = frame_for_scenario(scenario, um_per_px)
            shape = shape or auto_shape
        shape = shape or shape_for(scenario, calibration)
        if model is None:
            model = ImageModel(dropout=scenario.noise.camera_dropout)
        self.camera = Camera(calibration, shape, model)
        self.calibration = calibration
        self._rng = np.random.default_rng(np.random.SeedSequence(self.seed, spawn_key=(FRAME_STREAM,)))
        self._track = _Tracker(scenario, calibration, tracker)
        self._keep = int(keep_frames)
        self._frames: list[TrackedFrame] = []
        self._count = 0

    # -- the Plant protocol ------------------------------------------------------------------------

    def observe(self) -> np.ndarray:
        """Render a frame of the true poses, track it, return the tracked poses (NaN rows: not found)."""
        true = self.plant.true_poses()
        frame = self.camera.render(true, self.scenario.lengths_um, self.scenario.widths_um, self._rng)
        poses = self._track(frame)
        if self._keep > 0 and (_keep(self._count) or self._keep == 1):
            self._frames.append(TrackedFrame(self.plant.time_s, self._count, frame, poses.copy(), true, self.calibration))
            if len(self._frames) > self._keep:
                del self._frames[1]  # keep the first frame and the latest ones
        self._last_frame = (self._count, frame, poses.copy(), true)
        self._count += 1
        return poses

    def apply(self, waveform: Sequence[Any]) -> None:
        self.plant.apply(waveform)

    # -- outside the protocol (reports, tests) ------------------------------------------------------

    def true_poses(self) -> np.ndarray:
        return self.plant.true_poses()

    @property
    def docked(self) -> np.ndarray:
        """The simulator's docked flags: which robots its compliance docked (the run's judge asks)."""
        return self.plant.docked

    @property
    def time_s(self) -> float:
        return self.plant.time_s

    @property
    def frames(self) -> tuple[TrackedFrame, ...]:
        """Kept frames, the last frame observed included."""
        out = list(self._frames)
        last = getattr(self, "_last_frame", None)
        if self._keep > 0 and last is not None and (not out or out[-1].index != last[0]):
            out.append(TrackedFrame(self.plant.time_s, last[0], last[1], last[2], last[3], self.calibration))
        return tuple(out)

    @property
    def frames_observed(self) -> int:
        return self._count

    def describe(self) -> dict[str, Any]:
        """The camera's settings and use, for ``result.json`` (reproducing an image-in-the-loop run)."""
        from dataclasses import asdict

        return {"um_per_px": self.calibration.um_per_px, "origin_px": list(self.calibration.origin_px),
                "frame_shape": list(self.camera.shape), "image_model": asdict(self.camera.model),
                "frames_observed": self._count, "image_stream_spawn_key": FRAME_STREAM}


class HardwarePlant:
    """Lab hardware behind the Plant protocol: a waveform generator and a camera.

    Parameters
    ----------
    scenario:
        The robots (thresholds, body sizes) and electrode limits.
    awg:
        An open PyVISA resource of the generator (or anything with ``write``, ``query`` and
        ``write_binary_values``).
    camera:
        Anything with ``grab() -> ndarray`` (a 2-D grey frame).
    calibration:
        The camera's :class:`~stressbots.tracking.Calibration`.
    gain, offset_V, sample_rate_hz, awg_max_V, name:
        As for :func:`stressbots.lab.awg.compile_awg` / :func:`~stressbots.lab.awg.upload`.
    sleep:
        How to wait while a waveform plays (default :func:`time.sleep`; tests pass a fake clock).
    burst:
        Play each waveform as a triggered burst of one cycle (default); False plays it by switching the
        output on for its duration, for generators that know only the SPEC 9.1 commands
        (:func:`stressbots.lab.awg.play_once`).

    Notes
    -----
    Between waveforms the output is off, so the electrodes sit at 0 V and every arm releases. To keep
    the controller's model (arm states persist between ``apply`` calls) each waveform is preceded by the
    Holds that restore the arm state the previous one left (from all-up; robots do not move during
    Holds). The arm state is followed by replaying every waveform through the hysteresis model.
    """

    def __init__(self, scenario, awg, camera, calibration: Calibration, *, gain: float = 20.0, offset_V: float = 0.0,
                 sample_rate_hz: float = 100_000.0, awg_max_V: float = 10.0, name: str = "stressbots",
                 sleep: Callable[[float], None] | None = None, tracker: TrackerSettings | None = None, burst: bool = True):
        from ..electrostatics import analyse_scenario

        self.scenario = scenario
        self.awg = awg
        self.camera = camera
        self.calibration = calibration
        self.options: dict[str, Any] = {"gain": gain, "offset_V": offset_V, "sample_rate_hz": sample_rate_hz, "awg_max_V": awg_max_V}
        self.name = name
        self._sleep = sleep
        self._burst = bool(burst)
        self._analysis = analyse_scenario(scenario)
        self._arms = np.zeros(scenario.n, np.uint8)
        self._track = _Tracker(scenario, calibration, tracker)

    def restore(self) -> tuple[Any, ...]:
        """Holds that take the arms from all-up (0 V) to the state the last waveform left."""
        from ..electrostatics import level_sequence
        from ..waveform import Hold

        if not self._arms.any():
            return ()
        hold = self.scenario.electrodes.hold_s
        return tuple(Hold(v, hold) for v in level_sequence(self._analysis, np.zeros(self.scenario.n, np.uint8), self._arms))

    def apply(self, waveform: Sequence[Any]) -> None:
        """Compile (refusing anything unsafe before the instrument is touched), upload and play once."""
        from ..waveform import replay
        from .awg import compile_awg, play_once, scpi_number

        segs = self.restore() + tuple(waveform)
        program = compile_awg(segs, self.scenario.electrodes, **self.options)
        last = getattr(self, "_last_low", None)
        if last is not None and program.u_high <= last:
            # upload sets VOLT:HIGH before VOLT:LOW (SPEC 9.1); a HIGH below the current LOW would be a settings
            # conflict on the instrument, so lower LOW first (the output is off here)
            self.awg.write(f"SOUR1:VOLT:LOW {scpi_number(program.u_low)}")
        play_once(program, self.awg, name=self.name, sleep=self._sleep, burst=self._burst)
        self._last_low = program.u_low
        self._arms = np.asarray(replay(segs, self.scenario.snap_down_V, self.scenario.release_V).final, np.uint8)

    def observe(self) -> np.ndarray:
        """Grab a frame and track it."""
        return self._track(np.asarray(self.camera.grab()))

    @property
    def arm_states(self) -> np.ndarray:
        """The arm state the last waveform left (1 = down), from the hysteresis model."""
        return self._arms.copy()
