import filter_reference
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.signal import butter, sosfilt
from scipy.spatial.transform import Rotation

from hiros_core.errors import ConfigError
from hiros_core.model import Skeleton, SkeletonGroup, sec_to_ns
from hiros_filter import Filter, FilterParams
from hiros_filter import filter as filter_module
from hiros_filter.filter import BUTTERWORTH_ORDER

RATE = 30.0
J = 32


def frame(positions, t, skeleton_id=0, orientations=None):
    skeleton = Skeleton.from_positions(
        positions, skeleton_id=skeleton_id, src_time_ns=sec_to_ns(t), orientations=orientations
    )
    return SkeletonGroup(sec_to_ns(t), "world", [skeleton])


def feed(stage, trajectory, times, **kwargs):
    """Run ``(T, J, 3)`` through the stage; returns the output skeletons."""
    return [
        stage.update(frame(p, t, **kwargs)).skeletons[0]
        for p, t in zip(trajectory, times, strict=True)
    ]


def base_pose(seed=0):
    return np.random.default_rng(seed).normal(size=(J, 3))


@pytest.mark.parametrize("mode", ["kalman", "butterworth"])
def test_constant_velocity_gives_that_velocity(mode):
    times = np.arange(90) / RATE
    velocity = np.array([0.8, -0.3, 0.1])
    trajectory = base_pose()[None] + times[:, None, None] * velocity
    out = feed(Filter(FilterParams(filter=mode)), trajectory, times)
    np.testing.assert_allclose(out[-1].velocities, np.tile(velocity, (J, 1)), atol=1e-3)
    np.testing.assert_allclose(out[-1].accelerations, 0.0, atol=1e-2)
    if mode == "kalman":  # the CA model follows a ramp without lag
        np.testing.assert_allclose(out[-1].positions, trajectory[-1], atol=1e-4)


def test_constant_acceleration_gives_that_acceleration():
    times = np.arange(120) / RATE
    acceleration = np.array([0.0, 2.0, -1.0])
    trajectory = base_pose(1)[None] + 0.5 * times[:, None, None] ** 2 * acceleration
    out = feed(Filter(), trajectory, times)
    np.testing.assert_allclose(out[-1].accelerations, np.tile(acceleration, (J, 1)), atol=1e-2)
    np.testing.assert_allclose(
        out[-1].velocities, np.tile(acceleration * times[-1], (J, 1)), atol=1e-2
    )


def test_butterworth_matches_scipy_and_fills_a_dropped_frame():
    rng = np.random.default_rng(2)
    times = np.arange(60) / RATE
    signal = base_pose(2)[None] + rng.normal(scale=0.02, size=(60, J, 3))
    params = FilterParams(filter="butterworth")  # at the rate estimated from the stamps
    sos = butter(BUTTERWORTH_ORDER, params.cutoff_frequency, fs=RATE, output="sos")
    expected = sosfilt(sos, signal - signal[0], axis=0) + signal[0]
    out = feed(Filter(params), signal, times)
    got = np.stack([s.positions for s in out])
    np.testing.assert_allclose(got, expected, atol=1e-9)
    # Without frame 30 the filter sees the interpolation of frames 29 and 31 in its place.
    keep = np.arange(60) != 30
    resampled = signal.copy()
    resampled[30] = 0.5 * (signal[29] + signal[31])
    expected = sosfilt(sos, resampled - signal[0], axis=0) + signal[0]
    out = feed(Filter(params), signal[keep], times[keep])
    np.testing.assert_allclose(out[-1].positions, expected[-1], atol=1e-9)


def test_sampling_rate_is_estimated_and_followed():
    stage = Filter(FilterParams(filter="butterworth"))
    pose = base_pose(3)
    feed(stage, np.repeat(pose[None], 30, axis=0), np.arange(30) / RATE)
    assert stage.sample_frequency == pytest.approx(RATE)
    # The camera drops to 15 Hz: the low-pass is re-designed and stays at rest on a still body.
    times = 1.0 + np.arange(1, 80) / 15.0
    out = feed(stage, np.repeat(pose[None], len(times), axis=0), times)
    assert stage.sample_frequency == pytest.approx(15.0, rel=0.01)
    np.testing.assert_allclose(out[-1].positions, pose, atol=1e-9)


