"""Azure Kinect driver MarkerArray <-> model: round trips and every bad input."""

import numpy as np
import pytest

from hiros_core.codec import (
    MarkerArrayData,
    decode_marker_array,
    decode_marker_fields,
    encode_marker_array,
)
from hiros_core.driver import (
    ADD,
    DELETE,
    DELETEALL,
    SPHERE,
    DriverBridge,
    DriverBridgeParams,
    group_to_driver_markers,
    load_bridge_params,
)
from hiros_core.errors import CodecError, ConfigError
from hiros_core.layouts import AZURE_KINECT, KINECT_V2
from hiros_core.model import Skeleton, SkeletonGroup

FRAME = "k01_depth_camera_link"
STAMP = 1_635_261_007_408_000_123


def _group(n_people=2, stamp=STAMP, layout=AZURE_KINECT, seed=0):
    rng = np.random.default_rng(seed)
    skeletons = []
    for person in range(n_people):
        positions = rng.normal([0.0, 0.0, 2.5], 0.4, size=(layout.n_joints, 3))
        orientations = rng.normal(size=(layout.n_joints, 4))
        orientations /= np.linalg.norm(orientations, axis=1, keepdims=True)
        levels = rng.integers(0, 4, layout.n_joints)
        skeletons.append(
            Skeleton.from_positions(
                positions,
                layout,
                skeleton_id=person + 1,
                src_time_ns=stamp,
                src_frame=FRAME,
                confidences=levels / 3,
                orientations=orientations,
            )
        )
    return SkeletonGroup(stamp, FRAME, skeletons)


def _markers(ids, positions=None, actions=None, stamps=None, texts=None):
    data = MarkerArrayData.new(len(ids), frame_id=FRAME, stamp_ns=STAMP)
    data.ids[:] = ids
    if positions is not None:
        data.poses[:, :3] = positions
    if actions is not None:
        data.actions[:] = actions
    if stamps is not None:
        data.stamps_ns[:] = stamps
    if texts is not None:
        data.texts = list(texts)
    return data


def test_driver_convention():
    group = _group()
    data = group_to_driver_markers(group)
    assert len(data) == 2 * 32
    assert data.ids[:3].tolist() == [100, 101, 102]
    assert data.ids[32] == 200
    assert (data.types == SPHERE).all()
    assert (data.actions == ADD).all()
    assert set(data.frame_ids) == {FRAME}
    assert (data.stamps_ns == STAMP).all()
    assert set(data.namespaces) == {""}
    levels = np.rint(group.skeletons[0].confidences * 3).astype(int)
    assert data.texts[:32] == [str(v) for v in levels]
    np.testing.assert_array_equal(data.poses[:32, :3], group.skeletons[0].positions)


def test_round_trip_through_cdr_is_exact():
    group = _group(3)
    group.skeletons[1].marker_present[[4, 9]] = False
    group.skeletons[1].markers[[4, 9]] = np.nan
    group.skeletons[1].update_links()
    group.skeletons[2].orientations[5] = np.nan  # unknown orientation
    group.skeletons[2].confidences[6] = np.nan  # no confidence level
    group.skeletons[2].update_links()
    raw = encode_marker_array(group_to_driver_markers(group))
    bridge = DriverBridge()
    out = bridge.update(decode_marker_array(raw))
    assert out is not None
    assert out.same_as(group)
    assert not bridge.drops


def test_kinect_v2_layout_travels_in_namespace():
    group = _group(1, layout=KINECT_V2)
    data = group_to_driver_markers(group)
    assert set(data.namespaces) == {"kinect_v2"}
    out = DriverBridge().update(data)
    assert out.skeletons[0].layout is KINECT_V2
    assert out.same_as(group)


def test_empty_array_and_deleteall():
    bridge = DriverBridge()
    assert bridge.update(MarkerArrayData.new(0)) is None
    assert bridge.drops["empty_array"] == 1
    clear = _markers([0], actions=[DELETEALL])
    out = bridge.update(clear)
    assert out is not None
    assert out.skeletons == []
    assert out.stamp_ns == STAMP
    # an unstamped DELETEALL after data neither gives a group nor restarts the clock
    bridge.update(_markers([100], positions=[[0, 0, 1]], stamps=[STAMP + 10]))
    assert bridge.update(_markers([0], actions=[DELETEALL], stamps=[0])) is None
    assert bridge.last_stamp_ns == STAMP + 10
    assert bridge.drops["deleteall_marker"] == 2


