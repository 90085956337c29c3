"""What RecordingWriter adds as rosbag2 Jazzy does: channel metadata, the bag metadata record,
the first-message log time of what describes the whole recording; older files still read."""

import re

import yaml
from mcap.reader import make_reader
from mcap.writer import Writer as McapLibraryWriter
from mcap_ros2.decoder import DecoderFactory

from hiros_core.codec import encode_group
from hiros_core.recording import SKELETON_GROUP, RecordingWriter, iter_groups
from hiros_core.recording.msgdefs import DELIMITER, message_definition, type_hash

STRING = "std_msgs/msg/String"
HELLO = b"\x00\x01\x00\x00\x06\x00\x00\x00hello\x00"


def _summary(path):
    with path.open("rb") as stream:
        reader = make_reader(stream)
        summary = reader.get_summary()
        records = list(reader.iter_metadata())
        messages = [(c.topic, m.log_time) for _, c, m in reader.iter_messages(log_time_order=False)]
    return summary, records, messages


def test_channels_carry_qos_and_type_hash(tmp_path, samples):
    path = tmp_path / "out.mcap"
    with RecordingWriter(path) as writer:
        writer.write_group("/k01/skeletons", samples.make_group(0))
        writer.write("/tf_static", "tf2_msgs/msg/TFMessage", b"\x00\x01\x00\x00\x00\x00\x00\x00", 1)
    summary, _, _ = _summary(path)
    channels = {c.topic: c.metadata for c in summary.channels.values()}
    stream = yaml.safe_load(channels["/k01/skeletons"]["offered_qos_profiles"])
    latched = yaml.safe_load(channels["/tf_static"]["offered_qos_profiles"])
    assert stream[0]["reliability"] == "reliable"
    assert stream[0]["durability"] == "volatile"
    assert (latched[0]["durability"], latched[0]["depth"]) == ("transient_local", 1)
    assert channels["/k01/skeletons"]["topic_type_hash"] == type_hash(SKELETON_GROUP)
    assert channels["/tf_static"]["topic_type_hash"].startswith("RIHS01_")


def test_rosbag2_metadata_record_matches_the_file(tmp_path, samples):
    path = tmp_path / "bag"
    with RecordingWriter(path) as writer:
        for index in range(3):
            writer.write_group("/k01/skeletons", samples.make_group(index))
    summary, records, _ = _summary(path / "bag_0.mcap")
    assert summary.statistics.metadata_count == 1
    assert [index.name for index in summary.metadata_indexes] == ["rosbag2"]
    (record,) = records
    assert record.metadata["ROS_DISTRO"] == "jazzy"
    info = yaml.safe_load(record.metadata["serialized_metadata"])
    folder = yaml.safe_load((path / "metadata.yaml").read_text())["rosbag2_bagfile_information"]
    assert info == folder
    assert info["version"] == 9
    assert info["message_count"] == 3
    assert info["duration"]["nanoseconds"] == 2 * samples.PERIOD
    (topic,) = info["topics_with_message_count"]
    assert isinstance(topic["topic_metadata"]["offered_qos_profiles"], list)  # version 9: a list
    assert topic["topic_metadata"]["type_description_hash"] == type_hash(SKELETON_GROUP)


def test_initial_message_takes_the_first_data_time(tmp_path, samples):
    path = tmp_path / "out.mcap"
    with RecordingWriter(path) as writer:
        writer.write_initial("/hiros/calibration", STRING, HELLO)
        writer.write_group("/hiros/filter", samples.make_group(0))
        writer.write_group("/hiros/filter", samples.make_group(1))
    summary, _, messages = _summary(path)
    assert messages[0] == ("/hiros/calibration", samples.T0)
    assert summary.statistics.message_start_time == samples.T0


def test_initial_message_alone_is_kept(tmp_path):
    path = tmp_path / "out.mcap"
    with RecordingWriter(path) as writer:
        writer.write_initial("/hiros/calibration", STRING, HELLO)
    _, _, messages = _summary(path)
    assert messages == [("/hiros/calibration", 0)]


def test_files_with_the_older_schema_labels_still_read(tmp_path, samples):
    """Before rosbag2's labels, our schemas said ``MSG: std_msgs/msg/Header``: still read."""
    text = message_definition(SKELETON_GROUP)
    old_text = re.sub(r"\nMSG: (\w+)/(\w+)\n", r"\nMSG: \1/msg/\2\n", text)
    assert f"{DELIMITER}\nMSG: std_msgs/msg/Header\n" in old_text
    path = tmp_path / "old.mcap"
    group = samples.make_group(0)
    with path.open("wb") as stream:
        writer = McapLibraryWriter(stream)
        writer.start(profile="ros2", library="hiros")
        schema = writer.register_schema(SKELETON_GROUP, "ros2msg", old_text.encode())
        channel = writer.register_channel("/k01/skeletons", "cdr", schema)
        writer.add_message(channel, group.stamp_ns, encode_group(group), group.stamp_ns)
        writer.finish()
    ((_, read),) = list(iter_groups(path))
    assert read.same_as(group)
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        ((_, _, _, decoded),) = list(reader.iter_decoded_messages())
    assert decoded.header.frame_id == group.frame_id
    assert len(decoded.skeletons) == len(group.skeletons)
