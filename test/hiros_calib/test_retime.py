"""The clocks refined by the joints' motion once the poses are known (hiros_calib.retime)."""

from __future__ import annotations

import copy

import pytest

from hiros_calib import Calibrator, CalibratorParams
from hiros_calib.retime import MAX_SHIFT, motion_shift, retime

OFF = 0.015
"""A clock error (s) the correlation could leave: half a frame at 30 Hz."""


@pytest.fixture(scope="module")
def calibrated(make_scene):
    """A calibrated three-camera scene with joint noise (cam1 sees the person's back)."""
    scene = make_scene(noise=0.01, duration=20.0)
    calibrator = Calibrator(CalibratorParams(reference="cam0"))
    calibrator.calibrate(scene.camera_groups)
    return scene, calibrator


def _retimed(calibrator, clocks, sync_pairs):
    result = calibrator.result
    return retime(
        clocks,
        "cam0",
        sync_pairs=sync_pairs,
        pose_pairs=result.pose_pairs,
        poses=result.poses,
        tracks=result.tracks,
        params=calibrator.params,
    )


def test_a_pairs_motion_shift_is_the_clock_error_between_its_cameras(calibrated):
    scene, calibrator = calibrated
    result = calibrator.result
    clocks = copy.deepcopy(result.clocks)
    for camera, clock in clocks.items():  # the true clocks, then cam1's off by OFF
        clock.time_offset = scene.truth.cameras[camera].time_offset
    clocks["cam1"].time_offset += OFF
    pair = next(p for p in result.pose_pairs if (p.camera_a, p.camera_b) == ("cam0", "cam1"))
    b_to_a = result.poses["cam0"].transform.inverse() @ result.poses["cam1"].transform

    found = motion_shift(pair, result.tracks, clocks, b_to_a, calibrator.params)

    # adding the shift to cam1's offset undoes the error
    assert found.shift == pytest.approx(-OFF, abs=0.003)
    assert 0 < found.standard_error < 0.003
    assert found.samples > 1000


def test_a_clock_the_correlation_left_off_is_put_back_by_the_motion(calibrated):
    scene, calibrator = calibrated
    truth = {c: cam.time_offset for c, cam in scene.truth.cameras.items()}
    clocks = copy.deepcopy(calibrator.result.clocks)
    clocks["cam1"].time_offset = truth["cam1"] + OFF
    clocks["cam2"].time_offset = truth["cam2"]

    refined, shifts = _retimed(calibrator, clocks, sync_pairs=[])

    assert len(shifts) == 3  # every camera pair measured
    assert refined["cam1"].time_offset == pytest.approx(truth["cam1"], abs=0.003)
    assert refined["cam2"].time_offset == pytest.approx(truth["cam2"], abs=0.003)
    assert refined["cam1"].quality["motion_shift_ms"] == pytest.approx(-1e3 * OFF, abs=3.0)
    assert clocks["cam1"].time_offset == truth["cam1"] + OFF  # the input is left as it was


def test_the_correlation_and_the_motion_are_weighed_by_their_errors(calibrated):
    """Windows that agree pin a clock: the motion moves it less than when they scatter."""
    scene, calibrator = calibrated
    truth = scene.truth.cameras["cam1"].time_offset
    clocks = copy.deepcopy(calibrator.result.clocks)
    clocks["cam1"].time_offset = truth + OFF
    pairs = [copy.deepcopy(p) for p in calibrator.result.sync_pairs if p.ok]
    sure, unsure = copy.deepcopy(pairs), copy.deepcopy(pairs)
    for pair in sure:
        pair.windows[:, 1] = pair.windows[:, 1].mean()  # every window alike: the floor's error
    for pair in unsure:
        pair.windows[:, 1] += 0.05 * (-1.0) ** pair.windows[:, 0].argsort().argsort()

    moved_sure = _retimed(calibrator, clocks, sure)[0]["cam1"].time_offset - (truth + OFF)
    moved_unsure = _retimed(calibrator, clocks, unsure)[0]["cam1"].time_offset - (truth + OFF)

    assert moved_sure < 0  # towards the truth
    assert moved_unsure < 0
    assert abs(moved_sure) < abs(moved_unsure)
    assert moved_unsure == pytest.approx(-OFF, abs=0.003)


def test_a_shift_beyond_the_linear_range_is_left_to_the_lag_checks(calibrated):
    scene, calibrator = calibrated
    clocks = copy.deepcopy(calibrator.result.clocks)
    for camera, clock in clocks.items():
        clock.time_offset = scene.truth.cameras[camera].time_offset
    clocks["cam1"].time_offset += 3 * MAX_SHIFT  # a frame pattern, not a refinement

    refined, shifts = _retimed(calibrator, clocks, sync_pairs=[])

    assert all("cam1" not in (s.camera_a, s.camera_b) for s in shifts)
    assert refined["cam1"].time_offset == clocks["cam1"].time_offset


def test_a_calibration_reports_how_far_the_motion_moved_each_clock(calibrated):
    scene, calibrator = calibrated
    calibration = calibrator.result.calibration
    for camera in ("cam1", "cam2"):
        moved = calibration.cameras[camera].quality["time_motion_shift_ms"]
        error = calibration.cameras[camera].time_offset - scene.truth.cameras[camera].time_offset
        assert abs(moved) < 5.0  # a clock the correlation timed well stays about where it was
        assert abs(error) < 0.003
    assert "time_motion_shift_ms" not in calibration.cameras["cam0"].quality