def test_bad_markers_are_counted_not_raised():
    ids = [100, 101, 101, 150, -5, 102, 103, 104, 105]
    positions = np.tile([0.1, 0.2, 2.0], (len(ids), 1))
    positions[2] = [9, 9, 9]  # duplicate of joint 1: the first copy stays
    positions[5] = [np.nan, 0.0, 1.0]
    positions[6] = [np.inf, 0.0, 1.0]
    actions = [ADD] * 7 + [DELETE, 7]
    texts = ["3", "x", "1", "", "", "", "", "", ""]
    bridge = DriverBridge()
    out = bridge.update(_markers(ids, positions, actions, texts=texts))
    assert bridge.drops == {
        "duplicate_marker": 1,
        "unknown_joint": 2,
        "nan_position": 2,
        "delete_marker": 1,
        "unknown_action": 1,
    }
    (skeleton,) = out.skeletons
    assert skeleton.id == 1
    assert np.flatnonzero(skeleton.marker_present).tolist() == [0, 1]
    np.testing.assert_array_equal(skeleton.positions[1], [0.1, 0.2, 2.0])
    assert skeleton.confidences[0] == 1.0
    assert np.isnan(skeleton.confidences[1])  # "x" is no level


def test_stamps_backwards_repeated_mixed_and_restart():
    bridge = DriverBridge()
    assert bridge.update(_markers([100], stamps=[STAMP])) is not None
    assert bridge.update(_markers([100], stamps=[STAMP])) is None
    assert bridge.update(_markers([100], stamps=[STAMP - 1000])) is None
    assert bridge.drops["repeated_stamp"] == 1
    assert bridge.drops["stamp_backwards"] == 1
    out = bridge.update(_markers([100, 101], stamps=[STAMP + 5, STAMP + 6]))
    assert out.stamp_ns == STAMP + 5
    assert bridge.drops["mixed_stamps"] == 1
    restarted = bridge.update(_markers([100], stamps=[STAMP - 10**10]))  # replay looped
    assert restarted is not None
    assert bridge.drops["source_restarted"] == 1


def test_generic_scheme_millimetres_and_joint_order(tmp_path):
    order = list(reversed(KINECT_V2.joint_names))
    spec = tmp_path / "driver.yaml"
    spec.write_text(
        "topic: /people\nlayout: kinect_v2\nid_scheme: joint_major\nid_stride: 1000\n"
        f"position_scale: 0.001\njoint_names: {order}\nframe_id: cam_link\n"
    )
    params, rest = load_bridge_params(spec)
    assert rest == {"topic": "/people"}
    bridge = DriverBridge(params)
    # driver joint 0 is the layout's last joint (ThumbRight); body 7
    data = _markers([0 * 1000 + 7, 24 * 1000 + 7], positions=[[1000, 0, 2000], [0, 500, 0]])
    out = bridge.update(data)
    (skeleton,) = out.skeletons
    assert skeleton.id == 7
    assert out.frame_id == "cam_link"
    np.testing.assert_allclose(skeleton.positions[KINECT_V2.index("ThumbRight")], [1, 0, 2])
    np.testing.assert_allclose(skeleton.positions[KINECT_V2.index("SpineBase")], [0, 0.5, 0])


def test_layout_file_relative_to_description(tmp_path):
    (tmp_path / "tiny.yaml").write_text("name: tiny\njoints: [a, b]\nparents: [-1, 0]\n")
    spec = tmp_path / "bridge.yaml"
    spec.write_text("layout: tiny.yaml\n")
    params, _ = load_bridge_params(spec)
    out = DriverBridge(params).update(_markers([300, 301, 302], positions=np.ones((3, 3))))
    assert out.skeletons[0].layout.name == "tiny"
    assert DriverBridge(params).drops["unknown_joint"] == 0


@pytest.mark.parametrize(
    "text",
    ["id_scheme: sideways\n", "id_stride: 0\n", "layout: nope\n", "joint_names: [Elbow]\n", "[1]"],
)
def test_bad_descriptions(tmp_path, text):
    spec = tmp_path / "bad.yaml"
    spec.write_text(text)
    with pytest.raises(ConfigError, match=r"bad\.yaml"):
        load_bridge_params(spec)