@pytest.mark.parametrize("mode", ["kalman", "butterworth"])
def test_gap_and_new_track_restart_without_blow_up(mode):
    stage = Filter(FilterParams(filter=mode))  # back after 1 s: past MAX_GAP
    times = np.arange(30) / RATE
    moving = base_pose(4)[None] + times[:, None, None] * np.array([3.0, 0.0, 0.0])
    feed(stage, moving, times)
    # Back 1 s later, 5 m away: a restart, not a 150 m/s jump.
    far = moving[-1] + np.array([0.0, 5.0, 0.0])
    first = stage.update(frame(far, times[-1] + 1.0)).skeletons[0]
    np.testing.assert_allclose(first.positions, far)
    np.testing.assert_allclose(first.velocities, 0.0)
    # A brand-new track starts at its own measurement too.
    other = stage.update(frame(far + 1.0, times[-1] + 1.0 + 1 / RATE, skeleton_id=7))
    np.testing.assert_allclose(other.skeletons[0].positions, far + 1.0)


def test_missing_joint_stays_absent_then_rejoins_smoothly():
    stage = Filter()
    times = np.arange(60) / RATE
    trajectory = base_pose(5)[None] + times[:, None, None] * np.array([0.5, 0.0, 0.0])
    trajectory[20:25, 6] = np.nan  # an elbow lost for 5 frames
    out = feed(stage, trajectory, times)
    assert not out[22].marker_present[6]
    assert np.isnan(out[22].positions[6]).all()
    assert out[26].marker_present[6]
    np.testing.assert_allclose(out[26].positions[6], trajectory[26, 6], atol=0.01)
    assert np.isfinite(np.concatenate([s.velocities[s.marker_present] for s in out])).all()


def test_orientations_stay_on_so3_with_the_right_angular_velocity():
    times = np.arange(90) / RATE
    rate = np.array([0.0, 0.0, 1.5])  # rad/s about z
    rotations = Rotation.from_rotvec(times[:, None] * rate)
    quaternions = np.repeat(rotations.as_quat()[:, None], J, axis=1)
    pose = np.repeat(base_pose(6)[None], 90, axis=0)
    stage = Filter()
    out = [
        stage.update(frame(p, t, orientations=q)).skeletons[0]
        for p, t, q in zip(pose, times, quaternions, strict=True)
    ]
    norms = np.linalg.norm(np.stack([s.orientations for s in out]), axis=-1)
    np.testing.assert_allclose(norms, 1.0)
    np.testing.assert_allclose(out[-1].angular_velocities, np.tile(rate, (J, 1)), atol=1e-6)
    # smoothing lags the measured angle a little, never more than a few frames' worth
    lag_angle = (Rotation.from_quat(out[-1].orientations[0]).inv() * rotations[-1]).magnitude()
    assert 0 < lag_angle < 5 * 1.5 / RATE


def test_stale_frames_and_bad_skeletons_are_counted():
    stage = Filter()
    pose = base_pose(7)
    stage.update(frame(pose, 1.0))
    assert stage.update(frame(pose, 1.0)).skeletons == []
    assert stage.update(frame(pose, 0.5)).skeletons == []
    broken = Skeleton.from_positions(pose, skeleton_id=1, src_time_ns=sec_to_ns(2.0))
    broken.positions[3] = np.inf
    anonymous = Skeleton.from_positions(pose, skeleton_id=-1, src_time_ns=sec_to_ns(2.0))
    out = stage.update(SkeletonGroup(sec_to_ns(2.0), "world", [broken, anonymous]))
    assert list(out.ids) == [-1]
    assert sum(stage.drops.values()) == 4


