"""RecordingWriter -> RecordingReader / rosbags / mcap round trips, truncation, bad paths."""

from collections import Counter

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from rosbags.highlevel import AnyReader
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Rosbag2Writer

from hiros_core.codec import decode_group, decode_marker_array, encode_group
from hiros_core.driver import DriverBridge
from hiros_core.errors import RecordingError
from hiros_core.recording import (
    MARKER_ARRAY,
    SKELETON_GROUP,
    RecordingReader,
    RecordingWriter,
    iter_groups,
    iter_logged_groups,
    read_camera_groups,
    source_name,
)


@pytest.fixture(name="driver_frames")
def _driver_frames(samples):
    return samples.driver_frames()


def _write(path, driver_frames, **kwargs):
    with RecordingWriter(path, **kwargs) as writer:
        for topic, group, markers in driver_frames:
            writer.write_marker_array(topic, markers)
            writer.write_group(topic.replace("body_tracking_data", "skeletons"), group)
    return writer


def test_single_mcap_round_trip(tmp_path, driver_frames, samples):
    path = tmp_path / "take.mcap"
    _write(path, driver_frames)
    with RecordingReader(path) as reader:
        assert reader.topics == {
            "/k01/body_tracking_data": MARKER_ARRAY,
            "/k02/body_tracking_data": MARKER_ARRAY,
            "/k01/skeletons": SKELETON_GROUP,
            "/k02/skeletons": SKELETON_GROUP,
        }
        messages = list(reader.messages())
    assert len(messages) == 200
    times = [m.log_time_ns for m in messages]
    assert times == sorted(times)
    assert times[0] == samples.T0
    first = next(m for m in messages if m.topic == "/k01/skeletons")
    assert decode_group(first.data).same_as(driver_frames[0][1])
    markers = decode_marker_array(messages[0].data)
    assert len(markers) == 64


def test_groups_from_both_kinds_of_topic_agree(tmp_path, driver_frames):
    path = tmp_path / "take.mcap"
    _write(path, driver_frames)
    drops = Counter()
    by_topic = {}
    for source, group in iter_groups(path, drops=drops):
        by_topic.setdefault(source, []).append(group)
    assert sorted(by_topic) == ["k01", "k02"]
    assert len(by_topic["k01"]) == 100  # 50 from the driver topic, 50 from the group topic
    driver, decoded = by_topic["k01"][0::2], by_topic["k01"][1::2]
    for a, b in zip(driver, decoded, strict=True):
        assert a.same_as(b)
    assert sum(drops.values()) == 0


def test_other_tools_open_the_file(tmp_path, driver_frames):
    path = tmp_path / "take.mcap"
    _write(path, driver_frames[:4])
    with AnyReader([path]) as reader:
        assert reader.message_count == 8
        for connection, _, raw in reader.messages():
            message = reader.deserialize(raw, connection.msgtype)
            if connection.msgtype == SKELETON_GROUP:
                assert len(message.skeletons) == 2
                assert message.skeletons[0].markers[0].confidence == 1.0
            else:
                assert message.markers[0].id == 100
    with path.open("rb") as stream:
        reader = make_reader(stream, decoder_factories=[DecoderFactory()])
        decoded = list(reader.iter_decoded_messages())
    assert len(decoded) == 8
    group = next(d for _, c, _, d in decoded if c.topic == "/k01/skeletons")
    expected = driver_frames[0][1].skeletons[0].positions[0]
    position = group.skeletons[0].markers[0].center.pose.position
    np.testing.assert_allclose([position.x, position.y, position.z], expected)


def test_folder_with_metadata(tmp_path, driver_frames, samples):
    folder = tmp_path / "bag"
    _write(folder, driver_frames[:10])
    assert (folder / "metadata.yaml").is_file()
    with AnyReader([folder]) as reader:
        assert reader.message_count == 20
        assert reader.start_time == samples.T0
    with RecordingReader(folder) as reader:
        assert len(list(reader.messages({"/k01/skeletons"}))) == 5
        assert not reader.problems


def test_folder_without_metadata_merges_files_in_time_order(tmp_path, samples):
    folder = tmp_path / "crashed"
    folder.mkdir()
    for part, indices in enumerate(([0, 2, 4], [1, 3, 5])):
        with RecordingWriter(folder / f"part_{part}.mcap") as writer:
            for index in indices:
                writer.write_group("/k01/skeletons", samples.make_group(index))
    with RecordingReader(folder) as reader:
        stamps = [decode_group(m.data).stamp_ns for m in reader.messages()]
        assert "no metadata.yaml" in reader.problems[0]
    assert stamps == [samples.T0 + i * samples.PERIOD for i in range(6)]