def test_unwritable_ids():
    group = _group(1)
    group.skeletons[0].id = -1
    with pytest.raises(CodecError, match="id -1"):
        group_to_driver_markers(group)
    assert len(group_to_driver_markers(SkeletonGroup(STAMP, FRAME, []))) == 0


def test_bridge_params_defaults_match_driver():
    params = DriverBridgeParams()
    assert (params.layout, params.id_stride, params.id_scheme) == (
        "azure_kinect",
        100,
        "body_major",
    )


def test_bytes_path_equals_decoded_path_frame_after_frame():
    """update_bytes (partial decode, cached id shapes) == update(decode_marker_array(...))."""
    frames = []
    for step in range(8):
        group = _group(3, stamp=STAMP + step * 33_000_000, seed=step)
        if step in (2, 3):  # a missing joint: the same ids twice in a row, not whole bodies
            group.skeletons[1].marker_present[7] = False
            group.skeletons[1].markers[7] = np.nan
            group.skeletons[1].update_links()
        data = group_to_driver_markers(group)
        if step == 4:  # the usual ids, but a NaN position: counted, not taken
            data.poses[5, 0] = np.nan
        if step == 5:  # out of order and a duplicate: sorted and counted
            data.ids[[0, 1]] = data.ids[[1, 0]]
            data.ids[40] = data.ids[39]
        if step == 6:  # some DELETE markers among the joints
            data.actions[10:12] = DELETE
        frames.append(encode_marker_array(data))
    frames.append(encode_marker_array(_markers([0], actions=[DELETEALL], stamps=[STAMP + 10**9])))
    by_bytes, by_columns = DriverBridge(), DriverBridge()
    for raw in frames + frames[:3]:  # the repeats go back in time: dropped by both
        fast, slow = by_bytes.update_bytes(raw), by_columns.update(decode_marker_array(raw))
        assert (fast is None and slow is None) or fast.same_as(slow)
    assert by_bytes.drops == by_columns.drops
    assert {"nan_position", "duplicate_marker", "delete_marker"} <= set(by_bytes.drops)
    with pytest.raises(CodecError):
        by_bytes.update_bytes(frames[0][:-9])


def test_compiled_frame_path_equals_the_numpy_path(monkeypatch):
    """The numba path for usual frames gives the numpy path's groups and drops."""
    frames = []
    for step in range(6):
        group = _group(2, stamp=STAMP + step * 33_000_000, seed=10 + step)
        group.skeletons[0].orientations[3] = np.nan  # written as a zero quaternion
        group.skeletons[1].confidences[4] = np.nan  # no level text
        data = group_to_driver_markers(group)
        if step == 3:  # not finite: the compiled path hands the frame to the numpy path
            data.poses[9, 2] = np.inf
        if step == 4:  # the same ids, a joint missing: people arranged by the cached rows
            data = group_to_driver_markers(group)
            keep = np.ones(len(data), dtype=bool)
            keep[40] = False
            data = _markers(
                data.ids[keep], data.poses[keep, :3], stamps=data.stamps_ns[keep],
                texts=[t for t, k in zip(data.texts, keep, strict=True) if k],
            )  # fmt: skip
        frames.append(encode_marker_array(data))
    results = {}
    compiled_rows = DriverBridge._compiled_rows
    assert compiled_rows(DriverBridge(), decode_marker_fields(frames[0])) is not None
    for compiled in (False, True):
        # without the compiled rows, every frame takes the general (numpy) path
        monkeypatch.setattr(DriverBridge, "_compiled_rows", compiled_rows if compiled else _none)
        for scale in (1.0, 0.001):
            bridge = DriverBridge(DriverBridgeParams(position_scale=scale))
            groups = [bridge.update_bytes(raw) for raw in frames + frames[4:5]]
            results[compiled, scale] = groups, dict(bridge.drops)
    for scale in (1.0, 0.001):
        (fast, fast_drops), (slow, slow_drops) = results[True, scale], results[False, scale]
        assert fast_drops == slow_drops
        assert fast_drops["nan_position"] == 1
        for a, b in zip(fast, slow, strict=True):
            assert (a is None and b is None) or a.same_as(b)


