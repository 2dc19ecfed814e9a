"""Plants for the lab (SPEC 9.2): SyntheticLab (image in the loop) and HardwarePlant (with fakes)."""

from __future__ import annotations

import numpy as np
import pytest

from stressbots.generate import LITERATURE_NOISE, random_scenario

pytest.importorskip("cv2")

from stressbots.control import Plant, assemble  # noqa: E402
from stressbots.lab import HardwarePlant, SyntheticLab  # noqa: E402
from stressbots.lab.awg import compile_awg  # noqa: E402
from stressbots.lab.camera import Camera, ImageModel  # noqa: E402
from stressbots.tracking import Calibration  # noqa: E402
from stressbots.waveform import synthesize  # noqa: E402
from tests.test_awg import RecordingInstrument  # noqa: E402


def _is_plant(obj: object) -> bool:
    """The runtime protocol check, kept out of the test's flow so that ``isinstance`` does not narrow the
    lab object to ``Plant`` (the tests go on to use its lab-only attributes)."""
    return isinstance(obj, Plant)


@pytest.fixture(scope="module")
def pair():
    return random_scenario(2, seed=1, shape="pair", noise=LITERATURE_NOISE)


def test_synthetic_lab_observes_through_frames(pair):
    lab = SyntheticLab(pair, seed=3, um_per_px=4.0, keep_frames=2)
    assert _is_plant(lab)
    obs = lab.observe()
    true = lab.true_poses()
    assert np.all(np.hypot(*(obs[:, :2] - true[:, :2]).T) < 3.0)
    assert np.all(np.abs((obs[:, 2] - true[:, 2] + np.pi) % (2 * np.pi) - np.pi) < np.radians(2.0))
    # same seed, same frames, same observations (bit-identical)
    again = SyntheticLab(pair, seed=3, um_per_px=4.0)
    assert np.array_equal(again.observe(), obs)
    assert lab.frames[0].frame.shape == lab.camera.shape and lab.frames[0].index == 0


def test_image_in_the_loop_assembles_like_the_pose_camera(pair):
    lab = SyntheticLab(pair, seed=1, um_per_px=4.0)
    res = assemble(pair, lab, seed=1)
    assert res.success, res.failure
    assert lab.frames_observed > 5
    # the result's final poses are the simulator's truth, and the tracker saw them within a few um
    final = lab.true_poses()
    assert res.final_true is not None and np.allclose(res.final_true, final)
    assert np.all(np.hypot(*(lab.observe()[:, :2] - final[:, :2]).T) < 3.0)


class FakeCamera:
    """A camera whose ``grab`` renders the poses it is told."""

    def __init__(self, scenario, cal, shape):
        self.scenario, self.poses = scenario, scenario.starts.copy()
        self.cam = Camera(cal, shape, ImageModel())
        self.rng = np.random.default_rng(0)

    def grab(self):
        return self.cam.render(self.poses, self.scenario.lengths_um, self.scenario.widths_um, self.rng)


def test_hardware_plant_uploads_plays_and_tracks(pair):
    from stressbots.electrostatics import analyse_scenario

    cal = Calibration(4.0, (0.0, 750.0))
    cam = FakeCamera(pair, cal, (750, 750))
    awg = RecordingInstrument()
    waits: list[float] = []
    hw = HardwarePlant(pair, awg, cam, cal, gain=20.0, sample_rate_hz=50_000.0, sleep=waits.append)
    assert _is_plant(hw)
    a = analyse_scenario(pair)
    wf1 = synthesize(a, [("P1", 0.002)])
    hw.apply(wf1)
    msgs = [m for _, m in awg.log]
    prog = compile_awg(wf1, pair.electrodes, gain=20.0, sample_rate_hz=50_000.0)
    raw = next(m for k, m in awg.log if k == "write_raw")
    assert raw.endswith(prog.codes.astype("<i2").tobytes() + b"\n")  # exactly the compiled codes
    i_on, i_trg, i_off = msgs.index("OUTP1 ON"), msgs.index("*TRG"), msgs.index("OUTP1 OFF")
    assert msgs.index("SOUR1:BURS:NCYC 1") < i_on < i_trg < i_off == len(msgs) - 1
    assert waits == [pytest.approx(prog.duration_s)]
    assert hw.arm_states.tolist() == list(a.primitive("P1").state)
    # the next waveform starts by restoring the arm state P1 left (the output was off: 0 V, all arms up)
    awg.log.clear()
    wf2 = synthesize(a, [("P1", 0.002)], initial=hw.arm_states)
    hw.apply(wf2)
    prog2 = compile_awg(hw.restore() + tuple(wf2), pair.electrodes, gain=20.0, sample_rate_hz=50_000.0)
    raw2 = next(m for k, m in awg.log if k == "write_raw")
    assert raw2.endswith(prog2.codes.astype("<i2").tobytes() + b"\n") and len(hw.restore()) >= 1
    obs = hw.observe()
    assert np.all(np.hypot(*(obs[:, :2] - cam.poses[:, :2]).T) < 3.0)


def test_hardware_plant_refuses_before_touching_the_generator(pair):
    from stressbots.lab.awg import AwgError
    from stressbots.waveform import Hold

    awg = RecordingInstrument()
    hw = HardwarePlant(pair, awg, None, Calibration(4.0), gain=5.0)  # 5 x 10 V: 150 V is out of the generator's range
    with pytest.raises(AwgError):
        hw.apply([Hold(150.0, 0.001)])
    assert awg.log == []


def test_cli_simulate_with_images(run_cli, tmp_path, pair):
    import json

    from stressbots.scenario import to_toml

    path = tmp_path / "pair.toml"
    path.write_text(to_toml(pair))
    r = run_cli("simulate", path, "--seed", "1", "--out", tmp_path / "sim", "--camera", "images", "-q")
    assert r.code == 0, r.err
    doc = json.loads((tmp_path / "sim" / "result.json").read_text())
    assert doc["camera"] == "images" and doc["success"] and doc["image_camera"]["um_per_px"] == 2.0
    assert (tmp_path / "sim" / "frames.png").stat().st_size > 1000
    r = run_cli("simulate", path, "--plan", path, "--out", tmp_path / "open", "--camera", "images")
    assert r.code == 2 and "--camera" in r.err


def test_hardware_plant_without_burst_uses_only_the_spec_commands(pair):
    from stressbots.electrostatics import analyse_scenario

    awg = RecordingInstrument()
    waits: list[float] = []
    hw = HardwarePlant(pair, awg, None, Calibration(4.0), sample_rate_hz=50_000.0, sleep=waits.append, burst=False)
    hw.apply(synthesize(analyse_scenario(pair), [("P2", 0.001)]))
    msgs = [m for kind, m in awg.log if kind != "write_raw"]
    assert not any("BURS" in m or m == "*TRG" for m in msgs)
    assert msgs[-2:] == ["OUTP1 ON", "OUTP1 OFF"] and len(waits) == 1