def test_messages_out_of_order_in_the_file_come_out_in_time_order(tmp_path, samples):
    path = tmp_path / "late.mcap"
    with RecordingWriter(path, chunk_size=2000) as writer:
        for index in (3, 1, 0, 2, 5, 4):
            writer.write_group("/k01/skeletons", samples.make_group(index), samples.T0 + index)
            writer.write_group("/k02/skeletons", samples.make_group(index), samples.T0 + index)
    with RecordingReader(path) as reader:
        times = [m.log_time_ns for m in reader.messages()]
    assert times == sorted(times)
    assert len(times) == 12


def test_chunk_reading_keeps_the_mcap_readers_order(tmp_path, samples):
    """Overlapping chunks and equal log times: the order of the ``mcap`` library's reader."""
    path = tmp_path / "overlap.mcap"
    with RecordingWriter(path, chunk_size=60_000) as writer:
        for index in (3, 1, 0, 2, 5, 4, 4, 9, 6, 8, 7, 7):
            for camera in ("k01", "k02"):
                group = samples.make_group(index, camera)
                writer.write_group(f"/{camera}/skeletons", group, samples.T0 + index)
    with path.open("rb") as stream:
        reader = make_reader(stream)
        assert len(reader.get_summary().chunk_indexes) > 3
        expected = [(c.topic, m.log_time, m.data) for _, c, m in reader.iter_messages()]
        only_k02 = [e for e in expected if e[0] == "/k02/skeletons"]
    with RecordingReader(path) as recording:
        read = [(m.topic, m.log_time_ns, m.data) for m in recording.messages()]
        batched = [
            (m.topic, m.log_time_ns, m.data) for b in recording.batches() for m in b.messages()
        ]
        some = [(m.topic, m.log_time_ns, m.data) for m in recording.messages({"/k02/skeletons"})]
        transient = [  # each batch read before the next replaces its buffer
            (m.topic, m.log_time_ns, m.data)
            for b in recording.batches(transient=True)
            for m in list(b.messages())
        ]
    assert read == batched == transient == expected
    assert some == only_k02


def test_logged_groups_and_the_camera_groups_of_a_calibration(tmp_path, driver_frames):
    path = tmp_path / "take.mcap"
    _write(path, driver_frames)
    with RecordingReader(path) as reader:
        log_times = [m.log_time_ns for m in reader.messages(["/k01/body_tracking_data"])]
    logged = list(iter_logged_groups(path, topics=["/k01/body_tracking_data"]))
    assert [t for _, _, t in logged] == log_times
    plain = list(iter_groups(path, topics=["/k01/body_tracking_data"]))
    assert all(a[1].same_as(b[1]) for a, b in zip(logged, plain, strict=True))
    groups, arrivals = read_camera_groups(path)
    every = list(iter_logged_groups(path))
    assert sorted(groups) == ["k01", "k02"]
    for camera in groups:
        mine = [(group, t) for source, group, t in every if source == camera]
        assert arrivals[camera] == [t for _, t in mine]
        assert all(a.same_as(b) for a, (b, _) in zip(groups[camera], mine, strict=True))


def _one_message_at_a_time(path):
    """``iter_logged_groups`` of ``path`` by the codec and a bridge per topic, message after
    message (the reference the batch reading is held to)."""
    bridges, out = {}, []
    with RecordingReader(path) as reader:
        for message in reader.messages():
            if message.msgtype == SKELETON_GROUP:
                group = decode_group(message.data)
            else:
                group = bridges.setdefault(message.topic, DriverBridge()).update_bytes(message.data)
            if group is not None:
                out.append((source_name(message.topic), group, message.log_time_ns))
    return out


def test_the_first_batch_read_in_growing_pieces_gives_every_group_once(tmp_path, driver_frames):
    path = tmp_path / "take.mcap"
    _write(path, driver_frames)  # one chunk of 200 messages: pieces of 8, 16, 32, 64, 80
    with RecordingReader(path) as reader:
        assert len(next(reader.batches())) > 8 + 16 + 32 + 64
        head, tail = next(reader.batches()).split(8)
        whole = list(next(reader.batches()).messages())
        assert [m for batch in (head, tail) for m in batch.messages()] == whole
    in_pieces = list(iter_logged_groups(path))
    one_by_one = _one_message_at_a_time(path)
    assert [(s, t) for s, _, t in in_pieces] == [(s, t) for s, _, t in one_by_one]
    assert all(a[1].same_as(b[1]) for a, b in zip(in_pieces, one_by_one, strict=True))


