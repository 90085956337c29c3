"""Camera transforms beside the Azure Kinect driver's static TF: one parent per frame, and the
chain through the driver's edge gives the calibrated pose."""

from collections import Counter

import numpy as np
from scipy.spatial.transform import Rotation

from hiros_core.calibration import Calibration, CameraCalibration
from hiros_core.frames import (
    AZURE_KINECT_MOUNT,
    DIRECT_MOUNT,
    CameraMount,
    StaticTransform,
    camera_transforms,
)
from hiros_core.geometry import RigidTransform


def _calibration() -> Calibration:
    rng = np.random.default_rng(5)
    cameras = {
        name: CameraCalibration(
            f"{name}_depth_camera_link",
            translation=rng.normal(0, 2, 3),
            rotation=Rotation.random(random_state=i).as_quat(),
        )
        for i, name in enumerate(["k01", "k02", "k03"])
    }
    cameras["k01"] = CameraCalibration("k01_depth_camera_link")  # the reference
    cameras["lidar"] = CameraCalibration("lidar_optical", translation=np.ones(3))  # no driver
    return Calibration("k01", cameras=cameras)


def _driver_tree(prefix: str) -> list[StaticTransform]:
    """What the Azure Kinect ROS driver publishes on /tf_static for one camera (values aside
    from camera_base -> depth_camera_link do not matter here)."""
    fixed = AZURE_KINECT_MOUNT.fixed
    identity = (np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))
    return [
        StaticTransform(f"{prefix}camera_base", f"{prefix}depth_camera_link",
                        fixed.translation, fixed.quaternion),
        StaticTransform(f"{prefix}depth_camera_link", f"{prefix}rgb_camera_link", *identity),
        StaticTransform(f"{prefix}depth_camera_link", f"{prefix}imu_link", *identity),
    ]  # fmt: skip


def _chain(edges: list[StaticTransform], frame: str) -> tuple[list[str], RigidTransform]:
    """The frames from ``frame`` up to the root, and ``frame -> root``."""
    parents = {e.child: e for e in edges}
    path, pose = [frame], RigidTransform.identity()
    while frame in parents:
        edge = parents[frame]
        pose = RigidTransform.from_quaternion(edge.rotation, edge.translation) @ pose
        frame = edge.parent
        path.append(frame)
    return path, pose


def test_one_parent_per_frame_with_the_drivers_tree():
    calibration = _calibration()
    ours = camera_transforms(calibration)
    edges = ours + [e for name in ("k01", "k02", "k03") for e in _driver_tree(f"{name}_")]
    parents = Counter(e.child for e in edges)
    assert max(parents.values()) == 1, parents
    assert "world" not in parents  # the root
    for name, camera in calibration.cameras.items():
        path, pose = _chain(edges, camera.frame_id)
        assert path[-1] == "world"
        if name != "lidar":
            assert path == [camera.frame_id, f"{name}_camera_base", "world"]
        expected = camera.extrinsics
        assert np.allclose(pose.translation, expected.translation, atol=1e-9)
        assert (pose.rotation * expected.rotation.inv()).magnitude() < 1e-9


def test_azure_kinect_fixed_transform_is_the_drivers():
    """Depth camera 6 degrees below camera_base's x axis, optical axes, 1.8 mm up."""
    fixed = AZURE_KINECT_MOUNT.fixed
    forward, down, right = fixed.rotate(np.eye(3)[[2, 1, 0]])
    tilt = np.radians(6.0)
    assert np.allclose(forward, [np.cos(tilt), 0.0, -np.sin(tilt)], atol=1e-7)
    assert np.allclose(down, [-np.sin(tilt), 0.0, -np.cos(tilt)], atol=1e-7)
    assert np.allclose(right, [0.0, -1.0, 0.0], atol=1e-7)
    assert np.allclose(fixed.translation, [0.0, 0.0, 0.0018])
    assert np.isclose(np.linalg.norm(AZURE_KINECT_MOUNT.base_to_frame[3:]), 1.0)


def test_direct_and_custom_mounts():
    calibration = _calibration()
    direct = camera_transforms(calibration, DIRECT_MOUNT)
    assert {e.child for e in direct} == {c.frame_id for c in calibration.cameras.values()}
    other = CameraMount(
        frame_suffix="optical", base_suffix="base", base_to_frame=(1, 0, 0, 0, 0, 0, 1)
    )
    edges = {e.child: e for e in camera_transforms(calibration, other)}
    assert "lidar_base" in edges
    assert np.allclose(edges["lidar_base"].translation, [0.0, 1.0, 1.0])


def test_recording_tree_encodes_as_tf2s_message():
    """A run's /tf_static: ours and the driver's edges, decoded by another CDR reader."""
    from rosbags.typesys import Stores, get_typestore

    from hiros_core.frames import encode_tf_message, recording_transforms

    calibration = _calibration()
    edges = recording_transforms(calibration)
    assert max(Counter(e.child for e in edges).values()) == 1
    message = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(
        encode_tf_message(edges, 1_700_000_000_123_456_789), "tf2_msgs/msg/TFMessage"
    )
    assert len(message.transforms) == len(edges) == 7  # 4 cameras, 3 with a driver tree
    for edge, decoded in zip(edges, message.transforms, strict=True):
        assert (decoded.header.stamp.sec, decoded.header.stamp.nanosec) == (1700000000, 123456789)
        assert (decoded.header.frame_id, decoded.child_frame_id) == (edge.parent, edge.child)
        t, q = decoded.transform.translation, decoded.transform.rotation
        assert np.allclose([t.x, t.y, t.z, q.x, q.y, q.z, q.w], [*edge.translation, *edge.rotation])


def test_a_world_named_after_a_camera_frame_is_not_its_child():
    calibration = Calibration(
        "k01", world_frame="k01_depth_camera_link",
        cameras={"k01": CameraCalibration("k01_depth_camera_link")},
    )  # fmt: skip
    assert camera_transforms(calibration) == []
