import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.errors import CalibrationError
from hiros_core.geometry import RigidTransform
from hiros_eval.calibration import compare_calibration


def _camera(pose, offset, drift=0.0, epoch=0.0):
    return CameraCalibration(
        frame_id="f",
        time_offset=offset,
        drift=drift,
        drift_epoch=epoch,
        translation=pose.translation,
        rotation=pose.quaternion,
    )


@pytest.fixture
def truth():
    # an arbitrary world frame and reference clock: nothing is relative to camera a
    poses = {
        "a": RigidTransform(Rotation.from_rotvec([0.1, 0.2, 1.0]), np.array([3.0, 0.0, 1.5])),
        "b": RigidTransform(Rotation.from_rotvec([0.0, -0.3, 2.5]), np.array([-3.0, 1.0, 1.2])),
        "c": RigidTransform(Rotation.from_rotvec([1.0, 0.0, 0.0]), np.array([0.0, 3.0, 2.0])),
    }
    clocks = {"a": (5.0, 1e-4, 100.0), "b": (-2.0, -5e-5, 50.0), "c": (0.3, 0.0, 0.0)}
    cal = Calibration(reference="a")
    for name, pose in poses.items():
        cal.cameras[name] = _camera(pose, *clocks[name])
    return cal


def _relative_to(cal, reference):
    """The truth as a perfect estimate with ``reference``'s frame and clock."""
    ref = cal.cameras[reference]
    out = Calibration(reference=reference)
    for name, cam in cal.cameras.items():
        pose = ref.extrinsics.inverse() @ cam.extrinsics
        # t_ref_cam = inverse of ref's clock applied to cam's reference time (linear map)
        t0, t1 = 0.0, 1000.0
        y0, y1 = (
            (cam.to_reference_time(t) - ref.time_offset + ref.drift * ref.drift_epoch)
            / (1 + ref.drift)
            for t in (t0, t1)
        )
        slope = (y1 - y0) / (t1 - t0)
        out.cameras[name] = _camera(pose, y0, slope - 1.0, 0.0)
    return out


def test_perfect_estimate_has_no_error(truth):
    for reference in ("a", "b"):
        estimate = _relative_to(truth, reference)
        errors = compare_calibration(estimate, truth, {"b": np.array([10.0, 90.0])})
        assert set(errors) == {"a", "b", "c"} - {reference}
        for e in errors.values():
            assert e.time_error_ms < 1e-6
            assert e.rotation_error_deg < 1e-6
            assert e.translation_error_cm < 1e-6


def test_known_errors_are_reported(truth):
    estimate = _relative_to(truth, "a")
    cam = estimate.cameras["b"]
    cam.time_offset += 0.003
    pose = cam.extrinsics
    moved = RigidTransform(pose.rotation * Rotation.from_rotvec([0, 0, np.radians(0.5)]),
                           pose.translation + np.array([0.02, 0.0, 0.0]))  # fmt: skip
    cam.rotation, cam.translation = moved.quaternion, moved.translation
    errors = compare_calibration(estimate, truth)
    assert errors["b"].time_error_ms == pytest.approx(3.0, abs=1e-6)
    assert errors["b"].rotation_error_deg == pytest.approx(0.5, abs=1e-6)
    assert errors["b"].translation_error_cm == pytest.approx(2.0, abs=1e-6)
    assert errors["c"].time_error_ms < 1e-6


def test_missing_camera_gives_nan_and_unknown_reference_raises(truth):
    estimate = _relative_to(truth, "a")
    del estimate.cameras["c"]
    assert np.isnan(compare_calibration(estimate, truth)["c"].rotation_error_deg)
    estimate.reference = "z"
    with pytest.raises(CalibrationError, match="not in the truth"):
        compare_calibration(estimate, truth)