def test_truncated_mcap_reads_what_it_can(tmp_path, driver_frames):
    path = tmp_path / "cut.mcap"
    _write(path, driver_frames, chunk_size=20_000)
    data = path.read_bytes()
    path.write_bytes(data[: int(len(data) * 0.6)])
    with RecordingReader(path) as reader:
        assert set(reader.topics) >= {"/k01/body_tracking_data", "/k01/skeletons"}
        messages = list(reader.messages())
        assert 0 < len(messages) < 200
        assert reader.drops["truncated"] == 1
        assert "ends early" in reader.problems[0]
    for message in messages:  # whatever was read is whole
        if message.msgtype == SKELETON_GROUP:
            decode_group(message.data)
    drops, problems = Counter(), []
    groups = list(iter_groups(path, drops=drops, problems=problems))
    assert len(groups) == len(messages)
    assert not drops  # every message read became a group; how many the cut took is unknown
    assert "ends early" in problems[0]


@pytest.mark.parametrize("compression", ["zstd", "lz4", "none"])
def test_a_chunk_cut_by_the_files_end_gives_its_whole_messages(
    tmp_path, driver_frames, compression
):
    """A recorder killed while writing a chunk: the messages at the chunk's start are read.

    zstd and lz4 decompress a block (up to 128 or 64 kB) at a time: the chunk is larger.
    """
    path = tmp_path / "take.mcap"
    _write(path, driver_frames, chunk_size=400_000, compression=compression)
    with RecordingReader(path) as reader:
        whole = [m.data for m in reader.messages()]
    (start, length), *_ = _chunk_offsets(path)[1:]
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: start + int(length * 0.7)])
    complete = tmp_path / "complete.mcap"  # the same file cut before that chunk instead
    complete.write_bytes(path.read_bytes()[:start])
    with RecordingReader(complete) as reader:
        before = len(list(reader.messages()))
    with RecordingReader(cut) as reader:
        read = [m.data for m in reader.messages()]
        assert reader.drops["truncated"] == 1
        assert "from the chunk the end cuts" in reader.problems[0]
    assert before < len(read) < len(whole)
    assert read == whole[: len(read)]  # each one whole, in the file's order


def test_sqlite3_file(tmp_path, samples):
    folder = tmp_path / "sq"
    writer = Rosbag2Writer(folder, version=9, storage_plugin=StoragePlugin.SQLITE3)
    with writer:
        from rosbags.typesys import Stores, get_typestore

        store = get_typestore(Stores.ROS2_JAZZY)
        text = (tmp_path / "dummy").as_posix()  # any string payload
        connection = writer.add_connection("/note", "std_msgs/msg/String", typestore=store)
        raw = store.serialize_cdr(
            store.types["std_msgs/msg/String"](data=text), "std_msgs/msg/String"
        )
        writer.write(connection, samples.T0, raw)
    (db3,) = folder.glob("*.db3")
    for path in (folder, db3):
        with RecordingReader(path) as reader:
            (message,) = reader.messages()
            assert message.topic == "/note"
            assert message.msgtype == "std_msgs/msg/String"
            assert message.data == bytes(raw)


def test_bad_paths(tmp_path):
    with pytest.raises(RecordingError, match="does not exist"):
        RecordingReader(tmp_path / "none.mcap")
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"this is not a recording at all")
    with pytest.raises(RecordingError, match="not an MCAP file"):
        RecordingReader(junk)
    other = tmp_path / "take.txt"
    other.write_text("x")
    with pytest.raises(RecordingError, match="not a recording"):
        RecordingReader(other)
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(RecordingError, match="holds no recording"):
        RecordingReader(empty)
    broken = tmp_path / "broken.db3"
    broken.write_bytes(b"SQLite format 3\x00" + b"\x00" * 50)
    with pytest.raises(RecordingError, match=r"broken\.db3"):
        RecordingReader(broken)


def test_writer_refuses_existing_path_and_bad_compression(tmp_path):
    path = tmp_path / "x.mcap"
    path.write_bytes(b"")
    with pytest.raises(RecordingError, match="exists already"):
        RecordingWriter(path)
    with pytest.raises(RecordingError, match="compression"):
        RecordingWriter(tmp_path / "y.mcap", compression="brotli")


