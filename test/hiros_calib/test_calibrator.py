import numpy as np
import pytest

from hiros_calib.calibrator import Calibrator, CalibratorParams
from hiros_calib.extrinsics import relative_error
from hiros_core.errors import CalibrationError


@pytest.fixture(scope="module")
def three_cameras(make_scene):
    return make_scene(duration=15.0, noise=0.005, n_people=2, drop=0.01, seed=7)


@pytest.mark.slow
def test_three_cameras_recover_the_known_calibration(three_cameras):
    scene = three_cameras
    calibrator = Calibrator(CalibratorParams())
    calibration = calibrator.calibrate(scene.camera_groups)
    assert calibration.reference == "cam0"
    assert list(calibration.cameras) == ["cam0", "cam1", "cam2"]
    reference = scene.truth.cameras["cam0"].extrinsics
    estimated_reference = calibration.cameras["cam0"].extrinsics  # the world is the floor's
    for name, estimate in calibration.cameras.items():
        truth = scene.truth.cameras[name]
        assert estimate.frame_id == f"{name}_depth_camera_link"
        assert estimate.time_offset == pytest.approx(truth.time_offset, abs=3e-3)
        angle, distance = relative_error(
            estimated_reference.inverse() @ estimate.extrinsics,
            reference.inverse() @ truth.extrinsics,
        )
        assert angle < 0.2
        assert distance < 0.01
    quality = calibration.cameras["cam1"].quality
    assert quality["inlier_ratio"] > 0.9
    assert quality["time_peak"] > 0.5
    assert set(quality["joint_residual_m"]) >= {"Pelvis", "KneeLeft"}


@pytest.mark.slow
def test_reference_camera_can_be_named(three_cameras):
    # world "camera": the reference camera's own frame is the world, as before the floor
    calibration = Calibrator(CalibratorParams(reference="cam2", world="camera")).calibrate(
        three_cameras.camera_groups
    )
    assert calibration.reference == "cam2"
    assert next(iter(calibration.cameras)) == "cam2"
    assert calibration.cameras["cam2"].time_offset == 0.0
    np.testing.assert_allclose(calibration.cameras["cam2"].translation, 0.0)
    truth = three_cameras.truth.cameras
    expected = truth["cam0"].time_offset - truth["cam2"].time_offset
    assert calibration.cameras["cam0"].time_offset == pytest.approx(expected, abs=3e-3)


def test_update_then_calibrate_equals_direct_call(make_scene):
    scene = make_scene(angles_deg=(0.0, 120.0), duration=10.0, seed=4)
    calibrator = Calibrator()
    for groups in scene.camera_groups.values():
        for group in groups:
            assert calibrator.update(group) is group
    fed = calibrator.calibrate()
    direct = Calibrator().calibrate(scene.camera_groups)
    assert fed.cameras["cam1"].time_offset == pytest.approx(direct.cameras["cam1"].time_offset)


def test_still_people_raise_with_the_reason(make_scene):
    scene = make_scene(angles_deg=(0.0, 90.0), duration=10.0, noise=0.01, still=True)
    with pytest.raises(CalibrationError, match=r"camera cam1.*hardly move"):
        Calibrator().calibrate(scene.camera_groups)


def test_partial_result_leaves_the_refused_camera_out(make_scene):
    scene = make_scene(angles_deg=(0.0, 90.0), duration=10.0, noise=0.01, still=True)
    calibrator = Calibrator(CalibratorParams(require_all=False))
    calibration = calibrator.calibrate(scene.camera_groups)
    assert list(calibration.cameras) == ["cam0"]
    assert "hardly move" in calibrator.result.refused["cam1"]


def test_one_camera_is_not_enough(make_scene):
    scene = make_scene(angles_deg=(0.0,), duration=5.0)
    with pytest.raises(CalibrationError, match="at least two cameras"):
        Calibrator().calibrate(scene.camera_groups)
