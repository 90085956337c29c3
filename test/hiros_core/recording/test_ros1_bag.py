"""ROS 1 bags (how UNIPD-BPE ships its recordings): read as ROS 2 CDR and as groups."""

from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag1 import Writer as Rosbag1Writer
from rosbags.typesys import Stores, get_typestore

from hiros_core.codec import decode_marker_array
from hiros_core.errors import RecordingError
from hiros_core.recording import MARKER_ARRAY, RecordingReader, iter_groups

SHARED_DATA = Path(__file__).resolve().parents[4] / "shared" / "data"
UNIPD_POS = SHARED_DATA / "unipd_bpe_sample" / "sbj01_bend1KinectPos.csv"


def _ros1_marker_array(store, stamp_ns, frame, body_id, positions):
    types = store.types
    time = types["builtin_interfaces/msg/Time"](sec=stamp_ns // 10**9, nanosec=stamp_ns % 10**9)
    markers = []
    for joint, (x, y, z) in enumerate(positions):
        markers.append(
            types["visualization_msgs/msg/Marker"](
                header=types["std_msgs/msg/Header"](seq=joint, stamp=time, frame_id=frame),
                ns="",
                id=body_id * 100 + joint,
                type=2,
                action=0,
                pose=types["geometry_msgs/msg/Pose"](
                    position=types["geometry_msgs/msg/Point"](x=x, y=y, z=z),
                    orientation=types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
                ),
                scale=types["geometry_msgs/msg/Vector3"](x=0.05, y=0.05, z=0.05),
                color=types["std_msgs/msg/ColorRGBA"](r=1.0, g=0.0, b=0.0, a=1.0),
                lifetime=types["builtin_interfaces/msg/Duration"](sec=0, nanosec=250_000_000),
                frame_locked=False,
                points=[],
                colors=[],
                text=str(joint % 4),
                mesh_resource="",
                mesh_use_embedded_materials=False,
            )
        )
    return types["visualization_msgs/msg/MarkerArray"](markers=markers)


def test_ros1_driver_bag_from_unipd_frames(tmp_path):
    if not UNIPD_POS.is_file():
        pytest.skip(f"{UNIPD_POS} is not available")
    csv = UNIPD_POS
    table = np.loadtxt(csv, delimiter=",", skiprows=1, max_rows=20)
    stamps_ns = table[:, 0].astype(np.int64) * 1_000_000
    positions = table[:, 1:].reshape(len(table), 32, 3)
    store = get_typestore(Stores.ROS1_NOETIC)
    bag = tmp_path / "sbj01_bend1.bag"
    with Rosbag1Writer(bag) as writer:
        connection = writer.add_connection(
            "/k01/body_tracking_data", "visualization_msgs/msg/MarkerArray", typestore=store
        )
        for stamp, frame_positions in zip(stamps_ns, positions, strict=True):
            message = _ros1_marker_array(
                store, int(stamp), "k01_depth_camera_link", 1, frame_positions
            )
            raw = store.serialize_ros1(message, "visualization_msgs/msg/MarkerArray")
            writer.write(connection, int(stamp), raw)

    with RecordingReader(bag) as reader:
        assert reader.topics == {"/k01/body_tracking_data": MARKER_ARRAY}
        first = next(reader.messages())
    markers = decode_marker_array(first.data)  # ROS 2 Jazzy CDR now
    assert len(markers) == 32
    assert markers.ids[5] == 105
    np.testing.assert_array_equal(markers.poses[:, :3], positions[0])
    assert markers.texts[:4] == ["0", "1", "2", "3"]
    assert markers.lifetimes_ns[0] == 250_000_000

    drops = Counter()
    groups = list(iter_groups(bag, drops=drops))
    assert [source for source, _ in groups] == ["k01"] * 20
    assert [g.stamp_ns for _, g in groups] == stamps_ns.tolist()
    skeleton = groups[-1][1].skeletons[0]
    assert skeleton.id == 1
    assert skeleton.src_frame == "k01_depth_camera_link"
    np.testing.assert_array_equal(skeleton.positions, positions[-1])
    np.testing.assert_allclose(skeleton.confidences[:4], [0, 1 / 3, 2 / 3, 1])
    assert sum(drops.values()) == 0


def test_a_bag_without_its_index_is_refused_with_the_repair(tmp_path):
    """A ROS 1 recorder killed mid-take leaves a .bag.active with no index at its end."""
    store = get_typestore(Stores.ROS1_NOETIC)
    bag = tmp_path / "take.bag"
    with Rosbag1Writer(bag) as writer:
        connection = writer.add_connection("/note", "std_msgs/msg/String", typestore=store)
        for k in range(500):
            note = store.types["std_msgs/msg/String"](data=f"{k}" * 200)
            writer.write(connection, 10**9 + k, store.serialize_ros1(note, "std_msgs/msg/String"))
    data = bag.read_bytes()
    for name in ("cut.bag", "take.bag.active"):
        cut = tmp_path / name
        cut.write_bytes(data[: len(data) * 2 // 3])
        with pytest.raises(RecordingError, match="rosbag reindex"):
            RecordingReader(cut)
