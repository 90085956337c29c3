"""Diagnostics follow the last minute, not the totals; rates and latencies; an empty room."""

from __future__ import annotations

import pytest

from hiros_ros.diagnostics import NodeHealth


def test_the_window_forgets_what_is_older_than_a_minute() -> None:
    health = NodeHealth(window=60.0, rate_window=10.0)
    for second in range(200):
        received = 30 * second
        dropped = 2 if second >= 5 else 0  # two frames dropped at t = 5 s, then none
        health.sample(float(second), {"received": received, "dropped": dropped})
        if second == 30:
            assert health.recent("dropped") == 2
            assert health.rate("received") == pytest.approx(30.0)
        if second == 64:
            assert health.recent("dropped") == 2  # t = 4 s is still the window's start
    assert health.recent("dropped") == 0
    assert health.recent("received") == 30 * 60
    assert health.rate("received") == pytest.approx(30.0)


def test_latency_percentiles() -> None:
    health = NodeHealth(latencies=100)
    assert health.latency_ms() == {}
    for k in range(1, 201):
        health.add_duration(k * 1e-3)  # 1 .. 200 ms; the last 100 are kept
    latency = health.latency_ms()
    assert latency["max"] == pytest.approx(200.0)
    assert latency["p50"] == pytest.approx(150.5)
    assert 198.0 < latency["p99"] < 200.0


@pytest.mark.ros
def test_a_node_is_ok_again_after_a_clean_minute(ros_context, monkeypatch) -> None:
    from diagnostic_msgs.msg import DiagnosticStatus

    import hiros_ros.node as node_module
    from hiros_ros import HirosNode

    clock = [1000.0]
    monkeypatch.setattr(node_module.time, "monotonic", lambda: clock[0])
    node = HirosNode("diagnosed")
    published = []
    node._diagnostics.publish = published.append
    try:
        node.counters["received"] += 10
        node.counters["processed"] += 9
        node.drop("bad frame", "test")
        node.publish_diagnostics()
        clock[0] += 61.0
        node.publish_diagnostics()
    finally:
        node.destroy_node()
    first, later = (array.status[0] for array in published)
    assert first.level == DiagnosticStatus.WARN
    assert first.message == "1 of 10 frame(s) dropped in the last 60 s"
    assert later.level == DiagnosticStatus.OK
    assert later.message == "1 frame(s) dropped before"
    values = {kv.key: kv.value for kv in later.values}
    assert values["dropped.bad frame"] == "1"
    assert {"input_rate_hz", "output_rate_hz"} <= set(values)


@pytest.mark.ros
def test_an_empty_room_is_nobody_in_view_not_a_drop(ros_context) -> None:
    from diagnostic_msgs.msg import DiagnosticStatus
    from rclpy.serialization import serialize_message
    from visualization_msgs.msg import MarkerArray

    from hiros_azure_bridge.node import BridgeNode
    from hiros_core.codec import decode_group

    node = BridgeNode()
    sent, published = [], []
    node._diagnostics.publish = published.append
    node.publish_raw = lambda _publisher, data: sent.append(decode_group(data))
    try:
        for _ in range(3):
            node.on_markers("k01", None, serialize_message(MarkerArray()))
        node.publish_diagnostics()
    finally:
        node.destroy_node()
    assert [len(group.skeletons) for group in sent] == [0, 0, 0]
    assert [group.frame_id for group in sent] == ["k01_depth_camera_link"] * 3
    assert sent[0].stamp_ns < sent[1].stamp_ns < sent[2].stamp_ns
    status = published[0].status[0]
    assert status.level == DiagnosticStatus.OK
    assert status.message == "nobody in view: k01 (3 empty frame(s) so far)"
    values = {kv.key: kv.value for kv in status.values}
    assert values["processed"] == "3"
    assert not any(key.startswith("dropped") for key in values)


@pytest.mark.ros
def test_the_stages_downstream_learn_that_nobody_is_there(ros_context) -> None:
    """The bridge's empty groups go on: the tracker publishes the frames it released with
    nobody in them as empty groups, and the merger passes on an empty result."""
    from hiros_core.calibration import Calibration, CameraCalibration
    from hiros_core.codec import decode_group, encode_group
    from hiros_core.model import SkeletonGroup
    from hiros_merger.node import MergerNode
    from hiros_tracker.node import TrackerNode

    tracker, merger = TrackerNode(), MergerNode()
    frame = "k01_depth_camera_link"
    tracker.tracker.set_calibration(
        Calibration(reference="k01", cameras={"k01": CameraCalibration(frame_id=frame)})
    )
    sent: dict[str, list] = {"tracker": [], "merger": []}
    for name, node in (("tracker", tracker), ("merger", merger)):
        node.publish_raw = lambda _publisher, data, name=name: sent[name].append(decode_group(data))
    try:
        for k in range(10):  # a third of a second of an empty room at 30 Hz
            tracker.on_group(encode_group(SkeletonGroup(1_000_000_000 + k * 33_000_000, frame, [])))
        for group in sent["tracker"]:
            merger.on_group(encode_group(group))
    finally:
        tracker.destroy_node()
        merger.destroy_node()
    assert len(sent["tracker"]) >= 8  # the frames released past the tracker's 50 ms wait
    assert all(not group.skeletons for group in sent["tracker"])
    assert len(sent["merger"]) == len(sent["tracker"])
    assert all(not group.skeletons for group in sent["merger"])
    assert tracker.tracker.processed == len(sent["tracker"])  # one group per released frame
