"""SimulatedPlant(log_drives=True): the truth at the end of every Drive, without changing the motion."""

from __future__ import annotations

import numpy as np
import pytest

from stressbots.generate import LITERATURE_NOISE
from stressbots.sim import SimulatedPlant
from stressbots.waveform import Drive, replay

from .test_sim import FAR, far_scenario


def _waveform(plant_scn):
    from stressbots.electrostatics import analyse_scenario
    from stressbots.waveform import synthesize

    analysis = analyse_scenario(plant_scn)
    steps = [("P2", 1.5), ("P0", 0.7), ("P4", 2.0), ("P1", 0.4), ("P3", 1.1)]
    return synthesize(analysis, steps)


def test_drive_log_records_every_drive_end_and_changes_nothing():
    scn = far_scenario(FAR, noise=LITERATURE_NOISE)
    wf = _waveform(scn)
    plain, logged = SimulatedPlant(scn, seed=7), SimulatedPlant(scn, seed=7, log_drives=True)
    for p in (plain, logged):
        p.apply(wf[:4])
        p.apply(wf[4:])
    assert np.array_equal(plain.true_poses(), logged.true_poses()) and plain.time_s == logged.time_s
    t, turning, poses = logged.drive_log()
    dec = replay(tuple(wf), scn.snap_down_V, scn.release_V)
    drives = list(dec.drives)
    assert len(t) == len(drives) == sum(isinstance(s, Drive) for s in wf)
    assert np.allclose(t, [d.t_start_s + d.duration_s for d in drives], atol=1e-12)
    assert np.array_equal(turning, np.stack([d.states.astype(bool) | d.chatter for d in drives]))
    assert np.array_equal(poses[-1], logged.true_poses())
    # replaying the log Drive by Drive on a fresh plant passes through the same poses
    again = SimulatedPlant(scn, seed=7)
    again.apply(wf[:4])
    k = len(replay(tuple(wf[:4]), scn.snap_down_V, scn.release_V).drives)
    assert np.array_equal(poses[k - 1], again.true_poses())


def test_drive_log_needs_the_option():
    with pytest.raises(RuntimeError, match="log_drives"):
        SimulatedPlant(far_scenario(FAR)).drive_log()
    t, turning, poses = SimulatedPlant(far_scenario(FAR), log_drives=True).drive_log()
    assert t.shape == (0,) and turning.shape == (0, 4) and poses.shape == (0, 4, 3)