def _none(*_args: object) -> None:
    return None


def _batch_frames():
    """Driver messages of every kind ``update_batch`` meets, as CDR bytes, in stamp order."""
    frames = []
    for step in range(14):
        stamp = STAMP + step * 33_000_000
        group = _group(3, stamp=stamp, seed=20 + step)
        group.skeletons[0].orientations[2] = np.nan  # a zero quaternion on the wire
        group.skeletons[2].confidences[5] = np.nan  # no level text
        if step in {2, 3}:  # a missing joint: ids not whole bodies, still usual
            group.skeletons[1].marker_present[7] = False
            group.skeletons[1].markers[7] = np.nan
            group.skeletons[1].update_links()
        data = group_to_driver_markers(group)
        if step == 4:  # a NaN position: counted and dropped by the general path
            data.poses[5, 0] = np.nan
        if step == 5:  # out of order and a duplicate
            data.ids[[0, 1]] = data.ids[[1, 0]]
            data.ids[40] = data.ids[39]
        if step == 6:  # DELETE markers among the joints
            data.actions[10:12] = DELETE
        if step == 7:  # texts that are no level, or one the codec must judge
            data.texts[3], data.texts[4] = "x", " 2"
        if step == 8:  # mixed stamps, a non-ASCII frame id
            data.stamps_ns[9] += 1
            data.frame_ids = ["kamera_ü"] * len(data)
        if step == 9:  # the same stamp again: dropped whole
            data.stamps_ns[:] = stamp - 33_000_000
        if step == 10:  # an unknown joint id
            data.ids[-1] = data.ids[-1] // 100 * 100 + 60
        frames.append(encode_marker_array(data))
        if step == 11:  # another layout in the namespace, an empty array, a DELETEALL
            other = group_to_driver_markers(_group(1, stamp + 1, KINECT_V2))
            frames.append(encode_marker_array(other))
            frames.append(encode_marker_array(MarkerArrayData.new(0)))
            frames.append(encode_marker_array(_markers([0], actions=[DELETEALL],
                                                       stamps=[stamp + 2])))  # fmt: skip
        if step == 12:  # bytes no codec reads
            frames.append(frames[-1][:-40])
    return frames


def _one_at_a_time(bridge, frames):
    """update_bytes of each frame, with update_batch's convention for undecodable bytes."""
    out = []
    for raw in frames:
        try:
            out.append(bridge.update_bytes(raw))
        except CodecError:
            bridge.drops["undecodable"] += 1
            out.append(None)
    return out


@pytest.mark.parametrize(
    "params",
    [
        DriverBridgeParams(),
        DriverBridgeParams(position_scale=0.001, frame_id="cam"),
        DriverBridgeParams(joint_names=list(reversed(AZURE_KINECT.joint_names))),
    ],
)
def test_batch_path_equals_message_after_message(params):
    """update_batch (compiled, a batch at a time) == update_bytes frame after frame."""
    from hiros_core.driver import kernels as compiled

    frames = _batch_frames()
    ends = np.cumsum([len(f) for f in frames])
    starts = ends - [len(f) for f in frames]
    buffer = b"".join(frames)
    one, batch = DriverBridge(params), DriverBridge(params)
    expected = _one_at_a_time(one, frames)
    got = batch.update_batch(buffer, starts, ends)
    half = len(frames) // 2  # the bridge's stamp carries over from batch to batch
    again = DriverBridge(params)
    split = again.update_batch(buffer, starts[:half], ends[:half])
    split += again.update_batch(buffer, starts[half:], ends[half:])
    for a, b, c in zip(expected, got, split, strict=True):
        assert (a is None and b is None) or a.same_as(b)
        assert (a is None and c is None) or a.same_as(c)
    assert batch.drops == one.drops == again.drops
    met = {"nan_position", "duplicate_marker", "delete_marker", "mixed_stamps", "repeated_stamp"}
    assert met | {"empty_array", "undecodable", "unknown_joint"} <= set(one.drops)
    # the compiled reading takes the usual frames itself (the test above could not tell)
    parsed = compiled.driver_messages(np.frombuffer(buffer, np.uint8), starts, ends, 1.0)
    assert parsed[1][[0, 1, 2, 3, 9, 12]].all()
    assert not parsed[1][[4, 6, 7, 8]].any()
