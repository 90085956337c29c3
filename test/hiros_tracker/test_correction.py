import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.layouts import AZURE_KINECT
from hiros_core.model import Skeleton, SkeletonGroup, stack_rows
from hiros_tracker.correction import MAX_REMEMBERED, UNCALIBRATED, CameraCorrection


def _calibration(time_offset: float = 0.5, drift: float = 0.0) -> Calibration:
    camera = CameraCalibration(
        frame_id="k02_depth_camera_link",
        time_offset=time_offset,
        drift=drift,
        drift_epoch=100.0,
        translation=np.array([1.0, 2.0, 3.0]),
        rotation=Rotation.from_euler("z", 90, degrees=True).as_quat(),
    )
    return Calibration("k02", "world", {"k02": camera})


def _group(frame: str = "k02_depth_camera_link", stamp_ns: int = 100_000_000_000) -> SkeletonGroup:
    positions = np.zeros((AZURE_KINECT.n_joints, 3))
    positions[:, 0] = 1.0  # every joint 1 m along the camera's x
    positions[3] = np.nan
    skeleton = Skeleton.from_positions(
        positions, skeleton_id=7, src_time_ns=stamp_ns, src_frame=frame
    )
    skeleton.velocities[:] = [1.0, 0.0, 0.0]
    return SkeletonGroup(stamp_ns, frame, [skeleton])


def test_moves_into_the_world_and_corrects_stamps():
    correction = CameraCorrection(_calibration(time_offset=0.5, drift=1e-3))
    out = correction.apply(_group())
    assert out is not None
    assert out.frame_id == "world"
    skeleton = out.skeletons[0]
    present = skeleton.marker_present
    assert not present[3]
    # Rz(90°) maps camera x to world y, then + t.
    np.testing.assert_allclose(skeleton.positions[present], [[1.0, 3.0, 3.0]] * present.sum())
    np.testing.assert_allclose(
        skeleton.velocities[present], [[0.0, 1.0, 0.0]] * present.sum(), atol=1e-12
    )
    expected = 100.0 + 0.5 + 1e-3 * (100.0 - 100.0)
    assert skeleton.src_time_ns == round(expected * 1e9)
    assert out.stamp_ns == skeleton.src_time_ns
    assert skeleton.src_frame == "k02_depth_camera_link"
    assert skeleton.id == 7


def test_camera_found_by_frame_id_when_the_name_differs():
    correction = CameraCorrection(_calibration())
    assert correction.apply(_group(frame="/some/odd_frame")) is None
    calibration = _calibration()
    calibration.cameras["k02"].frame_id = "/some/odd_frame"
    correction.set_calibration(calibration)
    assert correction.apply(_group(frame="/some/odd_frame")) is not None


def test_uncalibrated_camera_is_dropped_counted_and_reported_once():
    correction = CameraCorrection(_calibration())
    for _ in range(3):
        assert correction.apply(_group(frame="k09_depth_camera_link")) is None
    assert correction.drops[UNCALIBRATED] == 3
    assert correction.uncalibrated == {"k09"}


def test_ever_new_frame_ids_are_counted_without_growing_memory():
    correction = CameraCorrection(_calibration())
    for k in range(10 * MAX_REMEMBERED):
        assert correction.apply(_group(frame=f"x{k}_depth_camera_link")) is None
    assert correction.drops[UNCALIBRATED] == 10 * MAX_REMEMBERED
    assert len(correction.uncalibrated) == MAX_REMEMBERED
    assert len(correction._names) <= MAX_REMEMBERED
    assert correction.apply(_group()) is not None  # the calibrated camera is still found


def test_calibration_replaced_at_runtime():
    correction = CameraCorrection(_calibration())
    before = correction.apply(_group())
    moved = CameraCalibration(
        frame_id="k02_depth_camera_link", translation=np.array([0.0, 0.0, 0.0])
    )
    correction.set_camera("k02", moved)
    after = correction.apply(_group())
    assert before is not None
    assert after is not None
    present = after.skeletons[0].marker_present
    np.testing.assert_allclose(after.skeletons[0].positions[present][0], [1.0, 0.0, 0.0])
    assert after.stamp_ns == 100_000_000_000
    correction.set_camera("k09", moved)
    assert correction.apply(_group(frame="k09_depth_camera_link")) is not None


def test_same_result_as_apply_to_skeleton():
    rng = np.random.default_rng(0)
    calibration = _calibration()
    calibration.cameras["k02"].rotation = Rotation.random(random_state=1).as_quat()
    group = _group()
    skeleton = group.skeletons[0]
    skeleton.markers[:, 1:] = rng.normal(size=(len(skeleton.markers), 19))
    skeleton.markers[5, 4:8] = 0.0  # a zero quaternion stays unknown
    skeleton.update_links()
    skeleton.bounding_box[:7] = rng.normal(size=7)
    group.skeletons.append(skeleton.copy())
    out = CameraCorrection(calibration).apply(group)
    expected = calibration.cameras["k02"].extrinsics.apply_to_skeleton(skeleton)
    for moved in out.skeletons:
        np.testing.assert_allclose(moved.markers, expected.markers, atol=1e-12)
        np.testing.assert_allclose(moved.links, expected.links, atol=1e-12)
        np.testing.assert_allclose(moved.bounding_box, expected.bounding_box, atol=1e-12)


def test_moved_skeletons_are_one_new_stack_and_the_input_is_left_alone():
    frame = "k02_depth_camera_link"
    positions = np.tile(np.linspace(0.0, 1.0, AZURE_KINECT.n_joints)[:, None], (3, 1, 3))
    shared = SkeletonGroup(
        7, frame, Skeleton.many_from_positions(positions, skeleton_ids=(1, 2, 3), src_frame=frame)
    )
    apart = SkeletonGroup(7, frame, [s.copy() for s in shared.skeletons])
    for group in (shared, apart):  # rows of one stack (as a bridge makes them), or not
        before = [s.copy() for s in group.skeletons]
        moved = CameraCorrection(_calibration()).move(group)
        assert moved is not None
        assert stack_rows(moved.group.skeletons) is moved.stack  # handed on without a copy
        assert [s.id for s in moved.group.skeletons] == [1, 2, 3]
        assert all(a.same_as(b) for a, b in zip(before, group.skeletons, strict=True))
        assert not np.shares_memory(moved.stack.markers, group.skeletons[0].markers)
