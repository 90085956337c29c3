import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from hiros_calib.extrinsics import relative_error
from hiros_calib.live import LiveCalibrator, LiveCalibratorParams
from hiros_core.geometry import RigidTransform


def _feed(scene, live, until=None, step_every=3):
    """Frames in arrival order (arrival = reference time + 20 ms), stepping as a node would."""
    frames = []
    for name, groups in scene.camera_groups.items():
        cam = scene.truth.cameras[name]
        for g in groups:
            arrival = round((cam.to_reference_time(g.stamp) + 0.02) * 1e9)
            frames.append((arrival, g))
    frames.sort(key=lambda f: f[0])
    changes = []
    for k, (arrival, group) in enumerate(frames):
        if until is not None and arrival > until * 1e9:
            break
        live.update(group, arrival)
        if k % step_every == 0 and live.step(arrival):
            changes.append(arrival * 1e-9)
    return changes


def _pose_error(live, truth_pose, camera="cam1"):
    est = live.calibration.cameras[camera].extrinsics
    return relative_error(est, truth_pose)


@pytest.mark.slow
def test_live_calibrates_then_recalibrates_a_moved_camera(make_scene):
    turn = Rotation.from_rotvec([0.0, 0.0, np.radians(12.0)])
    scene0 = make_scene(angles_deg=(0.0, 100.0), duration=1.0)
    position = scene0.truth.cameras["cam1"].translation
    # rotate the camera about its own position and shift it 30 cm: a bumped tripod
    move = RigidTransform(turn, position - turn.apply(position) + np.array([0.3, 0.0, 0.0]))
    scene = make_scene(
        angles_deg=(0.0, 100.0), duration=45.0, noise=0.005, moves={1: (100.0 + 28.0, move)}
    )
    params = LiveCalibratorParams(buffer_length=20.0, first_estimate_after=12.0, update_period=8.0)
    live = LiveCalibrator(params)
    truth = scene.truth.cameras
    before = truth["cam0"].extrinsics.inverse() @ truth["cam1"].extrinsics
    after = truth["cam0"].extrinsics.inverse() @ move @ truth["cam1"].extrinsics

    _feed(scene, live)
    events = " | ".join(f"{t * 1e-9:.1f} {m}" for t, m in live.events)
    moved_at = truth["cam0"].to_reference_time(128.0)  # cam0 is the reference clock
    calibrated = [t * 1e-9 for t, m in live.events if m == "cam1: calibrated"]
    detected = [t * 1e-9 for t, m in live.events if m.startswith("cam1: moved")]
    assert calibrated, events
    assert calibrated[0] < moved_at
    # detected and recalibrated within 10 s of data after the move
    assert detected, events
    assert moved_at < detected[0] < moved_at + 10.0, events
    assert any(moved_at < t < moved_at + 10.0 for t in calibrated[1:]), events
    angle, distance = _pose_error(live, after)
    assert angle < 0.5, events
    assert distance < 0.02, events
    assert relative_error(live.calibration.cameras["cam1"].extrinsics, before)[0] > 10.0
    assert live.calibration.cameras["cam1"].time_offset == pytest.approx(
        truth["cam1"].time_offset, abs=3e-3
    )


def test_stamps_far_back_restart_the_cameras_buffer_small_steps_are_dropped():
    """One frame stamped far ahead (or a restarted camera clock) used to make every later
    frame of the camera 'out_of_order', for good."""
    from hiros_core.model import SkeletonGroup

    live = LiveCalibrator(LiveCalibratorParams())
    second = 1_000_000_000
    stamps = [1, 2, 3, 2**31 * second, 4, 5, 4.5, 6]  # a glitch, then a small step back
    for index, stamp in enumerate(stamps):
        live.update(SkeletonGroup(round(stamp * second), "cam0"), index)
    assert live.snapshot()["buffered"] == {"cam0": 3}  # 4, 5, 6
    assert live.drops == {"stamps_went_back": 1, "out_of_order": 1}
    assert "cam0: stamps went back" in live.events[-1][1]
