import numpy as np
import pytest

from hiros_core.layouts import AZURE_KINECT
from hiros_eval.body import (
    JOINT_ANGLES,
    jitter,
    joint_angle_rmse,
    joint_angles,
    lag,
    limb_length_cv,
    mpjpe,
    sample_truth,
)

J = AZURE_KINECT.n_joints


def test_mpjpe_overall_and_per_joint_skip_nan():
    truth = np.zeros((4, J, 3))
    estimate = truth.copy()
    estimate[:, 3, 0] = 0.1
    estimate[0, 5] = np.nan
    overall, per_joint = mpjpe(estimate, truth)
    assert per_joint[3] == pytest.approx(0.1)
    assert per_joint[5] == 0.0
    assert overall == pytest.approx(0.4 / (4 * J - 1))


def test_limb_length_cv_is_zero_for_rigid_and_known_for_stretching():
    rng = np.random.default_rng(0)
    pose = rng.normal(size=(J, 3))
    rigid = np.repeat(pose[None], 10, axis=0) + rng.normal(size=(10, 1, 3))
    cv = limb_length_cv(rigid)
    assert np.isnan(cv[0])
    np.testing.assert_allclose(cv[1:], 0.0, atol=1e-12)
    scales = np.array([0.9, 1.1])
    stretched = pose[None] * scales[:, None, None]
    np.testing.assert_allclose(limb_length_cv(stretched)[1:], 0.1)


def test_joint_angles_of_a_bent_knee():
    positions = np.zeros((J, 3))
    index = AZURE_KINECT.index
    positions[index("SpineChest")] = (0, 0, 1)
    positions[index("HipLeft")] = (0.1, 0, 0)
    positions[index("KneeLeft")] = (0.1, 0, -0.4)
    positions[index("AnkleLeft")] = (0.1, 0.4, -0.4)  # shank horizontal: 90 degrees
    angles = joint_angles(positions)
    assert set(angles) == set(JOINT_ANGLES)
    assert angles["knee_left"] == pytest.approx(90.0)
    assert angles["hip_left"] == pytest.approx(0.0, abs=1e-6)  # thigh along the trunk's down axis


def test_joint_angle_rmse():
    rng = np.random.default_rng(1)
    truth = rng.normal(size=(20, J, 3))
    rmse = joint_angle_rmse(truth, truth)
    assert all(value == pytest.approx(0.0, abs=1e-6) for value in rmse.values())
    noisy = joint_angle_rmse(truth + rng.normal(scale=0.05, size=truth.shape), truth)
    assert noisy["mean"] > 1.0


def test_lag_of_a_delayed_signal():
    rate = 30.0
    t = np.arange(600) / rate
    rng = np.random.default_rng(2)
    signal = np.cumsum(rng.normal(size=(600, 3)), axis=0)
    late = np.interp(t - 0.05, t, signal[:, 0])  # 50 ms = 1.5 frames late
    assert lag(late[:, None], signal[:, :1], rate) == pytest.approx(0.05, abs=0.01)
    assert lag(signal, signal, rate) == pytest.approx(0.0, abs=1e-9)


def test_jitter_of_the_error_ignores_smooth_motion():
    t = np.arange(100) / 30.0
    smooth = np.stack([t**2, t, 0 * t], axis=1)
    assert jitter(smooth, smooth) == 0.0
    shaky = smooth + np.where(np.arange(100) % 2, 0.001, -0.001)[:, None]
    assert jitter(shaky, smooth) == pytest.approx(0.004)  # second difference of ±1 mm


def test_sample_truth_interpolates_and_leaves_outside_nan():
    truth_times = np.array([0.0, 1.0, 2.0])
    truth = np.array([0.0, 1.0, 4.0])[:, None, None] * np.ones((1, 2, 3))
    out = sample_truth(np.array([-0.5, 0.5, 1.5, 2.5]), truth_times, truth)
    assert np.isnan(out[[0, 3]]).all()
    np.testing.assert_allclose(out[1:3, 0, 0], [0.5, 2.5])