def test_a_stamp_far_ahead_does_not_stop_the_track_for_good():
    """One frame stamped far in the future used to make every later frame of the track
    'not after the track's previous one', for the rest of the run."""
    stage = Filter()
    pose = base_pose(7)
    for t in (1.0, 1.033, 1e6, 1.066, 1.1):
        out = stage.update(frame(pose, t))
    assert [s.id for s in out.skeletons] == [0]
    assert stage.drops == {"stamp far before the track's previous one (restarted)": 1}


def test_slerp():
    start = Rotation.identity().as_quat()
    end = Rotation.from_rotvec([0.0, 0.0, 1.0]).as_quat()
    np.testing.assert_allclose(filter_reference.slerp(start, end, 0.0), start, atol=1e-12)
    np.testing.assert_allclose(
        filter_reference.slerp(start, -end, 1.0), end, atol=1e-12
    )  # q and -q are one rotation
    half = Rotation.from_quat(filter_reference.slerp(start, end, 0.5))
    np.testing.assert_allclose(half.as_rotvec(), [0.0, 0.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(filter_reference.slerp(start, start, 0.3), start)


def test_params_are_checked():
    with pytest.raises(ConfigError):
        FilterParams(filter="median")
    with pytest.raises(ConfigError):
        FilterParams(cutoff_frequency=0.0)


def test_adaptive_noise_follows_a_movement_start_sooner(monkeypatch):
    times = np.arange(60) / RATE
    start = np.clip(times - 1.0, 0.0, None)  # still for 1 s, then a 3 m/s swing
    trajectory = base_pose(8)[None] + start[:, None, None] * np.array([3.0, 0.0, 0.0])
    errors = {}
    for scale in (1.0, 10.0):
        monkeypatch.setattr(filter_module, "MAX_NOISE_SCALE", scale)  # 1: a fixed noise
        out = feed(Filter(), trajectory, times)
        got = np.stack([s.positions for s in out[33:40]])  # after the first surprise
        errors[scale] = np.abs(got - trajectory[33:40]).max()
    assert errors[10.0] < 0.8 * errors[1.0]


def test_process_noise_is_filterpys():
    from filterpy.common import Q_continuous_white_noise

    for dt in (0.001, 0.033333, 0.1, 0.5):
        expected = Q_continuous_white_noise(dim=3, dt=dt, spectral_density=300.0)
        np.testing.assert_array_equal(filter_reference.process_noise(dt, 300.0), expected)


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    slots=st.sampled_from([[3, 1, 4], [1, 2, 3], [0]]),
    max_noise_scale=st.sampled_from([1.0, 10.0]),
)
def test_kalman_step_equals_predict_then_masked_correction(seed, slots, max_noise_scale):
    """Scattered and consecutive slots (a block: numpy's views), partial and full masks."""
    from hiros_filter.estimators import KalmanBank

    rng = np.random.default_rng(seed)
    slots = np.array(slots)
    banks = [KalmanBank((5, 6), 300.0, 0.01, max_noise_scale=max_noise_scale) for _ in range(2)]
    start = rng.normal(size=(len(slots) * 6, 3))
    for bank in banks:
        bank.reset(np.repeat(slots, 6), np.tile(np.arange(6), len(slots)), start)
    for _ in range(3):
        dt = rng.uniform(0.01, 0.1, len(slots))
        measured = rng.normal(scale=0.05, size=(len(slots), 6, 3))
        mask = rng.random((len(slots), 6)) > rng.choice([0.0, 0.3])
        filter_reference.predict(banks[0], slots, dt)
        filter_reference.correct(banks[0], slots, mask, np.where(mask[..., None], measured, np.nan))
        banks[1].step(slots, dt, mask, measured)
        np.testing.assert_allclose(banks[1].x, banks[0].x, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(banks[1].P, banks[0].P, rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(banks[1].scale, banks[0].scale, rtol=1e-12)