def test_undecodable_messages_are_counted(tmp_path, samples):
    path = tmp_path / "bad.mcap"
    good = encode_group(samples.make_group(0))
    with RecordingWriter(path) as writer:
        writer.write("/k01/skeletons", SKELETON_GROUP, good[: len(good) // 2], samples.T0)
        writer.write("/k01/skeletons", SKELETON_GROUP, good, samples.T0 + 1)
        writer.write(
            "/k01/body_tracking_data", MARKER_ARRAY, b"\x00\x01\x00\x00\x05", samples.T0 + 2
        )
    drops = Counter()
    groups = list(iter_groups(path, drops=drops))
    assert len(groups) == 1
    assert drops["undecodable"] == 2


def test_a_write_error_in_the_writer_thread_reaches_the_caller():
    import io

    from hiros_core.recording.mcap_out import McapWriter

    class FullDisk(io.BytesIO):
        writes = 0

        def write(self, data):
            self.writes += 1
            if self.writes > 3:
                raise OSError("disk full")
            return super().write(data)

    writer = McapWriter(FullDisk(), chunk_size=100)
    writer.start()
    channel = writer.register_channel("/a", "cdr", writer.register_schema("x/msg/Y", "", b""), {})

    def write_all() -> None:
        for stamp in range(200):
            writer.add_message(channel, stamp, b"x" * 50, stamp, stamp)
        writer.finish()

    with pytest.raises(OSError, match="disk full"):
        write_all()
    writer.abort()


def test_chunks_hold_messages_larger_than_their_buffer_and_reserved_space_commits():
    import io

    from mcap.reader import make_reader

    from hiros_core.recording.mcap_out import McapWriter

    stream = io.BytesIO()
    writer = McapWriter(stream, chunk_size=1000)
    writer.start()
    channel = writer.register_channel("/a", "cdr", writer.register_schema("x/msg/Y", "", b""), {})
    payloads = [bytes([k]) * size for k, size in enumerate([10, 3 << 20, 700, 5, 2 << 20])]
    for stamp, payload in enumerate(payloads):
        if stamp % 2:  # written in place, as RecordingWriter.write_group does
            at = writer.reserve(len(payload))
            writer.buffer[at : at + len(payload)] = np.frombuffer(payload, dtype=np.uint8)
            writer.commit(channel, stamp, len(payload), stamp, stamp + 1)
        else:
            writer.add_message(channel, stamp, payload, stamp, stamp + 1)
    at = writer.reserve(4)  # reserved but never committed: not in the file
    writer.buffer[at : at + 4] = 7
    writer.finish()
    stream.seek(0)
    read = [bytes(m.data) for _, _, m in make_reader(stream).iter_messages()]
    assert read == payloads


def _chunk_offsets(path):
    """(start, length) of each chunk record, from the file's summary."""
    with path.open("rb") as stream:
        summary = make_reader(stream).get_summary()
    return [(c.chunk_start_offset, c.chunk_length) for c in summary.chunk_indexes]


def _damaged_copy(path, out, offset):
    data = bytearray(path.read_bytes())
    data[offset] ^= 0xFF
    out.write_bytes(bytes(data))
    return out


@pytest.mark.parametrize("transient", [False, True])
def test_a_damaged_chunk_is_skipped_and_counted(tmp_path, driver_frames, transient):
    path = tmp_path / "take.mcap"
    _write(path, driver_frames, chunk_size=20_000)
    (start, length), *rest = _chunk_offsets(path)[1:]
    assert rest
    damaged = _damaged_copy(path, tmp_path / "damaged.mcap", start + length // 2)
    with RecordingReader(path) as reader:
        whole = [b.data(i) for b in reader.batches() for i in range(len(b))]
    with RecordingReader(damaged) as reader:
        read = [b.data(i) for b in reader.batches(transient=transient) for i in range(len(b))]
        lost = reader.drops["damaged_chunk"]
        assert "chunk at byte" in reader.problems[0]
    assert 0 < lost < 200
    assert len(read) + lost == len(whole) == 200
    assert set(read) <= set(whole)


def test_a_damaged_chunk_of_a_file_without_summary_is_skipped(tmp_path, driver_frames):
    path = tmp_path / "take.mcap"
    _write(path, driver_frames, chunk_size=20_000)
    chunks = _chunk_offsets(path)
    cut = chunks[-1][0] + chunks[-1][1]  # the last chunk ends there: no index, no summary
    start, length = chunks[1]
    damaged = _damaged_copy(path, tmp_path / "damaged.mcap", start + length // 2)
    damaged.write_bytes(damaged.read_bytes()[:cut])
    with RecordingReader(damaged) as reader:
        read = list(reader.messages())
        assert reader.drops["damaged_chunk"] == 1
        assert "damaged" in reader.problems[0]
    assert 0 < len(read) < 200
    last = driver_frames[-1][1].stamp_ns
    assert read[-1].log_time_ns == last  # the chunks after the damaged one are read


def test_a_damaged_summary_is_not_trusted(tmp_path, driver_frames):
    path = tmp_path / "take.mcap"
    _write(path, driver_frames, chunk_size=20_000)
    damaged = _damaged_copy(path, tmp_path / "damaged.mcap", len(path.read_bytes()) - 60)
    with RecordingReader(damaged) as reader:
        assert len(list(reader.messages())) == 200
        assert "summary" in reader.problems[0]
        assert not reader.drops


def test_a_file_cut_before_any_topic_is_refused(tmp_path, driver_frames):
    path = tmp_path / "take.mcap"
    _write(path, driver_frames)
    path.write_bytes(path.read_bytes()[:100])
    with pytest.raises(RecordingError, match="before any topic is defined"):
        RecordingReader(path)


def test_iter_groups_hands_the_readers_problems_on(tmp_path, driver_frames):
    path = tmp_path / "cut.mcap"
    _write(path, driver_frames, chunk_size=20_000)
    path.write_bytes(path.read_bytes()[: int(path.stat().st_size * 0.6)])
    problems: list[str] = []
    assert list(iter_groups(path, problems=problems))
    assert len(problems) == 1
    assert "ends early" in problems[0]


@pytest.mark.parametrize("name", ["take.mcap", "take"])
def test_discard_removes_what_the_writer_made(tmp_path, driver_frames, name):
    writer = _write(tmp_path / name, driver_frames[:4])
    writer.discard()
    assert not (tmp_path / name).exists()
    folder = tmp_path / "kept"
    writer = RecordingWriter(folder)
    (folder / "notes.txt").write_text("mine")
    writer.discard()
    assert [p.name for p in folder.iterdir()] == ["notes.txt"]


def test_discard_on_error_removes_the_output_of_a_failed_block_only(tmp_path):
    def write_then_raise(path, error, options):
        with RecordingWriter(path, **options) as writer:
            writer.write("/t", "std_msgs/msg/String", b"\x00\x01\x00\x00\x01\x00\x00\x00\x00", 1)
            raise error

    def fail(path, error, **options):
        with pytest.raises(type(error)):
            write_then_raise(path, error, options)

    fail(tmp_path / "failed.mcap", ValueError("bad frame"), discard_on_error=True)
    assert not (tmp_path / "failed.mcap").exists()
    fail(tmp_path / "stopped.mcap", KeyboardInterrupt(), discard_on_error=True)  # Ctrl-C keeps it
    assert (tmp_path / "stopped.mcap").exists()
    fail(tmp_path / "kept.mcap", ValueError("bad frame"))  # the default keeps what was written
    assert (tmp_path / "kept.mcap").exists()
    with RecordingWriter(tmp_path / "fine.mcap", discard_on_error=True):
        pass
    assert (tmp_path / "fine.mcap").exists()


def test_a_time_mcap_cannot_hold_is_refused_and_the_file_still_closes(tmp_path, samples):
    path = tmp_path / "take.mcap"
    group = samples.make_group(0)
    with RecordingWriter(path) as writer:
        writer.write("/note", "std_msgs/msg/String", b"\x00\x01\x00\x00\x01\x00\x00\x00\x00", 5)
        for bad in (-1, 1 << 64):
            with pytest.raises(RecordingError, match="cannot be recorded"):
                writer.write("/note", "std_msgs/msg/String", b"\x00\x01\x00\x00", bad)
            with pytest.raises(RecordingError, match="cannot be recorded"):
                writer.write_group("/k01/skeletons", group, bad)
    with RecordingReader(path) as reader:
        assert [m.log_time_ns for m in reader.messages()] == [5]


def test_the_pipelines_outputs_are_not_camera_topics(tmp_path, samples):
    path = tmp_path / "session.mcap"
    with RecordingWriter(path) as writer:  # a live session recorded with every topic
        for index in range(3):
            group = samples.make_group(index)
            writer.write_group("/k01/skeletons", group)
            for stage in ("tracker", "merger", "optimizer", "filter"):
                writer.write_group(f"/hiros/{stage}", group)
    assert {source for source, _ in iter_groups(path)} == {"k01"}
