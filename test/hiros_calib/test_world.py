"""The gravity-aligned world: z up and the floor at z = 0, found from the people's feet."""

from __future__ import annotations

import numpy as np
import pytest

from hiros_calib import Calibrator, CalibratorParams
from hiros_calib.world import FloorFit, align_to_floor
from hiros_core.calibration import Calibration, CameraCalibration
from hiros_sim import SimParams, simulate


@pytest.mark.slow
def test_the_world_is_the_floor_with_z_up_on_a_simulated_scene() -> None:
    scene = simulate(SimParams(duration=40.0, seed=1))
    calibration = Calibrator(CalibratorParams(reference="k01")).calibrate(
        scene.camera_groups, arrival_ns=scene.receive_ns
    )
    # the estimated world in the truth's (z up, floor at z = 0): through the reference camera
    truth_from_world = (
        scene.calibration.cameras["k01"].extrinsics
        @ calibration.cameras["k01"].extrinsics.inverse()
    )
    up = truth_from_world.rotate(np.array([0.0, 0.0, 1.0]))
    assert np.degrees(np.arccos(up[2])) < 1.5
    # the floor where the people walk: the truth's pelvis positions, dropped to z = 0
    people = np.nanmean(scene.truth.positions[:, :, 0], axis=(0, 1))
    world_from_truth = truth_from_world.inverse()
    below = world_from_truth.apply(np.array([people[0], people[1], 0.0]))
    assert abs(below[2]) < 0.05
    quality = calibration.cameras["k01"].quality
    assert quality["floor_up_from"] == "feet"
    assert 5.0 < quality["floor_tilt_deg"] < 30.0  # the camera looks slightly down
    assert quality["floor_residual_cm"] < 10.0


def test_aligning_to_a_floor_puts_the_reference_camera_above_the_origin() -> None:
    # the reference camera looks horizontally (optical y down = -up), 1.5 m above the floor
    calibration = Calibration("k01", cameras={"k01": CameraCalibration("k01_depth")})
    floor = FloorFit(np.array([0.0, -1.0, 0.0]), -1.5, 0.01, 100, "feet")
    align_to_floor(calibration, floor)
    cam = calibration.cameras["k01"]
    np.testing.assert_allclose(cam.translation, [0.0, 0.0, 1.5], atol=1e-9)
    # its optical z (forward) is the world's x, its optical y (down) the world's -z
    rotated = cam.extrinsics.rotate(np.eye(3))
    np.testing.assert_allclose(rotated[2], [1.0, 0.0, 0.0], atol=1e-9)
    np.testing.assert_allclose(rotated[1], [0.0, 0.0, -1.0], atol=1e-9)
    assert cam.quality["floor_tilt_deg"] == pytest.approx(0.0, abs=1e-6)
