"""Clocks found with the poses of an earlier calibration kept (``known_poses``)."""

from __future__ import annotations

import copy
from collections import Counter

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hiros_calib import Calibrator, CalibratorParams
from hiros_calib.known import check_lags, known_relative_poses
from hiros_calib.quality import flag_cameras
from hiros_calib.sync import PairOffset
from hiros_calib.tracks import extract_tracks
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.errors import CalibrationError
from hiros_eval.calibration import compare_calibration
from hiros_sim import simulate
from hiros_sim.presets import preset_params


def _turned(calibration: Calibration, camera: str, degrees: float) -> Calibration:
    """A copy with ``camera`` turned about the world's vertical by ``degrees``."""
    turned = copy.deepcopy(calibration)
    cam = turned.cameras[camera]
    turn = Rotation.from_euler("z", degrees, degrees=True)
    cam.rotation = (turn * Rotation.from_quat(cam.rotation)).as_quat()
    return turned


def test_the_known_poses_must_hold_every_camera():
    known = Calibration(reference="k01")
    known.cameras = {
        name: CameraCalibration(frame_id=name, translation=[k, 0.0, 0.0], rotation=[0, 0, 0, 1.0])
        for k, name in enumerate(("k01", "k02"))
    }
    assert set(known_relative_poses(known, ["k01", "k02"], "k01")) == {"k01", "k02"}
    with pytest.raises(CalibrationError, match="hold no camera k03"):
        known_relative_poses(known, ["k01", "k02", "k03"], "k01")


@pytest.mark.slow
def test_a_person_exercising_on_one_spot_is_timed_against_known_poses():
    """The take alone flags its pose (the person stayed on one spot); with the poses known
    the clocks come out, the poses and world are the known ones, and nothing is flagged. The
    same known poses with k02 turned by 3 deg (a camera moved since) flag k02."""
    scene = simulate(preset_params("exercise-on-spot", seed=2, duration=40.0))
    truth = scene.calibration
    alone = Calibrator(CalibratorParams(reference="k01")).calibrate(
        scene.camera_groups, arrival_ns=scene.receive_ns
    )
    assert "stayed on one spot" in alone.flagged["k02"]

    calibration = Calibrator(CalibratorParams(reference="k01")).calibrate(
        scene.camera_groups, arrival_ns=scene.receive_ns, known_poses=truth
    )
    assert calibration.flagged == {}
    times = {c: np.array([g.stamp for g in gs])[::15] for c, gs in scene.camera_groups.items()}
    accuracy = compare_calibration(calibration, truth, times)
    assert accuracy["k02"].time_error_ms < 10.0
    for name, camera in calibration.cameras.items():
        assert camera.translation == pytest.approx(truth.cameras[name].translation, abs=1e-9)
    quality = calibration.cameras["k02"].quality
    assert quality["known_pose_residual_cm"] - quality["own_pose_residual_cm"] < 1.5

    moved = Calibrator(CalibratorParams(reference="k01")).calibrate(
        scene.camera_groups, arrival_ns=scene.receive_ns, known_poses=_turned(truth, "k02", 3.0)
    )
    assert "a camera has moved since" in moved.flagged["k02"]


@pytest.mark.slow
def test_the_known_poses_find_the_lag_they_fit_best_and_a_pair_far_from_it_is_flagged():
    """On the exercise take the known poses fit best at the true lag; a pair the motion timed
    seconds away from it (as noisy gestures on one spot can) is flagged, not kept silently."""
    scene = simulate(preset_params("exercise-on-spot", seed=2, duration=40.0))
    truth = scene.calibration
    tracks = {
        camera: extract_tracks(
            groups, camera, max_gap=0.25, min_frames=10, min_confidence=0.5, drops=Counter()
        )
        for camera, groups in scene.camera_groups.items()
    }
    known = known_relative_poses(truth, ["k01", "k02"], "k01")
    true_lag = truth.cameras["k02"].time_offset
    timed = PairOffset("k01", "k02", status="ok", offset=true_lag + 5.0)
    check_lags([timed], tracks, known)
    assert timed.quality["known_pose_best_lag"] == pytest.approx(true_lag, abs=0.06)

    calibration = copy.deepcopy(truth)
    flag_cameras(calibration, [timed], [], poses_known=True)
    assert "fit the k01-k02 skeletons best at lag" in calibration.flagged["k02"]
    timed.offset = true_lag
    calibration = copy.deepcopy(truth)
    flag_cameras(calibration, [timed], [], poses_known=True)
    assert "best at lag" not in calibration.cameras["k02"].flagged
